//! The triangle filter of an octree leaf (issue 57): eight triangles at a
//! time, the first half of the watertight ray–triangle test of Woop,
//! Benthin and Wald (2013) done lane by lane with the IEEE operations of
//! [`crate::primitive::Triangle`]'s exact test, in the same order, with no
//! fused multiply-add; on the portable path (two 4-lane halves), on AVX2
//! (one pack per 256-bit register) and on AVX-512 (two packs per 512-bit
//! register), every path passing the same lanes.
//!
//! A lane is passed when its three sheared edge functions `U, V, W` (eq. 1
//! of that paper's section 3) have one strict sign and the plane parameter
//! `t = T / det` lies in the ray's span, exactly where the exact test's
//! single-precision path accepts; and whenever one of `U, V, W` is too
//! small for its single-precision sign to be sure (`|a - b| <= SURE
//! (|a| + |b|) + f32::MIN_POSITIVE` of its two products), where the exact
//! test decides the signs in double precision and breaks ties (it may
//! accept there). So the filter never drops a lane the exact test hits,
//! and padding lanes (NaN vertices) are never passed.

/// The relative bound below which an edge function's single-precision
/// sign is not sure: `2^-21` (`crate::primitive::Triangle`'s `SURE`).
pub const SURE: f32 = 1.0 / 2_097_152.0;

/// Triangles per pack (a 256-bit register of `f32`).
pub const TRI_LANES: usize = 8;

/// Eight triangles stored column by column: vertex `i`'s axis `a` in
/// column `3 i + a`. Padding lanes hold NaN (never passed).
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(32))]
pub struct TriColumns {
    /// Columns `3 i + a`: vertex `i` (0..3), axis `a` (x, y, z).
    pub cols: [[f32; TRI_LANES]; 9],
}

impl TriColumns {
    /// Every lane padding.
    pub const EMPTY: TriColumns = TriColumns {
        cols: [[f32::NAN; TRI_LANES]; 9],
    };
}

/// The per-ray constants of the watertight test (Woop et al. 2013, section
/// 3): the axis the ray's direction is longest along (`kz`), the other two
/// (`kx`, `ky`, swapped when `d[kz] < 0` to keep the winding), and the
/// shear that maps the ray onto `+z`: `sx = d[kx] / d[kz]`,
/// `sy = d[ky] / d[kz]`, `sz = 1 / d[kz]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shear {
    /// Permuted axes `kx, ky, kz`.
    pub k: [usize; 3],
    /// `sx, sy, sz`.
    pub s: [f32; 3],
}

