//! Scattered occlusion rays walked through the grid several at once (the
//! front-to-back traversal of report §3.2, eight rays abreast).
//!
//! One ray at a time, the grid walk of [`Tree::walk_grid`] chooses the
//! axis it crosses next by a branch that rays of scattered directions
//! leave unpredictable, and a ray that meets nothing spends most of its
//! time in those steps (7.5 of them on a bunny's box rays, about 60 ns:
//! `docs/notes/backends.md`, issue 55, seventy-fourth session). Here [`LANES`] rays
//! walk side by side: each round every lane takes one step chosen by
//! comparisons kept as masks (no branch, and the lanes' chains are
//! independent, so one lane's latency hides behind the others'), and only
//! a lane whose new cell holds a node it has not visited leaves the round
//! for [`Tree::meets`] and [`Tree::enter`], the very calls of the walk of
//! one ray. A lane whose ray ends takes the batch's next ray. Each ray
//! visits the same cells in the same order with the same calls as when
//! walked alone, so its answer is the same.

use super::traverse::{AnyHit, RayCtx, Visitor};
use super::{Grid, NO_NODE, Octree, Tree};
use crate::accel::{Query, Skip};
use crate::primitive::Primitive;
use glam::Vec4;

/// Rays walked side by side: two groups of four lanes.
const LANES: usize = 8;

// A grid's cell indices are whole numbers `f32` holds exactly.
const _: () = assert!(1u64 << (3 * super::GRID_LEVEL) <= 1 << 24);

/// The lanes' walk state, each field a column of [`LANES`] in two
/// registers of four. Cell indices and counts are held as `f32`: whole
/// numbers below 2^24 (a grid of 16³ cells), which float addition keeps
/// exact, so the step is one register type throughout.
struct Lanes {
    /// The grid cell each lane is in (`x + n (y + n z)`).
    cell: [Vec4; 2],
    /// Per axis: where the lane's ray crosses into the next cell.
    t: [[Vec4; 2]; 3],
    /// Per axis: how far apart its crossings are.
    dt: [[Vec4; 2]; 3],
    /// Per axis: the step of the cell index.
    step: [[Vec4; 2]; 3],
    /// Per axis: the cells left before the grid's face.
    left: [[Vec4; 2]; 3],
    /// Where the lane's ray leaves the content or its span.
    exit: [Vec4; 2],
    /// The node the lane visited last.
    last: [u32; LANES],
    /// The query each lane walks.
    ray: [usize; LANES],
}

impl<P: Primitive> Octree<P> {
    /// [`crate::accel::Backend::occluded_from`] of every query in `qs`,
    /// into `out`: each part's tree asked of the queries no part before
    /// it found occluded (any part's hit occludes, whichever is asked
    /// first), a tree with a grid [`LANES`] rays at a time.
    pub(super) fn occluded_stream(&self, qs: &[Query], out: &mut [bool]) {
        assert!(out.len() >= qs.len(), "an answer per query");
        let out = &mut out[..qs.len()];
        out.fill(false);
        if self.references == 0 {
            return;
        }
        let plain = qs.iter().all(|q| q.from.is_none() && q.pass.is_none());
        for tree in &self.parts {
            if plain {
                tree.any_hit_each(qs, out, |_| crate::accel::NoSkip);
            } else {
                tree.any_hit_each(qs, out, Query::secondary);
            }
        }
    }
}

