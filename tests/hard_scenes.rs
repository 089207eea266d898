//! The bundled hard-case scenes (scenes/hard.toml, scenes/hard/*.toml):
//! each rendered by both backends, which must agree ray for ray and pixel
//! for pixel, with no NaN anywhere.

mod common;

use common::render_with;

use splatray::scene::{Scene, build_scene, load_scene, parse_scene_str};
use splatray::validate::compare::compare_frames;
use std::path::{Path, PathBuf};

fn scenes() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let mut v = vec![root.join("hard.toml")];
    let mut more: Vec<PathBuf> = std::fs::read_dir(root.join("hard"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    more.sort();
    v.extend(more);
    v
}

fn small(mut s: Scene) -> Scene {
    s.set_view(Some(96), Some(72), Some(1), None).unwrap();
    s
}

#[test]
fn every_hard_scene_agrees_across_backends_without_nan() {
    let list = scenes();
    assert!(list.len() >= 4, "{list:?}");
    for path in list {
        let s = small(load_scene(&path, None).unwrap());
        let o = render_with(&s, common::default_renderer());
        let e = render_with(&s, common::other_renderer());
        let name = path.display();
        assert!(
            o.splat.iter().any(|&id| id != u32::MAX),
            "{name}: nothing was hit"
        );
        for f in [&o, &e] {
            assert!(
                f.rgb.iter().all(|c| c.is_finite()),
                "{name}: NaN or inf pixel"
            );
            assert!(f.normal.iter().all(|n| n.is_finite()), "{name}: NaN normal");
        }
        let a = compare_frames(&o, &e, s.options.scale.diagonal);
        assert_eq!(a.hit_agreement, 1.0, "{name}: {a:?}");
        assert_eq!(a.same_splat, 1.0, "{name}: {a:?}");
        assert_eq!(a.dt_rel_max, 0.0, "{name}: {a:?}");
        assert_eq!(a.image_max_abs, 0.0, "{name}: {a:?}");
    }
}

/// The far scene is the same scene as the one at the origin, translated by
/// 1e5: loading must shift it back in double precision, so both render to
/// (nearly) the same image. Without the f64 shift the splat centres would be
/// rounded to 1/128 of a unit, a seventh of a splat radius: with the shift
/// disabled this test measured hit agreement 0.99957, PSNR 35.8 dB and a
/// 136° worst normal, and failed.
#[test]
fn far_from_origin_renders_like_the_origin() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/hard/far.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let near_text = text
        .replace("100000.0", "0.0")
        .replace("100001.5", "1.5")
        .replace("100004.0", "4.0")
        .replace("100002.0", "2.0")
        .replace("100003.0", "3.0");
    assert_ne!(text, near_text);
    let far = small(load_scene(&path, None).unwrap());
    let near =
        small(build_scene(&parse_scene_str(&near_text).unwrap(), Path::new("."), None).unwrap());
    let a = render_with(&far, common::default_renderer());
    let b = render_with(&near, common::default_renderer());
    let c = compare_frames(&a, &b, far.options.scale.diagonal);
    eprintln!("far vs near: {c:?}");
    // Identical (measured 1.0, same splat 1.0): the bug above measured
    // 0.99957 and passed the old bound `> 0.999`.
    assert_eq!(c.hit_agreement, 1.0, "{c:?}");
    assert!(c.image_psnr_db.is_none_or(|p| p > 45.0), "{c:?}");
}

/// Every bundled scene renders with both backends to the same image (small
/// resolution), without NaN.
#[test]
fn bundled_scenes_render_identically_with_both_backends() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    for name in ["bunny.toml", "glass.toml", "shading.toml"] {
        let s = small(load_scene(&root.join(name), None).unwrap());
        let o = render_with(&s, common::default_renderer());
        let e = render_with(&s, common::other_renderer());
        assert!(o.rgb.iter().all(|c| c.is_finite()), "{name}: NaN pixel");
        assert!(o.splat.iter().any(|&id| id != u32::MAX), "{name}: empty");
        assert_eq!(o.rays, e.rays, "{name}: ray counts differ");
        assert_eq!(o.rgb, e.rgb, "{name}: images differ");
    }
}

