//! Secondary rays skip only the surface they leave (issue 10): a sphere
//! resting on a coarse floor casts its shadow up to the contact, as it does
//! on a fine floor and on the exact surfaces; a lit noisy plane does not
//! shadow itself.

mod common;

use common::{Rng, render_with};
use glam::{Vec2, Vec3};
use splatray::accel::{Backend, CandidateHits, Query, Ray};
use splatray::render::integrator::{Frame, ShadeHit, SplatSurfaces, Surfaces, render_surfaces};
use splatray::scene::{Light, Scene, build_scene, parse_scene_file, parse_scene_str};
use splatray::splat::{PointCloud, SplatParams, generate};
use splatray::validate::compare::{render_truth, truth_errors};
use splatray::validate::truth::Truth;
use std::path::Path;

const CONTACT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/contact.toml");
const W: u32 = 240;
const H: u32 = 180;

/// `scenes/contact.toml` at `W × H`, its floor made of `floor_splats`.
fn contact_scene(floor_splats: usize) -> Scene {
    let path = Path::new(CONTACT);
    let mut file = parse_scene_file(path).unwrap();
    let floor = file.models[1].shape.as_mut().expect("model 2 is the floor");
    assert_eq!(
        floor.splats, 100,
        "the bundled scene's floor has 100 splats"
    );
    floor.splats = floor_splats;
    let mut scene = build_scene(&file, path.parent().unwrap(), None).unwrap();
    scene.set_view(Some(W), Some(H), None, None).unwrap();
    scene
}

/// PSNR (dB) of the splat render against the exact surfaces.
fn psnr_against_truth(scene: &Scene, frame: &Frame) -> f64 {
    let truth = render_truth(scene, &Truth::new(scene).unwrap(), None);
    let e = truth_errors(
        frame.clone(),
        &truth,
        &scene.camera,
        scene.options.scale.diagonal,
    );
    e.image_psnr_db.unwrap_or(f64::INFINITY)
}

#[test]
fn a_coarse_floor_renders_as_well_as_a_fine_one() {
    let coarse = contact_scene(100);
    let fine = contact_scene(10_000);
    let coarse_floor = coarse.splats.iter().map(|s| s.radii.x).fold(0.0, f32::max);
    assert!(
        coarse_floor > 0.5,
        "set-up: the coarse floor's splats ({coarse_floor}) are larger than the sphere"
    );
    let mut fine_psnr = f64::NAN;
    for name in common::renderers() {
        let a = psnr_against_truth(&coarse, &render_with(&coarse, name));
        let b = psnr_against_truth(&fine, &render_with(&fine, name));
        fine_psnr = b;
        eprintln!(
            "{name}: PSNR against the exact surfaces: 100-splat floor {a:.2} dB, 10,000-splat floor {b:.2} dB"
        );
        assert!(
            a >= b - 1.0,
            "{name}: the 100-splat floor ({a:.2} dB) is more than 1 dB below the 10,000-splat floor ({b:.2} dB)"
        );
    }
    // The guard before the rule (every hit within the radius of the splat a
    // ray leaves skipped) fails the measure.
    let backend = splatray::accel::registry::find(common::default_renderer())
        .unwrap()
        .build_splats(&coarse.splats)
        .unwrap();
    let old = render_surfaces(
        &coarse,
        &Guard {
            splats: SplatSurfaces {
                scene: &coarse,
                backend: backend.as_ref(),
                kept: None,
            },
            radius: true,
        },
        None,
    );
    let old = psnr_against_truth(&coarse, &old);
    eprintln!("the radius guard: 100-splat floor {old:.2} dB");
    assert!(
        old < fine_psnr - 1.0,
        "set-up: the radius guard renders the coarse floor at {old:.2} dB, the fine one renders at {fine_psnr:.2} dB"
    );
}

/// A floor pixel of `scene` near the contact: whether the exact sphere
/// shadows it, its radiance if lit, and whether it borders the sphere in
/// the image.
struct FloorPixel {
    index: usize,
    shadowed: bool,
    lit: f32,
    borders_sphere: bool,
}

