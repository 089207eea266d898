//! Points in, splats out: the whole splat generation pipeline of §2 and §4
//! behind one call, [`generate`].

use super::denoise;
use super::field;
use super::frame::{UnitFrame, first_unusable};
use super::grow::{GrowInput, grow_all};
use super::holes::{Measured, median_radius, on_splat, uncovered_large_measured};
use super::knn::{Knn, MortonGrid, build_tree};
use super::normals;
use super::outliers;
use crate::data::Splat;
use crate::data::{FACING_AWAY_COS, PointCloud, Viewpoints, WIDENED_SHARE};
use crate::progress::{Progress, notify};
use glam::Vec3;
use kiddo::SquaredEuclidean;
use kiddo::immutable::float::kdtree::ImmutableKdTree;
use rayon::prelude::*;
use serde::Serialize;
use std::fmt;
use std::time::Instant;

/// Parameters of splat generation.
///
/// The error threshold `ϵ` of §2.1 has one name for each of its two forms,
/// from the command line to the report: `epsilon_rel` is a fraction of the
/// bounding-box diagonal (what `--epsilon` and a scene's `epsilon` give),
/// `epsilon` alone is in the cloud's units (what the reports give, what
/// growth compares against), and `epsilon_abs` sets the latter directly.
#[derive(Clone, Debug, PartialEq)]
pub struct SplatParams {
    /// Neighbours per point in the neighbourhood graph of §2 (default 12).
    pub k: usize,
    /// Error threshold `ϵ` of §2.1 as a fraction of the cloud's bounding-box
    /// diagonal (default 0.002).
    pub epsilon_rel: f32,
    /// Density factor `k ∈ (0, 1]` of §2.2 (default 0.7).
    pub density: f32,
    /// Grow elliptical splats along the minimum-curvature direction (§2.1).
    pub ellipses: bool,
    /// The largest normal-field radius, as a multiple of the splat radius
    /// (fig. 15; default 1.2). Each splat's field reads about
    /// [`field::FIELD_POINTS`] normals, so its own radius lies between
    /// [`field::MIN_FIELD_FACTOR`] and this ([`field::field_factor`]).
    /// Fixed factors, re-measured with `splatray sweep --width 160 --height
    /// 120` on the bunny (issue 24), mean normal error of Phong splats at
    /// 507, 1,445, 4,239, 10,554, 23,469 and 44,603 splats: 0.7 → 7.56,
    /// 3.63, 1.88, 1.03, 1.02, 1.15°; 1.0 → 7.95, 4.02, 2.19, 1.06, 0.83,
    /// 0.83°; 1.2 → 8.22, 4.30, 2.45, 1.27, 0.82, 0.71° (flat 9.11 …
    /// 1.63°): small factors suit the large splats of coarse budgets, large
    /// ones the few-point splats of fine budgets; per splat, 0.6 … 1.2 →
    /// 7.33, 3.57, 1.90, 0.98, 0.79, 0.71° (with the robust fit of
    /// [`field::fit_field`]; 0.6 … 1.5 → … 0.97, 0.79, 0.67°, but 1.5 radii
    /// of the largest splats, 8 `ϵ`, reach past a tile's halo).
    pub field_radius_factor: f32,
    /// Where the scanner stood: estimated normals are oriented to face it
    /// (instead of outward from the extreme point of each piece). In the
    /// cloud's frame, like its positions (relative to
    /// [`PointCloud::origin`]).
    pub viewpoint: Option<Vec3>,
    /// Without a `viewpoint`: orient each point's normal (and trim free
    /// space) toward its own scanner when the cloud holds several scans
    /// ([`PointCloud::scans`]).
    pub scan_viewpoints: bool,
    /// Leave out statistical outliers (see [`super::outliers`]).
    pub remove_outliers: bool,
    /// `ϵ` in the cloud's units, in place of `epsilon_rel` times this
    /// cloud's diagonal: the tiles of one cloud share the whole cloud's.
    pub epsilon_abs: Option<f64>,
    /// Thin the cloud to one point per cell this many `ϵ` wide where it is
    /// denser (see [`super::thin`]; default [`super::thin::CELL_EPS`]);
    /// 0 keeps every point, or thins unasked with `auto_thin`.
    pub thin: f64,
    /// With `thin` 0: thin a cloud whose typical point's cell holds
    /// [`super::thin::AUTO_POINTS_AT`] or more points, at the widest such cell
    /// of [`super::thin::AUTO_CELL_EPS`] ε, twice and four times that
    /// that `epsilon_rel` allows ([`super::thin::auto_cell`]; default on;
    /// `--thin 0` turns it off).
    pub auto_thin: bool,
    /// Fit a linear colour field to each splat of a coloured cloud
    /// ([`super::color`], by [`super::color::fit_cloud`], the step after
    /// generation; default on): texture finer than a splat is kept to
    /// first order instead of averaged away.
    pub color_fields: bool,
    /// Find creases, corners and borders while growing: each splat is
    /// clipped where its own face's points end (`grow::CREASE_DEG`,
    /// `Grower::clip_lines` in `grow.rs`). Default [`Creases::Auto`]: on,
    /// but for a cloud sampled along scan lines.
    pub creases: Creases,
    /// A tile's core, the box `[lo, hi]` in the cloud's frame: lean
    /// growth's gate samples only its points (the halo's cut edges are no
    /// border of the surface), and only they seed splats; `None`: the
    /// whole cloud.
    pub gate_within: Option<[Vec3; 2]>,
    /// Grow the splats by [`super::lean`] where its gate passes (default
    /// [`LeanMode::Gated`]; the stages where the parameters ask for what only
    /// they make, see [`SplatParams::stages_only`]).
    pub lean: LeanMode,
}

/// When generation grows by [`super::lean`] ([`SplatParams::lean`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum LeanMode {
    /// Never: the stages (`--no-lean`).
    Off,
    /// Where its gate finds the cloud clean, closed, densely sampled and
    /// without creases, and the cloud has no viewpoint (a scan's normals
    /// face its scanner: the stages'); else the stages, the report saying
    /// why.
    #[default]
    Gated,
    /// Always, the gate measured but not asked (the held-out check's
    /// windows of a cloud grown by it: their cut edges are no border of
    /// the surface).
    Always,
    /// Always, with clip lines at creases and borders (the windows of a
    /// cloud grown so).
    AlwaysSharp,
    /// Always, a scan's points settled onto their surfaces first, then
    /// with clip lines (the windows of a scan grown so).
    AlwaysSettled,
}

/// Whether generation finds creases ([`SplatParams::creases`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Creases {
    /// Whole discs everywhere (`--no-creases`, a scene's `creases = false`).
    Off,
    /// On, except in a cloud whose nearest neighbours lie along scan lines
    /// (the graph widened to join them, see [`SplatReport::k`]): there the
    /// gap between two lines looks like a border to the border test of
    /// `Grower::clip_lines`, and on the scan-line bunny
    /// (`scenes/scan-lines.toml`) creases gave 68 dark specks against 48
    /// (17 on the surface against 1), and its coarse scan (800×100 rays)
    /// 95.43 % of the held-out lines of sight meeting the rendered surface
    /// against 95.73 % (`docs/notes/creases.md`, "Issue 39: creases on by
    /// default"); a warning says when they were left off.
    #[default]
    Auto,
    /// On everywhere (`--creases`, a scene's `creases = true`).
    On,
}

impl Creases {
    /// `true` is [`Creases::On`], `false` [`Creases::Off`].
    #[must_use]
    pub fn from_bool(on: bool) -> Creases {
        if on { Creases::On } else { Creases::Off }
    }

    /// Whether creases are found in a cloud whose graph was `widened` for
    /// scan lines.
    #[must_use]
    pub fn found(self, widened: bool) -> bool {
        match self {
            Creases::Off => false,
            Creases::Auto => !widened,
            Creases::On => true,
        }
    }
}

/// Where generation takes `cloud`'s points to have been seen from, indexed
/// as its positions: the parameters' viewpoint, else (with
/// [`SplatParams::scan_viewpoints`]) each point's scanner in a cloud of
/// several scans, else none.
#[must_use]
pub fn viewpoints_of(cloud: &PointCloud, params: &SplatParams) -> Option<Viewpoints> {
    match params.viewpoint {
        Some(v) => Some(Viewpoints::One(v)),
        None if params.scan_viewpoints && cloud.scans.is_some() => cloud.viewpoints(),
        None => None,
    }
}

