//! Lean growth: splats grown seed by seed over a uniform grid of the
//! points, with no normal a point (issue 54).
//!
//! The pipeline's growth (§2.1–2.2, eqs. 1–3) reads a normal at every point,
//! each fitted to its own neighbourhood, and the normal fields (eq. 4) fit
//! those normals again. On a clean cloud sampled densely enough, one plane
//! fit a splat does the same work: a seed's plane is fitted to its
//! [`K0`] nearest points, the splat takes its neighbours in order of
//! distance while they stay within [`GROW_EPS`] `ϵ` of that plane (refitted
//! to the points taken each time their count doubles), and every point it
//! takes is covered, so it seeds no splat of its own. The splat lies in its
//! points' least-squares plane (centred where the seed projects onto it);
//! its radius reaches the first point it did not take, grown by [`SCALE`]
//! so that neighbouring discs overlap. Its normal field (eq. 4) comes from
//! a quadric height field fitted to the heights of its points and of those
//! within [`REACH`] radii: the field's slopes are the quadric's curvatures
//! along its principal directions, which become the splat's axes.
//! Orientation follows a spanning tree over overlapping splats, most
//! parallel first (Prim), from the splat farthest from the centroid facing
//! away from it. Where three discs still leave a pinhole between them, the
//! third is widened over it before the fields ([`gaps`]: 15 pinholes of
//! the default scene to 4, 38.54 to 39.09 dB). Slabs of [`SLAB_POINTS`] of
//! the grid's order grow at once, each seeding from its own points only,
//! so the splats are the same for any number of threads.
//!
//! It has none of the pipeline's rules for noise, outliers, thin sheets,
//! creases or real scans, so it runs only where its [`Gate`] finds a cloud
//! it serves: measured on a stride sample of the points before anything is
//! grown, the median scatter of a point's nearest about their plane at
//! most [`GATE_SIGMA`] `ϵ`, at most [`GATE_HARD`] of the points with a
//! neighbour outside the [`GROW_EPS`] slab, and at most [`GATE_HARD_EPS`]
//! with one outside the `ϵ` slab, at most [`GATE_CREASE`] across a crease,
//! at most [`GATE_BORDER`] at a border. Against the mesh, 200k points
//! sampled from the bunny rendered 0.09 dB under the stages' splats on
//! average (-1.12 to +1.29 dB a view) at a fifth of the time and less than
//! half the memory, 1M points 1.2-2.9 dB over them; 140k points and
//! sparser, noisy samples are refused (`docs/notes/generation.md`, "Issue
//! 54, fifty-sixth session"). A cloud refused only for its creases and
//! borders (exact samples of a solid, an airborne survey) grows with clip
//! lines there ([`sharp`]; "fifty-eighth" and "fifty-ninth session"). A
//! dense scan too noisy for that has its points settled onto their
//! surfaces first ([`settle`]; "sixty-fifth session").

mod gaps;
mod settle;
mod sharp;

use super::fit::{height_axes, height_rows, normal_equations, plane_fit, solve6};
use super::grow::MAX_RADIUS_EPS;
use crate::data::{FACING_AWAY_COS, FACING_AWAY_MAX, NormalField, Splat, Viewpoints};
use crate::splat::clip::{Clip, ClipLine};
use glam::{DVec3, Vec2, Vec3};
use rayon::prelude::*;
use std::collections::BinaryHeap;

/// Points of a seed's first plane fit besides the seed.
pub const K0: usize = 12;

/// Half-width of the slab a splat's points stay in, in `ϵ`.
pub const GROW_EPS: f32 = 0.25;

/// A splat's radius over the distance of the first point it did not take.
pub const SCALE: f32 = 1.1;

/// How far the field's quadric reaches, in splat radii.
pub const REACH: f32 = 1.3;

/// Grid cell width in `ϵ`.
pub const CELL_EPS: f32 = 2.0;

/// Most shells of cells a seed's neighbours are gathered from.
const MAX_SHELL: i32 = 8;

/// Fewest points a quadric is fitted to (else the field is flat).
const FIELD_MIN: usize = 12;

/// A seed whose [`K0`]-th neighbour lies farther than this many times the
/// sample's median grows no splat (an outlier): its points seed their own.
const OUTLIER_SPACINGS: f32 = 4.0;

/// A seed farther than this many times the median distance of a point's
/// [`K0`]-th neighbour off the plane of its own [`K0`] nearest (fitted
/// without it) grows no splat (an outlier, [`Lean::outliers`]); a seed at
/// a corner lies at most about one such distance off. The solids scanned
/// exactly from one station (1000×750 rays; the median 1.75 `ϵ`) with 87
/// stray returns inside the box (0.5-1.5 times their ray's range) grew 10
/// splats centred 4.1-6.6 `ϵ` from every return, whose lines of sight
/// trimming then cut the surface for (1,302 lines blocked); with the rule
/// none and 241 lines (34.60 -> 34.63 dB, normal error 0.393° -> 0.367°,
/// against the mesh from the scanner's eye). On exact samples (the scan,
/// the 300k and 60k solids, the 200k bunny, the default survey) it leaves
/// out no seed: the same bytes (`docs/notes/generation.md`, "Issue 54,
/// sixty-first session").
pub const SEED_OFF_SPACINGS: f32 = 2.0;

/// Points the gate samples (every `n / GATE_SAMPLE`-th).
pub const GATE_SAMPLE: usize = 4096;

/// Points sampled where lean growth grows whatever the gate finds
/// ([`GrowWhen::Always`]): enough for the median spacing.
const ALWAYS_SAMPLE: usize = 512;

/// The gate's bound on the median scatter of a sampled point's nearest
/// about their plane, in `ϵ`, where lean growth's quality crosses the
/// stages' (`scripts/lean_quality.py`, twelve views against the mesh):
/// 0.028-0.029 on 200k bunny samples (+0.81 dB over the stages), 0.039 at
/// 140k (+0.44), 0.043-0.045 at 120k (+0.14), 0.047-0.048 at 110k
/// (-0.16), 0.050 at 100k (-0.27); 0.14 and 0.26 under noise of 0.16 and
/// 0.31 `ϵ`, 0.041 on the default survey's tile, 0.170 on the noisy scan
/// (at its robust box's `ϵ`; 0.105 at its whole box's, 1.6 times wider).
///
/// Sharp lean growth ([`sharp`]) takes the same bound, but for a scan with
/// creases ([`SCAN_SHARP_SIGMA`]). Its quality
/// crosses the stages' near 0.06 on surveys (`splatray terrain --noise`,
/// 800×600 against the truth: +0.26 to +1.6 dB at 0.015-0.054 over
/// seeds and noise, +0.75 to +2.3 on the other scan patterns at 0.042,
/// -0.2 and +0.16 at 0.067, -1.0 at 0.092) and near 0.045 on the solids'
/// noisy samples (mean of five views: +0.65 at 0.013, +2.26 at 0.025,
/// +0.44 at 0.031, -0.02 at 0.037, +0.04 at 0.044; before
/// `sharp::stop_line` +0.23, +2.0, -0.07, -0.50, -0.45).
pub const GATE_SIGMA: f32 = 0.046;

/// [`GATE_SIGMA`] for sharp lean growth on a scan (its scanners known)
/// with creases ([`GATE_CREASE`]): flat faces met at creases, trimmed and
/// faced by their lines of sight.
/// The stages dip below their flat-face rules' switch there (3 times the
/// noise at `ϵ/4`), where lean growth does not: the solids scanned from
/// one station (1000×750 rays, 400×300 against the mesh, seeds 1-3) with
/// range noise of 0.12, 0.15, 0.18 and 0.2 spacings (scatter 0.041,
/// 0.051, 0.062, 0.069) read 35.91, 35.37, 34.52 and 34.46 dB grown sharp
/// and lean against the stages' 34.90, 34.58, 34.05 and 33.49; with 400×300
/// rays (200×150) at 0.05 and 0.07 spacings (0.045, 0.063) 32.51 and 32.51
/// against 31.38 and 31.39. At 0.22 spacings (0.074) the stages' flat-face
/// rules are on and lead by a decibel, so the bound stays under 0.069,
/// leaving 0.2 spacings to the stages. A curved scan without creases (its
/// silhouettes are borders) keeps [`GATE_SIGMA`]: the bunny scanned with
/// range noise of 0.1 spacings (scatter 0.057, creases 0.2 %) read 35.56
/// dB lean against the stages' 35.78 (`docs/notes/generation.md`, "Issue
/// 54, sixty-second session").
pub const SCAN_SHARP_SIGMA: f32 = 0.065;

/// The scatter past which a scan with creases ([`GATE_CREASE`]) dense
/// enough to be settled ([`settle::SETTLE_SPARSE`]) is settled before
/// sharp lean growth rather than grown sharp from its points as they lie
/// (below [`SCAN_SHARP_SIGMA`] both serve it). The solids scanned from one
/// station (1000×750 rays, `compare --truth` at 400×300, seeds 1-6) with
/// range noise of 0.15 and 0.18 spacings (scatter 0.051 and 0.062) read
/// 35.50 and 35.38 dB settled against 35.30 and 35.03 grown sharp
/// (+0.20, +0.35; no seed lost more than 0.03), at 0.12 spacings (0.041)
/// the same, for 1.68 and 1.66 times the time (0.144 against 0.084 s on
/// 103,721 points) and 9 MiB more (`docs/notes/generation.md`, "Issue 54,
/// sixty-seventh session").
pub const SCAN_SETTLE_SIGMA: f32 = 0.05;

/// The gate's bound on the share of points with a neighbour outside the
/// [`GROW_EPS`] slab, where quality crosses as for [`GATE_SIGMA`]:
/// 3.4-4.2 % of the 200k bunny samples', 6.9 % at 140k, 8.6-9.4 % at 120k,
/// 10.1-10.7 % at 110k, 11.4 % at 100k.
pub const GATE_HARD: f32 = 0.097;

/// The gate's bound on the share with a neighbour outside the `ϵ` slab:
/// at most 0.02 % on the clean 200k bunny samples, 0.17 % on the solids,
/// 0.93 % on a cube's surface (3 `ϵ` spacing), 2.6 % on a survey tile.
pub const GATE_HARD_EPS: f32 = 0.005;

/// A point's nearest straddle a crease where their scatter about their
/// plane exceeds this share of the [`K0`]-th one's distance: curvature
/// gives a scatter growing with the square of that distance, a crease with
/// the distance itself. Over the 200k bunny's sample 0.3 % of the points
/// (its 99.9th percentile 0.15), the 1M's 0.05 %, the solids' about 3 %.
pub const CREASE_SCATTER: f32 = 0.12;

