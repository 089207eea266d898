//! The oriented elliptical disc of a splat (§2.1, fig. 3): the primitive of
//! every scene today.

use super::{AT_CHUNK, Hit, Local, Pack, PackRay, PackRays, Primitive};
use crate::geometry::Ray;
use crate::simd;
use glam::Vec3;

/// What the intersection hot loop reads of a splat: 48 contiguous bytes.
/// The tangent axes are pre-divided by the radii, so the local coordinates
/// it yields are already normalised (`|(u,v)| <= 1` on the splat).
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct Disc {
    /// Splat centre; all intersection math is relative to it.
    pub center: Vec3,
    /// Unit normal.
    pub normal: Vec3,
    /// `u_axis / r_u`.
    pub u_scaled: Vec3,
    /// `v_axis / r_v`.
    pub v_scaled: Vec3,
}

impl Primitive for Disc {
    type Pack = DiscPack;

    /// Intersects a ray with the disc, relative to its centre.
    ///
    /// Accepts `t_min <= t <= t_max` and the closed disc `u² + v² <= 1` (the
    /// rim counts as on the splat). A ray parallel to the splat plane
    /// (`n·d == 0`) misses, and so does a near-parallel one whose `t` is not
    /// finite; NaN in the ray or disc makes every comparison false, hence a
    /// miss. No division happens unless `n·d != 0`.
    #[inline]
    fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<Hit> {
        let denom = self.normal.dot(ray.dir);
        if denom == 0.0 {
            return None;
        }
        let oc = ray.origin - self.center;
        let t = -self.normal.dot(oc) / denom;
        if !(t >= t_min && t <= t_max && t.is_finite()) {
            return None;
        }
        let p = oc + ray.dir * t;
        let u = p.dot(self.u_scaled);
        let v = p.dot(self.v_scaled);
        if u * u + v * v <= 1.0 {
            Some(Hit { t, u, v })
        } else {
            None
        }
    }

    #[inline]
    fn center(&self) -> Vec3 {
        self.center
    }

    /// Along world axis `i`, `sqrt((r_u u_i)² + (r_v v_i)²)`, with the axes
    /// and radii recovered from the scaled axes (`|u_scaled| = 1 / r_u`).
    fn half_extent(&self) -> Vec3 {
        let (a, b) = self.axes();
        (a * a + b * b).map(f32::sqrt)
    }

    /// The ellipse's greatest semi-axis: the largest singular value of
    /// the semi-axes `(a, b)` (`r_u u`, `r_v v`; `max(r_u, r_v)` when they
    /// are orthogonal), where the box's ball is `sqrt(r_u² + r_v²)`.
    fn bounding_radius(&self) -> f32 {
        let (a, b) = self.axes();
        let (aa, bb, ab) = (a.length_squared(), b.length_squared(), a.dot(b));
        let spread = ((aa - bb) * (aa - bb) + 4.0 * ab * ab).sqrt();
        (0.5 * (aa + bb + spread)).sqrt()
    }

    /// `r_u u` and `r_v v`: the accepted points are `c + α a + β b`,
    /// `α² + β² <= 1` (`α = p·u_scaled`, `β = p·v_scaled`).
    fn semi_axes(&self) -> Option<(Vec3, Vec3)> {
        Some(self.axes())
    }

    /// The box of the bounding square `c ± r_u u ± r_v v` (§3.1).
    fn coarse_half_extent(&self) -> Vec3 {
        let (a, b) = self.axes();
        a.abs() + b.abs()
    }