impl Default for SplatParams {
    fn default() -> Self {
        SplatParams {
            k: 12,
            epsilon_rel: 0.002,
            density: 0.7,
            ellipses: false,
            field_radius_factor: 1.2,
            viewpoint: None,
            scan_viewpoints: true,
            remove_outliers: true,
            epsilon_abs: None,
            thin: 0.0,
            auto_thin: true,
            color_fields: true,
            creases: Creases::Auto,
            lean: LeanMode::Gated,
            gate_within: None,
        }
    }
}

impl SplatParams {
    /// What these parameters ask for that only the stages make, so that
    /// lean growth is not tried ([`LeanMode::Gated`]): elliptical splats,
    /// creases everywhere, another `k` or density than the defaults (the
    /// stages' knobs), or thinning asked for. `None` when lean growth may
    /// grow the splats.
    #[must_use]
    pub fn stages_only(&self) -> Option<&'static str> {
        let d = SplatParams::default();
        if self.ellipses {
            Some("elliptical splats")
        } else if self.creases == Creases::On {
            Some("creases everywhere")
        } else if self.k != d.k {
            Some("another k")
        } else if self.density != d.density {
            Some("another density")
        } else if self.thin > 0.0 {
            Some("thinning")
        } else {
            None
        }
    }
}

/// Points left out, and why.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Skipped {
    /// Why they were left out.
    pub reason: String,
    /// How many.
    pub count: usize,
}

/// Wall-clock seconds per stage.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct StageSeconds {
    /// Reading the input (filled in by the caller that read it; 0 here).
    pub read: f64,
    /// Cleaning, kd-tree and k nearest neighbours.
    pub knn: f64,
    /// Normal estimation and orientation.
    pub normals: f64,
    /// Splat growth with density control.
    pub grow: f64,
    /// Normal-field fitting and the coverage check.
    pub fit: f64,
    /// Free-space trimming (`crate::pipeline`; 0 without a viewpoint).
    pub trim: f64,
    /// Colour fields (`crate::pipeline`; 0 without colours).
    pub colors: f64,
    /// All of the above (the caller adds `read`).
    pub total: f64,
}

/// Tree queries for a point's `m` nearest neighbours (`knn::Nearest`), by
/// the stage that asked: the neighbourhood graph is built once, repaired
/// (not rebuilt) where outliers leave it, and rebuilt only where scan
/// lines widen it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct NeighbourQueries {
    /// The graph's `k` nearest (`knn::Knn`).
    pub graph: usize,
    /// The normals' wide neighbourhoods (`normals::estimate_multiscale`).
    pub normals: usize,
    /// The face search's (`normals::face_normals`): none for a point
    /// settled while its normal was estimated.
    pub faces: usize,
}

/// What [`generate`] did, for people and for `--report` JSON.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SplatReport {
    /// Points in the input, including those the reader skipped.
    pub input_points: usize,
    /// Points used to grow splats.
    pub used_points: usize,
    /// Points left out (by the reader and here), with why.
    pub skipped_points: Vec<Skipped>,
    /// Splats generated.
    pub splats: usize,
    /// How many of them are elliptical.
    pub elliptical_splats: usize,
    /// How many of them carry clip lines (`splat::clip`: a splat cut at a
    /// crease or a corner).
    pub clipped: usize,
    /// Crease lines moved onto the plane of the splat across them (clip
    /// partners, `splat::partners`).
    pub partner_lines: usize,
    /// Lean growth's discs widened to close a pinhole where three discs
    /// met and none covered (`splat::lean`'s gap pass).
    pub widened_at_pinholes: usize,
    /// Whole discs cut by a clipped neighbour's plane (under strong range
    /// noise, `splat::partners`).
    pub partner_cut: usize,
    /// Flat faces fitted whole under range noise (`splat::planes`).
    pub flat_faces: usize,
    /// Points moved onto those faces.
    pub face_points: usize,
    /// Points whose neighbourhood was searched for two faces meeting at an
    /// edge (`normals::face_normals`): with creases on, those neither on a
    /// flat face nor on one smooth surface; none on a smooth cloud's.
    pub face_searches: usize,
    /// Tree queries for a point's nearest neighbours, by stage.
    pub queries: NeighbourQueries,
    /// Fraction of the used points lying on at least one splat: within `ϵ`
    /// of its plane and inside its disc.
    pub coverage: f64,
    /// Mean splat radius (mean of both radii), in the cloud's units.
    pub mean_radius: f64,
    /// The largest splat against the sampling where it lies: the most, over
    /// the splats, of its larger radius over the k-th neighbour distance of
    /// the point nearest its centre (the local spacing `d_i` of §2; a
    /// sparse far part of a scan has large splats and a large spacing
    /// alike, which a median radius would not tell).
    pub largest_over_spacing: f64,
    /// Large splats over a hole: of the splats larger than
    /// [`HOLLOW_LARGE`] times the median radius, those whose centre lies
    /// farther than half their radius from every point (issue 39's "no disc
    /// over a hole"; growth shrinks such splats, so this is 0).
    pub hollow_large_splats: usize,
    /// Large splats over a hole, by how much of them their points cover:
    /// of the splats wider than [`super::holes::UNCOVERED_LARGE`] times the median
    /// radius, those whose kept (clipped) disc is less than half covered
    /// (a sample of the disc is covered where a point lies within
    /// [`super::holes::COVER_SPACINGS`] local spacings of it; [`super::holes::uncovered_large`]).
    pub uncovered_large_splats: usize,
    /// Large splats shrunk because their points covered less than half of
    /// their disc (`splat::holes::shrink_uncovered`).
    pub shrunk_over_holes: usize,
    /// Small splats added for the points those shrunk splats left bare.
    pub added_for_holes: usize,
    /// Splats whose normal field fell back to flat (too few points or a
    /// singular fit).
    pub fallback_normal_fields: usize,
    /// Normals estimated by plane fits (all of them when the input has none;
    /// else the zero or non-finite input normals).
    pub estimated_normals: usize,
    /// The points' scatter about their local surfaces: the median over the
    /// points whose normals were estimated of the standard deviation of each
    /// one's same-facing neighbourhood about its fitted quadratic height
    /// field (range noise; see [`super::denoise`]), in the cloud's units; 0
    /// when every normal was given. Where a bound proves it below every rule
    /// that reads it, the median of a stride sample of about
    /// [`super::denoise::NOISE_SAMPLE`] points (`denoise::quiet_noise`).
    pub noise: f64,
    /// The error threshold `ϵ` used, in the cloud's units
    /// ([`SplatParams::epsilon_rel`] times the diagonal, or
    /// [`SplatParams::epsilon_abs`]).
    pub epsilon: f64,
    /// The bounding-box diagonal of the used points.
    pub bbox_diagonal: f64,
    /// The cloud's origin: splat centres are offsets from it (as the
    /// cloud's positions are), in the file's coordinates.
    pub origin: [f64; 3],
    /// Neighbours per point actually used.
    pub k: usize,
    /// With a viewpoint and estimated normals: the share of those points
    /// whose consistently oriented normal faces away from the viewpoint by
    /// more than [`FACING_AWAY_COS`]. A scanner sees only surfaces facing
    /// it, so a large share says the viewpoint is not the scanner's (a
    /// cloud registered from several scans, or a default `VIEWPOINT`).
    pub facing_away: Option<f64>,
    /// Notes about the input that did not stop generation.
    pub warnings: Vec<String>,
    /// Time per stage.
    pub seconds: StageSeconds,
    /// Where lean growth was asked for ([`SplatParams::lean`]): what its
    /// gate found and whether it grew the splats.
    pub lean: Option<LeanReport>,
}

/// What lean growth ([`super::lean`]) did. Where it grew the splats, the
/// report's figures of the stages' hole rules (`hollow_large_splats` and
/// the rest) are not measured (0), and its `noise` is the gate's scatter.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LeanReport {
    /// Whether it grew the splats (else the gate refused the cloud, and
    /// the stages grew them as without it).
    pub used: bool,
    /// Why the gate refused the cloud.
    pub refused: Option<String>,
    /// What the gate measured.
    pub gate: super::lean::Gate,
    /// Seeds left without a splat as outliers.
    pub outliers: usize,
    /// Grown with clip lines at creases and borders (where the gate found
    /// them in a clean cloud, `splat::lean`'s `sharp`).
    pub sharp: bool,
    /// Grown on a scan's points settled onto their surfaces first (a
    /// noisy scan, `splat::lean`'s `settle`).
    pub settled: bool,
}

impl SplatReport {
    /// Whether the points were moved onto their local surfaces before growth
    /// (the noise exceeded [`NOISE_PROJECT`] times `ϵ`): points not moved
    /// (held out, or the raw input) lie within that noise of the splats.
    #[must_use]
    pub fn moved_onto_surfaces(&self) -> bool {
        self.noise > NOISE_PROJECT * self.epsilon
    }

