//! Many primary rays leaving one origin (a camera's, issue 55): the
//! directions in which no primitive lies, found once for the run
//! ([`Coverage`], built by [`crate::accel::Backend::fan`]), so a ray
//! along one of them is known to miss without a descent.
//!
//! In the basis `(u, v, w)`, `w` the run's mean direction, a point `p`
//! (relative to the origin) with `p·w > 0` has the gnomonic coordinates
//! `(p·u / p·w, p·v / p·w)`, the same for every point of a ray. A
//! primitive inside a ball of centre `c` and radius `R` lying wholly in
//! front (`c·w > R`) spans, in `x = p·u / p·w`, exactly the span over the
//! ball's projection on the `(u, w)` plane, a disc: the two tangents
//! from the origin bound it, slopes `(c_u c_w ± R sqrt(ρ² - R²)) / (c_w² -
//! R²)` with `ρ² = c_u² + c_w²`; the same for `y`. So each such primitive
//! covers a rectangle of the gnomonic plane, and every cell of a uniform
//! grid its rectangle meets is marked. A ray's direction is one point of
//! that plane: one cell; a ray starting at `t >= 0` in a cell no rectangle
//! meets hits nothing. A ball wholly behind (`c·w < -R`) is met by no ray
//! of the fan. A ball the plane `p·w = 0` cuts but lying outside the cone
//! of the grid's directions (`|c_⊥| - R > tan θ (c·w + R)`, `θ` the
//! grid's widest angle from `w`: a floor under or beside the eye) is met
//! by no ray the grid takes; the fan then claims no miss outside the grid.
//! A run with a ball the plane cuts inside that cone (the origin inside or
//! beside it) gets no fan.
//!
//! Why the answers are the octree's, bit for bit (`docs/DESIGN.md`, "The
//! backend contract", rule 1): only a ray that no primitive's ball can
//! hold a hit of is answered as a miss; every other ray goes to the
//! backend as before. `R` is the primitive's
//! [`Primitive::bounding_radius`] (a disc's greatest semi-axis, about
//! 0.71 of its box's ball, so fewer rays near a silhouette are left to the
//! octree) grown by [`MARGIN`] of `|c| + R`: a hit the f32 test
//! [`Primitive::intersect`] accepts lies on the ray within a few ulps of
//! `|c| + R` of the true primitive (its `t` and point are rounded, not the
//! ray), far inside that margin. A primitive that is an ellipse
//! ([`Primitive::semi_axes`]: a disc) covers instead the rectangle of the
//! points within that margin of its ellipse (`Coverage::ellipse_span`),
//! far narrower than the ball's for a disc seen edge-on at a silhouette.
//! Rectangles are padded by [`PAD`] for the
//! f64 arithmetic of the rectangles and of the rays' gnomonic
//! coordinates, and a ray's cell is found with the same monotone
//! operations as the rectangles' cells.
//!
//! **Rows.** A caller's rows of numbers may be keyed before they are
//! made rays ([`Fan::keys_of_rows`]), their directions `d` as given: the
//! conversion's direction `d fl(1 / |d|)` rounds each component once, so
//! it lies within an angle of `2^-24 √3` (about 1.1e-7) of `d`, and a
//! point the converted ray's f32 test accepts at a distance `L <= |c| +
//! R` from the origin lies within `1.1e-7 L` of the line along `d`: with
//! the test's own rounding (a few ulps), far inside [`MARGIN`] (1e-5 of
//! `|c| + R`). So the line along `d` meets the grown ball (or the points
//! within the margin of the ellipse) wherever the converted ray hits the
//! primitive, and `d`'s key is [`FAN_MISS`] only where the converted
//! ray's hits nothing; a row's origin is the fan's where its bits are the
//! fan's row's (the conversion is a function of the numbers).
//!
//! The grid spans a sample of the run's directions; a ray outside it is
//! known to miss where its coordinates lie past every rectangle's, unclipped
//! by the grid (the balls' reach), or where it does not point in front
//! (`d·w <= 0`) while no ball lies behind. The rays' keys are found four
//! at a time on the octree's SIMD path (`crate::simd::gnomonic_keys`), and
//! the grid's `u` follows the run's first step (a camera's row), so that
//! the rays of a row read one row of the grid's bits. A ray's key
//! ([`Fan::keys_each`]) is its block of 2×2 cells: the batch traces the
//! rays that may hit block by block, in packets of neighbouring
//! directions (`crate::render::cast`; issue 55, fortieth session). The
//! same rectangles give each block of cells its list of primitives, from
//! which the rays that may hit are answered (`bins`).

