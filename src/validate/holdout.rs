//! Held-out points: a fixed fraction of a cloud left out of splat
//! generation, to test the finished splats against points they were not
//! grown from. `scan-check` casts lines of sight to them; the held-out
//! coverage asks whether they lie on the splats at all, which a coverage
//! measured on the points the splats were grown from cannot fail to do.

use crate::pipeline::{Generated, generate_uncoloured};
use crate::rng::SplitMix64;
use crate::splat::{LeanMode, PointCloud, SplatParams, SplatReport, count_on_splats, outliers};
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
    let keep: Vec<bool> = (0..cloud.len())
        .map(|i| !held_out(seed, i, fraction))
        .collect();
    Ok(split_kept(cloud, params, &keep))
}

/// [`split`] with the points to keep marked in `keep` (the others held
/// out), the outlier test run on `cloud`.
fn split_kept(cloud: &PointCloud, params: &SplatParams, keep: &[bool]) -> Split {
    let n = cloud.len();
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
        ..cloud.subset(keep)
    };
    let held: Vec<usize> = (0..n).filter(|&i| !keep[i]).collect();
    let test: Vec<Vec3> = held
        .iter()
        .filter(|&&i| !rejected[i])
        .map(|&i| cloud.positions[i])
        .collect();
    Split {
        train,
        held_out: held.len(),
        held_out_outliers: held.len() - test.len(),
        test,
    }
}

/// What the held-out coverage measured.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct HeldOutCoverage {
    /// The fraction of the points held out.
    pub fraction: f32,
    /// Held-out points tested (outliers left out).
    pub tested: usize,
    /// Held-out points the outlier test rejected (not tested): in windows,
    /// those of the cores that the cloud's own generation left out.
    pub outliers: usize,
    /// Tested points lying on a splat.
    pub found: usize,
    /// `found / tested`.
    pub coverage: f64,
    /// The Wilson score interval of `coverage` at 95 % ([`wilson`]): how
    /// far the share of all such points lying on a splat may be from it,
    /// given that only `tested` were tested.
    pub interval: [f64; 2],
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
    Ok(HeldOutCoverage::new(
        fraction,
        (s.test.len(), found),
        s.held_out_outliers,
        tolerance,
    ))
}

impl HeldOutCoverage {
    /// `found` of `tested` held-out points lying on a splat (a coverage of
    /// 1 with none tested), with its interval.
    fn new(fraction: f32, (tested, found): (usize, usize), outliers: usize, tolerance: f64) -> Self {
        HeldOutCoverage {
            fraction,
            tested,
            outliers,
            found,
            coverage: if tested == 0 {
                1.0
            } else {
                found as f64 / tested as f64
            },
            interval: wilson(found, tested),
            tolerance,
        }
    }
}

/// The Wilson score interval at 95 % (`z` = 1.96) of a share measured as
/// `found` of `tested`: `(p + z²/2n ± z √(p(1-p)/n + z²/4n²)) / (1 + z²/n)`
/// with `p = found / tested`, `n = tested`; `[0, 1]` with none tested.
/// Unlike `p ± z √(p(1-p)/n)` it stays within `[0, 1]` and does not
/// shrink to a point at `p = 1`: 40 of 40 gives `[0.912, 1]`.
#[must_use]
pub fn wilson(found: usize, tested: usize) -> [f64; 2] {
    if tested == 0 {
        return [0.0, 1.0];
    }
    let z2 = 1.96f64 * 1.96;
    let n = tested as f64;
    let p = found.min(tested) as f64 / n;
    let centre = p + z2 / (2.0 * n);
    let half = (z2 * (p * (1.0 - p) / n + z2 / (4.0 * n * n))).sqrt();
    let d = 1.0 + z2 / n;
    [
        ((centre - half) / d).clamp(0.0, p),
        ((centre + half) / d).clamp(p, 1.0),
    ]
}

/// The held-out points the windows' cores should hold in all: windows
/// grow (their share by [`WINDOW_GROWTH`]) until they do, so a large
/// cloud's check tests enough points to tell a coverage of 0.99 from 1
/// (five misses), as far as [`MAX_SHARE`] allows.
pub const MIN_TESTED: usize = 500;

/// The most of the cloud the windows hold in all, at every size:
/// regrowing splats from them costs about that share of generation or a
/// little more (a small window's edges look like creases), so the check
/// stays within 15 % of it. At 10 % a 5,000-point bunny sample's check
/// took 17 % of generation's instructions. A small cloud's windows stop
/// here with fewer than [`MIN_TESTED`] points tested, and the coverage
/// carries its [`wilson`] interval.
pub const MAX_SHARE: f64 = 0.08;