    /// The box's section by the splat plane is the convex hull of the points
    /// where the plane crosses box edges (plus corners lying on it). In the
    /// disc's normalised coordinates the disc is the unit circle, so the two
    /// meet iff the disc centre lies in the box (then it lies in the section)
    /// or the hull comes within distance 1 of the origin; the latter is
    /// checked over all segments between section points, which include the
    /// hull's edges and otherwise lie inside it.
    fn meets_box(&self, lo: Vec3, hi: Vec3) -> bool {
        if self.center.cmpge(lo).all() && self.center.cmple(hi).all() {
            return true;
        }
        let half = (hi - lo) * 0.5;
        let rel_mid = (lo + half) - self.center;
        let height = self.normal.dot(rel_mid);
        if height.abs() > self.normal.abs().dot(half) {
            return false;
        }
        // Quick accept: the box centre's projection onto the plane lies in
        // the box and on the disc (a common point; rounding can only add a
        // reference, never lose one).
        let drop = self.normal * height;
        let foot = rel_mid - drop;
        let (fu, fv) = (foot.dot(self.u_scaled), foot.dot(self.v_scaled));
        if drop.abs().cmple(half).all() && fu * fu + fv * fv <= 1.0 {
            return true;
        }
        let mut s = [0.0f32; 8];
        let mut uv = [[0.0f32; 2]; 8];
        for k in 0..8 {
            let rel = lo - self.center
                + Vec3::new(
                    if k & 1 != 0 { hi.x - lo.x } else { 0.0 },
                    if k & 2 != 0 { hi.y - lo.y } else { 0.0 },
                    if k & 4 != 0 { hi.z - lo.z } else { 0.0 },
                );
            s[k] = self.normal.dot(rel);
            uv[k] = [rel.dot(self.u_scaled), rel.dot(self.v_scaled)];
        }
        let mut pts = [[0.0f32; 2]; 12];
        let mut n = 0;
        for k in 0..8 {
            if s[k] == 0.0 {
                pts[n] = uv[k];
                n += 1;
            }
        }
        for a in 0..8 {
            for bit in [1usize, 2, 4] {
                if a & bit != 0 {
                    continue;
                }
                let b = a | bit;
                if (s[a] < 0.0 && s[b] > 0.0) || (s[a] > 0.0 && s[b] < 0.0) {
                    let t = s[a] / (s[a] - s[b]);
                    pts[n] = [
                        uv[a][0] + (uv[b][0] - uv[a][0]) * t,
                        uv[a][1] + (uv[b][1] - uv[a][1]) * t,
                    ];
                    n += 1;
                }
            }
        }
        let pts = &pts[..n.min(12)];
        // A section point on the disc settles it without the segments.
        if pts.iter().any(|p| p[0] * p[0] + p[1] * p[1] <= 1.0) {
            return true;
        }
        for (i, p) in pts.iter().enumerate() {
            for q in &pts[i + 1..] {
                if segment_within_unit(*p, *q) {
                    return true;
                }
            }
        }
        false
    }

    /// `(u, v)` of `p`'s projection (the tangent axes are orthogonal to the
    /// normal, so projecting first changes nothing) and its height above the
    /// plane over the larger radius (`1 / min(|u_scaled|, |v_scaled|)`).
    #[inline]
    fn locate(&self, p: Vec3) -> Local {
        let d = p - self.center;
        let u = d.dot(self.u_scaled);
        let v = d.dot(self.v_scaled);
        let inv_r_max = self
            .u_scaled
            .length_squared()
            .min(self.v_scaled.length_squared())
            .sqrt();
        Local {
            radial2: u * u + v * v,
            height: self.normal.dot(d) * inv_r_max,
            normal: self.normal,
        }
    }
}

impl Disc {
    /// The semi-axes `r_u u` and `r_v v` as world vectors.
    fn axes(&self) -> (Vec3, Vec3) {
        let ru = 1.0 / self.u_scaled.length();
        let rv = 1.0 / self.v_scaled.length();
        (self.u_scaled * (ru * ru), self.v_scaled * (rv * rv))
    }
}

/// Does the segment `pq` pass within distance 1 of the origin?
fn segment_within_unit(p: [f32; 2], q: [f32; 2]) -> bool {
    let e = [q[0] - p[0], q[1] - p[1]];
    let ee = e[0] * e[0] + e[1] * e[1];
    if ee <= 0.0 {
        return false;
    }
    let t = (-(p[0] * e[0] + p[1] * e[1]) / ee).clamp(0.0, 1.0);
    let x = p[0] + e[0] * t;
    let y = p[1] + e[1] * t;
    x * x + y * y <= 1.0
}

