//! The scan as its own ground truth: every scanned point was seen from the
//! scanner, so the ray from the viewpoint to it must meet the splats at the
//! point, not before (a phantom occluder) and not after (a hole). A stated
//! fraction of the points is held out of splat generation, so nothing that
//! uses the lines of sight while making splats can fit the check.

use super::holdout;
use crate::accel::CandidateHits;
use crate::accel::registry;
use crate::freespace::{TrimReport, sight_line};
use crate::pipeline::{Generated, generate};
use crate::resolve::{Resolved, ShadingMode, resolve_within};
use crate::splat::{PointCloud, SplatParams, SplatReport};
use crate::{Error, Result};
use glam::Vec3;
use rayon::prelude::*;
use serde::Serialize;
use std::time::Instant;

/// What `scan-check` does.
#[derive(Clone, Debug, PartialEq)]
pub struct ScanCheckParams {
    /// Splat generation, as `splat` would run it (the viewpoint is set to
    /// the check's).
    pub splat: SplatParams,
    /// The scanner's position, in the cloud's frame (relative to
    /// [`PointCloud::origin`]); default: the cloud's own (PCD `VIEWPOINT`).
    pub viewpoint: Option<Vec3>,
    /// A hit within `tolerance × d` of the point's distance `d` is
    /// consistent.
    pub tolerance: f32,
    /// Fraction of the points held out of splat generation and checked.
    pub holdout: f32,
    /// Seed of the hold-out choice.
    pub seed: u64,
}

impl Default for ScanCheckParams {
    fn default() -> Self {
        ScanCheckParams {
            splat: SplatParams::default(),
            viewpoint: None,
            tolerance: 0.01,
            holdout: 0.1,
            seed: 1,
        }
    }
}

/// Counts and fractions of the checked lines of sight.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ScanCheckReport {
    /// Points in the cloud.
    pub points: usize,
    /// Points held out of generation.
    pub held_out: usize,
    /// Held-out points the generator's outlier test rejects (on the whole
    /// cloud): not checked, since no surface was seen there.
    pub held_out_outliers: usize,
    /// Rays cast: one per held-out point that is not an outlier.
    pub rays: usize,
    /// `|t - d| <= tolerance·d`.
    pub consistent: usize,
    /// `t < d - tolerance·d`: something stands in front of a point the
    /// scanner saw.
    pub early: usize,
    /// `t < 0.9 d` (a subset of `early`).
    pub gross_early: usize,
    /// `t > d + tolerance·d`: the ray passes the point through a hole.
    pub late: usize,
    /// No splat at all on the ray.
    pub miss: usize,
    /// Of `miss`, the held-out points on a rim of the scanned surface (a
    /// silhouette, the capture's edge; [`at_rim`]): a row past the border
    /// the other points leave, which an edge clipped at the last point it
    /// was grown from leaves open and a whole disc overhangs. The others
    /// are holes inside the scanned surface.
    pub miss_at_rim: usize,
    /// `consistent / rays`.
    pub consistent_fraction: f64,
    /// `early / rays`.
    pub early_fraction: f64,
    /// `gross_early / rays`.
    pub gross_early_fraction: f64,
    /// `late / rays`.
    pub late_fraction: f64,
    /// `miss / rays`.
    pub miss_fraction: f64,
    /// The tolerance used.
    pub tolerance: f64,
    /// The viewpoint used, in the cloud file's coordinates.
    pub viewpoint: [f64; 3],
    /// Splats made from the points not held out.
    pub splats: usize,
    /// Median splat radius (the larger radius of each splat).
    pub median_radius: f64,
    /// Largest splat radius.
    pub max_radius: f64,
    /// `max_radius / median_radius`.
    pub max_over_median_radius: f64,
    /// The generation report.
    pub generation: SplatReport,
    /// What free-space trimming did (on the points not held out).
    pub trim: Option<TrimReport>,
    /// False when too many points face away from the viewpoint
    /// ([`crate::data::FACING_AWAY_MAX`]): it is not the scanner's
    /// position, points behind real surfaces are counted early, and the
    /// lines of sight check nothing.
    pub viewpoint_is_scanner: bool,
    /// The same lines of sight against the surface a render shows (the
    /// resolved hit of §3.2 within the model's blending window, as the
    /// depth AOV gives it) instead of the nearest splat: the nearest of
    /// several overlapping splats whose planes noise has scattered stands
    /// in front of the surface they make together.
    pub surface: SurfaceCounts,
    /// Seconds to generate the splats.
    pub splat_seconds: f64,
    /// Seconds to cast the rays (including the backend build).
    pub check_seconds: f64,
}

