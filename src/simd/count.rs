//! How many points lie within a tolerance of a plane, eight at a time: the
//! count of the face search's planes through three points
//! (`crate::splat::normals`, the triples of its face planes), whose
//! loop over a point's neighbourhood is most of that search.
//!
//! Every path takes, for each point, the operations of the portable loop in
//! its order, `h = (n_x d_x + n_y d_y) + n_z d_z` and `|h| <= tol` (no fused
//! multiply-add; NaN is not within), so every path counts the same points.

use super::Isa;

/// For each of `normals`, into `out` (as long), how many of the offsets
/// `(dx[i], dy[i], dz[i])` have a height `(n_x d_x + n_y d_y) + n_z d_z` of
/// at most `tol` in magnitude along it, on the path `isa` (AVX-512 takes
/// the AVX2 kernel; a path the CPU does not run is replaced by the
/// portable loop, which counts the same). The three slices must be equally
/// long; a multiple of eight is counted eight at a time throughout (pad
/// with NaN, which no path counts).
#[inline]
pub fn count_within(
    dx: &[f32],
    dy: &[f32],
    dz: &[f32],
    normals: &[[f32; 3]],
    tol: f32,
    isa: Isa,
    out: &mut [u32],
) {
    let n = dx.len();
    let (dy, dz) = (&dy[..n], &dz[..n]);
    let out = &mut out[..normals.len()];
    match isa {
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2 | Isa::Avx512 if Isa::Avx2.supported() => {
            // SAFETY: the guard checked that the CPU runs AVX2.
            unsafe { avx2_count(dx, dy, dz, normals, tol, out) }
        }
        _ => {
            for (o, &normal) in out.iter_mut().zip(normals) {
                *o = portable_count(dx, dy, dz, normal, tol);
            }
        }
    }
}

/// The portable loop of [`count_within`] for one normal.
#[inline]
fn portable_count(dx: &[f32], dy: &[f32], dz: &[f32], normal: [f32; 3], tol: f32) -> u32 {
    let [nx, ny, nz] = normal;
    dx.iter()
        .zip(dy)
        .zip(dz)
        .map(|((x, y), z)| {
            let h = (nx * x) + (ny * y) + (nz * z);
            u32::from(h.abs() <= tol)
        })
        .sum::<u32>()
}

/// [`count_within`] on AVX2: eight offsets a step, four normals at once
/// (each eight offsets loaded once for the four), each lane's verdict
/// added into a lane count (a lane within is all ones, −1, subtracted),
/// the eight lane counts summed at the end; the rest (past the last
/// multiple of eight) by the portable loop. The same heights and tests as
/// the portable loop, lane by lane, so the same counts.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn avx2_count(dx: &[f32], dy: &[f32], dz: &[f32], normals: &[[f32; 3]], tol: f32, out: &mut [u32]) {
    let n = dx.len();
    let wide = n - n % 8;
    for (o, group) in out.chunks_mut(4).zip(normals.chunks(4)) {
        // A short last group padded with its first normal (its counts
        // not kept).
        let mut four = [group[0]; 4];
        four[..group.len()].copy_from_slice(group);
        // SAFETY: `wide <= n`, and `dy` and `dz` are `n` long
        // (`count_within` cut them).
        let counts = unsafe { avx2_count4(dx, dy, dz, wide, four, tol) };
        for (k, (o, &normal)) in o.iter_mut().zip(group).enumerate() {
            *o = counts[k];
            if wide < n {
                *o += portable_count(&dx[wide..], &dy[wide..], &dz[wide..], normal, tol);
            }
        }
    }
}