/// The windows' halo, in `ϵ`: a held-out point's verdict reads only the
/// splats whose discs hold it, not their normal fields (which the halo of
/// tiles, [`crate::tiled::HALO_EPS`], also covers). Measured against the
/// whole cloud's regrowth without the same held-out points, on six clouds
/// at this budget: the windows' verdicts differed from it on 2 of 1,062
/// tested points with a halo of 12 `ϵ`, 3 of 1,560 with 6, 2 of 1,619 with
/// 4 and 3 of 1,771 with 3; growth's order, not the halo, sets them apart.
/// Where the whole cloud's splats are wider on average (a sparse cloud:
/// `bunny-scan.ply`'s mean radius is 19 `ϵ`), the halo is their mean
/// radius: with 4 `ϵ` its windows tested 13 of 16 on a splat against 188
/// of 193 over the whole cloud.
pub const WINDOW_HALO_EPS: f64 = 4.0;

/// See [`MIN_TESTED`].
pub const WINDOW_GROWTH: f64 = 1.4;

/// Windows taken, each holding with its halo at least [`WINDOW_SHARE`] of
/// the cloud: in all about 6 % on a large cloud.
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
/// its outer [`WINDOW_HALO_EPS`] `ϵ` (or the whole cloud's mean splat
/// radius, if wider) are its halo (at least 2 `ϵ` of core are kept), so the splats over its core grow as they would in the whole
/// cloud. While the cores would hold fewer than [`MIN_TESTED`] held-out
/// points, the windows' share grows by [`WINDOW_GROWTH`], as far as
/// [`MAX_SHARE`] of the cloud allows (a last step to about that share
/// where the next one would pass it). Where the budget stops them, one
/// window of the budget is taken instead if its core holds over twice as
/// many points (a small or sparse cloud, whose four windows are mostly
/// halo), and where that one is over the budget too, nothing is measured
/// (an error that says so). The held-out points are the whole
/// cloud's ([`split`] with `seed`: those [`heldout_coverage`] would test),
/// less those the cloud's own generation left out as outliers (`left_out`,
/// indices into `cloud`, ascending: its statistical outliers, or lean
/// growth's outlier points), which are counted, not tested; the outlier test is not run
/// again on the windows (on the 200k bunny sample it took as long as the
/// windows' regrowth). Splats are regrown from
/// the windows' points without the held-out ones, with the whole cloud's
/// `ϵ` (`whole`: the report of the cloud's own generation; absolute, in
/// the cloud's units), and the held-out points of the windows' cores are
/// tested against them within the whole cloud's tolerance
/// ([`SplatReport::cover_tolerance`]): a window's few points measure the
/// noise less well (`bunny-scan.ply`: 1.8e-3 in its windows against
/// 4.2e-4 over the cloud).
///
/// # Errors
/// As [`split`] and [`generate_uncoloured`]; and a cloud too thin for a
/// window within the budget.
pub fn heldout_coverage_windows(
    cloud: &PointCloud,
    params: &SplatParams,
    fraction: f32,
    seed: u64,
    (whole, left_out): (&SplatReport, &[u32]),
) -> Result<(HeldOutCoverage, Windows)> {
    let epsilon = whole.epsilon;
    let n = cloud.len();
    if n == 0 || !(fraction > 0.0 && fraction <= 0.5) {
        return heldout_coverage(cloud, params, fraction, seed).map(|h| {
            let all = Windows {
                windows: 0,
                points: n,
                share: 1.0,
            };
            (h, all)
        });
    }
    let halo = (WINDOW_HALO_EPS * epsilon).max(whole.mean_radius);
    let (windows, in_window) = fit_windows(&cloud.positions, fraction, seed, (epsilon, halo))?;
    let mut keep = Vec::new();
    let (mut test, mut outliers) = (Vec::new(), 0);
    for i in (0..n).filter(|&i| in_window[i]) {
        let held = held_out(seed, i, fraction);
        keep.push(!held);
        let p = cloud.positions[i];
        if held && in_core(&windows, p) {
            if left_out.binary_search(&(i as u32)).is_ok() {
                outliers += 1;
            } else {
                test.push(p);
            }
        }
    }
    let local = cloud.subset(&in_window);
    // Grown as the whole was: by lean growth without its gate where that
    // grew the whole (a window's cut edges are no border of the surface).
    let lean = match &whole.lean {
        Some(l) if l.used && l.settled => LeanMode::AlwaysSettled,
        Some(l) if l.used && l.sharp => LeanMode::AlwaysSharp,
        Some(l) if l.used => LeanMode::Always,
        _ => LeanMode::Off,
    };
    let windowed = SplatParams {
        epsilon_abs: Some(epsilon),
        lean,
        ..params.clone()
    };
    let Generated { splats, .. } = generate_uncoloured(&local.subset(&keep), &windowed, None)?;
    let tolerance = whole.cover_tolerance();
    let found = count_on_splats(&test, &splats, tolerance as f32);
    let tested = (test.len(), found);
    Ok((
        HeldOutCoverage::new(fraction, tested, outliers, tolerance),
        Windows {
            windows: windows.len(),
            points: local.len(),
            share: local.len() as f64 / n as f64,
        },
    ))
}

