//! Embree's kernels chosen by `SPLATRAY_EMBREE_CONFIG`: every ISA this CPU
//! runs gives the same candidate hits through the user geometry (the
//! arithmetic there is splatray's own), and the floats Embree computes
//! itself (triangles, the exact surfaces of `--truth`) agree within a
//! stated tolerance, not bit for bit.

mod common;

use common::{bin, scratch};
use glam::Vec3;
use splatray::accel::embree::EmbreeBackend;
use splatray::accel::{Backend, CandidateHits, Ray};
use splatray::embree::{CONFIG_VAR, Device, TriangleScene, cpu_isas};
use splatray::splat::Splat;

/// The ISAs to force: every one of Embree's main kernel sets the CPU runs.
fn isas() -> Vec<&'static str> {
    cpu_isas()
        .into_iter()
        .filter(|i| splatray::embree::FORCIBLE_ISAS.contains(i))
        .collect()
}

#[test]
fn every_isa_gives_bit_identical_user_geometry_hits() {
    let isas = isas();
    assert!(!isas.is_empty(), "an x86-64 CPU runs at least sse4.2");
    let mut rng = splatray::rng::SplitMix64::new(common::seed());
    let splats: Vec<Splat> = (0..400)
        .map(|_| {
            let c = Vec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            );
            let n = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), 1.0);
            Splat::disc(c, n, rng.range(0.02, 0.2)).unwrap()
        })
        .collect();
    let discs: Vec<_> = splats.iter().map(Splat::disc_geometry).collect();
    let rays: Vec<Ray> = (0..2000)
        .map(|_| {
            let o = Vec3::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), 4.0);
            let at = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), 0.0);
            Ray::new(o, at - o)
        })
        .collect();
    let trace = |isa: &str| {
        let device = Device::with_config(&format!("isa={isa}")).unwrap();
        let backend = EmbreeBackend::new(&device, &discs).unwrap();
        let mut hits = CandidateHits::new(0.05);
        rays.iter()
            .map(|r| {
                backend.intersect(r, 0.0, f32::INFINITY, &mut hits);
                let all: Vec<(u32, u32)> = hits
                    .as_slice()
                    .iter()
                    .map(|h| (h.id, h.t.to_bits()))
                    .collect();
                (all, backend.occluded(r, 0.0, f32::INFINITY))
            })
            .collect::<Vec<_>>()
    };
    // Every ISA against the brute-force oracle (so a CPU with one ISA still
    // compares something), and so against each other.
    let oracle = splatray::accel::registry::oracle().build(&discs).unwrap();
    let mut hits = CandidateHits::new(0.05);
    let want: Vec<_> = rays
        .iter()
        .map(|r| {
            oracle.intersect(r, 0.0, f32::INFINITY, &mut hits);
            let all: Vec<(u32, u32)> = hits
                .as_slice()
                .iter()
                .map(|h| (h.id, h.t.to_bits()))
                .collect();
            (all, oracle.occluded(r, 0.0, f32::INFINITY))
        })
        .collect();
    // Measured: 1,1xx of the 2,000 rays hit (seed 0x5eed2007).
    assert!(want.iter().filter(|(h, _)| !h.is_empty()).count() > 200);
    for isa in &isas {
        let got = trace(isa);
        let differ = got.iter().zip(&want).filter(|(g, w)| g != w).count();
        assert_eq!(differ, 0, "isa={isa}: {differ} rays differ from the oracle");
    }
    eprintln!("embree isas compared: {isas:?}");
}

/// `splatray info`'s machine-readable lines, which scripts/test.sh reads to
/// run the suites again on each Embree ISA and SIMD path: present, and
/// naming exactly what this CPU runs (renamed or emptied, the re-runs would
/// do nothing).
#[test]
fn info_lists_the_isas_and_simd_paths_the_suite_reruns() {
    let o = bin().arg("info").output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    let line = |key: &str| -> Vec<String> {
        text.lines()
            .find_map(|l| l.strip_prefix(&format!("{key}: ")))
            .unwrap_or_else(|| {
                panic!("no '{key}:' line in `splatray info` (scripts/test.sh reads it):\n{text}")
            })
            .split_whitespace()
            .map(str::to_string)
            .collect()
    };
    assert_eq!(line("embree-isas"), isas(), "{text}");
    let paths: Vec<&str> = splatray::simd::available()
        .iter()
        .map(|i| i.name())
        .collect();
    assert_eq!(line("simd-paths"), paths, "{text}");
    assert!(!isas().is_empty() && !paths.is_empty(), "{text}");
}