    /// How far a point may lie from a splat's plane and still count as on
    /// it: `ϵ`, plus three times the noise where the points were moved onto
    /// their local surfaces (a point as read, or held out, lies within that
    /// noise of them).
    #[must_use]
    pub fn cover_tolerance(&self) -> f64 {
        self.epsilon
            + if self.moved_onto_surfaces() {
                3.0 * self.noise
            } else {
                0.0
            }
    }
}

/// The share of the points with estimated (not `fixed`) normals that face
/// away from `viewpoint` by more than [`FACING_AWAY_COS`].
fn facing_away(points: &[Vec3], normals: &[Vec3], fixed: &[bool], viewpoint: &Viewpoints) -> f64 {
    let (mut away, mut all) = (0usize, 0usize);
    for (i, ((p, n), f)) in points.iter().zip(normals).zip(fixed).enumerate() {
        let Some(sight) = (viewpoint.at(i) - *p).try_normalize() else {
            continue;
        };
        if *f {
            continue;
        }
        all += 1;
        if n.dot(sight) < FACING_AWAY_COS {
            away += 1;
        }
    }
    if all == 0 {
        0.0
    } else {
        away as f64 / all as f64
    }
}

/// Why no splats could be made.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum GenerateError {
    /// A parameter is out of range.
    BadParams(String),
    /// Fewer distinct finite points than a plane fit needs.
    TooFewPoints {
        /// Distinct finite points.
        usable: usize,
        /// Points needed.
        needed: usize,
    },
    /// All points lie on one line: there is no surface to cover.
    Collinear,
    /// The splats do not fit single precision in the cloud's units (a
    /// centre or radius overflowed, or a radius underflowed to zero).
    OutOfRange(String),
}

impl fmt::Display for GenerateError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            GenerateError::BadParams(s) => write!(f, "bad splat parameters: {s}"),
            GenerateError::TooFewPoints { usable, needed } => write!(
                f,
                "only {usable} distinct finite points, at least {needed} are needed to fit splats"
            ),
            GenerateError::Collinear => {
                write!(
                    f,
                    "all points lie on one line: there is no surface to splat"
                )
            }
            GenerateError::OutOfRange(s) => write!(f, "{s}"),
        }
    }
}

impl std::error::Error for GenerateError {}

