//! Splat growth (§2.1, eqs. 1–3) with density control (§2.2).

use super::knn::Knn;
use super::{NormalField, Splat, tangent_frame};
use glam::{DVec3, Vec2, Vec3};
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// A splat never grows past this many times its seed's k-th neighbour
/// distance: on flat regions eq. (1) alone would let it spread over the
/// whole surface and far past its borders.
pub const MAX_RADIUS_FACTOR: f32 = 12.0;

/// ... or past this many `ϵ`, whichever is larger: on a densely sampled
/// surface 12 k-th neighbour distances shrink below the radius eq. (1)
/// allows, and the number of splats would follow the sampling density
/// instead of `ϵ` and the surface. The bunny at the default `ϵ`: 1M samples
/// 21,732 splats, 10M 39,146 with the neighbour cap alone, 26,896 with this.
pub const MAX_RADIUS_EPS: f32 = 8.0;

/// What the growth stage needs.
pub struct GrowInput<'a> {
    /// Point positions (distinct, finite).
    pub points: &'a [Vec3],
    /// Unit, consistently oriented normals.
    pub normals: &'a [Vec3],
    /// Linear colours, when the cloud has them.
    pub colors: Option<&'a [Vec3]>,
    /// The neighbourhood graph.
    pub knn: &'a Knn,
    /// Error threshold `ϵ` on the span of eq. (1), absolute.
    pub epsilon: f32,
    /// Density factor `k ∈ (0, 1]` of §2.2.
    pub density: f32,
    /// Continue into the minimum-curvature direction for elliptical splats.
    pub ellipses: bool,
}

/// The result of growing splats over the whole cloud.
pub struct Grown {
    /// The splats (flat normal fields; fitted later).
    pub splats: Vec<Splat>,
    /// For each point: was it taken into some splat by growth (so it lies
    /// inside that splat's disc and within `ϵ/2` of its plane)?
    pub covered: Vec<bool>,
    /// How many splats are elliptical.
    pub elliptical: usize,
}

/// One growth from a seed in a planar metric: projected coordinates
/// `x = a·(q-p)`, `y = b·(q-p)`, distance² `(x/aspect)² + y²`.
struct Growth {
    /// Accepted points with their metric distance².
    accepted: Vec<(u32, f32)>,
    /// Every point reached by the traversal (accepted or not).
    visited: Vec<u32>,
    h_min: f32,
    h_max: f32,
}

struct Grower<'a> {
    inp: &'a GrowInput<'a>,
    stamp: Vec<u32>,
    round: u32,
    heap: BinaryHeap<Reverse<u64>>,
}

