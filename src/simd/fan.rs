//! The keys of rays by the cells of a fan's grid their directions fall
//! in, four at a time (`crate::accel::octree`'s fan: the directions from a
//! camera's eye in which no splat lies). The test runs once for every ray
//! of a camera's batch, before any is traced: with only the cells in
//! SIMD and the keys a scalar loop, 18 % of a camera `occluded` call's
//! instructions (issue 55, fortieth session).
//!
//! Every path takes, for each ray, the operations of [`gnomonic_key`] in
//! its order (`f64`, no fused multiply-add; the cell's bit gathered), so
//! every path finds the same keys.

use super::Isa;
use crate::geometry::Ray;

/// [`gnomonic_cell`]'s first word for a direction outside the grid:
/// behind the plane through the eye across `w`, past the grid's edges, or
/// not a number.
pub const NO_CELL: u32 = u32::MAX;

/// [`gnomonic_cell`]'s second word for a direction outside the grid that
/// the grid's reach leaves out ([`GnomonicGrid::reach`],
/// [`GnomonicGrid::behind`]); the second word is [`NO_CELL`] for the
/// others.
pub const BEYOND: u32 = u32::MAX - 1;

/// A fan's grid over the gnomonic plane of one eye: a direction `d` with
/// `d·w > 0` has the coordinates `(d·u / d·w, d·v / d·w)`, and the grid's
/// cell `(i, j)` holds the coordinates whose `(x − lo) · scale` truncate to
/// `i` and `j`, `n[0]` by `n[1]` cells (together below 2^31).
#[derive(Clone, Copy, Debug)]
pub struct GnomonicGrid {
    /// The plane's axes and the eye's mean direction.
    pub u: [f64; 3],
    pub v: [f64; 3],
    pub w: [f64; 3],
    /// The grid's lower corner in gnomonic coordinates.
    pub lo: [f64; 2],
    /// Cells per unit.
    pub scale: f64,
    /// Cells along each axis.
    pub n: [usize; 2],
    /// The least and most coordinates, in cells (`(x − lo) · scale`, past
    /// the grid too), of the directions in front some primitive may be
    /// met along: `[i_min, i_max, j_min, j_max]`.
    pub reach: [f64; 4],
    /// Whether some primitive may be met along a direction not in front
    /// (`d·w <= 0`).
    pub behind: bool,
}

/// The cell `[i, j]` of `grid` holding `ray`'s direction, or outside the
/// grid `[NO_CELL, BEYOND]` where its reach leaves the direction out (in
/// front past `reach`, or not in front while nothing is `behind`), else
/// `[NO_CELL; 2]`: the portable definition every path follows.
#[inline(always)]
#[must_use]
pub fn gnomonic_cell(grid: &GnomonicGrid, ray: &Ray) -> [u32; 2] {
    let d = ray.dir.to_array().map(f64::from);
    let dot = |e: [f64; 3]| d[0] * e[0] + d[1] * e[1] + d[2] * e[2];
    let z = dot(grid.w);
    let inv = 1.0 / z;
    let i = (dot(grid.u) * inv - grid.lo[0]) * grid.scale;
    let j = (dot(grid.v) * inv - grid.lo[1]) * grid.scale;
    // NaN compares false.
    let inside = |x: f64, a: usize| x >= 0.0 && x < grid.n[a] as f64;
    let r = grid.reach;
    let past = (i < r[0]) | (i > r[1]) | (j < r[2]) | (j > r[3]);
    let beyond = ((z > 0.0) & past) | ((z <= 0.0) & !grid.behind);
    if (z > 0.0) & inside(i, 0) & inside(j, 1) {
        // `0 <= i < n[0]` (the same for `j`): `as u32` truncates.
        [i as u32, j as u32]
    } else if beyond {
        [NO_CELL, BEYOND]
    } else {
        [NO_CELL; 2]
    }
}

/// [`gnomonic_keys`]' key of a ray known to miss.
pub const KEY_MISS: u32 = u32::MAX;

/// [`gnomonic_keys`]' key of a ray outside the grid that may hit.
pub const KEY_ELSEWHERE: u32 = u32::MAX - 1;