/// Distinct finite points, in Morton (Z-curve) order for locality, as
/// indices into the cloud; and the number of duplicates dropped.
fn clean_order(pos: &[Vec3]) -> (Vec<u32>, usize, usize) {
    let finite: Vec<u32> = (0..pos.len() as u32)
        .into_par_iter()
        .filter(|&i| pos[i as usize].is_finite())
        .collect();
    let non_finite = pos.len() - finite.len();
    if finite.is_empty() {
        return (finite, non_finite, 0);
    }
    let (lo, hi) = finite
        .par_iter()
        .map(|&i| (pos[i as usize], pos[i as usize]))
        .reduce(
            || (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
            |a, b| (a.0.min(b.0), a.1.max(b.1)),
        );
    let grid = MortonGrid::new(lo, hi);
    let bits = |i: u32| {
        let p = pos[i as usize];
        [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]
    };
    // Sorted by (Morton key, coordinate bits, index): by (key, index) first
    // (half the bytes to move), then each run of one key by bits.
    let mut keyed: Vec<(u64, u32)> = finite
        .par_iter()
        .map(|&i| (grid.key(pos[i as usize]), i))
        .collect();
    drop(finite);
    keyed.par_sort_unstable();
    let before = keyed.len();
    let mut order: Vec<u32> = Vec::with_capacity(before);
    let mut run: Vec<([u32; 3], u32)> = Vec::new();
    let mut start = 0;
    while start < keyed.len() {
        let key = keyed[start].0;
        let mut end = start + 1;
        while end < keyed.len() && keyed[end].0 == key {
            end += 1;
        }
        if end - start == 1 {
            order.push(keyed[start].1);
        } else {
            run.clear();
            run.extend(keyed[start..end].iter().map(|&(_, i)| (bits(i), i)));
            run.sort_unstable();
            // -0.0 and 0.0 differ in bits but not in position: compare values.
            run.dedup_by(|a, b| a.0.map(f32::from_bits) == b.0.map(f32::from_bits));
            order.extend(run.iter().map(|e| e.1));
        }
        start = end;
    }
    let dupes = before - order.len();
    (order, non_finite, dupes)
}

/// Turn a point cloud into splats: neighbourhoods (§2), normals, splat growth
/// (§2.1, eqs. 1–3) with density control (§2.2), and Phong normal fields
/// (§4.1–4.2, eq. 4).
///
/// Non-finite and duplicate points are skipped and counted. Input normals
/// are used (normalised) where present; zero or NaN ones are re-estimated.
/// Splat colour is the mean colour of the points a splat took, or white
/// when the cloud has no colour, so that the material alone sets the albedo.
///
/// The splats are in the cloud's frame: centres are offsets from
/// [`PointCloud::origin`] (also given as [`SplatReport::origin`]). Growth
/// runs in a unit-scale frame, so any scale works that single precision
/// can hold (`docs/DESIGN.md`, "Precision").
///
/// # Errors
/// [`GenerateError`] when the parameters are out of range, fewer than 3
/// distinct points remain, all points are collinear, or the splats do not
/// fit single precision in the cloud's units.
///
/// # Example
/// ```
/// use glam::Vec3;
/// use splatray::splat::{PointCloud, SplatParams, generate};
/// // A 60 x 60 grid on a gently curved sheet.
/// let positions: Vec<Vec3> = (0..3600)
///     .map(|i| {
///         let (x, y) = ((i % 60) as f32 / 59.0, (i / 60) as f32 / 59.0);
///         Vec3::new(x, y, 0.1 * (x * x + y * y))
///     })
///     .collect();
/// let cloud = PointCloud { positions, ..PointCloud::default() };
/// let (splats, report) = generate(&cloud, &SplatParams::default()).unwrap();
/// // Far fewer splats than points, and every point lies on one (§2.2).
/// assert!(splats.len() > 10 && splats.len() < 1000, "{}", splats.len());
/// assert_eq!(report.coverage, 1.0);
/// ```
pub fn generate(
    cloud: &PointCloud,
    params: &SplatParams,
) -> Result<(Vec<Splat>, SplatReport), GenerateError> {
    generate_with_progress(cloud, params, None)
}

/// [`generate`], reporting `(stage, fraction_done)` to `progress` now and
/// then from the calling thread (for a progress line).
///
/// # Errors
/// As [`generate`].
pub fn generate_with_progress(
    cloud: &PointCloud,
    params: &SplatParams,
    progress: Option<Progress<'_>>,
) -> Result<(Vec<Splat>, SplatReport), GenerateError> {
    generate_stages(cloud, params, progress, None).map(|(splats, report, _)| (splats, report))
}

/// What [`generate_stages`] hands its caller once the splats are grown:
/// the report as it will be in the cloud's units for every figure set by
/// then (`ϵ`, the noise, the diagonal) and the splats' mean radius, which
/// no later stage changes. A check that regrows splats with the cloud's
/// `ϵ` and tolerance (the held-out check) can start from it while the
/// fields are fitted; and the points generation left out as outliers
/// (indices into the cloud, ascending), which such a check need not test.
pub(crate) type Grown<'a> = &'a (dyn Fn(&SplatReport, &[u32]) + Sync);

/// [`generate_with_progress`], and the points it left out as statistical
/// outliers (indices into `cloud`, ascending): free-space trimming leaves
/// the same points' lines of sight out. `grown`, if given, is called once
/// the splats are grown ([`Grown`]).
pub(crate) fn generate_stages(
    cloud: &PointCloud,
    params: &SplatParams,
    progress: Option<Progress<'_>>,
    grown: Option<Grown<'_>>,
) -> Result<(Vec<Splat>, SplatReport, Vec<u32>), GenerateError> {
    let t0 = Instant::now();
    check_params(params)?;
    let raw = cloud;
    // Growth runs in a unit-scale frame (centred, divided by the diagonal),
    // so no squared distance or threshold overflows or underflows; the
    // splats and the report's lengths are mapped back at the end.
    let frame = UnitFrame::of(&cloud.positions);
    let (unit_cloud, unit_params) = to_unit(&frame, cloud, params);
    let (cloud, params) = (&unit_cloud, &unit_params);
    let mut report = start_report(cloud);
    // A scan's viewpoints turn lean growth's splats toward its scanners, as
    // they turn the stages' normals.
    let try_lean = match params.lean {
        LeanMode::Off => false,
        LeanMode::Gated => params.stages_only().is_none(),
        LeanMode::Always | LeanMode::AlwaysSharp | LeanMode::AlwaysSettled => true,
    };
    if try_lean
        && let Some(done) = lean_stages(cloud, params, &frame, &mut report, (progress, grown), t0)?
    {
        return Ok(done);
    }
    notify(progress, "neighbours", 0.0);
    let mut w = graph_stage(cloud, raw, params, &mut report)?;
    let outliers = std::mem::take(&mut w.outliers);
    let t1 = Instant::now();
    notify(progress, "normals", 0.0);
    let surface = surface_stage(w, cloud, params, &frame, &mut report);
    let t2 = Instant::now();
    let (mut splats, covered, elliptical, measured) =
        growth_stage(&surface, params, progress, &mut report);
    if let Some(grown) = grown {
        let mut whole = report.clone();
        whole.mean_radius = mean_radius(&splats);
        lengths_from_unit(&frame, &mut whole);
        grown(&whole, &outliers);
    }
    let t3 = Instant::now();
    notify(progress, "normal fields", 0.0);
    fields_stage(&mut splats, (&covered, &measured), &surface, params, &mut report);
    report.elliptical_splats = elliptical;
    // Back to the cloud's units, and nothing that single precision cannot
    // hold leaves here.
    from_unit(&frame, &mut splats, &mut report)?;
    report.origin = cloud.origin.to_array();
    let t4 = Instant::now();
    report.seconds = StageSeconds {
        read: 0.0,
        knn: (t1 - t0).as_secs_f64(),
        normals: (t2 - t1).as_secs_f64(),
        grow: (t3 - t2).as_secs_f64(),
        fit: (t4 - t3).as_secs_f64(),
        trim: 0.0,
        colors: 0.0,
        total: (t4 - t0).as_secs_f64(),
    };
    Ok((splats, report, outliers))
}

/// What [`generate_stages`] returns: the splats, the report, the outliers.
type Stages = (Vec<Splat>, SplatReport, Vec<u32>);

/// [`generate_stages`] by [`super::lean`] (`cloud` in the unit frame), where
/// its gate passes: the splats in the cloud's units, the report, and the
/// outlier seeds of a scan (none without viewpoints). `None` where the
/// gate refuses the cloud (`report` then says why, and the stages run as
/// without it).
fn lean_stages(
    cloud: &PointCloud,
    params: &SplatParams,
    frame: &UnitFrame,
    report: &mut SplatReport,
    (progress, grown): (Option<Progress<'_>>, Option<Grown<'_>>),
    t0: Instant,
) -> Result<Option<Stages>, GenerateError> {
    let points = &cloud.positions;
    let gated = params.lean == LeanMode::Gated;
    let (diagonal, spread, widened) = lean_scale(points, gated, params.epsilon_abs.is_some());
    let epsilon = match params.epsilon_abs {
        Some(e) => (e / frame.scale) as f32,
        None => (f64::from(params.epsilon_rel) * diagonal) as f32,
    };
    notify(progress, "lean growth", 0.0);
    use super::lean::GrowWhen;
    let when = match (params.lean, spread.is_some()) {
        (LeanMode::AlwaysSharp, _) => GrowWhen::AlwaysSharp,
        (LeanMode::AlwaysSettled, _) => GrowWhen::AlwaysSettled,
        (LeanMode::Always | LeanMode::Off, _) => GrowWhen::Always,
        (LeanMode::Gated, true) => GrowWhen::Never,
        // Creases off: whole discs, so no clip lines either.
        (LeanMode::Gated, false) if params.creases == Creases::Off => GrowWhen::Gated,
        (LeanMode::Gated, false) => GrowWhen::GatedSharp,
    };
    let views = viewpoints_of(cloud, params);
    let lean = super::lean::grow_lean(points, epsilon, (when, params.gate_within, views.as_ref()), |f| {
        notify(progress, "lean growth", f);
    });
    let refused = match when {
        GrowWhen::Gated => lean.gate.refusal(),
        GrowWhen::GatedSharp => lean.gate.sharp_refusal(),
        _ => None,
    };
    let refused = spread.or(refused);
    report.lean = Some(LeanReport {
        used: refused.is_none(),
        refused: refused.clone(),
        gate: lean.gate,
        outliers: lean.outliers,
        sharp: lean.sharp,
        settled: lean.settled,
    });
    if refused.is_some() {
        return Ok(None);
    }
    if let Some(wider) = widened {
        report.warnings.push(format!(
            "a few far points widen the bounding box by {:.1} %: epsilon is taken from the box of \
             all but the 0.1 % most extreme points along each axis, and lean growth left {} \
             seeds out as outliers",
            100.0 * wider,
            lean.outliers
        ));
    }
    let mut splats = lean.splats;
    report.used_points = points.len();
    report.splats = splats.len();
    report.bbox_diagonal = diagonal;
    report.epsilon = f64::from(epsilon);
    report.k = super::lean::K0;
    report.fallback_normal_fields = lean.flat_fields;
    report.clipped = lean.clipped;
    report.widened_at_pinholes = lean.widened;
    // No normal a point; the scatter the gate measured about the nearest's
    // planes (curvature in it too) stands for the noise.
    report.estimated_normals = 0;
    report.noise = f64::from(lean.gate.sigma) * f64::from(epsilon);
    report.largest_over_spacing = f64::from(lean.largest_over_spacing);
    report.facing_away = lean.facing_away;
    // A point a splat took within ϵ of its plane lies on it (inside its
    // radius); the rest are looked for on the splats.
    let unsure = &lean.unsure_points;
    let off = unsure.len() - count_on_splats(unsure, &splats, epsilon);
    report.coverage = 1.0 - off as f64 / points.len().max(1) as f64;
    report.mean_radius = mean_radius(&splats);
    if let Some(grown) = grown {
        let mut whole = report.clone();
        lengths_from_unit(frame, &mut whole);
        grown(&whole, &lean.outlier_points);
    }
    from_unit(frame, &mut splats, report)?;
    report.origin = cloud.origin.to_array();
    let [grid, grow, orient, fields] = lean.seconds;
    report.seconds = StageSeconds {
        read: 0.0,
        knn: grid,
        normals: 0.0,
        grow: grow + orient,
        fit: fields,
        trim: 0.0,
        colors: 0.0,
        total: t0.elapsed().as_secs_f64(),
    };
    Ok(Some((splats, report.clone(), lean.outlier_points)))
}

/// Lean growth's scale for `ϵ` over `points` (in the unit frame) and why
/// it must not run whatever its gate finds (`gated`): a non-finite point.
/// Where a few far points (outliers) widen the bounding box past
/// [`WIDENED_SHARE`], `ϵ` is taken from the box of all but the 0.1 % most
/// extreme points along each axis (the stages take it from the box left
/// after their outliers), and the box's widening over it is returned;
/// lean growth leaves the far points out as outlier seeds. The solids
/// scanned exactly from one station with 0.2 % stray returns (1000×750
/// rays, three seeds): 34.82 / 34.53 / 35.40 dB (mean 34.92) against the
/// stages' 35.35 / 34.12 / 34.84 (34.77), where lean growth was refused
/// before (`docs/notes/generation.md`, "Issue 54, sixty-first session").
/// Where `ϵ` is `given` (a tile's, from the plan's own trimmed box), the
/// box plays no part.
fn lean_scale(points: &[Vec3], gated: bool, given: bool) -> (f64, Option<String>, Option<f64>) {
    let diagonal = box_diagonal(points);
    if !gated {
        return (diagonal, None, None);
    }
    if !points.iter().all(|p| p.is_finite()) {
        return (diagonal, Some("non-finite coordinates".to_string()), None);
    }
    if given {
        return (diagonal, None, None);
    }
    let robust = robust_diagonal(points, &vec![true; points.len()], points.len());
    if robust < WIDENED_SHARE * diagonal && robust > 0.0 {
        (robust, None, Some(diagonal / robust - 1.0))
    } else {
        (diagonal, None, None)
    }
}

/// The first stage: the cloud (in the unit frame; `raw` as read) cleaned,
/// thinned and reordered, its neighbourhood graph, its statistical
/// outliers left out, and the bounding box's diagonal in the report.
fn graph_stage(
    cloud: &PointCloud,
    raw: &PointCloud,
    params: &SplatParams,
    report: &mut SplatReport,
) -> Result<Work, GenerateError> {
    let (order, thinned) = clean_and_thin(cloud, raw, params, report);
    let mut w = neighbours(cloud, params, order, report)?;
    w.thinned = thinned;
    if params.remove_outliers {
        drop_outliers(&mut w, report);
    }
    report.bbox_diagonal = box_diagonal(&w.points);
    Ok(w)
}

/// The diagonal of `points`' bounding box.
fn box_diagonal(points: &[Vec3]) -> f64 {
    let (lo, hi) = points.iter().fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(a, b), p| (a.min(*p), b.max(*p)),
    );
    f64::from((hi - lo).length())
}