/// A sampled point's nearest lie along a line where the second eigenvalue
/// of their covariance is under this share of the largest (a disc's
/// nearest about 1/1; a line's 0).
pub const LINE_SPREAD: f64 = 0.02;

/// The gate's bound on the share of points whose nearest lie along a line
/// ([`LINE_SPREAD`]): growth needs a plane a seed.
pub const GATE_LINE: f32 = 0.01;

/// The gate's bound on the share of points across a crease
/// ([`CREASE_SCATTER`]).
pub const GATE_CREASE: f32 = 0.01;

/// The gate's bound on the share of points at a border: a seed at an open
/// edge grows its disc past the edge (the pipeline's growth encloses its
/// points instead).
pub const GATE_BORDER: f32 = 0.002;

/// Neighbours the border test reads.
pub const GATE_RING: usize = 48;

/// A point is at a border where its [`GATE_RING`] nearest's centroid lies
/// this many times the farthest one's distance off it, in their plane: a
/// half disc's lies 0.42 off, a whole disc's about 0.1 at most by chance.
const BORDER_OFFSET: f32 = 0.3;

/// What the gate measured.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Gate {
    /// Points sampled.
    pub sampled: usize,
    /// Taken from a cloud with its scanners' positions (a scan's, or a
    /// viewpoint given): sharp lean growth takes [`SCAN_SHARP_SIGMA`] where
    /// it has creases.
    pub scan: bool,
    /// Median scatter of a sampled point's nearest about their plane, in `ϵ`.
    pub sigma: f32,
    /// Share of sampled points with a neighbour outside the growth slab.
    pub hard: f32,
    /// Share with a neighbour outside the `ϵ` slab.
    pub hard_eps: f32,
    /// Median distance to the [`K0`]-th neighbour, in `ϵ`.
    pub spacing: f32,
    /// Share of sampled points whose nearest scatter about their plane by
    /// more than [`CREASE_SCATTER`] of their spread (a crease or a corner
    /// between them).
    pub crease: f32,
    /// Share of sampled points whose nearest lie along a line (a scan
    /// line, a wire): their spread across under [`LINE_SPREAD`] of their
    /// spread along.
    pub line: f32,
    /// Share of sampled points at a border (an open edge or a hole's):
    /// their [`GATE_RING`] nearest lie to one side of them.
    pub border: f32,
}

impl Gate {
    /// Whether lean growth serves this cloud.
    #[must_use]
    pub fn passes(&self) -> bool {
        self.passes_within(GATE_SIGMA)
    }

    /// [`Gate::passes`] with the scatter bounded by `sigma`.
    fn passes_within(&self, sigma: f32) -> bool {
        self.sampled > 0
            && self.sigma <= sigma
            && self.hard <= GATE_HARD
            && self.hard_eps <= GATE_HARD_EPS
            && self.crease <= GATE_CREASE
            && self.line <= GATE_LINE
            && self.border <= GATE_BORDER
            && self.spacing >= GATE_DENSE
    }

    /// Whether the gate found creases, corners or borders: one of its
    /// bounds on them refuses the cloud.
    #[must_use]
    pub fn sharp_features(&self) -> bool {
        self.crease > GATE_CREASE || self.hard_eps > GATE_HARD_EPS || self.border > GATE_BORDER
    }

    /// Whether sharp lean growth serves this scan once its points are
    /// settled onto their surfaces ([`settle`]), asked before sharp lean
    /// growth: a scan scattering over [`SCAN_SHARP_SIGMA`] (over
    /// [`SCAN_SETTLE_SIGMA`] with creases), at most
    /// [`settle::SETTLE_SIGMA`] and no sparser than
    /// [`settle::SETTLE_SPARSE`], its nearest not along a line.
    #[must_use]
    pub fn settle_passes(&self) -> bool {
        self.scan
            && self.sampled > 0
            && self.sigma > self.settle_from()
            && self.sigma <= settle::SETTLE_SIGMA
            && self.line <= GATE_LINE
            && self.spacing >= GATE_DENSE
            && self.spacing <= settle::SETTLE_SPARSE
    }

    /// The scatter past which a dense scan is settled: [`SCAN_SETTLE_SIGMA`]
    /// on a scan with creases (over [`GATE_CREASE`]), else
    /// [`SCAN_SHARP_SIGMA`] (past which neither lean nor sharp lean growth
    /// passes).
    fn settle_from(&self) -> f32 {
        if self.scan && self.crease > GATE_CREASE { SCAN_SETTLE_SIGMA } else { SCAN_SHARP_SIGMA }
    }

    /// Whether sharp lean growth (clip lines at creases and borders,
    /// [`sharp`]) serves this cloud: it has creases or borders
    /// ([`Gate::sharp_features`]) and passes lean growth's other bounds,
    /// its points curving off their slab counted without those across a
    /// crease, and lies no sparser than [`sharp::SHARP_SPARSE`]. A smooth
    /// cloud refused only for curving off (the bunny sampled 115k times:
    /// 10.1 % of its points, 0.20 % across a crease) keeps the stages:
    /// grown sharp it lost 3.2 dB (`scripts/lean_quality.py --points
    /// 115000 --seeds 1`, 4 views), clipped at bends and random gaps.
    #[must_use]
    pub fn sharp_passes(&self) -> bool {
        self.sharp_features()
            && self.sharp_plain().passes_within(self.sharp_sigma())
            && self.spacing <= sharp::SHARP_SPARSE
    }

    /// The scatter sharp lean growth takes: [`SCAN_SHARP_SIGMA`] on a
    /// scan with creases (over [`GATE_CREASE`]; a scan's silhouettes are
    /// borders whatever it shows), else [`GATE_SIGMA`].
    fn sharp_sigma(&self) -> f32 {
        if self.scan && self.crease > GATE_CREASE { SCAN_SHARP_SIGMA } else { GATE_SIGMA }
    }

    /// The gate as lean growth's other bounds read it where creases and
    /// borders are clipped: none counted, and the points curving off their
    /// slab less those across a crease.
    fn sharp_plain(&self) -> Gate {
        Gate {
            hard: self.hard - self.crease,
            hard_eps: 0.0,
            crease: 0.0,
            border: 0.0,
            ..*self
        }
    }

    /// Why neither lean growth nor sharp lean growth serves it (`None`
    /// where one does).
    #[must_use]
    pub fn sharp_refusal(&self) -> Option<String> {
        if self.passes() || self.sharp_passes() || self.settle_passes() {
            return None;
        }
        let noisy = self.scan && self.sigma > SCAN_SHARP_SIGMA && self.sigma <= settle::SETTLE_SIGMA;
        if noisy && self.spacing > settle::SETTLE_SPARSE {
            return Some(format!(
                "the points scatter {:.3} epsilon about their nearest's plane (noise; lean growth needs at most {SCAN_SHARP_SIGMA}) and a point's 12th nearest lies {:.1} epsilon away (settling the points onto their surfaces first needs at most {})",
                self.sigma,
                self.spacing,
                settle::SETTLE_SPARSE
            ));
        }
        if !self.sharp_features() {
            return self.refusal();
        }
        if self.sharp_plain().passes_within(self.sharp_sigma()) {
            return Some(format!(
                "a point's 12th nearest lies {:.1} epsilon away, with creases or borders (lean growth's splats stop at {} epsilon, the stages' grow past; at most {} with creases or borders)",
                self.spacing,
                super::grow::MAX_RADIUS_EPS,
                sharp::SHARP_SPARSE
            ));
        }
        self.sharp_plain().refusal_within(self.sharp_sigma())
    }

    /// Why it does not, in a few words (`None` where it passes).
    #[must_use]
    pub fn refusal(&self) -> Option<String> {
        self.refusal_within(GATE_SIGMA)
    }

    /// [`Gate::refusal`] with the scatter bounded by `sigma`.
    fn refusal_within(&self, sigma: f32) -> Option<String> {
        if self.sampled == 0 {
            Some("too few points".into())
        } else if self.sigma > sigma {
            Some(format!(
                "the points scatter {:.3} epsilon about their nearest's plane (noise or sparse sampling; lean growth needs at most {sigma})",
                self.sigma
            ))
        } else if self.hard_eps > GATE_HARD_EPS {
            Some(format!(
                "{:.1} % of the points have a neighbour epsilon off their plane (creases or corners; at most {:.1} %)",
                100.0 * self.hard_eps,
                100.0 * GATE_HARD_EPS
            ))
        } else if self.line > GATE_LINE {
            Some(format!(
                "{:.1} % of the points have nearest along a line (scan lines; at most {:.0} %)",
                100.0 * self.line,
                100.0 * GATE_LINE
            ))
        } else if self.crease > GATE_CREASE {
            Some(format!(
                "{:.1} % of the points have nearest that straddle a crease (at most {:.0} %)",
                100.0 * self.crease,
                100.0 * GATE_CREASE
            ))
        } else if self.hard > GATE_HARD {
            Some(format!(
                "{:.1} % of the points curve off their plane within their nearest (at most {:.1} %)",
                100.0 * self.hard,
                100.0 * GATE_HARD
            ))
        } else if self.border > GATE_BORDER {
            Some(format!(
                "{:.2} % of the points lie at an open border or a hole (at most {:.1} %)",
                100.0 * self.border,
                100.0 * GATE_BORDER
            ))
        } else if self.spacing < GATE_DENSE {
            Some(format!(
                "the points lie denser than epsilon needs (a point's 12th nearest {:.2} epsilon away, at least {GATE_DENSE}): the stages thin them",
                self.spacing
            ))
        } else {
            None
        }
    }
}

/// The gate's least median distance to a point's [`K0`]-th neighbour, in
/// `ϵ`: lean growth keeps every point, and a cloud denser than that is
/// thinned by the stages (`splat::thin`) faster and in less memory. The
/// bunny sampled 100M times (0.09 `ϵ`, in 9 tiles under `--max-memory
/// 4`): lean growth 120.1 s and 2.70 GB, the stages 68.4 s and 1.63 GB;
/// 2M times (about 0.66 `ϵ`): lean growth 1.15 s, the stages 1.49 s,
/// lean 1.4-3.4 dB nearer the mesh.
pub const GATE_DENSE: f32 = 0.5;

