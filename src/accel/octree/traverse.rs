//! Front-to-back traversal of the [`Octree`] (§3.2) and what it does in the
//! leaves: gather the candidate window, or stop at the first hit.

use super::{INTERIOR, Octree, child_lo, lanes};
use crate::accel::{Candidate, CandidateHits, Skip};
use crate::geometry::Ray;
use crate::primitive::{Pack, PackRay, Primitive};
use glam::{Vec3, Vec3A};

impl<P: Primitive> Octree<P> {
    /// Front-to-back traversal from the root; `visitor` sees the leaves.
    /// Returns true when the visitor stopped it.
    #[inline]
    pub(super) fn traverse<V: Visitor<P>>(&self, ray: &Ray, t_min: f32, visitor: &mut V) -> bool {
        if self.references == 0 {
            return false;
        }
        let ctx = RayCtx {
            origin: ray.origin,
            inv_dir: Vec3::ONE / ray.dir,
            sign_mask: usize::from(ray.dir.x.is_sign_negative())
                | usize::from(ray.dir.y.is_sign_negative()) << 1
                | usize::from(ray.dir.z.is_sign_negative()) << 2,
            t_min,
            origin_a: Vec3A::from(ray.origin),
            inv_dir_a: Vec3A::ONE / Vec3A::from(ray.dir),
        };
        let pad = Vec3::splat(self.pad);
        let lo = self.root_lo;
        let a = (lo - pad - ctx.origin) * ctx.inv_dir;
        let b = (lo + Vec3::splat(self.root_size) + pad - ctx.origin) * ctx.inv_dir;
        let (near, far) = slab(a, b);
        let entry = max4(t_min, near);
        let exit = min4(visitor.cutoff(), far);
        // NaN compares false: a NaN entry or exit misses the root.
        let meets_root = entry <= exit;
        if !meets_root {
            return false;
        }
        match &self.grid {
            Some(g) => self.walk_grid(g, ray, entry, &ctx, visitor),
            None => self.visit(0, lo, self.root_size, &ctx, visitor),
        }
    }

    /// The top levels as a uniform grid: the cells the ray crosses, front
    /// to back from `entry` (3D-DDA, Amanatides and Woo), each cell's node
    /// visited as a subtree (once: consecutive cells under one shallow leaf
    /// visit it once). A crossing misjudged by rounding skips at most a
    /// sliver of a cell thinner than the padding, whose primitives the
    /// neighbouring cells' padded leaves also hold.
    fn walk_grid<V: Visitor<P>>(
        &self,
        g: &super::Grid,
        ray: &Ray,
        entry: f32,
        ctx: &RayCtx,
        visitor: &mut V,
    ) -> bool {
        let n = g.n as i32;
        let p = (ray.origin + ray.dir * entry - self.root_lo) / g.cell;
        let start = |c: f32| (c.floor() as i32).clamp(0, n - 1);
        let mut idx = [start(p.x), start(p.y), start(p.z)];
        let d = ray.dir.to_array();
        let o = ray.origin.to_array();
        let inv = ctx.inv_dir.to_array();
        let lo = self.root_lo.to_array();
        let mut step = [0i32; 3];
        let mut t_next = [f32::INFINITY; 3];
        let mut t_delta = [f32::INFINITY; 3];
        for a in 0..3 {
            if d[a] > 0.0 {
                step[a] = 1;
                t_next[a] = (lo[a] + (idx[a] + 1) as f32 * g.cell - o[a]) * inv[a];
                t_delta[a] = g.cell * inv[a];
            } else if d[a] < 0.0 {
                step[a] = -1;
                t_next[a] = (lo[a] + idx[a] as f32 * g.cell - o[a]) * inv[a];
                t_delta[a] = -g.cell * inv[a];
            }
        }
        let mut last = super::NO_NODE;
        // Each step leaves the grid on one axis or moves one cell: at most
        // 3n steps cross it (a NaN ray stops at the first comparison).
        for _ in 0..3 * g.n + 3 {
            let i = (idx[0] + n * (idx[1] + n * idx[2])) as usize;
            let node = g.node[i];
            if node != super::NO_NODE && node != last {
                last = node;
                if self.visit(node as usize, g.lo[i], g.size[i], ctx, visitor) {
                    return true;
                }
            }
            let a = if t_next[0] < t_next[1] {
                if t_next[0] < t_next[2] { 0 } else { 2 }
            } else if t_next[1] < t_next[2] {
                1
            } else {
                2
            };
            // The next cell starts beyond the window (or NaN): done.
            let within = t_next[a] <= visitor.cutoff();
            if !within {
                return false;
            }
            idx[a] += step[a];
            if idx[a] < 0 || idx[a] >= n {
                return false;
            }
            t_next[a] += t_delta[a];
        }
        false
    }