/// The surface growth reads: points (moved onto their local surfaces
/// where noise scatters them), oriented normals, faces and creases.
struct Surface {
    points: Vec<Vec3>,
    normals: Vec<Vec3>,
    colors: Option<Vec<Vec3>>,
    /// The kd-tree over `points`.
    tree: super::knn::PointTree,
    knn: Knn,
    /// The points as read, and their tree, where denoising moved them
    /// (for `partners::meet_partners`).
    read: Option<(Vec<Vec3>, super::knn::PointTree)>,
    /// Which points lie on a flat face (for `field::fit_field`).
    flat: Vec<bool>,
    /// Which lie on a whole flat face fitted under strong noise.
    on_face: Vec<bool>,
    /// Which are settled on one face (`normals::Estimated::settled`; empty
    /// for none, and after the face search).
    settled: Vec<bool>,
    /// Strong noise (`normals::FlatFaces::Strong`).
    strong: bool,
    /// Creases searched.
    creases: bool,
    /// Seen from a scanner (a viewpoint, or each point's scanner).
    scanned: bool,
    /// `ϵ` in the unit frame.
    epsilon: f32,
    /// The width of the cells the cloud was thinned in, in the unit frame
    /// (0: not thinned; `grow::GrowInput::thinned`).
    thinned: f32,
}

/// The second stage: normals, denoising, and with creases each point's
/// own face (`normals::face_normals`) and, under strong noise, whole flat
/// faces (`splat::planes`).
fn surface_stage(
    mut w: Work,
    cloud: &PointCloud,
    params: &SplatParams,
    frame: &UnitFrame,
    report: &mut SplatReport,
) -> Surface {
    let epsilon = match params.epsilon_abs {
        Some(e) => (e / frame.scale) as f32,
        None => (f64::from(params.epsilon_rel) * report.bbox_diagonal) as f32,
    };
    report.epsilon = f64::from(epsilon);
    // The face search's least tolerance (`faces_and_creases`): points
    // whose planes hold their neighbourhoods within it are settled while
    // their normals are estimated.
    let settle = (params.creases != Creases::Off).then(|| settling(epsilon));
    let (mut nrm, fixed, to_estimate, mut settled) =
        normals_of(&mut w, cloud, params, settle, report);
    let Work {
        mut points,
        colors,
        mut tree,
        mut knn,
        sights,
        thinned,
        ..
    } = w;
    if !params.creases.found(knn.k > params.k) || to_estimate == 0 {
        // No face search: the wide rows' last reader is done.
        knn.wide = None;
    }
    // The points as read, for the check that a crease cut leaves none of
    // them off every splat (`partners::meet_partners`), kept only where
    // denoising moved them (12 bytes a point through growth).
    let before = (params.creases != Creases::Off).then(|| points.clone());
    let read = if onto_local_surfaces(&mut points, &mut nrm, &fixed, to_estimate, &knn, report) {
        // The wide rows were of the points before they moved.
        knn.wide = None;
        let read_tree = std::mem::replace(&mut tree, build_tree(&points));
        // Moved points and refitted normals: nothing is settled.
        settled = Vec::new();
        before.map(|b| (b, read_tree))
    } else {
        // Not kept through the face search (12 bytes a point).
        drop(before);
        None
    };
    let mut surface = Surface {
        points,
        normals: nrm,
        colors,
        tree,
        read,
        flat: Vec::new(),
        on_face: Vec::new(),
        settled,
        strong: false,
        creases: params.creases.found(knn.k > params.k),
        scanned: sights.is_some(),
        knn,
        epsilon,
        thinned: (thinned * f64::from(epsilon)) as f32,
    };
    if params.creases == Creases::Auto && !surface.creases {
        report.warnings.push(
            "creases not searched: the nearest neighbours lie along scan lines, whose gaps look \
             like borders (--creases searches them anyway)"
                .into(),
        );
    }
    if surface.creases && to_estimate > 0 {
        faces_and_creases(&mut surface, &fixed, sights.as_ref(), report);
    }
    // No stage after reads the wide rows.
    surface.knn.wide = None;
    surface
}

/// The settling test of the normals' estimate (`normals::Settling`), at
/// the face search's least tolerance: a quarter `ϵ`, the plane's count
/// alone, no quadric tried: where the flat-face rules are off the
/// face search is sparse (`normals::face_normals`), and the points it
/// chooses try that quadric first themselves (the same fit up to the
/// normal's sign, at a tolerance as large or larger: the same answer);
/// where they are on, no settled point is read. No output depends on it.
/// On the 200k bunny sample it spared 110,141 fits and cost 16,830 more
/// at the points the search chose (13,554 to 30,384; the same 19,618
/// plane searches; `docs/notes/generation.md`, issue 54, seventeenth
/// session).
fn settling(epsilon: f32) -> normals::Settling {
    normals::Settling::at(normals::FACE_TOL_EPS * epsilon)
}

/// With creases on: each point's normal from its own face where an edge is
/// near (`normals::face_normals`), its plane holding the points within a
/// quarter ϵ of it, or three times the noise. Where the noise sets that
/// tolerance, flat faces take their normals from their wide planes, and
/// their fields stay constant unless a gradient stands out of the noise
/// (`field::fit_field`).
fn faces_and_creases(
    s: &mut Surface,
    fixed: &[bool],
    sights: Option<&Viewpoints>,
    report: &mut SplatReport,
) {
    let by_eps = normals::FACE_TOL_EPS * s.epsilon;
    let by_noise = normals::FACE_TOL_NOISE * report.noise as f32;
    let tol = by_eps.max(by_noise);
    let faces = normals::FlatFaces::from_tolerances(by_eps, by_noise);
    s.strong = faces == normals::FlatFaces::Strong;
    let found = normals::face_normals(
        &s.points,
        &s.tree,
        &s.knn,
        &mut s.normals,
        fixed,
        tol,
        faces,
        &s.settled,
    );
    s.settled = Vec::new();
    s.knn.wide = None;
    s.flat = found.flat;
    report.face_searches = found.searched;
    report.queries.faces = found.queries;
    if s.strong {
        // Under strong noise, whole flat faces fitted, their points
        // moved onto them along their lines of sight (`splat::planes`).
        let found = super::planes::fit_faces(
            &mut s.points,
            &mut s.normals,
            fixed,
            &mut s.flat,
            &s.knn,
            super::planes::FACE_TOL * tol,
            sights,
        );
        report.flat_faces = found.faces;
        report.face_points = found.points;
        if found.points > 0 {
            s.tree = build_tree(&s.points);
        }
        s.on_face = found.on_face;
    }
}

/// The third stage: splats grown over the surface (§2.1–2.2), clipped
/// where faces end, crease lines met across, and no disc left over a hole
/// (`splat::holes`). The splats, which points they cover, how many are
/// elliptical, and the covered shares measured of the large ones.
fn growth_stage(
    s: &Surface,
    params: &SplatParams,
    progress: Option<Progress<'_>>,
    report: &mut SplatReport,
) -> (Vec<Splat>, Vec<bool>, usize, Measured) {
    let n = s.points.len();
    let input = GrowInput {
        points: &s.points,
        normals: &s.normals,
        colors: s.colors.as_deref(),
        knn: &s.knn,
        tree: &s.tree,
        // The requested k: a graph widened for scan lines is for joining
        // the lines, not for the no-holes radius.
        cover: params.k.min(s.knn.k),
        epsilon: s.epsilon,
        density: params.density,
        ellipses: params.ellipses,
        creases: s.creases,
        scanned: s.scanned,
        on_face: &s.on_face,
        thinned: s.thinned,
    };
    let grown = grow_all(&input, |i| {
        notify(progress, "growing splats", i as f64 / n as f64);
    });
    let mut splats = grown.splats;
    let mut covered = grown.covered;
    if s.creases {
        // Clip partners: crease lines onto the planes of the splats across
        // them; under strong noise, whole discs such a line crosses cut.
        let cover = report.cover_tolerance() as f32;
        let (read, read_tree) = match &s.read {
            Some((p, t)) => (&p[..], t),
            None => (&s.points[..], &s.tree),
        };
        let met = super::partners::meet_partners(
            &mut splats,
            s.epsilon,
            s.strong,
            (read, read_tree, cover),
        );
        report.partner_lines = met.moved;
        report.partner_cut = met.cut;
    }
    // No disc over a hole: large splats their points cover less than half
    // of shrunk to what they cover, the points they leave bare given
    // splats of their own (`splat::holes`).
    let (holes, measured) = super::holes::shrink_uncovered_measured(
        &mut splats,
        &mut covered,
        (&s.points, &s.normals, s.colors.as_deref()),
        &s.tree,
        &s.knn,
        s.knn.k > params.k,
        s.epsilon,
    );
    report.shrunk_over_holes = holes.shrunk;
    report.added_for_holes = holes.added;
    (splats, covered, grown.elliptical, measured)
}