impl Shear {
    /// The shear of a ray along `dir`, or `None` when `dir` is zero or
    /// not finite (the ray meets nothing).
    #[inline]
    #[must_use]
    pub fn new(dir: [f32; 3]) -> Option<Shear> {
        if !dir.iter().all(|d| d.is_finite()) {
            return None;
        }
        let a = dir.map(f32::abs);
        let kz = if a[0] > a[1] {
            if a[0] > a[2] { 0 } else { 2 }
        } else if a[1] > a[2] {
            1
        } else {
            2
        };
        if dir[kz] == 0.0 {
            return None;
        }
        let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
        if dir[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        Some(Shear {
            k: [kx, ky, kz],
            s: [dir[kx] / dir[kz], dir[ky] / dir[kz], 1.0 / dir[kz]],
        })
    }
}

/// Bit `l` of `out[i]` set when lane `l` of `packs[i]` may be hit in
/// `[t_min, t_max]` by the ray (`origin`, `dir`), on the path `isa` (one
/// the CPU does not run is replaced by the portable one, which passes the
/// same lanes). `out` must be at least as long as `packs`.
#[inline]
pub fn tri_masks(
    packs: &[TriColumns],
    origin: [f32; 3],
    dir: [f32; 3],
    t_min: f32,
    t_max: f32,
    isa: super::Isa,
    out: &mut [u32],
) {
    tri_masks_sheared(packs, origin, Shear::new(dir).as_ref(), t_min, t_max, isa, out);
}

/// [`tri_masks`] with the ray's shear made beforehand (`Shear::new` of its
/// direction, `None` passing no lane), so a ray tested against many leaves
/// shears once.
#[inline]
pub fn tri_masks_sheared(
    packs: &[TriColumns],
    origin: [f32; 3],
    sh: Option<&Shear>,
    t_min: f32,
    t_max: f32,
    isa: super::Isa,
    out: &mut [u32],
) {
    let out = &mut out[..packs.len()];
    let Some(sh) = sh else {
        out.fill(0);
        return;
    };
    match isa {
        #[cfg(target_arch = "x86_64")]
        super::Isa::Avx2 if super::Isa::Avx2.supported() => {
            // SAFETY: the guard checked that the CPU runs AVX2.
            unsafe { x86::avx2_tri_masks(packs, origin, sh, t_min, t_max, out) }
        }
        #[cfg(target_arch = "x86_64")]
        super::Isa::Avx512 if super::Isa::Avx512.supported() => {
            // SAFETY: the guard checked that the CPU runs AVX-512 F.
            unsafe { x86::avx512_tri_masks(packs, origin, sh, t_min, t_max, out) }
        }
        _ => {
            for (p, m) in packs.iter().zip(out.iter_mut()) {
                *m = portable_tri_mask(p, origin, sh, t_min, t_max);
            }
        }
    }
}

/// The portable filter: the pack as two halves of four lanes (glam's
/// `Vec4`, SSE2 on x86-64).
#[inline]
fn portable_tri_mask(p: &TriColumns, o: [f32; 3], sh: &Shear, t_min: f32, t_max: f32) -> u32 {
    use glam::Vec4;
    let [kx, ky, kz] = sh.k;
    let [sx, sy, sz] = sh.s.map(Vec4::splat);
    let half = |h: usize| {
        let col = |i: usize, a: usize| {
            Vec4::from_slice(&p.cols[3 * i + a][4 * h..4 * h + 4]) - Vec4::splat(o[a])
        };
        // Vertex `i` relative to the origin, sheared: (x, y, z).
        let vert = |i: usize| {
            let (x, y, z) = (col(i, kx), col(i, ky), col(i, kz));
            (x - sx * z, y - sy * z, sz * z)
        };
        let (ax, ay, az) = vert(0);
        let (bx, by, bz) = vert(1);
        let (cx, cy, cz) = vert(2);
        let (p1, p2) = (cx * by, cy * bx);
        let (p3, p4) = (ax * cy, ay * cx);
        let (p5, p6) = (bx * ay, by * ax);
        let (u, v, w) = (p1 - p2, p3 - p4, p5 - p6);
        let unsure = |e: Vec4, a: Vec4, b: Vec4| {
            e.abs()
                .cmple((a.abs() + b.abs()) * Vec4::splat(SURE) + Vec4::splat(f32::MIN_POSITIVE))
        };
        let z = Vec4::ZERO;
        let zero = unsure(u, p1, p2) | unsure(v, p3, p4) | unsure(w, p5, p6);
        let pos = u.cmpgt(z) & v.cmpgt(z) & w.cmpgt(z);
        let neg = u.cmplt(z) & v.cmplt(z) & w.cmplt(z);
        let det = u + v + w;
        let tt = u * az + v * bz + w * cz;
        let t = tt / det;
        let ok = t.cmpge(Vec4::splat(t_min))
            & t.cmple(Vec4::splat(t_max))
            & t.abs().cmplt(Vec4::INFINITY);
        (zero | ((pos | neg) & ok)).bitmask()
    };
    half(0) | half(1) << 4
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::super::x86::avx2_in_range;
    use super::{Shear, TriColumns};
    use std::arch::x86_64::*;

    /// Vertex `i` of the pack relative to the origin `org`, sheared by
    /// `(sx, sy, sz)` along the axes `k`: `(x - sx z, y - sy z, sz z)`.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn avx2_vert(
        p: &TriColumns,
        i: usize,
        k: [usize; 3],
        org: &[__m256; 3],
        s: &[__m256; 3],
    ) -> [__m256; 3] {
        // SAFETY: `cols[k]` is 8 f32 at a 32-byte aligned address
        // (`TriColumns` is 32-byte aligned, each column 32 bytes).
        let col = |a: usize| _mm256_sub_ps(unsafe { _mm256_load_ps(p.cols[3 * i + a].as_ptr()) }, org[a]);
        let (x, y, z) = (col(k[0]), col(k[1]), col(k[2]));
        [
            _mm256_sub_ps(x, _mm256_mul_ps(s[0], z)),
            _mm256_sub_ps(y, _mm256_mul_ps(s[1], z)),
            _mm256_mul_ps(s[2], z),
        ]
    }

