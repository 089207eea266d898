//! Measures the factor between a splat's radius and the sigma of the
//! Gaussian it is exported as (`splatray::io::RADIUS_PER_SIGMA`).
//!
//! A Gaussian renderer composites the exported Gaussians (opacity
//! `EXPORT_OPACITY`, alpha `o exp(-rho^2 / 2)`, rho in sigmas); where they
//! reach an accumulated opacity of one half it shows a surface. The discs
//! show a surface inside their union. For each factor `K` (radius = K
//! sigma) this samples points on the splats' planes out to 1.5 radii
//! (rims, gaps between discs and the space past a border) and counts where
//! the two disagree: holes (inside a disc, Gaussians under one half) and
//! spill (outside every disc, Gaussians at one half or more).
//!
//! `cargo run --release --example gaussian_factor -- SPLATS.ply [...]`

use glam::Vec3;
use kiddo::SquaredEuclidean;
use splatray::io::{EXPORT_OPACITY, read_splats};
use splatray::rng::SplitMix64;
use splatray::splat::{Splat, knn::build_tree};
use std::num::NonZero;
use std::path::PathBuf;

/// Test points per file.
const SAMPLES: usize = 40_000;
/// Neighbour centres looked at per test point.
const NEIGHBOURS: usize = 64;
/// Factors tried: 1.0 to 3.0 by 0.1.
const FACTORS: usize = 21;

fn factor(k: usize) -> f32 {
    1.0 + 0.1 * k as f32
}

/// Squared normalised distances (in radii) from `x` to the splats near it
/// that lie in nearly its plane (`normal` is the plane's).
fn local_distances(splats: &[Splat], near: &[u32], x: Vec3, normal: Vec3) -> Vec<f32> {
    near.iter()
        .map(|&i| &splats[i as usize])
        .filter(|s| {
            let d = x - s.center;
            s.normal.dot(normal).abs() > 0.5 && s.normal.dot(d).abs() <= 0.5 * s.radii.x
        })
        .map(|s| {
            let d = x - s.center;
            let a = d.dot(s.u_axis) / s.radii.x;
            let b = d.dot(s.v_axis) / s.radii.y;
            a * a + b * b
        })
        .collect()
}

fn main() -> Result<(), String> {
    let files: Vec<PathBuf> = std::env::args_os().skip(1).map(PathBuf::from).collect();
    if files.is_empty() {
        return Err("usage: gaussian_factor SPLATS.ply [...]".into());
    }
    let mut total = [0f64; FACTORS];
    // Per file: its name, then holes and spill (per cent) per factor.
    let mut columns: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    for f in &files {
        let set = read_splats(f).map_err(|e| e.to_string())?;
        let splats = &set.splats;
        let centres: Vec<Vec3> = splats.iter().map(|s| s.center).collect();
        let tree = build_tree(&centres);
        let mut rng = SplitMix64::new(7);
        let mut holes = [0usize; FACTORS];
        let mut spill = [0usize; FACTORS];
        for _ in 0..SAMPLES {
            let s = &splats[rng.below(splats.len())];
            // Uniform in the ellipse of 1.5 radii.
            let (a, b) = loop {
                let a = rng.range(-1.5, 1.5);
                let b = rng.range(-1.5, 1.5);
                if a * a + b * b <= 2.25 {
                    break (a, b);
                }
            };
            let x = s.center + s.u_axis * (a * s.radii.x) + s.v_axis * (b * s.radii.y);
            let near: Vec<u32> = tree
                .nearest_n::<SquaredEuclidean>(
                    &x.to_array(),
                    NonZero::new(NEIGHBOURS).expect("non-zero"),
                )
                .into_iter()
                .map(|n| n.item)
                .collect();
            let d2 = local_distances(splats, &near, x, s.normal);
            let in_disc = d2.iter().any(|&d| d <= 1.0);
            for k in 0..FACTORS {
                let f = factor(k);
                let clear: f32 = d2
                    .iter()
                    .map(|&d| 1.0 - EXPORT_OPACITY * (-0.5 * f * f * d).exp())
                    .product();
                let shown = 1.0 - clear >= 0.5;
                holes[k] += usize::from(in_disc && !shown);
                spill[k] += usize::from(!in_disc && shown);
            }
        }
        let name = f.file_name().map_or(String::new(), |n| {
            format!("{} ({})", n.to_string_lossy(), splats.len())
        });
        let pct = |c: usize| 100.0 * c as f64 / SAMPLES as f64;
        let col: Vec<(f64, f64)> = (0..FACTORS)
            .map(|k| (pct(holes[k]), pct(spill[k])))
            .collect();
        for (k, (h, s)) in col.iter().enumerate() {
            total[k] += h + s;
        }
        columns.push((name, col));
    }
    println!("holes % / spill % of points sampled out to 1.5 radii on each splat's plane");
    print!("{:>4}", "K");
    for (name, _) in &columns {
        print!(" | {name:>24}");
    }
    println!(" | mean mismatch %");
    for k in 0..FACTORS {
        print!("{:>4.1}", factor(k));
        for (_, col) in &columns {
            print!(" | {:>11.2} / {:>10.2}", col[k].0, col[k].1);
        }
        println!(" | {:>8.2}", total[k] / files.len() as f64);
    }
    let best = (0..FACTORS)
        .min_by(|&a, &b| total[a].total_cmp(&total[b]))
        .unwrap_or(0);
    println!(
        "least mismatch over all files: K = {} (mean {:.2} %)",
        factor(best),
        total[best] / files.len() as f64
    );
    Ok(())
}
