//! Rays cast against splats on both backends, compared: a point cloud is
//! read and made into splats, a grid of rays is cast from the scanner's
//! position (or from in front of the cloud) on the octree and on Embree,
//! and every answer — distance, splat and shading normal — must be the
//! same bit for bit (`docs/DESIGN.md`, "The backend contract"). Exits 1
//! at the first ray they disagree on, or when no ray hits anything.
//!
//! `cargo run --release --example cast_both -- CLOUD [RAYS_PER_SIDE]`

use glam::Vec3;
use splatray::{
    Camera, CastOutputs, Error, GenerationOptions, Ray, Result, SplatSurfaces, build_backend,
    cast_rays, generate, read_points, splats_scene,
};
use std::path::PathBuf;

fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("cast_both: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

/// One backend's answers: distance, splat id and normal of every ray.
struct Answers {
    t: Vec<f32>,
    ids: Vec<u32>,
    normals: Vec<f32>,
}

fn run() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (path, side) = match args.as_slice() {
        [p] => (PathBuf::from(p), 200),
        [p, n] => (
            PathBuf::from(p),
            n.parse::<u32>()
                .ok()
                .filter(|n| (1..=4096).contains(n))
                .ok_or_else(|| {
                    Error::invalid(format!("RAYS_PER_SIDE '{n}' must be in 1..=4096"))
                })?,
        ),
        _ => return Err(Error::invalid("usage: cast_both CLOUD [RAYS_PER_SIDE]")),
    };

    // Points to splats, with the pipeline's default options.
    let cloud = read_points(&path)?;
    let made = generate(&cloud, &GenerationOptions::default(), None)?;
    println!(
        "{}: {} points -> {} splats",
        path.display(),
        cloud.len(),
        made.splats.len()
    );

    // The rays: a pinhole grid from the scanner (or from in front of the
    // splats' box), aimed at the splats' centre; positions are relative to
    // the cloud's origin, as the splats'.
    let n = made.splats.len() as f32;
    let centre = made.splats.iter().map(|s| s.center).sum::<Vec3>() / n;
    let radius = made
        .splats
        .iter()
        .map(|s| (s.center - centre).length())
        .fold(0.0_f32, f32::max);
    let eye = cloud
        .viewpoint
        .unwrap_or(centre + Vec3::new(0.0, 0.0, 3.0 * radius));
    let fov = (2.0 * (radius / (centre - eye).length()).atan())
        .to_degrees()
        .clamp(1.0, 120.0);
    let camera = Camera::look_at(eye, centre, Vec3::Y, fov, side, side, 1)?;
    let rays: Vec<Ray> = (0..side * side)
        .map(|i| camera.ray((i % side) as f32 + 0.5, (i / side) as f32 + 0.5))
        .collect();
    let lens: Vec<f32> = rays.iter().map(|r| r.dir.length()).collect();
    let scene = splats_scene(made.splats, camera)?;

    let cast = |name: &str| -> Result<Answers> {
        let backend = build_backend(name, &scene)?;
        let surfaces = SplatSurfaces {
            scene: &scene,
            backend: &*backend,
            kept: None,
        };
        let mut a = Answers {
            t: vec![0.0; rays.len()],
            ids: vec![0; rays.len()],
            normals: vec![0.0; 3 * rays.len()],
        };
        let out = CastOutputs {
            t: &mut a.t,
            ids: Some(&mut a.ids),
            normals: Some(&mut a.normals),
        };
        cast_rays(&surfaces, &rays, &lens, out);
        Ok(a)
    };
    let octree = cast("octree")?;
    let embree = cast("embree")?;

    for i in 0..rays.len() {
        let same = octree.t[i].to_bits() == embree.t[i].to_bits()
            && octree.ids[i] == embree.ids[i]
            && (0..3).all(|k| {
                octree.normals[3 * i + k].to_bits() == embree.normals[3 * i + k].to_bits()
            });
        if !same {
            return Err(Error::invalid(format!(
                "ray {i}: octree t {} splat {}, embree t {} splat {}",
                octree.t[i], octree.ids[i], embree.t[i], embree.ids[i]
            )));
        }
    }
    let hits = octree.ids.iter().filter(|&&id| id != u32::MAX).count();
    if hits == 0 {
        return Err(Error::invalid("no ray hit a splat: nothing was compared"));
    }
    println!(
        "{} rays, {hits} hits: octree and embree identical (t, splat, normal, bit for bit)",
        rays.len()
    );
    Ok(())
}
