//! Short runs of `u64` keys sorted by a bitonic network in SIMD lanes: the
//! sorts of generation's neighbourhoods (a neighbour search's 49 nearest,
//! `crate::splat::knn`; a wide neighbourhood's 49 heights,
//! `crate::splat::normals`), about a tenth of a smooth cloud's
//! instructions through the standard library's sort.
//!
//! Sorting integers has one answer: every path writes the same keys in the
//! same order, whatever network or algorithm it runs (equal keys are the
//! same bits).

use super::Isa;

/// The most keys the networks sort; longer runs take the standard sort.
pub const SORT_NETWORK_MAX: usize = 64;

/// The fewest keys the networks sort; shorter runs take the standard sort
/// (an insertion sort there, cheaper than a network of 16).
pub const SORT_NETWORK_MIN: usize = 17;

/// Sorts `keys` ascending on the path `isa`: a bitonic network of 32 or 64
/// lanes on AVX2 (AVX-512 takes the AVX2 kernel) for
/// [`SORT_NETWORK_MIN`] to [`SORT_NETWORK_MAX`] keys, else (and on a path
/// the CPU does not run) `sort_unstable`. The same keys in the same order
/// on every path.
#[inline]
pub fn sort_keys(keys: &mut [u64], isa: Isa) {
    let n = keys.len();
    match isa {
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2 | Isa::Avx512
            if (SORT_NETWORK_MIN..=SORT_NETWORK_MAX).contains(&n) && Isa::Avx2.supported() =>
        {
            if n <= 32 {
                // SAFETY: the guard checked that the CPU runs AVX2; `n` is
                // at most 32, the network's lanes (8 registers of 4).
                unsafe { x86::avx2_sort::<8>(keys) }
            } else {
                // SAFETY: as above; `n` is at most 64 (16 registers of 4).
                unsafe { x86::avx2_sort::<16>(keys) }
            }
        }
        _ => keys.sort_unstable(),
    }
}

