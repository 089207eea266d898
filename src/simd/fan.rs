//! The cells of a fan's grid that rays' directions fall in, four at a time
//! (`crate::accel::octree`'s fan: the directions from a camera's eye in
//! which no splat lies). The test runs once for every ray of a camera's
//! batch, before any is traced: about a sixth of a camera `occluded`
//! call's time as a scalar loop (issue 55, fortieth session).
//!
//! Every path takes, for each ray, the operations of [`gnomonic_cell`] in
//! its order (`f64`, no fused multiply-add), so every path finds the same
//! cells.

use super::Isa;
use crate::geometry::Ray;

/// [`gnomonic_cells`]' first word for a direction outside the grid:
/// behind the plane through the eye across `w`, past the grid's edges, or
/// not a number.
pub const NO_CELL: u32 = u32::MAX;

/// [`gnomonic_cells`]' second word for a direction outside the grid that
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

/// [`gnomonic_cell`] of each of `rays` into `cells` (as long), on the path
/// `isa` (AVX-512 takes the AVX2 kernel; a path the CPU does not run is
/// replaced by the portable loop, which finds the same cells).
pub fn gnomonic_cells(grid: &GnomonicGrid, rays: &[Ray], isa: Isa, cells: &mut [[u32; 2]]) {
    let cells = &mut cells[..rays.len()];
    match isa {
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2 | Isa::Avx512 if Isa::Avx2.supported() => {
            // SAFETY: the guard checked that the CPU runs AVX2.
            unsafe { avx2_cells(grid, rays, cells) }
        }
        _ => {
            for (c, r) in cells.iter_mut().zip(rays) {
                *c = gnomonic_cell(grid, r);
            }
        }
    }
}