    /// The edge function `a b - c d` and the lanes where its sign is not
    /// sure (all ones).
    #[inline]
    #[target_feature(enable = "avx2")]
    fn avx2_edge(a: __m256, b: __m256, c: __m256, d: __m256) -> (__m256, __m256) {
        let sign = _mm256_set1_ps(-0.0);
        let abs = |x| _mm256_andnot_ps(sign, x);
        let (p, q) = (_mm256_mul_ps(a, b), _mm256_mul_ps(c, d));
        let e = _mm256_sub_ps(p, q);
        let bound = _mm256_add_ps(
            _mm256_mul_ps(_mm256_add_ps(abs(p), abs(q)), _mm256_set1_ps(super::SURE)),
            _mm256_set1_ps(f32::MIN_POSITIVE),
        );
        (e, _mm256_cmp_ps::<_CMP_LE_OQ>(abs(e), bound))
    }

    /// [`super::tri_masks`] with one pack per 256-bit register. A pack
    /// with no lane inside its three edges (nor unsure) is done before
    /// its plane parameter's division.
    ///
    /// # Safety
    /// The CPU must run AVX2.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn avx2_tri_masks(
        packs: &[TriColumns],
        o: [f32; 3],
        sh: &Shear,
        t_min: f32,
        t_max: f32,
        out: &mut [u32],
    ) {
        let s = sh.s.map(|x| _mm256_set1_ps(x));
        let org = o.map(|x| _mm256_set1_ps(x));
        let (tmin, tmax) = (_mm256_set1_ps(t_min), _mm256_set1_ps(t_max));
        for (p, m) in packs.iter().zip(out.iter_mut()) {
            let [ax, ay, az] = avx2_vert(p, 0, sh.k, &org, &s);
            let [bx, by, bz] = avx2_vert(p, 1, sh.k, &org, &s);
            let [cx, cy, cz] = avx2_vert(p, 2, sh.k, &org, &s);
            let (u, uu) = avx2_edge(cx, by, cy, bx);
            let (v, uv) = avx2_edge(ax, cy, ay, cx);
            let (w, uw) = avx2_edge(bx, ay, by, ax);
            let on_edge = _mm256_movemask_ps(_mm256_or_ps(_mm256_or_ps(uu, uv), uw)) as u32;
            // Sided: one sign bit for the three and none NaN. This takes
            // a zero's sign bit for a sign, unlike the other paths' strict
            // comparisons; but a zero is never sure (`on_edge` passes it
            // anyway): the same masks.
            let mixed = _mm256_or_ps(_mm256_xor_ps(u, v), _mm256_xor_ps(u, w));
            let nan = _mm256_or_ps(
                _mm256_cmp_ps::<_CMP_UNORD_Q>(u, v),
                _mm256_cmp_ps::<_CMP_UNORD_Q>(w, w),
            );
            let sided = !(_mm256_movemask_ps(_mm256_or_ps(mixed, nan)) as u32) & 0xff;
            if sided & !on_edge == 0 {
                *m = on_edge;
                continue;
            }
            let det = _mm256_add_ps(_mm256_add_ps(u, v), w);
            let tt = _mm256_add_ps(
                _mm256_add_ps(_mm256_mul_ps(u, az), _mm256_mul_ps(v, bz)),
                _mm256_mul_ps(w, cz),
            );
            let t = _mm256_div_ps(tt, det);
            let ok = _mm256_movemask_ps(avx2_in_range(t, tmin, tmax)) as u32;
            *m = on_edge | (sided & ok);
        }
    }

    /// [`super::tri_masks`] with two packs per 512-bit register (the last
    /// pack of an odd count alone, its upper half NaN padding).
    ///
    /// # Safety
    /// The CPU must run AVX-512 F.
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn avx512_tri_masks(
        packs: &[TriColumns],
        o: [f32; 3],
        sh: &Shear,
        t_min: f32,
        t_max: f32,
        out: &mut [u32],
    ) {
        let [kx, ky, kz] = sh.k;
        let [sx, sy, sz] = sh.s.map(|x| _mm512_set1_ps(x));
        let org = o.map(|x| _mm512_set1_ps(x));
        let (tmin, tmax) = (_mm512_set1_ps(t_min), _mm512_set1_ps(t_max));
        let inf = _mm512_set1_ps(f32::INFINITY);
        let zero = _mm512_setzero_ps();
        let sure = _mm512_set1_ps(super::SURE);
        let tiny = _mm512_set1_ps(f32::MIN_POSITIVE);
        let mut i = 0;
        while i < packs.len() {
            let a = &packs[i];
            let b = packs.get(i + 1);
            let col = |v: usize, ax: usize| {
                let k = 3 * v + ax;
                // SAFETY: `cols[k]` is 8 f32 at a 32-byte aligned address
                // (`TriColumns` is 32-byte aligned, each column 32 bytes).
                let lo = unsafe { _mm256_load_ps(a.cols[k].as_ptr()) };
                let hi = match b {
                    // SAFETY: as above.
                    Some(b) => unsafe { _mm256_load_ps(b.cols[k].as_ptr()) },
                    None => _mm256_set1_ps(f32::NAN),
                };
                let both = _mm512_castpd_ps(_mm512_insertf64x4::<1>(
                    _mm512_castpd256_pd512(_mm256_castps_pd(lo)),
                    _mm256_castps_pd(hi),
                ));
                _mm512_sub_ps(both, org[ax])
            };
            let vert = |v: usize| {
                let (x, y, z) = (col(v, kx), col(v, ky), col(v, kz));
                (
                    _mm512_sub_ps(x, _mm512_mul_ps(sx, z)),
                    _mm512_sub_ps(y, _mm512_mul_ps(sy, z)),
                    _mm512_mul_ps(sz, z),
                )
            };
            let (ax, ay, az) = vert(0);
            let (bx, by, bz) = vert(1);
            let (cx, cy, cz) = vert(2);
            let edge = |a: __m512, b: __m512, c: __m512, d: __m512| {
                let (p, q) = (_mm512_mul_ps(a, b), _mm512_mul_ps(c, d));
                let e = _mm512_sub_ps(p, q);
                let sum = _mm512_add_ps(_mm512_abs_ps(p), _mm512_abs_ps(q));
                let bound = _mm512_add_ps(_mm512_mul_ps(sum, sure), tiny);
                (e, _mm512_cmp_ps_mask::<_CMP_LE_OQ>(_mm512_abs_ps(e), bound))
            };
            let (u, uu) = edge(cx, by, cy, bx);
            let (v, uv) = edge(ax, cy, ay, cx);
            let (w, uw) = edge(bx, ay, by, ax);
            let gt = |x| _mm512_cmp_ps_mask::<_CMP_GT_OQ>(x, zero);
            let lt = |x| _mm512_cmp_ps_mask::<_CMP_LT_OQ>(x, zero);
            let on_edge = uu | uv | uw;
            let sided = (gt(u) & gt(v) & gt(w)) | (lt(u) & lt(v) & lt(w));
            let det = _mm512_add_ps(_mm512_add_ps(u, v), w);
            let tt = _mm512_add_ps(
                _mm512_add_ps(_mm512_mul_ps(u, az), _mm512_mul_ps(v, bz)),
                _mm512_mul_ps(w, cz),
            );
            let t = _mm512_div_ps(tt, det);
            let ok = _mm512_cmp_ps_mask::<_CMP_GE_OQ>(t, tmin)
                & _mm512_cmp_ps_mask::<_CMP_LE_OQ>(t, tmax)
                & _mm512_cmp_ps_mask::<_CMP_LT_OQ>(_mm512_abs_ps(t), inf);
            let mask = on_edge | (sided & ok);
            out[i] = u32::from(mask & 0xff);
            if b.is_some() {
                out[i + 1] = u32::from(mask >> 8);
            }
            i += 2;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use crate::simd::{Isa, available};

    /// Packs of random triangles (some lanes padding, some degenerate,
    /// NaN and infinite vertices, some sharing vertices exactly) against
    /// random rays (some with zero components): every path this CPU runs
    /// gives the portable path's masks.
    #[test]
    fn every_path_gives_the_portable_triangle_masks() {
        let mut rng = SplitMix64::new(57);
        let mut f = |s: f32| (rng.next_f64() as f32 * 2.0 - 1.0) * s;
        let mut packs = Vec::new();
        for p in 0..37 {
            let mut pack = TriColumns::EMPTY;
            for l in 0..TRI_LANES {
                if (p + l) % 7 == 3 {
                    continue; // padding
                }
                let c = [f(2.0), f(2.0), f(2.0)];
                for (k, col) in pack.cols.iter_mut().enumerate() {
                    col[l] = c[k % 3] + f(0.8);
                }
                match (p * 5 + l) % 23 {
                    0 => pack.cols[4][l] = f32::NAN,
                    1 => pack.cols[7][l] = f32::INFINITY,
                    2 => {
                        // Degenerate: vertex 2 on vertex 0.
                        for a in 0..3 {
                            pack.cols[6 + a][l] = pack.cols[a][l];
                        }
                    }
                    3 if l > 0 => {
                        // Shares vertices 0 and 1 with the lane before.
                        for a in 0..3 {
                            pack.cols[a][l] = pack.cols[3 + a][l - 1];
                            pack.cols[3 + a][l] = pack.cols[a][l - 1];
                        }
                    }
                    _ => {}
                }
            }
            packs.push(pack);
        }
        let mut total = 0;
        for r in 0..400 {
            let origin = [f(3.0), f(3.0), f(3.0)];
            let mut dir = [f(1.0), f(1.0), f(1.0)];
            if r % 17 == 0 {
                dir[r % 3] = 0.0;
            }
            if r % 53 == 0 {
                dir[1] = f32::NAN;
            }
            let (t_min, t_max) = if r % 3 == 0 {
                (0.0, f32::INFINITY)
            } else {
                (0.1, 2.5)
            };
            for n in [1, 2, 5, packs.len()] {
                let mut want = vec![0; n];
                tri_masks(
                    &packs[..n],
                    origin,
                    dir,
                    t_min,
                    t_max,
                    Isa::Portable,
                    &mut want,
                );
                total += want.iter().map(|m| m.count_ones()).sum::<u32>();
                for isa in available() {
                    let mut got = vec![u32::MAX; n];
                    tri_masks(&packs[..n], origin, dir, t_min, t_max, isa, &mut got);
                    assert_eq!(got, want, "{isa}, ray {r}, {n} packs");
                }
            }
        }
        assert!(
            total > 500,
            "the rays pass too few lanes to test much: {total}"
        );
    }
}
