//! Where the error of a splat render against the exact surface's comes
//! from: every pixel is given one cause, decided from the two frames'
//! AOVs, and the squared error of the image (the PSNR of
//! [`crate::validate::compare::TruthErrors::image_psnr_db`]) is summed per
//! cause, with the PSNR the image would have if that cause's pixels were
//! exact.
//!
//! The rule, first match wins (the two frames: the splats' and the exact
//! surface's of [`crate::validate::compare::render_truth`]):
//!
//! 1. **background**: neither frame hits (no error unless the background
//!    differs);
//! 2. **hole**: the surface is hit, the splats are not (§3.1: a gap
//!    between discs);
//! 3. **false hit**: the splats are hit, the surface is not (disc rims
//!    past the silhouette, or discs bridging a gap);
//! 4. **silhouette**: both hit, and within [`Tolerances::silhouette_px`]
//!    pixels of a pixel whose coverage differs from this one's, or whose
//!    depth differs by more than [`Tolerances::edge_depth_rel`] of the
//!    nearer, in either frame (a coverage or occlusion edge: pixels whose
//!    radiance mixes two surfaces as soon as the edge moves);
//! 5. **depth**: both hit, `|Δt|` above [`Tolerances::depth_rel`] of the
//!    scene diagonal (another surface: the far side, the floor behind);
//! 6. **terminator**: the same surface, but the share of the direct light
//!    in front of the shading normal differs by more than
//!    [`Tolerances::light`] (`Frame::light_facing`): the normal field of
//!    eq. (4) has moved a light across the terminator;
//! 7. **shadow**: the same surface and the same facing light, but the
//!    share of it that is occluded differs by more than
//!    [`Tolerances::light`] (`Frame::light_lit`): a cast shadow moved, or
//!    a shadow ray of §3.2 met a neighbouring splat (acne);
//! 8. **shading**: the rest (same surface, same light, the radiance
//!    differs by the normal error of eq. 4 and 5 alone).
//!
//! Holes and false hits are also split by how far they lie from the exact
//! surface's silhouette ([`Coverage`]): a pixel beside it is a silhouette
//! that moved, one far from it a gap or a stray disc.

use super::compare::angle_deg;
use crate::render::integrator::Frame;
use glam::Vec3;
use image::{ImageBuffer, Rgb};

/// What makes a pixel of a splat render differ from the exact surface's.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Cause {
    /// Neither frame hits a surface.
    Background,
    /// The exact surface is hit, the splats are not.
    Hole,
    /// The splats are hit, the exact surface is not.
    FalseHit,
    /// Both hit, near a coverage or occlusion edge of either frame.
    Silhouette,
    /// Both hit, at different depths (another surface).
    Depth,
    /// The same surface; a light sample's facing differs (shading normal).
    Terminator,
    /// The same surface and facing; a light sample's visibility differs.
    Shadow,
    /// The same surface and light; the shading differs.
    Shading,
}

impl Cause {
    /// Every cause, in the order of the rule (module docs).
    pub const ALL: [Cause; 8] = [
        Cause::Background,
        Cause::Hole,
        Cause::FalseHit,
        Cause::Silhouette,
        Cause::Depth,
        Cause::Terminator,
        Cause::Shadow,
        Cause::Shading,
    ];

    /// The name used in reports.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Cause::Background => "background",
            Cause::Hole => "hole",
            Cause::FalseHit => "false_hit",
            Cause::Silhouette => "silhouette",
            Cause::Depth => "depth",
            Cause::Terminator => "terminator",
            Cause::Shadow => "shadow",
            Cause::Shading => "shading",
        }
    }

    /// The colour of the cause in [`cause_image`].
    #[must_use]
    pub fn colour(self) -> [u8; 3] {
        match self {
            Cause::Background => [0, 0, 0],
            Cause::Hole => [255, 0, 255],
            Cause::FalseHit => [0, 255, 255],
            Cause::Silhouette => [255, 255, 0],
            Cause::Depth => [255, 0, 0],
            Cause::Terminator => [255, 128, 0],
            Cause::Shadow => [64, 96, 255],
            Cause::Shading => [0, 200, 0],
        }
    }
}