/// Whether [`sort_keys`] sorts `a` keys and `b` keys with the same
/// network on the path `isa` (so sorting the longer costs what the shorter
/// costs): both 17 to 32, or both 33 to 64, on a path with networks.
#[must_use]
pub fn same_network(a: usize, b: usize, isa: Isa) -> bool {
    let networks = matches!(isa, Isa::Avx2 | Isa::Avx512) && Isa::Avx2.supported();
    let net = |n: usize| (SORT_NETWORK_MIN..=SORT_NETWORK_MAX).contains(&n).then_some(n <= 32);
    networks && net(a).is_some() && net(a) == net(b)
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use std::arch::x86_64::*;

    /// The lanes of `a` and `b` ordered: `(min, max)` lane by lane, as
    /// signed integers (the keys carry their top bit flipped).
    #[inline]
    #[target_feature(enable = "avx2")]
    fn min_max(a: __m256i, b: __m256i) -> (__m256i, __m256i) {
        let gt = _mm256_cmpgt_epi64(a, b);
        (_mm256_blendv_epi8(a, b, gt), _mm256_blendv_epi8(b, a, gt))
    }

    /// One layer of comparators between registers `J / 4` apart (lanes
    /// `J` apart, `J` at least 4) of the stage that merges blocks of `K`:
    /// the lower register of a pair keeps the least keys where its block
    /// ascends (bit `K` of its first lane clear), else the most.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn across<const R: usize, const K: usize, const J: usize>(v: &mut [__m256i; R]) {
        let jr = J / 4;
        // Pair `q`'s lower register, and whether its block ascends: every
        // index and choice a constant once the loop is unrolled.
        for q in 0..R / 2 {
            let r = q / jr * 2 * jr + q % jr;
            let (lo, hi) = min_max(v[r], v[r + jr]);
            let up = (4 * r) & K == 0;
            v[r] = if up { lo } else { hi };
            v[r + jr] = if up { hi } else { lo };
        }
    }

    /// One layer of comparators within each register, between lanes `J`
    /// apart (1 or 2), of the stage that merges blocks of `K`: each lane
    /// ends with the least of its pair where it is the pair's lower lane in
    /// an ascending block (or the upper in a descending one), else the most.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn within<const R: usize, const K: usize, const J: usize>(v: &mut [__m256i; R]) {
        // The pairs' upper lanes, and the lanes of descending blocks (by
        // lane within a register for blocks of 2, else whole registers).
        let upper = if J == 2 {
            _mm256_set_epi64x(-1, -1, 0, 0)
        } else {
            _mm256_set_epi64x(-1, 0, -1, 0)
        };
        for (r, x) in v.iter_mut().enumerate() {
            let descending = if K == 2 {
                _mm256_set_epi64x(-1, -1, 0, 0)
            } else if (4 * r) & K != 0 {
                _mm256_set1_epi64x(-1)
            } else {
                _mm256_setzero_si256()
            };
            // Which lanes take the pair's larger key.
            let takes_max = _mm256_xor_si256(upper, descending);
            let t = if J == 2 {
                _mm256_permute4x64_epi64::<0x4E>(*x)
            } else {
                _mm256_permute4x64_epi64::<0xB1>(*x)
            };
            // A lane takes its partner's key where that one is the less
            // and it keeps the least, or is not the less and it keeps the
            // most (an equal key is the same either way).
            let take = _mm256_xor_si256(_mm256_cmpgt_epi64(*x, t), takes_max);
            *x = _mm256_blendv_epi8(*x, t, take);
        }
    }

    /// The stage of the bitonic network that merges blocks of `K` lanes
    /// (of `4 R`): its layers `K / 2`, `K / 4`, ... 1 apart.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn stage<const R: usize, const K: usize>(v: &mut [__m256i; R]) {
        if K >= 64 {
            across::<R, K, 32>(v);
        }
        if K >= 32 {
            across::<R, K, 16>(v);
        }
        if K >= 16 {
            across::<R, K, 8>(v);
        }
        if K >= 8 {
            across::<R, K, 4>(v);
        }
        if K >= 4 {
            within::<R, K, 2>(v);
        }
        within::<R, K, 1>(v);
    }

    /// [`super::sort_keys`]' network: `keys` (at most `4 R`) padded with
    /// the largest key to `4 R` lanes in `R` registers (8 or 16), their top
    /// bits flipped so that signed compares order them as unsigned, sorted
    /// by the bitonic network (blocks of `K` merged ascending or descending
    /// by bit `K` of their first lane, `K` from 2 to `4 R`), the first
    /// `keys.len()` written back.
    ///
    /// # Safety
    /// The CPU must run AVX2, `R` is 8 or 16, and `keys.len() <= 4 R`.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn avx2_sort<const R: usize>(keys: &mut [u64]) {
        let n = keys.len();
        debug_assert!(n <= 4 * R && (R == 8 || R == 16));
        let mut buf = [u64::MAX; 64];
        buf[..n].copy_from_slice(keys);
        let flip = _mm256_set1_epi64x(i64::MIN);
        let mut v = [_mm256_setzero_si256(); R];
        for (r, x) in v.iter_mut().enumerate() {
            // SAFETY: `4 r + 4 <= 4 R <= 64`, inside `buf`.
            let at = unsafe { buf.as_ptr().add(4 * r).cast::<__m256i>() };
            // SAFETY: `at` points at four `u64` of `buf` (unaligned load).
            *x = _mm256_xor_si256(unsafe { _mm256_loadu_si256(at) }, flip);
        }
        stage::<R, 2>(&mut v);
        stage::<R, 4>(&mut v);
        stage::<R, 8>(&mut v);
        stage::<R, 16>(&mut v);
        stage::<R, 32>(&mut v);
        if R == 16 {
            stage::<R, 64>(&mut v);
        }
        for (r, x) in v.iter().enumerate() {
            // SAFETY: as for the loads, four `u64` inside `buf`.
            let at = unsafe { buf.as_mut_ptr().add(4 * r).cast::<__m256i>() };
            // SAFETY: `at` points at four `u64` of `buf` (unaligned store).
            unsafe { _mm256_storeu_si256(at, _mm256_xor_si256(*x, flip)) };
        }
        keys.copy_from_slice(&buf[..n]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// Every length from 0 to 80 (the networks' 17 to 64 and either side),
    /// random keys, keys with many ties, keys at 0 and `u64::MAX` (the
    /// padding's own value), already sorted and reversed runs: every path
    /// this CPU runs gives `sort_unstable`'s answer bit for bit.
    /// Lengths share a network only where both are sorted by the same
    /// one: 17 to 32, or 33 to 64, on a path that has networks.
    #[test]
    fn lengths_share_a_network_only_within_one() {
        for isa in super::super::available() {
            let nets = matches!(isa, Isa::Avx2 | Isa::Avx512);
            assert_eq!(same_network(17, 32, isa), nets);
            assert_eq!(same_network(33, 64, isa), nets);
            assert_eq!(same_network(49, 60, isa), nets);
            for (a, b) in [(16, 17), (32, 33), (64, 65), (13, 14), (49, 70), (0, 0)] {
                assert!(!same_network(a, b, isa), "{a} {b} {isa:?}");
            }
        }
    }

    #[test]
    fn every_path_sorts_as_the_standard_sort() {
        let mut rng = SplitMix64::new(54);
        let mut checked = 0;
        for len in 0..81 {
            for case in 0..6 {
                let keys: Vec<u64> = (0..len)
                    .map(|i| {
                        let r = rng.next_u64();
                        match case {
                            0 => r,
                            1 => r % 5,
                            2 => [0, u64::MAX, 1 << 63, (1 << 63) - 1][(r % 4) as usize],
                            3 => i as u64 * 3,
                            4 => u64::MAX - i as u64,
                            _ => (r & 0xffff_ffff_0000_0000) | (r % 3),
                        }
                    })
                    .collect();
                let mut want = keys.clone();
                want.sort_unstable();
                for isa in super::super::available() {
                    let mut got = keys.clone();
                    sort_keys(&mut got, isa);
                    assert_eq!(got, want, "{isa}, {len} keys, case {case}");
                    checked += 1;
                }
            }
        }
        assert!(checked >= 81 * 6);
    }
}
