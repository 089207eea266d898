//! Sharp lean growth: clip lines for lean splats at creases and borders
//! (issue 54), so that a cloud with flat faces meeting at edges (a
//! sampled solid, a CAD model, an airborne survey's buildings) grows lean
//! instead of by the stages.
//!
//! A lean splat stops where its neighbours leave its slab (a crease) or
//! where there are none (a border), but its disc reaches [`super::SCALE`]
//! past the first point it did not take: over a crease onto the other
//! face, past a border into the void. Its clip lines (the report's
//! `Clip`, §2.3's sharp features) cut that part off:
//!
//! - **Across a crease** ([`meet_line`]): the points within the disc that
//!   left the slab, lying to one side and on a plane of their own at least
//!   [`CREASE_SIN`] off the splat's, give the crease as the line where the
//!   two planes meet.
//! - **At a crease too few points cross** ([`stop_line`]): one to three
//!   points within the disc lie more than [`STOP_SLABS`] slabs off its
//!   plane, to one side (a small splat grown beside an edge): the line
//!   through its own points' farthest reach toward them.
//! - **At a border** ([`border_lines`]): in one of [`DIRS`] directions the
//!   splat's points reach less than [`BORDER_FRAC`] of its radius, where
//!   its points' density would put at least [`BORDER_EXPECTED`] of them
//!   beyond (a random gap between samples rarely holds that many), and no
//!   point in the slab lies farther on that side (the surface does not go
//!   on past a gap): the line through the farthest point on that side.
//!
//! A seed whose nearest already leave the slab (a seed on the crease
//! itself) grows no splat of its own at first; once every other seed has
//! grown, each point left uncovered takes the plane of the neighbouring
//! splat it lies nearest ([`face_splat`]), its points in that plane's slab
//! within [`FACE_REACH`] of its [`super::K0`]-th neighbour's distance, so
//! the faces reach the crease from both sides.

use super::{GROW_EPS, Grid, Grown, K0, Near, SCALE};
use crate::splat::fit::plane_fit;
use glam::Vec3;

/// The gate's most median distance to a point's [`K0`]-th neighbour, in
/// `ϵ`, for sharp lean growth: a gable roof of 8,000 points at 7.9 grew
/// 1,147 lean splats against the stages' 239 (lean growth's radius stops
/// at `MAX_RADIUS_EPS`, about a spacing there); the solids' 60k samples
/// read 3.8, 300k 1.7, a half sphere 2.9.
pub const SHARP_SPARSE: f32 = 5.0;

/// The least sine between a splat's plane and the plane of the points
/// across a crease: the clean solids' creases read 0.95-1.0, the 200k
/// bunny's bends that leave a splat's slab 0.26-0.93 (median 0.38).
pub const CREASE_SIN: f32 = 0.7;

/// Fewest points across a crease its plane is fitted to.
pub const ACROSS_MIN: usize = 4;

/// The points across lie to one side: the mean of their unit directions
/// from the centre is at least this long (a half disc's 0.64, a bend all
/// round near 0).
const ACROSS_SIDE: f32 = 0.5;

/// A point across a crease too few cross to fit a plane to lies at least
/// this many growth slabs off the disc's plane (noise reaches past one).
/// The solids' 300k samples, mean of five views against the mesh over
/// the stages: +1.55 -> +2.06 dB exact, +0.23 -> +0.65 at 0.013 `ϵ` of
/// scatter, -0.50 -> -0.02 at 0.037 (at 1 slab +2.01, +0.72, -0.05; at 3
/// -0.13 at 0.037); the default survey 29.52 -> 29.63 dB at 800×600 (at 1
/// slab 29.41: noise across).
pub const STOP_SLABS: f32 = 2.0;

/// Directions a border is looked for in.
pub const DIRS: usize = 16;

/// A border where the splat's points reach less than this share of its
/// radius in a direction.
pub const BORDER_FRAC: f32 = 0.8;