/// The thresholds of the rule (module docs).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Tolerances {
    /// Pixels (Chebyshev distance) a silhouette reaches either side of an
    /// edge.
    pub silhouette_px: u32,
    /// A depth step between neighbouring pixels larger than this fraction
    /// of the nearer depth is an occlusion edge.
    pub edge_depth_rel: f32,
    /// `|Δt|` above this fraction of the scene diagonal is another surface.
    pub depth_rel: f32,
    /// A light share (`Frame::light_facing`, `Frame::light_lit`) differing
    /// by more than this is a different light.
    pub light: f32,
}

impl Default for Tolerances {
    /// One pixel either side of an edge; a 3 % depth step; 0.5 % of the
    /// diagonal (ten times the bunny's p99 depth error); 1 % of the light
    /// (one of nine area-light samples carries about 10 %).
    fn default() -> Tolerances {
        Tolerances {
            silhouette_px: 1,
            edge_depth_rel: 0.03,
            depth_rel: 5e-3,
            light: 0.01,
        }
    }
}

/// One cause's part of the squared error.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct CauseError {
    /// The cause.
    pub cause: Cause,
    /// Pixels given this cause.
    pub pixels: usize,
    /// Their squared error, summed over pixels and channels (radiance
    /// clamped to [0, 1]).
    pub squared_error: f64,
    /// Their share of the image's squared error (the shares sum to 1; 0
    /// when the images are identical).
    pub share: f64,
    /// The PSNR of the image with these pixels made exact, dB (`null`:
    /// infinite, no error left).
    pub psnr_if_exact_db: Option<f64>,
    /// Mean angle between the two frames' shading normals over these
    /// pixels, degrees (0 where not both frames hit): the share of
    /// `compare --truth`'s mean normal error that each cause holds.
    pub normal_deg_mean: f64,
    /// This cause's part of the mean normal error over every pixel both
    /// frames hit, degrees (the parts add up to that mean).
    pub normal_deg_part: f64,
}

/// Holes or false hits by their Chebyshev distance in pixels to the exact
/// surface's silhouette: for a hole, the nearest pixel the surface misses
/// (1 pixel: the splats' silhouette moved inward; farther: a gap inside
/// the surface); for a false hit, the nearest pixel the surface hits
/// (1 pixel: disc rims past the silhouette; farther: a disc bridging a
/// gap, or a stray one).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct Coverage {
    /// Beside it (1 pixel).
    pub at_1px: usize,
    /// 2 or 3 pixels away.
    pub at_2_3px: usize,
    /// Farther (nothing within 3 pixels).
    pub farther: usize,
}

/// The squared error of a splat frame against the exact surface's, by
/// cause.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ErrorBudget {
    /// The thresholds used.
    pub tolerances: Tolerances,
    /// Pixels compared.
    pub pixels: usize,
    /// The image's PSNR, dB (as `TruthErrors::image_psnr_db`).
    pub psnr_db: Option<f64>,
    /// Every cause of `Cause::ALL`, in that order.
    pub causes: Vec<CauseError>,
    /// The holes by distance to the exact surface's silhouette.
    pub holes: Coverage,
    /// The false hits by distance to the exact surface's coverage.
    pub false_hits: Coverage,
    /// The same split over the pixels whose splat hit is of each material
    /// (each model has its own), materials without such pixels left out;
    /// holes and background have no splat hit and are in none. The PSNR
    /// if exact is the whole image's with those pixels made exact.
    pub by_material: Vec<MaterialBudget>,
}

/// The causes of the pixels whose splat hit is of one material.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct MaterialBudget {
    /// Material (model) index.
    pub material: u16,
    /// Every cause of [`Cause::ALL`], in that order; shares of the whole
    /// image's squared error.
    pub causes: Vec<CauseError>,
}

fn hit(f: &Frame, i: usize) -> bool {
    f.splat[i] != u32::MAX
}

/// Squared error of one pixel, radiance clamped to [0, 1], summed over
/// the channels (as `compare_frames` sums it).
fn pixel_se(a: Vec3, b: Vec3) -> f64 {
    (a.clamp(Vec3::ZERO, Vec3::ONE) - b.clamp(Vec3::ZERO, Vec3::ONE)).length_squared() as f64
}

