//! The cloud's scene, step by step: survey, view and up rules, text.

use super::view::frame;
use super::*;
use crate::resolve::ShadingMode;
use glam::{DVec3, Vec3};
use std::path::Path;

/// Points on the surface of a box `size`, centred at `c`, `n` per face
/// side (a deterministic grid).
fn box_points(c: Vec3, size: Vec3, n: usize) -> Vec<Vec3> {
    let mut out = Vec::new();
    for axis in 0..3 {
        for side in [-0.5f32, 0.5] {
            for i in 0..n {
                for j in 0..n {
                    let a = i as f32 / (n - 1) as f32 - 0.5;
                    let b = j as f32 / (n - 1) as f32 - 0.5;
                    let mut p = Vec3::ZERO;
                    p[axis] = side;
                    p[(axis + 1) % 3] = a;
                    p[(axis + 2) % 3] = b;
                    out.push(c + p * size);
                }
            }
        }
    }
    out
}

/// [`survey`] of points offset from the origin, without colours.
fn points_survey(points: &[Vec3], viewpoint: Option<Vec3>) -> Survey {
    survey(CloudKind::Points, points, DVec3::ZERO, viewpoint, false).unwrap()
}

/// Projects `p` with the camera of `v`; true when inside the frame.
fn in_frame(v: &View, p: DVec3, aspect: f64) -> bool {
    let f = (v.at - v.from).normalize();
    let (r, u) = frame(f, v.up).unwrap();
    let q = p - v.from;
    let z = q.dot(f);
    let ty = (0.5 * v.fov.to_radians()).tan();
    z > 0.0 && (q.dot(u) / z).abs() <= ty && (q.dot(r) / z).abs() <= ty * aspect
}

#[test]
fn outliers_are_left_out_of_the_framing() {
    let mut pts = box_points(Vec3::new(10.0, 0.0, 0.0), Vec3::ONE, 30);
    let clean = points_survey(&pts, None);
    assert_eq!(clean.outliers, 0);
    // A few stray points far out.
    for k in 0..5 {
        pts.push(Vec3::new(10.0 + 20.0 * k as f32, 15.0, -9.0));
    }
    let s = points_survey(&pts, None);
    assert_eq!(s.outliers, 5);
    assert!((s.hi - s.lo - DVec3::ONE).abs().max_element() < 1e-5);
}

#[test]
fn framing_shows_every_point_and_fills_the_frame() {
    for (size, aspect) in [
        (Vec3::new(1.0, 2.0, 0.5), 4.0 / 3.0),
        (Vec3::new(30.0, 3.0, 5.0), 1.0),
        (Vec3::new(0.01, 0.02, 0.015), 0.5),
    ] {
        let pts = box_points(Vec3::new(3.0, -1.0, 100.0), size, 10);
        let s = points_survey(&pts, None);
        let v = choose_view(&s, None, aspect);
        assert!(s.sample.iter().all(|p| in_frame(&v, *p, aspect)), "{v:?}");
        // Not too small: a narrower frame cuts points off.
        let tight = View {
            fov: v.fov * 0.8,
            ..v.clone()
        };
        assert!(!s.sample.iter().all(|p| in_frame(&tight, *p, aspect)));
        assert!(v.from.y > s.center().y, "from above: {v:?}");
    }
}

#[test]
fn up_axis_rules() {
    // Flat: a terrain patch in x-y, seen by a viewpoint above it (+z).
    let mut ground = Vec::new();
    for i in 0..40 {
        for j in 0..40 {
            let h = ((i * 7 + j * 3) % 5) as f32 * 0.01;
            ground.push(Vec3::new(i as f32, j as f32, h));
        }
    }
    let s = points_survey(&ground, Some(Vec3::new(20.0, 20.0, 2.0)));
    let v = choose_view(&s, None, 1.0);
    assert_eq!(v.up, DVec3::Z, "{}", v.note);
    // The same terrain seen from below: the other side is up.
    let below = Survey {
        viewpoint: Some(DVec3::new(20.0, 20.0, -2.0)),
        ..s.clone()
    };
    assert_eq!(choose_view(&below, None, 1.0).up, DVec3::NEG_Z);
    // A pole along z, scanned from 10 units away along x, looked down on:
    // z is up (the lamppost).
    let pole = box_points(Vec3::new(-10.0, 0.0, -2.5), Vec3::new(1.0, 0.8, 6.0), 12);
    let s = points_survey(&pole, Some(Vec3::ZERO));
    let v = choose_view(&s, None, 4.0 / 3.0);
    assert_eq!(v.from, DVec3::ZERO, "{}", v.note);
    assert_eq!(v.up, DVec3::Z, "{}", v.note);
    // The same pole scanned level: no reason to leave +y.
    let level = Survey {
        viewpoint: Some(DVec3::new(0.0, 0.0, -2.5)),
        ..s.clone()
    };
    assert_eq!(choose_view(&level, None, 1.0).up, DVec3::Y);
    // A viewpoint looking along -z at an object: +z is along the line
    // of sight, +y is up (the milk carton, the synthetic scans).
    let obj = box_points(Vec3::new(0.25, -0.1, -0.7), Vec3::splat(0.15), 10);
    let s = points_survey(&obj, Some(Vec3::ZERO));
    let v = choose_view(&s, None, 1.0);
    assert_eq!((v.from, v.up), (DVec3::ZERO, DVec3::Y), "{}", v.note);
    assert!(s.sample.iter().all(|p| in_frame(&v, *p, 1.0)));
    // A given up wins.
    assert_eq!(choose_view(&s, Some(DVec3::X * 2.0), 1.0).up, DVec3::X);
    // No viewpoint: +y, unless the cloud stands on its -y end.
    let cone = |wide_at_top: bool| {
        let mut pts = Vec::new();
        for i in 0..40 {
            let y = i as f32 / 39.0;
            let r = 0.05 + if wide_at_top { y } else { 1.0 - y };
            for j in 0..40 {
                let a = j as f32 * std::f32::consts::TAU / 40.0;
                pts.push(Vec3::new(r * a.cos(), y, r * a.sin()));
            }
        }
        points_survey(&pts, None)
    };
    assert_eq!(choose_view(&cone(false), None, 1.0).up, DVec3::Y);
    let v = choose_view(&cone(true), None, 1.0);
    assert_eq!(v.up, DVec3::NEG_Y, "{}", v.note);
    assert!(cone(true).sample.iter().all(|p| in_frame(&v, *p, 1.0)));
}

