//! Held-out points: a fixed fraction of a cloud left out of splat
//! generation, to test the finished splats against points they were not
//! grown from. `scan-check` casts lines of sight to them; the held-out
//! coverage asks whether they lie on the splats at all, which a coverage
//! measured on the points the splats were grown from cannot fail to do.

use crate::pipeline::{Generated, generate_uncoloured};
use crate::rng::SplitMix64;
use crate::splat::{PointCloud, SplatParams, count_on_splats, outliers};
use crate::{Error, Result};
use glam::Vec3;

/// Is point `i` held out? A hash of `(seed, i)`, so the choice does not
/// depend on thread count or order.
#[must_use]
pub fn held_out(seed: u64, i: usize, fraction: f32) -> bool {
    let mut r = SplitMix64::new(seed ^ (i as u64).wrapping_mul(0xA24B_AED4_963E_E407));
    r.next_f32() < fraction
}

/// A cloud split into the points splats are grown from and the held-out
/// ones.
pub struct Split {
    /// The cloud without the held-out points (normals, colours and
    /// viewpoint kept).
    pub train: PointCloud,
    /// The held-out points the outlier test keeps (those it rejects were
    /// not seen on a surface: they are counted, not tested).
    pub test: Vec<Vec3>,
    /// Held-out points in all.
    pub held_out: usize,
    /// Held-out points the outlier test rejects.
    pub held_out_outliers: usize,
}

/// Splits `cloud`, holding out `fraction` (in `(0, 0.5]`) of its points by
/// [`held_out`] with `seed`.
///
/// # Errors
/// The fraction is out of range.
pub fn split(cloud: &PointCloud, params: &SplatParams, fraction: f32, seed: u64) -> Result<Split> {
    if !(fraction > 0.0 && fraction <= 0.5) {
        return Err(Error::invalid(format!(
            "hold-out fraction {fraction} must be in (0, 0.5]"
        )));
    }
    let n = cloud.len();
    let keep: Vec<bool> = (0..n).map(|i| !held_out(seed, i, fraction)).collect();
    let rejected = if params.remove_outliers {
        outliers::find(
            &cloud.positions,
            params.k,
            crate::splat::viewpoints_of(cloud, params).as_ref(),
        )
    } else {
        vec![false; n]
    };
    let train = PointCloud {
        skipped: cloud.skipped.clone(),
        ..cloud.subset(&keep)
    };
    let held: Vec<usize> = (0..n).filter(|&i| !keep[i]).collect();
    let test: Vec<Vec3> = held
        .iter()
        .filter(|&&i| !rejected[i])
        .map(|&i| cloud.positions[i])
        .collect();
    Ok(Split {
        train,
        held_out: held.len(),
        held_out_outliers: held.len() - test.len(),
        test,
    })
}

/// What the held-out coverage measured.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct HeldOutCoverage {
    /// The fraction of the points held out.
    pub fraction: f32,
    /// Held-out points tested (outliers left out).
    pub tested: usize,
    /// Held-out points the outlier test rejected (not tested).
    pub outliers: usize,
    /// Tested points lying on a splat.
    pub found: usize,
    /// `found / tested`.
    pub coverage: f64,
    /// How far from a splat's plane a point may lie: ϵ, plus three times
    /// the measured noise where the cloud was moved onto its local
    /// surfaces (held-out points keep their noise).
    pub tolerance: f64,
}

/// Grows splats from `cloud` without `fraction` of its points (as
/// [`generate_uncoloured`] would from all of them) and tests the held-out
/// points against them: the share lying on a splat (see
/// [`crate::splat::on_splat`]).
///
/// # Errors
/// As [`split`] and [`generate_uncoloured`].
pub fn heldout_coverage(
    cloud: &PointCloud,
    params: &SplatParams,
    fraction: f32,
    seed: u64,
) -> Result<HeldOutCoverage> {
    let s = split(cloud, params, fraction, seed)?;
    let Generated { splats, report, .. } = generate_uncoloured(&s.train, params, None)?;
    let tolerance = report.cover_tolerance();
    let found = count_on_splats(&s.test, &splats, tolerance as f32);
    Ok(HeldOutCoverage {
        fraction,
        tested: s.test.len(),
        outliers: s.held_out_outliers,
        found,
        coverage: if s.test.is_empty() {
            1.0
        } else {
            found as f64 / s.test.len() as f64
        },
        tolerance,
    })
}

