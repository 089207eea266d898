//! The points of a neighbour search's cached ball within a bound of a
//! query, eight at a time: the scan of `crate::splat::knn`'s bounded
//! queries, most of the neighbourhood graph's time.
//!
//! Every path takes, for each point, the tree's squared distance in its
//! order, `d = (d_x d_x + d_y d_y) + d_z d_z` with `d_x = x - q_x` (no fused
//! multiply-add), and `d <= bound` (NaN is not within), so every path finds
//! the same points with the same distances bit for bit; only the order in
//! which they are written differs (the caller sorts them).

use super::Isa;

/// The points `(x[i], y[i], z[i])` (three equally long slices, and
/// `items` as long) within squared distance `bound` of `q`, written to the front of
/// `keys` as `(d.to_bits() << 32) | items[i]` in an order of the path's
/// own, on the path `isa` (AVX-512 takes the AVX2 kernel; a path the CPU
/// does not run is replaced by the portable loop); returns how many.
/// `keys` must be at least 8 longer than the slices (each step writes
/// eight keys, of which only the passing ones are kept).
#[inline]
pub fn keys_within(
    [x, y, z]: [&[f32]; 3],
    items: &[u32],
    q: [f32; 3],
    bound: f32,
    isa: Isa,
    keys: &mut [u64],
) -> usize {
    let n = x.len();
    let (y, z, items) = (&y[..n], &z[..n], &items[..n]);
    let keys = &mut keys[..n + 8];
    match isa {
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2 | Isa::Avx512 if Isa::Avx2.supported() => {
            // SAFETY: the guard checked that the CPU runs AVX2.
            unsafe { avx2_keys(x, y, z, items, q, bound, keys) }
        }
        _ => portable_keys(x, y, z, items, q, bound, keys),
    }
}

/// The squared distance of [`keys_within`] (the tree's sum, in its order).
#[inline]
fn dist_sq(a: [f32; 3], b: [f32; 3]) -> f32 {
    let (dx, dy, dz) = (a[0] - b[0], a[1] - b[1], a[2] - b[2]);
    dx * dx + dy * dy + dz * dz
}

/// A found point's key: its squared distance's bits, then its index.
#[inline]
fn key(d: f32, item: u32) -> u64 {
    (u64::from(d.to_bits()) << 32) | u64::from(item)
}

/// The portable loop of [`keys_within`]: eight distances at a time (in
/// lanes the compiler vectorises), then their keys without a branch on the
/// bound (half the points pass it, at random): every key is written, and
/// the next one lands after it only where it passed.
#[inline]
fn portable_keys(
    x: &[f32],
    y: &[f32],
    z: &[f32],
    items: &[u32],
    q: [f32; 3],
    bound: f32,
    keys: &mut [u64],
) -> usize {
    let mut len = 0;
    let lanes = x.len() / 8 * 8;
    for at in (0..lanes).step_by(8) {
        let lane = |v: &[f32]| -> [f32; 8] { v[at..at + 8].try_into().unwrap_or_default() };
        let (cx, cy, cz) = (lane(x), lane(y), lane(z));
        let mut d = [0f32; 8];
        for l in 0..8 {
            d[l] = dist_sq([cx[l], cy[l], cz[l]], q);
        }
        let out = &mut keys[len..len + 8];
        let mut n = 0;
        for (l, &d) in d.iter().enumerate() {
            out[n & 7] = key(d, items[at + l]);
            n += usize::from(d <= bound);
        }
        len += n;
    }
    for j in lanes..x.len() {
        let d = dist_sq([x[j], y[j], z[j]], q);
        keys[len] = key(d, items[j]);
        len += usize::from(d <= bound);
    }
    len
}

/// For each 8-bit mask, the lanes set in it, lowest first, then the rest:
/// the permutation that packs a step's passing lanes to its front.
const PACK: [[u32; 8]; 256] = {
    let mut table = [[0u32; 8]; 256];
    let mut m = 0;
    while m < 256 {
        let (mut n, mut l) = (0, 0);
        while l < 8 {
            if m >> l & 1 == 1 {
                table[m][n] = l as u32;
                n += 1;
            }
            l += 1;
        }
        let mut l = 0;
        while l < 8 {
            if m >> l & 1 == 0 {
                table[m][n] = l as u32;
                n += 1;
            }
            l += 1;
        }
        m += 1;
    }
    table
};

