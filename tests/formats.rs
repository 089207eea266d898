//! Formats scanners write: LAS and LAZ, through the `las` crate, written
//! here with the same crate.

mod common;

use common::{Rng, scratch};
use glam::DVec3;
use splatray::io::read_points;
use std::path::Path;
use std::process::Command;

/// Centre of a georeferenced test sphere (UTM-like metres).
const CENTRE: DVec3 = DVec3::new(512_345.678, 4_012_345.123, 100.0);

/// A sphere of radius 10 at [`CENTRE`] with colours, as points.
fn sphere(n: usize) -> Vec<(DVec3, [u16; 3])> {
    let mut rng = Rng::new(11);
    (0..n)
        .map(|_| {
            let d = rng.unit().as_dvec3();
            let c = [(d.x.abs() * 65535.0) as u16, 32768, 65535];
            (CENTRE + d * 10.0, c)
        })
        .collect()
}

/// Writes `points` as LAS or LAZ (by `path`'s extension), millimetre scale,
/// point format 2 (with colour).
fn write_las(path: &Path, points: &[(DVec3, [u16; 3])]) {
    let mut b = las::Builder::default();
    b.point_format = las::point::Format::new(2).unwrap();
    let t = |o: f64| las::Transform {
        scale: 0.001,
        offset: o.round(),
    };
    b.transforms = las::Vector {
        x: t(CENTRE.x),
        y: t(CENTRE.y),
        z: t(CENTRE.z),
    };
    let mut w = las::Writer::from_path(path, b.into_header().unwrap()).unwrap();
    for (p, c) in points {
        w.write_point(las::Point {
            x: p.x,
            y: p.y,
            z: p.z,
            color: Some(las::Color {
                red: c[0],
                green: c[1],
                blue: c[2],
            }),
            ..Default::default()
        })
        .unwrap();
    }
    w.close().unwrap();
}

#[test]
fn las_and_laz_read_through_scale_and_offset_in_f64() {
    let dir = scratch("las");
    let pts = sphere(4000);
    for name in ["s.las", "s.laz"] {
        let path = dir.join(name);
        write_las(&path, &pts);
        let c = read_points(&path).unwrap();
        assert_eq!(c.len(), pts.len(), "{name}");
        // Millimetre scale: every point within half a millimetre (plus the
        // f32 rounding of its offset from the cloud's origin, about 1e-6 at
        // 10 m), although the coordinates are 4e6 from zero.
        for (i, (p, col)) in pts.iter().enumerate() {
            let d = (c.world(i) - *p).abs().max_element();
            assert!(d <= 0.0005 + 2e-6, "{name}: point {i} off by {d}");
            let got = c.colors.as_ref().unwrap()[i];
            let want = splatray::io::srgb_to_linear(f32::from(col[0]) / 65535.0);
            assert!(
                (got.x - want).abs() < 1e-5,
                "{name}: colour {got} vs {want}"
            );
        }
    }
    let las_size = std::fs::metadata(dir.join("s.las")).unwrap().len();
    let laz_size = std::fs::metadata(dir.join("s.laz")).unwrap().len();
    assert!(laz_size < las_size, "LAZ {laz_size} vs LAS {las_size}");
    // A truncated LAS fails in one line naming the file.
    let bytes = std::fs::read(dir.join("s.las")).unwrap();
    let cut = dir.join("cut.las");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let e = read_points(&cut).unwrap_err().to_string();
    assert!(e.contains("cut.las") && e.lines().count() == 1, "{e}");
}

/// `splatray compare FILE` on a LAS and a LAZ file: a scene made for the
/// cloud, rendered by every backend, bit-identical.
#[test]
fn las_and_laz_render_with_backends_identical() {
    let dir = scratch("las-render");
    let pts = sphere(3000);
    for name in ["s.las", "s.laz"] {
        let path = dir.join(name);
        write_las(&path, &pts);
        let report = dir.join(format!("{name}.json"));
        let o = Command::new(env!("CARGO_BIN_EXE_splatray"))
            .arg("compare")
            .arg(&path)
            .args(["--width", "64", "--height", "48", "--report"])
            .arg(&report)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
        let b = r["backends"].as_array().unwrap();
        assert!(b.len() >= 2, "{r}");
        let a = &b[1]["agreement"];
        assert_eq!(a["hit_agreement"], 1.0, "{name}: {a}");
        assert_eq!(a["same_splat"], 1.0, "{name}: {a}");
        assert!(a["image_psnr_db"].is_null(), "{name}: {a}");
        assert!(r["splats"].as_u64().unwrap() > 100, "{r}");
    }
}