use crate::accel::{FAN_MISS, Fan};
use crate::simd::{FanBits, GnomonicGrid, Isa, gnomonic_key, gnomonic_keys};
use crate::geometry::{Ray, RaySet};
use crate::primitive::Primitive;
use glam::{DVec3, Vec3};
use rayon::prelude::*;

/// A ball's radius grows by this fraction of `|c| + R` (about 170 ulps of
/// f32), covering the exact test's rounding.
const MARGIN: f64 = 1e-5;

/// Rectangles grow by this fraction of `1 + |x0| + |x1|` each way,
/// covering the f64 arithmetic of rectangles and rays' cells.
const PAD: f64 = 1e-9;

/// The grid reaches no farther than `d·w = MIN_COS |d|` (about 75° from
/// `w`) along either axis.
const MIN_COS: f64 = 0.25;

/// Fewest rays in a run for which a fan is built, and the least ratio of
/// rays to primitives: fewer do not pay for visiting every primitive.
pub(super) const MIN_RAYS: usize = 4096;

/// Rays sampled for the run's mean direction and the grid's extent.
const SAMPLE: usize = 4096;

/// Rays per cell the grid is sized for (from the sample's extent).
const RAYS_PER_CELL: f64 = 4.0;

/// Most cells of a grid.
const MAX_CELLS: usize = 1 << 20;

/// The cells of the gnomonic plane of one origin that some primitive's
/// ball covers (module doc).
pub(super) struct Coverage {
    /// The origin's bits.
    pub(super) origin: [u32; 3],
    u: DVec3,
    v: DVec3,
    w: DVec3,
    /// The grid: lower corner in gnomonic coordinates, cells per unit,
    /// cells per axis.
    lo: [f64; 2],
    scale: f64,
    pub(super) n: [usize; 2],
    /// Per cell (`i + n[0] j`), bit `at % 32` of word `at / 32`: set
    /// when some ball covers it (a bit, not a byte: the rays' reads of the
    /// grid stay in the core's nearest cache).
    covered: Vec<u32>,
    /// The least and most coordinates in cells, on both axes, of the
    /// balls in front (past the grid too): a direction in front outside
    /// them meets none.
    far: [f64; 4],
    /// Whether some ball lies wholly behind (a direction not in front may
    /// meet it).
    behind: bool,
    /// The most `|p_⊥| / p·w` of a direction in the grid (`p_⊥` across
    /// `w`), with a margin: the tangent of the cone holding every ray the
    /// grid takes.
    cone: f64,
    /// The origin's distance from the world's.
    apex_len: f64,
    /// The least distance from the origin of any primitive's ball (behind,
    /// beside or in front): no point nearer the origin holds a hit.
    near_min: f64,
    /// The SIMD path of the rays' cells (the octree's).
    pub(super) isa: Isa,
}