/// ... and the points expected beyond them there, at the density of the
/// splat's own, are at least this many (a random gap between samples
/// rarely holds that many). The solids' 60k exact samples: 30.36 dB and
/// 0.13 % false hits at 4, 29.38 dB and 0.41 % at 6 (the ground's border
/// let through), 35.3 dB at 300k at 8; a half sphere (scatter 0.009 `ϵ`)
/// at 4 clips 115 of 2,272 splats, all on its rim. Plain lean growth's
/// clouds stay without: on the 200k bunny 4 clipped 1,116 of 13,571
/// splats at random gaps, 6 clipped 230 and cost 0.3 dB.
pub const BORDER_EXPECTED: f32 = 4.0;

/// A point in the slab farther than this many [`K0`]-th neighbour
/// distances beyond the farthest point on a side shows the surface goes
/// on (a gap between samples, not a border).
const GOES_ON: f32 = 0.5;

/// A field's points beyond its seed's points lie within this many growth
/// slabs of its plane (a curved face's reach; the other face's points
/// bend a crease splat's field).
pub const FIELD_SLABS: f32 = 2.0;

/// A crease point's splat takes its face's points within this many of its
/// [`K0`]-th neighbour's distance.
pub const FACE_REACH: f32 = 2.0;

/// A clip line of a splat in the cloud's frame: the kept side is
/// `w · (x - centre) <= d` for `x` in the splat's plane, `w` a unit vector
/// in that plane.
pub type Line = (Vec3, f32);

/// The part of `q - centre` in the plane of normal `n`.
fn flat(n: Vec3, centre: Vec3, q: Vec3) -> Vec3 {
    let d = q - centre;
    d - n * n.dot(d)
}

/// What one splat's clip lines are found from.
pub struct Disc<'a> {
    pub g: &'a Grid,
    pub centre: Vec3,
    pub normal: Vec3,
    /// The disc's radius (after [`SCALE`]).
    pub radius: f32,
    /// The points it took.
    pub members: &'a [u32],
    /// Points near it it did not take.
    pub others: &'a [u32],
    /// Half-width of its slab.
    pub slab: f32,
    /// Its seed's [`K0`]-th neighbour's distance.
    pub spacing: f32,
}

impl Disc<'_> {
    fn flat(&self, k: u32) -> Vec3 {
        flat(self.normal, self.centre, self.g.pos[k as usize])
    }

    /// The points near it that left its slab, within its radius along its
    /// plane.
    fn across(&self) -> Vec<Vec3> {
        let n = self.normal;
        (self.others.iter())
            .map(|&k| self.g.pos[k as usize])
            .filter(|&q| n.dot(q - self.centre).abs() > self.slab && flat(n, self.centre, q).length() <= self.radius)
            .collect()
    }

    /// The sum of the unit directions in its plane toward `across`, where
    /// they lie to one side (the sum at least [`ACROSS_SIDE`] of their
    /// count long).
    fn to_one_side(&self, across: &[Vec3]) -> Option<Vec3> {
        let side = across.iter().map(|&q| flat(self.normal, self.centre, q).normalize_or_zero()).sum::<Vec3>();
        (side.length() >= ACROSS_SIDE * across.len() as f32).then_some(side)
    }

    /// How far its points reach along `w`.
    fn reach(&self, w: Vec3) -> f32 {
        self.members.iter().map(|&k| self.flat(k).dot(w)).fold(f32::MIN, f32::max)
    }
}

/// The clip lines ([`lines`]) of a splat (its centre, normal and radius)
/// grown in a slab of half-width `slab` from a seed whose [`K0`]-th
/// neighbour lies `spacing` away, and `extra` (its field's points beyond
/// its own) cut to those on the kept side within [`FIELD_SLABS`] slabs of
/// its plane: the other face's points bend a quadric fitted across a
/// crease.
pub fn clip(
    g: &Grid,
    (centre, normal, radius): (Vec3, Vec3, f32),
    (slab, spacing): (f32, f32),
    members: &[u32],
    extra: &mut Vec<u32>,
) -> [Option<Line>; 2] {
    let clips = lines(&Disc { g, centre, normal, radius, members, others: extra, slab, spacing });
    let near_plane = FIELD_SLABS * slab;
    extra.retain(|&k| {
        let q = g.pos[k as usize];
        normal.dot(q - centre).abs() <= near_plane && kept(&clips, normal, centre, q)
    });
    clips
}

