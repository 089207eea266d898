//! The triangle (issue 57): a mesh face as a primitive of the contract,
//! beside the splats' discs. One exact, watertight test decides every hit
//! ([`Triangle::intersect`]), in every backend, so the octree and Embree
//! (which hands its candidates to this same test) give the same bits.
//!
//! The test is that of Woop, Benthin and Wald, "Watertight Ray/Triangle
//! Intersection" (JCGT 2013): the ray is sheared onto `+z` (the same
//! shear for every triangle, [`simd::Shear`]), the vertices projected
//! along it, and the three 2D edge functions `U, V, W` decide. A shared
//! edge's function is computed from the same sheared values in both
//! triangles, so it is exactly the other's negation: a ray never slips
//! between two triangles. Where an edge function is exactly zero (the ray
//! through an edge or a vertex) it is recomputed in double precision, as
//! that paper does, and a zero that remains is decided by a symbolic
//! perturbation of the ray (toward `(-ε², ε)` in the sheared plane), the
//! same for every triangle: an edge belongs to the triangle on one side of
//! it only, and a vertex to one triangle of the fan around it. So a ray
//! through a shared edge or vertex of a consistently wound mesh hits
//! exactly one triangle.

use super::{Hit, Local, Pack, PackRay, PackRays, Primitive};
use crate::geometry::Ray;
use crate::simd::{self, Shear, TRI_LANES, TriColumns};
use glam::{DVec3, Vec3};

/// A triangle: its three vertices, in the order that gives its face
/// normal `(v1 - v0) × (v2 - v0)`.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct Triangle {
    /// The vertices.
    pub v: [Vec3; 3],
}

/// How far (relative to the largest vertex coordinate and the triangle's
/// size) a point may lie from a triangle and still count, for the self-hit
/// rule of secondary rays, as lying on it: the "radius" of
/// [`Triangle::locate`]. A departure point computed as `o + t d` lies off
/// the surface it hit by a few ulps of its coordinates (`2^-23` each);
/// `2^-16` is over a hundred times that and, for a scene a metre across,
/// 15 µm.
pub const ON_TRIANGLE: f32 = 1.0 / 65536.0;

/// An edge function `a - b` computed in single precision has the sign of
/// the exact `a - b` of the exact products when its magnitude exceeds
/// `SURE` times `|a| + |b|` (plus the smallest normal, for products that
/// underflow): each product and the difference round by at most `2^-24`
/// relative, four times less. The filter of `crate::simd` passes every
/// lane where one does not (the exact test decides there in double).
use crate::simd::SURE;

/// The sign of an edge function that is exactly zero, perturbing the ray
/// toward `(-ε², ε)` in the sheared plane: for the edge from `p` to `q` of
/// an edge function `orient(p, q, origin)`, the sign of `q.x - p.x`, else
/// of `q.y - p.y` (zero only when the edge projects to a point).
#[inline]
fn tie(e: f64, p: (f32, f32), q: (f32, f32)) -> f64 {
    if e != 0.0 {
        return e.signum();
    }
    if q.0 != p.0 {
        return f64::from(q.0 - p.0).signum();
    }
    if q.1 != p.1 {
        return f64::from(q.1 - p.1).signum();
    }
    0.0
}

impl Triangle {
    /// The unnormalised face normal `(v1 - v0) × (v2 - v0)`.
    #[must_use]
    pub fn face_normal(&self) -> Vec3 {
        (self.v[1] - self.v[0]).cross(self.v[2] - self.v[0])
    }

    /// The unit face normal (NaN for a degenerate triangle).
    #[must_use]
    pub fn unit_normal(&self) -> Vec3 {
        self.face_normal().normalize()
    }

    /// True when the vertices are finite and span a non-zero area.
    #[must_use]
    pub fn is_proper(&self) -> bool {
        let n = self.face_normal();
        self.v.iter().all(|v| v.is_finite()) && n.is_finite() && n.length_squared() > 0.0
    }

    /// Box centre and half extent.
    fn bounds(&self) -> (Vec3, Vec3) {
        let lo = self.v[0].min(self.v[1]).min(self.v[2]);
        let hi = self.v[0].max(self.v[1]).max(self.v[2]);
        ((lo + hi) * 0.5, (hi - lo) * 0.5)
    }
}

impl Primitive for Triangle {
    type Pack = TrianglePack;