/// The points sorted by grid cell, and the cells by key in a hash table.
struct Grid {
    lo: Vec3,
    h: f32,
    /// Positions in cell order.
    pos: Vec<Vec3>,
    /// Distinct cells' keys, in order (a row's cells, along x, in a run),
    /// and where their points start (one more entry: the end).
    keys: Vec<u64>,
    start: Vec<u32>,
    /// Each row's (y, z) key and its first cell (one more entry: the end).
    rows: Vec<u64>,
    row_first: Vec<u32>,
    /// Open addressing over the rows: a row's index plus one, 0 empty.
    table: Vec<u32>,
    shift: u32,
    /// Each position's index in the points given (a scan's only: its
    /// viewpoints and outliers are the input's; empty elsewhere).
    order: Vec<u32>,
    /// How far, per unit past a splat's last point, a point beyond it may
    /// rise off its slab and still show the surface going on (a scan's
    /// curved silhouettes, [`SCAN_BEND`]; 0 elsewhere: in-slab only).
    bend: f32,
}

/// A scan's splat has no border line where the points past its last rise
/// off its slab by at most this much per unit beyond it: a curved surface
/// seen edge-on from the scanner (a cylinder's side against what stands
/// behind it) curves out of the slab toward its silhouette, where the
/// surface goes on unseen. The solids scanned exactly from one station
/// (1000×750 rays, `compare --truth` at 400×300): the stages 35.03 dB,
/// sharp lean growth with border lines in-slab only 35.23 (69 hole
/// pixels), at 0.5 35.70 (62), at 0.25 35.65. Not for an airborne survey
/// (no viewpoint): its walls below a roof's edge would read as the roof
/// going on (29.63 -> 29.23 dB; `docs/notes/generation.md`, "Issue 54,
/// sixtieth session").
pub const SCAN_BEND: f32 = 0.5;

/// Bits of a cell coordinate in a key.
const AXIS_BITS: u32 = 21;

impl Grid {
    /// The grid of `points` in cells `h` wide; a scan's (`scan`) keeps the
    /// points' order and bends its borders ([`Grid::order`], [`Grid::bend`]).
    fn build(points: &[Vec3], h: f32, scan: bool) -> Grid {
        // On the threads (a minimum and maps: the same values).
        let inf = Vec3::splat(f32::INFINITY);
        let lo = points.par_iter().with_min_len(8192).fold(|| inf, |a, p| a.min(*p)).reduce(|| inf, Vec3::min);
        let top = (1i32 << AXIS_BITS) - 1;
        let mut keyed: Vec<(u64, u32)> = points
            .par_iter()
            .with_min_len(8192)
            .enumerate()
            .map(|(i, &p)| (key_of(cell_of(lo, h, p, top)), i as u32))
            .collect();
        keyed.par_sort_unstable();
        let pos = keyed.par_iter().with_min_len(8192).map(|&(_, i)| points[i as usize]).collect();
        let order = if scan { keyed.par_iter().with_min_len(8192).map(|&(_, i)| i).collect() } else { Vec::new() };
        let (mut keys, mut start) = (Vec::new(), Vec::new());
        for (i, &(k, _)) in keyed.iter().enumerate() {
            if keys.last() != Some(&k) {
                keys.push(k);
                start.push(i as u32);
            }
        }
        start.push(keyed.len() as u32);
        let (mut rows, mut row_first) = (Vec::new(), Vec::new());
        for (c, &k) in keys.iter().enumerate() {
            if rows.last() != Some(&(k >> AXIS_BITS)) {
                rows.push(k >> AXIS_BITS);
                row_first.push(c as u32);
            }
        }
        row_first.push(keys.len() as u32);
        let bits = (2 * rows.len()).next_power_of_two().trailing_zeros().max(4);
        let shift = 64 - bits;
        let mut table = vec![0u32; 1 << bits];
        for (r, &k) in rows.iter().enumerate() {
            let mut s = slot(k, shift);
            while table[s] != 0 {
                s = (s + 1) & (table.len() - 1);
            }
            table[s] = r as u32 + 1;
        }
        Grid {
            lo,
            h,
            pos,
            keys,
            start,
            rows,
            row_first,
            table,
            shift,
            order,
            bend: if scan { SCAN_BEND } else { 0.0 },
        }
    }

    fn cell(&self, p: Vec3) -> [i32; 3] {
        cell_of(self.lo, self.h, p, (1 << AXIS_BITS) - 1)
    }

    /// The cells of row (`y`, `z`) (none outside the grid), as a range of
    /// indices into `keys`.
    fn row(&self, y: i32, z: i32) -> std::ops::Range<usize> {
        let top = (1 << AXIS_BITS) - 1;
        if !(0..=top).contains(&y) || !(0..=top).contains(&z) {
            return 0..0;
        }
        let k = key_of([0, y, z]) >> AXIS_BITS;
        let mut s = slot(k, self.shift);
        loop {
            let e = self.table[s];
            if e == 0 {
                return 0..0;
            }
            let r = e as usize - 1;
            if self.rows[r] == k {
                return self.row_first[r] as usize..self.row_first[r + 1] as usize;
            }
            s = (s + 1) & (self.table.len() - 1);
        }
    }

    /// The x coordinate of cell `c` (an index into `keys`).
    fn x_of(&self, c: u32) -> i32 {
        (self.keys[c as usize] & ((1 << AXIS_BITS) - 1)) as i32
    }
}

fn cell_of(lo: Vec3, h: f32, p: Vec3, top: i32) -> [i32; 3] {
    let c = ((p - lo) / h).floor();
    // Saturating casts: NaN to 0, beyond the key's range to its ends.
    [c.x as i32, c.y as i32, c.z as i32].map(|x| x.clamp(0, top))
}

fn key_of(c: [i32; 3]) -> u64 {
    c[0] as u64 | (c[1] as u64) << AXIS_BITS | (c[2] as u64) << (2 * AXIS_BITS)
}

fn slot(k: u64, shift: u32) -> usize {
    (k.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> shift) as usize
}

/// The fewest known candidates [`Near::sort_to`] sorts at a time.
const SORT_LEAST: usize = 32;

/// Rows of cells a search may reach across: those within [`MAX_SHELL`]
/// cells along y and z.
const ROWS_SEEN: usize = (2 * MAX_SHELL as usize + 1).pow(2);

/// A row of cells a search has reached: its cells (indices into the grid's
/// `keys`, `first..end`) and, of them, those gathered so far (`a..b`).
#[derive(Clone, Copy, Default)]
struct RowSeen {
    first: u32,
    end: u32,
    a: u32,
    b: u32,
}

/// A point's neighbours by distance, gathered shell by shell of cells.
#[derive(Default)]
struct Near {
    /// Candidates as keys, the squared distance's bits over the index into
    /// the grid's order ([`key`]): the first `sorted` sorted and nearer
    /// than all the rest, then up to `known` those within `sure` (nearer
    /// than all the rest, in no order), the rest in no order.
    cand: Vec<u64>,
    sorted: usize,
    known: usize,
    /// The first `picked` candidates are nearer than all the rest (the
    /// first `sorted` of them in order): [`Near::nearest_unordered`]'s.
    picked: usize,
    shell: i32,
    /// Every point within this distance has been gathered.
    sure: f32,
    centre: Vec3,
    cell: [i32; 3],
    /// The rows within the shells gathered, by (y, z) offset from `cell`:
    /// a row is looked up once, at the first shell that reaches it, and
    /// each later shell steps its gathered cells out by one at each end.
    rows: Vec<RowSeen>,
}

/// A candidate's key: a squared distance is finite and not negative (a
/// sum of squares, never -0), so its bits order as the distance does, and
/// the keys order as (distance, index) pairs: one order, the pairs being
/// distinct, sorted as plain integers.
fn key(d2: f32, j: u32) -> u64 {
    (u64::from(d2.to_bits()) << 32) | u64::from(j)
}

/// Moves the keys within `bits` (a squared distance's bits, [`key`]) to
/// the front of `keys`, in no order, and counts them: branch-free, a key
/// past `bits` swaps with another past it (or with itself) and the count
/// stays.
fn move_up_within(keys: &mut [u64], bits: u32) -> usize {
    let mut within = 0;
    for i in 0..keys.len() {
        let near = (keys[i] >> 32) as u32 <= bits;
        keys.swap(i, within);
        within += usize::from(near);
    }
    within
}

/// The (squared distance, index) pair of a [`key`].
fn unkey(k: u64) -> (f32, u32) {
    (f32::from_bits((k >> 32) as u32), k as u32)
}

impl Near {
    fn start(&mut self, g: &Grid, p: Vec3) {
        self.cand.clear();
        self.sorted = 0;
        self.known = 0;
        self.picked = 0;
        self.shell = -1;
        self.sure = 0.0;
        self.centre = p;
        self.cell = g.cell(p);
        self.widen(g);
    }

    /// Gathers the next shell of cells; false at [`MAX_SHELL`], where the
    /// rest are known as they are.
    fn widen(&mut self, g: &Grid) -> bool {
        if !self.reach(g) {
            self.known = self.cand.len();
            return false;
        }
        // Those within `sure` are the nearest of all: moved up, known.
        self.known += move_up_within(&mut self.cand[self.known..], (self.sure * self.sure).to_bits());
        true
    }

    /// Sorts the known candidates up to the `n`-th at least: all of them
    /// when that is most of them; else those within the distance a surface
    /// would hold a quarter more than wanted at (the sorted ones at least
    /// doubled), split off in one pass, when they are enough. A search
    /// sorts about a third of what it gathers and uses a third of that
    /// (the real table scan: 21 million sorted a search's shell at a time,
    /// 7.8 million asked for).
    fn sort_to(&mut self, n: usize) {
        let want = (n - self.sorted).max(self.sorted).max(SORT_LEAST);
        let known = &mut self.cand[self.sorted..self.known];
        if 2 * want < known.len() {
            // On a surface the count within `r` grows as `r²`.
            let share = (self.sorted as f32 + 1.25 * want as f32) / self.known as f32;
            let within = move_up_within(known, (self.sure * self.sure * share).to_bits());
            if within >= want {
                known[..within].sort_unstable();
                self.sorted += within;
                return;
            }
        }
        known.sort_unstable();
        self.sorted = self.known;
    }

    /// Gathers the next shell of cells, in no order, and how far every point
    /// is now known (`sure`); false at [`MAX_SHELL`].
    fn reach(&mut self, g: &Grid) -> bool {
        if self.shell >= MAX_SHELL {
            return false;
        }
        self.shell += 1;
        self.gather(g);
        // The distance from `p` to the gathered block's faces: a point of
        // a later shell lies at least this far.
        let q = (self.centre - g.lo) / g.h;
        let s = self.shell as f32;
        let c = self.cell;
        let face = |a: f32, ci: i32| (a - ci as f32 + s).min(ci as f32 + 1.0 + s - a) * g.h;
        self.sure = face(q.x, c[0]).min(face(q.y, c[1])).min(face(q.z, c[2])).max(0.0);
        true
    }

