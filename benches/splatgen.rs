//! Splat generation speed: 100k and 1M points sampled from the bunny mesh,
//! and each stage's share of the time (printed once per size before timing).
//!
//! `cargo bench --bench splatgen -- --sample-size 10`

use criterion::{Criterion, criterion_group, criterion_main};
use splatray::io::{read_mesh, sample_mesh};
use splatray::splat::{SplatParams, generate};
use std::hint::black_box;
use std::path::Path;
use std::time::Duration;

fn bench(c: &mut Criterion) {
    let mesh = read_mesh(&Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/data/bunny-mesh.ply"))
        .expect("bundled bunny mesh");
    let params = SplatParams::default();
    let mut group = c.benchmark_group("splatgen");
    group.sample_size(10);
    group.measurement_time(Duration::from_secs(15));
    group.warm_up_time(Duration::from_secs(1));
    for n in [100_000usize, 1_000_000] {
        let mut cloud = sample_mesh(&mesh, n, 0.0, 42);
        cloud.normals = None; // estimate normals, as for a scan
        let (splats, r) = generate(&cloud, &params).expect("splats");
        let s = &r.seconds;
        let pct = |x: f64| 100.0 * x / s.total;
        eprintln!(
            "splatgen {n} points: {} splats, coverage {:.4}, total {:.3} s = knn {:.0}% + normals {:.0}% + grow {:.0}% + fit {:.0}%",
            splats.len(),
            r.coverage,
            s.total,
            pct(s.knn),
            pct(s.normals),
            pct(s.grow),
            pct(s.fit)
        );
        group.bench_function(format!("{n}_points"), |b| {
            b.iter(|| generate(black_box(&cloud), &params).expect("splats"))
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
