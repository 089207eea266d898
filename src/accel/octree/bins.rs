//! A fan's blocks of directions, each with its own list of the
//! primitives a ray along it may meet (issue 55): a camera's ray is
//! tested against its block's list instead of descending the octree.
//!
//! The fan ([`Coverage`], `fan`'s module doc) finds for each primitive the
//! rectangle of the gnomonic plane holding every direction along which the
//! f32 test [`Primitive::intersect`] can accept a hit of it at `t >= 0`
//! from the fan's origin: a ray leaving that origin (bit for bit) whose
//! direction lies in a cell of the grid meets at `t >= 0` only primitives
//! whose rectangle holds that cell. So each block of [`BLOCK`]² cells
//! lists the primitives whose rectangle meets it, copied into
//! packs as a leaf's are, and such a ray's query is the brute-force
//! oracle's over its block's list: every primitive it can hit is there,
//! each decided by the leaves' own filter and exact test
//! ([`Visitor::packs_met`]), and the window does not depend on the order
//! hits are offered ([`CandidateHits`]). The answers are the octree's bit
//! for bit (`docs/DESIGN.md`, "The backend contract", rule 1); a ray
//! leaving elsewhere, from `t < 0`, outside the grid, or in a block whose
//! list is long ([`MAX_LIST`]) is the octree's own.
//!
//! A shadow ray toward a light at the fan's origin (a headlight: every
//! scene splatray makes for a cloud has one) is answered from a list too:
//! the part of its span that can hold a hit projects into one block
//! ([`Coverage::toward`]), so every primitive it can meet is in that
//! block's list, and the any-hit test is order-free ([`Binned::toward`]).
//!
//! Each list runs nearest first, and a ray stops at the first pack whose
//! bound on its lanes' distances lies past its window's end
//! ([`Lists::of`]). The lists are built for the run, after the coverage:
//! the rectangles' blocks counted and filled in bands of block rows on
//! the threads, the packs filled in parallel. On the bunny's 1024² camera
//! rays a block of 4×4 cells (about 64 rays) lists about 42 splats, and a
//! camera `cast_rays` call takes 0.71 of the octree's instructions
//! (`docs/notes/backends.md`, "Issue 55, forty-second session").

use super::fan::Coverage;
use super::traverse::{AnyHit, Gather, RunsAnyHit, Visitor, occluded_by, occluded_split};
use super::{NO_PRIMITIVE, Octree, lanes};
use crate::accel::{Backend, BuildStats, CandidateHits, Fan, NoSkip, PACKET, Query, Skip};
use crate::geometry::{Ray, RaySet};
use crate::primitive::{Pack, Primitive};
use crate::simd::{GnomonicGrid, NO_CELL, gnomonic_cell};
use rayon::prelude::*;

/// Most primitives a block lists: a ray of a block with more is traced
/// by the octree (a ray tests its list's packs up to the first whose
/// bound lies past its window, which in a deep list is many).
const MAX_LIST: usize = 128;

/// Cells per block along each axis.
const BLOCK: usize = 4;

// A fan key's block of 2×2 cells lies in one list's block
// (`Fan::gather_keyed`).
const _: () = assert!(BLOCK.is_multiple_of(2), "a key's 2×2 cells in one block");

/// How far inside its block, in cells, both ends of a shadow ray's
/// projection lie for the block's list to answer it ([`Binned::toward`]):
/// far above the f64 rounding of the projections (cells number at most
/// 2^20).
const EDGE: f64 = 1e-6;

/// Most list entries in all, per ray of the run: beyond it the lists are
/// not built (their memory and building would not pay).
const MAX_ENTRIES_PER_RAY: usize = 1;