/// Rule 0: a LAS or LAZ file's z is its elevation, whatever its box. The
/// bundled airborne tile is thinnest along y (28 m against 200 m of z), so
/// the same points in a PLY stand on their y side by rule 1; a `--up`
/// still wins.
#[test]
fn a_las_files_up_is_its_z() {
    let laz = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/data/32-1-472-150-76.laz");
    let s = survey_file(&laz).expect("the bundled tile reads");
    assert!(s.z_is_elevation);
    let v = choose_view(&s, None, 4.0 / 3.0);
    assert_eq!(v.up, DVec3::Z, "{}", v.note);
    assert!(v.note.contains("a LAS file"), "{}", v.note);
    assert_eq!(choose_view(&s, Some(DVec3::X), 1.0).up, DVec3::X);
    let dir = std::env::temp_dir().join(format!("splatray-cloud-las-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a temporary folder");
    let ply = dir.join("tile.ply");
    let (cloud, _) = crate::io::read_any(&laz).expect("the bundled tile reads");
    let crate::io::CloudRead::Points(cloud) = cloud else {
        panic!("a LAZ file holds points");
    };
    crate::io::write_points(&ply, &cloud).expect("the PLY is written");
    let p = survey_file(&ply).expect("the PLY reads");
    // The same LAZ bytes without an extension: found by their `LASF`.
    let bare = dir.join("tile");
    std::fs::copy(&laz, &bare).expect("the copy is written");
    assert!(survey_file(&bare).expect("the bare file reads").z_is_elevation);
    std::fs::remove_dir_all(&dir).ok();
    assert!(!p.z_is_elevation);
    let v = choose_view(&p, None, 4.0 / 3.0);
    assert_eq!(v.up.abs(), DVec3::Y, "{}", v.note);
}

#[test]
fn viewpoints_that_are_not_sensible() {
    let obj = box_points(Vec3::ZERO, Vec3::ONE, 10);
    // Inside the cloud: framing instead.
    let s = points_survey(&obj, Some(Vec3::new(0.1, 0.0, 0.0)));
    let v = choose_view(&s, None, 1.0);
    assert_ne!(v.from, DVec3::new(0.1, 0.0, 0.0));
    assert!(v.note.contains("framing"), "{}", v.note);
    assert!(s.sample.iter().all(|p| in_frame(&v, *p, 1.0)));
    // Very far away along +x: moved in on the same line of sight.
    let far = DVec3::new(1e5, 0.0, 0.0);
    let s = Survey {
        viewpoint: Some(far),
        ..s
    };
    let v = choose_view(&s, None, 1.0);
    assert!(v.from.x > 1.0 && v.from.x < 10.0, "{v:?}");
    assert!(v.from.y.abs() < 1e-9 && v.from.z.abs() < 1e-9, "{v:?}");
    assert!(s.sample.iter().all(|p| in_frame(&v, *p, 1.0)));
}

#[test]
fn scene_text_parses_and_keeps_the_view() {
    // Offsets from a far origin, as the readers give them: the view is
    // in the file's coordinates.
    let obj = box_points(Vec3::new(0.0, 2.0, -3.0), Vec3::splat(0.5), 8);
    let origin = DVec3::new(5e6, -3e6, 100.0);
    let s = survey(CloudKind::Points, &obj, origin, None, true).unwrap();
    assert!((s.center() - origin - DVec3::new(0.0, 2.0, -3.0)).length() < 1e-6);
    let v = choose_view(&s, None, 4.0 / 3.0);
    assert!((v.at - s.center()).length() < 1.0, "{v:?}");
    let o = CloudSceneOptions {
        spp: 4,
        shading: Some(ShadingMode::Flat),
        ..CloudSceneOptions::default()
    };
    let text = scene_text(Path::new("dir with \"quotes\"/c.ply"), &s, &v, &o).unwrap();
    let f = crate::scene::parse_scene_str(&text).unwrap();
    assert_eq!(
        f.models[0].points.as_deref(),
        Some(Path::new("dir with \"quotes\"/c.ply"))
    );
    let from = DVec3::from(f.camera.from);
    assert!((from - v.from).length() < 1e-5 * s.radius(), "{text}");
    assert_eq!(f.camera.spp, 4);
    assert_eq!(f.render.shading, Some(ShadingMode::Flat));
    assert_eq!(f.lights.len(), 2);
}

#[test]
fn relative_paths() {
    let d = std::env::temp_dir().join(format!("splatray-cloud-rel-{}", std::process::id()));
    std::fs::create_dir_all(d.join("a/b")).unwrap();
    std::fs::create_dir_all(d.join("c")).unwrap();
    std::fs::write(d.join("c/x.ply"), "ply\n").unwrap();
    assert_eq!(
        path_from(&d.join("a/b"), &d.join("c/x.ply")),
        Path::new("../../c/x.ply")
    );
    assert_eq!(
        path_from(&d.join("c"), &d.join("c/x.ply")),
        Path::new("x.ply")
    );
    let _ = std::fs::remove_dir_all(&d);
}