/// Does pixel `j` differ from pixel `i` of `f` in coverage, or in depth by
/// more than `rel` of the nearer?
fn edge_between(f: &Frame, i: usize, j: usize, rel: f32) -> bool {
    match (hit(f, i), hit(f, j)) {
        (true, true) => {
            let (a, b) = (f.depth[i], f.depth[j]);
            (a - b).abs() > rel * a.min(b)
        }
        (x, y) => x != y,
    }
}

/// Pixels within Chebyshev distance `r` of pixel `i` (excluding it) of a
/// `w × h` image.
fn around(i: usize, w: usize, h: usize, r: usize) -> impl Iterator<Item = (usize, usize)> {
    let (x, y) = (i % w, i / w);
    let ys = y.saturating_sub(r)..=(y + r).min(h - 1);
    ys.flat_map(move |yy| {
        (x.saturating_sub(r)..=(x + r).min(w - 1))
            .map(move |xx| (yy * w + xx, x.abs_diff(xx).max(y.abs_diff(yy))))
    })
    .filter(move |&(j, _)| j != i)
}

/// The cause of every pixel (row-major), by the rule of the module docs.
/// `splats` and `truth` are frames of the same camera; `diagonal` is the
/// scene's.
#[must_use]
pub fn classify(splats: &Frame, truth: &Frame, diagonal: f32, tol: &Tolerances) -> Vec<Cause> {
    assert_eq!(
        (splats.width, splats.height),
        (truth.width, truth.height),
        "frames of different sizes"
    );
    let (w, h) = (splats.width as usize, splats.height as usize);
    let r = tol.silhouette_px as usize;
    (0..w * h)
        .map(|i| match (hit(splats, i), hit(truth, i)) {
            (false, false) => Cause::Background,
            (false, true) => Cause::Hole,
            (true, false) => Cause::FalseHit,
            (true, true) => {
                let edge = around(i, w, h, r).any(|(j, _)| {
                    edge_between(splats, i, j, tol.edge_depth_rel)
                        || edge_between(truth, i, j, tol.edge_depth_rel)
                });
                let shadowed = |f: &Frame| f.light_facing[i] - f.light_lit[i];
                if edge {
                    Cause::Silhouette
                } else if (splats.depth[i] - truth.depth[i]).abs() > tol.depth_rel * diagonal {
                    Cause::Depth
                } else if (splats.light_facing[i] - truth.light_facing[i]).abs() > tol.light {
                    Cause::Terminator
                } else if (shadowed(splats) - shadowed(truth)).abs() > tol.light {
                    Cause::Shadow
                } else {
                    Cause::Shading
                }
            }
        })
        .collect()
}

/// Chebyshev distance (1 to 3) from pixel `i` to the nearest pixel `f`
/// hits (`hits`) or misses, as the [`Coverage`] band it falls in.
fn tally_distance(band: &mut Coverage, f: &Frame, i: usize, hits: bool) {
    let (w, h) = (f.width as usize, f.height as usize);
    let d = around(i, w, h, 3)
        .filter(|&(j, _)| hit(f, j) == hits)
        .map(|(_, d)| d)
        .min();
    match d {
        Some(1) => band.at_1px += 1,
        Some(2 | 3) => band.at_2_3px += 1,
        _ => band.farther += 1,
    }
}

/// PSNR of a summed squared error over `pixels` pixels (three channels).
fn psnr(se: f64, pixels: usize) -> Option<f64> {
    let mse = se / (3 * pixels.max(1)) as f64;
    (mse > 0.0).then(|| 10.0 * (1.0 / mse).log10())
}

/// Squared error, pixels and the sum of normal angles (degrees) per cause.
type Sums = (
    [f64; Cause::ALL.len()],
    [usize; Cause::ALL.len()],
    [f64; Cause::ALL.len()],
);

/// The rows of [`ErrorBudget::causes`] for `sums`, shares and PSNRs taken
/// against the image's `total` squared error over `n` pixels, normal error
/// parts against the `both` pixels both frames hit.
fn rows(sums: &Sums, total: f64, n: usize, both: usize) -> Vec<CauseError> {
    let (se, pixels, angles) = sums;
    Cause::ALL
        .iter()
        .map(|&c| {
            let k = c as usize;
            CauseError {
                cause: c,
                pixels: pixels[k],
                squared_error: se[k],
                share: if total > 0.0 { se[k] / total } else { 0.0 },
                psnr_if_exact_db: psnr((total - se[k]).max(0.0), n),
                normal_deg_mean: angles[k] / pixels[k].max(1) as f64,
                normal_deg_part: angles[k] / both.max(1) as f64,
            }
        })
        .collect()
}

