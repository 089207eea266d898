//! Ray packets through the [`Octree`] (issue 25): up to [`PACKET`] rays of
//! one batch descend the tree together, each node's content box and each
//! child cell tested for every ray of the packet at once (the interval
//! test of §3.2 lane by lane, the same IEEE operations as the single ray's,
//! so a ray takes part in a node exactly when its own traversal would let
//! it in with the same window), with a mask of the rays still active; in a
//! leaf every active ray runs the single ray's leaf code (with the copies'
//! layout, only the packs whose boxes it meets; the SIMD filter of its
//! path, then [`crate::primitive::Primitive::intersect`] and the self-hit
//! rule per lane).
//!
//! Rays sharing an origin (a shadow batch leaving one hit toward a sphere
//! light's samples, the primary rays of one eye; the integrator's batches)
//! take a leaf together instead ([`Tree::leaf_packet`]): each pack is read
//! once for all of them ([`Pack::masks_rays`], the filter's lanes for each
//! ray, computed with its operations), after a test dropping the discs
//! that lie farther than their largest radius from a cone around the
//! packet's rays ([`Cone`]), which no ray of the packet can hit; each
//! ray's lanes are then decided in the single ray's order, pack after pack
//! and lane after lane, the packs of a leaf filtered in runs of
//! [`LEAF_CHUNK`] per call (with the copies' layout, only the packs whose
//! boxes the packet's [`Spread`] meets: `met_packs_spread`). Above the
//! leaves such a packet (with a finite
//! origin and finite `1 / dir`) descends by its [`Spread`]
//! ([`Tree::visit_spread`]): each interior node's box and child cells
//! tested once for the whole packet with an interval holding every ray's
//! own, each ray's own interval tested only at a leaf. An any-hit packet
//! whose rays leave several finite origins (a screen tile's shadow rays
//! toward one light) descends the same way by its [`Scatter`], the bounds of its
//! slab parameters over the box of its origins, each ray then taking a
//! leaf with its own leaf code ([`Tree::leaf_rays`]). Any-hit packets
//! walk the parts in index order, as [`Octree::any_hit`] does
//! (closest-hit packets by the first ray's entry).
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
//! which is never nearer than the final window's far end. A ray taken
//! into a cell its own descent would skip (the [`Spread`] descent, where
//! another ray of the packet meets the cell) offers only true hits of its
//! own, which leave that final window as it is.
//!
//! A packet whose rays' direction signs differ (no common front-to-back
//! order) is traced one ray at a time, and so is a batch of fewer than
//! [`MIN_PACKET`] rays; a packet that thins out to [`LONE`] active rays
//! or fewer hands each to the single ray's descent at that node.

use super::traverse::{AnyHit, Gather, RayCtx, Visitor, met_in_groups};
use super::{
    ENTRY_MASK_SHIFT, ENTRY_PACK, INTERIOR, Node, Octree, PackBoxes, Tree, child_lo, lanes,
};
use crate::accel::{CandidateHits, NoSkip, PACKET, Query, Skip};
use crate::primitive::{Pack, PackRays, Primitive};
use crate::simd::Cone;
use glam::{Vec3, Vec3A, Vec4};
use std::cell::OnceCell;

/// A packet of several origins descends by its [`Scatter`] through the
/// cells whose edge is at least this many times the widest extent of the
/// box of its origins, below them ray by ray ([`Tree::visit_packet`]):
/// where cells are not much wider than that box, the prism the box sweeps
/// along the rays meets far more of them than the rays do. The accel
/// benchmark's shadow packets (8 neighbouring hits' rays toward a point
/// light) at 1M splats ran at 2.02 of Embree's packets before the scatter,
/// 0.78 with it unbounded and 2.12 with this bound (35k: 0.96, 0.92,
/// 1.03). Counted on 1M discs of a bumpy sphere, the unbounded scatter
/// entered 7.3 times the interior nodes of a descent testing each ray at
/// every node; a bound of 2 ran as fast as 4, 16 about 3 % slower
/// (`docs/notes/backends.md`, "Issue 55, fifty-first session").
const SCATTER_CELLS: f32 = 4.0;

/// Fewest rays traced as a packet; smaller batches go one at a time.
const MIN_PACKET: usize = 2;

/// A packet that thins out to this many active rays hands each to the
/// single ray's descent.
const LONE: u32 = 2;

/// Packs of a leaf filtered per call of [`Pack::masks_rays`].
const LEAF_CHUNK: usize = 16;

/// Lane mask type: bit `k` for ray `k` of the packet.
type Mask = u32;

/// Eight lanes as two SIMD registers (lanes 0–3, 4–7).
type Wide = [Vec4; 2];

/// Packs of a leaf's first filter call for an any-hit packet (issue 55):
/// a ray that stops in a leaf's first packs had the filter's lanes of
/// the rest of the call computed for nothing. The answer does not depend
/// on it (whether some accepted hit lies within the fixed cutoff).
/// Measured on the 128,894 occluded camera rays of the 200k bunny, one
/// thread, CPU over 16 (5 pairs each, noisy): 4 0.935, 8 0.959, 2 0.969,
/// 1 0.956. Later calls take [`LEAF_CHUNK`].
const FIRST_ANY_HIT_CHUNK: usize = 4;

/// Packs of a leaf's first filter call for visitor `V`.
#[inline(always)]
fn first_chunk<P: Primitive, V: Visitor<P>>() -> usize {
    if V::FIXED_CUTOFF {
        FIRST_ANY_HIT_CHUNK
    } else {
        LEAF_CHUNK
    }
}