    /// The `n` nearest (those [`Near::get`] gives as `0..n`), in no order:
    /// the shells gathered until `n` lie within `sure`, then a selection
    /// among those within it past the nearest known (`sorted`, `picked`),
    /// not a sort. `None` when fewer than `n` lie within [`MAX_SHELL`].
    /// The search goes on from there ([`Near::get`] sorts what it needs).
    fn nearest_unordered(&mut self, g: &Grid, n: usize) -> Option<&[u64]> {
        let front = self.sorted.max(self.picked);
        // Those within `sure` are moved up behind the front (and those known
        // already), shell by shell.
        let mut inside = front.max(self.known);
        loop {
            inside += move_up_within(&mut self.cand[inside..], (self.sure * self.sure).to_bits());
            if inside >= n || !self.reach(g) {
                break;
            }
        }
        if self.cand.len() < n {
            return None;
        }
        if inside < n {
            // At [`MAX_SHELL`]: the nearest of all gathered.
            inside = self.cand.len();
        }
        self.known = inside;
        if n > front {
            self.cand[front..inside].select_nth_unstable(n - front - 1);
        }
        self.picked = self.picked.max(n);
        Some(&self.cand[..n])
    }

    /// Gathers the points of the cells at Chebyshev distance `shell` from
    /// `cell` (the order they come in plays no part: candidates are sorted
    /// as keys, distinct and totally ordered).
    fn gather(&mut self, g: &Grid) {
        if self.rows.is_empty() {
            self.rows = vec![RowSeen::default(); ROWS_SEEN];
        }
        let (s, c, p) = (self.shell, self.cell, self.centre);
        let (x0, x1) = (c[0] - s, c[0] + s);
        let cand = &mut self.cand;
        let mut take = |cells: std::ops::Range<u32>| {
            let (i, j) = (g.start[cells.start as usize], g.start[cells.end as usize]);
            cand.extend((i..j).map(|k| key(g.pos[k as usize].distance_squared(p), k)));
        };
        let side = 2 * MAX_SHELL + 1;
        for dz in -s..=s {
            for dy in -s..=s {
                let r = &mut self.rows[((dz + MAX_SHELL) * side + dy + MAX_SHELL) as usize];
                if dz.abs() == s || dy.abs() == s {
                    // A row first reached: its cells from x0 to x1.
                    let cells = g.row(c[1] + dy, c[2] + dz);
                    let (first, end) = (cells.start as u32, cells.end as u32);
                    let mut a = first;
                    while a < end && g.x_of(a) < x0 {
                        a += 1;
                    }
                    let mut b = a;
                    while b < end && g.x_of(b) <= x1 {
                        b += 1;
                    }
                    *r = RowSeen { first, end, a, b };
                    take(a..b);
                } else {
                    // A row within: the next cell out at each end of those
                    // gathered (a row's cells are in order along x).
                    if r.a > r.first && g.x_of(r.a - 1) == x0 {
                        r.a -= 1;
                        take(r.a..r.a + 1);
                    }
                    if r.b < r.end && g.x_of(r.b) == x1 {
                        take(r.b..r.b + 1);
                        r.b += 1;
                    }
                }
            }
        }
    }

    /// The `j`-th nearest (0: the point itself), once every point nearer
    /// is known; else the `j`-th of those gathered within [`MAX_SHELL`].
    fn get(&mut self, g: &Grid, j: usize) -> Option<(f32, u32)> {
        loop {
            if j < self.sorted {
                return Some(unkey(self.cand[j]));
            }
            if j < self.known {
                self.sort_to(j + 1);
            } else if !self.widen(g) && j >= self.known {
                return None;
            }
        }
    }
}

/// How a splat grows: at error `eps` (its radius capped at
/// [`MAX_RADIUS_EPS`] of it), taking points within `slab` of its plane, from
/// a seed whose [`K0`]-th neighbour lies within `far` (else an outlier).
#[derive(Clone, Copy)]
struct Growth<'a> {
    eps: f32,
    slab: f32,
    far: f32,
    /// A scan's scanners and its scatter (the gate's, a length; 0 where
    /// unknown): a seed's plane fitted within [`NOISY_NEAREST`] scatters
    /// and leaning toward its sight line is widened ([`off_the_sight_line`]).
    scanners: Option<(&'a Viewpoints, f32)>,
}

/// A grown splat before its field.
struct Grown {
    centre: Vec3,
    normal: Vec3,
    radius: f32,
    /// The points it took (indices into the grid's order).
    members: Vec<u32>,
    /// The points beyond them within [`REACH`] radii (its field's too).
    extra: Vec<u32>,
    /// Its seed's distance to its [`K0`]-th neighbour.
    spacing: f32,
    /// Grown from a seed whose nearest already left the growth slab: its
    /// points may lie off its plane by more than `ϵ`.
    hard: bool,
    /// Its clip lines (sharp lean growth only).
    clips: [Option<sharp::Line>; 2],
}

/// What lean growth made.
#[derive(Clone, Debug)]
pub struct Lean {
    /// The splats, or none where the gate refused the cloud.
    pub splats: Vec<Splat>,
    /// What the gate measured.
    pub gate: Gate,
    /// Seeds left without a splat as outliers.
    pub outliers: usize,
    /// The outlier seeds, as indices into the points given (ascending):
    /// free-space trimming leaves their lines of sight out, as it does the
    /// stages' outliers, and the held-out check does not test them.
    pub outlier_points: Vec<u32>,
    /// A scan's share of points whose splat faces away from their
    /// viewpoint ([`orient`]; `None` without viewpoints).
    pub facing_away: Option<f64>,
    /// The points no splat took within `ϵ` of its plane (an outlier
    /// seed's, a point off the plane of a splat grown from nearest that
    /// left the growth slab): to be looked for on the splats.
    pub unsure_points: Vec<Vec3>,
    /// The most, over the splats, of its radius over its seed's distance
    /// to its [`K0`]-th neighbour.
    pub largest_over_spacing: f32,
    /// Splats whose field stayed flat (too few points, a singular fit).
    pub flat_fields: usize,
    /// Grown with clip lines at creases and borders ([`sharp`]).
    pub sharp: bool,
    /// Grown on the points settled onto their surfaces first ([`settle`]).
    pub settled: bool,
    /// Splats with a clip line.
    pub clipped: usize,
    /// Discs widened to close a pinhole where three met ([`gaps`]).
    pub widened: usize,
    /// Seconds: the grid and the gate, growth, orientation, fields.
    pub seconds: [f64; 4],
}

/// The gate of a cloud with too few points to sample.
const NO_GATE: Gate = Gate {
    sampled: 0,
    scan: false,
    sigma: f32::INFINITY,
    hard: 1.0,
    hard_eps: 1.0,
    spacing: f32::INFINITY,
    crease: 1.0,
    line: 1.0,
    border: 1.0,
};

/// What the gate reads of one sampled point.
struct Sample {
    /// Scatter of its nearest about their plane, in `ϵ`.
    sigma: f32,
    /// Its [`K0`]-th neighbour's distance, in `ϵ`.
    dk: f32,
    hard: bool,
    hard_eps: bool,
    line: bool,
    border: bool,
}

/// Point `i`'s [`Sample`] (`None`: too few neighbours, a degenerate fit).
fn sample(g: &Grid, near: &mut Near, i: usize, eps: f32) -> Option<Sample> {
    near.start(g, g.pos[i]);
    let mut idx = Vec::with_capacity(GATE_RING + 1);
    for j in 0..=GATE_RING {
        match near.get(g, j) {
            Some(c) => idx.push(c),
            None => break,
        }
    }
    if idx.len() <= K0 {
        return None;
    }
    let pts = idx[..=K0].iter().map(|&(_, k)| g.pos[k as usize]);
    let (c, vals, vecs) = plane_fit(pts.clone());
    let (c, nrm) = (c.as_vec3(), vecs[0].as_vec3());
    if !nrm.is_finite() || !c.is_finite() {
        return None;
    }
    let off = pts.map(|q| nrm.dot(q - c).abs()).fold(0.0, f32::max);
    let p = g.pos[i];
    let ring = idx.iter().map(|&(_, k)| g.pos[k as usize] - p);
    let mean = ring.map(|d| d - nrm * nrm.dot(d)).sum::<Vec3>() / idx.len() as f32;
    let far = idx.last().map_or(0.0, |c| c.0.sqrt());
    Some(Sample {
        sigma: ((vals[0].max(0.0) / (K0 + 1) as f64).sqrt() as f32) / eps,
        dk: idx[K0].0.sqrt() / eps,
        hard: off > GROW_EPS * eps,
        hard_eps: off > eps,
        line: vals[1] <= LINE_SPREAD * vals[2],
        border: mean.length() > BORDER_OFFSET * far,
    })
}

/// The gate's figures over a stride sample of about `most` of `g`'s
/// points, of those inside `within` where given.
fn gate(g: &Grid, eps: f32, most: usize, within: Option<[Vec3; 2]>) -> (Gate, f32) {
    let n = g.pos.len();
    if n <= K0 {
        return (NO_GATE, f32::INFINITY);
    }
    // The sampled points alone: no list of every point where no box limits them.
    let picked: Vec<u32> = match within {
        None => (0..n as u32).step_by(n.div_ceil(most).max(1)).collect(),
        Some(_) => {
            let inner: Vec<u32> = (0..n as u32).filter(|&i| inside(g.pos[i as usize], within)).collect();
            let stride = inner.len().div_ceil(most).max(1);
            inner.into_iter().step_by(stride).collect()
        }
    };
    let samples: Vec<Sample> = picked
        .into_par_iter()
        .map_init(Near::default, |near, i| sample(g, near, i as usize, eps))
        .flatten()
        .collect();
    let mut sig: Vec<f32> = samples.iter().map(|s| s.sigma).collect();
    let mut dks: Vec<f32> = samples.iter().map(|s| s.dk).collect();
    let count = |f: fn(&Sample) -> bool| samples.iter().filter(|s| f(s)).count();
    let (hard, hard_eps, border) = (count(|s| s.hard), count(|s| s.hard_eps), count(|s| s.border));
    let line = count(|s| s.line);
    let sampled = sig.len();
    if sampled == 0 {
        return (NO_GATE, f32::INFINITY);
    }
    let median = |v: &mut Vec<f32>| {
        let m = v.len() / 2;
        *v.select_nth_unstable_by(m, f32::total_cmp).1
    };
    let crease = sig.iter().zip(&dks).filter(|(s, d)| **s > CREASE_SCATTER * **d).count();
    let spacing = median(&mut dks);
    let gate = Gate {
        sampled,
        scan: false,
        sigma: median(&mut sig),
        hard: hard as f32 / sampled as f32,
        hard_eps: hard_eps as f32 / sampled as f32,
        spacing,
        crease: crease as f32 / sampled as f32,
        line: line as f32 / sampled as f32,
        border: border as f32 / sampled as f32,
    };
    (gate, spacing * eps)
}

