//! Many primary rays leaving one origin (a camera's, issue 55): the
//! primitives binned by their direction from it, so a ray tests only the
//! primitives of its bin, nearest first ([`Fan`], built per run of a batch
//! by [`crate::accel::Backend::fan`]).
//!
//! In the basis `(u, v, w)`, `w` the run's mean direction, a point `p`
//! (relative to the origin) with `p·w > 0` has the gnomonic coordinates
//! `(p·u / p·w, p·v / p·w)`, the same for every point of a ray. A
//! primitive inside a ball of centre `c` and radius `R` lying wholly in
//! front (`c·w > R`) spans, in `x = p·u / p·w`, exactly the span over the
//! ball's projection on the `(u, w)` plane, a disc: the two tangents
//! from the origin bound it, slopes `(c_u c_w ± R sqrt(ρ² - R²)) / (c_w² -
//! R²)` with `ρ² = c_u² + c_w²`; the same for `y`. So each such primitive
//! gets a rectangle of the gnomonic plane, and is listed in every cell of
//! a uniform grid its rectangle meets. A ray's direction is one point of
//! that plane: one cell. A ball the plane `p·w = 0` cuts (the origin
//! inside or beside it) goes in a list every ray tests; a ball wholly
//! behind is met by no ray of the fan. Each list is sorted by the ball's
//! distance from the origin, `|c| - R`, which no hit on the primitive is
//! nearer than, so a ray stops when that exceeds its window's far end.
//!
//! Why the candidates are the octree's, bit for bit (`docs/DESIGN.md`, "The
//! backend contract", rules 1 and 2): every primitive listed is decided by
//! [`Primitive::intersect`] with the ray's span up to the window's current
//! far end and the query's skip rule, as in a leaf, and offered to the same
//! [`CandidateHits`], whose final window does not depend on the order of
//! offers; the bins only leave out primitives no hit of the ray within that
//! far end can lie on. `R` is the radius of the primitive's box
//! (`|half_extent|`) grown by [`MARGIN`] of `|c| + R`: a hit the f32 test
//! accepts lies on the ray within a few ulps of `|c| + R` of the true
//! primitive (its `t` and point are rounded, not the ray), far inside that
//! margin; rectangles are padded by [`PAD`] for the f64 arithmetic of the
//! rectangles and of the ray's cell; a ray's cell is found with the same
//! monotone operations as the rectangles' cells. A query the fan cannot
//! take (another origin, a secondary ray, `t_min < 0`, a direction outside
//! the grid) is the octree's own.

use super::{NO_PRIMITIVE, Octree, lanes};
use crate::accel::{Backend, BuildStats, Candidate, CandidateHits, NoSkip, Query, Skip};
use crate::geometry::Ray;
use crate::primitive::{Pack, Primitive};
use glam::{DVec3, Vec3};

/// A ball's radius grows by this fraction of `|c| + R` (about 170 ulps of
/// f32), covering the exact test's rounding.
const MARGIN: f64 = 1e-5;

/// Rectangles grow by this fraction of `1 + |x0| + |x1|` each way,
/// covering the f64 arithmetic of rectangles and rays' cells.
const PAD: f64 = 1e-9;

/// A ray the fan takes has `d·w > MIN_COS |d|` (within about 75° of `w`).
const MIN_COS: f64 = 0.25;

/// Fewest rays in a run for which a fan is built, and the least ratio of
/// rays to primitives: fewer do not pay for binning every primitive.
const MIN_RAYS: usize = 4096;

/// Rays sampled for the run's mean direction and the grid's extent.
const SAMPLE: usize = 4096;

/// Rays per cell the grid is sized for (from the sample's extent).
const RAYS_PER_CELL: f64 = 4.0;

/// Most cells of a grid, and most entries of its cells' lists a fan may
/// hold (a run needing more is traced as before).
const MAX_CELLS: usize = 1 << 20;
const MAX_ENTRIES: usize = 1 << 24;

/// The primitives of an [`Octree`] binned by direction from one origin,
/// answering every query exactly as the octree does (module doc).
pub(super) struct Fan<'a, P: Primitive> {
    tree: &'a Octree<P>,
    /// The origin's bits.
    origin: [u32; 3],
    u: DVec3,
    v: DVec3,
    w: DVec3,
    /// The grid: lower corner in gnomonic coordinates, cells per unit,
    /// cells per axis.
    lo: [f64; 2],
    scale: f64,
    n: [usize; 2],
    /// Per cell `c`, its entries `entries[start[c]..start[c + 1]]`.
    start: Vec<u32>,
    entries: Vec<u32>,
    /// The entries every ray tests (balls the plane `p·w = 0` cuts).
    every: Vec<u32>,
    /// Per entry: the ball's distance from the origin (rounded down), the
    /// primitive's id, the primitive; by increasing distance.
    near: Vec<f32>,
    ids: Vec<u32>,
    prims: Vec<P>,
}