/// `a` as two registers.
#[inline(always)]
fn wide(a: &[f32; PACKET]) -> Wide {
    [
        Vec4::new(a[0], a[1], a[2], a[3]),
        Vec4::new(a[4], a[5], a[6], a[7]),
    ]
}

/// The packet's rays, lane by lane (structure of arrays); a lane past the
/// last ray repeats it.
struct Lanes<'q> {
    /// Origins, per axis.
    o: [Wide; 3],
    /// `1 / dir`, per axis (IEEE: `±inf` on zero components).
    inv: [Wide; 3],
    t_min: Wide,
    /// The queries, for the single-ray descent of a lone ray.
    qs: &'q [Query<'q>],
    /// The direction signs every ray of the packet shares.
    sign_mask: usize,
    /// The origin, when every ray of the packet has the same one (bit for
    /// bit): the leaves then test each pack once for all the rays
    /// ([`Pack::masks_rays`]).
    origin: Option<[f32; 3]>,
    /// With a shared origin and every `t_min >= 0`: a cone from it holding
    /// every ray, computed when the packet first reaches a leaf.
    cone: OnceCell<Option<Cone>>,
    /// With a shared finite origin and finite `1 / dir` on every lane: the
    /// bounds of the packet's slab parameters ([`Spread`]).
    spread: Option<Spread>,
    /// With finite origins that differ and finite `1 / dir` on every
    /// lane: the bounds of the packet's slab parameters ([`Scatter`]).
    scatter: Option<Scatter>,
}

/// The extremes of a packet's rays sharing a finite origin `o` whose
/// `1 / dir` are finite, per axis: the rays' slab parameter at a plane `x`
/// is `(x - o) inv_k`, monotone in `inv_k` for a fixed `x - o` (rounding is
/// monotone), so its least and greatest over the rays are those of the
/// least and greatest `inv_k`. A cell's interval for the packet, from the
/// least near and the greatest far parameter, holds every ray's own: the
/// packet meets the cell whenever one of its rays does.
#[derive(Clone, Copy, Debug)]
struct Spread {
    o: Vec3A,
    inv_lo: Vec3A,
    inv_hi: Vec3A,
    /// The least `t_min`.
    t_min: f32,
}

/// The extremes of a packet's rays leaving several finite origins (a
/// screen tile's shadow rays toward one light) whose `1 / dir` are
/// finite, per axis: at a plane `x` a ray's slab parameter is
/// `(x - o) inv`, monotone in `o` for a fixed `inv` and in `inv` for a
/// fixed `x - o` (rounding is monotone), so over the box of the origins
/// and the range of `inv` its least and greatest lie at the corners. As
/// with [`Spread`], a cell's interval for the packet holds every ray's
/// own.
#[derive(Clone, Copy, Debug)]
struct Scatter {
    /// The widest extent of the origins' box, times [`SCATTER_CELLS`].
    width: f32,
    o_lo: Vec3A,
    o_hi: Vec3A,
    inv_lo: Vec3A,
    inv_hi: Vec3A,
    /// The least `t_min`.
    t_min: f32,
}

/// The bounds of a packet's slab parameters a descent tests each
/// interior node with, once for the whole packet ([`Tree::visit_spread`]).
trait Interval {
    /// The least `t_min` of the rays.
    fn t_min(&self) -> f32;
    /// The least and greatest slab parameters of the rays at the planes
    /// `x` (per axis).
    fn at(&self, x: Vec3A) -> (Vec3A, Vec3A);
    /// The shared origin's spread, whose leaves take each pack once for
    /// every ray ([`Tree::leaf_packet`]).
    fn shared(&self) -> Option<&Spread>;
    /// True when a cell of edge `size` is wide enough for this descent
    /// ([`SCATTER_CELLS`]).
    fn fits(&self, size: f32) -> bool;

    /// The least near and the greatest far parameter of the slabs between
    /// the planes `a` and `b` (per axis).
    #[inline(always)]
    fn slab(&self, a: Vec3A, b: Vec3A) -> (Vec3A, Vec3A) {
        let (a_lo, a_hi) = self.at(a);
        let (b_lo, b_hi) = self.at(b);
        (a_lo.min(b_lo), a_hi.max(b_hi))
    }
}

impl Interval for Spread {
    #[inline(always)]
    fn t_min(&self) -> f32 {
        self.t_min
    }

    #[inline(always)]
    fn at(&self, x: Vec3A) -> (Vec3A, Vec3A) {
        let d = x - self.o;
        let (a, b) = (d * self.inv_lo, d * self.inv_hi);
        let up = d.cmpge(Vec3A::ZERO);
        (Vec3A::select(up, a, b), Vec3A::select(up, b, a))
    }

    #[inline(always)]
    fn shared(&self) -> Option<&Spread> {
        Some(self)
    }

    #[inline(always)]
    fn fits(&self, _size: f32) -> bool {
        true
    }
}

impl Interval for Scatter {
    #[inline(always)]
    fn t_min(&self) -> f32 {
        self.t_min
    }

    /// The four corners' products: `x - o` runs over `[x - o_hi, x -
    /// o_lo]`, `inv` over `[inv_lo, inv_hi]` (finite, so no NaN).
    #[inline(always)]
    fn at(&self, x: Vec3A) -> (Vec3A, Vec3A) {
        let (d_lo, d_hi) = (x - self.o_hi, x - self.o_lo);
        let (a, b) = (d_lo * self.inv_lo, d_lo * self.inv_hi);
        let (c, d) = (d_hi * self.inv_lo, d_hi * self.inv_hi);
        (a.min(b).min(c.min(d)), a.max(b).max(c.max(d)))
    }