/// A unit cube made of splats, each face a grid of discs that overhang
/// its edges, clipped at the edges (one line along an edge, two at a
/// corner; `splat::clip`) or not, rendered against the exact cube.
fn cube_scene(dir: &Path, clipped: bool) -> Scene {
    use glam::{DVec3, Vec3};
    use splatray::splat::{Clip, ClipLine, Splat};
    const N: usize = 8;
    let step = 1.0 / N as f32;
    let r = 0.75 * step;
    let mut splats = Vec::new();
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let mut n = Vec3::ZERO;
            n[axis] = sign;
            let (a1, a2) = ((axis + 1) % 3, (axis + 2) % 3);
            for i in 0..N {
                for j in 0..N {
                    let mut c = n * 0.5;
                    c[a1] = (i as f32 + 0.5) * step - 0.5;
                    c[a2] = (j as f32 + 0.5) * step - 0.5;
                    let mut s = Splat::disc(c, n, r).unwrap();
                    // An edge the disc reaches: the face stops at
                    // |c[k]| = 0.5 along each in-plane axis k.
                    let mut lines = Vec::new();
                    for k in [a1, a2] {
                        if c[k].abs() + r > 0.5 {
                            let mut m = Vec3::ZERO;
                            m[k] = c[k].signum();
                            let (la, lb) = (s.u_axis.dot(m), s.v_axis.dot(m));
                            lines.push(ClipLine {
                                a: la,
                                b: lb,
                                d: (0.5 - c[k].abs()) / r,
                            });
                        }
                    }
                    if clipped {
                        s.clip = match lines[..] {
                            [] => Clip::NONE,
                            [l] => Clip::one(l),
                            [l, m] => Clip::two(l, m),
                            _ => unreachable!("at most two edges"),
                        };
                    }
                    splats.push(s);
                }
            }
        }
    }
    let name = if clipped { "clipped" } else { "whole" };
    let path = dir.join(format!("cube-{name}.ply"));
    splatray::io::write_splats(&path, &splats, DVec3::ZERO).unwrap();
    // The exact cube: each face its own 4 corners (no normal shared
    // across an edge, so its shading is flat), 12 triangles facing out.
    let mut mesh = String::from(
        "ply\nformat ascii 1.0\nelement vertex 24\nproperty double x\nproperty double y\nproperty double z\nelement face 12\nproperty list uchar int vertex_indices\nend_header\n",
    );
    let faces = [
        [0, 4, 6, 2],
        [1, 3, 7, 5],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 2, 3, 1],
        [4, 5, 7, 6],
    ];
    for f in faces {
        for k in f {
            let c = |b: usize| if k & b != 0 { 0.5 } else { -0.5 };
            mesh += &format!("{} {} {}\n", c(1), c(2), c(4));
        }
    }
    for i in 0..6 {
        let v = 4 * i;
        mesh += &format!("3 {} {} {}\n3 {} {} {}\n", v, v + 1, v + 2, v, v + 2, v + 3);
    }
    std::fs::write(dir.join("cube-mesh.ply"), mesh).unwrap();
    let toml = format!(
        "background = [0.3, 0.4, 0.5]\n[camera]\nfrom = [1.7, 1.3, 2.0]\nat = [0, 0, 0]\nfov = 40\nwidth = 160\nheight = 120\n[[model]]\nsplats = \"cube-{name}.ply\"\ntruth = \"cube-mesh.ply\"\nmaterial = {{ kind = \"diffuse\", color = [0.7, 0.6, 0.5] }}\n[[light]]\nkind = \"point\"\nposition = [3.0, 4.0, 2.0]\nintensity = 30.0\n[render]\nambient = 0.1\n"
    );
    std::fs::write(dir.join(format!("cube-{name}.toml")), &toml).unwrap();
    let file = parse_scene_str(&toml).unwrap();
    build_scene(&file, dir, None).unwrap()
}

/// Edges and corners of clipped splats render as the cube's: against the
/// exact cube, above a PSNR and below a share of false hits (the discs'
/// overhang past the silhouette) with clipping, both backends identical;
/// the same discs whole are clearly worse, so the check can fail.
#[test]
fn a_cube_of_clipped_splats_renders_its_edges_and_corners() {
    use splatray::validate::compare::{render_truth, truth_errors};
    use splatray::validate::truth::Truth;
    let dir = common::scratch("clipped-cube");
    let mut figures = Vec::new();
    for clipped in [true, false] {
        let scene = cube_scene(&dir, clipped);
        assert_eq!(
            scene.splats.iter().filter(|s| s.is_clipped()).count(),
            if clipped { 6 * 28 } else { 0 },
            "set-up: every splat along an edge is clipped"
        );
        let truth = render_truth(&scene, &Truth::new(&scene).unwrap(), None);
        let o = render_with(&scene, "octree");
        let e = render_with(&scene, "embree");
        assert_eq!(o.rgb, e.rgb, "octree and Embree differ (clipped {clipped})");
        assert_eq!(o.splat, e.splat, "octree and Embree hit other splats");
        let t = truth_errors(o, &truth, &scene.camera, scene.options.scale.diagonal);
        let psnr = t.image_psnr_db.unwrap_or(f64::INFINITY);
        eprintln!(
            "cube, clipped {clipped}: PSNR {psnr:.2} dB, false hits {:.4}, coverage {:.4}, normal error {:.2}°",
            t.false_hits, t.coverage, t.normal_deg_mean
        );
        figures.push((psnr, t.false_hits));
    }
    let [(psnr, false_hits), (whole_psnr, whole_false)] = figures[..] else {
        unreachable!()
    };
    // Measured (160x120): clipped 156.81 dB (the exact cube's image but
    // for rounding), false hits 0; whole discs 28.13 dB, false hits
    // 0.0179 of the image (their overhang past the silhouette edges).
    assert!(psnr > 140.0, "clipped: {psnr} dB");
    assert!(false_hits <= 1e-4, "clipped: false hits {false_hits}");
    assert!(whole_psnr < 30.0, "whole discs: {whole_psnr} dB");
    assert!(whole_false > 0.015, "whole discs: false hits {whole_false}");
}