/// Discs per [`DiscPack`]: as many as an AVX2 register holds.
const LANES: usize = simd::LANES;

/// [`LANES`] discs stored component by component (SoA,
/// [`simd::DiscColumns`]), so [`Pack::masks`] tests them together on the
/// widest path the CPU runs (`crate::simd`).
pub type DiscPack = simd::DiscColumns;

impl Pack<Disc> for DiscPack {
    const LANES: usize = LANES;

    /// All lanes padding: a zero normal, so no ray can hit them (`n·d` is
    /// 0 or NaN, hence `t` is never finite).
    const EMPTY: DiscPack = simd::DiscColumns {
        cols: [[0.0; LANES]; 12],
    };
    /// Nothing: the lanes hold the whole disc.
    type Side = ();

    fn side(_prims: &[Disc]) {}

    fn side_bytes((): &()) -> usize {
        0
    }

    type Prep = ();

    fn prep(_ray: &PackRay) {}

    fn set(&mut self, lane: usize, d: &Disc) {
        let c = &mut self.cols;
        for k in 0..3 {
            c[simd::CENTER + k][lane] = d.center[k];
            c[simd::NORMAL + k][lane] = d.normal[k];
            c[simd::U_SCALED + k][lane] = d.u_scaled[k];
            c[simd::V_SCALED + k][lane] = d.v_scaled[k];
        }
    }

    #[inline]
    fn get(&self, lane: usize, _id: u32, (): &()) -> Disc {
        let c = &self.cols;
        let get = |k: usize| Vec3::new(c[k][lane], c[k + 1][lane], c[k + 2][lane]);
        Disc {
            center: get(simd::CENTER),
            normal: get(simd::NORMAL),
            u_scaled: get(simd::U_SCALED),
            v_scaled: get(simd::V_SCALED),
        }
    }

    /// The operations of [`Disc::intersect`] in the same order per lane
    /// (glam's `dot` is `x*x' + y*y' + z*z'`, left to right; no fused
    /// operations), so the mask equals "`intersect` hits" except that the
    /// rim test is relaxed by `1e-4` — a conservative filter in any case,
    /// since each set lane is then decided by `intersect` itself.
    #[inline]
    fn may_hit(&self, ray: &PackRay) -> u32 {
        let mut m = [0];
        Self::masks(std::slice::from_ref(self), ray, simd::Isa::Portable, &mut m);
        m[0]
    }

    /// [`DiscPack::may_hit`] of every pack on the path `isa`
    /// ([`simd::disc_masks`]: the same lanes on every path).
    #[inline]
    fn masks(packs: &[Self], ray: &PackRay, isa: simd::Isa, out: &mut [u32]) {
        pack_masks(packs, ray, isa, out);
    }

    /// [`simd::disc_masks_met`]: the met packs' masks in one call.
    #[inline]
    fn masks_met(packs: &[Self], met: u32, ray: &PackRay, (): &(), isa: simd::Isa, out: &mut [u32]) {
        pack_masks_met(packs, met, ray, isa, out);
    }

    const LANE_HITS: bool = true;

    /// [`simd::disc_hits_met`]: the met packs' masks and lanes' answers
    /// in one call.
    #[inline(always)]
    fn hits_met(
        packs: &[Self],
        met: u32,
        ray: &PackRay,
        (): &(),
        isa: simd::Isa,
        out: &mut [u32],
        hits: &mut simd::LaneHits<'_>,
    ) {
        pack_hits_met(packs, met, ray, isa, out, hits);
    }

    /// [`lane_disc_hit`].
    #[inline(always)]
    fn lane_hit(
        &self,
        _lane: usize,
        _id: u32,
        (): &(),
        _ray: &Ray,
        (_t_min, cut): (f32, f32),
        tuv: (f32, f32, f32),
    ) -> Option<Hit> {
        lane_disc_hit(cut, tuv)
    }

