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

/// [`count_within`] on AVX2: eight offsets a step, the rest (past the last
/// multiple of eight) by the portable loop.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn avx2_count(dx: &[f32], dy: &[f32], dz: &[f32], normals: &[[f32; 3]], tol: f32, out: &mut [u32]) {
    use std::arch::x86_64::*;
    let n = dx.len();
    let wide = n - n % 8;
    let (tol8, sign) = (_mm256_set1_ps(tol), _mm256_set1_ps(-0.0));
    for (o, &normal) in out.iter_mut().zip(normals) {
        let (nx, ny, nz) = (
            _mm256_set1_ps(normal[0]),
            _mm256_set1_ps(normal[1]),
            _mm256_set1_ps(normal[2]),
        );
        let mut count = 0u32;
        let mut i = 0;
        while i < wide {
            // SAFETY: `i + 8 <= wide <= n`, and `dy` and `dz` are `n` long
            // (`count_within` cut them), so each unaligned load reads eight
            // floats inside its slice.
            let (x, y, z) = unsafe {
                (
                    _mm256_loadu_ps(dx.as_ptr().add(i)),
                    _mm256_loadu_ps(dy.as_ptr().add(i)),
                    _mm256_loadu_ps(dz.as_ptr().add(i)),
                )
            };
            let h = _mm256_add_ps(
                _mm256_add_ps(_mm256_mul_ps(nx, x), _mm256_mul_ps(ny, y)),
                _mm256_mul_ps(nz, z),
            );
            let within = _mm256_cmp_ps::<_CMP_LE_OQ>(_mm256_andnot_ps(sign, h), tol8);
            count += (_mm256_movemask_ps(within) as u32).count_ones();
            i += 8;
        }
        if wide < n {
            count += portable_count(&dx[wide..], &dy[wide..], &dz[wide..], normal, tol);
        }
        *o = count;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// Random offsets (some on the bound `tol` exactly, signed zeros, NaN
    /// and infinite components) and normals, every length from 0 to 70:
    /// every path this CPU runs counts what the portable loop counts.
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
            for r in 0..12 {
                let normal = if r == 0 {
                    [1.0, 0.0, 0.0]
                } else {
                    let v = glam::Vec3::new(f(1.0), f(1.0), f(1.0)).normalize_or_zero();
                    v.to_array()
                };
                let want = portable_count(&d[0], &d[1], &d[2], normal, tol);
                for isa in super::super::available() {
                    let mut got = [0u32; 2];
                    count_within(&d[0], &d[1], &d[2], &[normal; 2], tol, isa, &mut got);
                    assert_eq!(got, [want; 2], "{isa} at {len}");
                    checked += 1;
                }
                if r == 0 {
                    assert!(want > 0 || len < 2, "the on-bound offsets are counted at {len}");
                }
            }
        }
        assert!(checked >= 71 * 12);
    }
}