impl Grower<'_> {
    /// Grow from seed `i` with normal `n` in the metric `(a, b, aspect)`:
    /// take neighbours in order of (metric) projected distance by a
    /// best-first traversal of the neighbourhood graph, until the span of
    /// the signed distances `h_j = n·(p_j - p_i)` (eq. 1) exceeds `ϵ` or the
    /// distance exceeds `max_d`. Points whose normal faces away from `n`
    /// (the other side of a thin sheet) are passed over, never taken.
    fn run(&mut self, i: usize, a: Vec3, b: Vec3, aspect: f32, max_d: f32) -> Growth {
        let inp = self.inp;
        let p = inp.points[i];
        let n = inp.normals[i];
        self.round = self.round.wrapping_add(1);
        if self.round == 0 {
            self.stamp.fill(0);
            self.round = 1;
        }
        let round = self.round;
        self.heap.clear();
        self.stamp[i] = round;
        self.heap.push(Reverse(i as u64));
        let max_d2 = max_d * max_d;
        let mut g = Growth {
            accepted: Vec::new(),
            visited: vec![i as u32],
            h_min: 0.0,
            h_max: 0.0,
        };
        while let Some(Reverse(key)) = self.heap.pop() {
            let j = (key & 0xffff_ffff) as usize;
            let d2 = f32::from_bits((key >> 32) as u32);
            if d2 > max_d2 {
                break;
            }
            if j != i && inp.normals[j].dot(n) <= 0.0 {
                continue;
            }
            let h = n.dot(inp.points[j] - p); // eq. (1)
            let (lo, hi) = (g.h_min.min(h), g.h_max.max(h));
            if hi - lo > inp.epsilon {
                break;
            }
            g.h_min = lo;
            g.h_max = hi;
            g.accepted.push((j as u32, d2));
            for &q in inp.knn.of(j) {
                let q = q as usize;
                if self.stamp[q] == round {
                    continue;
                }
                self.stamp[q] = round;
                g.visited.push(q as u32);
                let d = inp.points[q] - p;
                let (x, y) = (a.dot(d) / aspect, b.dot(d));
                let qd2 = x * x + y * y;
                self.heap
                    .push(Reverse((u64::from(qd2.to_bits()) << 32) | q as u64));
            }
        }
        g
    }

    /// The smallest circle, in the metric `(a, b, aspect)` around seed `i`,
    /// holding the seed, the points `growth` took and the seed's same-facing
    /// `k` neighbours (all within `r`): its centre's offset from the seed and
    /// its radius (at most `r`).
    fn enclosing(
        &self,
        i: usize,
        growth: &Growth,
        a: Vec3,
        b: Vec3,
        aspect: f32,
        r: f32,
    ) -> (Vec2, f32) {
        let inp = self.inp;
        let (p, n) = (inp.points[i], inp.normals[i]);
        let metric = |q: usize| {
            let d = inp.points[q] - p;
            Vec2::new(a.dot(d) / aspect, b.dot(d))
        };
        let mut pts: Vec<Vec2> = vec![Vec2::ZERO];
        pts.extend(growth.accepted.iter().map(|&(j, _)| metric(j as usize)));
        pts.extend(
            inp.knn
                .of(i)
                .iter()
                .filter(|&&q| inp.normals[q as usize].dot(n) > 0.0)
                .map(|&q| metric(q as usize)),
        );
        // A fixed shuffle per seed: the incremental algorithm's expected
        // linear time, and the same splats on every run.
        let mut rng = crate::rng::SplitMix64::new(i as u64);
        for k in (1..pts.len()).rev() {
            let m = (rng.next_u64() % (k as u64 + 1)) as usize;
            pts.swap(k, m);
        }
        let (c, rad) = min_circle(&pts);
        if !c.is_finite() || !rad.is_finite() || rad >= r {
            return (Vec2::ZERO, r);
        }
        // A hair larger, so the points on the circle stay inside in f32.
        (c, rad * (1.0 + 1e-4) + 1e-7 * r)
    }

    /// The metric radius that covers the seed's same-facing `k` neighbours.
    fn cover_radius(&self, i: usize, a: Vec3, b: Vec3, aspect: f32) -> f32 {
        let inp = self.inp;
        let (p, n) = (inp.points[i], inp.normals[i]);
        let mut r2 = 0f32;
        for &q in inp.knn.of(i) {
            let q = q as usize;
            if inp.normals[q].dot(n) <= 0.0 {
                continue;
            }
            let d = inp.points[q] - p;
            let (x, y) = (a.dot(d) / aspect, b.dot(d));
            r2 = r2.max(x * x + y * y);
        }
        r2.sqrt()
    }
}

/// The smallest circle holding `pts` (Welzl's incremental algorithm,
/// expected linear time for points in random order): centre and radius.
fn min_circle(pts: &[Vec2]) -> (Vec2, f32) {
    let inside = |c: Vec2, r: f32, q: Vec2| q.distance(c) <= r * (1.0 + 1e-6);
    let Some(&first) = pts.first() else {
        return (Vec2::ZERO, 0.0);
    };
    let (mut c, mut r) = (first, 0.0f32);
    for i in 1..pts.len() {
        if inside(c, r, pts[i]) {
            continue;
        }
        (c, r) = (pts[i], 0.0);
        for j in 0..i {
            if inside(c, r, pts[j]) {
                continue;
            }
            c = 0.5 * (pts[i] + pts[j]);
            r = 0.5 * pts[i].distance(pts[j]);
            for k in 0..j {
                if inside(c, r, pts[k]) {
                    continue;
                }
                (c, r) =
                    circumcircle(pts[i], pts[j], pts[k]).unwrap_or((c, r.max(c.distance(pts[k]))));
            }
        }
    }
    (c, r)
}