/// The floor pixels of the exact render `truth` within `near` of the
/// contact.
fn floor_pixels(scene: &Scene, truth: &Frame, near: f32) -> Vec<FloorPixel> {
    // World: sphere of radius 0.5 at (0, 0.5, 0) on the floor y = 0, floor
    // albedo 0.75 (red channel), one point light; see scenes/contact.toml.
    let center = Vec3::new(0.0, 0.5, 0.0) - scene.offset;
    let contact = Vec3::ZERO - scene.offset;
    let Light::Point { position, power } = scene.lights[0] else {
        panic!("the scene's light is a point light")
    };
    let (albedo, ambient) = (0.75, scene.options.ambient);
    let (w, h) = (scene.camera.width as usize, scene.camera.height as usize);
    let point = |i: usize| {
        let ray = scene.camera.ray((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
        ray.at(truth.depth[i])
    };
    let on_floor = |i: usize| truth.depth[i].is_finite() && (point(i).y - contact.y).abs() < 1e-4;
    let on_sphere = |i: usize| truth.depth[i].is_finite() && !on_floor(i);
    let mut out = Vec::new();
    for i in 0..w * h {
        if !on_floor(i) || (point(i) - contact).length() > near {
            continue;
        }
        let p = point(i);
        let to = position - p;
        let (d, l) = (to.length(), to.normalize());
        // Does the segment to the light cross the exact sphere?
        let oc = p - center;
        let b = oc.dot(l);
        let disc = b * b - (oc.length_squared() - 0.25);
        let shadowed = disc > 0.0 && -b - disc.sqrt() < d && -b + disc.sqrt() > 0.0;
        let (x, y) = (i % w, i / w);
        let borders_sphere = (x > 0 && on_sphere(i - 1))
            || (x + 1 < w && on_sphere(i + 1))
            || (y > 0 && on_sphere(i - w))
            || (y + 1 < h && on_sphere(i + w));
        out.push(FloorPixel {
            index: i,
            shadowed,
            lit: albedo * (ambient + power.x * l.y / (d * d)),
            borders_sphere,
        });
    }
    out
}

#[test]
fn the_shadow_reaches_the_contact() {
    let scene = contact_scene(100);
    let truth = render_truth(&scene, &Truth::new(&scene).unwrap(), None);
    let near = 0.6; // floor within 0.6 of the contact (sphere radius 0.5)
    let pixels = floor_pixels(&scene, &truth, near);
    let shadowed: Vec<&FloorPixel> = pixels.iter().filter(|p| p.shadowed).collect();
    let touching: Vec<&&FloorPixel> = shadowed.iter().filter(|p| p.borders_sphere).collect();
    assert!(
        shadowed.len() > 200 && touching.len() > 20,
        "set-up: {} shadowed floor pixels within {near} of the contact, {} of them next to the sphere",
        shadowed.len(),
        touching.len()
    );
    let ambient_only = 0.75 * scene.options.ambient;
    // A pixel is dark when its radiance is below halfway between the
    // ambient term and its radiance if lit.
    let dark_in =
        |frame: &Frame, p: &FloorPixel| frame.rgb[p.index].x < 0.5 * (ambient_only + p.lit);
    // The guard before the rule (skip every hit within the radius of the
    // splat a ray leaves) left a lit gap: the measure can fail.
    let octree = splatray::accel::registry::find(common::default_renderer()).unwrap();
    let backend = octree.build_splats(&scene.splats).unwrap();
    let old = render_surfaces(
        &scene,
        &Guard {
            splats: SplatSurfaces {
                scene: &scene,
                backend: backend.as_ref(),
                kept: None,
            },
            radius: true,
        },
        None,
    );
    let old_gap = touching.iter().filter(|p| !dark_in(&old, p)).count();
    eprintln!(
        "the radius guard: lit next to the sphere {old_gap} of {}",
        touching.len()
    );
    assert!(
        old_gap * 4 > touching.len(),
        "set-up: the radius guard lit only {old_gap} of {} shadowed pixels next to the sphere",
        touching.len()
    );
    for name in common::renderers() {
        let frame = render_with(&scene, name);
        let dark = |p: &FloorPixel| dark_in(&frame, p);
        let lit = shadowed.iter().filter(|p| !dark(p)).count();
        let gap = touching.iter().filter(|p| !dark(p)).count();
        let false_shadow = pixels.iter().filter(|p| !p.shadowed && dark(p)).count();
        eprintln!(
            "{name}: {} floor pixels within {near} of the contact, {} in the exact shadow ({} of them next to the sphere): lit {lit} (next to the sphere {gap}); dark outside the exact shadow {false_shadow}",
            pixels.len(),
            shadowed.len(),
            touching.len()
        );
        // The shadow touches the sphere in the image: every shadowed floor
        // pixel next to the sphere is dark (no lit gap between them).
        assert_eq!(
            gap, 0,
            "{name}: a lit gap between the sphere and its shadow"
        );
        // And the shadow near the contact is where the exact one is, but
        // for a few pixels on its edges.
        assert!(
            lit * 100 <= shadowed.len(),
            "{name}: {lit} of {} shadowed floor pixels near the contact are lit",
            shadowed.len()
        );
        assert!(
            false_shadow * 100 <= pixels.len() - shadowed.len(),
            "{name}: {false_shadow} floor pixels outside the exact shadow are dark"
        );
    }
}

/// The splats without the self-hit rule: secondary rays skip every hit
/// within a distance of their origin instead, `eps_self`, or (`radius`, the
/// guard before the rule) the larger of it and the radius of the splat
/// they leave.
struct Guard<'a> {
    splats: SplatSurfaces<'a>,
    radius: bool,
}

impl Guard<'_> {
    fn t_min(&self, from: &ShadeHit) -> f32 {
        let eps = self.splats.eps_self();
        if self.radius {
            eps.max(
                self.splats.scene.splats[from.surface.id as usize]
                    .radii
                    .max_element(),
            )
        } else {
            eps
        }
    }
}