/// [`avx2_count`]'s counts of four normals over the first `wide` (a
/// multiple of eight) offsets.
///
/// # Safety
/// `wide` is a multiple of eight and at most the length of each of `dx`,
/// `dy` and `dz`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn avx2_count4(dx: &[f32], dy: &[f32], dz: &[f32], wide: usize, four: [[f32; 3]; 4], tol: f32) -> [u32; 4] {
    use std::arch::x86_64::*;
    let tol8 = _mm256_set1_ps(tol);
    let planes = [splat3(four[0]), splat3(four[1]), splat3(four[2]), splat3(four[3])];
    let mut acc = [_mm256_setzero_si256(); 4];
    let mut i = 0;
    while i < wide {
        // SAFETY: `i + 8 <= wide`, at most each slice's length (the
        // caller's bound).
        let [x, y, z] = unsafe { load8(dx, dy, dz, i) };
        for (a, [nx, ny, nz]) in acc.iter_mut().zip(&planes) {
            let h = _mm256_add_ps(
                _mm256_add_ps(_mm256_mul_ps(*nx, x), _mm256_mul_ps(*ny, y)),
                _mm256_mul_ps(*nz, z),
            );
            *a = _mm256_sub_epi32(*a, _mm256_castps_si256(within8_lanes(h, tol8)));
        }
        i += 8;
    }
    // The four lane counts summed: pairs, then pairs of pairs, then the
    // two halves.
    let ab = _mm256_hadd_epi32(acc[0], acc[1]);
    let cd = _mm256_hadd_epi32(acc[2], acc[3]);
    let abcd = _mm256_hadd_epi32(ab, cd);
    let sum = _mm_add_epi32(_mm256_castsi256_si128(abcd), _mm256_extracti128_si256::<1>(abcd));
    let mut counts = [0u32; 4];
    // SAFETY: `counts` is 16 bytes, the width of the store.
    unsafe { _mm_storeu_si128(counts.as_mut_ptr().cast(), sum) };
    counts
}

/// Which of the points `(xs[i], ys[i], zs[i])` lie within `tol` of the
/// plane through `origin` with normal `normal`, as bits (point `i` at bit
/// `i % 64` of `out[i / 64]`; the points past `64 · out.len()` are not
/// tested, and the words past the last point are zero), on the path `isa`
/// (as [`count_within`]'s). Every path takes, point by point, the height
/// `h = (n_x (x - o_x) + n_y (y - o_y)) + n_z (z - o_z)` and `|h| <= tol`
/// (no fused multiply-add; NaN is not within), so every path sets the same
/// bits. The three slices must be equally long.
#[inline]
#[allow(clippy::too_many_arguments)] // a plane, its points and the path
pub fn held_within(
    xs: &[f32],
    ys: &[f32],
    zs: &[f32],
    normal: [f32; 3],
    origin: [f32; 3],
    tol: f32,
    isa: Isa,
    out: &mut [u64],
) {
    let n = xs.len().min(64 * out.len());
    let (xs, ys, zs) = (&xs[..n], &ys[..n], &zs[..n]);
    match isa {
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2 | Isa::Avx512 if Isa::Avx2.supported() => {
            // SAFETY: the guard checked that the CPU runs AVX2.
            unsafe { avx2_held(xs, ys, zs, normal, origin, tol, out) }
        }
        _ => portable_held(xs, ys, zs, normal, origin, tol, out),
    }
}

/// The portable loop of [`held_within`], each word's points folded into
/// its bits without a branch.
fn portable_held(
    xs: &[f32],
    ys: &[f32],
    zs: &[f32],
    normal: [f32; 3],
    origin: [f32; 3],
    tol: f32,
    out: &mut [u64],
) {
    let ([nx, ny, nz], [ox, oy, oz]) = (normal, origin);
    out.fill(0);
    let chunks = xs.chunks(64).zip(ys.chunks(64)).zip(zs.chunks(64));
    for (word, ((xs, ys), zs)) in out.iter_mut().zip(chunks) {
        *word = xs
            .iter()
            .zip(ys)
            .zip(zs)
            .enumerate()
            .fold(0u64, |bits, (j, ((x, y), z))| {
                let h = (nx * (x - ox)) + (ny * (y - oy)) + (nz * (z - oz));
                bits | (u64::from(h.abs() <= tol) << j)
            });
    }
}