    #[inline(always)]
    fn shared(&self) -> Option<&Spread> {
        None
    }

    #[inline(always)]
    fn fits(&self, size: f32) -> bool {
        self.width <= size
    }
}

impl<'q> Lanes<'q> {
    /// The lanes of `qs` (at most [`PACKET`]), or `None` when their
    /// direction signs differ.
    fn new(qs: &'q [Query<'q>]) -> Option<Lanes<'q>> {
        let q = |k: usize| &qs[k.min(qs.len() - 1)];
        let dir: [Wide; 3] = [0, 1, 2].map(|a| wide(&std::array::from_fn(|k| q(k).ray.dir[a])));
        // The sign bits of every lane (`RayCtx::sign_mask`'s, per axis):
        // all set or all clear.
        let mut sign_mask = 0;
        for (a, d) in dir.iter().enumerate() {
            match d[0].is_negative_bitmask() | d[1].is_negative_bitmask() << 4 {
                0 => {}
                0xff => sign_mask |= 1 << a,
                _ => return None,
            }
        }
        let bits = |k: usize| q(k).ray.origin.to_array().map(f32::to_bits);
        let shared = (1..qs.len()).all(|k| bits(k) == bits(0));
        let forward = qs.iter().all(|q| q.t_min >= 0.0);
        let cone = OnceCell::new();
        if !(shared && forward) {
            let _ = cone.set(None);
        }
        // One division per lane, as `RayCtx::new`'s.
        let inv = dir.map(|d| d.map(|v| Vec4::ONE / v));
        let t_min = wide(&std::array::from_fn(|k| q(k).t_min));
        let finite = |v: Vec4| v.abs().cmplt(Vec4::INFINITY).all();
        let origin = qs[0].ray.origin;
        let o = [0, 1, 2].map(|a| wide(&std::array::from_fn(|k| q(k).ray.origin[a])));
        let bounded = t_min.iter().all(|w| !w.is_nan_mask().any())
            && inv.iter().all(|w| finite(w[0]) && finite(w[1]));
        let (inv_lo, inv_hi) = (
            Vec3A::from_array(inv.map(|w| w[0].min(w[1]).min_element())),
            Vec3A::from_array(inv.map(|w| w[0].max(w[1]).max_element())),
        );
        let least_t_min = t_min[0].min(t_min[1]).min_element();
        let spread = (shared && bounded && origin.is_finite()).then(|| Spread {
            o: origin.into(),
            inv_lo,
            inv_hi,
            t_min: least_t_min,
        });
        let (o_lo, o_hi) = (
            Vec3A::from_array(o.map(|w| w[0].min(w[1]).min_element())),
            Vec3A::from_array(o.map(|w| w[0].max(w[1]).max_element())),
        );
        let finite_o = o.iter().all(|w| finite(w[0]) && finite(w[1]));
        let scatter = (!shared && bounded && finite_o).then(|| Scatter {
            width: (o_hi - o_lo).max_element() * SCATTER_CELLS,
            o_lo,
            o_hi,
            inv_lo,
            inv_hi,
            t_min: least_t_min,
        });
        Some(Lanes {
            o,
            inv,
            t_min,
            qs,
            sign_mask,
            origin: shared.then(|| origin.to_array()),
            cone,
            spread,
            scatter,
        })
    }

    /// Ray `k`'s own constants ([`RayCtx`]).
    fn ctx(&self, k: usize) -> RayCtx {
        let q = &self.qs[k];
        RayCtx::new(&q.ray, q.t_min)
    }

    /// The cone of [`Lanes::cone`], once.
    fn cone(&self) -> Option<Cone> {
        *self.cone.get_or_init(|| {
            let q = |k: usize| &self.qs[k.min(self.qs.len() - 1)];
            Cone::around(&std::array::from_fn(|a| {
                std::array::from_fn(|k| q(k).ray.dir[a])
            }))
        })
    }
}

/// `slab` of the single ray on four lanes: `(near, far)` of the planes at
/// parameters `a` and `b`, with its NaN rule (`a < b` false: the other
/// value).
#[inline(always)]
fn slab(a: Vec4, b: Vec4) -> (Vec4, Vec4) {
    (
        Vec4::select(a.cmplt(b), a, b),
        Vec4::select(a.cmpgt(b), a, b),
    )
}

/// The lanes whose `entry <= exit`, entry the largest of `near` (x, y, z)
/// and `t_min`, exit the smallest of `far` and `cut`: `maxps` / `minps`
/// (`a > b ? a : b`), the single ray's comparisons and NaN rule.
#[inline(always)]
fn open(near: [Vec4; 3], far: [Vec4; 3], t_min: Vec4, cut: Vec4) -> Mask {
    let entry = near[0].max(near[1]).max(near[2]).max(t_min);
    let exit = far[0].min(far[1]).min(far[2]).min(cut);
    entry.cmple(exit).bitmask()
}

/// Each active ray's cutoff (`-inf` on lanes without a ray).
#[inline(always)]
fn cutoffs<P: Primitive, V: Visitor<P>>(vis: &[Option<V>; PACKET]) -> Wide {
    wide(&std::array::from_fn(|k| {
        vis[k].as_ref().map_or(f32::NEG_INFINITY, V::cutoff)
    }))
}