/// Grows one splat from the point `i` (grid order); `None` where it grows
/// none (a degenerate fit, an outlier).
fn grow(g: &Grid, near: &mut Near, i: u32, (growth, sharp): (Growth, bool)) -> Option<Grown> {
    let Growth { eps, slab, far, scanners } = growth;
    let cap = MAX_RADIUS_EPS * eps;
    let p = g.pos[i as usize];
    near.start(g, p);
    let mut members = Vec::with_capacity(64);
    for j in 0..=K0 {
        let (d2, idx) = near.get(g, j)?;
        if j == K0 && d2 > far * far {
            return None;
        }
        members.push(idx);
    }
    let fit = |m: &[u32]| {
        let (c, _, vecs) = plane_fit(m.iter().map(|&k| g.pos[k as usize]));
        (vecs[0].as_vec3(), c.as_vec3())
    };
    let within = |n: Vec3, c: Vec3, m: &[u32]| m.iter().all(|&k| n.dot(g.pos[k as usize] - c).abs() <= slab);
    let (mut n, mut c) = fit(&members);
    // `far` is OUTLIER_SPACINGS median spacings.
    let off = far * (SEED_OFF_SPACINGS / OUTLIER_SPACINGS);
    if !n.is_finite() || !c.is_finite() || off_its_nearest(&members, p, off, fit) {
        return None;
    }
    if let Some((views, scatter)) = scanners
        && g.pos[members[K0] as usize].distance(p) < NOISY_NEAREST * scatter
        && let Some(&k) = g.order.get(i as usize)
        && let Some(wider) = off_the_sight_line(g, near, (&members, n, c), views.at(k as usize))
    {
        (n, c) = wider;
    }
    if !within(n, c, &members) {
        // Its nearest already leave the slab (a bend tighter than the
        // seed's spacing): a splat of them alone.
        let radius = g.pos[members[K0] as usize].distance(p);
        let centre = p + n * n.dot(c - p);
        return Some(Grown {
            centre,
            normal: n,
            radius: radius * SCALE,
            members,
            extra: Vec::new(),
            spacing: radius,
            hard: true,
            clips: [None; 2],
        });
    }
    let spacing = g.pos[members[K0] as usize].distance(p);
    let mut next_fit = 2 * members.len();
    let mut j = members.len();
    let stop = loop {
        let Some((d2, idx)) = near.get(g, j) else {
            break None;
        };
        let q = g.pos[idx as usize];
        if d2 > near.sure * near.sure || d2.sqrt() > cap || n.dot(q - c).abs() > slab {
            break Some(d2.sqrt());
        }
        members.push(idx);
        j += 1;
        if members.len() >= next_fit {
            let (m, mc) = fit(&members);
            if !(m.is_finite() && mc.is_finite() && within(m, mc, &members)) {
                // The refitted plane leaves some of them: stop here.
                break near.get(g, j).map(|c| c.0.sqrt());
            }
            (n, c) = (m, mc);
            next_fit *= 2;
        }
    };
    let last = members.last().map_or(0.0, |&k| g.pos[k as usize].distance(p));
    let radius = stop.unwrap_or(last).min(cap).max(last);
    let centre = p + n * n.dot(c - p);
    let reach = radius * REACH;
    let mut extra = Vec::new();
    while let Some((d2, idx)) = near.get(g, j) {
        if d2 > reach * reach || d2 > near.sure * near.sure {
            break;
        }
        extra.push(idx);
        j += 1;
    }
    let clips = if sharp {
        sharp::clip(g, (centre, n, radius * SCALE), (slab, spacing), &members, &mut extra)
    } else {
        [None; 2]
    };
    Some(Grown {
        centre,
        normal: n,
        radius: radius * SCALE,
        members,
        extra,
        spacing,
        hard: false,
        clips,
    })
}

/// A scan's seed whose [`K0`]-th nearest lies within this many of the
/// scan's scatters (the gate's) has a plane the range noise tilts: its
/// nearest spread along their sight lines about as far as across the
/// surface, so the fit leans toward the sight line
/// ([`off_the_sight_line`]). The real table scan (`scenes/data/`), scatter
/// 0.151 `ϵ`, reads a median 6.9 (its 5th percentile 4.5) and 2.0 in its
/// band of five times the density, where a tilting scanner turned and swept
/// the same lines again. The solids scanned at 1000×750 rays with range
/// noise up to half a spacing have a seed's plane widened at most (one at
/// half a spacing, seed 1; `compare --truth` the same for seeds 1-3; with
/// the bound at 10, 23 there and 0.23 dB lost); with 0.75, 1 and 1.5
/// spacings, where it widens many, `compare --truth` (400×300, means of seeds 1-3) reads 32.87, 31.91 and
/// 30.56 dB against 32.87, 31.88 and 30.14 without.
pub const NOISY_NEAREST: f32 = 8.0;

/// A noisy seed's plane ([`NOISY_NEAREST`]) leans toward its sight line
/// where the sine of the sight line over the plane is under this (the
/// sight line more than 60° off the normal). On the real table scan the
/// band's [`K0`] nearest read a median 0.09 and the rest of it 0.68; a plane
/// of 2,000 nearest in the band 0.80, as its neighbours'. Taken from 0.4
/// to 0.6, the table scan's held-out lines of sight meet the splats alike
/// (`docs/notes/generation.md`, "Issue 54, sixty-ninth session").
pub const LEANING_SIN: f32 = 0.5;

/// The most nearest a leaning seed's plane is refitted to: its [`K0`]
/// nearest and itself, four times over three times (832).
const WIDEST: usize = (K0 + 1) * 64;

/// The plane of a seed's nearest (`n`, `c` of `members`, the seed
/// `members[0]`, where `near` searched from) leaning toward its sight line
/// from `eye` ([`LEANING_SIN`]) refitted to four, sixteen and sixty-four
/// times as many nearest, the first refit that does not lean; `None` keeps
/// it (it does not lean, or every refit leans as well: a surface seen at a
/// glancing angle).
fn off_the_sight_line(g: &Grid, near: &mut Near, (members, n, c): (&[u32], Vec3, Vec3), eye: Vec3) -> Option<(Vec3, Vec3)> {
    let leans = |n: Vec3, c: Vec3| {
        let to = c - eye;
        n.dot(to).abs() < LEANING_SIN * to.length()
    };
    if !leans(n, c) {
        return None;
    }
    let mut size = members.len();
    let mut wider = None;
    while size < WIDEST && wider.is_none() {
        size *= 4;
        let Some(keys) = near.nearest_unordered(g, size) else {
            break;
        };
        let (wc, _, vecs) = plane_fit(keys.iter().map(|&k| g.pos[unkey(k).1 as usize]));
        let (m, mc) = (vecs[0].as_vec3(), wc.as_vec3());
        wider = (m.is_finite() && mc.is_finite() && !leans(m, mc)).then_some((m, mc));
    }
    wider
}

/// True when the seed `p` (`members[0]`, its [`K0`] nearest after it)
/// lies more than `off` off its nearest's plane, fitted without it
/// ([`SEED_OFF_SPACINGS`]): a stray return near a surface, whose nearest
/// are the surface's (near enough for [`OUTLIER_SPACINGS`]), would grow a
/// disc tilted between itself and them, standing off the surface.
fn off_its_nearest(members: &[u32], p: Vec3, off: f32, fit: impl Fn(&[u32]) -> (Vec3, Vec3)) -> bool {
    let (n, c) = fit(&members[1..]);
    // A degenerate fit (NaN) says nothing: the seed is kept.
    n.dot(p - c).abs() > off
}

/// Each splat's links: the splats sharing a point with it, each once,
/// with how far the link is trusted ([`link_weight`], as `w * 1e6`),
/// found on every thread. `points` is how many points the grid holds;
/// `scan` as [`link_weight`]'s.
fn links(splats: &[Grown], points: usize, scan: bool) -> Vec<Vec<(u32, u32)>> {
    let n = splats.len();
    // Each point's splats, as compressed rows.
    let mut start = vec![0u32; points + 1];
    for s in splats.iter() {
        for &k in &s.members {
            start[k as usize + 1] += 1;
        }
    }
    for i in 0..points {
        start[i + 1] += start[i];
    }
    let mut at = start.clone();
    let mut took = vec![0u32; start[points] as usize];
    for (i, s) in splats.iter().enumerate() {
        for &k in &s.members {
            took[at[k as usize] as usize] = i as u32;
            at[k as usize] += 1;
        }
    }
    // (`link_weight` reads no normal's sign, which orientation turns.)
    (0..n)
        .into_par_iter()
        .map_init(
            || vec![u32::MAX; n],
            |seen, a| {
                let mut out = Vec::new();
                for &k in &splats[a].members {
                    for &b in &took[start[k as usize] as usize..start[k as usize + 1] as usize] {
                        let bu = b as usize;
                        if bu != a && seen[bu] != a as u32 {
                            seen[bu] = a as u32;
                            if let Some(w) = link_weight(&splats[a], &splats[bu], scan) {
                                out.push(((w * 1e6) as u32, b));
                            }
                        }
                    }
                }
                out
            },
        )
        .collect()
}