/// The splat's clip lines (at most two), across a crease first.
#[must_use]
pub fn lines(s: &Disc<'_>) -> [Option<Line>; 2] {
    let across = s.across();
    let mut out = [meet_line(s, &across).or_else(|| stop_line(s, &across)), None];
    border_lines(s, &mut out);
    out
}

/// The crease the points across the disc show, if they do.
/// (`across`: [`Disc::across`]).
fn meet_line(s: &Disc<'_>, across: &[Vec3]) -> Option<Line> {
    let n = s.normal;
    if across.len() < ACROSS_MIN {
        return None;
    }
    s.to_one_side(across)?;
    let (c2, vals, vecs) = plane_fit(across.iter().copied());
    let (c2, n2) = (c2.as_vec3(), vecs[0].as_vec3());
    let scatter = (vals[0].max(0.0) / across.len() as f64).sqrt() as f32;
    let m = n2 - n * n.dot(n2);
    let sin = m.length();
    if !(sin > CREASE_SIN && scatter <= s.slab && n2.is_finite() && c2.is_finite()) {
        return None;
    }
    // Points x of the plane with n2 · (x - c2) = 0: m · f = n2 · (c2 - centre).
    let (mut w, mut d) = (m / sin, n2.dot(c2 - s.centre) / sin);
    let mean = s.members.iter().map(|&k| s.flat(k)).sum::<Vec3>() / s.members.len() as f32;
    if w.dot(mean) > d {
        (w, d) = (-w, -d);
    }
    (d < s.radius && (d - s.reach(w)).abs() <= s.spacing).then_some((w, d))
}

/// Where one to three points more than [`STOP_SLABS`] slabs off the
/// disc's plane lie within it, to one side (too few to fit the plane
/// across a crease): the line through its own points' farthest reach
/// toward them (`across`: the points that left its slab, [`Disc::across`]).
fn stop_line(s: &Disc<'_>, across: &[Vec3]) -> Option<Line> {
    let off = STOP_SLABS * s.slab;
    let across: Vec<Vec3> = (across.iter().copied())
        .filter(|&q| s.normal.dot(q - s.centre).abs() > off)
        .collect();
    if across.is_empty() || across.len() >= ACROSS_MIN {
        return None;
    }
    let w = s.to_one_side(&across)?.normalize_or_zero();
    let d = s.reach(w);
    (w.is_finite() && d > 0.0 && d < s.radius).then_some((w, d))
}

/// Adds the borders of the disc to `out`'s free places, nearest first,
/// none within 60° of a line it has.
fn border_lines(s: &Disc<'_>, out: &mut [Option<Line>; 2]) {
    let (t1, t2) = s.normal.any_orthonormal_pair();
    let dirs: [Vec3; DIRS] = std::array::from_fn(|i| {
        let a = i as f32 * std::f32::consts::TAU / DIRS as f32;
        t1 * a.cos() + t2 * a.sin()
    });
    // Each point's reach along every direction in one pass over the
    // points (the same products and maxima as `Disc::reach` direction by
    // direction), the directions' components apart so the lanes line up.
    let (dx, dy, dz): ([f32; DIRS], [f32; DIRS], [f32; DIRS]) = (
        std::array::from_fn(|i| dirs[i].x),
        std::array::from_fn(|i| dirs[i].y),
        std::array::from_fn(|i| dirs[i].z),
    );
    let (mut h, mut ext) = ([f32::MIN; DIRS], 0.0f32);
    for &k in s.members {
        let f = s.flat(k);
        for i in 0..DIRS {
            h[i] = h[i].max(f.x * dx[i] + f.y * dy[i] + f.z * dz[i]);
        }
        ext = ext.max(f.length());
    }
    let density = s.members.len() as f32 / (std::f32::consts::PI * ext * ext);
    // Area of the circle of radius `ext` beyond the chord at `x`.
    let beyond = |x: f32| {
        let c = (x / ext).clamp(-1.0, 1.0);
        ext * ext * (c.acos() - c * (1.0 - c * c).max(0.0).sqrt())
    };
    let mut order: [usize; DIRS] = std::array::from_fn(|i| i);
    order.sort_by(|&a, &b| h[a].total_cmp(&h[b]).then(a.cmp(&b)));
    for i in order {
        let Some(free) = out.iter().position(Option::is_none) else {
            return;
        };
        let expected = density * beyond(h[i]);
        if h[i] >= BORDER_FRAC * s.radius || expected.is_nan() || expected < BORDER_EXPECTED {
            return;
        }
        let w = dirs[i];
        let apart = out.iter().flatten().all(|(v, _)| v.dot(w) < 0.5);
        if apart && !goes_on(s, w, h[i]) {
            out[free] = Some((w, h[i]));
        }
    }
}

