//! Triangles on the octree against Embree (issue 57): the bundled bunny
//! mesh (`scenes/data/bunny-mesh.ply`, 69,666 faces) built as
//! `Triangle`s on the octree and on Embree's user geometry (both deciding
//! with the one exact test, the same hits), and as Embree's own triangle
//! geometry (its own test: the speed the report's first claim is about).
//! One thread; primary rays of a 512 × 512 view of the mesh's box.
//! Prints build seconds, MB and Mrays/s of each; `cargo bench --bench
//! triangles`.

use glam::Vec3;
use splatray::accel::{CandidateHits, registry};
use splatray::embree::Device;
use splatray::embree::TriangleScene;
use splatray::geometry::Ray;
use splatray::primitive::Triangle;
use std::time::Instant;

fn main() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/data/bunny-mesh.ply");
    let mesh = splatray::io::read_mesh(&path).expect("the bundled bunny mesh");
    let tris: Vec<Triangle> = mesh
        .triangles
        .iter()
        .map(|t| Triangle {
            v: t.map(|i| mesh.positions[i as usize]),
        })
        .filter(Triangle::is_proper)
        .collect();
    let (lo, hi) = mesh.positions.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let (c, size) = ((lo + hi) * 0.5, (hi - lo).max_element());
    let eye = c + Vec3::new(0.3, 0.4, 2.0) * size;
    let fwd = (c - eye).normalize();
    let right = fwd.cross(Vec3::Y).normalize();
    let up = right.cross(fwd);
    const N: usize = 512;
    let rays: Vec<Ray> = (0..N * N)
        .map(|k| {
            let (x, y) = (
                (k % N) as f32 / N as f32 - 0.5,
                (k / N) as f32 / N as f32 - 0.5,
            );
            Ray::new(eye, fwd + (right * x + up * y) * 0.6)
        })
        .collect();
    println!(
        "bunny mesh: {} triangles, {} rays, one thread",
        tris.len(),
        rays.len()
    );
    let passes = 3;
    let mut reference: Option<Vec<Option<(u32, f32)>>> = None;
    for name in ["octree", "embree"] {
        let info = registry::lookup::<Triangle>(name).unwrap();
        let b = info.build(&tris).unwrap();
        let mut hits = CandidateHits::new(0.0);
        let mut got = Vec::with_capacity(rays.len());
        let mut best = f64::INFINITY;
        for _ in 0..passes {
            got.clear();
            let t0 = Instant::now();
            for r in &rays {
                b.intersect(r, 0.0, f32::INFINITY, &mut hits);
                got.push(hits.nearest().map(|h| (h.id, h.t)));
            }
            best = best.min(t0.elapsed().as_secs_f64());
        }
        let s = b.stats();
        println!(
            "{name:>14} (exact test): build {:.3} s, {:.1} MB, {:.2} Mrays/s (best of {passes}), {} hits",
            s.build_seconds,
            s.memory_bytes as f64 / 1e6,
            rays.len() as f64 / best / 1e6,
            got.iter().flatten().count()
        );
        match &reference {
            None => reference = Some(got),
            Some(r) => assert_eq!(r, &got, "{name}: the same hits as the octree"),
        }
    }
    let device = Device::new().unwrap();
    let before = device.memory();
    let idx: Vec<[u32; 3]> = mesh.triangles.clone();
    let t0 = Instant::now();
    let native = TriangleScene::new(&device, &[(&mesh.positions, &idx)]).unwrap();
    let build = t0.elapsed().as_secs_f64();
    let mem = device.memory().saturating_sub(before);
    let mut best = f64::INFINITY;
    let mut n = 0;
    for _ in 0..passes {
        n = 0;
        let t0 = Instant::now();
        for r in &rays {
            n += usize::from(native.intersect(r, 0.0, f32::INFINITY).is_some());
        }
        best = best.min(t0.elapsed().as_secs_f64());
    }
    println!(
        "{:>14} (own test):   build {build:.3} s, {:.1} MB, {:.2} Mrays/s (best of {passes}), {n} hits",
        "embree-native",
        mem as f64 / 1e6,
        rays.len() as f64 / best / 1e6
    );
}