/// After a child's visit stopped the rays `s` (of a packet or a spread):
/// they join `stopped` and leave `active`, and, rays being left, the
/// cutoffs are read anew (only a visit moves a cutoff). True when no ray
/// is left.
#[inline(always)]
fn settle<P: Primitive, V: Visitor<P>>(
    s: Mask,
    stopped: &mut Mask,
    active: &mut Mask,
    cut: &mut Wide,
    vis: &[Option<V>; PACKET],
) -> bool {
    *stopped |= s;
    *active &= !s;
    if *active == 0 {
        return true;
    }
    if !V::FIXED_CUTOFF {
        *cut = cutoffs(vis);
    }
    false
}

impl<P: Primitive> Tree<P> {
    /// The rays of `active` that meet the node's content box `[lo, hi]`
    /// within `[t_min, cutoff]`: [`Tree::visit`]'s test, four lanes at a
    /// time.
    // The halves of several arrays in lockstep.
    #[allow(clippy::needless_range_loop)]
    #[inline(always)]
    fn meets_box(l: &Lanes, [lo, hi]: [Vec3; 2], cut: &Wide, active: Mask) -> Mask {
        let mut m = 0;
        for h in 0..2 {
            let mut near = [Vec4::ZERO; 3];
            let mut far = [Vec4::ZERO; 3];
            for a in 0..3 {
                let (o, inv) = (l.o[a][h], l.inv[a][h]);
                (near[a], far[a]) = slab(
                    (Vec4::splat(lo[a]) - o) * inv,
                    (Vec4::splat(hi[a]) - o) * inv,
                );
            }
            m |= open(near, far, l.t_min[h], cut[h]) << (4 * h);
        }
        m & active
    }

    /// The leaf `node` for the rays of `active`, which share `origin`: each
    /// pack filtered once for all of them ([`Pack::masks_rays`], the lanes
    /// each ray's own filter passes), then each ray's lanes decided by its
    /// visitor, pack after pack and lane after lane as in
    /// [`Tree::leaf`]; with the copies' layout and a `spread` (the
    /// packet's, and the greatest cutoff of its rays or more), only the
    /// packs whose boxes it meets. Returns the rays whose visitor stopped.
    // The leaf, the packet and its state.
    #[allow(clippy::too_many_arguments)]
    fn leaf_packet<V: Visitor<P>>(
        &self,
        node: Node,
        origin: [f32; 3],
        cone: Option<Cone>,
        spread: Option<(&Spread, f32)>,
        vis: &mut [Option<V>; PACKET],
        mut active: Mask,
    ) -> Mask {
        let mut rays = PackRays {
            origin,
            cone,
            dir: [[0.0; 3]; PACKET],
            t_min: [0.0; PACKET],
            t_max: [0.0; PACKET],
        };
        let mut left = active;
        while left != 0 {
            let k = left.trailing_zeros() as usize;
            left &= left - 1;
            if let Some(v) = vis[k].as_ref() {
                let r = v.filter();
                rays.dir[k] = r.dir;
                rays.t_min[k] = r.t_min;
                rays.t_max[k] = r.t_max;
            }
        }
        // Each active ray's filter constants, made when its query started.
        let preps: [Option<<P::Pack as Pack<P>>::Prep>; PACKET] =
            std::array::from_fn(|k| vis[k].as_ref().map(|v| *v.prep()));
        let range = node.first as usize..(node.first + node.meta) as usize;
        let l = lanes::<P>();
        let mut stopped = 0;
        // The packs `at` (lanes `lanes[j]` of pack `at[j]`; at most
        // LEAF_CHUNK) for every active ray, filtered in one call; false
        // once no ray is left. A window narrowed within the call only
        // leaves the filter looser (each lane is decided by the visitor).
        let mut chunk = |at: &[u32], lanes: &[u32]| {
            let mut masks = [[0; PACKET]; LEAF_CHUNK];
            let mut passed = [0; LEAF_CHUNK];
            if self.shared {
                P::Pack::masks_rays_at(&self.packs, at, &rays, active, self.isa, &mut masks, &mut passed);
            } else if at[at.len() - 1] - at[0] != at.len() as u32 - 1 {
                // Packs left out by their boxes: the runs between.
                P::Pack::masks_rays_at(&self.packs, at, &rays, active, self.isa, &mut masks, &mut passed);
            } else {
                let packs = &self.packs[at[0] as usize..at[0] as usize + at.len()];
                P::Pack::masks_rays_prepped(
                    packs,
                    &rays,
                    &preps,
                    active,
                    self.isa,
                    &mut masks,
                    &mut passed,
                );
            }
            for (j, &p) in at.iter().enumerate() {
                let pack = &self.packs[p as usize];
                let ids = &self.pack_ids[p as usize * l..(p as usize + 1) * l];
                let mut left = passed[j] & active;
                while left != 0 {
                    let k = left.trailing_zeros() as usize;
                    left &= left - 1;
                    let mut m = masks[j][k] & lanes[j];
                    if m == 0 {
                        continue;
                    }
                    let Some(v) = vis[k].as_mut() else { continue };
                    while m != 0 {
                        let lane = m.trailing_zeros() as usize;
                        m &= m - 1;
                        if v.lane(pack.get(lane, ids[lane], &self.side), ids[lane]) {
                            stopped |= 1 << k;
                            active &= !(1 << k);
                            break;
                        }
                    }
                    rays.t_max[k] = v.filter().t_max;
                }
                if active == 0 {
                    return false;
                }
            }
            true
        };
        // The leaf's packs, LEAF_CHUNK a call ([`first_chunk`] the
        // first): the shared layout's entries wherever their packs lie
        // (with the lanes each references), the copies' packs in order.
        let mut start = range.start;
        let mut size = first_chunk::<P, V>();
        while start < range.end {
            let end = (start + size).min(range.end);
            let mut at = [0; LEAF_CHUNK];
            let mut lanes = [u32::MAX; LEAF_CHUNK];
            // The packs this call filters: `n` of them in `at`.
            let n = if self.shared {
                for (j, &e) in self.entries[start..end].iter().enumerate() {
                    (at[j], lanes[j]) = (e & ENTRY_PACK, e >> ENTRY_MASK_SHIFT);
                }
                end - start
            } else if let Some((sp, far)) = spread {
                // The copies' packs whose boxes the packet meets.
                let mut met = met_packs_spread(&self.pack_boxes, start, end - start, sp, far);
                let mut n = 0;
                while met != 0 {
                    at[n] = (start + met.trailing_zeros() as usize) as u32;
                    met &= met - 1;
                    n += 1;
                }
                n
            } else {
                at = std::array::from_fn(|j| (start + j) as u32);
                end - start
            };
            if n > 0 && !chunk(&at[..n], &lanes[..n]) {
                break;
            }
            (start, size) = (end, LEAF_CHUNK);
        }
        stopped
    }

