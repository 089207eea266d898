//! Analytic image tests for the integrator and the shading modes, and
//! backend image agreement on a small render.

mod common;

use common::render_with;

use glam::Vec3;
use splatray::resolve::ShadingMode;
use splatray::scene::{Scene, build_scene, parse_scene_str};
use std::path::Path;

fn scene(text: &str) -> Scene {
    build_scene(&parse_scene_str(text).unwrap(), Path::new("."), None).unwrap()
}

/// A diffuse splat sphere (albedo 1) under a directional light (irradiance
/// 1), no ambient, black background: the closed form is `max(0, n·l)` with
/// `n` the true sphere normal where the pixel's ray meets the true sphere.
const LAMBERT: &str = r#"
[camera]
from = [0.0, 0.0, 6.0]
at = [0.0, 0.0, 0.0]
fov = 25
width = 160
height = 160

[[model]]
shape = { kind = "sphere", center = [0.0, 0.0, 0.0], radius = 1.0, splats = 1500 }
material = { kind = "diffuse", color = [1.0, 1.0, 1.0] }

[[light]]
kind = "directional"
direction = [-0.5, -0.4, -1.0]

[render]
ambient = 0.0
"#;

/// Mean and max |rendered - closed form| over pixels where the ray hits the
/// true sphere well inside the silhouette (|cos| to the view > 0.3).
fn lambert_error(mode: ShadingMode) -> (f64, f32, usize) {
    let mut sc = scene(LAMBERT);
    sc.options.shading = mode;
    let frame = render_with(&sc, common::other_renderer());
    let center = -sc.offset; // the sphere's centre in scene coordinates
    let l = -Vec3::new(-0.5, -0.4, -1.0).normalize();
    let (mut sum, mut max, mut n) = (0.0f64, 0.0f32, 0usize);
    for y in 0..sc.camera.height {
        for x in 0..sc.camera.width {
            let ray = sc.camera.ray(x as f32 + 0.5, y as f32 + 0.5);
            let oc = ray.origin - center;
            let b = oc.dot(ray.dir);
            let disc = b * b - (oc.length_squared() - 1.0);
            if disc <= 0.0 {
                continue;
            }
            let t = -b - disc.sqrt();
            let normal = (ray.at(t) - center).normalize();
            if normal.dot(-ray.dir) < 0.3 {
                continue;
            }
            let expected = normal.dot(l).max(0.0);
            let got = frame.rgb[(y * sc.camera.width + x) as usize].x;
            let e = (got - expected).abs();
            sum += e as f64;
            max = max.max(e);
            n += 1;
        }
    }
    (sum / n as f64, max, n)
}

#[test]
fn phong_splats_match_closed_form_lambert_and_flat_splats_do_not() {
    let (phong_mean, phong_max, n) = lambert_error(ShadingMode::Phong);
    let (flat_mean, flat_max, _) = lambert_error(ShadingMode::Flat);
    eprintln!(
        "lambert over {n} pixels: phong mean {phong_mean:.5} max {phong_max:.4}; flat mean {flat_mean:.5} max {flat_max:.4}"
    );
    assert!(n > 5000, "too few pixels compared: {n}");
    // Stated tolerance: mean error 0.5% of the peak radiance, max 3%.
    assert!(phong_mean < 0.005, "phong mean error {phong_mean} >= 0.005");
    assert!(phong_max < 0.03, "phong max error {phong_max} >= 0.03");
    // Flat splats are measurably worse: at least 4x the mean error.
    assert!(
        flat_mean > 4.0 * phong_mean,
        "flat mean {flat_mean} not > 4x phong mean {phong_mean}"
    );
}

/// White furnace for the integrator: a perfect mirror sphere in a uniform
/// white background, no lights. Every pixel, hit or not, must be exactly 1:
/// reflection neither gains nor loses energy.
#[test]
fn white_furnace_mirror_sphere_is_invisible() {
    let sc = scene(
        r#"
background = [1.0, 1.0, 1.0]
[camera]
from = [0.0, 0.0, 5.0]
at = [0.0, 0.0, 0.0]
fov = 30
width = 96
height = 96
[[model]]
shape = { kind = "sphere", center = [0.0, 0.0, 0.0], radius = 1.0, splats = 2000 }
material = { kind = "mirror", reflectance = 1.0 }
"#,
    );
    let frame = render_with(&sc, common::other_renderer());
    assert!(frame.rays.reflection > 1000, "{:?}", frame.rays);
    for (i, c) in frame.rgb.iter().enumerate() {
        assert!(
            (*c - Vec3::ONE).abs().max_element() < 1e-5,
            "pixel {i}: {c}, expected 1"
        );
    }
}

