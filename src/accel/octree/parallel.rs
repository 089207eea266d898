//! The shadow rays of one directional light (issue 55): every one leaves
//! its hit along the same direction, bit for bit, so a primitive it can
//! meet is one whose shadow, cast along that direction onto a plane
//! across it, holds the ray's origin's. The primitives' shadows are
//! filed once a render in the cells of a uniform grid on that plane, and
//! such a ray is tested against its cell's list instead of descending the
//! octree.
//!
//! In the basis `(u, v, w)`, `w` the light's unit direction (toward the
//! light), a point `p` falls on the plane at `(p·u, p·v)` and stands at
//! height `p·w`. A primitive's ball (centre `c`, its
//! [`Primitive::bounding_radius`] `R` grown by [`MARGIN`] of the scene's
//! size) falls on the rectangle `c·u ± R`, `c·v ± R`, and an ellipse's
//! (disc's) points within that margin on the narrower `c·e ± (|(a·e,
//! b·e)| + margin)`; no point of it stands higher than `c·w` plus the same
//! reach along `w`, its top.
//!
//! Why the answers are the octree's, bit for bit (`docs/DESIGN.md`, "The
//! backend contract", rule 1): a hit the f32 test [`Primitive::intersect`]
//! accepts at `t` has the exact point `o + t d` within a few ulps of the
//! coordinates the test works with of the primitive (the fan's argument,
//! `fan`'s module doc); a ray is taken only while its origin, and so
//! those coordinates, lie within the scene's size of the world's origin,
//! where the margin is about forty ulps of them. That point falls on the plane
//! where the origin does, up to `t |d|` times the basis' rounding (a few
//! parts in 10^16), and stands at least `o·w + t_min |d|` high. So where
//! the origin falls [`EDGE`] of a cell (plus that drift) inside one cell,
//! every primitive the ray can hit is in that cell's list with its top at
//! least that high; the lists run from the highest top down, and a ray
//! stops at the first pack whose top lies below its origin's height. The
//! any-hit test does not depend on the order (each candidate is kept or
//! skipped on its own), so the answer is the octree's. A ray along
//! another direction, from `t_min < 0`, from far outside the scene, or in
//! a cell whose list is long (as a camera fan's block's, `bins`) is the
//! octree's own.

use super::bins::pack_starts;
use super::fan::grid_size;
use super::traverse::{AnyHit, RunsAnyHit, Visitor, occluded_by, occluded_split};
use super::{NO_PRIMITIVE, Octree, lanes};
use crate::accel::{Backend, BuildStats, CandidateHits, Query, Skip};
use crate::primitive::{Pack, Primitive};
use glam::{DVec3, Vec3};
use rayon::prelude::*;

/// A ball's radius grows by this fraction of the scene's size (the most
/// `|c| + R` of its primitives, from the world's origin), covering the
/// exact test's rounding.
const MARGIN: f64 = 1e-5;

/// How far inside its cell, in cells, a ray's origin falls for the cell's
/// list to answer it, beyond the drift of its hits (far above the f64
/// rounding of the projections; cells number at most 2^20).
const EDGE: f64 = 1e-6;

/// Primitives a cell, on the mean, the grid is sized for.
const PRIMS_PER_CELL: f64 = 2.0;

/// Most list entries in all, per ray the render expects along the light:
/// beyond it the lists are not built (their memory and building would not
/// pay).
const MAX_ENTRIES_PER_RAY: usize = 1;

/// Fewest rays for which the lists are built.
const MIN_RAYS: usize = 4096;

/// Least ratio of rays to primitives for which the lists are built: a
/// primitive's shadow meets 4-11 cells (measured on the bundled scenes and
/// a 200k-point bunny sample's splats), so fewer rays would mostly find
/// the lists past [`MAX_ENTRIES_PER_RAY`] after the primitives' copy.
const RAYS_PER_PRIMITIVE: usize = 12;