    /// The watertight test (module doc). Accepts `t_min <= t <= t_max`,
    /// `t` finite, either side of the triangle; the hit's `(u, v)` are the
    /// barycentric weights of `v[1]` and `v[2]`. NaN or infinity in the ray
    /// or the triangle, and a zero direction, are misses.
    #[inline]
    fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<Hit> {
        let sh = Shear::new(ray.dir.to_array())?;
        if !ray.origin.is_finite() {
            return None;
        }
        let [kx, ky, kz] = sh.k;
        let [sx, sy, sz] = sh.s;
        let o = ray.origin;
        let vert = |i: usize| {
            let p = self.v[i] - o;
            (p[kx] - sx * p[kz], p[ky] - sy * p[kz], sz * p[kz])
        };
        // The operations of `simd::tri_masks`, in its order.
        let (ax, ay, az) = vert(0);
        let (bx, by, bz) = vert(1);
        let (cx, cy, cz) = vert(2);
        let (p1, p2) = (cx * by, cy * bx);
        let (p3, p4) = (ax * cy, ay * cx);
        let (p5, p6) = (bx * ay, by * ax);
        let (u, v, w) = (p1 - p2, p3 - p4, p5 - p6);
        let unsure =
            |e: f32, a: f32, b: f32| e.abs() <= (a.abs() + b.abs()) * SURE + f32::MIN_POSITIVE;
        if !(unsure(u, p1, p2) || unsure(v, p3, p4) || unsure(w, p5, p6)) {
            let sided = (u > 0.0 && v > 0.0 && w > 0.0) || (u < 0.0 && v < 0.0 && w < 0.0);
            if !sided {
                return None;
            }
            let det = u + v + w;
            let tt = u * az + v * bz + w * cz;
            let t = tt / det;
            if !(t >= t_min && t <= t_max && t.abs() < f32::INFINITY) {
                return None;
            }
            return Some(Hit {
                t,
                u: v / det,
                v: w / det,
            });
        }
        if u.is_nan() || v.is_nan() || w.is_nan() {
            return None;
        }
        // Near an edge or a vertex: the signs again in double precision
        // (the products of two `f32` are exact there, so each sign is the
        // exact orientation of the sheared vertices), a zero decided by the
        // perturbation (`tie`). Every sign is then exact, so a shared
        // edge's is the negation of its reverse's in the neighbour, and a
        // ray meets a closed mesh an even number of times.
        let d = |x: f32| f64::from(x);
        let su = tie(d(cx) * d(by) - d(cy) * d(bx), (cx, cy), (bx, by));
        let sv = tie(d(ax) * d(cy) - d(ay) * d(cx), (ax, ay), (cx, cy));
        let sw = tie(d(bx) * d(ay) - d(by) * d(ax), (bx, by), (ax, ay));
        if su == 0.0 || su != sv || sv != sw {
            return None;
        }
        let (u, v, w) = (
            d(cx) * d(by) - d(cy) * d(bx),
            d(ax) * d(cy) - d(ay) * d(cx),
            d(bx) * d(ay) - d(by) * d(ax),
        );
        let det = u + v + w;
        if det == 0.0 {
            return None;
        }
        let t = ((u * d(az) + v * d(bz) + w * d(cz)) / det) as f32;
        if !(t >= t_min && t <= t_max && t.abs() < f32::INFINITY) {
            return None;
        }
        Some(Hit {
            t,
            u: (v / det) as f32,
            v: (w / det) as f32,
        })
    }

    fn center(&self) -> Vec3 {
        self.bounds().0
    }

    fn half_extent(&self) -> Vec3 {
        self.bounds().1
    }

    /// The boxes overlap and the box straddles the triangle's plane (its
    /// corners' heights over the plane, with a relative slack for
    /// rounding): conservative, it may keep a box the triangle misses
    /// beside its edges, never drop one it meets.
    fn meets_box(&self, lo: Vec3, hi: Vec3) -> bool {
        let (c, h) = self.bounds();
        if (c - (lo + hi) * 0.5).abs().cmpgt(h + (hi - lo) * 0.5).any() {
            return false;
        }
        let n = self.face_normal().as_dvec3();
        let mid = ((lo + hi) * 0.5).as_dvec3();
        let half = ((hi - lo) * 0.5).as_dvec3();
        let s = n.dot(mid - self.v[0].as_dvec3());
        let r = n.abs().dot(half);
        let slack = 1e-5 * (n.abs().dot(mid.abs() + self.v[0].as_dvec3().abs()) + r);
        // NaN: kept (never drop what rounding cannot decide).
        s.abs().partial_cmp(&(r + slack)) != Some(std::cmp::Ordering::Greater)
    }

