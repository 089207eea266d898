//! Per-ray and per-image agreement between two renders of one scene.

use crate::render::integrator::Frame;
use glam::Vec3;
use image::{ImageBuffer, Rgb};

/// Agreement figures between two frames of the same scene and camera, each
/// measured from the frames given (nothing is assumed).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Agreement {
    /// Primary rays compared (one per pixel: the pixel's first sample).
    pub rays: usize,
    /// Fraction of rays that both frames hit or both miss.
    pub hit_agreement: f64,
    /// Among rays both hit, the fraction resolved to the same splat.
    pub same_splat: f64,
    /// Rays that only the first frame hit (holes in the second).
    pub only_first: usize,
    /// Rays that only the second frame hit (holes in the first).
    pub only_second: usize,
    /// Median |Δt| / scene diagonal over rays both hit.
    pub dt_rel_p50: f64,
    /// 99th percentile of |Δt| / diagonal.
    pub dt_rel_p99: f64,
    /// Maximum |Δt| / diagonal.
    pub dt_rel_max: f64,
    /// Mean resolved-normal angle difference, degrees.
    pub normal_deg_mean: f64,
    /// 99th percentile of the resolved-normal angle difference, degrees.
    pub normal_deg_p99: f64,
    /// Maximum resolved-normal angle difference, degrees.
    pub normal_deg_max: f64,
    /// PSNR of the radiance clamped to [0, 1], dB; `null` (infinite) when
    /// the images are identical.
    pub image_psnr_db: Option<f64>,
    /// Maximum absolute per-channel radiance difference (clamped to [0, 1]).
    pub image_max_abs: f64,
}

/// The `q` quantile (nearest rank) of `v`, sorted in place; 0 when empty.
fn quantile(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let i = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1;
    v[i]
}

/// Angle between two directions in degrees, `atan2(|a×b|, a·b)` in f64:
/// exact 0 for equal vectors and accurate for tiny angles (acos of a
/// rounded dot product is not).
pub(crate) fn angle_deg(a: Vec3, b: Vec3) -> f64 {
    let (a, b) = (a.as_dvec3(), b.as_dvec3());
    a.cross(b).length().atan2(a.dot(b)).to_degrees()
}

/// Compares two frames of the same camera; `diagonal` is the scene's.
#[must_use]
pub fn compare_frames(a: &Frame, b: &Frame, diagonal: f32) -> Agreement {
    assert_eq!(
        (a.width, a.height),
        (b.width, b.height),
        "frames of different sizes"
    );
    let n = a.depth.len();
    let (mut agree, mut both, mut same, mut only_a, mut only_b) = (0usize, 0usize, 0usize, 0, 0);
    let mut dts = Vec::new();
    let mut angles = Vec::new();
    for i in 0..n {
        let ha = a.splat[i] != u32::MAX;
        let hb = b.splat[i] != u32::MAX;
        match (ha, hb) {
            (true, true) => {
                agree += 1;
                both += 1;
                if a.splat[i] == b.splat[i] {
                    same += 1;
                }
                dts.push(((a.depth[i] - b.depth[i]).abs() / diagonal) as f64);
                angles.push(angle_deg(a.normal[i], b.normal[i]));
            }
            (false, false) => agree += 1,
            (true, false) => only_a += 1,
            (false, true) => only_b += 1,
        }
    }
    let mut se = 0.0f64;
    let mut max_abs = 0.0f64;
    for (ca, cb) in a.rgb.iter().zip(&b.rgb) {
        let d = (ca.clamp(Vec3::ZERO, Vec3::ONE) - cb.clamp(Vec3::ZERO, Vec3::ONE)).abs();
        se += d.length_squared() as f64;
        max_abs = max_abs.max(d.max_element() as f64);
    }
    let mse = se / (3 * a.rgb.len().max(1)) as f64;
    let frac = |k: usize, of: usize| if of == 0 { 1.0 } else { k as f64 / of as f64 };
    Agreement {
        rays: n,
        hit_agreement: frac(agree, n),
        same_splat: frac(same, both),
        only_first: only_a,
        only_second: only_b,
        dt_rel_p50: quantile(&mut dts, 0.5),
        dt_rel_p99: quantile(&mut dts, 0.99),
        dt_rel_max: dts.last().copied().unwrap_or(0.0),
        normal_deg_mean: angles.iter().sum::<f64>() / angles.len().max(1) as f64,
        normal_deg_p99: quantile(&mut angles, 0.99),
        normal_deg_max: angles.last().copied().unwrap_or(0.0),
        image_psnr_db: (mse > 0.0).then(|| 10.0 * (1.0 / mse).log10()),
        image_max_abs: max_abs,
    }
}