/// [`gnomonic_cells`] on AVX2: four rays a step in `f64` lanes, the rest
/// one at a time.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn avx2_cells(grid: &GnomonicGrid, rays: &[Ray], cells: &mut [[u32; 2]]) {
    use std::arch::x86_64::{
        _CMP_GE_OQ, _CMP_GT_OQ, _CMP_LE_OQ, _CMP_LT_OQ, _mm_setr_ps, _mm_storeu_si128, _mm_unpackhi_epi32,
        _mm_unpacklo_epi32, _mm256_add_pd, _mm256_and_pd, _mm256_cmp_pd, _mm256_cvtps_pd, _mm256_or_pd,
        _mm256_cvttpd_epi32, _mm256_div_pd, _mm256_movemask_pd, _mm256_mul_pd, _mm256_set1_pd,
        _mm256_setzero_pd, _mm256_sub_pd,
    };
    let splat = |e: [f64; 3]| e.map(|x| _mm256_set1_pd(x));
    let (u, v, w) = (splat(grid.u), splat(grid.v), splat(grid.w));
    let (lo0, lo1) = (_mm256_set1_pd(grid.lo[0]), _mm256_set1_pd(grid.lo[1]));
    let scale = _mm256_set1_pd(grid.scale);
    let (n0, n1) = (_mm256_set1_pd(grid.n[0] as f64), _mm256_set1_pd(grid.n[1] as f64));
    let (zero, one) = (_mm256_setzero_pd(), _mm256_set1_pd(1.0));
    let reach = grid.reach.map(|x| _mm256_set1_pd(x));
    // Whether a direction not in front is beyond reach: all lanes or none.
    let none_behind = !grid.behind;
    let mut quads = rays.chunks_exact(4);
    let mut outs = cells.chunks_exact_mut(4);
    for (r, out) in (&mut quads).zip(&mut outs) {
        let axis = |a: usize| {
            let c = |k: usize| r[k].dir.to_array()[a];
            _mm256_cvtps_pd(_mm_setr_ps(c(0), c(1), c(2), c(3)))
        };
        let d = [axis(0), axis(1), axis(2)];
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
        let inside = |x, n| {
            _mm256_and_pd(
                _mm256_cmp_pd::<_CMP_GE_OQ>(x, zero),
                _mm256_cmp_pd::<_CMP_LT_OQ>(x, n),
            )
        };
        let within = _mm256_and_pd(
            _mm256_cmp_pd::<_CMP_GT_OQ>(z, zero),
            _mm256_and_pd(inside(i, n0), inside(j, n1)),
        );
        let mask = _mm256_movemask_pd(within);
        let past = _mm256_or_pd(
            _mm256_or_pd(
                _mm256_cmp_pd::<_CMP_LT_OQ>(i, reach[0]),
                _mm256_cmp_pd::<_CMP_GT_OQ>(i, reach[1]),
            ),
            _mm256_or_pd(
                _mm256_cmp_pd::<_CMP_LT_OQ>(j, reach[2]),
                _mm256_cmp_pd::<_CMP_GT_OQ>(j, reach[3]),
            ),
        );
        let ahead_past = _mm256_movemask_pd(_mm256_and_pd(_mm256_cmp_pd::<_CMP_GT_OQ>(z, zero), past));
        let not_ahead = _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_LE_OQ>(z, zero));
        let beyond = ahead_past | if none_behind { not_ahead } else { 0 };
        // Truncation, as `as u32` within the grid (elsewhere not read),
        // then each lane's `[i, j]`.
        let (i, j) = (_mm256_cvttpd_epi32(i), _mm256_cvttpd_epi32(j));
        let mut c = [[0u32; 2]; 4];
        // SAFETY: two unaligned stores of 16 bytes, at offsets 0 and 16 of
        // a 32-byte array.
        unsafe {
            _mm_storeu_si128(c.as_mut_ptr().cast(), _mm_unpacklo_epi32(i, j));
            _mm_storeu_si128(c.as_mut_ptr().add(2).cast(), _mm_unpackhi_epi32(i, j));
        }
        for (k, o) in out.iter_mut().enumerate() {
            *o = if mask >> k & 1 != 0 {
                c[k]
            } else if beyond >> k & 1 != 0 {
                [NO_CELL, BEYOND]
            } else {
                [NO_CELL; 2]
            };
        }
    }
    for (r, o) in quads.remainder().iter().zip(outs.into_remainder()) {
        *o = gnomonic_cell(grid, r);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use glam::{DVec3, Vec3};

    /// Every path finds the portable loop's cells, for directions across
    /// the grid, past its edges, behind the eye, edge-on, zero and NaN,
    /// with batches whose length is no multiple of four; and most in front
    /// fall in the grid.
    #[test]
    fn every_path_finds_the_portable_cells() {
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
            n: [300, 240],
            reach: [-60.0, 330.0, -1e300, 250.0],
            behind: false,
        };
        let (wf, uf, vf) = (w.as_vec3(), u.as_vec3(), v.as_vec3());
        let mut rays: Vec<Ray> = (0..4001)
            .map(|k| {
                let d = match k % 8 {
                    // Behind, edge-on, zero.
                    0 => -wf + uf * r(-1.0, 1.0),
                    1 => uf * r(-1.0, 1.0) + vf * r(-1.0, 1.0),
                    2 => Vec3::ZERO,
                    3 => Vec3::NAN,
                    // Across the grid and past its edges.
                    _ => wf + uf * r(-0.7, 0.7) + vf * r(-0.6, 0.6),
                };
                Ray {
                    origin: Vec3::new(1.0, 2.0, 3.0),
                    dir: d,
                }
            })
            .collect();
        rays.push(Ray {
            origin: Vec3::ZERO,
            dir: Vec3::INFINITY,
        });
        for behind in [false, true] {
            let grid = GnomonicGrid { behind, ..grid };
            let want: Vec<[u32; 2]> = rays.iter().map(|ray| gnomonic_cell(&grid, ray)).collect();
            let count = |w: [u32; 2]| want.iter().filter(|&&c| c == w).count();
            let inside = want.iter().filter(|c| c[0] != NO_CELL).count();
            // Measured: 937 (about 0.48 of the 2,000 across).
            assert!(inside > 850 && inside < 1050, "{inside} in the grid");
            assert!(want.iter().all(|&[i, j]| i < 300 && j < 240 || i == NO_CELL));
            // Measured: beyond 1,908 with nothing behind (in front past
            // reach, and the 1,500 behind, edge-on and zero), 639 with
            // something behind (in front past reach).
            let beyond = count([NO_CELL, BEYOND]);
            let bound = if behind { 550..750 } else { 1800..2000 };
            assert!(bound.contains(&beyond), "behind {behind}: {beyond} beyond");
            for isa in super::super::available() {
                for len in [rays.len(), 4000, 3, 0] {
                    let mut got = vec![[0u32; 2]; len];
                    gnomonic_cells(&grid, &rays[..len], isa, &mut got);
                    assert_eq!(got, want[..len], "{isa:?}, {len} rays");
                }
            }
        }
    }
}