    fn visit<V: Visitor<P>>(
        &self,
        index: usize,
        lo: Vec3,
        size: f32,
        ctx: &RayCtx,
        visitor: &mut V,
    ) -> bool {
        let node = self.nodes[index];
        if node.meta & INTERIOR == 0 {
            let range = node.first as usize..(node.first + node.meta) as usize;
            return visitor.leaf(
                &self.packs[range.clone()],
                &self.pack_ids[range.start * lanes::<P>()..range.end * lanes::<P>()],
            );
        }
        let mask = node.meta & 0xff;
        let half = size * 0.5;
        // The same IEEE operations as on `Vec3`, four lanes at a time.
        let lo_a = Vec3A::from(lo);
        let pad = Vec3A::splat(self.pad);
        let mid = lo_a + Vec3A::splat(half);
        let hi = lo_a + Vec3A::splat(size);
        let o = ctx.origin_a;
        let inv = ctx.inv_dir_a;
        // Slab parameters of the padded lower and upper halves on each axis.
        let (lower_near, lower_far) = slab_a((lo_a - pad - o) * inv, (mid + pad - o) * inv);
        let (upper_near, upper_far) = slab_a((mid - pad - o) * inv, (hi + pad - o) * inv);
        // Entry and exit of all eight children at once, branch free; only
        // the children whose interval is non-empty are visited.
        let cut = visitor.cutoff();
        let near = [lower_near.to_array(), upper_near.to_array()];
        let far = [lower_far.to_array(), upper_far.to_array()];
        let corner = |oct: usize, v: &[[f32; 3]; 2]| {
            Vec3::new(v[oct & 1][0], v[(oct >> 1) & 1][1], v[oct >> 2][2])
        };
        let entry: [f32; 8] = std::array::from_fn(|oct| max4(ctx.t_min, corner(oct, &near)));
        let exit: [f32; 8] = std::array::from_fn(|oct| min4(cut, corner(oct, &far)));
        let mut open = 0u32;
        for oct in 0..8 {
            open |= u32::from(entry[oct] <= exit[oct]) << oct;
        }
        let open = open & mask;
        if open == 0 {
            return false;
        }
        for i in 0..8 {
            let oct = i ^ ctx.sign_mask;
            // The window may have shrunk since `exit` was computed.
            if open & (1 << oct) == 0 || entry[oct] > visitor.cutoff() {
                continue;
            }
            let child = node.first as usize + (mask & ((1 << oct) - 1)).count_ones() as usize;
            if self.visit(child, child_lo(lo, half, oct), half, ctx, visitor) {
                return true;
            }
        }
        false
    }
}

/// Per-ray constants of the traversal.
struct RayCtx {
    origin: Vec3,
    /// `1 / dir`, `±inf` on zero components.
    inv_dir: Vec3,
    /// Bit `k` set when `dir[k]` is negative (sign bit, so `-0.0` counts).
    sign_mask: usize,
    t_min: f32,
    /// `origin` and `inv_dir` in SIMD lanes.
    origin_a: Vec3A,
    inv_dir_a: Vec3A,
}

/// Per-axis (near, far) of a slab from the parameters of its two planes.
/// `a < b` is false for NaN, which then yields NaN or the other value; the
/// callers' comparisons treat that as a miss of the cell (module doc).
#[inline]
fn slab(a: Vec3, b: Vec3) -> (Vec3, Vec3) {
    let near = Vec3::new(
        if a.x < b.x { a.x } else { b.x },
        if a.y < b.y { a.y } else { b.y },
        if a.z < b.z { a.z } else { b.z },
    );
    let far = Vec3::new(
        if a.x > b.x { a.x } else { b.x },
        if a.y > b.y { a.y } else { b.y },
        if a.z > b.z { a.z } else { b.z },
    );
    (near, far)
}