    /// [`simd::disc_masks`] of the packs `packs[at[j]]` in one call
    /// ([`pack_masks_at`]).
    #[inline]
    fn masks_at(packs: &[Self], at: &[u32], ray: &PackRay, isa: simd::Isa, out: &mut [u32]) {
        pack_masks_at(packs, at, ray, isa, out);
    }

    /// [`simd::disc_masks_rays`] of the packs `packs[at[j]]` in one call
    /// ([`pack_masks_rays_at`]).
    #[inline]
    fn masks_rays_at(
        packs: &[Self],
        at: &[u32],
        rays: &PackRays,
        active: u32,
        isa: simd::Isa,
        out: &mut [[u32; simd::RAYS]],
        any: &mut [u32],
    ) {
        pack_masks_rays_at(packs, at, rays, active, isa, out, any);
    }

    /// [`simd::disc_masks_rays`]: each pack and its `n·(o - c)` once for
    /// all the rays (the lanes of [`DiscPack::masks`] per ray, less those
    /// whose disc lies beyond its radius from the rays' cone).
    #[inline]
    fn masks_rays(
        packs: &[Self],
        rays: &PackRays,
        active: u32,
        isa: simd::Isa,
        out: &mut [[u32; simd::RAYS]],
        any: &mut [u32],
    ) {
        pack_masks_rays(packs, rays, active, isa, out, any);
    }
}

/// [`simd::disc_masks`] of the disc packs `packs` hold (a [`DiscPack`]
/// itself, or a pack of a primitive built on discs that holds one), read
/// in place: [`Pack::masks`] of [`DiscPack`] and of packs that filter by
/// their discs.
#[inline]
pub(super) fn pack_masks<C: AsRef<DiscPack>>(
    packs: &[C],
    ray: &PackRay,
    isa: simd::Isa,
    out: &mut [u32],
) {
    simd::disc_masks(packs, ray.origin, ray.dir, ray.t_min, ray.t_max, isa, out);
}

/// [`simd::disc_masks_met`] of the disc packs `packs` hold, as
/// [`pack_masks`]: [`Pack::masks_met`] of [`DiscPack`] and of packs that
/// filter by their discs.
#[inline]
pub(super) fn pack_masks_met<C: AsRef<DiscPack>>(
    packs: &[C],
    met: u32,
    ray: &PackRay,
    isa: simd::Isa,
    out: &mut [u32],
) {
    simd::disc_masks_met(packs, met, ray.origin, ray.dir, ray.t_min, ray.t_max, isa, out);
}

/// [`simd::disc_hits_met`] of the disc packs `packs` hold, as
/// [`pack_masks_met`].
#[inline(always)]
pub(super) fn pack_hits_met<C: AsRef<DiscPack>>(
    packs: &[C],
    met: u32,
    ray: &PackRay,
    isa: simd::Isa,
    out: &mut [u32],
    hits: &mut simd::LaneHits<'_>,
) {
    let span = (ray.t_min, ray.t_max);
    simd::disc_hits_met(packs, met, ray.origin, ray.dir, span, isa, out, hits);
}

/// [`Disc::intersect`]'s answer within `[t_min, cut]` for a lane the
/// disc filter passed with `(t, u, v)` ([`simd::disc_hits_met`], the same
/// operations) for a span `[t_min, t_max]`, `t_max >= cut`: the filter
/// found `t` finite and at least `t_min`, so the hit is the lane's when
/// `t <= cut` and `u * u + v * v <= 1` (the exact rim), bit for bit.
#[inline(always)]
pub(super) fn lane_disc_hit(cut: f32, (t, u, v): (f32, f32, f32)) -> Option<Hit> {
    (t <= cut && u * u + v * v <= 1.0).then_some(Hit { t, u, v })
}