/// The circle through three points; `None` when they are collinear.
fn circumcircle(a: Vec2, b: Vec2, c: Vec2) -> Option<(Vec2, f32)> {
    let (b, c2) = (b - a, c - a);
    let d = 2.0 * (b.x * c2.y - b.y * c2.x);
    if d.abs() <= f32::EPSILON * (b.length_squared() + c2.length_squared()) {
        return None;
    }
    let (bb, cc) = (b.length_squared(), c2.length_squared());
    let u = Vec2::new(c2.y * bb - b.y * cc, b.x * cc - c2.x * bb) / d;
    Some((a + u, u.length()))
}

/// Principal directions of the height field `h(x, y)` of the accepted points
/// (least-squares quadric `h = A x² + B xy + C y² + D x + E y + F`): the unit
/// minimum-curvature direction in `(x, y)` and the ratio `|κ_max / κ_min|`.
#[allow(clippy::needless_range_loop)] // index form mirrors the elimination
fn min_curvature(samples: &[(f64, f64, f64)]) -> Option<(f64, f64, f64)> {
    if samples.len() < 8 {
        return None;
    }
    let mut m = [[0f64; 7]; 6];
    for &(x, y, h) in samples {
        let row = [x * x, x * y, y * y, x, y, 1.0];
        for r in 0..6 {
            for c in 0..6 {
                m[r][c] += row[r] * row[c];
            }
            m[r][6] += row[r] * h;
        }
    }
    // Gaussian elimination with partial pivoting.
    for col in 0..6 {
        let piv = (col..6).max_by(|&a, &b| m[a][col].abs().total_cmp(&m[b][col].abs()))?;
        if m[piv][col].abs() < 1e-30 {
            return None;
        }
        m.swap(col, piv);
        for r in 0..6 {
            if r != col {
                let f = m[r][col] / m[col][col];
                for c in col..7 {
                    m[r][c] -= f * m[col][c];
                }
            }
        }
    }
    let (qa, qb, qc) = (m[0][6] / m[0][0], m[1][6] / m[1][1], m[2][6] / m[2][2]);
    // Hessian [[2A, B], [B, 2C]].
    let (h11, h12, h22) = (2.0 * qa, qb, 2.0 * qc);
    let tr = 0.5 * (h11 + h22);
    let disc = (0.25 * (h11 - h22) * (h11 - h22) + h12 * h12).sqrt();
    let (k1, k2) = (tr + disc, tr - disc);
    let (kmax, kmin) = if k1.abs() >= k2.abs() {
        (k1, k2)
    } else {
        (k2, k1)
    };
    // Eigenvector of kmin.
    let (ex, ey) = if h12.abs() > 1e-12 * (h11.abs() + h22.abs() + 1e-300) {
        (kmin - h22, h12)
    } else if (h11 - kmin).abs() < (h22 - kmin).abs() {
        (1.0, 0.0)
    } else {
        (0.0, 1.0)
    };
    let len = (ex * ex + ey * ey).sqrt();
    if len.is_nan() || len <= 0.0 || !kmax.is_finite() {
        return None;
    }
    Some((
        ex / len,
        ey / len,
        kmax.abs() / kmin.abs().max(kmax.abs() / 64.0),
    ))
}