    /// The point's distance from the triangle, measured in units of
    /// [`ON_TRIANGLE`] of its size and position: `radial2` the squared
    /// distance of its projection from the triangle in the plane, `height`
    /// its signed distance from the plane, `normal` the unit face normal.
    /// So the self-hit rule skips a triangle only when the departure point
    /// lies on it (to rounding), never a neighbour a ray could truly meet:
    /// a triangle is an exact surface.
    fn locate(&self, p: Vec3) -> Local {
        let n = self.unit_normal();
        let (c, h) = self.bounds();
        let scale = ON_TRIANGLE * (c.abs().max_element() + h.max_element());
        let height = n.dot(p - self.v[0]);
        let q = (p - n * height).as_dvec3();
        let gap = distance_in_plane(&self.v.map(Vec3::as_dvec3), q) as f32;
        Local {
            radial2: (gap / scale) * (gap / scale),
            height: height / scale,
            normal: n,
        }
    }
}

/// Distance from `q` (in the triangle's plane) to the triangle: 0 inside.
fn distance_in_plane(v: &[DVec3; 3], q: DVec3) -> f64 {
    let n = (v[1] - v[0]).cross(v[2] - v[0]);
    let inside = (0..3).all(|i| (v[(i + 1) % 3] - v[i]).cross(q - v[i]).dot(n) >= 0.0);
    if inside {
        return 0.0;
    }
    (0..3)
        .map(|i| {
            let (a, b) = (v[i], v[(i + 1) % 3]);
            let e = b - a;
            let s = ((q - a).dot(e) / e.length_squared()).clamp(0.0, 1.0);
            if s.is_nan() {
                (q - a).length()
            } else {
                (q - (a + e * s)).length()
            }
        })
        .fold(f64::INFINITY, f64::min)
}

/// [`TRI_LANES`] triangles stored column by column ([`TriColumns`]), for
/// the filter of `crate::simd` on the widest path the CPU runs.
pub type TrianglePack = TriColumns;

impl Pack<Triangle> for TrianglePack {
    const LANES: usize = TRI_LANES;
    const EMPTY: TrianglePack = TriColumns::EMPTY;
    type Side = ();

    fn side(_prims: &[Triangle]) {}

    fn side_bytes((): &()) -> usize {
        0
    }

    /// The ray's shear (Woop et al. 2013, section 3), once per ray.
    type Prep = Option<Shear>;

    fn prep(ray: &PackRay) -> Option<Shear> {
        Shear::new(ray.dir)
    }

    fn set(&mut self, lane: usize, t: &Triangle) {
        for i in 0..3 {
            for a in 0..3 {
                self.cols[3 * i + a][lane] = t.v[i][a];
            }
        }
    }

    fn get(&self, lane: usize, _id: u32, (): &()) -> Triangle {
        let c = &self.cols;
        Triangle {
            v: [0, 1, 2].map(|i| Vec3::new(c[3 * i][lane], c[3 * i + 1][lane], c[3 * i + 2][lane])),
        }
    }

    /// The lanes of [`simd::tri_masks`] on the portable path.
    fn may_hit(&self, ray: &PackRay) -> u32 {
        let mut m = [0];
        Self::masks(std::slice::from_ref(self), ray, simd::Isa::Portable, &mut m);
        m[0]
    }

    /// [`simd::tri_masks`] on the path `isa` (the same lanes on every path).
    #[inline]
    fn masks(packs: &[Self], ray: &PackRay, isa: simd::Isa, out: &mut [u32]) {
        simd::tri_masks(packs, ray.origin, ray.dir, ray.t_min, ray.t_max, isa, out);
    }

    /// [`simd::tri_masks_sheared`] with the ray's shear made once.
    #[inline]
    fn masks_prepped(
        packs: &[Self],
        ray: &PackRay,
        prep: &Option<Shear>,
        isa: simd::Isa,
        out: &mut [u32],
    ) {
        let (o, t) = (ray.origin, (ray.t_min, ray.t_max));
        simd::tri_masks_sheared(packs, o, prep.as_ref(), t.0, t.1, isa, out);
    }

