//! The planes through a point and two later points, eight pairs at a time:
//! the triples of the face search's planes (`crate::splat::normals`, its
//! `triple_planes`), one first point's planes a call.
//!
//! Every path takes, for each triple, the operations of the portable loop
//! in its order (glam's `cross`, `length_squared` and `normalize` written
//! out: `c = u × v`, `|c|² = (c_x c_x + c_y c_y) + c_z c_z`, the test
//! `|c|² < (0.04 |u|²) |v|²`, then `c · (1 / √|c|²)`; no fused
//! multiply-add, and square root and division are correctly rounded per
//! lane), so every path keeps the same triples and gives the same normals
//! bit for bit, in the same order.

use super::Isa;

/// The unit normals of the planes through the origin and two of the
/// offsets `(xs[j], ys[j], zs[j])`, `j < m` (a first point's offsets to the
/// points after it), pushed to `out` in the order of the pairs `(b, c)`,
/// `b < c` (by `b`, then by `c`): for each pair `u` the offset `b` and `v`
/// the offset `c`, `u × v` normalised, except where `|u × v|² < 0.04 |u|²
/// |v|²` (the two nearly in line with the origin; not a number is kept).
/// On the path `isa` (AVX-512 takes the AVX2 kernel; a path the CPU does
/// not run is replaced by the portable loop, which gives the same). The
/// slices must each be at least `m` long; the kernels may read (never
/// keep) the floats past `m` up to each slice's end.
#[inline]
pub fn triple_normals(xs: &[f32], ys: &[f32], zs: &[f32], m: usize, isa: Isa, out: &mut Vec<[f32; 3]>) {
    assert!(xs.len().min(ys.len()).min(zs.len()) >= m, "fewer than {m} offsets");
    match isa {
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2 | Isa::Avx512 if Isa::Avx2.supported() => {
            // SAFETY: the guard checked that the CPU runs AVX2.
            unsafe { avx2_triples(xs, ys, zs, m, out) }
        }
        _ => portable_triples(xs, ys, zs, m, out),
    }
}

/// The portable loop of [`triple_normals`]: glam's vector operations, one
/// triple at a time.
fn portable_triples(xs: &[f32], ys: &[f32], zs: &[f32], m: usize, out: &mut Vec<[f32; 3]>) {
    use glam::Vec3;
    let at = |j: usize| Vec3::new(xs[j], ys[j], zs[j]);
    for b in 0..m {
        let u = at(b);
        for c in b + 1..m {
            let v = at(c);
            let n = u.cross(v);
            // Triples nearly in line fix no plane.
            if n.length_squared() < 0.04 * u.length_squared() * v.length_squared() {
                continue;
            }
            out.push(n.normalize().to_array());
        }
    }
}

/// [`triple_normals`] on AVX2 where each slice holds 7 floats past `m`
/// (a step's last lanes read in place), else on the offsets copied into
/// zero-padded room of [`PADDED`] floats (up to `PADDED - 7` offsets; more
/// take the portable loop).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn avx2_triples(xs: &[f32], ys: &[f32], zs: &[f32], m: usize, out: &mut Vec<[f32; 3]>) {
    if xs.len().min(ys.len()).min(zs.len()) >= m + 7 {
        // SAFETY: each slice holds `m + 7` floats.
        unsafe { avx2_pairs([xs.as_ptr(), ys.as_ptr(), zs.as_ptr()], m, out) }
    } else if m + 7 <= PADDED {
        let mut room = [[0f32; PADDED]; 3];
        for (r, s) in room.iter_mut().zip([xs, ys, zs]) {
            r[..m].copy_from_slice(&s[..m]);
        }
        let [x, y, z] = &room;
        // SAFETY: each row holds `PADDED >= m + 7` floats.
        unsafe { avx2_pairs([x.as_ptr(), y.as_ptr(), z.as_ptr()], m, out) }
    } else {
        portable_triples(xs, ys, zs, m, out);
    }
}

/// Room for [`avx2_triples`]' copied offsets.
const PADDED: usize = 32;