/// The squared error of `splats` against `truth` split by the causes of
/// [`classify`] (returned beside it); `material_of` gives each splat's
/// material for [`ErrorBudget::by_material`] (empty: no such split). The
/// normal figures compare the two frames' normals as they are: turn both
/// toward the camera first
/// ([`crate::validate::compare::orient_to_camera`]), as
/// [`crate::validate::compare::truth_errors`] does, so that their parts add
/// up to its mean normal error.
#[must_use]
pub fn error_budget(
    splats: &Frame,
    truth: &Frame,
    diagonal: f32,
    tol: &Tolerances,
    material_of: &[u16],
) -> (ErrorBudget, Vec<Cause>) {
    let causes = classify(splats, truth, diagonal, tol);
    let mut all: Sums = Default::default();
    let mut per_material: Vec<Sums> = Vec::new();
    let (mut holes, mut false_hits) = (Coverage::default(), Coverage::default());
    let mut both_hit = 0usize;
    for (i, &c) in causes.iter().enumerate() {
        let k = c as usize;
        let e = pixel_se(splats.rgb[i], truth.rgb[i]);
        let both = hit(splats, i) && hit(truth, i);
        let a = if both {
            angle_deg(splats.normal[i], truth.normal[i])
        } else {
            0.0
        };
        both_hit += usize::from(both);
        all.0[k] += e;
        all.1[k] += 1;
        all.2[k] += a;
        if let Some(&m) = material_of.get(splats.splat[i] as usize) {
            let m = m as usize;
            if per_material.len() <= m {
                per_material.resize(m + 1, Default::default());
            }
            per_material[m].0[k] += e;
            per_material[m].1[k] += 1;
            per_material[m].2[k] += a;
        }
        match c {
            Cause::Hole => tally_distance(&mut holes, truth, i, false),
            Cause::FalseHit => tally_distance(&mut false_hits, truth, i, true),
            _ => {}
        }
    }
    let n = causes.len();
    let total: f64 = all.0.iter().sum();
    let budget = ErrorBudget {
        tolerances: *tol,
        pixels: n,
        psnr_db: psnr(total, n),
        causes: rows(&all, total, n, both_hit),
        holes,
        false_hits,
        by_material: per_material
            .iter()
            .enumerate()
            .filter(|(_, s)| s.1.iter().any(|&p| p > 0))
            .map(|(m, s)| MaterialBudget {
                material: m as u16,
                causes: rows(s, total, n, both_hit),
            })
            .collect(),
    };
    (budget, causes)
}