/// One primitive's place in the fan while it is built.
struct Placed<P> {
    near: f32,
    id: u32,
    prim: P,
    /// Cells `[i0, i1] x [j0, j1]`, or `None`: every ray tests it.
    cells: Option<[usize; 4]>,
}

impl<P: Primitive> Octree<P> {
    /// The fan of the rays `rays` (sharing their first ray's origin), or
    /// `None` when it would not pay or not fit ([`MIN_RAYS`],
    /// [`MAX_ENTRIES`]).
    pub(super) fn build_fan(&self, rays: &[Ray]) -> Option<Fan<'_, P>> {
        let origin = rays.first()?.origin;
        let count = self.primitive_count();
        if rays.len() < MIN_RAYS.max(count) || !origin.is_finite() {
            return None;
        }
        let mut fan = Fan::frame(self, origin, rays)?;
        let placed = fan.place(self.primitives());
        fan.fill(placed).then_some(fan)
    }

    /// One more than the largest primitive id held.
    fn primitive_count(&self) -> usize {
        self.parts
            .iter()
            .flat_map(|t| t.pack_ids.iter())
            .filter(|&&id| id != NO_PRIMITIVE)
            .max()
            .map_or(0, |&m| m as usize + 1)
    }

    /// Every primitive held, once, with its id.
    fn primitives(&self) -> Vec<(u32, P)> {
        let mut seen = vec![false; self.primitive_count()];
        let mut out = Vec::with_capacity(seen.len());
        let l = lanes::<P>();
        for tree in &self.parts {
            for (p, pack) in tree.packs.iter().enumerate() {
                for (lane, &id) in tree.pack_ids[p * l..(p + 1) * l].iter().enumerate() {
                    if id != NO_PRIMITIVE && !std::mem::replace(&mut seen[id as usize], true) {
                        out.push((id, pack.get(lane, id, &tree.side)));
                    }
                }
            }
        }
        out
    }
}