impl Surfaces for Guard<'_> {
    fn hit(
        &self,
        ray: &Ray,
        from: Option<&ShadeHit>,
        hits: &mut CandidateHits,
    ) -> Option<ShadeHit> {
        let t_min = from.map_or(0.0, |f| self.t_min(f));
        self.splats
            .surface(Query::new(*ray, t_min, f32::INFINITY), hits)
    }

    fn occluded(&self, ray: &Ray, from: &ShadeHit, t_max: f32) -> bool {
        // The integrator stops `eps_self` short of the light; the guard
        // stopped its own distance short.
        let t_min = self.t_min(from);
        let t_max = t_max + self.eps_self() - t_min;
        self.splats.backend.occluded(ray, t_min, t_max)
    }

    fn eps_self(&self) -> f32 {
        self.splats.eps_self()
    }
}

/// A plane `y = 0` of points spaced `spacing` apart, displaced along `y` by
/// Gaussian noise of half the spacing, turned into splats (normals
/// estimated, facing up), in a scene whose exact surface is the plane: the
/// scene file's quad, whose splats are replaced by the noisy ones.
fn noisy_plane() -> Scene {
    let (n, half) = (121usize, 1.0f32);
    let spacing = 2.0 * half / (n - 1) as f32;
    let mut rng = Rng::new(common::seed());
    let mut positions = Vec::with_capacity(n * n);
    for i in 0..n {
        for j in 0..n {
            let x = -half + i as f32 * spacing;
            let z = -half + j as f32 * spacing;
            let y = (rng.next_gaussian() * 0.5 * f64::from(spacing)) as f32;
            positions.push(Vec3::new(x, y, z));
        }
    }
    let cloud = PointCloud {
        positions,
        ..PointCloud::default()
    };
    // Whole discs: with creases, noise this strong has the plane fitted
    // whole and its points moved onto it (`splat::planes`), and no noise
    // would be left for the rule to meet.
    let params = SplatParams {
        viewpoint: Some(Vec3::new(0.0, 5.0, 0.0)),
        creases: splatray::splat::Creases::Off,
        ..SplatParams::default()
    };
    let (splats, _) = generate(&cloud, &params).unwrap();
    let text = r#"
[camera]
from = [0.0, 2.2, 2.4]
at = [0.0, 0.0, 0.0]
fov = 40
width = 200
height = 160
[[model]]
shape = { kind = "quad", center = [0.0, 0.0, 0.0], size = [2.0, 2.0], splats = 400 }
material = { kind = "diffuse", color = [0.8, 0.8, 0.8] }
[[light]]
kind = "point"
position = [1.6, 1.1, 0.8]
intensity = 6.0
[render]
ambient = 0.0
"#;
    let mut scene = build_scene(&parse_scene_str(text).unwrap(), Path::new("."), None).unwrap();
    let offset = scene.offset;
    scene.splats = splats
        .into_iter()
        .map(|mut s| {
            s.center -= offset;
            s
        })
        .collect();
    scene.material_of = vec![0; scene.splats.len()];
    scene
}