/// Errors of a splat render against the render of the exact surface.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct TruthErrors {
    /// Of the pixels where the exact surface is hit, the fraction where the
    /// splats are hit too (1 = no holes).
    pub coverage: f64,
    /// Fraction of all pixels where splats are hit but the surface is not.
    pub false_hits: f64,
    /// Median |Δdepth| / scene diagonal where both are hit.
    pub depth_rel_p50: f64,
    /// 99th percentile of |Δdepth| / diagonal.
    pub depth_rel_p99: f64,
    /// Mean angle between the resolved splat normal and the surface normal,
    /// degrees (both turned toward the camera).
    pub normal_deg_mean: f64,
    /// 99th percentile of that angle, degrees.
    pub normal_deg_p99: f64,
    /// PSNR of the splat image against the surface's image, dB (`null` when
    /// identical).
    pub image_psnr_db: Option<f64>,
}

/// Turns every normal of `frame` toward the camera ray of its pixel centre,
/// so that surfaces whose orientations differ compare by shape only.
pub fn orient_to_camera(frame: &mut Frame, camera: &crate::scene::Camera) {
    let w = frame.width as usize;
    for (i, n) in frame.normal.iter_mut().enumerate() {
        let ray = camera.ray((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
        if n.dot(ray.dir) > 0.0 {
            *n = -*n;
        }
    }
}

/// Renders the exact surfaces of `scene` through the shared integrator,
/// with the normals turned toward the camera ([`orient_to_camera`]): the
/// reference for [`truth_errors`]. Reports to `progress` as
/// [`crate::render::integrator::render_surfaces`] does.
#[must_use]
pub fn render_truth(
    scene: &crate::scene::Scene,
    truth: &crate::validate::truth::Truth,
    progress: Option<crate::progress::Progress<'_>>,
) -> Frame {
    let mut f = crate::render::integrator::render_surfaces(scene, truth, progress);
    orient_to_camera(&mut f, &scene.camera);
    f
}

/// Errors of a splat render against `truth` (from [`render_truth`]); the
/// splat frame's normals are turned toward `camera` first.
#[must_use]
pub fn truth_errors(
    mut splats: Frame,
    truth: &Frame,
    camera: &crate::scene::Camera,
    diagonal: f32,
) -> TruthErrors {
    orient_to_camera(&mut splats, camera);
    let a = compare_frames(&splats, truth, diagonal);
    let truth_hits = truth.splat.iter().filter(|&&s| s != u32::MAX).count();
    TruthErrors {
        coverage: if truth_hits == 0 {
            1.0
        } else {
            1.0 - a.only_second as f64 / truth_hits as f64
        },
        false_hits: a.only_first as f64 / a.rays.max(1) as f64,
        depth_rel_p50: a.dt_rel_p50,
        depth_rel_p99: a.dt_rel_p99,
        normal_deg_mean: a.normal_deg_mean,
        normal_deg_p99: a.normal_deg_p99,
        image_psnr_db: a.image_psnr_db,
    }
}

/// A heat map a person can read at a glance: the two renders side by side,
/// then the per-pixel difference (black = equal, through blue and red to
/// yellow = the largest difference, scaled to the maximum), with rays that
/// only one frame hit in magenta.
#[must_use]
pub fn diff_image(a: &Frame, b: &Frame) -> ImageBuffer<Rgb<u8>, Vec<u8>> {
    let (w, h) = (a.width, a.height);
    let left = crate::render::output::to_srgb8(a);
    let mid = crate::render::output::to_srgb8(b);
    let diffs: Vec<f32> = a
        .rgb
        .iter()
        .zip(&b.rgb)
        .map(|(x, y)| {
            (x.clamp(Vec3::ZERO, Vec3::ONE) - y.clamp(Vec3::ZERO, Vec3::ONE))
                .abs()
                .max_element()
        })
        .collect();
    let max = diffs.iter().copied().fold(0.0f32, f32::max);
    let heat = |v: f32| -> [u8; 3] {
        // black -> blue -> red -> yellow
        let x = if max > 0.0 {
            (v / max).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let (r, g, bl) = if x == 0.0 {
            (0.0, 0.0, 0.0)
        } else if x < 1.0 / 3.0 {
            (0.0, 0.0, 0.3 + 2.1 * x)
        } else if x < 2.0 / 3.0 {
            let t = 3.0 * x - 1.0;
            (t, 0.0, 1.0 - t)
        } else {
            (1.0, 3.0 * x - 2.0, 0.0)
        };
        [(r * 255.0) as u8, (g * 255.0) as u8, (bl * 255.0) as u8]
    };
    ImageBuffer::from_fn(3 * w, h, |x, y| {
        let i = (y * w + x % w) as usize;
        match x / w {
            0 => *left.get_pixel(x, y),
            1 => *mid.get_pixel(x - w, y),
            _ => {
                if (a.splat[i] == u32::MAX) != (b.splat[i] == u32::MAX) {
                    Rgb([255, 0, 255])
                } else {
                    Rgb(heat(diffs[i]))
                }
            }
        }
    })
}