/// The lines of sight judged against the resolved surface
/// ([`ScanCheckReport::surface`]).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SurfaceCounts {
    /// The blending window the surface is resolved within (the renderer's
    /// for these splats: [`crate::scene::load::XI_STANDOFFS`] standoffs).
    pub window: f64,
    /// `|t - d| <= tolerance·d`, as a fraction of the rays.
    pub consistent_fraction: f64,
    /// `t < d - tolerance·d`.
    pub early_fraction: f64,
    /// `t > d + tolerance·d`.
    pub late_fraction: f64,
}

/// Runs the check on `cloud`.
///
/// # Errors
/// No viewpoint, parameters out of range, too few points, or a backend
/// that cannot be built.
pub fn scan_check(
    cloud: &PointCloud,
    params: &ScanCheckParams,
    progress: Option<crate::progress::Progress<'_>>,
) -> Result<ScanCheckReport> {
    if let Some(s) = &cloud.scans {
        return Err(Error::invalid(format!(
            "the cloud holds {} scans taken from different places; scan-check casts rays from one \
             scanner: check each scan on its own",
            s.positions.len()
        )));
    }
    let vp = params.viewpoint.or(cloud.viewpoint).ok_or_else(|| {
        Error::invalid(
            "the cloud has no viewpoint (no PCD VIEWPOINT): give the scanner's position with --viewpoint X,Y,Z",
        )
    })?;
    if !vp.is_finite() {
        return Err(Error::invalid("the viewpoint must be finite"));
    }
    if !(params.tolerance > 0.0 && params.tolerance < 1.0) {
        return Err(Error::invalid(format!(
            "tolerance {} must be in (0, 1)",
            params.tolerance
        )));
    }
    let sp = SplatParams {
        viewpoint: Some(vp),
        ..params.splat.clone()
    };
    // Held-out points the generator would reject as outliers were not seen
    // on a surface: they are counted, not checked.
    let split = holdout::split(cloud, &sp, params.holdout, params.seed)?;
    let (mut train, test, held_out_outliers) = (split.train, split.test, split.held_out_outliers);
    train.viewpoint = Some(vp);
    let held_len = split.held_out;
    let t0 = Instant::now();
    let Generated {
        splats,
        report: generation,
        trim,
        ..
    } = generate(&train, &sp, progress)?;
    let t1 = Instant::now();
    let info = &registry::renderers()[0];
    let backend = info.build_splats(&splats)?;
    let tol = params.tolerance;
    let window = crate::scene::load::XI_STANDOFFS * crate::splat::standoff::standoff(&splats);
    // (consistent, early, gross_early, late, miss; and of the resolved
    // surface: consistent, early, late)
    let classes: Vec<[usize; 8]> = test
        .par_iter()
        .with_min_len(512)
        .map_init(
            || CandidateHits::new(window),
            |hits, &p| {
                let mut c = [0usize; 8];
                let Some((ray, d)) = sight_line(vp, p) else {
                    return c;
                };
                backend.intersect(&ray, 0.0, f32::INFINITY, hits);
                let surface = resolve_within(hits, &ray, &splats, ShadingMode::Flat, window)
                    .and_then(Resolved::hit);
                match surface {
                    Some(h) if h.t < d - tol * d => c[6] = 1,
                    Some(h) if h.t > d + tol * d => c[7] = 1,
                    Some(_) => c[5] = 1,
                    None => {}
                }
                match hits.nearest() {
                    None => c[4] = 1,
                    Some(h) if h.t < d - tol * d => {
                        c[1] = 1;
                        if h.t < 0.9 * d {
                            c[2] = 1;
                        }
                    }
                    Some(h) if h.t > d + tol * d => c[3] = 1,
                    Some(_) => c[0] = 1,
                }
                c
            },
        )
        .collect();
    let counts = classes.iter().fold([0usize; 8], |a, b| std::array::from_fn(|k| a[k] + b[k]));
    let missed: Vec<Vec3> = (test.iter().zip(&classes))
        .filter(|(_, c)| c[4] == 1)
        .map(|(&p, _)| p)
        .collect();
    let miss_at_rim = rim_count(&cloud.positions, &missed);
    let t2 = Instant::now();
    let mut radii: Vec<f32> = splats.iter().map(|s| s.radii.max_element()).collect();
    let (median_radius, max_radius) = if radii.is_empty() {
        (0.0, 0.0)
    } else {
        let mid = radii.len() / 2;
        let m = *radii.select_nth_unstable_by(mid, f32::total_cmp).1;
        (
            f64::from(m),
            f64::from(radii.iter().copied().fold(0f32, f32::max)),
        )
    };
    let rays = test.len();
    let frac = |k: usize| counts[k] as f64 / rays.max(1) as f64;
    Ok(ScanCheckReport {
        points: cloud.len(),
        held_out: held_len,
        held_out_outliers,
        rays,
        consistent: counts[0],
        early: counts[1],
        gross_early: counts[2],
        late: counts[3],
        miss: counts[4],
        miss_at_rim,
        consistent_fraction: frac(0),
        early_fraction: frac(1),
        gross_early_fraction: frac(2),
        late_fraction: frac(3),
        miss_fraction: frac(4),
        tolerance: f64::from(tol),
        viewpoint: (cloud.origin + vp.as_dvec3()).to_array(),
        splats: splats.len(),
        median_radius,
        max_radius,
        max_over_median_radius: max_radius / median_radius.max(f64::MIN_POSITIVE),
        viewpoint_is_scanner: generation
            .facing_away
            .is_none_or(|a| a <= crate::data::FACING_AWAY_MAX),
        surface: SurfaceCounts {
            window: f64::from(window),
            consistent_fraction: frac(5),
            early_fraction: frac(6),
            late_fraction: frac(7),
        },
        generation,
        trim,
        splat_seconds: (t1 - t0).as_secs_f64(),
        check_seconds: (t2 - t1).as_secs_f64(),
    })
}