/// Whether a point in the slab lies well past `h` along `w`, near the disc
/// (in a scan's, within the slab widened by [`super::SCAN_BEND`] times its
/// distance past `h`: a surface curving away toward its silhouette).
fn goes_on(s: &Disc<'_>, w: Vec3, h: f32) -> bool {
    let n = s.normal;
    s.others.iter().any(|&k| {
        let q = s.g.pos[k as usize];
        let f = flat(n, s.centre, q);
        let along = f.dot(w);
        n.dot(q - s.centre).abs() <= s.slab + s.g.bend * (along - h)
            && along > h + GOES_ON * s.spacing
            && f.length() <= 1.2 * s.radius
    })
}

/// Whether `q` lies on the kept side of every line.
#[must_use]
fn kept(lines: &[Option<Line>; 2], n: Vec3, centre: Vec3, q: Vec3) -> bool {
    let f = flat(n, centre, q);
    lines.iter().flatten().all(|(w, d)| w.dot(f) <= *d)
}

/// The splat of the uncovered point `i` on the plane of the splat of
/// `grown` that took one of its [`K0`] nearest and whose plane it lies
/// nearest, within the growth slab (`owner`: a point's splat, `u32::MAX`
/// none); `None` where no such splat is.
pub fn face_splat(g: &Grid, near: &mut Near, i: u32, eps: f32, (grown, owner): (&[Grown], &[u32])) -> Option<Grown> {
    let p = g.pos[i as usize];
    let slab = GROW_EPS * eps;
    near.start(g, p);
    let (mut best, mut spacing) = (None::<(f32, usize)>, 0.0);
    for j in 1..=K0 {
        let (d2, k) = near.get(g, j)?;
        spacing = d2.sqrt();
        let o = owner[k as usize];
        if (o as usize) < grown.len() {
            let s = &grown[o as usize];
            let h = s.normal.dot(p - s.centre).abs();
            if best.is_none_or(|(b, _)| h < b) {
                best = Some((h, o as usize));
            }
        }
    }
    let (h, o) = best?;
    if h > slab {
        return None;
    }
    let (n, c) = (grown[o].normal, grown[o].centre);
    let reach = FACE_REACH * spacing;
    let (mut members, mut others) = (vec![i], Vec::new());
    let mut j = 1;
    while let Some((d2, k)) = near.get(g, j) {
        if d2 > (1.3 * reach) * (1.3 * reach) || d2 > near.sure * near.sure {
            break;
        }
        if d2 <= reach * reach && n.dot(g.pos[k as usize] - c).abs() <= slab {
            members.push(k);
        } else {
            others.push(k);
        }
        j += 1;
    }
    let centre = p - n * n.dot(p - c);
    let far = members.iter().map(|&k| g.pos[k as usize].distance(centre)).fold(0.0, f32::max);
    let radius = far.max(0.5 * spacing) * SCALE;
    let disc = Disc { g, centre, normal: n, radius, members: &members, others: &others, slab, spacing };
    let clips = lines(&disc);
    Some(Grown { centre, normal: n, radius, members, extra: Vec::new(), spacing, hard: false, clips })
}