/// The fourth stage: normal fields (§4.1, eq. 4) fitted, and what the
/// report measures of the splats (coverage, sizes, large splats over holes).
fn fields_stage(
    splats: &mut [Splat],
    (covered, measured): (&[bool], &Measured),
    s: &Surface,
    params: &SplatParams,
    report: &mut SplatReport,
) {
    report.fallback_normal_fields = field::fit_all(
        splats,
        params.field_radius_factor,
        &s.tree,
        &s.points,
        &s.normals,
        &s.flat,
    );
    report.coverage = coverage(&s.points, covered, splats, s.epsilon);
    report.splats = splats.len();
    report.clipped = splats.iter().filter(|s| s.is_clipped()).count();
    report.largest_over_spacing = largest_over_spacing(splats, &s.tree, &s.knn);
    report.hollow_large_splats = hollow_large(splats, &s.tree);
    report.uncovered_large_splats =
        uncovered_large_measured(splats, measured, &s.tree, &s.knn, s.knn.k > params.k);
    report.mean_radius = mean_radius(splats);
}

/// The splats' mean radius (the mean of each splat's two).
fn mean_radius(splats: &[Splat]) -> f64 {
    splats
        .iter()
        .map(|s| 0.5 * f64::from(s.radii.x + s.radii.y))
        .sum::<f64>()
        / splats.len().max(1) as f64
}

/// The cloud and parameters in the unit frame `frame` (positions,
/// viewpoints and scanners mapped; normals, colours and counts as they are).
fn to_unit(
    frame: &UnitFrame,
    cloud: &PointCloud,
    params: &SplatParams,
) -> (PointCloud, SplatParams) {
    let unit_cloud = PointCloud {
        positions: cloud.positions.par_iter().map(|&p| frame.unit(p)).collect(),
        origin: cloud.origin,
        normals: cloud.normals.clone(),
        colors: cloud.colors.clone(),
        skipped: cloud.skipped.clone(),
        viewpoint: cloud.viewpoint.map(|v| frame.unit_viewpoint(v)),
        scans: cloud.scans.as_ref().map(|s| crate::data::Scans {
            positions: s
                .positions
                .iter()
                .map(|&v| frame.unit_viewpoint(v))
                .collect(),
            of: s.of.clone(),
            misses: Vec::new(),
            misses_of: Vec::new(),
        }),
        // Free-space trimming, the one user of misses, runs in the cloud's
        // own frame.
        misses: None,
    };
    let unit_params = SplatParams {
        viewpoint: params.viewpoint.map(|v| frame.unit_viewpoint(v)),
        gate_within: params.gate_within.map(|b| b.map(|c| frame.unit(c))),
        ..params.clone()
    };
    (unit_cloud, unit_params)
}

/// A report counting the cloud's points and what its reader skipped.
fn start_report(cloud: &PointCloud) -> SplatReport {
    let mut report = SplatReport {
        input_points: cloud.positions.len() + cloud.skipped_total(),
        ..SplatReport::default()
    };
    for (reason, count) in &cloud.skipped {
        report.skipped_points.push(Skipped {
            reason: reason.clone(),
            count: *count,
        });
    }
    report
}

/// The points of the unit cloud `unit` kept, in the order growth visits
/// them: finite, not duplicates, and with `params.thin`, one per cell
/// `thin` ε wide (cells in the cloud's own units, `raw`, so tiles and the
/// whole cloud cut alike), or unasked (`params.auto_thin`) one per cell
/// of the widest of [`super::thin::AUTO_LEVELS`] widths from
/// [`super::thin::AUTO_CELL_EPS`] ε up whose typical point's cell holds
/// [`super::thin::AUTO_POINTS_AT`] or more and that `epsilon_rel` allows
/// ([`super::thin::auto_cell`]); what was left out is counted in the
/// report. With the cell's width in ε (0 where nothing was thinned).
fn clean_and_thin(
    unit: &PointCloud,
    raw: &PointCloud,
    params: &SplatParams,
    report: &mut SplatReport,
) -> (Vec<u32>, f64) {
    let (mut order, non_finite, dupes) = clean_order(&unit.positions);
    for (why, count) in [
        ("non-finite coordinates", non_finite),
        ("duplicate point", dupes),
    ] {
        if count > 0 {
            report.skipped_points.push(Skipped {
                reason: why.into(),
                count,
            });
        }
    }
    if order.len() > 3 && (params.thin > 0.0 || params.auto_thin) {
        // The kept points as a mask, made once where a pass reads them.
        let member = std::cell::OnceCell::new();
        let member = || member.get_or_init(|| super::thin::members(&order, raw.positions.len()));
        let epsilon = match params.epsilon_abs {
            Some(e) => e,
            None => {
                let diagonal = robust_diagonal(&raw.positions, member(), order.len());
                f64::from(params.epsilon_rel) * diagonal
            }
        };
        let world = |i: u32| raw.origin + raw.positions[i as usize].as_dvec3();
        let (cell, why) = if params.thin > 0.0 {
            let why = format!(
                "denser than epsilon needs: one point kept per cell {} epsilon wide",
                params.thin
            );
            (params.thin, why)
        } else {
            let finest = super::thin::AUTO_CELL_EPS * epsilon;
            let held = super::thin::typical_cell_counts(&order, member(), world, finest);
            let Some((auto, at_least)) = super::thin::auto_cell(&held, params.epsilon_rel) else {
                return (order, 0.0);
            };
            let why = format!(
                "denser than epsilon needs (a typical point's cell {auto} epsilon wide held {at_least} or more): one point kept per cell; --thin 0 keeps every point"
            );
            (auto, why)
        };
        if let Some(keep) = super::thin::keep(&order, raw.positions.len(), world, cell * epsilon) {
            let before = order.len();
            order.retain(|&i| keep[i as usize]);
            report.skipped_points.push(Skipped {
                reason: why,
                count: before - order.len(),
            });
            return (order, cell);
        }
    }
    (order, 0.0)
}

/// The kept points of the (unit) cloud with their viewpoints and colours,
/// its k-d tree and k nearest neighbours; too few points or collinear ones
/// are errors, coplanar ones and a reduced `k` warnings.
fn neighbours(
    cloud: &PointCloud,
    params: &SplatParams,
    order: Vec<u32>,
    report: &mut SplatReport,
) -> Result<Work, GenerateError> {
    let n = order.len();
    report.used_points = n;
    if n < 3 {
        return Err(GenerateError::TooFewPoints {
            usable: n,
            needed: 3,
        });
    }
    let points: Vec<Vec3> = order.iter().map(|&i| cloud.positions[i as usize]).collect();
    let sights = viewpoints_of(cloud, params).map(|v| v.pick(&order));
    let colors: Option<Vec<Vec3>> = cloud
        .colors
        .as_ref()
        .filter(|c| c.len() == cloud.positions.len())
        .map(|c| order.iter().map(|&i| c[i as usize]).collect());
    let (_, vals, _) = normals::plane_fit(points.iter().copied());
    if vals[1] <= 1e-12 * vals[2] {
        return Err(GenerateError::Collinear);
    }
    if vals[0] <= 1e-12 * vals[2] {
        report
            .warnings
            .push("all points are coplanar: normals are oriented by a convention only".into());
    }
    let k = params.k.min(n - 1);
    if k < params.k {
        report.warnings.push(format!(
            "only {n} points: using k = {k} neighbours instead of {}",
            params.k
        ));
    }
    report.k = k;
    let tree = build_tree(&points);
    // One query a point: with normals to estimate, each point's wide
    // neighbourhood (the face search's, `normals::estimate_multiscale`),
    // whose prefix is the graph's row.
    let knn = if estimates_normals(cloud, &order) {
        Knn::build_wide(&tree, &points, k, (k * normals::WIDE_FACTOR + 1).min(n))
    } else {
        Knn::build(&tree, &points, k)
    };
    report.queries.graph = knn.queries;
    Ok(Work {
        order,
        points,
        sights,
        colors,
        k,
        tree,
        knn,
        outliers: Vec::new(),
        thinned: 0.0,
    })
}