/// White furnace with a glass sphere: Fresnel reflection plus refraction
/// must sum to 1 at every interface, so pixels stay at 1 up to the energy
/// of paths cut by the depth limit (which can only lose energy).
#[test]
fn white_furnace_glass_sphere_conserves_energy() {
    let sc = scene(
        r#"
background = [1.0, 1.0, 1.0]
[camera]
from = [0.0, 0.0, 5.0]
at = [0.0, 0.0, 0.0]
fov = 30
width = 96
height = 96
[[model]]
shape = { kind = "sphere", center = [0.0, 0.0, 0.0], radius = 1.0, splats = 3000 }
material = { kind = "glass", ior = 1.5 }
[render]
max_depth = 12
"#,
    );
    let frame = render_with(&sc, common::other_renderer());
    assert!(frame.rays.refraction > 1000, "{:?}", frame.rays);
    let mut low = 0;
    let mut sum = 0.0f64;
    for (i, c) in frame.rgb.iter().enumerate() {
        assert!(
            c.max_element() <= 1.0 + 1e-4,
            "pixel {i}: {c} gained energy"
        );
        if c.min_element() < 0.95 {
            low += 1;
        }
        sum += c.x as f64;
    }
    let mean = sum / frame.rgb.len() as f64;
    eprintln!("glass furnace: mean {mean:.5}, {low} pixels below 0.95");
    assert!(mean > 0.995, "mean {mean}");
    assert!(low * 100 < frame.rgb.len(), "{low} pixels below 0.95");
}

/// The two backends see the same candidates, so the same scene renders to
/// the same image, AOVs included, one sample a pixel and four; the octree
/// answers the camera's rays from its fan's lists (`Backend::fan`), which
/// the brute-force backend has none of.
#[test]
fn backends_render_identical_images() {
    for spp in [1, 4] {
        backends_render_identical_images_at(spp);
    }
}

fn backends_render_identical_images_at(spp: u32) {
    let mut sc = scene(
        r#"
background = [0.1, 0.1, 0.2]
[camera]
from = [0.0, 1.5, 5.0]
at = [0.0, 0.0, 0.0]
width = 80
height = 60
[[model]]
shape = { kind = "sphere", center = [0.0, 0.2, 0.0], radius = 0.8, splats = 600 }
material = { kind = "glass" }
[[model]]
shape = { kind = "quad", center = [0.0, -0.7, 0.0], size = [4.0, 4.0], splats = 400 }
material = { kind = "mirror" }
[[model]]
shape = { kind = "sphere", center = [1.2, 0.0, -1.0], radius = 0.5, splats = 300 }
material = { kind = "phong" }
[[light]]
kind = "sphere"
position = [2.0, 4.0, 3.0]
radius = 0.5
intensity = 30
samples = 4
"#,
    );
    sc.camera.spp = spp;
    let rays = sc.camera.pixel_rays(0..sc.camera.height);
    let oct = splatray::accel::registry::find("octree")
        .unwrap()
        .build_scene(&sc)
        .unwrap();
    let fan = oct
        .fan(&rays.as_slice())
        .expect("the octree makes a fan for the camera");
    assert!(fan.backend().is_some(), "the fan holds its blocks' lists");
    let a = render_with(&sc, "brute");
    assert!(a.rays.refraction > 0 && a.rays.reflection > 0 && a.rays.shadow > 0);
    for info in splatray::accel::registry::renderers() {
        let b = render_with(&sc, info.name);
        let k = info.name;
        assert_eq!(a.rays, b.rays, "{k}: ray counts differ");
        assert_eq!(a.splat, b.splat, "{k}: resolved splats differ");
        assert_eq!(a.depth, b.depth, "{k}: depths differ");
        assert_eq!(a.normal, b.normal, "{k}: normals differ");
        assert_eq!(a.rgb, b.rgb, "{k}: radiance differs");
    }
}