/// Neighbours (in the whole cloud) whose directions [`at_rim`] reads.
pub const RIM_NEIGHBOURS: usize = 24;

/// A point lies on a rim of the scanned surface (a silhouette, the
/// capture's edge) where its [`RIM_NEIGHBOURS`] nearest,
/// seen in their plane, leave a gap of at least this many degrees round it
/// (a point on a straight border 180°, inside a surface about 30-60°):
/// 4.1 % of `milk.pcd`'s points (the median gap 38°, the 95th percentile
/// 96°); of the held-out points its splats missed over seeds 1-30, 35 of
/// 48 with creases and 22 of 31 with whole discs.
pub const RIM_GAP_DEG: f32 = 120.0;

/// How many of `missed` lie on the rim of `points` ([`at_rim`]); no tree
/// is built when none was missed.
fn rim_count(points: &[Vec3], missed: &[Vec3]) -> usize {
    if missed.is_empty() {
        return 0;
    }
    let finite: Vec<Vec3> = points.iter().copied().filter(|p| p.is_finite()).collect();
    let tree = crate::splat::knn::build_tree(&finite);
    missed
        .par_iter()
        .filter(|&&p| {
            let near: Vec<Vec3> = tree
                .nearest_n::<kiddo::SquaredEuclidean>(&p.to_array(), std::num::NonZero::new(RIM_NEIGHBOURS + 1).unwrap_or(std::num::NonZero::<usize>::MIN))
                .iter()
                .map(|nb| finite[nb.item as usize])
                .filter(|&q| q != p)
                .take(RIM_NEIGHBOURS)
                .collect();
            at_rim(p, &near)
        })
        .count()
}