/// [`triple_normals`] on AVX2 over the offsets at `d` (x, y and z): for
/// each `b`, the pairs `(b, c)` eight `c` at a time (the last step's lanes
/// past `m` computed, not kept), the kept lanes written in order. The
/// portable loop's operations lane by lane.
///
/// # Safety
/// Each of the three pointers reads `m + 7` floats.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn avx2_pairs(d: [*const f32; 3], m: usize, out: &mut Vec<[f32; 3]>) {
    use std::arch::x86_64::*;
    let one = _mm256_set1_ps(1.0);
    for b in 0..m {
        // SAFETY: `b < m`, within the caller's bound.
        let [ux, uy, uz] = d.map(|p| unsafe { *p.add(b) });
        // `0.04 * u.length_squared()`, the bound's first product.
        let bound = 0.04 * ((ux * ux) + (uy * uy) + (uz * uz));
        let (bx, by, bz, bb) = (
            _mm256_set1_ps(ux),
            _mm256_set1_ps(uy),
            _mm256_set1_ps(uz),
            _mm256_set1_ps(bound),
        );
        let mut c = b + 1;
        while c < m {
            // SAFETY: `c + 8 <= m + 7`, within the caller's bound.
            let [vx, vy, vz] = d.map(|p| unsafe { _mm256_loadu_ps(p.add(c)) });
            // `u.cross(v)`.
            let nx = _mm256_sub_ps(_mm256_mul_ps(by, vz), _mm256_mul_ps(vy, bz));
            let ny = _mm256_sub_ps(_mm256_mul_ps(bz, vx), _mm256_mul_ps(vz, bx));
            let nz = _mm256_sub_ps(_mm256_mul_ps(bx, vy), _mm256_mul_ps(vx, by));
            // glam's `length_squared`: `(x x + y y) + z z`.
            let nn = super::x86::avx2_dot([nx, ny, nz], [nx, ny, nz]);
            let vv = super::x86::avx2_dot([vx, vy, vz], [vx, vy, vz]);
            // Kept unless `nn < bound * vv` (not a number: kept).
            let keep = _mm256_cmp_ps::<_CMP_NLT_UQ>(nn, _mm256_mul_ps(bb, vv));
            let r = _mm256_div_ps(one, _mm256_sqrt_ps(nn));
            let valid = (m - c).min(8);
            let bits = _mm256_movemask_ps(keep) as u32 & ((1u32 << valid) - 1);
            let n = [_mm256_mul_ps(nx, r), _mm256_mul_ps(ny, r), _mm256_mul_ps(nz, r)];
            // Room for eight 16-byte stores from the end on.
            out.reserve(9);
            let len = out.len();
            // SAFETY: the capacity holds `len + 9` normals, and the stores
            // reach at most 16 bytes past the `len + 7`th's start.
            unsafe {
                let kept = store_kept(out.as_mut_ptr().add(len).cast(), n, bits, valid);
                out.set_len(len + kept);
            }
            c += 8;
        }
    }
}