impl<P: Primitive> Octree<P> {
    /// The fan of the rays `rays` (sharing their first ray's origin): the
    /// coverage with each block's list of primitives ([`Binned`]) where
    /// the lists are short enough, else the coverage alone; `None` when
    /// it would not pay ([`Backend::fan_pays`]) or a ball straddles the
    /// plane through the origin across the rays inside the cone of their
    /// directions (`fan`'s module doc).
    pub(super) fn build_fan(&self, rays: &dyn RaySet) -> Option<Box<dyn Fan + '_>> {
        Some(match self.lists_or_coverage(rays)? {
            Ok(binned) => Box::new(binned),
            Err(coverage) => Box::new(coverage),
        })
    }

    /// [`Octree::build_fan`]'s fan: the lists, or the coverage alone.
    pub(super) fn lists_or_coverage(&self, rays: &dyn RaySet) -> Option<Result<Binned<'_, P>, Coverage>> {
        let origin = (!rays.is_empty()).then(|| rays.ray(0).origin)?;
        if !self.fan_pays(rays.len()) || !origin.is_finite() {
            return None;
        }
        // The frame (from the rays) beside the tree's primitives (found
        // the first time a fan is built, kept after).
        let (fan, (ids, prims)) = rayon::join(|| Coverage::frame(origin, rays, self.simd()), || self.primitives());
        let mut fan = fan?;
        let (cells, near) = fan.cover(prims)?;
        Some(match Lists::of::<P>(&fan, (&cells, &near), rays.len()) {
            Some(lists) => Ok(Binned::new(self, fan, lists, ids, prims)),
            None => Err(fan),
        })
    }

    /// Every primitive held, once, and its id: found the first time a
    /// fan asks, and kept (what the tree holds does not change).
    pub(super) fn primitives(&self) -> (&[u32], &[P]) {
        let (ids, prims) = self.held.get_or_init(|| self.find_primitives());
        (ids, prims)
    }

    /// [`Octree::primitives`], found: each in its first pack's lane.
    fn find_primitives(&self) -> (Vec<u32>, Vec<P>) {
        let mut seen = vec![false; self.count];
        let (mut ids, mut out) = (Vec::with_capacity(seen.len()), Vec::with_capacity(seen.len()));
        let l = lanes::<P>();
        for tree in &self.parts {
            for (p, pack) in tree.packs.iter().enumerate() {
                for (lane, &id) in tree.pack_ids[p * l..(p + 1) * l].iter().enumerate() {
                    if id != NO_PRIMITIVE && !std::mem::replace(&mut seen[id as usize], true) {
                        ids.push(id);
                        out.push(pack.get(lane, id, &tree.side));
                    }
                }
            }
        }
        (ids, out)
    }
}

/// The blocks' lists of a fan, as indices into the primitives the fan was
/// covered with ([`Lists::of`]).
pub(super) struct Lists {
    /// Blocks per row (cell `(i, j)`'s block: `j / BLOCK * cols + i /
    /// BLOCK`).
    cols: usize,
    /// Per block, the first of its packs; the last entry ends the last
    /// block's.
    first: Vec<u32>,
    /// Per block, whether its list is too long to be kept ([`MAX_LIST`]).
    long: Vec<bool>,
    /// Per lane of the packs, block after block: the index of the
    /// primitive, [`NO_PRIMITIVE`] on padding; each block's nearest first.
    slots: Vec<u32>,
    /// Per pack, a bound below the distance from the origin of every
    /// point its lanes' exact tests can accept ([`Lists::of`]).
    near: Vec<f32>,
}

impl Lists {
    /// The lists of the fan `cov`, each primitive `k` (of packs of `P`) in
    /// every block its cells `cells[k]` (`[i0, i1, j0, j1]`, what
    /// [`Coverage::cover`] gave with `near`) meet, for a run of `rays`
    /// rays; `None` when they would hold more than
    /// [`MAX_ENTRIES_PER_RAY`] entries a ray.
    ///
    /// Each list runs from the primitive nearest the origin to the
    /// farthest by `near[k]`, `|c| - R` (its centre's distance less the
    /// radius of its ball as the fan grows it) rounded down to f32, ties by
    /// `k`: a point the exact test accepts lies within that margin of the
    /// primitive, so no nearer to the origin than that. A pack's bound is
    /// its first lane's, the least of its lanes'.
    pub(super) fn of<P: Primitive>(
        cov: &Coverage,
        (cells, near): (&[Option<[usize; 4]>], &[f64]),
        rays: usize,
    ) -> Option<Lists> {
        let l = lanes::<P>();
        let cols = cov.n[0].div_ceil(BLOCK);
        let blocks = cols * cov.n[1].div_ceil(BLOCK);
        let span = |[i0, i1, j0, j1]: [usize; 4]| (i0 / BLOCK..=i1 / BLOCK, j0 / BLOCK..=j1 / BLOCK);
        // The primitives in front, nearest first by their bounds rounded
        // down to f32 (a pack's bound is its first lane's), ties by index:
        // a bound is at least 0, so its bits sort as it does. Keys unique
        // (an index each): one order.
        let mut order: Vec<u64> = Vec::with_capacity(cells.len());
        let mut entries = 0;
        for (k, c) in cells.iter().enumerate() {
            if let Some(c) = c {
                let (i, j) = span(*c);
                entries += (i.end() - i.start() + 1) * (j.end() - j.start() + 1);
                order.push(u64::from(down(near[k]).to_bits()) << 32 | k as u64);
            }
        }
        if entries > MAX_ENTRIES_PER_RAY * rays {
            return None;
        }
        order.sort_unstable();
        // Bands of rows of blocks, each counted and filled by one task
        // from the primitives whose cells reach its rows, nearest first.
        let rows = cov.n[1].div_ceil(BLOCK);
        let band = rows.div_ceil(4 * rayon::current_num_threads()).max(1);
        let mut in_band: Vec<Vec<([u32; 4], f32, u32)>> = vec![Vec::new(); rows.div_ceil(band)];
        for &key in &order {
            let k = key as u32;
            if let Some(c) = cells[k as usize] {
                for prims in &mut in_band[c[2] / BLOCK / band..=c[3] / BLOCK / band] {
                    prims.push((c.map(|x| x as u32), f32::from_bits((key >> 32) as u32), k));
                }
            }
        }
        let within = |c: [u32; 4], r0: usize, r1: usize| {
            let (i, j) = span(c.map(|x| x as usize));
            (i, *j.start().max(&r0)..(*j.end() + 1).min(r1))
        };
        let mut count = vec![0u32; blocks];
        count.par_chunks_mut(band * cols).zip(&in_band).enumerate().for_each(|(k, (count, prims))| {
            let r0 = k * band;
            let r1 = r0 + count.len() / cols;
            for &(c, _, _) in prims {
                let (i, j) = within(c, r0, r1);
                for bj in j {
                    for bi in i.clone() {
                        count[(bj - r0) * cols + bi] += 1;
                    }
                }
            }
        });
        let (long, first) = pack_starts(&count, l);
        let at = first[blocks];
        let mut slots = vec![NO_PRIMITIVE; at as usize * l];
        let mut pack_near = vec![f32::INFINITY; at as usize];
        let mut pieces = Vec::new();
        let (mut rest, mut rest_near) = (&mut slots[..], &mut pack_near[..]);
        for r0 in (0..rows).step_by(band) {
            let r1 = (r0 + band).min(rows);
            let packs = (first[r1 * cols] - first[r0 * cols]) as usize;
            let (s, r) = std::mem::take(&mut rest).split_at_mut(packs * l);
            let (n, rn) = std::mem::take(&mut rest_near).split_at_mut(packs);
            (rest, rest_near) = (r, rn);
            pieces.push((r0, r1, s, n));
        }
        pieces.into_par_iter().zip(&in_band).for_each(|((r0, r1, slots, pack_near), prims)| {
            let base = first[r0 * cols];
            let mut next: Vec<u32> = first[r0 * cols..r1 * cols].iter().map(|&f| (f - base) * l as u32).collect();
            for &(c, bound, k) in prims {
                let (i, j) = within(c, r0, r1);
                for bj in j {
                    for bi in i.clone() {
                        let b = bj * cols + bi;
                        if long[b] {
                            continue;
                        }
                        let slot = &mut next[b - r0 * cols];
                        let at = *slot as usize;
                        if at.is_multiple_of(l) {
                            pack_near[at / l] = bound;
                        }
                        slots[at] = k;
                        *slot += 1;
                    }
                }
            }
        });
        Some(Lists {
            cols,
            first,
            long,
            slots,
            near: pack_near,
        })
    }
}