/// The windows of [`heldout_coverage_windows`] for the points `pos` (with
/// `ϵ` and the halo's width), and which points they hold with their halos.
fn fit_windows(
    pos: &[Vec3],
    fraction: f32,
    seed: u64,
    (epsilon, halo): (f64, f64),
) -> Result<(Vec<Window>, Vec<bool>)> {
    use rayon::prelude::*;
    let n = pos.len();
    let halo = halo as f32;
    let min_core = 2.0 * epsilon as f32;
    let pick = |count, share| pick_windows(pos, seed, (count, share), halo, min_core);
    // Counted on the threads (each a pass over the cloud).
    let held_of = |w: &[bool]| w.par_iter().filter(|&&w| w).count();
    let cores = |w: &(Vec<Window>, Vec<bool>)| pos.par_iter().filter(|p| in_core(&w.0, **p)).count();
    let budget = (MAX_SHARE * n as f64) as usize;
    let mut share = WINDOW_SHARE;
    let mut fit = None;
    loop {
        let w = pick(WINDOWS, share);
        let held = held_of(&w.1);
        if held > budget {
            break;
        }
        if cores(&w) as f64 * f64::from(fraction) >= MIN_TESTED as f64 {
            return Ok(w);
        }
        fit = Some((share, held, w));
        share *= WINDOW_GROWTH;
    }
    let four = fit.map(|(share, held, w)| {
        // The step past the budget overshot: one to about the budget
        // (the windows' points grow about as their share).
        let last = pick(WINDOWS, share * budget as f64 / held.max(1) as f64);
        if held_of(&last.1) <= budget { last } else { w }
    });
    // A small or sparse cloud's four windows are mostly halo: one window
    // of the budget is taken where its core holds over twice as many
    // points (a window holding a share of the points holds a few more:
    // ties, and its core of at least 2 `ϵ`).
    let one = pick(1, 0.9 * MAX_SHARE);
    let held = held_of(&one.1);
    match four {
        Some(f) if held > budget || cores(&one) <= 2 * cores(&f) => Ok(f),
        _ if held <= budget => Ok(one),
        _ => Err(Error::invalid(format!(
            "no window fits the check's budget (the smallest holds {:.0} % of the \
             {n} points, over {:.0} %): --holdout-full measures it over the whole cloud",
            100.0 * held as f64 / n as f64,
            100.0 * budget as f64 / n as f64
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The interval against values worked by hand from its formula (5 of
    /// 10: 0.2366-0.7634, the textbook case), at the ends, and with none
    /// tested.
    #[test]
    fn wilson_interval() {
        let near = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).abs() < 1e-4 && (a[1] - b[1]).abs() < 1e-4;
        assert!(near(wilson(5, 10), [0.2366, 0.7634]), "{:?}", wilson(5, 10));
        assert!(near(wilson(40, 40), [0.9124, 1.0]), "{:?}", wilson(40, 40));
        assert!(near(wilson(539, 545), [0.9762, 0.9949]), "{:?}", wilson(539, 545));
        assert!(near(wilson(0, 20), [0.0, 0.1611]), "{:?}", wilson(0, 20));
        assert_eq!(wilson(0, 0), [0.0, 1.0]);
        // It narrows as more points are tested, about as 1 / sqrt(n).
        let width = |f, n| {
            let [lo, hi] = wilson(f, n);
            hi - lo
        };
        assert!(width(90, 100) > 1.8 * width(900, 1000));
        assert!(width(90, 100) < 3.5 * width(900, 1000));
    }
}