/// Orients the splats' normals along a spanning tree over splats that took
/// a point in common, most parallel first, from the splat farthest from the
/// centroid facing away from it (each part of the tree from its own).
/// Sharing a point, not overlapping discs, makes two splats neighbours: the
/// discs on the two faces of a thin sheet (a bunny's ear) overlap and stand
/// nearly parallel, and joining them would turn one face inside out; a
/// splat takes only points within its slab, never the far face's.
///
/// A scan's splats (`views`: where each point of the grid's order was seen
/// from, and the points) are then turned tree by tree to face the
/// scanners, as the stages turn their normals (`normals::orient`): a tree
/// whose points mostly see its splats from behind is turned over
/// ([`face_the_scanners`]). Returns the share of the points taken (counted
/// once a splat) whose splat then faces away from their viewpoint past
/// [`FACING_AWAY_COS`] (`None` without `views`), which tells free-space
/// trimming whether the viewpoint is the scanner's. `adjacent` are the
/// splats' [`links`].
fn orient(splats: &mut [Grown], adjacent: &[Vec<(u32, u32)>], views: Option<(&[Vec3], &[Vec3])>) -> Option<f64> {
    let n = splats.len();
    if n == 0 {
        return views.map(|_| 0.0);
    }
    let centroid = splats.iter().map(|s| s.centre).sum::<Vec3>() / n as f32;
    let mut done = vec![false; n];
    // Each splat's tree, by its root.
    let mut tree = vec![u32::MAX; n];
    let mut heap = BinaryHeap::new();
    let mut by_distance: Vec<u32> = (0..n as u32).collect();
    by_distance.sort_unstable_by(|&a, &b| {
        let (da, db) = (splats[a as usize].centre.distance_squared(centroid), splats[b as usize].centre.distance_squared(centroid));
        db.total_cmp(&da).then(a.cmp(&b))
    });
    // The heap's entries are distinct (one a pair), so it pops them in
    // one order whatever order they were pushed in.
    let push = |heap: &mut BinaryHeap<(u32, u32, u32)>, done: &[bool], a: usize| {
        for &(w, b) in &adjacent[a] {
            if !done[b as usize] {
                heap.push((w, u32::MAX - b, a as u32));
            }
        }
    };
    for &root in &by_distance {
        let root = root as usize;
        if done[root] {
            continue;
        }
        let s = &mut splats[root];
        if s.normal.dot(s.centre - centroid) < 0.0 {
            s.normal = -s.normal;
        }
        done[root] = true;
        tree[root] = root as u32;
        push(&mut heap, &done, root);
        while let Some((_, b, a)) = heap.pop() {
            let (a, b) = (a as usize, (u32::MAX - b) as usize);
            if done[b] {
                continue;
            }
            done[b] = true;
            tree[b] = root as u32;
            if turned(&splats[a], &splats[b], views.is_some()) {
                splats[b].normal = -splats[b].normal;
            }
            push(&mut heap, &done, b);
        }
    }
    views.map(|views| face_the_scanners(splats, &tree, views))
}

/// Whether `b` must turn over to agree with `a`: when their normals
/// oppose; in a scan's tree (`scan`), across a crease (the cosine between
/// them under [`CREASE_AGREE`] either way, where that sign says little),
/// when each faces the other's centre on a different side (an edge seen
/// consistently has both normals away from the other splat, convex, or
/// both toward it, concave). The exactly scanned solids: 7.2 % of the
/// points facing away from the scanner by the sign alone, so trimming
/// refused the viewpoint; by the sides, none. Elsewhere the sign alone:
/// the default survey moved by 0.01 dB with the sides, the solids not.
fn turned(a: &Grown, b: &Grown, scan: bool) -> bool {
    let d = a.normal.dot(b.normal);
    if !scan || d.abs() >= CREASE_AGREE {
        return d < 0.0;
    }
    let (sa, sb) = (a.normal.dot(b.centre - a.centre), b.normal.dot(a.centre - b.centre));
    (sa < 0.0) != (sb < 0.0)
}

/// [`turned`]'s cosine below which two splats meet across a crease.
const CREASE_AGREE: f32 = 0.5;

/// How far [`orient`]'s tree (grown from the most trusted links first)
/// trusts the link between `a` and `b`: `|n_a · n_b|`, but in a scan's tree
/// (`scan`) across a crease, where [`turned`] reads the sides, the nearer
/// of the two centres' distances from the other's plane over the larger
/// radius, scaled under [`CREASE_AGREE`] (so after every link that is not
/// across a crease), and no link at all under [`CREASE_TRUST`] (the two
/// then turn by their own trees' votes). A centre nearly in the other's
/// plane gives a side that a splat tilted at the edge decides: by `|n_a ·
/// n_b|` alone, the exactly scanned solids at `ϵ` 0.0032 of the diagonal
/// (1000×750 rays) had 30.5 % of their points facing away from the
/// scanner after the trees' turns, so trimming refused the viewpoint; the
/// sparse scan (400×300) 9.2 % at 0.0035 and 8.9 % at 0.008, two stations
/// in an E57 file 22.1 % at 0.0025; with the links weighed but none
/// dropped, a 60k-point tile of the scan with range noise of 0.18 spacings
/// still 23.3 % through one link trusted 0.012. By this rule none
/// (`docs/notes/generation.md`, "Issue 54, sixty-second session").
fn link_weight(a: &Grown, b: &Grown, scan: bool) -> Option<f32> {
    let d = a.normal.dot(b.normal).abs();
    if !scan || d >= CREASE_AGREE {
        return Some(d);
    }
    let off = a.normal.dot(b.centre - a.centre).abs().min(b.normal.dot(a.centre - b.centre).abs());
    // A NaN or a zero radius (coincident points) gives no trust.
    let trust = off / a.radius.max(b.radius);
    (trust.is_finite() && trust >= CREASE_TRUST).then(|| CREASE_AGREE * 0.999 * trust.min(1.0))
}

/// [`link_weight`]'s least trust in a link across a crease: the links
/// that turned a scan's trees the wrong way were trusted 0.00002-0.07.
const CREASE_TRUST: f32 = 0.1;

/// [`orient`]'s turn of each tree (`tree`: each splat's root) toward the
/// viewpoints `views` (by the grid's order) of the points it took, and the
/// share of them that face away after it; where that share is at most
/// [`FACING_AWAY_MAX`] (the viewpoint holds), each splat then faces the
/// most of its own points' viewpoints.
fn face_the_scanners(splats: &mut [Grown], tree: &[u32], (views, pos): (&[Vec3], &[Vec3])) -> f64 {
    // Per splat, in one pass over its points' lines of sight: those seeing
    // it from the front and from behind, those that would see it face away
    // past the bound as it stands and turned over (`-n · s` is `n · s`
    // negated exactly), and all of them.
    let votes: Vec<[u32; 5]> = splats
        .par_iter()
        .map(|s| {
            let mut v = [0u32; 5];
            for &k in &s.members {
                if let Some(sight) = (views[k as usize] - pos[k as usize]).try_normalize() {
                    let c = s.normal.dot(sight);
                    v[0] += u32::from(c > 0.0);
                    v[1] += u32::from(c < 0.0);
                    v[2] += u32::from(c < FACING_AWAY_COS);
                    v[3] += u32::from(-c < FACING_AWAY_COS);
                    v[4] += 1;
                }
            }
            v
        })
        .collect();
    let all: usize = votes.iter().map(|v| v[4] as usize).sum();
    let mut balance = vec![0i64; splats.len()];
    for (t, v) in tree.iter().zip(&votes) {
        balance[*t as usize] += i64::from(v[0]) - i64::from(v[1]);
    }
    let turned = |t: u32| balance[t as usize] < 0;
    let away: usize = votes.iter().zip(tree).map(|(v, &t)| v[if turned(t) { 3 } else { 2 }] as usize).sum();
    let away = if all == 0 { 0.0 } else { away as f64 / all as f64 };
    // A viewpoint the trees bear out is the scanner's: each splat then
    // faces the points it took, whatever its tree's turn.
    let each = away <= FACING_AWAY_MAX;
    for (s, (v, &t)) in splats.iter_mut().zip(votes.iter().zip(tree)) {
        let (front, back) = if turned(t) { (v[1], v[0]) } else { (v[0], v[1]) };
        if turned(t) != (each && back > front) {
            s.normal = -s.normal;
        }
    }
    away
}

/// A splat's quadric height field `h = f + d x + e y + a x² + b x y + c y²`
/// over its axes `(u, v)` along its unit normal `n`, offsets from its
/// centre scaled by `1 / scale` (into the unit ball, `fit::height_rows`).
struct Quadric {
    n: DVec3,
    u: DVec3,
    v: DVec3,
    scale: f64,
    /// `[f, d, e, a, b, c]`.
    coef: [f64; 6],
}

/// The [`Quadric`] fitted to the heights of the points `s` took and of
/// those within its field's reach; `None` for too few points or a singular
/// fit.
fn quadric(g: &Grid, s: &Grown) -> Option<Quadric> {
    let offsets: Vec<Vec3> = (s.members.iter().chain(&s.extra))
        .map(|&k| g.pos[k as usize] - s.centre)
        .collect();
    let (Some((rows, scale)), Some((n, u, v))) = (height_rows(&offsets, s.normal, FIELD_MIN), height_axes(s.normal)) else {
        return None;
    };
    let (ata, atb) = normal_equations(&rows);
    let coef = solve6(ata, atb)?;
    Some(Quadric { n, u, v, scale, coef })
}

/// The splat of `s` with its normal field (eq. 4) from the quadric
/// `h = a x² + b x y + c y² + d x + e y + f` fitted to its points' heights
/// over its plane: the field's slopes along the quadric's principal
/// directions (its axes) are minus its curvatures times the radius, its
/// centre `(x_c, y_c)` minus the slopes `(d, e)`.
fn fitted(g: &Grid, s: &Grown) -> (Splat, bool) {
    let n = s.normal;
    let mut splat = Splat::disc(s.centre, n, s.radius).unwrap_or(Splat {
        center: s.centre,
        normal: Vec3::Z,
        u_axis: Vec3::X,
        v_axis: Vec3::Y,
        radii: Vec2::splat(s.radius),
        color: Vec3::ONE,
        field: NormalField::FLAT,
        clip: Clip::NONE,
    });
    let Some(Quadric { u: u0, v: v0, scale, coef: [_, d, e, a, b, c], .. }) = quadric(g, s) else {
        return (splat, true);
    };
    let (a, b, c) = (a / scale, b / scale, c / scale);
    // The Hessian [[2a, b], [b, 2c]]: its eigenvalues and first direction.
    let th = 0.5 * b.atan2(a - c);
    let (sn, cs) = th.sin_cos();
    let root = ((a - c) * (a - c) + b * b).sqrt();
    let (k1, k2) = (a + c + root, a + c - root);
    let (du, dv) = (d * cs + e * sn, -d * sn + e * cs);
    let r = f64::from(s.radius);
    let field = NormalField {
        xc: (-du) as f32,
        yc: (-dv) as f32,
        alpha: (-k1 * r) as f32,
        beta: (-k2 * r) as f32,
    };
    let u = (u0 * cs + v0 * sn).as_vec3();
    if ![field.xc, field.yc, field.alpha, field.beta].iter().all(|x| x.is_finite()) || !u.is_finite() {
        return (splat, true);
    }
    splat.u_axis = u;
    splat.v_axis = n.cross(u);
    splat.field = field;
    (splat, false)
}