/// Per list, from its count of primitives, whether it is too long to be
/// kept ([`MAX_LIST`]), and where each list's packs of `l` lanes start (the
/// last entry ends the last list's; a long list holds none).
pub(super) fn pack_starts(count: &[u32], l: usize) -> (Vec<bool>, Vec<u32>) {
    let long: Vec<bool> = count.iter().map(|&c| c as usize > MAX_LIST).collect();
    let mut first = Vec::with_capacity(count.len() + 1);
    let mut at = 0u32;
    for (&c, &long) in count.iter().zip(&long) {
        first.push(at);
        if !long {
            at += (c as usize).div_ceil(l) as u32;
        }
    }
    first.push(at);
    (long, first)
}

/// The greatest f32 at most `x` (NaN: minus infinity, a bound that stops
/// nothing).
fn down(x: f64) -> f32 {
    if x.is_nan() {
        return f32::NEG_INFINITY;
    }
    let y = x as f32;
    if f64::from(y) > x { y.next_down() } else { y }
}

/// A fan whose blocks hold their lists of primitives, and the backend that
/// answers its run's rays from them (module doc).
pub(super) struct Binned<'a, P: Primitive> {
    oct: &'a Octree<P>,
    cov: Coverage,
    grid: GnomonicGrid,
    cols: usize,
    first: Vec<u32>,
    long: Vec<bool>,
    /// The lists' primitives, packs block after block.
    packs: Vec<P::Pack>,
    /// The primitive id of each lane of `packs`.
    ids: Vec<u32>,
    /// Per pack, the bound below its lanes' hits' distances from the
    /// origin ([`Lists::of`]).
    near: Vec<f32>,
}

impl<'a, P: Primitive> Binned<'a, P> {
    /// The lists `lists` of the fan `cov` of `oct`, made of the primitives
    /// `prims` (ids `ids`) the fan was covered with.
    pub(super) fn new(oct: &'a Octree<P>, cov: Coverage, lists: Lists, ids: &[u32], prims: &[P]) -> Self {
        let l = lanes::<P>();
        let Lists {
            cols,
            first,
            long,
            mut slots,
            near,
        } = lists;
        let packs = slots
            .par_chunks(l)
            .map(|s| {
                <P::Pack as Pack<P>>::from_fn(|lane| (s[lane] != NO_PRIMITIVE).then(|| prims[s[lane] as usize]))
            })
            .collect();
        slots.par_iter_mut().for_each(|k| {
            if *k != NO_PRIMITIVE {
                *k = ids[*k as usize];
            }
        });
        Binned {
            oct,
            grid: cov.grid(),
            cov,
            cols,
            first,
            long,
            packs,
            ids: slots,
            near,
        }
    }