impl<'a, P: Primitive> Fan<'a, P> {
    /// The basis and the grid (no entries yet): `w` the mean of a sample
    /// of the rays' unit directions, the grid over the sample's gnomonic
    /// extent grown by a sixteenth each way, sized for [`RAYS_PER_CELL`].
    fn frame(tree: &'a Octree<P>, origin: Vec3, rays: &[Ray]) -> Option<Fan<'a, P>> {
        let step = rays.len().div_ceil(SAMPLE).max(1);
        let sample = || rays.iter().step_by(step).map(|r| r.dir.as_dvec3());
        let w = sample()
            .filter(|d| d.is_finite() && *d != DVec3::ZERO)
            .map(DVec3::normalize)
            .sum::<DVec3>()
            .try_normalize()?;
        let u = w.any_orthonormal_vector();
        let v = w.cross(u);
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        let mut taken = 0usize;
        for d in sample() {
            let z = d.dot(w);
            if z > MIN_COS * d.length() {
                let g = [d.dot(u) / z, d.dot(v) / z];
                for a in 0..2 {
                    lo[a] = lo[a].min(g[a]);
                    hi[a] = hi[a].max(g[a]);
                }
                taken += 1;
            }
        }
        if taken * 2 < sample().count() {
            return None;
        }
        let limit = (1.0 - MIN_COS * MIN_COS).sqrt() / MIN_COS;
        for a in 0..2 {
            let grow = (hi[a] - lo[a]) / 16.0 + 1e-6;
            lo[a] = (lo[a] - grow).max(-limit);
            hi[a] = (hi[a] + grow).min(limit);
        }
        let area = (hi[0] - lo[0]) * (hi[1] - lo[1]);
        let cells = (rays.len() as f64 / RAYS_PER_CELL).clamp(1.0, MAX_CELLS as f64);
        let mut scale = (cells / area).sqrt();
        let n = |scale: f64| [0, 1].map(|a| (((hi[a] - lo[a]) * scale).ceil() as usize).max(1));
        while n(scale)[0] * n(scale)[1] > MAX_CELLS {
            scale *= 0.9;
        }
        Some(Fan {
            tree,
            origin: origin.to_array().map(f32::to_bits),
            u,
            v,
            w,
            lo,
            scale,
            n: n(scale),
            start: Vec::new(),
            entries: Vec::new(),
            every: Vec::new(),
            near: Vec::new(),
            ids: Vec::new(),
            prims: Vec::new(),
        })
    }

    /// Each primitive's distance and cells (module doc), nearest first;
    /// those behind the origin left out.
    fn place(&self, prims: Vec<(u32, P)>) -> Vec<Placed<P>> {
        let o = Vec3::from_array(self.origin.map(f32::from_bits)).as_dvec3();
        let mut placed: Vec<Placed<P>> = prims
            .into_iter()
            .filter_map(|(id, prim)| {
                let c = prim.center().as_dvec3() - o;
                let r = prim.half_extent().as_dvec3().length();
                let dist = c.length();
                let r = r + MARGIN * (dist + r);
                let (cu, cv, cw) = (c.dot(self.u), c.dot(self.v), c.dot(self.w));
                // Wholly behind: no ray of the fan (`d·w > 0`, `t >= 0`)
                // meets it.
                if cw < -r {
                    return None;
                }
                let near = (dist - r) * (1.0 - MARGIN);
                // Rounded down; NaN: 0, tested by every ray.
                let near = if near > 0.0 { (near as f32).next_down().max(0.0) } else { 0.0 };
                let cells = if cw > 1.01 * r {
                    let x = self.span(cu, cw, r, 0)?;
                    let y = self.span(cv, cw, r, 1)?;
                    Some([x[0], x[1], y[0], y[1]])
                } else {
                    None
                };
                Some(Placed {
                    near,
                    id,
                    prim,
                    cells,
                })
            })
            .collect();
        placed.sort_unstable_by(|a, b| a.near.total_cmp(&b.near).then(a.id.cmp(&b.id)));
        placed
    }

    /// The cells `[i0, i1]` along axis `a` of a ball wholly in front
    /// (centre `cx` across, `cw` along `w`, radius `r`), or `None` when its
    /// span misses the grid.
    fn span(&self, cx: f64, cw: f64, r: f64, a: usize) -> Option<[usize; 2]> {
        let den = cw * cw - r * r;
        let rho2 = cx * cx + cw * cw;
        let s = r * (rho2 - r * r).sqrt();
        let (x0, x1) = ((cx * cw - s) / den, (cx * cw + s) / den);
        let pad = PAD * (1.0 + x0.abs() + x1.abs());
        let (i0, i1) = (self.coord(x0 - pad, a), self.coord(x1 + pad, a));
        // NaN compares false: kept, at every cell of the axis.
        if i1 < 0.0 || i0 >= self.n[a] as f64 {
            return None;
        }
        let last = self.n[a] - 1;
        let cell = |i: f64| if i >= 0.0 { (i as usize).min(last) } else { 0 };
        Some([cell(i0), if i1.is_nan() { last } else { cell(i1) }])
    }

    /// Gnomonic coordinate `x` on axis `a` in cells from the grid's lower
    /// corner: the one operation rectangles and rays share (monotone).
    #[inline(always)]
    fn coord(&self, x: f64, a: usize) -> f64 {
        (x - self.lo[a]) * self.scale
    }

    /// The cells' lists from the placed primitives (nearest first in every
    /// list); false when they would hold more than [`MAX_ENTRIES`].
    fn fill(&mut self, placed: Vec<Placed<P>>) -> bool {
        let [nx, ny] = self.n;
        let mut count = vec![0u32; nx * ny + 1];
        let mut total = 0usize;
        for p in &placed {
            if let Some([i0, i1, j0, j1]) = p.cells {
                total += (i1 - i0 + 1) * (j1 - j0 + 1);
                if total > MAX_ENTRIES {
                    return false;
                }
                for j in j0..=j1 {
                    for c in &mut count[j * nx + i0..=j * nx + i1] {
                        *c += 1;
                    }
                }
            }
        }
        let mut sum = 0;
        for c in &mut count {
            (*c, sum) = (sum, sum + *c);
        }
        let mut next = count.clone();
        self.entries = vec![0; total];
        self.near.reserve(placed.len());
        self.ids.reserve(placed.len());
        self.prims.reserve(placed.len());
        for (k, p) in placed.into_iter().enumerate() {
            let k = k as u32;
            match p.cells {
                None => self.every.push(k),
                Some([i0, i1, j0, j1]) => {
                    for j in j0..=j1 {
                        for c in j * nx + i0..=j * nx + i1 {
                            self.entries[next[c] as usize] = k;
                            next[c] += 1;
                        }
                    }
                }
            }
            self.near.push(p.near);
            self.ids.push(p.id);
            self.prims.push(p.prim);
        }
        self.start = count;
        true
    }

    /// The cell of a query the fan takes (its origin the fan's, a primary
    /// ray, `t_min >= 0`, its direction within the grid), else `None`.
    #[inline]
    fn cell(&self, q: &Query) -> Option<usize> {
        if q.ray.origin.to_array().map(f32::to_bits) != self.origin
            || q.from.is_some()
            || !(q.t_min >= 0.0)
        {
            return None;
        }
        let d = q.ray.dir.as_dvec3();
        let z = d.dot(self.w);
        // NaN compares false.
        if !(z > 0.0 && z * z > MIN_COS * MIN_COS * d.length_squared()) {
            return None;
        }
        let i = self.coord(d.dot(self.u) / z, 0);
        let j = self.coord(d.dot(self.v) / z, 1);
        let inside = |i: f64, a: usize| i >= 0.0 && i < self.n[a] as f64;
        (inside(i, 0) && inside(j, 1)).then(|| i as usize + self.n[0] * j as usize)
    }

    /// The entries of `cell`: those every ray tests, then the cell's.
    #[inline(always)]
    fn lists(&self, cell: usize) -> [&[u32]; 2] {
        let (a, b) = (self.start[cell] as usize, self.start[cell + 1] as usize);
        [&self.every, &self.entries[a..b]]
    }

    /// The candidate window of `q` (in `cell`) into `hits`, as the octree's
    /// leaves gather it.
    fn gather<S: Skip>(&self, q: &Query, cell: usize, skip: S, hits: &mut CandidateHits) {
        let ray = &q.ray;
        let len = ray.dir.as_dvec3().length();
        let limit = |cut: f32| reach(cut, len);
        let mut cut = q.t_max.min(hits.far());
        let mut far = limit(cut);
        for list in self.lists(cell) {
            for &k in list {
                let k = k as usize;
                if self.near[k] > far {
                    break;
                }
                let (prim, id) = (&self.prims[k], self.ids[k]);
                if let Some(h) = prim.intersect(ray, q.t_min, cut)
                    && !skip.skips(ray.dir, id, prim, &h)
                {
                    let c = Candidate {
                        id,
                        t: h.t,
                        u: h.u,
                        v: h.v,
                    };
                    cut = hits.offer(c).min(q.t_max);
                    far = limit(cut);
                }
            }
        }
    }

    /// Whether `q` (in `cell`) meets a primitive its skip rule keeps.
    fn any_hit<S: Skip>(&self, q: &Query, cell: usize, skip: S) -> bool {
        let ray = &q.ray;
        let far = reach(q.t_max, ray.dir.as_dvec3().length());
        self.lists(cell).iter().any(|list| {
            list.iter()
                .map(|&k| k as usize)
                .take_while(|&k| self.near[k] <= far)
                .any(|k| {
                    let (prim, id) = (&self.prims[k], self.ids[k]);
                    prim.intersect(ray, q.t_min, q.t_max)
                        .is_some_and(|h| !skip.skips(ray.dir, id, prim, &h))
                })
        })
    }
}

/// The farthest a hit at `t <= cut` on a ray of direction length `len`
/// lies from the origin, rounded up (`+inf` for an infinite `cut`).
#[inline(always)]
fn reach(cut: f32, len: f64) -> f32 {
    ((f64::from(cut) * len * (1.0 + MARGIN)) as f32).next_up()
}

impl<P: Primitive> Backend for Fan<'_, P> {
    /// The bins for a query the fan takes, else the octree.
    fn intersect_from(&self, q: &Query, hits: &mut CandidateHits) {
        let Some(cell) = self.cell(q) else {
            return self.tree.intersect_from(q, hits);
        };
        hits.clear();
        if q.meets_nothing() {
            return;
        }
        match q.pass {
            None => self.gather(q, cell, NoSkip, hits),
            Some(_) => self.gather(q, cell, q.secondary(), hits),
        }
    }

    fn occluded_from(&self, q: &Query) -> bool {
        let Some(cell) = self.cell(q) else {
            return self.tree.occluded_from(q);
        };
        if q.meets_nothing() {
            return false;
        }
        match q.pass {
            None => self.any_hit(q, cell, NoSkip),
            Some(_) => self.any_hit(q, cell, q.secondary()),
        }
    }

    fn stats(&self) -> &BuildStats {
        self.tree.stats()
    }
}