/// The shadows' lists of one direction, and the backend answering the
/// rays along it from them (module doc).
pub(super) struct Parallel<'a, P: Primitive> {
    oct: &'a Octree<P>,
    /// The rays' direction's bits.
    dir: [u32; 3],
    u: DVec3,
    v: DVec3,
    w: DVec3,
    /// The grid: lower corner on the plane, cells per unit, cells per axis.
    lo: [f64; 2],
    scale: f64,
    n: [usize; 2],
    /// The scene's size: the most `|c| + R` of its primitives.
    size: f64,
    /// The rays' `|d|`.
    len: f64,
    /// How far inside its cell a ray's origin falls ([`EDGE`], and a hit
    /// lies within about twice the size of the origin, so `t |d|` times
    /// the basis' rounding is far below the rest), in cells.
    edge: f64,
    /// Per cell, the first of its packs; the last entry ends the last
    /// cell's.
    first: Vec<u32>,
    /// Per cell, whether its list is too long to be kept.
    long: Vec<bool>,
    /// The lists' primitives, packs cell after cell, highest top first.
    packs: Vec<P::Pack>,
    /// The primitive id of each lane of `packs` ([`NO_PRIMITIVE`] on
    /// padding).
    ids: Vec<u32>,
    /// Per pack, its first lane's top rounded up: no point its lanes'
    /// exact tests accept stands higher.
    top: Vec<f32>,
}

/// What one primitive's shadow covers: cells `[i0, i1, j0, j1]` and its
/// top.
type Shadow = ([usize; 4], f64);

impl<P: Primitive> Octree<P> {
    /// The lists of the rays along `dir` (about `rays` of them, the
    /// shadow rays of a directional light): `None` when they would not pay
    /// (too few rays for the primitives, or more entries than
    /// [`MAX_ENTRIES_PER_RAY`] a ray) or the direction or a primitive is
    /// not finite.
    pub(super) fn build_parallel(&self, dir: Vec3, rays: usize) -> Option<Parallel<'_, P>> {
        if rays < MIN_RAYS.max(RAYS_PER_PRIMITIVE * self.count) || !dir.is_finite() {
            return None;
        }
        let w = dir.as_dvec3().try_normalize()?;
        let u = w.any_orthonormal_vector();
        let v = w.cross(u);
        let (ids, prims) = self.primitives();
        let size = prims
            .par_iter()
            .map(|p| f64::from(p.center().length()) + f64::from(p.bounding_radius()))
            .reduce(|| 0.0, f64::max);
        if !size.is_finite() {
            return None;
        }
        let margin = MARGIN * size;
        // Each primitive's reach along `u`, `v` and `w` from its centre.
        let reach = |p: &P| -> [f64; 3] {
            let r = f64::from(p.bounding_radius()) + margin;
            match p.semi_axes() {
                Some((a, b)) => {
                    let (a, b) = (a.as_dvec3(), b.as_dvec3());
                    [u, v, w].map(|e| a.dot(e).hypot(b.dot(e)) + margin).map(|x| x.min(r))
                }
                None => [r; 3],
            }
        };
        // (`size`'s `max` passes a NaN over: each span is checked.)
        let spans: Vec<([f64; 4], f64)> = prims
            .par_iter()
            .map(|p| {
                let c = p.center().as_dvec3();
                let [ru, rv, rw] = reach(p);
                let (cu, cv) = (c.dot(u), c.dot(v));
                let span = [cu - ru, cu + ru, cv - rv, cv + rv];
                let top = c.dot(w) + rw;
                (span.iter().all(|x| x.is_finite()) && top.is_finite()).then_some((span, top))
            })
            .collect::<Option<_>>()?;
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for (s, _) in &spans {
            lo = [lo[0].min(s[0]), lo[1].min(s[2])];
            hi = [hi[0].max(s[1]), hi[1].max(s[3])];
        }
        if spans.is_empty() {
            return None;
        }
        let (scale, n) = grid_size(lo, hi, prims.len() as f64 / PRIMS_PER_CELL);
        let cell = |x: f64, a: usize| {
            let at = (x - lo[a]) * scale;
            if at > 0.0 { (at as usize).min(n[a] - 1) } else { 0 }
        };
        let shadows: Vec<Shadow> = spans
            .par_iter()
            .map(|&([u0, u1, v0, v1], top)| {
                let pad = |x: f64| 1e-9 * (size + x.abs());
                let cells = [
                    cell(u0 - pad(u0), 0),
                    cell(u1 + pad(u1), 0),
                    cell(v0 - pad(v0), 1),
                    cell(v1 + pad(v1), 1),
                ];
                (cells, top + pad(top))
            })
            .collect();
        let entries: usize = shadows.iter().map(|([i0, i1, j0, j1], _)| (i1 - i0 + 1) * (j1 - j0 + 1)).sum();
        if entries > MAX_ENTRIES_PER_RAY * rays {
            return None;
        }
        let (first, long, slots, top) = fill::<P>(n, &shadows);
        let l = lanes::<P>();
        let packs = slots
            .par_chunks(l)
            .map(|s| <P::Pack as Pack<P>>::from_fn(|lane| (s[lane] != NO_PRIMITIVE).then(|| prims[s[lane] as usize])))
            .collect();
        let ids = slots.iter().map(|&k| if k == NO_PRIMITIVE { k } else { ids[k as usize] }).collect();
        Some(Parallel {
            oct: self,
            dir: dir.to_array().map(f32::to_bits),
            u,
            v,
            w,
            lo,
            scale,
            n,
            size,
            len: dir.as_dvec3().length(),
            edge: EDGE + 1e-12 * size * scale,
            first,
            long,
            packs,
            ids,
            top,
        })
    }
}