#[test]
fn triangle_distances_agree_within_ulps_across_isas() {
    let positions = [
        Vec3::new(-1.0, -1.0, 0.3),
        Vec3::new(1.0, -1.0, -0.2),
        Vec3::new(0.0, 1.0, 0.1),
    ];
    let mut rng = splatray::rng::SplitMix64::new(common::seed());
    // Rays from random origins to random points well inside the triangle.
    let rays: Vec<Ray> = (0..500)
        .map(|_| {
            let (a, b) = (rng.range(0.05, 0.9), rng.range(0.05, 0.9));
            let (a, b) = if a + b > 0.95 {
                (0.95 - a, 0.95 - b)
            } else {
                (a, b)
            };
            let (a, b) = (a.max(0.02), b.max(0.02));
            let p = positions[0]
                + a * (positions[1] - positions[0])
                + b * (positions[2] - positions[0]);
            let o = Vec3::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), 3.0);
            Ray::new(o, p - o)
        })
        .collect();
    for isa in isas() {
        let device = Device::with_config(&format!("isa={isa}")).unwrap();
        let scene = TriangleScene::new(&device, &[(&positions[..], &[[0, 1, 2]][..])]).unwrap();
        for r in &rays {
            // The plane through the triangle, solved in f64.
            let (a, b, c) = (positions[0], positions[1], positions[2]);
            let n = (b - a).cross(c - a).as_dvec3();
            let d = r.dir.as_dvec3();
            let t = n.dot(a.as_dvec3() - r.origin.as_dvec3()) / n.dot(d);
            let got = scene.intersect(r, 0.0, f32::INFINITY);
            let t_embree = got
                .unwrap_or_else(|| panic!("{isa}: the triangle is missed"))
                .t;
            // Embree's kernels round differently per ISA: a few ulps of t.
            let tol = 8.0 * f64::from(f32::EPSILON) * t;
            assert!(
                (f64::from(t_embree) - t).abs() <= tol,
                "{isa}: t {t_embree} against {t} (tolerance {tol})"
            );
        }
    }
}

fn compare_report(isa: &str, dir: &std::path::Path) -> serde_json::Value {
    let report = dir.join(format!("{isa}.json"));
    let o = bin()
        .env(CONFIG_VAR, format!("isa={isa}"))
        .args([
            "compare",
            concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/bunny.toml"),
            "--width",
            "120",
            "--height",
            "90",
            "--truth",
            "--report",
        ])
        .arg(&report)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "{isa}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap()
}

/// The bundled bunny under each forced ISA: octree and Embree agree on
/// every ray (hit agreement 1, same splat 1, identical image); the errors
/// against the exact surfaces, which Embree's triangles give, agree across
/// ISAs within a tolerance.
#[test]
fn bunny_compare_agrees_completely_under_every_isa() {
    let dir = scratch("embree-isa");
    let reports: Vec<(&str, serde_json::Value)> = isas()
        .into_iter()
        .map(|i| (i, compare_report(i, &dir)))
        .collect();
    for (isa, r) in &reports {
        let embree = r["backends"]
            .as_array()
            .unwrap()
            .iter()
            .find(|b| b["name"] == "embree")
            .unwrap_or_else(|| panic!("{isa}: no embree row"));
        let a = &embree["agreement"];
        assert_eq!(a["hit_agreement"], 1.0, "{isa}: {a}");
        assert_eq!(a["same_splat"], 1.0, "{isa}: {a}");
        assert_eq!(a["only_first"], 0, "{isa}: {a}");
        assert_eq!(a["only_second"], 0, "{isa}: {a}");
        assert!(a["image_psnr_db"].is_null(), "{isa}: images differ: {a}");
    }
    let truth = |r: &serde_json::Value, key: &str| -> f64 {
        r["truth"]["backends"][0][key].as_f64().unwrap()
    };
    let rays = reports[0].1["rays"].as_f64().unwrap();
    let (first, r0) = &reports[0];
    for (isa, r) in &reports[1..] {
        // Shares of rays: at most one ray's worth apart.
        for key in ["coverage", "false_hits"] {
            let (a, b) = (truth(r0, key), truth(r, key));
            assert!((a - b).abs() <= 1.0 / rays, "{key}: {first} {a}, {isa} {b}");
        }
        // Continuous figures: within 1e-3 relative.
        for key in ["normal_deg_mean", "depth_rel_p99", "image_psnr_db"] {
            let (a, b) = (truth(r0, key), truth(r, key));
            assert!(
                (a - b).abs() <= 1e-3 * a.abs().max(1e-12),
                "{key}: {first} {a}, {isa} {b}"
            );
        }
    }
}

/// An ISA the CPU lacks, or a name Embree does not know (which Embree itself
/// would quietly read as `sse2`), is a one-line error and a non-zero exit.
#[test]
fn an_isa_that_cannot_run_is_a_one_line_error() {
    let mut configs = vec!["isa=avx3"];
    if !cpu_isas().contains(&"avx512") {
        configs.push("isa=avx512");
    }
    for config in configs {
        let o = bin().env(CONFIG_VAR, config).arg("info").output().unwrap();
        assert!(!o.status.success(), "{config}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(err.trim_end().lines().count(), 1, "{config}: {err}");
        assert!(err.contains(config), "{config}: {err}");
    }
}