    /// The block whose list answers `q`: a ray leaving the fan's origin
    /// from `t_min >= 0`, its direction in a cell of the grid, in a block
    /// with a list; `None` for the octree.
    #[inline]
    fn block(&self, q: &Query) -> Option<usize> {
        if !self.leaves_origin(q) {
            return None;
        }
        let [i, j] = gnomonic_cell(&self.grid, &q.ray);
        if i == NO_CELL {
            return None;
        }
        self.listed([i as usize, j as usize])
    }

    /// Whether a block's list may answer `q`: its ray leaves the fan's
    /// origin (bit for bit) from `t_min >= 0` (a NaN `t_min` is not).
    #[inline(always)]
    fn leaves_origin(&self, q: &Query) -> bool {
        let from_zero = q.t_min.partial_cmp(&0.0).is_some_and(std::cmp::Ordering::is_ge);
        from_zero && q.ray.origin.to_array().map(f32::to_bits) == self.cov.origin
    }

    /// The block holding cell `[i, j]`, where it keeps its list (`None`
    /// past the grid's blocks).
    #[inline(always)]
    fn listed(&self, [i, j]: [usize; 2]) -> Option<usize> {
        let b = j / BLOCK * self.cols + i / BLOCK;
        (b < self.long.len() && !self.long[b]).then_some(b)
    }

    /// Block `b`'s list to `visitor` for the ray `ray`, pack after pack,
    /// nearest first, each filtered with the window's end as it stands, up
    /// to the first pack whose bound lies past that end, or past `reach`
    /// from the origin where given (a ray leaving elsewhere,
    /// [`Binned::toward`]); true when the visitor stopped.
    #[inline]
    fn visit<V: Visitor<P>>(&self, b: usize, ray: &Ray, reach: Option<f64>, visitor: &mut V) -> bool {
        let l = lanes::<P>();
        let (p0, p1) = (self.first[b] as usize, self.first[b + 1] as usize);
        let side = &*self.oct.parts[0].side;
        // `|d|`, and a margin far above the rounding of `t |d|` here and of
        // the hit's `t` (a point within the bound's margin of the
        // primitive lies on the ray at `t |d|` from the origin).
        let len = ray.dir.as_dvec3().length() * (1.0 + 1e-9);
        for p in p0..p1 {
            let past = reach.unwrap_or_else(|| f64::from(visitor.cutoff()) * len);
            if f64::from(self.near[p]) > past {
                break;
            }
            let one = |_: usize, _: usize, _: f32| 1;
            if visitor.packs_met(&self.packs[p..=p], &self.ids[p * l..(p + 1) * l], one, self.cov.isa, side) {
                return true;
            }
        }
        false
    }

    /// The block whose list answers the occlusion query `q` of a ray
    /// leaving elsewhere toward the fan's origin (a shadow ray toward a
    /// headlight), and the distance from the origin past which its list
    /// holds nothing the ray can meet: where the part of its span that can
    /// hold a hit projects into one block with a list, both ends at least
    /// [`EDGE`] of a cell inside it ([`Coverage::toward`]). Every
    /// primitive the ray can hit is then in that list, at most that far.
    #[inline]
    fn toward(&self, q: &Query) -> Option<(usize, f64)> {
        let (ends, reach) = self.cov.toward(&q.ray, q.t_min, q.t_max)?;
        let block = |[i, j]: [f64; 2]| {
            let axis = |x: f64, a: usize| {
                let (lo, hi) = (x - EDGE, x + EDGE);
                // NaN compares false; `as` truncates, at least 0 here.
                if !(lo >= 0.0 && hi < self.cov.n[a] as f64) {
                    return None;
                }
                let (b0, b1) = (lo as usize / BLOCK, hi as usize / BLOCK);
                (b0 == b1).then_some(b0)
            };
            Some(axis(j, 1)? * self.cols + axis(i, 0)?)
        };
        let b = block(ends[0])?;
        (block(ends[1])? == b && !self.long[b]).then_some((b, reach))
    }
}

impl<P: Primitive> Fan for Binned<'_, P> {
    #[inline]
    fn misses(&self, ray: &Ray) -> bool {
        self.cov.misses(ray)
    }

    fn keys_each(&self, rays: &[Ray], keys: &mut [u32]) {
        self.cov.keys_each(rays, keys);
    }

    fn keys_of_rows(&self, rows: &[Ray], origin: [u32; 3], keys: &mut [u32]) -> bool {
        self.cov.keys_of_rows(rows, origin, keys)
    }

    /// The key's block's list where [`Binned::block`] would take one (a
    /// primary query from `t_min >= 0` leaving the origin, a block with a
    /// list). A row's key may be its converted ray's neighbour block (the
    /// two directions round apart): the key's list still holds every
    /// primitive the converted ray can hit, whose rectangle covers the
    /// row's direction (`fan`'s module doc, "Rows"), so the window is the
    /// same.
    fn gather_keyed(&self, key: u32, q: &Query, hits: &mut CandidateHits) -> bool {
        // The key's block of 2×2 cells lies in one block of `BLOCK`² (both
        // aligned to the grid's corner): its lowest cell's.
        let primary = q.from.is_none() && q.pass.is_none();
        match (primary && self.leaves_origin(q)).then(|| self.listed(self.cov.key_cell(key))) {
            Some(Some(b)) => {
                self.gather(b, q, hits);
                true
            }
            _ => false,
        }
    }

    fn backend(&self) -> Option<&dyn Backend> {
        Some(self)
    }
}