/// The held-out points the windows' cores should hold in all: windows
/// grow (their share by [`WINDOW_GROWTH`]) until they do, so a cloud's
/// check tests enough points to tell a coverage of 0.99 from 1 (five
/// misses), as far as [`MAX_SHARE`] allows.
pub const MIN_TESTED: usize = 500;

/// The most of the cloud the windows hold in all, or [`MAX_POINTS`] if
/// more: regrowing splats from them costs about that share of generation
/// (a budget of 15 %), and a cloud's windows stop growing there even when
/// they test fewer points than [`MIN_TESTED`]. A cloud of under
/// `MAX_POINTS / MAX_SHARE` (about 170k) points may take more than that
/// share, at most [`MAX_POINTS`] points in all: on `milk.pcd` (12,575
/// points) 12 % of the cloud tested 39 points, not 545, for 0.13 s less
/// (coverage 1.000 against 0.989, whose interval those 39 cannot tell
/// from 0.9).
pub const MAX_SHARE: f64 = 0.12;

/// See [`MAX_SHARE`]: regrowing splats from 20,000 points takes about
/// 0.3 s on one core here.
pub const MAX_POINTS: usize = 20_000;

/// Windows holding more than this share of the cloud in all cost about
/// as much as the whole cloud: it is measured whole instead (only a cloud
/// of under `2 MAX_POINTS` points gets there).
pub const WHOLE_FROM_SHARE: f64 = 0.5;

/// See [`MIN_TESTED`].
pub const WINDOW_GROWTH: f64 = 1.4;

/// Windows taken, each holding with its halo at least [`WINDOW_SHARE`] of
/// the cloud: in all about 6 % on a large cloud, so the coverage costs
/// under 10 % of generation.
pub const WINDOWS: usize = 4;

/// See [`WINDOWS`].
pub const WINDOW_SHARE: f64 = 0.015;


/// Where the held-out coverage was measured.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Windows {
    /// Windows taken (0: the whole cloud).
    pub windows: usize,
    /// Points in them with their halos.
    pub points: usize,
    /// Their share of the cloud.
    pub share: f64,
}

/// One window: its centre, the half width of its core and of the whole
/// box (core and halo), in the cloud's units.
type Window = (Vec3, f32, f32);

/// [`WINDOWS`] boxes around points picked by `seed`, each just large
/// enough to hold `share` of the cloud, whose outer `halo` is their halo
/// (at least `min_core` of core kept); and which points they hold.
fn pick_windows(
    pos: &[Vec3],
    seed: u64,
    (count, share): (usize, f64),
    halo: f32,
    min_core: f32,
) -> (Vec<Window>, Vec<bool>) {
    use rayon::prelude::*;
    let n = pos.len();
    let mut windows: Vec<Window> = Vec::new();
    let mut in_window = vec![false; n];
    let mut rng = SplitMix64::new(seed ^ 0x0571_d0e5);
    // Every 16th point measures the reach (every point of a small cloud).
    let step = if n >= 64_000 { 16 } else { 1 };
    while windows.len() < count {
        let c = pos[(rng.next_u64() % n as u64) as usize];
        let mut d: Vec<f32> = pos
            .par_iter()
            .step_by(step)
            .map(|p| (*p - c).abs().max_element())
            .collect();
        let k = ((share * d.len() as f64) as usize).min(d.len() - 1);
        let (_, &mut reach, _) = d.select_nth_unstable_by(k, f32::total_cmp);
        let core = (reach - halo).max(min_core);
        let half = core + halo;
        in_window
            .par_iter_mut()
            .zip(pos.par_iter())
            .for_each(|(w, p)| *w |= (*p - c).abs().max_element() <= half);
        windows.push((c, core, half));
    }
    (windows, in_window)
}

/// Whether `p` lies in the core of one of `windows`.
fn in_core(windows: &[Window], p: Vec3) -> bool {
    windows
        .iter()
        .any(|(c, core, _)| (p - *c).abs().max_element() <= *core)
}