impl Coverage {
    /// The basis and the grid (nothing covered yet): `w` the mean of a sample
    /// of the rays' unit directions, the grid over the sample's gnomonic
    /// extent grown by a sixteenth each way, sized for [`RAYS_PER_CELL`].
    pub(super) fn frame(origin: Vec3, rays: &dyn RaySet, isa: Isa) -> Option<Coverage> {
        // An odd step: a camera's rows of an even width are sampled at
        // every column, not at the same few.
        let step = rays.len().div_ceil(SAMPLE) | 1;
        // The sample read once, on the threads (its rays lie far apart in
        // memory, each a cache miss).
        let sampled: Vec<DVec3> = (0..rays.len().div_ceil(step))
            .into_par_iter()
            .map(|s| rays.ray(s * step).dir.as_dvec3())
            .collect();
        let sample = || sampled.iter().copied();
        let w = sample()
            .filter(|d| d.is_finite() && *d != DVec3::ZERO)
            .map(DVec3::normalize)
            .sum::<DVec3>()
            .try_normalize()?;
        // `u` along the step from the first ray to the next, where they
        // differ (a camera's row, so that a row of rays keeps to a row of
        // cells: their reads of the grid run on), else any.
        // Taken off `w` twice: a step nearly along `w` leaves, after one
        // pass, a part along `w` far above the rounding the spans' `PAD`
        // covers.
        let off_w = |x: DVec3| (x - w * x.dot(w)).try_normalize();
        let along = |r: &dyn RaySet| {
            let [a, b] = [0, 1].map(|i| (i < r.len()).then(|| r.ray(i).dir.as_dvec3().try_normalize()).flatten());
            off_w(off_w(b? - a?)?)
        };
        let u = along(rays).unwrap_or_else(|| w.any_orthonormal_vector());
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
        if taken * 2 < sampled.len() {
            return None;
        }
        let limit = (1.0 - MIN_COS * MIN_COS).sqrt() / MIN_COS;
        for a in 0..2 {
            let grow = (hi[a] - lo[a]) / 16.0 + 1e-6;
            lo[a] = (lo[a] - grow).max(-limit);
            hi[a] = (hi[a] + grow).min(limit);
        }
        let (scale, cells_n) = grid_size(lo, hi, rays.len() as f64 / RAYS_PER_CELL);
        let most = |a: usize| lo[a].abs().max((lo[a] + cells_n[a] as f64 / scale).abs());
        let cone = 1.001 * most(0).hypot(most(1)) + 1e-9;
        Some(Coverage {
            cone,
            origin: origin.to_array().map(f32::to_bits),
            u,
            v,
            w,
            lo,
            scale,
            n: cells_n,
            covered: Vec::new(),
            far: [f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY],
            behind: false,
            near_min: f64::INFINITY,
            apex_len: origin.as_dvec3().length(),
            isa,
        })
    }

    /// The span in `x = p·e / p·w` of a ball wholly in front (centre
    /// `cx` across along `e`, `cw` along `w`, radius `r`): the tangents'
    /// slopes (module doc).
    fn ball_span(cx: f64, cw: f64, r: f64) -> [f64; 2] {
        let den = cw * cw - r * r;
        let rho2 = cx * cx + cw * cw;
        let s = r * (rho2 - r * r).sqrt();
        [(cx * cw - s) / den, (cx * cw + s) / den]
    }

