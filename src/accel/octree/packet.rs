//! Ray packets through the [`Octree`] (issue 25): up to [`PACKET`] rays of
//! one batch descend the tree together, each node's content box and each
//! child cell tested for every ray of the packet at once (the interval
//! test of §3.2 lane by lane, the same IEEE operations as the single ray's,
//! so a ray takes part in a node exactly when its own traversal would let
//! it in with the same window), with a mask of the rays still active; in a
//! leaf every active ray runs the single ray's leaf code (the SIMD filter of
//! its path, then [`crate::primitive::Primitive::intersect`] and the
//! self-hit rule per lane).
//!
//! Why the candidates are those of one ray at a time (`docs/DESIGN.md`,
//! "The backend contract", rules 1 and 2): each ray keeps its own window
//! ([`CandidateHits`]) and its own cutoff; a ray meets a cell when its
//! padded slab interval there is non-empty within `[t_min, cutoff]`, as in
//! [`Tree::visit`]; the order cells are visited in (the packet's, not the
//! ray's own, and from the root rather than along the top-level grid) only
//! changes which hits are offered before the window narrows, never the
//! final window, which does not depend on arrival order. A cell is skipped
//! for a ray only when it is entered beyond the ray's current cutoff,
//! which is never nearer than the final window's far end.
//!
//! A packet whose rays' direction signs differ (no common front-to-back
//! order) is traced one ray at a time, and so is a batch of fewer than
//! [`MIN_PACKET`] rays; a packet that thins out to one active ray hands it
//! to the single ray's descent at that node.

use super::traverse::{AnyHit, Gather, RayCtx, Visitor};
use super::{INTERIOR, Octree, Tree, child_lo};
use crate::accel::{CandidateHits, NoSkip, PACKET, Query, Skip};
use crate::primitive::Primitive;
use glam::Vec3;

/// Fewest rays traced as a packet; smaller batches go one at a time.
const MIN_PACKET: usize = 2;

/// A packet that thins out to this many active rays hands each to the
/// single ray's descent.
const LONE: u32 = 2;

/// Lane mask type: bit `k` for ray `k` of the packet.
type Mask = u32;

/// The packet's rays, lane by lane (structure of arrays).
struct Lanes {
    /// Origins, per axis.
    o: [[f32; PACKET]; 3],
    /// `1 / dir`, per axis (IEEE: `±inf` on zero components).
    inv: [[f32; PACKET]; 3],
    t_min: [f32; PACKET],
    /// Each ray's own constants, for the single-ray descent of a lone ray.
    ctx: [RayCtx; PACKET],
    /// The direction signs every ray of the packet shares.
    sign_mask: usize,
}

impl Lanes {
    /// The lanes of `qs` (at most [`PACKET`]), or `None` when their
    /// direction signs differ.
    fn new(qs: &[Query]) -> Option<Lanes> {
        let ctx: [RayCtx; PACKET] = std::array::from_fn(|k| {
            let q = &qs[k.min(qs.len() - 1)];
            RayCtx::new(&q.ray, q.t_min)
        });
        let sign_mask = ctx[0].sign_mask;
        if ctx[..qs.len()].iter().any(|c| c.sign_mask != sign_mask) {
            return None;
        }
        let axis = |a: usize, f: &dyn Fn(&RayCtx) -> Vec3| std::array::from_fn(|k| f(&ctx[k])[a]);
        Some(Lanes {
            o: [
                axis(0, &|c| c.origin),
                axis(1, &|c| c.origin),
                axis(2, &|c| c.origin),
            ],
            inv: [
                axis(0, &|c| c.inv_dir),
                axis(1, &|c| c.inv_dir),
                axis(2, &|c| c.inv_dir),
            ],
            t_min: std::array::from_fn(|k| ctx[k].t_min),
            ctx,
            sign_mask,
        })
    }
}

/// `slab` of the single ray: `(near, far)` of the planes at parameters
/// `a` and `b`, with its NaN rule (`a < b` false: the other value).
#[inline(always)]
fn slab(a: f32, b: f32) -> (f32, f32) {
    (if a < b { a } else { b }, if a > b { a } else { b })
}