/// [`held_within`] on AVX2: eight points a step, the rest (past the last
/// multiple of eight) by the portable loop's test.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn avx2_held(
    xs: &[f32],
    ys: &[f32],
    zs: &[f32],
    normal: [f32; 3],
    origin: [f32; 3],
    tol: f32,
    out: &mut [u64],
) {
    use std::arch::x86_64::*;
    let n = xs.len();
    let (ys, zs) = (&ys[..n], &zs[..n]);
    let wide = n - n % 8;
    out.fill(0);
    let tol8 = _mm256_set1_ps(tol);
    let ([nx, ny, nz], [ox, oy, oz]) = (splat3(normal), splat3(origin));
    let mut i = 0;
    while i < wide {
        // SAFETY: `i + 8 <= wide <= n`, and `ys` and `zs` are `n` long (cut
        // above).
        let [x, y, z] = unsafe { load8(xs, ys, zs, i) };
        let h = _mm256_add_ps(
            _mm256_add_ps(
                _mm256_mul_ps(nx, _mm256_sub_ps(x, ox)),
                _mm256_mul_ps(ny, _mm256_sub_ps(y, oy)),
            ),
            _mm256_mul_ps(nz, _mm256_sub_ps(z, oz)),
        );
        out[i / 64] |= u64::from(within8(h, tol8)) << (i % 64);
        i += 8;
    }
    let ([nx, ny, nz], [ox, oy, oz]) = (normal, origin);
    for j in wide..n {
        let h = (nx * (xs[j] - ox)) + (ny * (ys[j] - oy)) + (nz * (zs[j] - oz));
        out[j / 64] |= u64::from(h.abs() <= tol) << (j % 64);
    }
}

/// Eight lanes of each of `v`'s three components.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn splat3(v: [f32; 3]) -> [std::arch::x86_64::__m256; 3] {
    use std::arch::x86_64::_mm256_set1_ps;
    [_mm256_set1_ps(v[0]), _mm256_set1_ps(v[1]), _mm256_set1_ps(v[2])]
}

/// The eight points from `i` on of the three coordinate slices, unaligned.
///
/// # Safety
/// `i + 8` is at most the length of each of `xs`, `ys` and `zs`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn load8(xs: &[f32], ys: &[f32], zs: &[f32], i: usize) -> [std::arch::x86_64::__m256; 3] {
    use std::arch::x86_64::_mm256_loadu_ps;
    // SAFETY: by the caller's bound each load reads eight floats inside its
    // slice.
    unsafe {
        [
            _mm256_loadu_ps(xs.as_ptr().add(i)),
            _mm256_loadu_ps(ys.as_ptr().add(i)),
            _mm256_loadu_ps(zs.as_ptr().add(i)),
        ]
    }
}

/// The lanes of `h` at most `tol8` in magnitude (NaN is not), as the low
/// eight bits: `|h| <= tol`, the portable loops' test.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn within8(h: std::arch::x86_64::__m256, tol8: std::arch::x86_64::__m256) -> u32 {
    use std::arch::x86_64::_mm256_movemask_ps;
    _mm256_movemask_ps(within8_lanes(h, tol8)) as u32
}