/// [`heldout_coverage`] measured in [`WINDOWS`] windows rather than over
/// the whole cloud, at every size. Each window is a box around a point
/// picked by `seed`, large enough to hold [`WINDOW_SHARE`] of the cloud;
/// its outer [`crate::tiled::HALO_EPS`] `ϵ` are its halo (at least 2 `ϵ` of
/// core are kept), so the splats over its core grow as they would in the
/// whole cloud. While the cores would hold fewer than [`MIN_TESTED`]
/// held-out points, the windows' share grows by [`WINDOW_GROWTH`], as far
/// as the budget allows ([`MAX_SHARE`] of the cloud or [`MAX_POINTS`]
/// points, the more); where they would then hold over
/// [`WHOLE_FROM_SHARE`] of the cloud (a small cloud), the coverage is
/// measured whole. Where four windows of the least share are already over
/// the budget (a thin or long cloud, whose halos are most of each window),
/// one window of the budget is taken, and where that one is over it too,
/// nothing is measured (an error that says so). Splats are regrown from
/// the windows' points without the held-out ones, with the whole cloud's
/// `epsilon` (absolute, in the cloud's units), and the held-out points of
/// the windows' cores are tested against them.
///
/// # Errors
/// As [`split`] and [`generate_uncoloured`]; and a cloud too thin for a
/// window within the budget.
pub fn heldout_coverage_windows(
    cloud: &PointCloud,
    params: &SplatParams,
    fraction: f32,
    seed: u64,
    epsilon: f64,
) -> Result<(HeldOutCoverage, Windows)> {
    let n = cloud.len();
    let pos = &cloud.positions;
    let halo = (crate::tiled::HALO_EPS * epsilon) as f32;
    let whole = || {
        heldout_coverage(cloud, params, fraction, seed).map(|h| {
            (
                h,
                Windows {
                    windows: 0,
                    points: n,
                    share: 1.0,
                },
            )
        })
    };
    if n == 0 || fraction.is_nan() || fraction <= 0.0 {
        return whole();
    }
    let budget = ((MAX_SHARE * n as f64) as usize).max(MAX_POINTS);
    let held_of = |w: &[bool]| w.iter().filter(|&&w| w).count();
    let min_core = 2.0 * epsilon as f32;
    let mut share = WINDOW_SHARE;
    let mut fits: Option<(Vec<Window>, Vec<bool>)> = None;
    loop {
        let (windows, in_window) = pick_windows(pos, seed, (WINDOWS, share), halo, min_core);
        let held = held_of(&in_window);
        if held as f64 > WHOLE_FROM_SHARE * n as f64 && held <= budget {
            return whole();
        }
        if held > budget {
            break;
        }
        let cores = pos.iter().filter(|p| in_core(&windows, **p)).count();
        fits = Some((windows, in_window));
        if cores as f64 * f64::from(fraction) >= MIN_TESTED as f64 {
            break;
        }
        share *= WINDOW_GROWTH;
    }
    let (windows, in_window) = match fits {
        Some(f) => f,
        None => {
            let one = pick_windows(pos, seed, (1, MAX_SHARE), halo, min_core);
            let held = held_of(&one.1);
            if held > budget {
                return Err(Error::invalid(format!(
                    "no window fits the check's budget (the smallest holds {:.0} % of the \
                     {n} points, over {:.0} %): --holdout-full measures it over the whole cloud",
                    100.0 * held as f64 / n as f64,
                    100.0 * budget as f64 / n as f64
                )));
            }
            one
        }
    };
    let local = cloud.subset(&in_window);
    let windowed = SplatParams {
        epsilon_abs: Some(epsilon),
        ..params.clone()
    };
    let s = split(&local, &windowed, fraction, seed)?;
    let Generated { splats, report, .. } = generate_uncoloured(&s.train, &windowed, None)?;
    let tolerance = report.cover_tolerance();
    let test: Vec<Vec3> = s
        .test
        .iter()
        .copied()
        .filter(|p| in_core(&windows, *p))
        .collect();
    let found = count_on_splats(&test, &splats, tolerance as f32);
    Ok((
        HeldOutCoverage {
            fraction,
            tested: test.len(),
            outliers: s.held_out_outliers,
            found,
            coverage: if test.is_empty() {
                1.0
            } else {
                found as f64 / test.len() as f64
            },
            tolerance,
        },
        Windows {
            windows: windows.len(),
            points: local.len(),
            share: local.len() as f64 / n as f64,
        },
    ))
}