/// [`slab`] on SIMD lanes, with the same NaN rule (`a < b` false: the
/// other value).
#[inline]
fn slab_a(a: Vec3A, b: Vec3A) -> (Vec3, Vec3) {
    let near = Vec3A::select(a.cmplt(b), a, b);
    let far = Vec3A::select(a.cmpgt(b), a, b);
    (Vec3::from(near), Vec3::from(far))
}

#[inline]
fn max4(t: f32, v: Vec3) -> f32 {
    let m = if v.x > v.y { v.x } else { v.y };
    let m = if m > v.z { m } else { v.z };
    if m > t { m } else { t }
}

#[inline]
fn min4(t: f32, v: Vec3) -> f32 {
    let m = if v.x < v.y { v.x } else { v.y };
    let m = if m < v.z { m } else { v.z };
    if m < t { m } else { t }
}

/// What a traversal does in the leaves.
pub(super) trait Visitor<P: Primitive> {
    /// Cells entered beyond this are skipped.
    fn cutoff(&self) -> f32;
    /// Tests a leaf's packs (with their lanes' primitive ids); true stops
    /// the traversal.
    fn leaf(&mut self, packs: &[P::Pack], ids: &[u32]) -> bool;
}

/// `intersect`: gathers the candidate window, leaving out what `skip`
/// skips.
pub(super) struct Gather<'a, S> {
    ray: &'a Ray,
    lanes: PackRay,
    t_min: f32,
    t_max: f32,
    skip: S,
    hits: &'a mut CandidateHits,
}

impl<'a, S: Skip> Gather<'a, S> {
    pub(super) fn new(
        ray: &'a Ray,
        t_min: f32,
        t_max: f32,
        skip: S,
        hits: &'a mut CandidateHits,
    ) -> Self {
        Gather {
            ray,
            lanes: PackRay::new(ray),
            t_min,
            t_max,
            skip,
            hits,
        }
    }
}

impl<P: Primitive, S: Skip> Visitor<P> for Gather<'_, S> {
    #[inline]
    fn cutoff(&self) -> f32 {
        self.t_max.min(self.hits.far())
    }

    #[inline]
    fn leaf(&mut self, packs: &[P::Pack], ids: &[u32]) -> bool {
        let mut cut = self.t_max.min(self.hits.far());
        for (pack, ids) in packs.iter().zip(ids.chunks_exact(lanes::<P>())) {
            let mut mask = pack.may_hit(&self.lanes, self.t_min, cut);
            while mask != 0 {
                let lane = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                // The shared routine decides, with the window's current end,
                // and the shared rule skips.
                let prim = pack.get(lane);
                if let Some(h) = prim.intersect(self.ray, self.t_min, cut) {
                    if self.skip.skips(self.ray.dir, ids[lane], &prim) {
                        continue;
                    }
                    let c = Candidate {
                        id: ids[lane],
                        t: h.t,
                        u: h.u,
                        v: h.v,
                    };
                    cut = self.hits.offer(c).min(self.t_max);
                }
            }
        }
        false
    }
}

/// `occluded`: stops at the first hit that `skip` does not skip.
pub(super) struct AnyHit<'a, S> {
    ray: &'a Ray,
    lanes: PackRay,
    t_min: f32,
    t_max: f32,
    skip: S,
}

impl<'a, S: Skip> AnyHit<'a, S> {
    pub(super) fn new(ray: &'a Ray, t_min: f32, t_max: f32, skip: S) -> Self {
        AnyHit {
            ray,
            lanes: PackRay::new(ray),
            t_min,
            t_max,
            skip,
        }
    }
}

impl<P: Primitive, S: Skip> Visitor<P> for AnyHit<'_, S> {
    #[inline]
    fn cutoff(&self) -> f32 {
        self.t_max
    }

    #[inline]
    fn leaf(&mut self, packs: &[P::Pack], ids: &[u32]) -> bool {
        packs
            .iter()
            .zip(ids.chunks_exact(lanes::<P>()))
            .any(|(pack, ids)| {
                let mut mask = pack.may_hit(&self.lanes, self.t_min, self.t_max);
                while mask != 0 {
                    let lane = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    let prim = pack.get(lane);
                    if prim.intersect(self.ray, self.t_min, self.t_max).is_some()
                        && !self.skip.skips(self.ray.dir, ids[lane], &prim)
                    {
                        return true;
                    }
                }
                false
            })
    }
}