/// Whether some of `order`'s points of `cloud` have no usable normal
/// (`normals_of` estimates theirs).
fn estimates_normals(cloud: &PointCloud, order: &[u32]) -> bool {
    match &cloud.normals {
        Some(v) if v.len() == cloud.positions.len() => order
            .iter()
            .any(|&i| v[i as usize].try_normalize().is_none()),
        _ => true,
    }
}

/// Range noise beyond the growth threshold: each splat would sit at its
/// seed's noisy height (eq. 2 centres it on the span of the points it
/// took), overlapping splats at scattered depths. The points are moved
/// onto their local quadratic surfaces first, and their normals are fitted
/// again to the moved points ([`denoise::normals_after`]). Only where the
/// normals were estimated here (`fixed` marks given ones, kept as they are
/// with their points). Sets the report's noise (needs its ε) and returns
/// true when points moved.
fn onto_local_surfaces(
    points: &mut [Vec3],
    nrm: &mut [Vec3],
    fixed: &[bool],
    to_estimate: usize,
    knn: &Knn,
    report: &mut SplatReport,
) -> bool {
    if to_estimate > 0 {
        let quiet = quiet_noise(report.epsilon);
        if let Some(noise) = denoise::quiet_noise(points, nrm, knn, fixed, quiet) {
            report.noise = noise;
            return false;
        }
    }
    let local = if to_estimate > 0 {
        denoise::fit_all(points, nrm, knn)
    } else {
        Vec::new()
    };
    let local: Vec<Option<denoise::Local>> = local
        .into_iter()
        .zip(fixed)
        .map(|(l, &f)| l.filter(|_| !f))
        .collect();
    report.noise = median(local.iter().flatten().map(|l| l.sd).collect());
    if !report.moved_onto_surfaces() {
        return false;
    }
    let mut moved = 0usize;
    for ((p, n), l) in points.iter_mut().zip(nrm.iter()).zip(&local) {
        if let Some(l) = l {
            *p += *n * l.offset;
            moved += 1;
        }
    }
    let after = denoise::normals_after(points, nrm, knn);
    for ((n, m), l) in nrm.iter_mut().zip(after).zip(&local) {
        if let (Some(m), Some(_)) = (m, l) {
            *n = m;
        }
    }
    report.warnings.push(format!(
        "the points scatter {:.2}x epsilon about their local surfaces (range noise?): \
         {moved} points were moved onto them before growing splats",
        report.noise / report.epsilon
    ));
    true
}

/// Below this share of what its first reader reads it against, the noise
/// is read by no rule ([`quiet_noise`]).
pub const QUIET_MARGIN: f64 = 0.8;

/// The noise under which no output reads it, at `epsilon`, by
/// [`QUIET_MARGIN`]: the points are not moved ([`NOISE_PROJECT`]), the
/// face tolerance is `ϵ`'s ([`normals::FACE_TOL_EPS`] over
/// [`normals::FACE_TOL_NOISE`], and the flat-face rules off), and the
/// free-space margin `ϵ`'s (`freespace::MARGIN_EPS` over `MARGIN_NOISE`).
/// Below it only the report's figure reads the noise.
fn quiet_noise(epsilon: f64) -> f64 {
    let face = f64::from(normals::FACE_TOL_EPS / normals::FACE_TOL_NOISE);
    let margin = f64::from(crate::freespace::MARGIN_EPS / crate::freespace::MARGIN_NOISE);
    QUIET_MARGIN * epsilon * NOISE_PROJECT.min(face).min(margin)
}

/// The largest splat radius over the local point spacing (the k-th
/// neighbour distance of the point nearest its centre).
fn largest_over_spacing(splats: &[Splat], tree: &super::knn::PointTree, knn: &Knn) -> f64 {
    splats
        .par_iter()
        .map(|s| {
            let near = tree.nearest_one::<kiddo::SquaredEuclidean>(&s.center.to_array());
            let d = knn.kth_distance[near.item as usize];
            f64::from(s.radii.max_element()) / f64::from(d.max(f32::MIN_POSITIVE))
        })
        .reduce(|| 0.0, f64::max)
}

/// A splat counts as large for [`SplatReport::hollow_large_splats`] above
/// this many times the median radius.
pub const HOLLOW_LARGE: f32 = 10.0;

/// How many splats larger than [`HOLLOW_LARGE`] times the median radius
/// have no point within half their (larger) radius of their centre.
#[must_use]
pub fn hollow_large(splats: &[Splat], tree: &super::knn::PointTree) -> usize {
    if splats.is_empty() {
        return 0;
    }
    let median = median_radius(splats);
    splats
        .par_iter()
        .filter(|s| {
            let r = s.radii.max_element();
            r > HOLLOW_LARGE * median && {
                let near = tree.nearest_one::<kiddo::SquaredEuclidean>(&s.center.to_array());
                near.distance > (0.5 * r) * (0.5 * r)
            }
        })
        .count()
}

/// The splats and the report's lengths back in the cloud's units; a splat
/// single precision cannot hold is an error, a cloud below its normal range
/// a warning.
fn from_unit(
    frame: &UnitFrame,
    splats: &mut [Splat],
    report: &mut SplatReport,
) -> Result<(), GenerateError> {
    for s in splats.iter_mut() {
        *s = frame.splat_from_unit(s);
    }
    if let Some(why) = first_unusable(splats) {
        return Err(GenerateError::OutOfRange(format!(
            "the cloud spans {:e} units: {why}",
            frame.scale
        )));
    }
    lengths_from_unit(frame, report);
    if frame.scale < f64::from(f32::MIN_POSITIVE) {
        report.warnings.push(format!(
            "the cloud spans only {:e} units, below single precision's normal range: its positions are coarsely quantised",
            frame.scale
        ));
    }
    Ok(())
}

/// The report's lengths (`ϵ`, the noise, the diagonal, the mean radius)
/// from the unit frame `frame` to the cloud's units.
fn lengths_from_unit(frame: &UnitFrame, report: &mut SplatReport) {
    report.epsilon = frame.length_from_unit(report.epsilon);
    report.noise = frame.length_from_unit(report.noise);
    report.bbox_diagonal = frame.length_from_unit(report.bbox_diagonal);
    report.mean_radius = frame.length_from_unit(report.mean_radius);
}

/// The cleaned points in Morton order with what the stages read of them.
struct Work {
    /// Indices into the cloud.
    order: Vec<u32>,
    /// Positions in the unit frame.
    points: Vec<Vec3>,
    /// The scanner each point was seen from.
    sights: Option<Viewpoints>,
    /// Linear colours.
    colors: Option<Vec<Vec3>>,
    /// Neighbours per point.
    k: usize,
    /// The kd-tree over `points`.
    tree: super::knn::PointTree,
    /// The neighbourhood graph of §2.
    knn: Knn,
    /// The points left out as statistical outliers (indices into the
    /// cloud, ascending).
    outliers: Vec<u32>,
    /// The width in ε of the cells the cloud was thinned in (0: not
    /// thinned).
    thinned: f64,
}

/// Leaves out the statistical outliers (with their colours and scanners)
/// and counts them; the kd-tree is rebuilt without them, and the graph
/// repaired (`Knn::retain`: only the points that had one as a neighbour
/// are queried again).
fn drop_outliers(w: &mut Work, report: &mut SplatReport) {
    let n = w.points.len();
    let out = outliers::flag(&w.points, &w.knn, w.sights.as_ref());
    let count = out.iter().filter(|&&o| o).count();
    if count > 0 && n - count > w.k {
        w.outliers = w.order.iter().zip(&out).filter(|(_, o)| **o).map(|(&i, _)| i).collect();
        w.outliers.sort_unstable();
        retain_unflagged(&mut w.order, &out);
        retain_unflagged(&mut w.points, &out);
        if let Some(s) = w.sights.as_mut() {
            s.retain(&out);
        }
        if let Some(c) = w.colors.as_mut() {
            retain_unflagged(c, &out);
        }
        report.skipped_points.push(Skipped {
            reason: format!(
                "statistical outlier (k-th neighbour over {}x its neighbours' or {}x the cloud's 90th percentile)",
                outliers::LOCAL_RATIO,
                outliers::GLOBAL_RATIO
            ),
            count,
        });
        report.used_points = n - count;
        let keep: Vec<bool> = out.iter().map(|&o| !o).collect();
        w.tree = w.knn.retain_building(&keep, &w.points);
        report.queries.graph += w.knn.queries;
    }
}