/// [`simd::disc_masks_rays`] of the disc packs `packs` hold, as
/// [`pack_masks`]: [`Pack::masks_rays`] of [`DiscPack`] and of packs that
/// filter by their discs.
#[inline]
pub(super) fn pack_masks_rays<C: AsRef<DiscPack>>(
    packs: &[C],
    rays: &PackRays,
    active: u32,
    isa: simd::Isa,
    out: &mut [[u32; simd::RAYS]],
    any: &mut [u32],
) {
    simd::disc_masks_rays(
        packs,
        rays.origin,
        &rays.dir,
        &rays.t_min,
        &rays.t_max,
        rays.cone.as_ref(),
        active,
        isa,
        out,
        any,
    );
}

/// [`pack_masks`] of the packs `packs[at[j]]`, [`AT_CHUNK`] indices a
/// call: the kernels take a list of references as they take a slice of
/// packs (the same operations on the same lanes, read where they are).
#[inline]
pub(super) fn pack_masks_at<C: AsRef<DiscPack>>(
    packs: &[C],
    at: &[u32],
    ray: &PackRay,
    isa: simd::Isa,
    out: &mut [u32],
) {
    for (c, at) in at.chunks(AT_CHUNK).enumerate() {
        let refs: [&C; AT_CHUNK] = std::array::from_fn(|j| &packs[at[j.min(at.len() - 1)] as usize]);
        pack_masks(&refs[..at.len()], ray, isa, &mut out[c * AT_CHUNK..]);
    }
}