/// The cells' lists of the shadows `shadows` on a grid of `n` cells: per
/// cell the first of its packs (and the end), whether it is long, each
/// lane's primitive (its index into `shadows`), highest top first, and
/// each pack's top (its first lane's, rounded up to f32).
fn fill<P: Primitive>(n: [usize; 2], shadows: &[Shadow]) -> (Vec<u32>, Vec<bool>, Vec<u32>, Vec<f32>) {
    let l = lanes::<P>();
    let cells = n[0] * n[1];
    let mut count = vec![0u32; cells];
    for &([i0, i1, j0, j1], _) in shadows {
        for j in j0..=j1 {
            for c in &mut count[j * n[0] + i0..=j * n[0] + i1] {
                *c += 1;
            }
        }
    }
    let (long, first) = pack_starts(&count, l);
    let at = first[cells];
    // Highest top first; ties by index (the keys are unique).
    let mut order: Vec<(f64, u32)> = shadows.iter().enumerate().map(|(k, s)| (s.1, k as u32)).collect();
    order.par_sort_unstable_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    let mut slots = vec![NO_PRIMITIVE; at as usize * l];
    let mut top = vec![f32::NEG_INFINITY; at as usize];
    let mut next: Vec<u32> = first[..cells].iter().map(|&f| f * l as u32).collect();
    for &(t, k) in &order {
        let [i0, i1, j0, j1] = shadows[k as usize].0;
        for j in j0..=j1 {
            for c in j * n[0] + i0..=j * n[0] + i1 {
                if long[c] {
                    continue;
                }
                let at = next[c] as usize;
                if at.is_multiple_of(l) {
                    top[at / l] = up(t);
                }
                slots[at] = k;
                next[c] += 1;
            }
        }
    }
    (first, long, slots, top)
}

/// The least f32 at least `x` (NaN: infinity, a bound that stops
/// nothing).
fn up(x: f64) -> f32 {
    if x.is_nan() {
        return f32::INFINITY;
    }
    let y = x as f32;
    if f64::from(y) < x { y.next_up() } else { y }
}