/// What [`gnomonic_keys`] reads besides the grid: the grid's cells as
/// bits (cell `at = i + n[0] j`: bit `at % 32` of word `at / 32`, set
/// where some primitive may be met), the eye's bits, and the blocks of
/// 2×2 cells a row.
#[derive(Clone, Copy, Debug)]
pub struct FanBits<'a> {
    pub covered: &'a [u32],
    pub origin: [u32; 3],
    pub cols: u32,
}

/// A ray's key: [`KEY_MISS`] where it leaves the eye (bit for bit) in a
/// cell no primitive covers or beyond the grid's reach
/// ([`gnomonic_cell`]), its direction a ray's (`0 < |d|² < ∞` in `f32`,
/// as a row's conversion takes `|d|`: a row keyed before it is converted
/// is then known to be a ray, `crate::accel::Fan::keys_of_rows`),
/// [`KEY_ELSEWHERE`] where it may hit outside the grid, else its block of
/// 2×2 cells, row after row of `cols` blocks: the portable definition
/// every path follows.
#[inline(always)]
#[must_use]
pub fn gnomonic_key(grid: &GnomonicGrid, bits: &FanBits<'_>, ray: &Ray) -> u32 {
    let [i, j] = gnomonic_cell(grid, ray);
    let here = ray.origin.to_array().map(f32::to_bits) == bits.origin;
    let q = ray.dir.dot(ray.dir);
    let ray_like = (q > 0.0) & (q < f32::INFINITY);
    let within = i != NO_CELL;
    let at = if within { i + grid.n[0] as u32 * j } else { 0 };
    let set = bits.covered[(at / 32) as usize] >> (at % 32) & 1 != 0;
    if here & ray_like & ((within & !set) | (j == BEYOND)) {
        KEY_MISS
    } else if within {
        j / 2 * bits.cols + i / 2
    } else {
        KEY_ELSEWHERE
    }
}

/// [`gnomonic_key`] of each of `rays` into `keys` (as long), on the path
/// `isa` (AVX-512 takes the AVX2 kernel; a path the CPU does not run is
/// replaced by the portable loop, which finds the same keys).
pub fn gnomonic_keys(grid: &GnomonicGrid, bits: &FanBits<'_>, rays: &[Ray], isa: Isa, keys: &mut [u32]) {
    let keys = &mut keys[..rays.len()];
    match isa {
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2 | Isa::Avx512 if Isa::Avx2.supported() => {
            // SAFETY: the guard checked that the CPU runs AVX2.
            unsafe { avx2_keys(grid, bits, rays, keys) }
        }
        _ => {
            for (k, r) in keys.iter_mut().zip(rays) {
                *k = gnomonic_key(grid, bits, r);
            }
        }
    }
}

