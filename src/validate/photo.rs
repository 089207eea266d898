//! The photo check of an organised colour scan (`scan-check --photo`): the
//! capture's own colours as the truth. A tenth of the measured pixels is
//! held out of splat generation, and a tenth of the empty ones out of the
//! scanner's misses that trimming uses; the splats are seen from the
//! sensor (its pose and fitted intrinsics, `scene::sensor`) through the
//! pixels' centres, rendered unlit: the albedo AOV of the renderer (the
//! resolved surface's colour, through the backend named); and the held-out
//! pixels' colours are compared with the captured ones, in sRGB: PSNR at
//! full resolution, and over 2×2 and 4×4 blocks (texture finer than a
//! splat dominates at full resolution), plus the share of the held-out
//! pixels the splats cover and of the held-out empty ones they fill.

use crate::accel::registry;
use crate::io::{Organised, linear_to_srgb};
use crate::render::integrator::render;
use crate::rng::SplitMix64;
use crate::scene::load::splats_scene;
use crate::scene::model::Camera;
use crate::scene::sensor::recover;
use crate::splat::{PointCloud, SplatParams};
use crate::{Error, Result};
use glam::Vec3;
use serde::Serialize;

/// What the photo check measured.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct PhotoReport {
    /// The grid: pixels per row, and rows.
    pub width: u32,
    /// See `width`.
    pub height: u32,
    /// Measured pixels (with a point), and of them held out.
    pub measured: usize,
    /// See `measured`.
    pub held_out: usize,
    /// Splats grown from the rest.
    pub splats: usize,
    /// Share of the held-out pixels whose ray meets a splat.
    pub covered: f64,
    /// Share of the held-out pixels the capture left empty (a share of
    /// them, left out of the scanner's misses that trimming uses) whose ray
    /// meets a splat.
    pub filled: f64,
    /// PSNR (dB, sRGB in `[0, 1]`) of the splats' colours against the
    /// captured ones over the covered held-out pixels: each pixel, and the
    /// means over 2×2 and 4×4 blocks.
    pub psnr: [f64; 3],
    /// The sensor fit's residual, pixels.
    pub residual: f64,
    /// Splats with a linear colour field (`splat::color`; 0 with
    /// `SplatParams::color_fields` off).
    pub color_fields: usize,
}