/// Whether `p` lies on the rim of the surface its neighbours `near` sample:
/// their directions from `p`, in the plane fitted to them, leave a gap of
/// at least [`RIM_GAP_DEG`]. Too few neighbours to span a plane: on the rim.
#[must_use]
pub fn at_rim(p: Vec3, near: &[Vec3]) -> bool {
    if near.len() < 3 {
        return true;
    }
    let (_, vals, vecs) = crate::splat::fit::plane_fit(near.iter().copied());
    // NaN eigenvalues span no plane either.
    if vals[1].partial_cmp(&(crate::splat::fit::COLLINEAR * vals[2])) != Some(std::cmp::Ordering::Greater) {
        return true;
    }
    let Some(n) = vecs[0].try_normalize() else {
        return true;
    };
    let (a, b) = n.any_orthonormal_pair();
    let (a, b) = (a.as_vec3(), b.as_vec3());
    let mut angles: Vec<f32> = near.iter().map(|&q| (q - p).dot(b).atan2((q - p).dot(a))).collect();
    angles.sort_unstable_by(f32::total_cmp);
    let wrap = angles[0] + std::f32::consts::TAU - angles[angles.len() - 1];
    let widest = angles.windows(2).map(|w| w[1] - w[0]).fold(wrap, f32::max);
    widest >= RIM_GAP_DEG.to_radians()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A jittered square lattice off the origin (as a cloud re-centred on
    /// its medians lies), tilted: a point in its middle is inside, one on
    /// an edge or a corner on its rim; the middle one with half the
    /// lattice cut away is on it, with a quarter cut away (a gap of 90°)
    /// not.
    #[test]
    fn a_point_is_on_the_rim_where_its_neighbours_leave_a_wide_gap() {
        let base = Vec3::new(30.0, -20.0, 5.0);
        let (u, v) = (Vec3::new(0.8, 0.0, 0.6), Vec3::Y);
        let mut rng = crate::rng::SplitMix64::new(3);
        let at = |i: i32, j: i32, rng: &mut crate::rng::SplitMix64| {
            base + u * (i as f32 + 0.2 * rng.next_f32()) * 0.01 + v * (j as f32 + 0.2 * rng.next_f32()) * 0.01
        };
        let grid: Vec<(i32, i32, Vec3)> = (0..21)
            .flat_map(|i| (0..21).map(move |j| (i, j)))
            .map(|(i, j)| (i, j, at(i, j, &mut rng)))
            .collect();
        let near = |p: Vec3, keep: &dyn Fn(i32, i32) -> bool| -> Vec<Vec3> {
            let mut all: Vec<Vec3> = grid.iter().filter(|&&(i, j, q)| keep(i, j) && q != p).map(|g| g.2).collect();
            all.sort_by(|a, b| (*a - p).length_squared().total_cmp(&(*b - p).length_squared()));
            all.truncate(RIM_NEIGHBOURS);
            all
        };
        let point = |i: i32, j: i32| grid.iter().find(|g| g.0 == i && g.1 == j).unwrap().2;
        let all = |_: i32, _: i32| true;
        assert!(!at_rim(point(10, 10), &near(point(10, 10), &all)));
        assert!(at_rim(point(0, 10), &near(point(0, 10), &all)));
        assert!(at_rim(point(20, 20), &near(point(20, 20), &all)));
        // A quarter cut away round (10, 10): 90° open, under the bound.
        let quarter = |i: i32, j: i32| !(i > 10 && j > 10);
        assert!(!at_rim(point(10, 10), &near(point(10, 10), &quarter)));
        // A half cut away: 180°.
        let half = |i: i32, _: i32| i <= 10;
        assert!(at_rim(point(10, 10), &near(point(10, 10), &half)));
        // Too few to span a plane.
        assert!(at_rim(point(10, 10), &[point(11, 10), point(12, 10)]));
    }
}