/// [`gnomonic_keys`] on AVX2: four rays a step in `f64` lanes (the cells'
/// words gathered), the rest one at a time.
///
/// Panics if `bits.covered` holds fewer bits than `grid` has cells, or
/// none.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn avx2_keys(grid: &GnomonicGrid, bits: &FanBits<'_>, rays: &[Ray], keys: &mut [u32]) {
    use std::arch::x86_64::{
        _CMP_GE_OQ, _CMP_GT_OQ, _CMP_LE_OQ, _CMP_LT_OQ, _mm_add_epi32, _mm_and_si128, _mm_andnot_si128,
        _mm_blendv_epi8, _mm_cmpeq_epi32, _mm_loadu_si128, _mm_mask_i32gather_epi32, _mm_mullo_epi32,
        _mm_add_ps, _mm_and_ps, _mm_castps_si128, _mm_cmpgt_ps, _mm_cmplt_ps, _mm_mul_ps, _mm_set1_ps,
        _mm_setzero_ps, _mm_or_si128, _mm_set1_epi32, _mm_setr_ps, _mm_setzero_si128, _mm_srli_epi32, _mm_srlv_epi32,
        _mm_storeu_si128, _mm256_add_pd, _mm256_and_pd, _mm256_castpd_si256, _mm256_castsi256_si128,
        _mm256_cmp_pd, _mm256_cvtps_pd, _mm256_cvttpd_epi32, _mm256_div_pd, _mm256_mul_pd, _mm256_or_pd,
        _mm256_permutevar8x32_epi32, _mm256_set1_pd, _mm256_setr_epi32, _mm256_setzero_pd, _mm256_sub_pd,
    };
    // The gathers below read the word of any cell of the grid (the first
    // outside it).
    assert!(
        bits.covered.len() * 32 >= grid.n[0] * grid.n[1] && !bits.covered.is_empty(),
        "a bit a cell"
    );
    let splat = |e: [f64; 3]| e.map(|x| _mm256_set1_pd(x));
    let (u, v, w) = (splat(grid.u), splat(grid.v), splat(grid.w));
    let (lo0, lo1) = (_mm256_set1_pd(grid.lo[0]), _mm256_set1_pd(grid.lo[1]));
    let scale = _mm256_set1_pd(grid.scale);
    let (n0, n1) = (_mm256_set1_pd(grid.n[0] as f64), _mm256_set1_pd(grid.n[1] as f64));
    let (zero, one) = (_mm256_setzero_pd(), _mm256_set1_pd(1.0));
    let reach = grid.reach.map(|x| _mm256_set1_pd(x));
    // A direction not in front is beyond reach in all lanes or in none.
    let not_ahead_beyond = if grid.behind { zero } else { _mm256_cmp_pd::<_CMP_LE_OQ>(zero, zero) };
    // The low halves of four 64-bit lane masks, as four 32-bit masks.
    let halves = _mm256_setr_epi32(0, 2, 4, 6, 0, 2, 4, 6);
    let narrow = |m| _mm256_castsi256_si128(_mm256_permutevar8x32_epi32(_mm256_castpd_si256(m), halves));
    let cols = _mm_set1_epi32(bits.cols as i32);
    let width = _mm_set1_epi32(grid.n[0] as i32);
    let (ones, one_i) = (_mm_set1_epi32(-1), _mm_set1_epi32(1));
    let (miss_key, elsewhere_key) = (_mm_set1_epi32(KEY_MISS as i32), _mm_set1_epi32(KEY_ELSEWHERE as i32));
    let infinity = _mm_set1_ps(f32::INFINITY);
    // Which of four lanes leave the eye, as 32-bit masks, by their bits.
    let here_masks: [[i32; 4]; 16] =
        std::array::from_fn(|m| std::array::from_fn(|k| if m >> k & 1 != 0 { -1 } else { 0 }));
    let mut quads = rays.chunks_exact(4);
    let mut outs = keys.chunks_exact_mut(4);
    for (r, out) in (&mut quads).zip(&mut outs) {
        let axis = |a: usize| {
            let c = |k: usize| r[k].dir.to_array()[a];
            _mm_setr_ps(c(0), c(1), c(2), c(3))
        };
        let f = [axis(0), axis(1), axis(2)];
        // `0 < |d|² < ∞`, `|d|²` as `Vec3::dot` sums it.
        let q = _mm_add_ps(_mm_add_ps(_mm_mul_ps(f[0], f[0]), _mm_mul_ps(f[1], f[1])), _mm_mul_ps(f[2], f[2]));
        let ray_like = _mm_castps_si128(_mm_and_ps(_mm_cmpgt_ps(q, _mm_setzero_ps()), _mm_cmplt_ps(q, infinity)));
        let d = f.map(|f| _mm256_cvtps_pd(f));
        // `d[0] * e[0] + d[1] * e[1] + d[2] * e[2]`, left to right.
        let dot = |e: [_; 3]| {
            _mm256_add_pd(
                _mm256_add_pd(_mm256_mul_pd(d[0], e[0]), _mm256_mul_pd(d[1], e[1])),
                _mm256_mul_pd(d[2], e[2]),
            )
        };
        let z = dot(w);
        let inv = _mm256_div_pd(one, z);
        let i = _mm256_mul_pd(_mm256_sub_pd(_mm256_mul_pd(dot(u), inv), lo0), scale);
        let j = _mm256_mul_pd(_mm256_sub_pd(_mm256_mul_pd(dot(v), inv), lo1), scale);
        let inside = |x, n| _mm256_and_pd(_mm256_cmp_pd::<_CMP_GE_OQ>(x, zero), _mm256_cmp_pd::<_CMP_LT_OQ>(x, n));
        let ahead = _mm256_cmp_pd::<_CMP_GT_OQ>(z, zero);
        let within = _mm256_and_pd(ahead, _mm256_and_pd(inside(i, n0), inside(j, n1)));
        let past = _mm256_or_pd(
            _mm256_or_pd(_mm256_cmp_pd::<_CMP_LT_OQ>(i, reach[0]), _mm256_cmp_pd::<_CMP_GT_OQ>(i, reach[1])),
            _mm256_or_pd(_mm256_cmp_pd::<_CMP_LT_OQ>(j, reach[2]), _mm256_cmp_pd::<_CMP_GT_OQ>(j, reach[3])),
        );
        let not_ahead = _mm256_and_pd(_mm256_cmp_pd::<_CMP_LE_OQ>(z, zero), not_ahead_beyond);
        let beyond = narrow(_mm256_or_pd(_mm256_and_pd(ahead, past), not_ahead));
        let within = narrow(within);
        // Truncation, as `as u32` within the grid; 0 elsewhere.
        let (i, j) = (
            _mm_and_si128(_mm256_cvttpd_epi32(i), within),
            _mm_and_si128(_mm256_cvttpd_epi32(j), within),
        );
        let at = _mm_add_epi32(i, _mm_mullo_epi32(j, width));
        // SAFETY: `at` is a cell of the grid (0 outside it), and `covered`
        // holds a bit for each: every word index is in bounds.
        let word = unsafe {
            _mm_mask_i32gather_epi32::<4>(_mm_setzero_si128(), bits.covered.as_ptr().cast(), _mm_srli_epi32::<5>(at), ones)
        };
        let set = _mm_and_si128(_mm_srlv_epi32(word, _mm_and_si128(at, _mm_set1_epi32(31))), one_i);
        let empty = _mm_andnot_si128(_mm_cmpeq_epi32(set, one_i), within);
        let here_bits = (0..4).fold(0, |m, k| m | usize::from(r[k].origin.to_array().map(f32::to_bits) == bits.origin) << k);
        // SAFETY: an unaligned load of 16 bytes from a 16-byte array.
        let here = unsafe { _mm_loadu_si128(here_masks[here_bits].as_ptr().cast()) };
        // Beyond reach counts outside the grid only (as `gnomonic_cell`).
        let miss = _mm_and_si128(
            _mm_and_si128(here, ray_like),
            _mm_or_si128(empty, _mm_andnot_si128(within, beyond)),
        );
        let block = _mm_add_epi32(
            _mm_mullo_epi32(_mm_srli_epi32::<1>(j), cols),
            _mm_srli_epi32::<1>(i),
        );
        let key = _mm_blendv_epi8(_mm_blendv_epi8(elsewhere_key, block, within), miss_key, miss);
        // SAFETY: an unaligned store of 16 bytes into four `u32`s.
        unsafe { _mm_storeu_si128(out.as_mut_ptr().cast(), key) };
    }
    for (r, o) in quads.remainder().iter().zip(outs.into_remainder()) {
        *o = gnomonic_key(grid, bits, r);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use glam::{DVec3, Vec3};

    /// Every path finds the portable loop's keys, for directions across
    /// the grid, past its edges, behind the eye, edge-on, zero, NaN and
    /// infinite, from the eye and (one in seven) not, with something
    /// behind and not, batches whose length is no multiple of four; and
    /// every kind of key is met.
    #[test]
    fn every_path_finds_the_portable_keys() {
        let mut rng = SplitMix64::new(40);
        let mut r = |a: f32, b: f32| a + (b - a) * rng.next_f32();
        let w = DVec3::new(0.3, -0.2, 0.9).normalize();
        let u = w.any_orthonormal_vector();
        let v = w.cross(u);
        let grid = GnomonicGrid {
            u: u.to_array(),
            v: v.to_array(),
            w: w.to_array(),
            lo: [-0.5, -0.4],
            scale: 300.0,
            n: [301, 240],
            reach: [-60.0, 330.0, -1e300, 250.0],
            behind: false,
        };
        // Every third cell of a band of rows covered.
        let mut covered = vec![0u32; (301 * 240usize).div_ceil(32)];
        for at in (301 * 60..301 * 180).step_by(3) {
            covered[at / 32] |= 1 << (at % 32);
        }
        let eye = Vec3::new(1.0, 2.0, 3.0);
        let bits = FanBits {
            covered: &covered,
            origin: eye.to_array().map(f32::to_bits),
            cols: 151,
        };
        let (wf, uf, vf) = (w.as_vec3(), u.as_vec3(), v.as_vec3());
        let mut rays: Vec<Ray> = (0..4001)
            .map(|k| {
                let dir = match k % 8 {
                    // Behind, edge-on, zero, NaN.
                    0 => -wf + uf * r(-1.0, 1.0),
                    1 => uf * r(-1.0, 1.0) + vf * r(-1.0, 1.0),
                    2 => Vec3::ZERO,
                    3 => Vec3::NAN,
                    // Across the grid and past its edges.
                    _ => wf + uf * r(-0.7, 0.7) + vf * r(-0.6, 0.6),
                };
                let origin = if k % 7 == 6 { Vec3::ZERO } else { eye };
                Ray { origin, dir }
            })
            .collect();
        rays.push(Ray {
            origin: eye,
            dir: Vec3::INFINITY,
        });
        // Not rays' directions (`|d|²` zero or infinite in `f32`) along
        // uncovered cells, never a miss: a row keyed before it is made a
        // ray is then known to be one where it is said to miss.
        // Last, the same direction of length 1, beyond the grid's reach.
        let odd = [1e-30, 1e30, 1.0].map(|s| (wf + uf * 0.1 + vf * 0.5) * s);
        rays.extend(odd.map(|dir| Ray { origin: eye, dir }));
        for behind in [false, true] {
            let grid = GnomonicGrid { behind, ..grid };
            let want: Vec<u32> = rays.iter().map(|ray| gnomonic_key(&grid, &bits, ray)).collect();
            let count = |f: &dyn Fn(u32) -> bool| want.iter().filter(|&&k| f(k)).count();
            let (miss, elsewhere) = (count(&|k| k == KEY_MISS), count(&|k| k == KEY_ELSEWHERE));
            let blocks = count(&|k| k < KEY_ELSEWHERE);
            // Measured: misses 1,910 / 1,251, elsewhere 1,850 / 2,509,
            // blocks 245 (nothing behind / something behind).
            let bound = |x: usize, m: usize| x * 10 > m * 9 && x * 10 < m * 11;
            let (m, e) = if behind { (1251, 2509) } else { (1910, 1850) };
            let ray_like = |d: Vec3| d.dot(d) > 0.0 && d.dot(d) < f32::INFINITY;
            let odd = rays.iter().zip(&want).filter(|(r, _)| !ray_like(r.dir));
            assert!(odd.clone().count() > 1000 && odd.clone().all(|(_, &k)| k != KEY_MISS));
            assert!(want.ends_with(&[KEY_ELSEWHERE, KEY_ELSEWHERE, KEY_MISS]), "behind {behind}");
            assert!(bound(miss, m) && bound(elsewhere, e) && bound(blocks, 245), "behind {behind}: {miss} {elsewhere} {blocks}");
            assert!(want.iter().all(|&k| !(151 * 120..KEY_ELSEWHERE).contains(&k)));
            for isa in super::super::available() {
                for len in [rays.len(), 4000, 3, 0] {
                    let mut got = vec![0u32; len];
                    gnomonic_keys(&grid, &bits, &rays[..len], isa, &mut got);
                    assert_eq!(got, want[..len], "{isa:?}, {len} rays");
                }
            }
        }
    }
}