/// Unit normals: given ones kept, the rest estimated at two scales and
/// oriented (§2); which are given; and how many were estimated. A cloud
/// whose nearest neighbours lie along scan lines gets a wider graph.
fn normals_of(
    w: &mut Work,
    cloud: &PointCloud,
    params: &SplatParams,
    settle: Option<normals::Settling>,
    report: &mut SplatReport,
) -> (Vec<Vec3>, Vec<bool>, usize, Vec<bool>) {
    let n = w.points.len();
    let mut settled = Vec::new();
    let input_normals: Option<Vec<Vec3>> = cloud
        .normals
        .as_ref()
        .filter(|v| v.len() == cloud.positions.len())
        .map(|v| w.order.iter().map(|&i| v[i as usize]).collect());
    let mut fixed = vec![false; n];
    let mut nrm = vec![Vec3::Z; n];
    let mut to_estimate = n;
    if let Some(inp) = &input_normals {
        to_estimate = 0;
        for i in 0..n {
            match inp[i].try_normalize() {
                Some(m) => {
                    nrm[i] = m;
                    fixed[i] = true;
                }
                None => to_estimate += 1,
            }
        }
    }
    if to_estimate > 0 {
        let normals::Estimated {
            normals: est,
            wide,
            collinear,
            degenerate,
            settled: settled_here,
            queries,
            ..
        } = normals::estimate_multiscale(&w.points, &w.tree, &w.knn, w.sights.as_ref(), settle);
        settled = settled_here;
        report.queries.normals = queries;
        if (collinear * 20 > n || wide * 5 > n) && w.k < params.k * normals::WIDE_FACTOR {
            // Anisotropic sampling (scan lines) or heavy noise: the k nearest
            // neighbours of many points lie along one line or do not reach
            // past the noise, so the neighbourhood graph would not join the
            // lines. Growth and orientation get a wider graph.
            let wider = (w.k * normals::WIDE_FACTOR).min(n - 1).min(256);
            report.warnings.push(format!(
                "the {} nearest neighbours of {:.1} % of the points lie on one line or \
                 within the noise (scan lines?): growing splats with k = {wider}",
                w.k,
                100.0 * wide.max(collinear) as f64 / n as f64
            ));
            w.k = wider;
            report.k = wider;
            // The face search's neighbourhood widens with the graph.
            settled = Vec::new();
            w.knn = w.knn.widened(wider, &w.tree, &w.points);
            report.queries.graph += w.knn.queries;
        }
        if wide * 100 > n {
            report.warnings.push(format!(
                "{wide} normals ({:.1} %) came from a {}x wider neighbourhood: the {} nearest \
                 neighbours were too noisy or lay along one scan line",
                100.0 * wide as f64 / n as f64,
                normals::WIDE_FACTOR,
                w.k
            ));
        }
        if degenerate > 0 {
            report.warnings.push(format!(
                "{degenerate} points have collinear neighbourhoods even with {} neighbours: \
                 their normals are a guess",
                normals::WIDE_MAX
            ));
        }
        // The face search (with a settling tolerance) reads the wide rows
        // of the points it does not skip only; it queries the others,
        // settled here, where noise turns its flat-face rules on.
        let searched = |i: usize| !fixed[i] && settled.get(i) != Some(&true);
        w.knn.keep_wide(|i| settle.is_some() && searched(i));
        for i in 0..n {
            if !fixed[i] {
                nrm[i] = est[i];
            }
        }
        normals::orient(&w.points, &w.knn, &mut nrm, &fixed, w.sights.as_ref());
        report.facing_away = w
            .sights
            .as_ref()
            .map(|vp| facing_away(&w.points, &nrm, &fixed, vp));
    }
    if input_normals.is_some() && to_estimate > 0 {
        report.warnings.push(format!(
            "{to_estimate} zero or non-finite input normals were re-estimated"
        ));
    }
    report.estimated_normals = to_estimate;
    (nrm, fixed, to_estimate, settled)
}

/// The diagonal of the box holding all but the 0.1 % most extreme of
/// `order`'s points along each axis: `ϵ`'s scale before outliers are known
/// (a few far outliers would widen the plain bounding box, and the cells of
/// [`super::thin`] with it). The quantiles are of the coordinates' values,
/// whatever their order, so the points are read in memory order (`member`:
/// the `n` kept points as a mask, [`super::thin::members`]) rather than
/// Morton order, whose loads miss the cache.
fn robust_diagonal(positions: &[Vec3], member: &[bool], n: usize) -> f64 {
    // One buffer an axis, filled on the calling thread (see
    // `robust_centre_size`).
    let mut axes: [Vec<f32>; 3] = std::array::from_fn(|_| Vec::with_capacity(n));
    for (p, _) in positions.iter().zip(member).filter(|e| *e.1) {
        for (v, c) in axes.iter_mut().zip(p.to_array()) {
            v.push(c);
        }
    }
    crate::data::trimmed_diagonal_of(&mut axes, f32::total_cmp, f64::from)
}

/// Keeps the items of `v` whose flag is false.
fn retain_unflagged<T>(v: &mut Vec<T>, flagged: &[bool]) {
    let mut it = flagged.iter();
    v.retain(|_| !it.next().copied().unwrap_or(false));
}

fn check_params(p: &SplatParams) -> Result<(), GenerateError> {
    let bad = |s: String| Err(GenerateError::BadParams(s));
    if p.k < 3 || p.k > 256 {
        return bad(format!("k = {} (must be 3..=256)", p.k));
    }
    if !(p.epsilon_rel > 0.0 && p.epsilon_rel < 1.0) {
        return bad(format!("epsilon = {} (must be in (0, 1))", p.epsilon_rel));
    }
    if let Some(e) = p.epsilon_abs
        && !(e.is_finite() && e > 0.0)
    {
        return bad(format!("absolute epsilon = {e} (must be finite and > 0)"));
    }
    if !(p.density > 0.0 && p.density <= 1.0) {
        return bad(format!("density = {} (must be in (0, 1])", p.density));
    }
    if !(p.thin >= 0.0 && p.thin <= 4.0) {
        return bad(format!("thin = {} (must be in [0, 4] epsilon)", p.thin));
    }
    if !(p.field_radius_factor >= 1.0 && p.field_radius_factor <= 10.0) {
        return bad(format!(
            "field radius factor = {} (must be in [1, 10])",
            p.field_radius_factor
        ));
    }
    Ok(())
}

/// Fraction of `points` lying on at least one splat. Points marked `covered`
/// were taken into a splat by growth and lie on it by construction; the
/// others are tested against every splat whose centre is near enough.
#[must_use]
pub fn coverage(points: &[Vec3], covered: &[bool], splats: &[Splat], epsilon: f32) -> f64 {
    if points.is_empty() {
        return 0.0;
    }
    let rest: Vec<usize> = (0..points.len()).filter(|&i| !covered[i]).collect();
    let found = if rest.is_empty() || splats.is_empty() {
        0
    } else {
        count_on_splats(
            rest.iter()
                .map(|&i| points[i])
                .collect::<Vec<_>>()
                .as_slice(),
            splats,
            epsilon,
        )
    };
    (points.len() - rest.len() + found) as f64 / points.len() as f64
}

/// How many of `points` lie on at least one of `splats` (see [`on_splat`]).
#[must_use]
pub fn count_on_splats(points: &[Vec3], splats: &[Splat], epsilon: f32) -> usize {
    if splats.is_empty() {
        return 0;
    }
    let centers: Vec<[f32; 3]> = splats.iter().map(|s| s.center.to_array()).collect();
    let tree: ImmutableKdTree<f32, u32, 3, 32> = ImmutableKdTree::new_from_slice(&centers);
    let reach = splats
        .iter()
        .map(|s| s.radii.x.max(s.radii.y))
        .fold(0f32, f32::max)
        + epsilon;
    points
        .par_iter()
        .with_min_len(256)
        .filter(|p| {
            tree.within_unsorted::<SquaredEuclidean>(&p.to_array(), reach * reach)
                .iter()
                .any(|nb| on_splat(&splats[nb.item as usize], **p, epsilon))
        })
        .count()
}

/// Points are moved onto their local planes before growth when the cloud's
/// noise ([`SplatReport::noise`]) exceeds this fraction of `ϵ`.
pub const NOISE_PROJECT: f64 = 0.25;

/// The median of `values` (0 for none).
fn median(mut values: Vec<f32>) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let mid = values.len() / 2;
    let (_, m, _) = values.select_nth_unstable_by(mid, f32::total_cmp);
    f64::from(*m)
}