impl<P: Primitive> Parallel<'_, P> {
    /// The cell whose list answers the occlusion query `q`, and the height
    /// below which its list holds nothing the ray can meet: a ray along
    /// the lists' direction, bit for bit, from `t_min >= 0`, its origin
    /// within the scene's size of the world's origin, falling on the plane
    /// [`EDGE`] (plus its hits' drift) inside a cell with a list.
    #[inline]
    fn cell(&self, q: &Query) -> Option<(usize, f64)> {
        let from_zero = q.t_min.partial_cmp(&0.0).is_some_and(std::cmp::Ordering::is_ge);
        if !from_zero || q.ray.dir.to_array().map(f32::to_bits) != self.dir {
            return None;
        }
        let o = q.ray.origin.as_dvec3();
        if !o.length().partial_cmp(&self.size).is_some_and(std::cmp::Ordering::is_le) {
            return None;
        }
        let axis = |x: f64, a: usize| {
            let at = (x - self.lo[a]) * self.scale;
            let (lo, hi) = (at - self.edge, at + self.edge);
            if !(lo >= 0.0 && hi < self.n[a] as f64) {
                return None;
            }
            let (c0, c1) = (lo as usize, hi as usize);
            (c0 == c1).then_some(c0)
        };
        let c = axis(o.dot(self.v), 1)? * self.n[0] + axis(o.dot(self.u), 0)?;
        let height = o.dot(self.w) + f64::from(q.t_min) * self.len - 1e-12 * self.size;
        (!self.long[c]).then_some((c, height))
    }

    /// Cell `c`'s list to `visitor`, pack after pack, highest top first,
    /// up to the first pack whose top lies below `height`; true when the
    /// visitor stopped.
    #[inline]
    fn visit<V: Visitor<P>>(&self, (c, height): (usize, f64), visitor: &mut V) -> bool {
        let l = lanes::<P>();
        let side = &*self.oct.parts[0].side;
        for p in self.first[c] as usize..self.first[c + 1] as usize {
            if f64::from(self.top[p]) < height {
                break;
            }
            let one = |_: usize, _: usize, _: f32| 1;
            if visitor.packs_met(&self.packs[p..=p], &self.ids[p * l..(p + 1) * l], one, self.oct.simd(), side) {
                return true;
            }
        }
        false
    }
}

/// A cell's list and the height its list stops at, for [`occluded_by`].
struct InCell<'l, 'a, P: Primitive>(&'l Parallel<'a, P>, (usize, f64));

impl<P: Primitive> RunsAnyHit<P> for InCell<'_, '_, P> {
    fn run<S: Skip>(&self, visitor: &mut AnyHit<'_, P, S>) -> bool {
        self.0.visit(self.1, visitor)
    }
}

impl<P: Primitive> Backend for Parallel<'_, P> {
    fn intersect_from(&self, q: &Query, hits: &mut CandidateHits) {
        self.oct.intersect_from(q, hits);
    }

    fn occluded_from(&self, q: &Query) -> bool {
        match self.cell(q) {
            Some(at) => occluded_by(q, &InCell(self, at)),
            None => self.oct.occluded_from(q),
        }
    }

    fn stats(&self) -> &BuildStats {
        self.oct.stats()
    }

    fn intersect_packet(&self, qs: &[Query], hits: &mut [CandidateHits]) {
        self.oct.intersect_packet(qs, hits);
    }

    /// The queries up to the first without a list from their lists, the
    /// rest as one packet of the octree's ([`occluded_split`]).
    fn occluded_packet(&self, qs: &[Query], out: &mut [bool]) {
        occluded_split(self.oct, qs, out, |q| Some(occluded_by(q, &InCell(self, self.cell(q)?))));
    }
}

#[cfg(test)]
mod tests {
    use super::super::traverse::tests::{bumpy, clipped_thirds, same_occlusion};
    use super::super::{Octree, OctreeParams};
    use crate::accel::{Backend, CandidateHits, Departure, Query};
    use crate::geometry::Ray;
    use crate::primitive::Primitive;
    use crate::rng::SplitMix64;
    use crate::splat::Splat;
    use glam::Vec3;