    /// The leaf `node` for each ray of `active`, with its own constants
    /// ([`Tree::leaf_of_ray`]); returns the rays whose visitor stopped.
    /// One copy for both descents that call it (inlined into each, the
    /// stripped Python module was 107 kB larger).
    #[inline(never)]
    fn leaf_rays<V: Visitor<P>>(
        &self,
        node: Node,
        l: &Lanes,
        vis: &mut [Option<V>; PACKET],
        mut active: Mask,
    ) -> Mask {
        let mut stopped = 0;
        while active != 0 {
            let k = active.trailing_zeros() as usize;
            active &= active - 1;
            if let Some(v) = vis[k].as_mut()
                && self.leaf_of_ray(node, &l.ctx(k), v)
            {
                stopped |= 1 << k;
            }
        }
        stopped
    }

    /// The subtree of node `index` (cell `lo`, edge `size`) for the rays of
    /// `active`, whose cutoffs are `cut` now, front to back in the
    /// packet's order; returns the rays whose visitor stopped (any-hit
    /// queries that found a hit).
    // The node, the packet and its state.
    #[allow(clippy::too_many_arguments)]
    fn visit_packet<V: Visitor<P>>(
        &self,
        index: usize,
        lo: Vec3,
        size: f32,
        l: &Lanes,
        vis: &mut [Option<V>; PACKET],
        active: Mask,
        mut cut: Wide,
    ) -> Mask {
        if active.count_ones() <= LONE {
            // Few rays left: each its own descent, with its own constants.
            let mut stopped = 0;
            let mut left = active;
            while left != 0 {
                let k = left.trailing_zeros() as usize;
                left &= left - 1;
                if let Some(v) = vis[k].as_mut()
                    && self.visit(index, lo, size, &l.ctx(k), v)
                {
                    stopped |= 1 << k;
                }
            }
            return stopped;
        }
        let node = self.nodes[index];
        let mut active = Self::meets_box(l, self.boxes[index], &cut, active);
        if active == 0 {
            return 0;
        }
        let mut stopped = 0;
        if node.meta & INTERIOR == 0 {
            if let Some(origin) = l.origin {
                let spread = l.spread.as_ref().map(|sp| (sp, reach(&cut, active)));
                return self.leaf_packet(node, origin, l.cone(), spread, vis, active);
            }
            return self.leaf_rays(node, l, vis, active);
        }
        // Slab parameters of the padded lower and upper halves on each
        // axis, for every ray: the single ray's arithmetic. Per half and
        // axis: (near, far) of the lower half, of the upper.
        let mask = node.meta & 0xff;
        let half = size * 0.5;
        let pad = self.pad;
        let (mid, hi) = (lo + Vec3::splat(half), lo + Vec3::splat(size));
        let mut lower = [[(Vec4::ZERO, Vec4::ZERO); 3]; 2];
        let mut upper = [[(Vec4::ZERO, Vec4::ZERO); 3]; 2];
        for h in 0..2 {
            for a in 0..3 {
                let (o, inv) = (l.o[a][h], l.inv[a][h]);
                let t = |x: f32| (Vec4::splat(x) - o) * inv;
                lower[h][a] = slab(t(lo[a] - pad), t(mid[a] + pad));
                upper[h][a] = slab(t(mid[a] - pad), t(hi[a] + pad));
            }
        }
        for i in 0..8 {
            let oct = i ^ l.sign_mask;
            if mask & (1 << oct) == 0 {
                continue;
            }
            let mut m = 0;
            for h in 0..2 {
                let side = |a: usize| {
                    if oct & (1 << a) != 0 {
                        upper[h][a]
                    } else {
                        lower[h][a]
                    }
                };
                let (x, y, z) = (side(0), side(1), side(2));
                m |= open([x.0, y.0, z.0], [x.1, y.1, z.1], l.t_min[h], cut[h]) << (4 * h);
            }
            let m = m & active;
            if m == 0 {
                continue;
            }
            let child = node.first as usize + (mask & ((1 << oct) - 1)).count_ones() as usize;
            let s = self.visit_packet(child, child_lo(lo, half, oct), half, l, vis, m, cut);
            if settle(s, &mut stopped, &mut active, &mut cut, vis) {
                break;
            }
        }
        stopped
    }
}