/// Of the pixels inside the plane (away from its edges) whose resolved
/// normal faces the light, how many get no direct light at all: shadowed by
/// the plane itself (nothing else is in the scene).
fn self_shadowed(scene: &Scene, frame: &Frame) -> (usize, usize) {
    let Light::Point { position, .. } = scene.lights[0] else {
        panic!("a point light")
    };
    let w = scene.camera.width as usize;
    let (mut facing, mut dark) = (0, 0);
    for (i, &depth) in frame.depth.iter().enumerate() {
        if !depth.is_finite() {
            continue;
        }
        let ray = scene.camera.ray((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
        let p = ray.at(depth) + scene.offset;
        if Vec2::new(p.x, p.z).abs().max_element() > 0.85 {
            continue;
        }
        let n = frame.normal[i];
        let n = if n.dot(ray.dir) > 0.0 { -n } else { n };
        if n.dot((position - ray.at(depth)).normalize()) < 0.05 {
            continue;
        }
        facing += 1;
        dark += usize::from(frame.rgb[i].max_element() == 0.0);
    }
    (dark, facing)
}

#[test]
fn a_lit_noisy_plane_does_not_shadow_itself() {
    let scene = noisy_plane();
    let truth = render_truth(&scene, &Truth::new(&scene).unwrap(), None);
    let (truth_dark, truth_facing) = self_shadowed(&scene, &truth);
    assert_eq!(truth_dark, 0, "the exact plane shadows itself");
    assert!(truth_facing > 5_000, "set-up: {truth_facing} plane pixels");
    let registry = splatray::accel::registry::renderers();
    for info in &registry {
        let backend: Box<dyn Backend> = info.build_splats(&scene.splats).unwrap();
        let frame = render_surfaces(
            &scene,
            &SplatSurfaces {
                scene: &scene,
                backend: backend.as_ref(),
                kept: None,
            },
            None,
        );
        let (dark, facing) = self_shadowed(&scene, &frame);
        let bare = render_surfaces(
            &scene,
            &Guard {
                splats: SplatSurfaces {
                    scene: &scene,
                    backend: backend.as_ref(),
                    kept: None,
                },
                radius: false,
            },
            None,
        );
        let (bare_dark, bare_facing) = self_shadowed(&scene, &bare);
        eprintln!(
            "{}: {} splats; self-shadowed pixels {dark} of {facing} (the exact plane: {truth_dark} of {truth_facing}); with eps_self alone {bare_dark} of {bare_facing}",
            info.name,
            scene.splats.len()
        );
        // Nearly none: at most one pixel in a thousand (measured 0 of 9629
        // with the default seed, whole discs; 4 of 9602 with creases,
        // before strong noise had the plane fitted whole). Without the
        // rule: 1,015 of 9,629.
        assert!(
            dark * 1000 <= facing,
            "{}: {dark} of {facing} pixels shadow themselves",
            info.name
        );
        // Without the rule, eps_self alone lets the plane shadow itself:
        // the measure can fail.
        assert!(
            bare_dark * 20 > bare_facing,
            "set-up: with eps_self alone only {bare_dark} of {bare_facing} pixels shadow themselves"
        );
    }
}