/// [`within8`]'s test as lanes: all ones where `|h| <= tol`, else zero.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn within8_lanes(h: std::arch::x86_64::__m256, tol8: std::arch::x86_64::__m256) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    let magnitude = _mm256_andnot_ps(_mm256_set1_ps(-0.0), h);
    _mm256_cmp_ps::<_CMP_LE_OQ>(magnitude, tol8)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// Random offsets (some on the bound `tol` exactly, signed zeros, NaN
    /// and infinite components) and normals, every length from 0 to 70,
    /// 0 to 12 normals at once: every path this CPU runs counts what the
    /// portable loop counts.
    #[test]
    fn every_path_counts_what_the_portable_loop_counts() {
        let mut rng = SplitMix64::new(11);
        let mut f = |s: f32| (rng.next_f64() as f32 * 2.0 - 1.0) * s;
        let tol = 0.25f32;
        let mut checked = 0;
        for len in 0..71 {
            let mut d = [vec![0f32; len], vec![0f32; len], vec![0f32; len]];
            for i in 0..len {
                for (a, col) in d.iter_mut().enumerate() {
                    col[i] = f(1.0);
                    match (i * 7 + a + len) % 29 {
                        0 => col[i] = f32::NAN,
                        1 => col[i] = f32::INFINITY,
                        2 => col[i] = -0.0,
                        _ => {}
                    }
                }
                if i % 5 == 1 {
                    // Exactly on the bound along the x axis.
                    (d[0][i], d[1][i], d[2][i]) = (tol, 0.0, 0.0);
                }
            }
            let normals: Vec<[f32; 3]> = (0..12)
                .map(|r| {
                    if r == 0 {
                        [1.0, 0.0, 0.0]
                    } else {
                        let v = glam::Vec3::new(f(1.0), f(1.0), f(1.0)).normalize_or_zero();
                        v.to_array()
                    }
                })
                .collect();
            let want: Vec<u32> = normals
                .iter()
                .map(|&normal| portable_count(&d[0], &d[1], &d[2], normal, tol))
                .collect();
            assert!(want[0] > 0 || len < 2, "the on-bound offsets are counted at {len}");
            // Every number of normals at once (the AVX2 kernel takes them
            // four at a time, a short last group padded).
            for many in 0..=normals.len() {
                for isa in super::super::available() {
                    let mut got = vec![u32::MAX; many];
                    count_within(&d[0], &d[1], &d[2], &normals[..many], tol, isa, &mut got);
                    assert_eq!(got, want[..many], "{isa} at {len}, {many} normals");
                    checked += many;
                }
            }
        }
        assert!(checked >= 71 * 78);
    }

    /// Random points about a random origin (some on the bound `tol`
    /// exactly, signed zeros, NaN and infinite components), every length
    /// from 0 to 140 into sets of one to three words: every path this CPU
    /// runs sets the bits of the portable loop, and none past the points.
    #[test]
    fn every_path_holds_what_the_portable_loop_holds() {
        let mut rng = SplitMix64::new(12);
        let mut f = |s: f32| (rng.next_f64() as f32 * 2.0 - 1.0) * s;
        let tol = 0.25f32;
        let mut held = 0;
        for len in 0..141 {
            let origin = [f(0.5), f(0.5), f(0.5)];
            let mut d = [vec![0f32; len], vec![0f32; len], vec![0f32; len]];
            for i in 0..len {
                for (a, col) in d.iter_mut().enumerate() {
                    col[i] = origin[a] + f(1.0);
                    match (i * 7 + a + len) % 29 {
                        0 => col[i] = f32::NAN,
                        1 => col[i] = f32::NEG_INFINITY,
                        2 => col[i] = -0.0,
                        _ => {}
                    }
                }
                if i % 5 == 1 {
                    // Exactly on the bound along the x axis.
                    (d[0][i], d[1][i], d[2][i]) = (origin[0] + tol, origin[1], origin[2]);
                }
            }
            for r in 0..8 {
                let normal = if r == 0 {
                    [1.0, 0.0, 0.0]
                } else {
                    glam::Vec3::new(f(1.0), f(1.0), f(1.0))
                        .normalize_or_zero()
                        .to_array()
                };
                for words in 1..4 {
                    let mut want = vec![u64::MAX; words];
                    portable_held(&d[0], &d[1], &d[2], normal, origin, tol, &mut want);
                    let kept = len.min(64 * words);
                    for (w, bits) in want.iter().enumerate() {
                        let past = kept.saturating_sub(64 * w).min(64);
                        assert!(past == 64 || bits >> past == 0, "bits past the points");
                    }
                    held += want.iter().map(|w| w.count_ones()).sum::<u32>();
                    for isa in super::super::available() {
                        let mut got = vec![u64::MAX; words];
                        held_within(&d[0], &d[1], &d[2], normal, origin, tol, isa, &mut got);
                        assert_eq!(got, want, "{isa} at {len}, {words} words");
                    }
                }
            }
        }
        assert!(held > 1000, "only {held} held");
    }
}