/// The causes as a picture: on the left every pixel in its cause's colour
/// ([`Cause::colour`]: hole magenta, false hit cyan, silhouette yellow,
/// depth red, terminator orange, shadow blue, shading green, background
/// black); on the right the same colours scaled by the pixel's error (the
/// square root of its squared error over the image's largest), so the
/// pixels that cost the most are the brightest.
#[must_use]
pub fn cause_image(
    splats: &Frame,
    truth: &Frame,
    causes: &[Cause],
) -> ImageBuffer<Rgb<u8>, Vec<u8>> {
    let (w, h) = (splats.width, splats.height);
    let err: Vec<f64> = splats
        .rgb
        .iter()
        .zip(&truth.rgb)
        .map(|(&a, &b)| pixel_se(a, b).sqrt())
        .collect();
    let max = err.iter().copied().fold(0.0f64, f64::max);
    ImageBuffer::from_fn(2 * w, h, |x, y| {
        let i = (y * w + x % w) as usize;
        let c = causes[i].colour();
        if x < w {
            Rgb(c)
        } else {
            let s = if max > 0.0 { err[i] / max } else { 0.0 };
            Rgb(c.map(|v| (f64::from(v) * s).round() as u8))
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::integrator::RayCounts;

    /// A `w × h` frame of one flat grey surface at depth 1, fully lit.
    fn flat(w: u32, h: u32) -> Frame {
        let n = (w * h) as usize;
        Frame {
            width: w,
            height: h,
            rgb: vec![Vec3::splat(0.5); n],
            depth: vec![1.0; n],
            normal: vec![Vec3::Z; n],
            splat: vec![0; n],
            albedo: vec![Vec3::ONE; n],
            light_facing: vec![1.0; n],
            light_lit: vec![1.0; n],
            rays: RayCounts::default(),
            seconds: 0.0,
        }
    }

    #[test]
    fn each_cause_is_found_where_it_was_put() {
        let (w, h) = (12u32, 10u32);
        let truth = flat(w, h);
        let mut s = flat(w, h);
        let at = |x: u32, y: u32| (y * w + x) as usize;
        // A hole far inside.
        s.splat[at(2, 2)] = u32::MAX;
        s.rgb[at(2, 2)] = Vec3::ZERO;
        // Another surface (the far side) over 3 × 3 pixels, away from the
        // hole: its rim is an occlusion edge, its centre a depth error.
        for y in 1..=3 {
            for x in 7..=9 {
                s.depth[at(x, y)] = 1.5;
                s.rgb[at(x, y)] = Vec3::splat(0.1);
            }
        }
        // A light sample behind the shading normal.
        s.light_facing[at(2, 7)] = 0.8;
        s.light_lit[at(2, 7)] = 0.8;
        s.rgb[at(2, 7)] = Vec3::splat(0.4);
        // Acne: facing, but occluded.
        s.light_lit[at(5, 7)] = 0.7;
        s.rgb[at(5, 7)] = Vec3::splat(0.35);
        // A shading difference only.
        s.rgb[at(9, 7)] = Vec3::splat(0.45);
        let (b, causes) = error_budget(&s, &truth, 10.0, &Tolerances::default(), &[3]);
        assert_eq!(causes[at(2, 2)], Cause::Hole);
        assert_eq!(causes[at(8, 2)], Cause::Depth);
        assert_eq!(causes[at(2, 7)], Cause::Terminator);
        assert_eq!(causes[at(5, 7)], Cause::Shadow);
        assert_eq!(causes[at(9, 7)], Cause::Shading);
        // The hole's neighbours, and the far surface's rim and the ring
        // around it, are silhouette: 8 + 8 + 16 pixels.
        assert_eq!(causes[at(3, 3)], Cause::Silhouette);
        assert_eq!(causes[at(7, 1)], Cause::Silhouette);
        assert_eq!(causes[at(6, 0)], Cause::Silhouette);
        assert_eq!(causes[at(5, 5)], Cause::Shading);
        let by = |c: Cause| &b.causes[c as usize];
        assert_eq!(by(Cause::Hole).pixels, 1);
        assert_eq!(by(Cause::Depth).pixels, 1);
        assert_eq!(by(Cause::Silhouette).pixels, 32);
        assert_eq!(b.holes.farther, 1);
        let shares: f64 = b.causes.iter().map(|c| c.share).sum();
        assert!((shares - 1.0).abs() < 1e-12, "{b:?}");
        let pixels: usize = b.causes.iter().map(|c| c.pixels).sum();
        assert_eq!(pixels, (w * h) as usize);
        // Making the depth pixel exact leaves the others' error.
        let depth = by(Cause::Depth);
        assert!((depth.squared_error - 3.0 * 0.16).abs() < 1e-6, "{depth:?}");
        let total: f64 = b.causes.iter().map(|c| c.squared_error).sum();
        let expect = 10.0 * (3.0 * (w * h) as f64 / (total - depth.squared_error)).log10();
        assert!((depth.psnr_if_exact_db.unwrap() - expect).abs() < 1e-9);
        // Every splat is of material 3: its split is the image's but for
        // the hole (no splat hit).
        assert_eq!(b.by_material.len(), 1);
        assert_eq!(b.by_material[0].material, 3);
        let m = &b.by_material[0].causes;
        assert_eq!(m[Cause::Hole as usize].pixels, 0);
        assert_eq!(
            m[Cause::Shading as usize],
            b.causes[Cause::Shading as usize]
        );
        let img = cause_image(&s, &truth, &causes);
        assert_eq!((img.width(), img.height()), (2 * w, h));
        assert_eq!(img.get_pixel(2, 2).0, Cause::Hole.colour());
    }
}
