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