    /// The span in `x = p·e / p·w` of every point within `delta` of the
    /// ellipse `c + α a + β b` (`α² + β² <= 1`, `c` from the origin, the
    /// ellipse and that margin wholly in front: `c·w > |(a·w, b·w)| +
    /// delta`). The ellipse's boundary `(k0 + k1 cos θ + k2 sin θ) / (l0 +
    /// l1 cos θ + l2 sin θ)` (`k = (c, a, b)·e`, `l = (c, a, b)·w`) reaches
    /// `x` exactly when `|k0 - x l0| <= |(k1 - x l1, k2 - x l2)|`: the
    /// span is between the roots of `(l0² - l1² - l2²) x² - 2 (k0 l0 - k1
    /// l1 - k2 l2) x + (k0² - k1² - k2²)`, the discriminant raised by a
    /// bound on its rounding (its square root otherwise loses half the
    /// digits near a double root). A point within `delta` of the ellipse
    /// moves `x` by at most `delta |∇x|`, `|∇x| = |e - x w| / p·w <= (1 +
    /// X) / zmin` over that margin (`zmin` the least `p·w` there, `X` the
    /// most `|x|`). The f64 rounding of the rest is far inside [`PAD`].
    fn ellipse_span(c: DVec3, [a, b]: [DVec3; 2], e: DVec3, w: DVec3, delta: f64) -> [f64; 2] {
        let k = [c.dot(e), a.dot(e), b.dot(e)];
        let l = [c.dot(w), a.dot(w), b.dot(w)];
        let qa = l[0] * l[0] - l[1] * l[1] - l[2] * l[2];
        let qb = k[0] * l[0] - k[1] * l[1] - k[2] * l[2];
        let qc = k[0] * k[0] - k[1] * k[1] - k[2] * k[2];
        let sb = (k[0] * l[0]).abs() + (k[1] * l[1]).abs() + (k[2] * l[2]).abs();
        let (sa, sc) = (l[0] * l[0] + l[1] * l[1] + l[2] * l[2], k[0] * k[0] + k[1] * k[1] + k[2] * k[2]);
        let rounding = 1e-14 * (sb * sb + sa * sc);
        let s = ((qb * qb - qa * qc).max(0.0) + rounding).sqrt();
        let zmin = l[0] - (l[1] * l[1] + l[2] * l[2]).sqrt() - delta;
        let most = (k[0].abs() + (k[1] * k[1] + k[2] * k[2]).sqrt() + delta) / zmin;
        let pad = delta * (1.0 + most) / zmin;
        [(qb - s) / qa - pad, (qb + s) / qa + pad]
    }

    /// The span `[x0, x1]` on axis `a` in cells ([`Coverage::coord`]),
    /// grown by [`PAD`].
    fn reach(&self, [x0, x1]: [f64; 2], a: usize) -> [f64; 2] {
        let pad = PAD * (1.0 + x0.abs() + x1.abs());
        [self.coord(x0 - pad, a), self.coord(x1 + pad, a)]
    }