    /// Shadow rays along `dir` from where 250² camera rays first meet
    /// `oct`'s primitives, leaving their splats (normals `normal`) as the
    /// renderer's do, and the same rays from `t_min` -1 and from a point
    /// far off: the lists' occlusion is the octree's bit for bit, one at a
    /// time and in packets of 8. Gives the queries, those the lists
    /// answered, those occluded, and those both.
    fn compare<P: Primitive>(oct: &Octree<P>, dir: Vec3, normal: impl Fn(u32) -> Vec3) -> [usize; 4] {
        let eye = Vec3::new(0.9, 0.7, 3.6);
        let fwd = -eye.normalize();
        let right = fwd.cross(Vec3::Y).normalize();
        let up = right.cross(fwd);
        let side = 250;
        let s = |i: usize| 0.5 * ((i as f32 + 0.5) / side as f32 * 2.0 - 1.0);
        let mut h = CandidateHits::new(0.05);
        let mut qs = Vec::new();
        for k in 0..side * side {
            let ray = Ray::new(eye, fwd + right * s(k % side) + up * s(k / side));
            oct.intersect_from(&Query::new(ray, 0.0, f32::INFINITY), &mut h);
            let Some(c) = h.as_slice().first() else {
                continue;
            };
            let p = ray.origin + ray.dir * c.t;
            let from = Some(Departure { id: c.id, point: p, normal: normal(c.id) });
            let q = Query { ray: Ray::new(p, dir), t_min: 1e-3, t_max: f32::INFINITY, from, pass: None };
            qs.push(q);
            if k % 50 == 0 {
                qs.push(Query { t_min: -1.0, ..q });
                qs.push(Query { ray: Ray::new(p * 1e3, dir), ..q });
            }
        }
        // A render's rays (one a pixel of 1024²).
        let lists = oct.build_parallel(dir, 1 << 20).expect("lists");
        same_occlusion(&lists, oct, &qs, |q| lists.cell(q).is_some())
    }

    /// The bumpy sphere's 4,000 small discs, whole and with clip lines on
    /// every third, over a floor of tilted discs, with 400 smaller discs
    /// floating above: the shadow rays of a light from above are answered
    /// from the lists as the octree answers them ([`compare`]); rays
    /// along another direction go to the octree.
    #[test]
    fn shadow_lists_answer_a_directional_light_as_the_octree() {
        let mut discs = bumpy(4_000, |_| 0.06);
        let mut rng = SplitMix64::new(11);
        let mut r = || rng.next_f32() * 2.0 - 1.0;
        for i in 0..40 {
            for k in 0..40 {
                let c = Vec3::new(-3.0 + 0.15 * i as f32, -1.3 + 0.02 * r(), -3.0 + 0.15 * k as f32);
                let n = (Vec3::Y + Vec3::new(r(), 0.0, r()) * 0.2).normalize();
                discs.push(Splat::disc(c, n, 0.11).unwrap().disc_geometry());
            }
        }
        for _ in 0..400 {
            let c = Vec3::new(r() * 1.5, 1.4 + 0.3 * r(), r() * 1.5);
            let n = Vec3::new(r(), r(), r()).normalize_or(Vec3::Y);
            discs.push(Splat::disc(c, n, 0.05).unwrap().disc_geometry());
        }
        let clipped = clipped_thirds(&discs);
        let params = OctreeParams::default();
        let dir = Vec3::new(0.3, 1.0, 0.2).normalize();
        let whole = compare(&Octree::new(&discs, &params), dir, |id| discs[id as usize].normal);
        let cut = compare(&Octree::new(&clipped, &params), dir, |id| clipped[id as usize].disc.normal);
        eprintln!("shadow rays, listed, occluded, both (whole, clipped): {whole:?} {cut:?}");
        // Measured: of 42,690 and 41,822 shadow rays, 41,084 and 40,246
        // answered from the lists, 11,142 and 11,037 occluded, 10,806 and
        // 10,703 both.
        for [_, listed, occluded, both] in [whole, cut] {
            assert!(listed > 39_500 && occluded > 10_500 && both > 10_000, "{listed} {occluded} {both}");
        }
        let oct = Octree::new(&discs, &params);
        let lists = oct.build_parallel(dir, 12 * discs.len()).expect("lists");
        let q = Query::new(Ray::new(Vec3::ZERO, -dir), 0.0, f32::INFINITY);
        assert!(lists.cell(&q).is_none(), "another direction");
        assert!(oct.build_parallel(dir, 12 * discs.len() - 1).is_none(), "too few rays");
    }
}