/// Bit `j` set when the packet of `sp` may meet the box of pack
/// `first + j` (`j < len <= 16`) of `boxes` ([`Tree::pack_boxes`]) within
/// `[sp.t_min, far]`: the interval of [`Spread`], holding every ray's own,
/// against [`super::BOX_GROUP`] packs a register; a pack no ray of the packet
/// meets within its window holds no lane its exact test could decide
/// (the single ray's [`super::traverse`] `met_packs`).
#[inline(always)]
fn met_packs_spread(boxes: &[PackBoxes], first: usize, len: usize, sp: &Spread, far: f32) -> u32 {
    let (o, lo, hi) = (sp.o.to_array(), sp.inv_lo.to_array(), sp.inv_hi.to_array());
    met_in_groups(boxes, first, len, |b| {
        let (mut near, mut exit) = (Vec4::splat(sp.t_min), Vec4::splat(far));
        for a in 0..3 {
            // The least and greatest parameters at a plane (`Spread::at`).
            let at = |x: Vec4| {
                let d = x - Vec4::splat(o[a]);
                let (p, q) = (d * lo[a], d * hi[a]);
                let up = d.cmpge(Vec4::ZERO);
                (Vec4::select(up, p, q), Vec4::select(up, q, p))
            };
            let ((l0, h0), (l1, h1)) = (at(b[a]), at(b[a + 3]));
            near = near.max(l0.min(l1));
            exit = exit.min(h0.max(h1));
        }
        near.cmple(exit).bitmask()
    })
}

/// The greatest cutoff of the rays of `active` (`-inf` for none; a NaN
/// cutoff, which lets its ray into no cell, is passed over).
#[inline(always)]
fn reach(cut: &Wide, active: Mask) -> f32 {
    let c = [cut[0].to_array(), cut[1].to_array()];
    let mut r = f32::NEG_INFINITY;
    for k in 0..PACKET {
        // NaN compares false: passed over.
        if active & (1 << k) != 0 && c[k >> 2][k & 3] > r {
            r = c[k >> 2][k & 3];
        }
    }
    r
}