    /// The cells `[i0, i1]` along axis `a` of the reach `[r0, r1]`
    /// ([`Coverage::reach`]), or `None` when it misses the grid.
    fn cells(&self, [i0, i1]: [f64; 2], a: usize) -> Option<[usize; 2]> {
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

    /// Where a ray leaving anywhere (a shadow ray) meets primitives only
    /// in directions of the grid, when its span ends within half of
    /// [`Coverage::near_min`] of the origin (a shadow ray toward a light
    /// at the fan's origin: a headlight): the cells ([`Coverage::coord`])
    /// of the two ends of a part of `[t_min, t_max]` holding every hit,
    /// and a bound on the distance from the origin of its points; `None`
    /// where the span does not end that near, the part leaves the front
    /// of the origin, or the margin would not cover the rounding (below).
    ///
    /// Why the part holds every hit, and its ends every direction of one:
    /// a hit the f32 test accepts at `t` lies within the grown ball of its
    /// primitive (module doc), so at least `near_min` from the origin;
    /// a point at `t` lies within `|x(t_max)| + (t_max - t) |d|` of it, so
    /// the part stops where that bound falls under `near_min` (less a
    /// millionth, far above the f64 rounding). A run of a straight line
    /// lies wholly in front when both its ends do (`p·w` is linear along
    /// it), and the gnomonic projection maps it onto the segment between
    /// its ends' projections. The ball's margin, `MARGIN (|c| + R) >=
    /// MARGIN near_min`, is the rounding's bound for the rays of the fan;
    /// a ray leaving elsewhere rounds with the coordinates it works with
    /// (its origin's, the primitive's, its length): taken only while
    /// `near_min` is at least an eighth of their sum, so that margin is
    /// still about 20 ulps of it.
    pub(super) fn toward(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<([[f64; 2]; 2], f64)> {
        let apex = Vec3::from_array(self.origin.map(f32::from_bits));
        // The cheap test first (NaN compares false).
        let end = ray.origin + ray.dir * t_max - apex;
        let half = 0.5 * self.near_min;
        if !(t_min.is_finite() && f64::from(end.length_squared()) < half * half) {
            return None;
        }
        let o = ray.origin.as_dvec3() - apex.as_dvec3();
        let d = ray.dir.as_dvec3();
        let len = d.length();
        let (t0, tm) = (f64::from(t_min), f64::from(t_max));
        let far = (o + d * tm).length();
        let t1 = tm - (self.near_min * (1.0 - 1e-6) - far) / len;
        if !t0.partial_cmp(&t1).is_some_and(std::cmp::Ordering::is_le) {
            return None;
        }
        let mut cells = [[0.0; 2]; 2];
        for (cell, t) in cells.iter_mut().zip([t0, t1]) {
            let x = o + d * t;
            let z = x.dot(self.w);
            let least = 1e-6 * (x.x.abs() + x.y.abs() + x.z.abs());
            if !z.partial_cmp(&least).is_some_and(std::cmp::Ordering::is_gt) {
                return None;
            }
            *cell = [self.coord(x.dot(self.u) / z, 0), self.coord(x.dot(self.v) / z, 1)];
        }
        let reach = (far + (tm - t0) * len) * (1.0 + 1e-9);
        let from = f64::from(ray.origin.length()) * (1.0 + 1e-6);
        let coordinates = self.apex_len + from + reach + tm * len;
        (8.0 * self.near_min >= coordinates).then_some((cells, reach))
    }

    /// Marks the cells each primitive's ball covers and gives each
    /// primitive's cells `[i0, i1, j0, j1]` (`None`: behind, or beside the
    /// grid) and, in front, its ball's least distance from the origin,
    /// `|c| - R` at least 0 (infinite behind); `None` when a ball
    /// straddles the plane `p·w = 0` inside the grid's cone (or is not
    /// finite). The rectangles are found in parallel, and the grid's words
    /// of bits in parallel pieces ([`Coverage::mark`]): the fan is built
    /// before any of its run's rays is traced.
    pub(super) fn cover<P: Primitive>(&mut self, prims: &[P]) -> Option<Covered> {
        let seen: Vec<Option<Seen>> = prims.par_iter().map(|prim| self.rectangle(prim)).collect();
        let mut rects = Vec::with_capacity(seen.len());
        for s in &seen {
            match (*s)? {
                Seen::Behind(least) => {
                    self.behind = true;
                    self.near_min = self.near_min.min(least);
                }
                // No direction outside the grid is known to miss.
                Seen::Aside(least) => {
                    self.near_min = self.near_min.min(least);
                    self.behind = true;
                    self.far = [f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY];
                }
                Seen::Front(reach, cells, least) => {
                    self.near_min = self.near_min.min(least);
                    // A reach not a number holds every direction.
                    let low = |x: f64| if x.is_nan() { f64::NEG_INFINITY } else { x };
                    let high = |x: f64| if x.is_nan() { f64::INFINITY } else { x };
                    for a in [0, 2] {
                        self.far[a] = self.far[a].min(low(reach[a]));
                        self.far[a + 1] = self.far[a + 1].max(high(reach[a + 1]));
                    }
                    rects.extend(cells);
                }
            }
        }
        self.covered = Self::mark(self.n, &rects);
        Some(seen.iter().map(|s| match s {
            Some(Seen::Front(_, cells, near)) => (*cells, *near),
            _ => (None, f64::INFINITY),
        }).unzip())
    }

    /// The bits of the grid of `[nx, ny]` cells (cell `i + nx j`, bit `at
    /// % 32` of word `at / 32`) set in the cells of the rectangles `rects`
    /// (`[i0, i1, j0, j1]`, inclusive, within the grid): in pieces of
    /// words on the threads, each summing a difference array along the
    /// rows its words span, over the rectangles that reach them.
    fn mark([nx, ny]: [usize; 2], rects: &[[usize; 4]]) -> Vec<u32> {
        let cells = nx * ny;
        let mut covered = vec![0u32; cells.div_ceil(32)];
        let piece = covered.len().div_ceil(8 * rayon::current_num_threads()).max(1);
        covered.par_chunks_mut(piece).enumerate().for_each(|(k, words)| {
            let (c0, c1) = (32 * k * piece, (32 * (k * piece + words.len())).min(cells));
            let (ja, jb) = (c0 / nx, (c1 - 1) / nx);
            let mut diff = vec![0i32; (jb - ja + 1) * (nx + 1)];
            for &[i0, i1, j0, j1] in rects {
                for j in j0.max(ja)..=j1.min(jb) {
                    let row = (j - ja) * (nx + 1);
                    diff[row + i0] += 1;
                    diff[row + i1 + 1] -= 1;
                }
            }
            for j in ja..=jb {
                let row = &diff[(j - ja) * (nx + 1)..][..nx];
                let mut sum = 0;
                for (i, d) in row.iter().enumerate() {
                    sum += d;
                    let at = i + nx * j;
                    if sum != 0 && (c0..c1).contains(&at) {
                        words[at / 32 - c0 / 32] |= 1 << (at % 32);
                    }
                }
            }
        });
        covered
    }

    /// `prim`'s ball as the fan takes it: its centre from the origin, and
    /// its [`Primitive::bounding_radius`] grown by [`MARGIN`] of `|c| +
    /// R` (module doc); then that radius as it was.
    fn ball<P: Primitive>(&self, prim: &P) -> (DVec3, f64, f64) {
        let o = Vec3::from_array(self.origin.map(f32::from_bits)).as_dvec3();
        let c = prim.center().as_dvec3() - o;
        let r = f64::from(prim.bounding_radius());
        (c, r + MARGIN * (c.length() + r), r)
    }

    /// What the fan sees of `prim`'s ball: wholly behind, or in front with
    /// its reach `[i0, i1, j0, j1]` in cells ([`Coverage::reach`]) and the
    /// cells it covers (`None` beside the grid), or across the plane `p·w
    /// = 0` outside the grid's cone; `None` when it straddles that plane
    /// inside the cone (or is not finite).
    fn rectangle<P: Primitive>(&self, prim: &P) -> Option<Seen> {
        let (c, r, bounding) = self.ball(prim);
        let (cu, cv, cw) = (c.dot(self.u), c.dot(self.v), c.dot(self.w));
        let least = (c.length() - r).max(0.0);
        // Wholly behind: no ray of the fan in front (`d·w > 0`, `t >= 0`)
        // meets it. NaN compares false: no fan.
        if cw < -r {
            return Some(Seen::Behind(least));
        }
        let in_front = cw > 1.01 * r;
        if !in_front {
            // Across the plane, outside the grid's cone: every point `p` of
            // the ball has `|p_⊥| >= |c_⊥| - r > cone (c·w + r) >= cone
            // p·w`, so no ray the grid takes meets it (NaN: no fan).
            let across = cu.hypot(cv);
            return (across - r > self.cone * (cw + r)).then_some(Seen::Aside(least));
        }
        let spans = match prim.semi_axes() {
            Some((a, b)) => {
                let ab = [a.as_dvec3(), b.as_dvec3()];
                let delta = r - bounding;
                [self.u, self.v].map(|e| Self::ellipse_span(c, ab, e, self.w, delta))
            }
            None => [Self::ball_span(cu, cw, r), Self::ball_span(cv, cw, r)],
        };
        let [[i0, i1], [j0, j1]] = [0, 1].map(|a| self.reach(spans[a], a));
        let cells = match (self.cells([i0, i1], 0), self.cells([j0, j1], 1)) {
            (Some([i0, i1]), Some([j0, j1])) => Some([i0, i1, j0, j1]),
            _ => None,
        };
        Some(Seen::Front([i0, i1, j0, j1], cells, least))
    }
}

/// A uniform grid over `[lo, hi]` of about `cells` square cells (at least
/// 1, at most [`MAX_CELLS`]): its cells per unit and cells per axis.
pub(super) fn grid_size(lo: [f64; 2], hi: [f64; 2], cells: f64) -> (f64, [usize; 2]) {
    let area = ((hi[0] - lo[0]) * (hi[1] - lo[1])).max(f64::MIN_POSITIVE);
    let mut scale = (cells.clamp(1.0, MAX_CELLS as f64) / area).sqrt();
    let n = |scale: f64| [0, 1].map(|a| (((hi[a] - lo[a]) * scale).ceil() as usize).max(1));
    while n(scale)[0] * n(scale)[1] > MAX_CELLS {
        scale *= 0.9;
    }
    (scale, n(scale))
}

/// What [`Coverage::cover`] gives: each primitive's cells, and its ball's
/// least distance from the origin.
pub(super) type Covered = (Vec<Option<[usize; 4]>>, Vec<f64>);

/// What [`Coverage::rectangle`] finds of a primitive's ball.
#[derive(Clone, Copy)]
enum Seen {
    /// Wholly behind the plane through the origin across `w` (with its
    /// ball's least distance from the origin, as the others).
    Behind(f64),
    /// Wholly in front: its reach in cells, the cells it covers (`None`:
    /// beside the grid), and its ball's least distance from the origin.
    Front([f64; 4], Option<[usize; 4]>, f64),
    /// Across the plane, but outside the cone of the grid's directions:
    /// met by no ray the grid takes (a floor beside or under the eye).
    /// The rays outside the grid are then the backend's.
    Aside(f64),
}

impl Fan for Coverage {
    /// True when `ray` leaves the fan's origin within the grid in a cell
    /// no ball covers, or outside the grid where no ball reaches.
    #[inline]
    fn misses(&self, ray: &Ray) -> bool {
        gnomonic_key(&self.grid(), &self.bits(), ray) == FAN_MISS
    }

    /// [`FAN_MISS`] where [`Fan::misses`] holds, [`FAN_ELSEWHERE`] for a
    /// ray outside the grid, else the block of 2×2 cells holding the ray's
    /// cell, row after row of blocks: on the octree's SIMD path
    /// ([`gnomonic_keys`]).
    fn keys_each(&self, rays: &[Ray], keys: &mut [u32]) {
        gnomonic_keys(&self.grid(), &self.bits(), rays, self.isa, keys);
    }

    /// The same keys, of rows not yet normalised (module doc, "Rows").
    fn keys_of_rows(&self, rows: &[Ray], origin: [u32; 3], keys: &mut [u32]) -> bool {
        let bits = FanBits { origin, ..self.bits() };
        gnomonic_keys(&self.grid(), &bits, rows, self.isa, keys);
        true
    }
}

impl Coverage {
    /// The grid's bits and the eye as the SIMD module takes them.
    fn bits(&self) -> FanBits<'_> {
        FanBits {
            covered: &self.covered,
            origin: self.origin,
            // At most `MAX_CELLS` cells: every block's key is far below
            // `FAN_ELSEWHERE`.
            cols: self.key_cols() as u32,
        }
    }

    /// A key's blocks of 2×2 cells per row ([`FanBits::cols`]).
    fn key_cols(&self) -> usize {
        self.n[0].div_ceil(2)
    }

    /// The lowest cell `[i, j]` of the block of 2×2 cells a key names
    /// ([`Fan::keys_each`]'s keys of rays that may hit in the grid; any
    /// other key gives a cell past the grid's rows).
    pub(super) fn key_cell(&self, key: u32) -> [usize; 2] {
        let (key, cols) = (key as usize, self.key_cols());
        [2 * (key % cols), 2 * (key / cols)]
    }

    /// The grid as the SIMD module takes it.
    pub(super) fn grid(&self) -> GnomonicGrid {
        GnomonicGrid {
            u: self.u.to_array(),
            v: self.v.to_array(),
            w: self.w.to_array(),
            lo: self.lo,
            scale: self.scale,
            n: self.n,
            reach: self.far,
            behind: self.behind,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// [`Coverage::mark`] sets exactly the bits of the cells some
    /// rectangle covers, on grids whose rows do and do not end on a word,
    /// from one cell to tens of thousands, with rectangles of one cell,
    /// whole rows and columns, the whole grid, none at all, and many
    /// overlapping: every piece's rows, including those its first and
    /// last words share with the next piece, summed as one grid would be.
    #[test]
    fn marked_cells_are_those_the_rectangles_cover() {
        let mut rng = SplitMix64::new(11);
        for (nx, ny, count) in [(1, 1, 1), (1, 1, 0), (7, 3, 5), (32, 8, 40), (33, 65, 200), (509, 516, 3000), (64, 1, 9), (1, 300, 20)] {
            let mut rects: Vec<[usize; 4]> = (0..count)
                .map(|_| {
                    let (a, b) = (rng.below(nx), rng.below(nx));
                    let (c, d) = (rng.below(ny), rng.below(ny));
                    // Mostly small, as a splat's.
                    let (i1, j1) = if rng.below(4) == 0 { (a.max(b), c.max(d)) } else { ((a + 3).min(nx - 1), (c + 2).min(ny - 1)) };
                    [a.min(b).min(i1), i1, c.min(d).min(j1), j1]
                })
                .collect();
            if count == 5 {
                rects.push([0, nx - 1, 0, ny - 1]);
            }
            let bits = Coverage::mark([nx, ny], &rects);
            assert_eq!(bits.len(), (nx * ny).div_ceil(32));
            let mut want = vec![0u32; bits.len()];
            for &[i0, i1, j0, j1] in &rects {
                for j in j0..=j1 {
                    for i in i0..=i1 {
                        let at = i + nx * j;
                        want[at / 32] |= 1 << (at % 32);
                    }
                }
            }
            assert_eq!(bits, want, "{nx} x {ny}, {} rectangles", rects.len());
        }
    }

    /// Every rim point of random tilted ellipses in front lies in its
    /// [`Coverage::ellipse_span`] on both axes, and the span is no wider
    /// than the ball's; edge-on along an axis, it is far narrower.
    #[test]
    fn ellipse_spans_hold_the_rim_and_beat_the_ball() {
        let mut rng = SplitMix64::new(24);
        let mut r = |a: f64, b: f64| a + (b - a) * f64::from(rng.next_f32());
        let (u, v, w) = (DVec3::X, DVec3::Y, DVec3::Z);
        let (mut narrower, mut cases) = (0, 0);
        for _ in 0..2000 {
            let c = DVec3::new(r(-2.0, 2.0), r(-2.0, 2.0), r(1.0, 4.0));
            let n = DVec3::new(r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0)).normalize();
            let a = n.any_orthonormal_vector() * r(0.01, 0.5);
            let b = n.cross(a).normalize() * r(0.01, 0.5);
            let big = a.length().max(b.length());
            if c.dot(w) <= 1.02 * big {
                continue;
            }
            cases += 1;
            for (k, e) in [u, v].into_iter().enumerate() {
                let [x0, x1] = Coverage::ellipse_span(c, [a, b], e, w, 0.0);
                let [b0, b1] = Coverage::ball_span(c.dot(e), c.dot(w), big);
                assert!(x0 >= b0 - 1e-12 && x1 <= b1 + 1e-12, "{k}: {x0} {x1} in {b0} {b1}");
                narrower += usize::from(x1 - x0 < 0.5 * (b1 - b0));
                for i in 0..256 {
                    let t = f64::from(i) / 256.0 * std::f64::consts::TAU;
                    let p = c + a * t.cos() + b * t.sin();
                    let x = p.dot(e) / p.dot(w);
                    assert!(x >= x0 - 1e-12 && x <= x1 + 1e-12, "{x} not in {x0} {x1}");
                }
            }
        }
        // Measured: all 2,000 in front, 1,430 of their 4,000 spans under
        // half the ball's.
        assert!(cases == 2000 && narrower > 1300, "{cases} {narrower}");
    }
}