/// The splat of `s` with its field ([`fitted`]) and its clip lines, in its
/// axes normalised by its radius.
fn finish(g: &Grid, s: &Grown) -> (Splat, bool) {
    let (mut splat, flat) = fitted(g, s);
    // In the splat's axes over its radius; none that is not finite (a
    // splat of coincident points, of radius 0).
    let line = |&(w, d): &sharp::Line| {
        let (a, b) = (w.dot(splat.u_axis), w.dot(splat.v_axis));
        let l = (a * a + b * b).sqrt();
        let line = ClipLine { a: a / l, b: b / l, d: d / s.radius };
        [line.a, line.b, line.d].iter().all(|x| x.is_finite()).then_some(line)
    };
    let lines: Vec<ClipLine> = s.clips.iter().flatten().filter_map(line).collect();
    splat.clip = match lines.as_slice() {
        [] => Clip::NONE,
        [x] => Clip::one(*x),
        [x, y, ..] => Clip::two(*x, *y),
    };
    (splat, flat)
}

/// Points a slab of the grid's order holds at most: slabs grow at once,
/// each seeding only from its own points and covering only them (a splat
/// takes its neighbours across the slab's ends too), so the splats do not
/// depend on the threads. Each pair of slabs meeting adds a band of
/// splats seeded twice.
pub const SLAB_POINTS: usize = 50_000;

/// Points of a large cloud the density pre-check ([`too_dense`]) reads.
const DENSE_SAMPLE: usize = 250_000;

/// The gate's figures on a stride sample of [`DENSE_SAMPLE`] of `points`,
/// its spacing scaled to the whole cloud's (by the square root of the
/// sample's share), where that spacing is under 0.8 of [`GATE_DENSE`]: a
/// cloud so dense the gate would refuse it, told without the whole cloud's
/// grid (9 s of 16M-point tiles' 68 s on a 100M-point cloud).
fn too_dense(points: &[Vec3], eps: f32, within: Option<[Vec3; 2]>) -> Option<Gate> {
    let n = points.len();
    if n < 4 * DENSE_SAMPLE {
        return None;
    }
    let stride = n / DENSE_SAMPLE;
    let sample: Vec<Vec3> = points.iter().step_by(stride).copied().collect();
    let g = Grid::build(&sample, CELL_EPS * eps, false);
    let (mut gate, _) = gate(&g, eps, GATE_SAMPLE / 4, within);
    gate.spacing *= (sample.len() as f32 / n as f32).sqrt();
    (gate.sampled > 0 && gate.spacing < 0.8 * GATE_DENSE).then_some(gate)
}

/// Whether `p` lies in the box `b` (every point without one).
fn inside(p: Vec3, b: Option<[Vec3; 2]>) -> bool {
    b.is_none_or(|[lo, hi]| p.cmpge(lo).all() && p.cmple(hi).all())
}

/// How a slab's seeds grow.
#[derive(Clone, Copy)]
enum Pass<'a> {
    /// Lean growth without clip lines.
    Plain,
    /// Sharp lean growth's first pass: splats with clip lines, a seed on a
    /// crease left for the second.
    SharpFirst,
    /// Its second: each point still uncovered on its face's plane
    /// ([`sharp::face_splat`]); `owner` is a point's splat of `grown` (an
    /// index past them: none, or a seed left as an outlier).
    SharpFaces { grown: &'a [Grown], owner: &'a [u32] },
}

/// The splats seeded from the points `range` of `g`'s order that lie in
/// `core` (their neighbours anywhere), and the seeds that grew none.
fn grow_slab(
    g: &Grid,
    range: std::ops::Range<usize>,
    growth: Growth,
    core: Option<[Vec3; 2]>,
    pass: Pass<'_>,
) -> (Vec<Grown>, Vec<u32>) {
    let start = range.start;
    let mut covered = match pass {
        Pass::SharpFaces { owner, .. } => range.clone().map(|i| owner[i] != u32::MAX).collect(),
        _ => vec![false; range.len()],
    };
    let mut near = Near::default();
    let (mut grown, mut outliers) = (Vec::new(), Vec::new());
    let sharp = !matches!(pass, Pass::Plain);
    for i in range.clone() {
        if covered[i - start] || !inside(g.pos[i], core) {
            continue;
        }
        covered[i - start] = true;
        let splat = match pass {
            Pass::SharpFaces { grown, owner } => sharp::face_splat(g, &mut near, i as u32, growth.eps, (grown, owner))
                .or_else(|| grow(g, &mut near, i as u32, (growth, true))),
            _ => grow(g, &mut near, i as u32, (growth, sharp)),
        };
        match splat {
            // Left for the faces' pass.
            Some(s) if s.hard && matches!(pass, Pass::SharpFirst) => covered[i - start] = false,
            Some(s) => {
                for &k in &s.members {
                    if range.contains(&(k as usize)) {
                        covered[k as usize - start] = true;
                    }
                }
                grown.push(s);
            }
            None => outliers.push(i as u32),
        }
    }
    (grown, outliers)
}

/// The grid's points `at` (indices into `g.pos`) as indices into the
/// `points` given, ascending: by the grid's order where it keeps one (a
/// scan's), else by their positions, in one pass over the points where
/// there are any (the grid's positions are the points as given; a copy
/// of a point shares its index set).
fn given_indices(points: &[Vec3], g: &Grid, at: &[u32]) -> Vec<u32> {
    let mut out: Vec<u32> = if at.is_empty() {
        Vec::new()
    } else if g.order.is_empty() {
        let bits = |p: Vec3| p.to_array().map(f32::to_bits);
        let wanted: std::collections::HashSet<[u32; 3]> = at.iter().map(|&i| bits(g.pos[i as usize])).collect();
        (0..points.len() as u32).filter(|&i| wanted.contains(&bits(points[i as usize]))).collect()
    } else {
        at.iter().map(|&i| g.order[i as usize]).collect()
    };
    out.sort_unstable();
    out
}

/// The points of `pos` (the grid's order) no splat of `grown` took within
/// `eps` of its plane (a taken point lies inside the splat's radius).
fn unsure(pos: &[Vec3], grown: &[Grown], eps: f32) -> Vec<Vec3> {
    let mut sure = vec![false; pos.len()];
    for s in grown {
        for &k in &s.members {
            let q = pos[k as usize];
            if !s.hard || s.normal.dot(q - s.centre).abs() <= eps {
                sure[k as usize] = true;
            }
        }
    }
    let off = sure.iter().zip(pos).filter(|(s, _)| !**s);
    off.map(|(_, &p)| p).collect()
}

/// Every slab's splats ([`grow_slab`]), and the seeds left as outliers
/// (grid order); with clip lines and a second pass over the points left on
/// creases where `sharp`.
fn grow_all(g: &Grid, growth: Growth, within: Option<[Vec3; 2]>, sharp: bool) -> (Vec<Grown>, Vec<u32>) {
    if !sharp {
        return every_slab(g, growth, within, Pass::Plain);
    }
    let (grown, outliers, _) = grow_all_then(g, growth, within, &|_| ());
    (grown, outliers)
}

/// Every slab grown at once by `pass`: their splats and outliers appended
/// in slab order.
fn every_slab(g: &Grid, growth: Growth, within: Option<[Vec3; 2]>, pass: Pass<'_>) -> (Vec<Grown>, Vec<u32>) {
    let per_slab: Vec<(Vec<Grown>, Vec<u32>)> = (0..slab_count(g))
        .into_par_iter()
        .map(|s| grow_slab(g, slab_range(g, s), growth, within, pass))
        .collect();
    let (mut grown, mut outliers) = (Vec::new(), Vec::new());
    for (g_s, o) in per_slab {
        grown.extend(g_s);
        outliers.extend(o);
    }
    (grown, outliers)
}

/// [`grow_all`] with clip lines: the first pass slab by slab, `then` run
/// on each slab's splats as soon as the slab is grown (on a thread the
/// other slabs leave idle), then the second pass ([`faces_pass`]) and
/// `then` on its splats. The splats, the outliers and `then`'s answers,
/// in the splats' order.
fn grow_all_then<T: Send>(
    g: &Grid,
    growth: Growth,
    within: Option<[Vec3; 2]>,
    then: &(dyn Fn(&[Grown]) -> T + Sync),
) -> (Vec<Grown>, Vec<u32>, Vec<T>) {
    let slabs = slab_count(g);
    type Slot<T> = std::sync::Mutex<Option<(Vec<Grown>, Vec<u32>, T)>>;
    let slots: Vec<Slot<T>> = (0..slabs).map(|_| std::sync::Mutex::new(None)).collect();
    rayon::scope_fifo(|sc| {
        for s in 0..slabs {
            let slots = &slots;
            sc.spawn_fifo(move |sc| {
                let (grown, outliers) = grow_slab(g, slab_range(g, s), growth, within, Pass::SharpFirst);
                sc.spawn_fifo(move |_| {
                    let t = then(&grown);
                    *slots[s].lock().unwrap_or_else(std::sync::PoisonError::into_inner) = Some((grown, outliers, t));
                });
            });
        }
    });
    let (mut grown, mut outliers, mut answers) = (Vec::new(), Vec::new(), Vec::new());
    for slot in slots {
        let (g_s, o, t) = slot.into_inner().unwrap_or_else(std::sync::PoisonError::into_inner).expect("every slab grown");
        grown.extend(g_s);
        outliers.extend(o);
        answers.push(t);
    }
    let (mut more, mut left) = faces_pass(g, growth, within, (&grown, &outliers));
    answers.push(then(&more));
    grown.append(&mut more);
    outliers.append(&mut left);
    (grown, outliers, answers)
}

/// Slabs of [`SLAB_POINTS`] in the grid's order (at least one).
fn slab_count(g: &Grid) -> usize {
    g.pos.len().div_ceil(SLAB_POINTS).max(1)
}

/// The points of slab `s` of [`slab_count`], as a range of the grid's order.
fn slab_range(g: &Grid, s: usize) -> std::ops::Range<usize> {
    let (n, slabs) = (g.pos.len(), slab_count(g));
    s * n / slabs..(s + 1) * n / slabs
}