impl<P: Primitive> Tree<P> {
    /// Sets `out[i]` for each query `i` of `qs` not yet set that this
    /// tree occludes ([`Tree::traverse`] of an [`AnyHit`] visitor skipping
    /// what `skip` gives it): along the grid [`LANES`] rays at once, or
    /// one at a time in a tree without one.
    fn any_hit_each<'q, S: Skip>(
        &self,
        qs: &'q [Query<'q>],
        out: &mut [bool],
        skip: impl Fn(&'q Query<'q>) -> S,
    ) {
        if self.references == 0 {
            return;
        }
        let Some(g) = &self.grid else {
            for (q, o) in qs.iter().zip(out.iter_mut()) {
                if !*o && !q.meets_nothing() {
                    let ctx = RayCtx::new(&q.ray, q.t_min);
                    *o = self.traverse(&q.ray, &ctx, &mut AnyHit::new(&q.ray, q.t_min, q.t_max, skip(q)));
                }
            }
            return;
        };
        let z = [Vec4::ZERO; 2];
        let mut w = Lanes {
            cell: z,
            t: [z; 3],
            dt: [z; 3],
            step: [z; 3],
            left: [z; 3],
            exit: z,
            last: [NO_NODE; LANES],
            ray: [0; LANES],
        };
        let idle_ray = crate::geometry::Ray::new(glam::Vec3::ZERO, glam::Vec3::X);
        let mut ctx: [RayCtx; LANES] = std::array::from_fn(|_| RayCtx::new(&idle_ray, 0.0));
        let mut hit: [Option<AnyHit<'q, P, S>>; LANES] = std::array::from_fn(|_| None);
        let mut next = 0;
        let mut active = 0u32;
        loop {
            // Idle lanes take the next rays that meet the content.
            let mut idle = !active & ((1 << LANES) - 1);
            while idle != 0 && next < qs.len() {
                let k = idle.trailing_zeros() as usize;
                let q = &qs[next];
                if !out[next] && !q.meets_nothing() && self.start_lane(g, q, next, &mut w, k, &mut ctx[k]) {
                    hit[k] = Some(AnyHit::new(&q.ray, q.t_min, q.t_max, skip(q)));
                    idle &= idle - 1;
                    active |= 1 << k;
                }
                next += 1;
            }
            if active == 0 {
                return;
            }
            // The lanes in a cell of a node they have not visited, each
            // visited as `walk_grid` visits it.
            let cells = [w.cell[0].to_array(), w.cell[1].to_array()];
            let mut visit = 0u32;
            for k in 0..LANES {
                let cell = &g.cells[cells[k >> 2][k & 3] as usize];
                visit |= u32::from(cell.node != w.last[k] && cell.node != NO_NODE) << k;
                w.last[k] = cell.node;
            }
            visit &= active;
            while visit != 0 {
                let k = visit.trailing_zeros() as usize;
                visit &= visit - 1;
                let cell = &g.cells[cells[k >> 2][k & 3] as usize];
                let v = hit[k].as_mut().expect("an active lane has its query");
                let node = cell.node as usize;
                if self.meets(node, &ctx[k], v.cutoff()) && self.enter(node, cell.lo, cell.size, &ctx[k], v) {
                    out[w.ray[k]] = true;
                    active &= !(1 << k);
                }
            }
            active &= !step_lanes(&mut w);
        }
    }

    /// Sets lane `k` of `w` walking query `q` (number `i`) from the grid
    /// cell where it enters the content, as [`Tree::walk_grid`] starts;
    /// false when the ray misses the content within its span.
    fn start_lane(&self, g: &Grid, q: &Query, i: usize, w: &mut Lanes, k: usize, ctx: &mut RayCtx) -> bool {
        *ctx = RayCtx::new(&q.ray, q.t_min);
        let (entry, far) = self.window(ctx);
        let cut = q.t_max;
        let exit = if far < cut { far } else { cut };
        // NaN compares false: a NaN entry or exit misses the root.
        let meets_root = entry <= exit;
        if !meets_root {
            return false;
        }
        let at = self.grid_start(g, &q.ray, ctx, entry);
        let (g4, l) = (k >> 2, k & 3);
        for a in 0..3 {
            w.step[a][g4][l] = at.step[a];
            w.left[a][g4][l] = at.left[a];
            w.t[a][g4][l] = at.t[a];
            w.dt[a][g4][l] = at.dt[a];
        }
        w.cell[g4][l] = at.cell as f32;
        w.exit[g4][l] = exit;
        w.last[k] = NO_NODE;
        w.ray[k] = i;
        true
    }
}

/// One step of every lane of `w`, as [`Tree::walk_grid`] takes it: the
/// axis crossed first (on a tie the later one, the same comparisons); a
/// lane whose crossing lies beyond its exit (or is NaN), or that would
/// leave the grid, stays where it is and its bit is set in the answer
/// (its walk is over).
#[inline(always)]
fn step_lanes(w: &mut Lanes) -> u32 {
    let mut done = 0u32;
    for h in 0..2 {
        let [tx, ty, tz] = [w.t[0][h], w.t[1][h], w.t[2][h]];
        let x_before_y = tx.cmplt(ty);
        let x = x_before_y & tx.cmplt(tz);
        let y = !x_before_y & ty.cmplt(tz);
        let t = Vec4::select(x, tx, Vec4::select(y, ty, tz));
        let [lx, ly, lz] = [w.left[0][h], w.left[1][h], w.left[2][h]];
        let left = Vec4::select(x, lx, Vec4::select(y, ly, lz));
        let go = t.cmple(w.exit[h]) & left.cmpne(Vec4::ZERO);
        done |= (!go).bitmask() << (4 * h);
        let (gx, gy) = (go & x, go & y);
        let gz = go & !(x | y);
        let pick = |m, v| Vec4::select(m, v, Vec4::ZERO);
        w.cell[h] += pick(gx, w.step[0][h]) + pick(gy, w.step[1][h]) + pick(gz, w.step[2][h]);
        w.left[0][h] = lx - pick(gx, Vec4::ONE);
        w.left[1][h] = ly - pick(gy, Vec4::ONE);
        w.left[2][h] = lz - pick(gz, Vec4::ONE);
        w.t[0][h] = Vec4::select(gx, tx + w.dt[0][h], tx);
        w.t[1][h] = Vec4::select(gy, ty + w.dt[1][h], ty);
        w.t[2][h] = Vec4::select(gz, tz + w.dt[2][h], tz);
    }
    done
}