impl<P: Primitive> Tree<P> {
    /// [`Tree::visit_packet`] for a packet with a [`Spread`]: each interior
    /// node's content box and child cells tested once for the whole packet
    /// (the interval of [`Spread`], holding every ray's own, against the
    /// least `t_min` and the greatest cutoff), the eight children at once
    /// as in [`Tree::visit`] (`far`: the greatest cutoff of the rays of
    /// `active`, or more); only a leaf tests each ray's own interval
    /// ([`Tree::meets_box`]) before [`Tree::leaf_packet`]. A ray is taken
    /// into a cell it does not meet only where another ray of the packet
    /// meets it; there it meets no leaf, or the leaf's own test drops it.
    // The node, the packet and its state.
    #[allow(clippy::too_many_arguments)]
    fn visit_spread<V: Visitor<P>, S: Interval>(
        &self,
        index: usize,
        lo: Vec3,
        size: f32,
        l: &Lanes,
        sp: &S,
        vis: &mut [Option<V>; PACKET],
        active: Mask,
        mut cut: Wide,
        mut far: f32,
    ) -> Mask {
        if active.count_ones() <= LONE || !sp.fits(size) {
            return self.visit_packet(index, lo, size, l, vis, active, cut);
        }
        let node = self.nodes[index];
        if node.meta & INTERIOR == 0 {
            let active = Self::meets_box(l, self.boxes[index], &cut, active);
            if active == 0 {
                return 0;
            }
            return match (sp.shared(), l.origin) {
                (Some(sp), Some(origin)) => {
                    self.leaf_packet(node, origin, l.cone(), Some((sp, far)), vis, active)
                }
                _ => self.leaf_rays(node, l, vis, active),
            };
        }
        let [blo, bhi] = self.boxes[index];
        let (near, exit) = sp.slab(Vec3A::from(blo), Vec3A::from(bhi));
        // NaN compares false (none is expected: finite origins and `inv`).
        let entry = super::traverse::max4(sp.t_min(), near.into());
        let meets = entry <= super::traverse::min4(far, exit.into());
        if !meets {
            return 0;
        }
        let mask = node.meta & 0xff;
        let half = size * 0.5;
        let [(l0, l1), (u0, u1)] = super::traverse::halves(lo, size, self.pad);
        let (lower_near, lower_far) = sp.slab(l0, l1);
        let (upper_near, upper_far) = sp.slab(u0, u1);
        // The eight children's intervals at once, as in `Tree::visit`.
        let (open, entries) = super::traverse::children(
            (lower_near.into(), lower_far.into()),
            (upper_near.into(), upper_far.into()),
            sp.t_min(),
            far,
            mask,
        );
        if open == 0 {
            return 0;
        }
        let mut active = active;
        let mut stopped = 0;
        for i in 0..8 {
            let oct = i ^ l.sign_mask;
            // The rays' windows may have shrunk since `far` was taken.
            let within = entries[oct >> 2][oct & 3] <= far;
            if open & (1 << oct) == 0 || !within {
                continue;
            }
            let child = node.first as usize + (mask & ((1 << oct) - 1)).count_ones() as usize;
            let s = self.visit_spread(
                child,
                child_lo(lo, half, oct),
                half,
                l,
                sp,
                vis,
                active,
                cut,
                far,
            );
            if settle(s, &mut stopped, &mut active, &mut cut, vis) {
                break;
            }
            if !V::FIXED_CUTOFF {
                far = reach(&cut, active);
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
        let first = l.ctx(0);
        for (i, tree) in self.parts.iter().enumerate().take(n) {
            order[i] = (tree.window(&first).0, i);
        }
        order[..n].sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        (order.map(|(_, i)| i), n)
    }

    /// Every part for the rays of `active`; the rays that stopped. Any-hit
    /// rays take the parts in their order, as [`Octree::any_hit`] does.
    fn walk_parts<V: Visitor<P>>(
        &self,
        l: &Lanes,
        vis: &mut [Option<V>; PACKET],
        mut active: Mask,
    ) -> Mask {
        let (order, n) = if V::FIXED_CUTOFF {
            let n = self.parts.len().min(super::parts::MAX_PARTS);
            (std::array::from_fn(|i| i), n)
        } else {
            self.part_order(l)
        };
        let mut stopped = 0;
        for &i in &order[..n] {
            let tree = &self.parts[i];
            if tree.references == 0 || tree.nodes.is_empty() {
                continue;
            }
            let cut = cutoffs(vis);
            let (lo, size) = (tree.root_lo, tree.root_size);
            let far = reach(&cut, active);
            let s = match (&l.spread, &l.scatter) {
                (Some(sp), _) => tree.visit_spread(0, lo, size, l, sp, vis, active, cut, far),
                // Shadow rays only (any-hit), where it was measured.
                (None, Some(sc)) if V::FIXED_CUTOFF => {
                    tree.visit_spread(0, lo, size, l, sc, vis, active, cut, far)
                }
                _ => tree.visit_packet(0, lo, size, l, vis, active, cut),
            };
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
        qs: &'q [Query<'q>],
        hits: &mut [CandidateHits],
        skip: impl Fn(&'q Query<'q>) -> S,
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
        let mut vis: [Option<Gather<'_, P, S>>; PACKET] = std::array::from_fn(|_| {
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
        qs: &'q [Query<'q>],
        out: &mut [bool],
        skip: impl Fn(&'q Query<'q>) -> S,
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
        let mut vis: [Option<AnyHit<'_, P, S>>; PACKET] = std::array::from_fn(|_| {
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
            } else if qs.iter().all(|q| q.from.is_none() && q.pass.is_none()) {
                self.gather_chunk(qs, hits, |_| NoSkip);
            } else {
                self.gather_chunk(qs, hits, Query::secondary);
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
            } else if qs.iter().all(|q| q.from.is_none() && q.pass.is_none()) {
                self.any_hit_chunk(qs, out, |_| NoSkip);
            } else {
                self.any_hit_chunk(qs, out, Query::secondary);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::traverse::tests::{bits, bumpy, clipped_thirds, packet_answers};
    use super::super::{Octree, OctreeParams};
    use crate::accel::{Backend, CandidateHits, Query};
    use crate::geometry::Ray;
    use crate::primitive::Primitive;
    use glam::Vec3;

    /// Every packet over spans `[t_min, inf)` and `[t_min, 3]`: the
    /// windows and occlusion of [`Backend::intersect_packet`] and
    /// [`Backend::occluded_packet`] those of one ray at a time, bit for
    /// bit; returns the windows not empty and the rays occluded.
    fn compare<P: Primitive>(oct: &Octree<P>, packets: &[Vec<Ray>], t_min: f32) -> (usize, usize) {
        let xi = 0.01;
        let mut one = CandidateHits::new(xi);
        let (mut found, mut blocked) = (0, 0);
        for t_max in [f32::INFINITY, 3.0] {
            for packet in packets {
                let qs: Vec<Query> = packet.iter().map(|r| Query::new(*r, t_min, t_max)).collect();
                let (got, occluded) = packet_answers(oct, &qs, xi);
                for ((q, g), o) in qs.iter().zip(&got).zip(occluded) {
                    oct.intersect_from(q, &mut one);
                    assert_eq!(bits(g), bits(&one), "{:?} {t_max}", q.ray);
                    assert_eq!(o, oct.occluded_from(q), "{:?} {t_max}", q.ray);
                    found += usize::from(!g.is_empty());
                    blocked += usize::from(o);
                }
            }
        }
        (found, blocked)
    }

    /// A [`super::Scatter`]'s bounds hold every ray's own slab parameter
    /// at a plane, `(x - o) inv` as the ray's descent computes it: packets
    /// of 8 rays from origins in boxes of several sizes, directions in
    /// cones of several widths (a packet's in one octant, every octant),
    /// planes near and far.
    #[test]
    fn a_scatter_holds_each_rays_slab_parameter() {
        use super::Interval;
        let mut rng = crate::rng::SplitMix64::new(55);
        for _ in 0..4_000 {
            let (spread, width) = (rng.range(0.0, 0.5), [1e-4, 1e-2, 0.3][rng.below(3)]);
            let (centre, axis) = (rng.unit() * 3.0, rng.unit().abs() + Vec3::splat(0.05));
            let octant = rng.unit().signum();
            let rays: Vec<Ray> = (0..8)
                .map(|_| {
                    let o = centre + rng.unit() * width * rng.next_f32();
                    Ray::new(o, (axis.normalize() + rng.unit() * spread).abs() * octant)
                })
                .collect();
            let qs: Vec<Query> = rays.iter().map(|r| Query::new(*r, 1e-3, 9.0)).collect();
            let sc = super::Lanes::new(&qs).and_then(|l| l.scatter).expect("one octant");
            for _ in 0..8 {
                let x = centre + (rng.unit() * [0.01, 0.5, 20.0][rng.below(3)]);
                let (lo, hi) = sc.at(x.into());
                for r in &rays {
                    let t = (x - r.origin) * r.dir.recip();
                    let within = t.cmpge(lo.into()) & t.cmple(hi.into());
                    assert!(within.all(), "{t} not in {lo}..{hi}");
                }
            }
        }
    }

    /// 150,000 discs on the bumpy sphere (a few wide ones), whole and with
    /// clip lines on every third: the grid's cells hold more than
    /// `max_leaf` centres, so the leaves below them hold up to
    /// `deep_leaf`. Packets of 8 camera rays from one eye (whose leaves
    /// leave out the packs the packet's spread misses), of 8 rays from
    /// points scattered over the sphere toward a light (each ray's own
    /// descent and leaf code, its packs' boxes) and of the shadow rays of 8
    /// neighbouring pixels' hits (descending by their [`super::Scatter`]
    /// through the wide cells) answer as one ray at a time, bit for bit.
    #[test]
    fn deep_leaves_answer_in_packets_as_one_ray_at_a_time() {
        let discs = bumpy(150_000, |i| if i % 5000 == 7 { 0.2 } else { 0.012 });
        let eye = Vec3::new(0.9, 0.7, 3.6);
        let (fwd, side) = (-eye.normalize(), 96);
        let right = fwd.cross(Vec3::Y).normalize();
        let up = right.cross(fwd);
        let s = |i: usize| 0.4 * ((i as f32 + 0.5) / side as f32 * 2.0 - 1.0);
        let camera: Vec<Vec<Ray>> = (0..side * side)
            .map(|k| Ray::new(eye, fwd + right * s(k % side) + up * s(k / side)))
            .collect::<Vec<_>>()
            .chunks(8)
            .map(<[Ray]>::to_vec)
            .collect();
        let light = Vec3::new(5.0, 6.0, 3.0);
        let shadow: Vec<Vec<Ray>> = (0..4_000)
            .map(|k| {
                let c = discs[k * 37].center;
                Ray::new(c, (light - c).normalize())
            })
            .collect::<Vec<_>>()
            .chunks(8)
            .map(<[Ray]>::to_vec)
            .collect();
        let params = OctreeParams::default();
        let whole = Octree::new(&discs, &params);
        let refs = whole.stats().mean_refs_per_leaf;
        // Measured: 132.4 references a leaf.
        assert!(refs > params.max_leaf as f64, "{refs} references a leaf");
        // The shadow rays of 8 neighbouring pixels' hits (of a row of a
        // 1024-pixel-wide image) toward `light`, as a render's screen tile
        // gives them.
        let mut hits = CandidateHits::new(0.01);
        let fine = |i: usize| 0.4 * ((i as f32 + 0.5) / 1024.0 * 2.0 - 1.0);
        let mut neighbours = |light: Vec3| -> Vec<Vec<Ray>> {
            (0..800)
                .map(|j| {
                    let (x0, y) = ((j * 131) % 1016, (j * 977) % 1024);
                    let mut from = |x: usize| {
                        let r = Ray::new(eye, fwd + right * fine(x) + up * fine(y));
                        whole.intersect_from(&Query::new(r, 0.0, f32::INFINITY), &mut hits);
                        let p = r.origin + r.dir * hits.as_slice().first()?.t;
                        Some(Ray::new(p, (light - p).normalize()))
                    };
                    (x0..x0 + 8).filter_map(&mut from).collect::<Vec<Ray>>()
                })
                .filter(|rays| rays.len() > 1)
                .collect()
        };
        // Far and near the surface (the near light's rays spread).
        let (far, near) = (neighbours(light), neighbours(Vec3::new(0.45, 0.4, 1.5)));
        // Most of them descend by their scatter down to the grid's cells
        // (measured: 285 and 283 of 321).
        let grid_cell = whole.parts[0].root_size / 16.0;
        let scattered = |packets: &[Vec<Ray>]| {
            let fits = |rays: &&Vec<Ray>| {
                let qs: Vec<Query> = rays.iter().map(|r| Query::new(*r, 1e-3, 9.0)).collect();
                let l = super::Lanes::new(&qs);
                l.and_then(|l| l.scatter).is_some_and(|sc| super::Interval::fits(&sc, grid_cell))
            };
            (packets.iter().filter(fits).count(), packets.len())
        };
        let (sf, sn) = (scattered(&far), scattered(&near));
        assert!(sf.0 * 10 > sf.1 * 8 && sn.0 * 10 > sn.1 * 5, "{sf:?} {sn:?}");
        let cut = Octree::new(&clipped_thirds(&discs), &params);
        let found = [
            compare(&whole, &camera, 0.0),
            compare(&cut, &camera, 0.0),
            compare(&whole, &shadow, 1e-3),
            compare(&cut, &shadow, 1e-3),
            compare(&whole, &far, 1e-3),
            compare(&cut, &far, 1e-3),
            compare(&whole, &near, 1e-3),
            compare(&cut, &near, 1e-3),
        ];
        eprintln!("{refs} references a leaf; (windows not empty, occluded): {found:?}");
        for (f, b) in found {
            assert!(f > 1_000 && b > 1_000, "{f} {b}");
        }
    }
}