impl<P: Primitive> Binned<'_, P> {
    /// The block whose list answers the closest-hit query `q`
    /// ([`Binned::block`]; nothing skipped).
    #[inline]
    fn gathers(&self, q: &Query) -> Option<usize> {
        match (&q.from, q.pass) {
            (None, None) => self.block(q),
            _ => None,
        }
    }

    /// The occlusion query `q`'s block and, for a ray leaving elsewhere,
    /// its reach ([`Binned::block`] for a ray leaving the origin with a
    /// pass-over rule at most, else [`Binned::toward`]).
    #[inline]
    fn occludes(&self, q: &Query) -> Option<(usize, Option<f64>)> {
        match q.from.is_none().then(|| self.block(q)).flatten() {
            Some(b) => Some((b, None)),
            None => self.toward(q).map(|(b, reach)| (b, Some(reach))),
        }
    }

    /// [`Backend::intersect_from`] of `q` from block `b`'s list.
    #[inline]
    fn gather(&self, b: usize, q: &Query, hits: &mut CandidateHits) {
        hits.clear();
        if !q.meets_nothing() {
            self.visit(b, &q.ray, None, &mut Gather::new(&q.ray, q.t_min, q.t_max, NoSkip, hits));
        }
    }

    /// Each of `qs`' block by `which`, or `None` when some query has none
    /// (or there are more than [`PACKET`]).
    #[inline]
    fn blocks<T: Copy + Default>(&self, qs: &[Query], which: impl Fn(&Query) -> Option<T>) -> Option<[T; PACKET]> {
        let mut bs = [T::default(); PACKET];
        if qs.len() > PACKET {
            return None;
        }
        for (b, q) in bs.iter_mut().zip(qs) {
            *b = which(q)?;
        }
        Some(bs)
    }
}

/// A block's list, its ray and the reach its list stops at (where
/// given), for [`occluded_by`].
struct InBlock<'l, 'a, P: Primitive>(&'l Binned<'a, P>, &'l Ray, (usize, Option<f64>));

impl<P: Primitive> RunsAnyHit<P> for InBlock<'_, '_, P> {
    fn run<S: Skip>(&self, visitor: &mut AnyHit<'_, P, S>) -> bool {
        let (b, reach) = self.2;
        self.0.visit(b, self.1, reach, visitor)
    }
}

impl<P: Primitive> Backend for Binned<'_, P> {
    fn intersect_from(&self, q: &Query, hits: &mut CandidateHits) {
        match self.gathers(q) {
            Some(b) => self.gather(b, q, hits),
            None => self.oct.intersect_from(q, hits),
        }
    }

    fn occluded_from(&self, q: &Query) -> bool {
        match self.occludes(q) {
            Some(at) => occluded_by(q, &InBlock(self, &q.ray, at)),
            None => self.oct.occluded_from(q),
        }
    }

    fn stats(&self) -> &BuildStats {
        self.oct.stats()
    }

    /// Each query from its list when every one of `qs` has one, else the
    /// octree's packets.
    fn intersect_packet(&self, qs: &[Query], hits: &mut [CandidateHits]) {
        let Some(bs) = self.blocks(qs, |q| self.gathers(q)) else {
            return self.oct.intersect_packet(qs, hits);
        };
        for ((q, h), &b) in qs.iter().zip(hits.iter_mut()).zip(&bs) {
            self.gather(b, q, h);
        }
    }

    /// The queries up to the first without a list from their lists, the
    /// rest as one packet of the octree's ([`occluded_split`]).
    fn occluded_packet(&self, qs: &[Query], out: &mut [bool]) {
        occluded_split(self.oct, qs, out, |q| {
            Some(occluded_by(q, &InBlock(self, &q.ray, self.occludes(q)?)))
        });
    }
}

#[cfg(test)]
mod tests {
    use super::Binned;
    use super::super::traverse::tests::{bits, bumpy, clipped_thirds, packet_answers, same_occlusion};
    use super::super::{Octree, OctreeParams};
    use crate::accel::{Backend, CandidateHits, Departure, Query};
    use crate::geometry::Ray;
    use crate::primitive::{Disc, Primitive};
    use crate::rng::SplitMix64;
    use glam::Vec3;