/// Sharp lean growth's second pass over every slab, after the first grew
/// `grown` and left `outliers`: its splats and outliers, in slab order.
fn faces_pass(
    g: &Grid,
    growth: Growth,
    within: Option<[Vec3; 2]>,
    (grown, outliers): (&[Grown], &[u32]),
) -> (Vec<Grown>, Vec<u32>) {
    // Each point's splat (past them: none), an outlier seed as covered.
    let mut owner = vec![u32::MAX; g.pos.len()];
    for &i in outliers {
        owner[i as usize] = u32::MAX - 1;
    }
    for (i, s) in grown.iter().enumerate() {
        for &k in &s.members {
            owner[k as usize] = i as u32;
        }
    }
    every_slab(g, growth, within, Pass::SharpFaces { grown, owner: &owner })
}

/// Whether [`grow_lean`] grows splats after measuring its gate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GrowWhen {
    /// Where the gate passes.
    Gated,
    /// Where the gate passes, else with clip lines ([`sharp`]) where
    /// [`Gate::sharp_passes`].
    GatedSharp,
    /// Whatever the gate found.
    Always,
    /// Whatever the gate found, with clip lines.
    AlwaysSharp,
    /// Whatever the gate found, a scan's points settled first ([`settle`]).
    AlwaysSettled,
    /// Never (the gate's figures alone).
    Never,
}

/// Lean growth over `points` at error `eps` (see the module's
/// documentation): the gate, and the splats when `when` says so. Where
/// `within` (a tile's core) is given, the gate samples only its points and
/// only they seed splats (the halo's are taken, never seeded: a splat
/// centred in the core covers every core point). A scan's `views` (where
/// each point was seen from) turn its splats toward its scanners and its
/// curved silhouettes keep their borders open ([`SCAN_BEND`]). `progress`
/// is told when growth is done, on the calling thread.
#[must_use]
pub fn grow_lean(
    points: &[Vec3],
    eps: f32,
    (when, within, views): (GrowWhen, Option<[Vec3; 2]>, Option<&Viewpoints>),
    progress: impl Fn(f64),
) -> Lean {
    let t0 = std::time::Instant::now();
    // Nothing grown yet: the gate's figures and the seconds so far.
    let none = |gate: Gate| Lean {
        splats: Vec::new(),
        gate,
        outliers: 0,
        outlier_points: Vec::new(),
        facing_away: None,
        unsure_points: Vec::new(),
        largest_over_spacing: 0.0,
        flat_fields: 0,
        sharp: false,
        settled: false,
        clipped: 0,
        widened: 0,
        seconds: [t0.elapsed().as_secs_f64(), 0.0, 0.0, 0.0],
    };
    // Growing whatever the gate finds (the held-out check's windows, a few
    // thousand points each), its figures serve only the median spacing and
    // a settled window's scatter: a sample of ALWAYS_SAMPLE. (Settled
    // windows sampled GATE_SAMPLE of their 8k points before: a quarter of
    // the held-out check's time on the noisy scan, its coverage the same
    // within two points of 360 on four scans; `docs/notes/generation.md`,
    // "Issue 54, sixty-sixth session".)
    let always = matches!(when, GrowWhen::Always | GrowWhen::AlwaysSharp | GrowWhen::AlwaysSettled);
    if !always && let Some(dense) = too_dense(points, eps, within) {
        return none(Gate {
            scan: views.is_some(),
            ..dense
        });
    }
    let g = Grid::build(points, CELL_EPS * eps, views.is_some());
    let most = if always { ALWAYS_SAMPLE } else { GATE_SAMPLE };
    let (gate, spacing) = gate(&g, eps, most, within);
    let gate = Gate {
        scan: views.is_some(),
        ..gate
    };
    let mut lean = none(gate);
    // (with clip lines, the points settled first)
    let grow_now = match when {
        GrowWhen::Gated => Some((false, false)).filter(|_| gate.passes()),
        GrowWhen::GatedSharp if gate.passes() => Some((false, false)),
        GrowWhen::GatedSharp if gate.settle_passes() => Some((true, true)),
        GrowWhen::GatedSharp => Some((true, false)).filter(|_| gate.sharp_passes()),
        GrowWhen::Always => Some((false, false)),
        GrowWhen::AlwaysSharp => Some((true, false)),
        GrowWhen::AlwaysSettled => Some((true, views.is_some())),
        GrowWhen::Never => None,
    };
    let Some((sharp, settled)) = grow_now else {
        return lean;
    };
    (lean.sharp, lean.settled) = (sharp, settled);
    let t1 = std::time::Instant::now();
    let growth = Growth {
        eps,
        slab: GROW_EPS * eps,
        far: OUTLIER_SPACINGS * spacing,
        scanners: views.map(|v| (v, gate.sigma * eps)),
    };
    let g = match views {
        Some(views) if settled => Grid::build(&settle::settle(&g, growth, within, views, gate.sigma * eps), g.h, true),
        _ => g,
    };
    let (mut grown, outliers) = grow_all(&g, growth, within, sharp);
    lean.outliers = outliers.len();
    lean.outlier_points = given_indices(points, &g, &outliers);
    lean.clipped = grown.iter().filter(|s| s.clips.iter().any(Option::is_some)).count();
    // A settled point is sure where the point as given lies on its splat.
    let given: Vec<Vec3> = if settled { g.order.iter().map(|&i| points[i as usize]).collect() } else { Vec::new() };
    lean.unsure_points = unsure(if settled { &given } else { &g.pos }, &grown, eps);
    lean.largest_over_spacing = grown
        .iter()
        .map(|s| s.radius / s.spacing)
        .filter(|x| x.is_finite())
        .fold(0.0, f32::max);
    progress(1.0);
    let t2 = std::time::Instant::now();
    // Where each point of the grid's order was seen from.
    let seen: Option<Vec<Vec3>> = views.map(|v| g.order.iter().map(|&i| v.at(i as usize)).collect());
    let links = links(&grown, g.pos.len(), views.is_some());
    lean.facing_away = orient(&mut grown, &links, seen.as_deref().map(|v| (v, g.pos.as_slice())));
    lean.widened = gaps::close_pinholes(&mut grown, &links, eps);
    drop(links);
    let t3 = std::time::Instant::now();
    let finished: Vec<(Splat, bool)> = grown.par_iter().map(|s| finish(&g, s)).collect();
    lean.flat_fields = finished.iter().filter(|f| f.1).count();
    lean.splats = finished.into_iter().map(|f| f.0).collect();
    lean.seconds[1] = (t2 - t1).as_secs_f64();
    lean.seconds[2] = (t3 - t2).as_secs_f64();
    lean.seconds[3] = t3.elapsed().as_secs_f64();
    lean
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// A search gives every point in order of distance (then index), as
    /// sorting all of them does: a wavy sheet and a scatter far from the
    /// origin, searched from its points and from empty space, out to the
    /// distance within which [`MAX_SHELL`] shells hold every point.
    #[test]
    fn a_search_gives_the_points_nearest_first() {
        let mut rng = SplitMix64::new(11);
        let base = Vec3::new(3.0e3, -1.0e3, 50.0);
        let mut pts: Vec<Vec3> = (0..20_000)
            .map(|_| {
                let (x, z) = (rng.next_f32() * 40.0, rng.next_f32() * 40.0);
                base + Vec3::new(x, (x * 0.3).sin() * 2.0 + rng.next_f32() * 0.2, z)
            })
            .collect();
        pts.extend((0..2_000).map(|_| base + Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 40.0));
        let g = Grid::build(&pts, 1.0, false);
        let mut near = Near::default();
        let mut checked = 0;
        for q in 0..60 {
            let p = if q % 2 == 0 { g.pos[q * 331] } else { base + Vec3::new(rng.next_f32(), 0.5, rng.next_f32()) * 40.0 };
            let mut all: Vec<u64> = g.pos.iter().enumerate().map(|(j, x)| key(x.distance_squared(p), j as u32)).collect();
            all.sort_unstable();
            near.start(&g, p);
            // Within MAX_SHELL cells every point has been gathered.
            let bound = (MAX_SHELL as f32 * g.h).powi(2);
            for (j, &k) in all.iter().enumerate().take_while(|(_, k)| unkey(**k).0 < bound) {
                assert_eq!(near.get(&g, j), Some(unkey(k)), "query {q}, neighbour {j}");
                checked += 1;
            }
        }
        // Measured: 64,304 neighbours checked.
        assert!(checked > 50_000, "{checked}");
    }

    /// The nearest taken unordered are the ones a search in order gives,
    /// and the search going on after them gives them in order: a
    /// jittered sheet, from its points and from beside it, 52 to 3,328 at a
    /// time (the last past what [`MAX_SHELL`] cells hold: none then, as a
    /// search in order finds fewer).
    #[test]
    fn the_nearest_unordered_are_the_nearest() {
        let mut rng = SplitMix64::new(5);
        let pts: Vec<Vec3> = (0..30_000)
            .map(|_| Vec3::new(rng.next_f32() * 30.0, rng.next_f32() * 0.3, rng.next_f32() * 30.0))
            .collect();
        let g = Grid::build(&pts, 0.5, false);
        let (mut near, mut ordered) = (Near::default(), Near::default());
        let (mut compared, mut short) = (0, 0);
        for q in 0..40 {
            let p = if q % 2 == 0 { g.pos[q * 701] } else { g.pos[q * 701] + Vec3::new(0.1, 0.4, -0.2) };
            // As growth asks: its nearest in order, then ever more, unordered,
            // on the same search, then in order again.
            near.start(&g, p);
            ordered.start(&g, p);
            assert_eq!(near.get(&g, K0), ordered.get(&g, K0));
            for n in [52, 208, 832, 3328] {
                let Some(keys) = near.nearest_unordered(&g, n) else {
                    // Fewer than n within MAX_SHELL cells, as in order.
                    assert_eq!(ordered.get(&g, n - 1), None, "query {q}, {n} nearest");
                    short += 1;
                    continue;
                };
                let mut keys = keys.to_vec();
                keys.sort_unstable();
                let first: Vec<u64> = (0..n).map(|j| ordered.get(&g, j).map(|(d2, k)| key(d2, k)).unwrap()).collect();
                assert_eq!(keys, first, "query {q}, {n} nearest");
                compared += 1;
            }
            for j in [K0 + 1, 40, 100, 500, 900] {
                assert_eq!(near.get(&g, j), ordered.get(&g, j), "query {q}, neighbour {j}");
            }
        }
        // Measured: 119 compared, 41 short (every query at 3,328, and at
        // 832 the grid's first point, in a corner of the sheet).
        assert!(compared >= 110 && short <= 45, "{compared} compared, {short} short");
    }
}