/// [`pack_masks_rays`] of the packs `packs[at[j]]`, as [`pack_masks_at`].
#[inline]
pub(super) fn pack_masks_rays_at<C: AsRef<DiscPack>>(
    packs: &[C],
    at: &[u32],
    rays: &PackRays,
    active: u32,
    isa: simd::Isa,
    out: &mut [[u32; simd::RAYS]],
    any: &mut [u32],
) {
    for (c, at) in at.chunks(AT_CHUNK).enumerate() {
        let refs: [&C; AT_CHUNK] = std::array::from_fn(|j| &packs[at[j.min(at.len() - 1)] as usize]);
        let (o, a) = (&mut out[c * AT_CHUNK..], &mut any[c * AT_CHUNK..]);
        pack_masks_rays(&refs[..at.len()], rays, active, isa, o, a);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use crate::splat::Splat;

    fn disc(c: Vec3, n: Vec3, r: f32) -> Disc {
        Splat::disc(c, n, r).unwrap().disc_geometry()
    }

    #[test]
    fn pack_filter_passes_every_hit_of_intersect() {
        // Rays aimed near the rims (so hits and misses are close calls),
        // some grazing, some with a finite window: every lane that
        // `intersect` hits must be in the mask.
        let mut rng = SplitMix64::new(0x0bad_cafe_1234_5678);
        let mut rnd = || rng.next_f32() - 0.5;
        let mut hits = 0;
        for _ in 0..20_000 {
            let mut pack = DiscPack::EMPTY;
            let mut discs = [None; LANES];
            for (lane, slot) in discs.iter_mut().enumerate().take(LANES - 1) {
                let n = Vec3::new(rnd(), rnd(), rnd());
                let c = Vec3::new(rnd(), rnd(), rnd());
                let Some(s) = Splat::disc(c, n, 0.2 + rnd().abs()) else {
                    continue;
                };
                let d = s.disc_geometry();
                pack.set(lane, &d);
                *slot = Some(d);
            }
            let origin = Vec3::new(rnd(), rnd(), rnd()) * 8.0;
            let target =
                discs[0].map_or(Vec3::ZERO, |d| d.center) + Vec3::new(rnd(), rnd(), rnd()) * 0.9;
            let ray = Ray::new(origin, target - origin);
            let t_max = if rnd() > 0.3 {
                f32::INFINITY
            } else {
                4.0 + rnd()
            };
            let mask = pack.may_hit(&PackRay::new(&ray, 0.0, t_max));
            for (lane, d) in discs.iter().enumerate() {
                let hit = d.is_some_and(|d| d.intersect(&ray, 0.0, t_max).is_some());
                hits += usize::from(hit);
                assert!(!hit || mask & (1 << lane) != 0, "lane {lane} filtered out");
                if d.is_none() {
                    assert_eq!(mask & (1 << lane), 0, "padding lane passed");
                } else {
                    assert_eq!(
                        pack.get(lane, 0, &()),
                        d.unwrap(),
                        "lane {lane} stored bit for bit"
                    );
                }
            }
        }
        assert!(hits > 1000, "the rays should often hit: {hits}");
    }

    /// `n` packs of random discs around the origin (centres and normals in
    /// the cube of side 1, radii 0.15 to 0.25; a degenerate draw leaves its
    /// lane empty), drawn from `rnd` in a fixed order.
    fn random_packs(n: usize, rnd: &mut impl FnMut() -> f32) -> Vec<DiscPack> {
        (0..n)
            .map(|_| {
                let discs: [Option<Disc>; LANES] = std::array::from_fn(|_| {
                    let (c, n) = (Vec3::new(rnd(), rnd(), rnd()), Vec3::new(rnd(), rnd(), rnd()));
                    Splat::disc(c, n, 0.15 + 0.2 * rnd().abs()).map(|s| s.disc_geometry())
                });
                DiscPack::from_fn(|l| discs[l])
            })
            .collect()
    }

    #[test]
    fn masks_met_are_the_masks_of_the_met_packs_on_every_path() {
        // 16 packs of discs around the origin, rays from outside and inside
        // them, sets of met packs (none, all, runs, scattered): on every
        // SIMD path each met pack's mask is its own, the other slots are
        // left as they were.
        let mut rng = SplitMix64::new(0x55_0028);
        let mut rnd = || rng.next_f32() - 0.5;
        let packs = random_packs(16, &mut rnd);
        let mut passed = 0;
        for trial in 0..200u32 {
            let origin = Vec3::new(rnd(), rnd(), rnd()) * if trial % 2 == 0 { 0.6 } else { 6.0 };
            let dir = Vec3::new(rnd(), rnd(), rnd()) * 0.8 - origin;
            let t_max = if trial % 4 == 0 { 5.0 } else { f32::INFINITY };
            let ray = PackRay::new(&Ray::new(origin, dir), 0.0, t_max);
            let met = match trial % 5 {
                0 => 0,
                1 => 0xffff,
                2 => 0x0ff0,
                _ => (rnd().abs() * 65536.0) as u32 & 0xffff,
            };
            for isa in simd::available() {
                let mut want = vec![0; 16];
                DiscPack::masks(&packs, &ray, isa, &mut want);
                let mut got = vec![0xdead; 16];
                DiscPack::masks_met(&packs, met, &ray, &(), isa, &mut got);
                for j in 0..16 {
                    let expect = if met & 1 << j != 0 { want[j] } else { 0xdead };
                    assert_eq!(got[j], expect, "{isa:?} trial {trial} pack {j}");
                }
                passed += want.iter().filter(|&&m| m != 0).count();
            }
        }
        assert!(passed > 100, "{passed}");
    }

    #[test]
    fn masks_at_are_the_masks_of_each_listed_pack_on_every_path() {
        // 40 packs of discs around the origin, lists of indices in any
        // order (repeats, runs, longer than a call takes), rays sharing
        // an origin: on every SIMD path the listed packs' masks, single
        // ray and per ray of a packet, are each pack's own.
        let mut rng = SplitMix64::new(0x55_0004);
        let mut rnd = || rng.next_f32() - 0.5;
        let packs = random_packs(40, &mut rnd);
        let origin = Vec3::new(0.3, 2.5, 4.0);
        let mut set = 0;
        for trial in 0..60 {
            let len = 1 + trial % 37;
            let at: Vec<u32> = (0..len)
                .map(|j| if trial % 3 == 0 { (trial + j) as u32 % 40 } else { (rnd().abs() * 79.0) as u32 % 40 })
                .collect();
            let dirs: [[f32; 3]; simd::RAYS] =
                std::array::from_fn(|_| (Vec3::new(rnd(), rnd(), rnd()) * 0.8 - origin).to_array());
            let t_max = if trial % 4 == 0 { 5.0 } else { f32::INFINITY };
            let cols: [[f32; simd::RAYS]; 3] = std::array::from_fn(|a| dirs.map(|d| d[a]));
            let rays = PackRays {
                origin: origin.to_array(),
                dir: dirs,
                t_min: [0.0; simd::RAYS],
                t_max: [t_max; simd::RAYS],
                cone: if trial % 2 == 0 { simd::Cone::around(&cols) } else { None },
            };
            let active = 0b1011_0111;
            for isa in simd::available() {
                let ray = PackRay::new(&Ray::new(origin, Vec3::from(dirs[0])), 0.0, t_max);
                let mut got = vec![0; len];
                DiscPack::masks_at(&packs, &at, &ray, isa, &mut got);
                let (mut out, mut any) = (vec![[0; simd::RAYS]; len], vec![0; len]);
                DiscPack::masks_rays_at(&packs, &at, &rays, active, isa, &mut out, &mut any);
                for (j, &p) in at.iter().enumerate() {
                    let one = std::slice::from_ref(&packs[p as usize]);
                    let mut m = [0];
                    DiscPack::masks(one, &ray, isa, &mut m);
                    assert_eq!(got[j], m[0], "{isa:?}, list {trial}, entry {j}");
                    let (mut o, mut a) = ([[0; simd::RAYS]], [0]);
                    DiscPack::masks_rays(one, &rays, active, isa, &mut o, &mut a);
                    assert_eq!((out[j], any[j]), (o[0], a[0]), "{isa:?}, list {trial}, entry {j}");
                    set += usize::from(m[0] != 0) + usize::from(a[0] != 0);
                }
            }
        }
        assert!(set > 500, "the rays should pass lanes often: {set}");
    }

    #[test]
    fn pack_from_fn_is_lane_by_lane_set() {
        let discs = [
            disc(Vec3::new(1.0, 2.0, 3.0), Vec3::new(0.3, -0.5, 0.8), 0.25),
            disc(Vec3::new(-4.0, 0.5, 1e3), Vec3::Y, 2.0),
        ];
        let lanes = |l: usize| match l {
            0 | 7 => Some(discs[0]),
            2 | 5 => Some(discs[1]),
            _ => None,
        };
        let mut by_set = DiscPack::EMPTY;
        for l in 0..LANES {
            if let Some(d) = lanes(l) {
                by_set.set(l, &d);
            }
        }
        let by_fn = DiscPack::from_fn(lanes);
        for l in 0..LANES {
            let (a, b) = (by_set.get(l, 0, &()), by_fn.get(l, 0, &()));
            for (x, y) in [
                (a.center, b.center),
                (a.normal, b.normal),
                (a.u_scaled, b.u_scaled),
                (a.v_scaled, b.v_scaled),
            ] {
                assert_eq!(
                    x.to_array().map(f32::to_bits),
                    y.to_array().map(f32::to_bits)
                );
            }
        }
    }

    #[test]
    fn exact_overlap_known_cases() {
        let d = disc(Vec3::ZERO, Vec3::Z, 1.0);
        // The box corner region near (0.8, 0.8): the disc rim passes at
        // 1/sqrt(2) ≈ 0.707 on the diagonal, so a box from 0.72 misses.
        assert!(!d.meets_box(Vec3::new(0.72, 0.72, -1.0), Vec3::new(2.0, 2.0, 1.0)));
        assert!(d.meets_box(Vec3::new(0.70, 0.70, -1.0), Vec3::new(2.0, 2.0, 1.0)));
        // Off the plane: misses however close in x, y.
        assert!(!d.meets_box(Vec3::new(-1.0, -1.0, 0.01), Vec3::new(1.0, 1.0, 1.0)));
        // Touching the plane with a face: meets.
        assert!(d.meets_box(Vec3::new(-0.1, -0.1, 0.0), Vec3::new(0.1, 0.1, 1.0)));
        // Box strictly inside the disc's slab but beside it along x.
        assert!(!d.meets_box(Vec3::new(1.01, -0.1, -0.1), Vec3::new(2.0, 0.1, 0.1)));
        assert!(d.meets_box(Vec3::new(0.99, -0.1, -0.1), Vec3::new(2.0, 0.1, 0.1)));
    }

    #[test]
    fn exact_overlap_agrees_with_dense_sampling() {
        // Any sampled disc point inside the box forces `true`; a `true`
        // without a sampled point must be a near miss of the sampling.
        let mut rng = SplitMix64::new(0x1234_5678_9abc_def0);
        let mut rnd = || rng.next_f32();
        for case in 0..400 {
            let n = Vec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5);
            let s = Splat {
                radii: glam::Vec2::new(0.3 + rnd() * 0.5, 0.1 + rnd() * 0.3),
                ..Splat::disc(Vec3::ZERO, n, 1.0).unwrap()
            };
            let d = s.disc_geometry();
            let lo = Vec3::new(rnd() - 0.9, rnd() - 0.9, rnd() - 0.9);
            let hi = lo + Vec3::new(rnd(), rnd(), rnd()) * 0.6 + Vec3::splat(0.01);
            let exact = d.meets_box(lo, hi);
            let mut sampled = false;
            let mut near = false;
            for i in 0..64 {
                for j in 0..64 {
                    let a = i as f32 / 63.0 * 2.0 - 1.0;
                    let b = j as f32 / 63.0 * 2.0 - 1.0;
                    if a * a + b * b > 1.0 {
                        continue;
                    }
                    let p = s.center + s.u_axis * (a * s.radii.x) + s.v_axis * (b * s.radii.y);
                    let e = Vec3::splat(0.02);
                    sampled |= p.cmpge(lo).all() && p.cmple(hi).all();
                    near |= p.cmpge(lo - e).all() && p.cmple(hi + e).all();
                }
            }
            assert!(
                !sampled || exact,
                "case {case}: a disc point lies in the box but the exact test says no: {s:?} {lo} {hi}"
            );
            assert!(
                !exact || near,
                "case {case}: exact test says yes but no disc point is near the box: {s:?} {lo} {hi}"
            );
        }
    }

    #[test]
    fn bounds_contain_the_rim() {
        let mut rng = SplitMix64::new(7);
        for _ in 0..200 {
            let s = Splat {
                radii: glam::Vec2::new(rng.range(0.1, 2.0), rng.range(0.1, 2.0)),
                ..Splat::disc(rng.unit() * 3.0, rng.unit(), 1.0).unwrap()
            };
            let d = s.disc_geometry();
            let (h, sq) = (d.half_extent(), d.coarse_half_extent());
            assert!(
                h.cmple(sq * (1.0 + 1e-6)).all(),
                "tight {h} within square {sq}"
            );
            // The ball: the greater radius, within the box's ball.
            let r = d.bounding_radius();
            let major = s.radii.x.max(s.radii.y);
            assert!((r - major).abs() <= 1e-5 * major, "radius {r} for radii {}", s.radii);
            assert!(r <= h.length(), "radius {r} beyond the box's ball {}", h.length());
            for k in 0..64 {
                let phi = k as f32 * std::f32::consts::TAU / 64.0;
                let p = s.u_axis * (s.radii.x * phi.cos()) + s.v_axis * (s.radii.y * phi.sin());
                assert!(
                    p.abs().cmple(h * (1.0 + 1e-5) + 1e-6).all(),
                    "{p} outside {h}"
                );
                assert!(p.length() <= r * (1.0 + 1e-5), "{p} beyond {r}");
            }
        }
    }
}