    /// 4,000 small discs on a bumpy sphere, a few wide ones across it.
    fn discs() -> Vec<Disc> {
        bumpy(4_000, |i| if i % 1000 == 7 { 0.6 } else { 0.06 })
    }

    /// A camera's rays from `eye` towards the origin (`side`² of them,
    /// directions not unit), then a tenth as many from the eye in random
    /// directions (a third behind it, the others around and past the
    /// camera's view), a few of them from elsewhere.
    fn rays(eye: Vec3, side: usize) -> Vec<Ray> {
        let fwd = -eye.normalize();
        let right = fwd.cross(Vec3::Y).normalize();
        let up = right.cross(fwd);
        let mut rays: Vec<Ray> = (0..side * side)
            .map(|k| {
                let s = |i: usize| 0.4 * ((i as f32 + 0.5) / side as f32 * 2.0 - 1.0);
                Ray::new(eye, (fwd + right * s(k % side) + up * s(k / side)) * 1.7)
            })
            .collect();
        let mut rng = SplitMix64::new(42);
        let mut r = || rng.next_f32() * 2.0 - 1.0;
        for k in 0..side * side / 10 {
            let d = if k % 3 == 0 { -fwd + Vec3::new(r(), r(), r()) } else { fwd + Vec3::new(r(), r(), r()) * 0.5 };
            let o = if k % 20 == 0 { eye + Vec3::new(r(), r(), r()) } else { eye };
            rays.push(Ray::new(o, d));
        }
        rays
    }

    /// Every query of `rays` over spans `[0, inf)`, `[0.5, 2]` and `[1, 1]`
    /// asked of the lists and of the octree: the same windows bit for bit
    /// one at a time and in packets of 8, the same occlusion; the number of
    /// queries the lists answered, and of windows not empty.
    fn compare<P: Primitive>(oct: &Octree<P>, rays: &[Ray]) -> (usize, usize) {
        let binned = match oct.lists_or_coverage(&rays) {
            Some(Ok(b)) => b,
            _ => panic!("no lists"),
        };
        let (mut listed, mut found) = (0, 0);
        let xi = 0.05;
        let (mut a, mut b) = (CandidateHits::new(xi), CandidateHits::new(xi));
        for (t_min, t_max) in [(0.0, f32::INFINITY), (0.5, 2.0), (1.0, 1.0)] {
            for ray in rays {
                let q = Query::new(*ray, t_min, t_max);
                listed += usize::from(binned.gathers(&q).is_some());
                binned.intersect_from(&q, &mut a);
                oct.intersect_from(&q, &mut b);
                assert_eq!(bits(&a), bits(&b), "{ray:?} {t_min} {t_max}");
                found += usize::from(!a.is_empty());
                assert_eq!(binned.occluded_from(&q), oct.occluded_from(&q), "{ray:?}");
            }
            for packet in rays.chunks(8) {
                let qs: Vec<Query> = packet.iter().map(|r| Query::new(*r, t_min, t_max)).collect();
                let (got, occluded) = packet_answers(&binned, &qs, xi);
                for ((q, g), o) in qs.iter().zip(&got).zip(occluded) {
                    oct.intersect_from(q, &mut b);
                    assert_eq!(bits(g), bits(&b));
                    assert_eq!(o, oct.occluded_from(q));
                }
            }
            keyed_windows_are_the_octrees(oct, &binned, rays, (t_min, t_max));
        }
        (listed, found)
    }

    /// Each ray's window gathered from its key ([`Fan::gather_keyed`]) is
    /// the octree's, bit for bit, wherever the fan answers: the key of the
    /// ray (`keys_each`), answered exactly where its block has a list
    /// ([`Binned::block`]), and of rows whose directions are the ray's
    /// scaled from 1e-3 to 1e4 (`keys_of_rows`), each then converted as a
    /// caller converts a row (`crate::simd::ray_from_row`, whose direction
    /// rounds apart from the row's), answered for nearly as many.
    fn keyed_windows_are_the_octrees<P: Primitive>(
        oct: &Octree<P>,
        binned: &Binned<'_, P>,
        rays: &[Ray],
        (t_min, t_max): (f32, f32),
    ) {
        use crate::accel::{FAN_ELSEWHERE, Fan};
        let (mut a, mut b) = (CandidateHits::new(0.05), CandidateHits::new(0.05));
        let origin = rays[0].origin.to_array().map(f32::to_bits);
        let mut keys = vec![0u32; rays.len()];
        // Queries whose block has a list, and those answered by their key.
        let mut check = |ray: Ray, key: u32, counts: &mut [usize; 2]| {
            let q = Query::new(ray, t_min, t_max);
            let listed = key < FAN_ELSEWHERE && binned.block(&q).is_some();
            let answered = binned.gather_keyed(key, &q, &mut a);
            if answered {
                oct.intersect_from(&q, &mut b);
                assert_eq!(bits(&a), bits(&b), "{ray:?} key {key}");
            }
            counts[0] += usize::from(listed);
            counts[1] += usize::from(answered);
            listed == answered
        };
        binned.keys_each(rays, &mut keys);
        let mut counts = [0; 2];
        for (r, &k) in rays.iter().zip(&keys) {
            assert!(check(*r, k, &mut counts), "{r:?} key {k}: answered where it has no list or not where it has");
        }
        assert!(counts[1] > 0, "no window answered by its key");
        for scale in [1e-3, 0.7, 3.0, 1e4] {
            let rows: Vec<Ray> = rays.iter().map(|r| Ray { origin: r.origin, dir: r.dir * scale }).collect();
            assert!(binned.keys_of_rows(&rows, origin, &mut keys), "rows keyed");
            let mut counts = [0; 2];
            for (r, &k) in rows.iter().zip(&keys) {
                let row: [f32; 6] = [r.origin.to_array(), r.dir.to_array()].concat().try_into().unwrap();
                let (ray, _, ok) = crate::simd::ray_from_row(&row, glam::DVec3::ZERO);
                if ok {
                    check(ray, k, &mut counts);
                }
            }
            assert!(counts[1] * 100 >= counts[0] * 99, "scale {scale}: {counts:?}");
        }
    }