/// [`keys_within`] on AVX2: eight points a step, the passing ones packed
/// to the front of the step's eight keys by one permutation ([`PACK`]),
/// the rest (past the last multiple of eight) by the portable loop.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn avx2_keys(
    x: &[f32],
    y: &[f32],
    z: &[f32],
    items: &[u32],
    q: [f32; 3],
    bound: f32,
    keys: &mut [u64],
) -> usize {
    use std::arch::x86_64::*;
    let n = x.len();
    let wide = n - n % 8;
    let (qx, qy, qz) = (_mm256_set1_ps(q[0]), _mm256_set1_ps(q[1]), _mm256_set1_ps(q[2]));
    let bound8 = _mm256_set1_ps(bound);
    let mut len = 0;
    let mut i = 0;
    while i < wide {
        // SAFETY: `i + 8 <= wide <= n`, and `y`, `z` and `items` are `n`
        // long (`keys_within` cut them), so each unaligned load reads
        // eight lanes inside its slice.
        let (px, py, pz, it) = unsafe {
            (
                _mm256_loadu_ps(x.as_ptr().add(i)),
                _mm256_loadu_ps(y.as_ptr().add(i)),
                _mm256_loadu_ps(z.as_ptr().add(i)),
                _mm256_loadu_si256(items.as_ptr().add(i).cast()),
            )
        };
        let (dx, dy, dz) = (_mm256_sub_ps(px, qx), _mm256_sub_ps(py, qy), _mm256_sub_ps(pz, qz));
        let d = _mm256_add_ps(
            _mm256_add_ps(_mm256_mul_ps(dx, dx), _mm256_mul_ps(dy, dy)),
            _mm256_mul_ps(dz, dz),
        );
        let mask = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(d, bound8)) as usize & 0xff;
        // SAFETY: `PACK[mask]` is eight `u32`, one unaligned load.
        let perm = unsafe { _mm256_loadu_si256(PACK[mask].as_ptr().cast()) };
        let d = _mm256_permutevar8x32_epi32(_mm256_castps_si256(d), perm);
        let it = _mm256_permutevar8x32_epi32(it, perm);
        // Keys 0, 1, 4, 5 and 2, 3, 6, 7 (index low, distance high), then
        // in order.
        let (lo, hi) = (_mm256_unpacklo_epi32(it, d), _mm256_unpackhi_epi32(it, d));
        let first = _mm256_permute2x128_si256::<0x20>(lo, hi);
        let second = _mm256_permute2x128_si256::<0x31>(lo, hi);
        // SAFETY: `len <= i` (at most eight keys a step of eight points),
        // so `len + 8 <= i + 8 <= n + 8 <= keys.len()` (`keys_within` cut
        // `keys` to `n + 8`): two unaligned stores of four keys inside it.
        unsafe {
            _mm256_storeu_si256(keys.as_mut_ptr().add(len).cast(), first);
            _mm256_storeu_si256(keys.as_mut_ptr().add(len + 4).cast(), second);
        }
        len += mask.count_ones() as usize;
        i += 8;
    }
    if wide < n {
        let rest = &mut keys[len..];
        len += portable_keys(&x[wide..], &y[wide..], &z[wide..], &items[wide..], q, bound, rest);
    }
    len
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// Random points (some exactly on the bound, signed zeros, NaN and
    /// infinite coordinates), every length from 0 to 70: every path this
    /// CPU runs finds the keys the portable loop finds (as sets: the order
    /// is each path's own), and those are the points a plain filter keeps.
    #[test]
    fn every_path_finds_what_the_portable_loop_finds() {
        let mut rng = SplitMix64::new(23);
        let mut f = |s: f32| (rng.next_f64() as f32 * 2.0 - 1.0) * s;
        let (q, bound) = ([0.125f32, -0.25, 0.5], 0.25f32);
        let mut checked = 0;
        for len in 0..71 {
            let mut p = [vec![0f32; len], vec![0f32; len], vec![0f32; len]];
            for i in 0..len {
                for (a, col) in p.iter_mut().enumerate() {
                    col[i] = q[a] + f(0.8);
                    match (i * 7 + a + len) % 29 {
                        0 => col[i] = f32::NAN,
                        1 => col[i] = f32::INFINITY,
                        2 => col[i] = -0.0,
                        _ => {}
                    }
                }
                if i % 5 == 1 {
                    // Exactly on the bound: 0.5 along x.
                    (p[0][i], p[1][i], p[2][i]) = (q[0] + 0.5, q[1], q[2]);
                }
            }
            let items: Vec<u32> = (0..len as u32).map(|i| i * 3 + 1).collect();
            let mut want: Vec<u64> = (0..len)
                .map(|i| (dist_sq([p[0][i], p[1][i], p[2][i]], q), items[i]))
                .filter(|&(d, _)| d <= bound)
                .map(|(d, i)| key(d, i))
                .collect();
            want.sort_unstable();
            let mut portable = vec![0u64; len + 8];
            let n = portable_keys(&p[0], &p[1], &p[2], &items, q, bound, &mut portable);
            let mut got = portable[..n].to_vec();
            got.sort_unstable();
            assert_eq!(got, want, "portable at {len}");
            if len > 2 {
                assert!(!want.is_empty(), "the on-bound points are found at {len}");
            }
            for isa in super::super::available() {
                let mut keys = vec![0u64; len + 8];
                let n = keys_within([&p[0], &p[1], &p[2]], &items, q, bound, isa, &mut keys);
                let mut got = keys[..n].to_vec();
                got.sort_unstable();
                assert_eq!(got, want, "{isa} at {len}");
                checked += 1;
            }
        }
        assert!(checked >= 71);
    }
}