/// Runs the photo check on an organised capture with colours.
///
/// # Errors
/// One line: no colours, a grid no camera fits, or splat generation's
/// error.
pub fn photo_check(
    grid: &Organised,
    splat: &SplatParams,
    holdout: f32,
    seed: u64,
    backend: &str,
) -> Result<PhotoReport> {
    let info = registry::lookup(backend)?;
    let colors = grid
        .colors
        .as_ref()
        .ok_or_else(|| Error::invalid("the organised cloud has no colours to compare with"))?;
    if !(holdout > 0.0 && holdout <= 0.5) {
        return Err(Error::invalid(format!(
            "holdout {holdout} must be in (0, 0.5]"
        )));
    }
    let sensor = recover(grid).map_err(Error::invalid)?;
    let origin = grid.position;
    let mut rng = SplitMix64::new(seed);
    let held: Vec<bool> = grid
        .pixels
        .iter()
        .map(|_| rng.next_f32() < holdout)
        .collect();
    let (mut positions, mut kept_colors) = (Vec::new(), Vec::new());
    for ((&(_, p), c), &h) in grid.pixels.iter().zip(colors).zip(&held) {
        if !h {
            positions.push((p - origin).as_vec3());
            kept_colors.push(*c);
        }
    }
    // The capture's empty cells are held out at the same rate (their own
    // draws, so the measured pixels held out do not depend on them); the
    // rest are the scanner's misses trimming uses, as a file's are.
    let (w, h) = (sensor.width, sensor.height);
    let mut measured = vec![false; (w * h) as usize];
    for &(i, _) in &grid.pixels {
        measured[i as usize] = true;
    }
    let mut rng = SplitMix64::new(seed ^ 0x9e37_79b9_7f4a_7c15);
    let empty_held: Vec<bool> = measured
        .iter()
        .map(|&m| !m && rng.next_f32() < holdout)
        .collect();
    let pinhole = grid.pinhole().map_err(Error::invalid)?;
    let misses = grid
        .miss_cells()
        .into_iter()
        .filter(|&k| !empty_held[k])
        .map(|k| grid.cell_ray(&pinhole, k))
        .collect();
    let cloud = PointCloud {
        positions,
        origin,
        colors: Some(kept_colors),
        viewpoint: Some(Vec3::ZERO),
        misses: Some(misses),
        ..PointCloud::default()
    };
    let params = SplatParams {
        viewpoint: Some(Vec3::ZERO),
        ..splat.clone()
    };
    let crate::pipeline::Generated {
        splats,
        color_fields: fields,
        constant_color_fields: constant,
        ..
    } = crate::pipeline::generate(&cloud, &params, None)?;
    let color_fields = fields.len() - constant;
    let camera = Camera::look_at_intrinsics(
        Vec3::ZERO,
        sensor.forward.as_vec3(),
        sensor.up.as_vec3(),
        sensor.intrinsics,
        w,
        h,
        1,
    )?;
    let n_splats = splats.len();
    let mut scene = splats_scene(splats, camera)?;
    scene.color_fields = fields;
    let built = info.build_scene(&scene)?;
    let frame = render(&scene, built.as_ref(), None);
    // The albedo each pixel sees (None: its ray meets nothing).
    let seen: Vec<Option<Vec3>> = frame
        .splat
        .iter()
        .zip(&frame.albedo)
        .map(|(&id, &a)| (id != u32::MAX).then_some(a))
        .collect();
    let mut truth: Vec<Option<Vec3>> = vec![None; (w * h) as usize];
    for ((&(i, _), c), &hd) in grid.pixels.iter().zip(colors).zip(&held) {
        if hd {
            truth[i as usize] = Some(*c);
        }
    }
    let held_out = truth.iter().flatten().count();
    let covered = truth
        .iter()
        .zip(&seen)
        .filter(|(t, s)| t.is_some() && s.is_some())
        .count();
    let empty = empty_held.iter().filter(|e| **e).count();
    let filled = empty_held
        .iter()
        .zip(&seen)
        .filter(|(e, s)| **e && s.is_some())
        .count();
    let srgb = |c: Vec3| c.map(|x| linear_to_srgb(x.clamp(0.0, 1.0)));
    let psnr = [1u32, 2, 4].map(|b| {
        let (mut se, mut n) = (0f64, 0usize);
        for by in 0..h.div_ceil(b) {
            for bx in 0..w.div_ceil(b) {
                let (mut a, mut t, mut k) = (Vec3::ZERO, Vec3::ZERO, 0u32);
                for y in by * b..((by + 1) * b).min(h) {
                    for x in bx * b..((bx + 1) * b).min(w) {
                        let i = (y * w + x) as usize;
                        if let (Some(tc), Some(sc)) = (truth[i], seen[i]) {
                            a += srgb(sc);
                            t += srgb(tc);
                            k += 1;
                        }
                    }
                }
                if k > 0 {
                    let d = (a - t) / k as f32;
                    se += f64::from(d.length_squared()) / 3.0;
                    n += 1;
                }
            }
        }
        if n == 0 {
            0.0
        } else {
            -10.0 * (se / n as f64).max(1e-12).log10()
        }
    });
    Ok(PhotoReport {
        width: w,
        height: h,
        measured: grid.pixels.len(),
        held_out,
        splats: n_splats,
        covered: covered as f64 / held_out.max(1) as f64,
        filled: filled as f64 / empty.max(1) as f64,
        psnr,
        residual: sensor.residual,
        color_fields,
    })
}