    /// The bumpy sphere on a floor of discs that runs under the eye and
    /// behind it, with a pad of discs beside the eye (balls across the
    /// plane through the eye, outside the cone of the camera's directions):
    /// the fan is made, its lists answer as the octree bit for bit, and a
    /// ray it calls a miss (in the grid, or outside it: sideways at the
    /// pad, behind) meets nothing in the octree. A wide disc across that
    /// plane inside the cone leaves no fan.
    #[test]
    fn a_floor_under_the_eye_leaves_the_fan_and_its_answers() {
        use crate::splat::Splat;
        let disc = |c: Vec3, n: Vec3, r: f32| Splat::disc(c, n, r).unwrap().disc_geometry();
        let eye = Vec3::new(0.9, 0.7, 3.6);
        let fwd = -eye.normalize();
        let right = fwd.cross(Vec3::Y).normalize();
        let up = right.cross(fwd);
        let mut discs = discs();
        for i in 0..60 {
            for k in 0..60 {
                let c = Vec3::new(-6.0 + 0.2 * i as f32, -1.3, -6.0 + 0.2 * k as f32);
                discs.push(disc(c, Vec3::Y, 0.15));
            }
        }
        let step = |k: usize| 0.1 * k as f32 - 0.2;
        let pad: Vec<Vec3> = (0..25)
            .map(|k| eye + right * 1.5 + Vec3::Y * step(k / 5) + fwd * step(k % 5))
            .collect();
        discs.extend(pad.iter().map(|&c| disc(c, -right, 0.08)));
        let mut rays = rays(eye, 150);
        rays.extend(pad.iter().flat_map(|&c| {
            [Vec3::ZERO, Vec3::Y * 0.03, fwd * 0.03].map(|d| Ray::new(eye, c + d - eye))
        }));
        let oct = Octree::new(&discs, &OctreeParams::default());
        let (listed, found) = compare(&oct, &rays);
        eprintln!("queries listed, windows not empty: {listed} {found}");
        // Measured: 34,221 of the 74,475 queries answered from the lists,
        // 16,801 windows not empty.
        assert!(listed > 33_500 && found > 16_000, "{listed} {found}");
        let fan = oct.build_fan(&rays.as_slice()).expect("a fan with the floor under the eye");
        let mut h = CandidateHits::new(0.05);
        let (mut misses, mut at_pad) = (0, 0);
        for ray in &rays {
            oct.intersect_from(&Query::new(*ray, 0.0, f32::INFINITY), &mut h);
            at_pad += usize::from(ray.dir.dot(right) > 0.9 * ray.dir.length() && !h.is_empty());
            if fan.misses(ray) {
                misses += 1;
                assert!(h.is_empty(), "{ray:?} called a miss hits");
            }
        }
        eprintln!("misses: {misses}, rays meeting the pad: {at_pad}");
        // Measured: 6,342 rays of 24,825 called misses; 75 rays meet the pad.
        assert!(misses > 6_000 && at_pad > 70, "{misses} {at_pad}");
        // A disc across the plane whose ball lies a third of the way into
        // the cone (its edge seen by the camera): no fan.
        let id = discs.len() as u32;
        discs.push(disc(eye + fwd * 0.5 + right * 0.72 + up * 0.1, up, 0.5));
        let oct = Octree::new(&discs, &OctreeParams::default());
        let camera = &rays[..150 * 150];
        let seen = camera.iter().filter(|r| {
            oct.intersect_from(&Query::new(**r, 0.0, f32::INFINITY), &mut h);
            h.as_slice().iter().any(|c| c.id == id)
        });
        let seen = seen.count();
        eprintln!("camera rays meeting the disc: {seen}");
        // Measured: 35 camera rays.
        assert!(seen > 30, "{seen}");
        assert!(oct.build_fan(&camera).is_none());
    }