/// Grow splats over the whole cloud, seeds in point order. A point taken
/// within the projected distance `k·r_j` of splat `j`'s centre seeds no
/// further splat (§2.2, fig. 6).
///
/// Each splat: centre by eq. (2), radius by eq. (3) — the projected distance
/// of the farthest point taken — but at least the projected distance that
/// covers the seed's `k` nearest (same-facing) neighbours, so neighbouring
/// splats overlap and leave no holes.
#[must_use]
pub fn grow_all(inp: &GrowInput<'_>, mut progress: impl FnMut(usize)) -> Grown {
    let n_pts = inp.points.len();
    let mut g = Grower {
        inp,
        stamp: vec![0; n_pts],
        round: 0,
        heap: BinaryHeap::new(),
    };
    let mut active = vec![true; n_pts];
    let mut covered = vec![false; n_pts];
    let mut splats = Vec::new();
    let mut elliptical = 0usize;
    for i in 0..n_pts {
        if i % 65536 == 0 {
            progress(i);
        }
        if !active[i] {
            continue;
        }
        let p = inp.points[i];
        let n = inp.normals[i];
        let d_k = inp.knn.kth_distance[i].max(f32::MIN_POSITIVE);
        let (tu, tv) = tangent_frame(n);
        let max_d = (MAX_RADIUS_FACTOR * d_k).max(MAX_RADIUS_EPS * inp.epsilon);
        let mut growth = g.run(i, tu, tv, 1.0, max_d);
        let grown_r = growth.accepted.last().map_or(0.0, |a| a.1.sqrt()); // eq. (3)
        let mut frame = (tu, tv, 1.0f32);
        let mut r = grown_r.max(g.cover_radius(i, tu, tv, 1.0));
        if inp.ellipses {
            let samples: Vec<(f64, f64, f64)> = growth
                .accepted
                .iter()
                .map(|&(j, _)| {
                    let d = (inp.points[j as usize] - p).as_dvec3();
                    (
                        d.dot(tu.as_dvec3()),
                        d.dot(tv.as_dvec3()),
                        d.dot(n.as_dvec3()),
                    )
                })
                .collect();
            if let Some((ex, ey, ratio)) = min_curvature(&samples) {
                let aspect = ratio.sqrt().clamp(1.0, 4.0) as f32;
                if aspect > 1.25 {
                    let a = (tu.as_dvec3() * ex + tv.as_dvec3() * ey)
                        .as_vec3()
                        .normalize();
                    let b = n.cross(a);
                    let e = g.run(i, a, b, aspect, max_d);
                    let e_r = e.accepted.last().map_or(0.0, |a| a.1.sqrt());
                    let rv = e_r.max(g.cover_radius(i, a, b, aspect));
                    if aspect * rv * rv > r * r * 1.05 {
                        growth = e;
                        frame = (a, b, aspect);
                        r = rv;
                    }
                }
            }
        }
        if r.is_nan() || r <= 0.0 {
            r = 0.5 * d_k;
        }
        let (a, b, aspect) = frame;
        // The disc over what it covers: the smallest circle (in the growth
        // metric) around the seed, the points taken and the neighbours the
        // radius was widened to cover. Inside a surface it is the disc of
        // eq. (3); at a border, where all of them lie on one side, it moves
        // inward and shrinks instead of overhanging the border by its radius.
        let (shift, r) = g.enclosing(i, &growth, a, b, aspect, r);
        let center = p
            + n * (0.5 * (growth.h_min + growth.h_max)) // eq. (2)
            + a * (shift.x * aspect)
            + b * shift.y;
        let mut color = DVec3::ZERO;
        for &(j, _) in &growth.accepted {
            if let Some(c) = inp.colors {
                color += c[j as usize].as_dvec3();
            }
        }
        // Density control (§2.2): every point reached that lies on this splat
        // (within ϵ of its plane, inside its disc, facing the same way) is
        // covered, and seeds nothing within the projected distance k·r.
        let limit2 = (inp.density * r) * (inp.density * r);
        let (r2, hc) = (r * r, 0.5 * (growth.h_min + growth.h_max));
        for &j in &growth.visited {
            let j = j as usize;
            let d = inp.points[j] - p;
            let (x, y) = (a.dot(d) / aspect - shift.x, b.dot(d) - shift.y);
            let d2 = x * x + y * y;
            let on = d2 <= r2
                && (n.dot(d) - hc).abs() <= inp.epsilon
                && (j == i || inp.normals[j].dot(n) > 0.0);
            if on {
                covered[j] = true;
                if d2 <= limit2 {
                    active[j] = false;
                }
            }
        }
        active[i] = false;
        let color = match inp.colors {
            Some(_) if !growth.accepted.is_empty() => {
                (color / growth.accepted.len() as f64).as_vec3()
            }
            _ => Vec3::ONE,
        };
        if aspect > 1.0 {
            elliptical += 1;
        }
        splats.push(Splat {
            center,
            normal: n,
            u_axis: a,
            v_axis: b,
            radii: Vec2::new(aspect * r, r),
            color,
            field: NormalField::FLAT,
        });
    }
    progress(n_pts);
    Grown {
        splats,
        covered,
        elliptical,
    }
}