/// `a > b ? a : b`, the rule of `maxps` and of the single ray's `max4`.
#[inline(always)]
fn max(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

/// `a < b ? a : b`, the rule of `minps` and of the single ray's `min4`.
#[inline(always)]
fn min(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// Each active ray's cutoff (`-inf` on lanes without a ray).
#[inline(always)]
fn cutoffs<P: Primitive, V: Visitor<P>>(vis: &[Option<V>; PACKET]) -> [f32; PACKET] {
    std::array::from_fn(|k| vis[k].as_ref().map_or(f32::NEG_INFINITY, V::cutoff))
}

impl<P: Primitive> Tree<P> {
    /// The rays of `active` that meet the node's content box `[lo, hi]`
    /// within `[t_min, cutoff]`: [`Tree::visit`]'s test, lane by lane.
    // The lanes of several arrays in lockstep: indexed, to vectorise.
    #[allow(clippy::needless_range_loop)]
    #[inline(always)]
    fn meets_box(l: &Lanes, [lo, hi]: [Vec3; 2], cut: &[f32; PACKET], active: Mask) -> Mask {
        let mut m = 0;
        for k in 0..PACKET {
            let (nx, fx) = slab(
                (lo.x - l.o[0][k]) * l.inv[0][k],
                (hi.x - l.o[0][k]) * l.inv[0][k],
            );
            let (ny, fy) = slab(
                (lo.y - l.o[1][k]) * l.inv[1][k],
                (hi.y - l.o[1][k]) * l.inv[1][k],
            );
            let (nz, fz) = slab(
                (lo.z - l.o[2][k]) * l.inv[2][k],
                (hi.z - l.o[2][k]) * l.inv[2][k],
            );
            let entry = max(max(max(nx, ny), nz), l.t_min[k]);
            let exit = min(min(min(fx, fy), fz), cut[k]);
            m |= Mask::from(entry <= exit) << k;
        }
        m & active
    }

    /// The subtree of node `index` (cell `lo`, edge `size`) for the rays of
    /// `active`, front to back in the packet's order; returns the rays
    /// whose visitor stopped (any-hit queries that found a hit).
    #[allow(clippy::needless_range_loop)]
    fn visit_packet<V: Visitor<P>>(
        &self,
        index: usize,
        lo: Vec3,
        size: f32,
        l: &Lanes,
        vis: &mut [Option<V>; PACKET],
        active: Mask,
    ) -> Mask {
        if active.count_ones() <= LONE {
            // Few rays left: each its own descent, with its own constants.
            let mut stopped = 0;
            let mut left = active;
            while left != 0 {
                let k = left.trailing_zeros() as usize;
                left &= left - 1;
                if let Some(v) = vis[k].as_mut()
                    && self.visit(index, lo, size, &l.ctx[k], v)
                {
                    stopped |= 1 << k;
                }
            }
            return stopped;
        }
        let node = self.nodes[index];
        let mut active = Self::meets_box(l, self.boxes[index], &cutoffs(vis), active);
        if active == 0 {
            return 0;
        }
        let mut stopped = 0;
        if node.meta & INTERIOR == 0 {
            while active != 0 {
                let k = active.trailing_zeros() as usize;
                active &= active - 1;
                if let Some(v) = vis[k].as_mut()
                    && self.leaf(node, v)
                {
                    stopped |= 1 << k;
                }
            }
            return stopped;
        }
        // Slab parameters of the padded lower and upper halves on each
        // axis, for every ray: the single ray's arithmetic.
        let mask = node.meta & 0xff;
        let half = size * 0.5;
        let pad = self.pad;
        let (lo_a, mid, hi) = (lo, lo + Vec3::splat(half), lo + Vec3::splat(size));
        // Per axis and ray: near and far of the lower half, of the upper.
        let mut ln = [[0.0f32; PACKET]; 3];
        let mut lf = [[0.0f32; PACKET]; 3];
        let mut un = [[0.0f32; PACKET]; 3];
        let mut uf = [[0.0f32; PACKET]; 3];
        for a in 0..3 {
            for k in 0..PACKET {
                let (o, inv) = (l.o[a][k], l.inv[a][k]);
                (ln[a][k], lf[a][k]) = slab((lo_a[a] - pad - o) * inv, (mid[a] + pad - o) * inv);
                (un[a][k], uf[a][k]) = slab((mid[a] - pad - o) * inv, (hi[a] + pad - o) * inv);
            }
        }
        for i in 0..8 {
            let oct = i ^ l.sign_mask;
            if mask & (1 << oct) == 0 {
                continue;
            }
            let cut = cutoffs(vis);
            let side = |a: usize| {
                if oct & (1 << a) != 0 {
                    (&un[a], &uf[a])
                } else {
                    (&ln[a], &lf[a])
                }
            };
            let ((nx, fx), (ny, fy), (nz, fz)) = (side(0), side(1), side(2));
            let mut m = 0;
            for k in 0..PACKET {
                let entry = max(max(max(nx[k], ny[k]), nz[k]), l.t_min[k]);
                let exit = min(min(min(fx[k], fy[k]), fz[k]), cut[k]);
                m |= Mask::from(entry <= exit) << k;
            }
            let m = m & active;
            if m == 0 {
                continue;
            }
            let child = node.first as usize + (mask & ((1 << oct) - 1)).count_ones() as usize;
            let s = self.visit_packet(child, child_lo(lo, half, oct), half, l, vis, m);
            stopped |= s;
            active &= !s;
            if active == 0 {
                break;
            }
        }
        stopped
    }
}

impl<P: Primitive> Octree<P> {
    /// The parts in the order the packet visits them: by the first ray's
    /// entry (rays for which a part lies elsewhere cull it at its root).
    fn part_order(&self, l: &Lanes) -> ([usize; super::parts::MAX_PARTS], usize) {
        let mut order = [(0.0f32, 0usize); super::parts::MAX_PARTS];
        let n = self.parts.len().min(super::parts::MAX_PARTS);
        for (i, tree) in self.parts.iter().enumerate().take(n) {
            order[i] = (tree.window(&l.ctx[0]).0, i);
        }
        order[..n].sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        (order.map(|(_, i)| i), n)
    }

    /// Every part for the rays of `active`; the rays that stopped.
    fn walk_parts<V: Visitor<P>>(
        &self,
        l: &Lanes,
        vis: &mut [Option<V>; PACKET],
        mut active: Mask,
    ) -> Mask {
        let (order, n) = self.part_order(l);
        let mut stopped = 0;
        for &i in &order[..n] {
            let tree = &self.parts[i];
            if tree.references == 0 || tree.nodes.is_empty() {
                continue;
            }
            let s = tree.visit_packet(0, tree.root_lo, tree.root_size, l, vis, active);
            stopped |= s;
            active &= !s;
            if active == 0 {
                break;
            }
        }
        stopped
    }

    /// [`crate::accel::Backend::intersect_packet`] for at most [`PACKET`]
    /// queries with skip rule `skip` (one type for the packet).
    fn gather_chunk<'q, S: Skip>(
        &self,
        qs: &'q [Query],
        hits: &mut [CandidateHits],
        skip: impl Fn(&'q Query) -> S,
    ) {
        for h in hits.iter_mut().take(qs.len()) {
            h.clear();
        }
        if self.references == 0 {
            return;
        }
        let Some(l) = Lanes::new(qs) else {
            for (q, h) in qs.iter().zip(hits.iter_mut()) {
                self.gather(&q.ray, q.t_min, q.t_max, skip(q), h);
            }
            return;
        };
        let mut it = qs.iter().zip(hits.iter_mut());
        let mut vis: [Option<Gather<'_, S>>; PACKET] = std::array::from_fn(|_| {
            it.next()
                .map(|(q, h)| Gather::new(&q.ray, q.t_min, q.t_max, skip(q), h))
        });
        let active = (1 << qs.len()) - 1;
        self.walk_parts(&l, &mut vis, active);
    }

    /// [`crate::accel::Backend::occluded_packet`] for at most [`PACKET`]
    /// queries with skip rule `skip`.
    fn any_hit_chunk<'q, S: Skip>(
        &self,
        qs: &'q [Query],
        out: &mut [bool],
        skip: impl Fn(&'q Query) -> S,
    ) {
        if self.references == 0 {
            out.iter_mut().take(qs.len()).for_each(|o| *o = false);
            return;
        }
        let Some(l) = Lanes::new(qs) else {
            for (q, o) in qs.iter().zip(out.iter_mut()) {
                *o = self.any_hit(&q.ray, q.t_min, q.t_max, skip(q));
            }
            return;
        };
        let mut it = qs.iter();
        let mut vis: [Option<AnyHit<'_, S>>; PACKET] = std::array::from_fn(|_| {
            it.next()
                .map(|q| AnyHit::new(&q.ray, q.t_min, q.t_max, skip(q)))
        });
        let active = (1 << qs.len()) - 1;
        let stopped = self.walk_parts(&l, &mut vis, active);
        for (k, o) in out.iter_mut().take(qs.len()).enumerate() {
            *o = stopped & (1 << k) != 0;
        }
    }

    /// Candidate windows of a batch: packets of [`PACKET`] rays (one
    /// monomorphised descent for primary rays, [`NoSkip`], another for
    /// batches holding a secondary ray).
    pub(super) fn gather_packets(&self, qs: &[Query], hits: &mut [CandidateHits]) {
        assert!(hits.len() >= qs.len(), "a window per query");
        for (qs, hits) in qs.chunks(PACKET).zip(hits.chunks_mut(PACKET)) {
            if qs.len() < MIN_PACKET {
                for (q, h) in qs.iter().zip(hits.iter_mut()) {
                    crate::accel::Backend::intersect_from(self, q, h);
                }
            } else if qs.iter().all(|q| q.from.is_none()) {
                self.gather_chunk(qs, hits, |_| NoSkip);
            } else {
                self.gather_chunk(qs, hits, |q| q.from.as_ref());
            }
        }
    }

    /// Any-hit answers of a batch, in packets as [`Octree::gather_packets`].
    pub(super) fn any_hit_packets(&self, qs: &[Query], out: &mut [bool]) {
        assert!(out.len() >= qs.len(), "an answer per query");
        for (qs, out) in qs.chunks(PACKET).zip(out.chunks_mut(PACKET)) {
            if qs.len() < MIN_PACKET {
                for (q, o) in qs.iter().zip(out.iter_mut()) {
                    *o = crate::accel::Backend::occluded_from(self, q);
                }
            } else if qs.iter().all(|q| q.from.is_none()) {
                self.any_hit_chunk(qs, out, |_| NoSkip);
            } else {
                self.any_hit_chunk(qs, out, |q| q.from.as_ref());
            }
        }
    }
}