    /// Shadow rays from where the camera rays of `rays` (the first
    /// `camera` of them) first meet `oct`'s primitives, leaving their
    /// splats (normals `normal`) as the renderer's do, toward a light at
    /// `eye` (a headlight) and at two points a little beside it: the lists'
    /// occlusion is the octree's bit for bit, one at a time and in packets
    /// of 8. Gives the queries, those the lists answered, those occluded,
    /// and those both.
    fn compare_shadows<P: Primitive>(
        oct: &Octree<P>,
        rays: &[Ray],
        camera: usize,
        normal: impl Fn(u32) -> Vec3,
    ) -> [usize; 4] {
        let binned = match oct.lists_or_coverage(&rays) {
            Some(Ok(b)) => b,
            _ => panic!("no lists"),
        };
        let eye = rays[0].origin;
        let beside = eye.cross(Vec3::Y).normalize();
        let mut h = CandidateHits::new(0.05);
        let mut qs = Vec::new();
        for ray in &rays[..camera] {
            oct.intersect_from(&Query::new(*ray, 0.0, f32::INFINITY), &mut h);
            let Some(c) = h.as_slice().first() else {
                continue;
            };
            let p = ray.origin + ray.dir * c.t;
            for light in [eye, eye + beside * 0.2, eye + Vec3::Y * 0.04] {
                let to = light - p;
                let d = to.length();
                qs.push(Query {
                    ray: Ray::new(p, to / d),
                    t_min: 1e-3,
                    t_max: d - 1e-3,
                    from: Some(Departure { id: c.id, point: p, normal: normal(c.id) }),
                    pass: None,
                });
            }
        }
        same_occlusion(&binned, oct, &qs, |q| binned.toward(q).is_some())
    }

    /// The bumpy sphere's 4,000 small discs, whole and with clip lines on
    /// every third, with 400 smaller discs floating between it and the eye: shadow
    /// rays toward a headlight are answered from the lists, as the octree
    /// answers them ([`compare_shadows`]); those toward lights beside the
    /// eye only where their part that can hold a hit lies in one block.
    #[test]
    fn block_lists_answer_shadow_rays_toward_the_eye_as_the_octree() {
        use crate::splat::Splat;
        let eye = Vec3::new(0.9, 0.7, 3.6);
        // No wide discs: their blocks' lists would be too long to keep.
        let mut discs = bumpy(4_000, |_| 0.06);
        let mut rng = SplitMix64::new(7);
        let mut r = || rng.next_f32() * 2.0 - 1.0;
        for _ in 0..400 {
            let c = eye * (0.35 + 0.1 * r()) + Vec3::new(r(), r(), r()) * 0.35;
            let n = Vec3::new(r(), r(), r()).normalize_or(Vec3::Z);
            discs.push(Splat::disc(c, n, 0.03).unwrap().disc_geometry());
        }
        let clipped = clipped_thirds(&discs);
        // Blocks of about 64 rays, as a 1024² render's.
        let rays = rays(eye, 400);
        let params = OctreeParams::default();
        let whole = compare_shadows(&Octree::new(&discs, &params), &rays, 400 * 400, |id| {
            discs[id as usize].normal
        });
        let cut = compare_shadows(&Octree::new(&clipped, &params), &rays, 400 * 400, |id| {
            clipped[id as usize].disc.normal
        });
        eprintln!("shadow rays, listed, occluded, both (whole, clipped): {whole:?} {cut:?}");
        // Measured: of 191,013 and 190,647 shadow rays, 113,065 and 112,543
        // answered from the lists, 10,979 and 11,042 occluded, 2,167 and
        // 2,213 both.
        for [_, listed, occluded, both] in [whole, cut] {
            assert!(listed > 110_000 && occluded > 10_500 && both > 2_000, "{listed} {occluded} {both}");
        }
    }

    /// On the bumpy sphere's 4,000 discs, whole and with clip lines on every
    /// third, seen by 22,500 camera rays and 2,250 more from the eye
    /// (some behind it, some from elsewhere): the lists' windows and
    /// occlusion are the octree's bit for bit, and they answer most rays.
    #[test]
    fn block_lists_answer_as_the_octree_bit_for_bit() {
        let discs = discs();
        let clipped = clipped_thirds(&discs);
        let rays = rays(Vec3::new(0.9, 0.7, 3.6), 150);
        let params = OctreeParams::default();
        let whole = compare(&Octree::new(&discs, &params), &rays);
        let cut = compare(&Octree::new(&clipped, &params), &rays);
        eprintln!("queries listed, windows not empty (whole, clipped): {whole:?} {cut:?}");
        // Measured: 35,409 of the 74,250 queries answered from the lists
        // (the others outside the grid, behind, from elsewhere or in
        // blocks of more than `MAX_LIST`), 9,571 and 9,545 windows not
        // empty.
        for (listed, found) in [whole, cut] {
            assert!(listed > 34_000 && found > 9_000, "{listed} {found}");
        }
    }
}