/// The lanes of `n` (x, y and z) whose bit is set in `bits`, written in
/// order from `p` as three floats each (each lane's store writes four at
/// the end of those kept so far, its fourth overwritten by the next; a lane
/// not kept is overwritten by the next too); the lanes past the first
/// four are stored only where `valid` (the lanes that may be kept) exceeds
/// four. Returns how many were kept.
///
/// # Safety
/// `p` writes 25 floats.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn store_kept(p: *mut f32, n: [std::arch::x86_64::__m256; 3], bits: u32, valid: usize) -> usize {
    use std::arch::x86_64::*;
    let [x, y, z] = n;
    // Lane `l`'s `(x, y, z, z)` in the 128-bit half `l / 4` of `l % 4`'s.
    let (xy_lo, xy_hi) = (_mm256_unpacklo_ps(x, y), _mm256_unpackhi_ps(x, y));
    let (zz_lo, zz_hi) = (_mm256_unpacklo_ps(z, z), _mm256_unpackhi_ps(z, z));
    let four = [
        _mm256_shuffle_ps::<0x44>(xy_lo, zz_lo),
        _mm256_shuffle_ps::<0xEE>(xy_lo, zz_lo),
        _mm256_shuffle_ps::<0x44>(xy_hi, zz_hi),
        _mm256_shuffle_ps::<0xEE>(xy_hi, zz_hi),
    ];
    let mut k = 0;
    for (l, v) in four.iter().enumerate() {
        // SAFETY: `k <= l < 4`, so the store ends by float `3 l + 4`,
        // within the caller's bound.
        unsafe { _mm_storeu_ps(p.add(3 * k), _mm256_castps256_ps128(*v)) };
        k += ((bits >> l) & 1) as usize;
    }
    if valid > 4 {
        for (l, v) in four.iter().enumerate() {
            // SAFETY: as above, `k <= l + 4 < 8`.
            unsafe { _mm_storeu_ps(p.add(3 * k), _mm256_extractf128_ps::<1>(*v)) };
            k += ((bits >> (l + 4)) & 1) as usize;
        }
    }
    k
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// The normals' bits, for comparisons that tell NaN and signed zeros
    /// apart.
    fn bits(normals: &[[f32; 3]]) -> Vec<[u32; 3]> {
        normals.iter().map(|n| n.map(f32::to_bits)).collect()
    }

    /// Sets of 0 to 14 offsets (random, repeated points, points in line
    /// with the origin and with each other, zeros, offsets far from the
    /// origin whose products overflow, exact ties of the in-line bound),
    /// read from slices exactly as long and with readable floats past `m`:
    /// every path this CPU runs pushes the portable loop's normals, bit
    /// for bit, in its order.
    #[test]
    fn every_path_gives_the_portable_loops_normals() {
        let mut rng = SplitMix64::new(32);
        let mut f = |s: f32| (rng.next_f64() as f32 * 2.0 - 1.0) * s;
        let (mut pushed, mut skipped, mut nan) = (0, 0, 0);
        for set in 0..3000 {
            let m = set % 15;
            let scale = [1.0, 1e-3, 3e3, 1e18, 2e19][set % 5];
            let shift = if set % 7 == 3 { 1e6 } else { 0.0 };
            let mut d = [vec![0f32; m + 9], vec![0f32; m + 9], vec![0f32; m + 9]];
            for j in 0..m + 9 {
                let p = [f(scale) + shift, f(scale), f(scale) - shift];
                let kind = (j * 5 + set) % 11;
                for (a, col) in d.iter_mut().enumerate() {
                    col[j] = match kind {
                        // A repeated point.
                        0 if j > 0 => col[j - 1],
                        // In line with the origin and the point before.
                        1 if j > 0 => col[j - 1] * 3.0,
                        // The origin itself.
                        2 => 0.0,
                        // On the axes: exact products and ties.
                        3 => [1.0, 0.0, 0.0][a] * scale,
                        4 => [0.0, 1.0, 0.0][a] * scale,
                        _ => p[a],
                    };
                }
            }
            let mut want = Vec::new();
            portable_triples(&d[0][..m], &d[1][..m], &d[2][..m], m, &mut want);
            skipped += m * m.saturating_sub(1) / 2 - want.len();
            pushed += want.len();
            nan += want.iter().filter(|n| n.iter().any(|x| x.is_nan())).count();
            for isa in super::super::available() {
                for len in [m, m + 9] {
                    let mut got = vec![[9.0; 3]];
                    triple_normals(&d[0][..len], &d[1][..len], &d[2][..len], m, isa, &mut got);
                    assert_eq!(bits(&got[1..]), bits(&want), "{isa} at set {set}, {m} offsets, {len} long");
                }
            }
        }
        // Measured: 84,803 pushed, 6,197 skipped, 24,252 NaN.
        assert!(pushed > 80_000 && skipped > 5_500 && nan > 22_000, "{pushed} pushed, {skipped} skipped, {nan} NaN");
    }
}