    /// Each active ray's masks with its shear made once per ray.
    #[inline]
    fn masks_rays_prepped(
        packs: &[Self],
        rays: &PackRays,
        preps: &[Option<Option<Shear>>; simd::RAYS],
        active: u32,
        isa: simd::Isa,
        out: &mut [[u32; simd::RAYS]],
        any: &mut [u32],
    ) {
        super::masks_per_ray(packs, rays, active, out, any, |c, r, k, m| {
            match &preps[k] {
                Some(p) => Self::masks_prepped(c, r, p, isa, m),
                None => Self::masks(c, r, isa, m),
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    fn tri(a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> Triangle {
        Triangle {
            v: [a.into(), b.into(), c.into()],
        }
    }

    /// A grid of `n × n` unit squares on `z = 0`, two triangles each,
    /// consistently wound (face normal +z).
    fn grid(n: usize) -> Vec<Triangle> {
        let mut out = Vec::new();
        for i in 0..n {
            for j in 0..n {
                let (x, y) = (i as f32, j as f32);
                let p = |dx: f32, dy: f32| [x + dx, y + dy, 0.0];
                out.push(tri(p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0)));
                out.push(tri(p(0.0, 0.0), p(1.0, 1.0), p(0.0, 1.0)));
            }
        }
        out
    }

    fn count(tris: &[Triangle], ray: &Ray) -> usize {
        tris.iter()
            .filter(|t| t.intersect(ray, 0.0, f32::INFINITY).is_some())
            .count()
    }

    #[test]
    fn a_ray_through_a_shared_edge_or_vertex_hits_exactly_one_triangle() {
        let tris = grid(4);
        // Straight down through every vertex, edge midpoint and diagonal
        // point of the inner grid (the edge functions are exactly zero),
        // and tilted rays aimed there.
        let mut n = 0;
        for i in 1..8 {
            for j in 1..8 {
                let p = Vec3::new(i as f32 * 0.5, j as f32 * 0.5, 0.0);
                for d in [
                    Vec3::new(0.0, 0.0, -1.0),
                    Vec3::new(0.0, 0.0, 1.0),
                    Vec3::new(0.3, -0.2, -1.0),
                    Vec3::new(-0.25, 0.5, 1.0),
                    Vec3::new(1.0, 1.0, -1.0),
                ] {
                    let ray = Ray::new(p - d * 3.0, d);
                    assert_eq!(count(&tris, &ray), 1, "through {p} along {d}");
                    n += 1;
                }
            }
        }
        assert_eq!(n, 245);
    }

    #[test]
    fn random_rays_through_a_closed_mesh_hit_it_an_even_number_of_times() {
        // A tetrahedron with its faces wound outward and random rays
        // aimed at its edges and vertices: never one hit alone, never
        // three (a ray slipping between faces, or hitting one edge twice).
        let p = [
            [0.0, 0.0, 0.0],
            [1.0, 0.1, 0.0],
            [0.2, 1.0, 0.1],
            [0.3, 0.3, 1.0],
        ];
        let f = |a: usize, b: usize, c: usize| tri(p[a], p[b], p[c]);
        let tet = [f(0, 2, 1), f(0, 1, 3), f(1, 2, 3), f(0, 3, 2)];
        let mut rng = SplitMix64::new(3);
        let mut r = |s: f32| (rng.next_f64() as f32 * 2.0 - 1.0) * s;
        let mut through = 0;
        for k in 0..20_000 {
            let (a, b) = (k % 4, (k / 4 + 1 + k % 4) % 4);
            let s = if k % 3 == 0 { 0.0 } else { r(1.0).abs() };
            let aim = Vec3::from(p[a]).lerp(Vec3::from(p[b]), s);
            // From 4 units away: outside the tetrahedron.
            let d = Vec3::new(r(1.0), r(1.0), r(1.0)).normalize();
            let ray = Ray::new(aim - d * 4.0, d);
            let hits = count(&tet, &ray);
            assert!(hits.is_multiple_of(2), "ray {k}: {hits} hits through {aim} {ray:?}");
            through += usize::from(hits == 2);
        }
        assert!(through > 5_000, "too few rays went through: {through}");
    }

    #[test]
    fn misses_on_nan_infinite_zero_and_in_plane_rays() {
        let t = tri([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        let o = Vec3::new(0.2, 0.2, 1.0);
        for ray in [
            Ray {
                origin: o,
                dir: Vec3::new(f32::NAN, 0.0, -1.0),
            },
            Ray {
                origin: Vec3::new(f32::NAN, 0.2, 1.0),
                dir: -Vec3::Z,
            },
            Ray {
                origin: Vec3::new(f32::INFINITY, 0.2, 1.0),
                dir: -Vec3::Z,
            },
            Ray {
                origin: o,
                dir: Vec3::new(0.0, 0.0, f32::INFINITY),
            },
            Ray {
                origin: o,
                dir: Vec3::ZERO,
            },
            // In the triangle's plane, across it.
            Ray {
                origin: Vec3::new(-1.0, 0.2, 0.0),
                dir: Vec3::X,
            },
        ] {
            assert_eq!(t.intersect(&ray, 0.0, f32::INFINITY), None, "{ray:?}");
        }
        // NaN span.
        let down = Ray::new(o, -Vec3::Z);
        assert_eq!(t.intersect(&down, f32::NAN, 5.0), None);
        assert_eq!(t.intersect(&down, 0.0, f32::NAN), None);
        let h = t.intersect(&down, 0.0, 5.0).unwrap();
        assert_eq!(h.t, 1.0);
        assert!(
            (h.u - 0.2).abs() < 1e-6 && (h.v - 0.2).abs() < 1e-6,
            "{h:?}"
        );
        // Grazing: nearly in the plane, still hits at the right place.
        let graze = Ray::new(Vec3::new(-1.0, 0.2, 1e-4), Vec3::new(1.0, 0.0, -1e-4));
        let h = t.intersect(&graze, 0.0, f32::INFINITY).unwrap();
        assert!((graze.at(h.t).x - 0.0).abs() < 1e-3, "{h:?}");
        // Degenerate: no hit.
        let flat = tri([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]);
        assert_eq!(
            flat.intersect(&Ray::new(Vec3::new(0.5, 0.0, 1.0), -Vec3::Z), 0.0, 9.0),
            None
        );
    }

    #[test]
    fn pack_filter_passes_every_hit_of_intersect() {
        let mut rng = SplitMix64::new(5);
        let mut f = |s: f32| (rng.next_f64() as f32 * 2.0 - 1.0) * s;
        let mut tris = grid(3);
        for _ in 0..40 {
            let c = Vec3::new(f(2.0), f(2.0), f(2.0));
            tris.push(Triangle {
                v: [0; 3].map(|_| c + Vec3::new(f(0.5), f(0.5), f(0.5))),
            });
        }
        let packs: Vec<TrianglePack> = tris
            .chunks(TRI_LANES)
            .map(|c| TrianglePack::from_fn(|l| c.get(l).copied()))
            .collect();
        let mut hits = 0;
        for r in 0..3000 {
            let target = tris[r % tris.len()];
            let aim = if r % 2 == 0 {
                target.v[r % 3]
            } else {
                target.center()
            };
            let d = Vec3::new(f(1.0), f(1.0), f(1.0));
            let ray = Ray::new(aim - d * 3.0, d);
            let (t_min, t_max) = if r % 3 == 0 {
                (0.0, f32::INFINITY)
            } else {
                (1.0, 3.0 + f(1.0))
            };
            for isa in simd::available() {
                let mut m = vec![0; packs.len()];
                let lanes = PackRay::new(&ray, t_min, t_max);
                TrianglePack::masks(&packs, &lanes, isa, &mut m);
                // The shear made once per ray: the same masks.
                let mut once = vec![u32::MAX; packs.len()];
                let prep = TrianglePack::prep(&lanes);
                TrianglePack::masks_prepped(&packs, &lanes, &prep, isa, &mut once);
                assert_eq!(once, m, "{isa}: ray {r}, the shear made once");
                for (i, t) in tris.iter().enumerate() {
                    let hit = t.intersect(&ray, t_min, t_max).is_some();
                    let passed = m[i / TRI_LANES] >> (i % TRI_LANES) & 1 == 1;
                    assert!(
                        passed || !hit,
                        "{isa}: ray {r} triangle {i} hit but filtered"
                    );
                    hits += usize::from(hit);
                }
                // Padding lanes are never passed.
                let last = tris.len() % TRI_LANES;
                assert_eq!(m[packs.len() - 1] >> last, 0, "{isa}: padding passed");
            }
        }
        assert!(hits > 2000, "too few hits to test: {hits}");
    }

    #[test]
    fn packet_masks_with_the_shears_made_once_are_each_rays_own() {
        let tris = grid(4);
        let packs: Vec<TrianglePack> = tris
            .chunks(TRI_LANES)
            .map(|c| TrianglePack::from_fn(|l| c.get(l).copied()))
            .collect();
        let origin = [1.7, 2.1, 3.0];
        let mut rays = PackRays {
            origin,
            dir: [[0.0; 3]; simd::RAYS],
            t_min: [0.0; simd::RAYS],
            t_max: [f32::INFINITY; simd::RAYS],
            cone: None,
        };
        // Toward the grid's vertices and edge midpoints, one ray stopping
        // short of it.
        rays.dir = std::array::from_fn(|k| {
            let aim = [k as f32 * 0.5, 4.0 - k as f32 * 0.5, 0.0];
            [0, 1, 2].map(|a| aim[a] - origin[a])
        });
        rays.t_max[5] = 0.5;
        let preps = rays.dir.map(|dir| {
            let one = PackRay {
                origin,
                dir,
                t_min: 0.0,
                t_max: 1.0,
            };
            Some(TrianglePack::prep(&one))
        });
        let active = 0b1011_1111;
        let mut passed = 0;
        for isa in simd::available() {
            let (mut out, mut any) = (vec![[0; simd::RAYS]; packs.len()], vec![0; packs.len()]);
            TrianglePack::masks_rays_prepped(&packs, &rays, &preps, active, isa, &mut out, &mut any);
            for (k, &dir) in rays.dir.iter().enumerate() {
                let ray = PackRay {
                    origin,
                    dir,
                    t_min: rays.t_min[k],
                    t_max: rays.t_max[k],
                };
                let mut want = vec![0; packs.len()];
                if active >> k & 1 == 1 {
                    TrianglePack::masks(&packs, &ray, isa, &mut want);
                }
                for j in 0..packs.len() {
                    assert_eq!(out[j][k], want[j], "{isa}: ray {k}, pack {j}");
                    assert_eq!(any[j] >> k & 1, u32::from(want[j] != 0));
                    passed += want[j].count_ones();
                }
            }
        }
        assert!(passed > 10, "too few lanes passed to test: {passed}");
    }

    #[test]
    fn the_box_test_keeps_every_box_the_triangle_meets() {
        let t = tri([0.0, 0.0, 0.0], [1.0, 0.0, 0.3], [0.0, 1.0, 0.6]);
        // A box around a point of the triangle always meets it.
        let mut rng = SplitMix64::new(9);
        let mut f = || rng.next_f64() as f32;
        for _ in 0..1000 {
            let (a, b) = (f(), f());
            let (a, b) = if a + b > 1.0 {
                (1.0 - a, 1.0 - b)
            } else {
                (a, b)
            };
            let p = t.v[0] + (t.v[1] - t.v[0]) * a + (t.v[2] - t.v[0]) * b;
            let h = Vec3::splat(f() * 0.1);
            let off = Vec3::new(f() - 0.5, f() - 0.5, f() - 0.5) * h;
            assert!(t.meets_box(p + off - h, p + off + h));
        }
        // Far above the plane, inside the triangle's box: not met.
        assert!(!t.meets_box(Vec3::new(0.1, 0.1, 0.9), Vec3::new(0.2, 0.2, 1.0)));
        assert!(!t.meets_box(Vec3::splat(5.0), Vec3::splat(6.0)));
    }

    #[test]
    fn locate_counts_only_points_on_the_triangle() {
        let t = tri([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        let on = t.locate(Vec3::new(0.3, 0.3, 1e-7));
        assert!(on.radial2 == 0.0 && on.height.abs() < 0.1, "{on:?}");
        // On the shared edge's far side, just off: within the rule's 2.5.
        let edge = t.locate(Vec3::new(0.5 + 1e-6, 0.5 + 1e-6, 0.0));
        assert!(edge.radial2 < 1.0, "{edge:?}");
        // A millimetre away (of a 1-unit triangle): far outside.
        let off = t.locate(Vec3::new(0.3, 0.3, 1e-3));
        assert!(off.height > 50.0, "{off:?}");
        let beside = t.locate(Vec3::new(1.0, 1.0, 0.0));
        assert!(beside.radial2 > 1e6, "{beside:?}");
        assert_eq!(on.normal, Vec3::Z);
    }
}
