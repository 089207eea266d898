//! Rows of six numbers (origin, then direction) to rays, as the Python
//! package's `SplatScene` takes its arrays: four rows a step on SSE2 (the
//! baseline of x86-64, so no path to choose at run time). One row at a
//! time, its conversion took 5 ms of a 33 ms call casting 1M camera rays
//! (issue 55, fifty-second session): two square roots and a division a
//! row, and its origin shifted in `f64`.
//!
//! [`ray_from_row`] is the definition; the SSE2 path does its IEEE
//! operations lane by lane in its order (no fused multiply-add), so every
//! ray, length and verdict is the same bit for bit.

use crate::geometry::Ray;
use glam::{DVec3, Vec3};

/// A row as a ray in a frame `shift` from the row's (the origin's `shift`
/// subtracted in `f64`, then rounded), its direction normalised as
/// [`Ray::new`] normalises it, the direction's length, and whether the row
/// is a ray: false for a NaN or infinite number, a direction of zero (or
/// too small or large a) length, or an origin too far for `f32` (such a
/// row gets some ray).
#[inline(always)]
#[must_use]
pub fn ray_from_row<T: Copy + Into<f64>>(r: &[T; 6], shift: DVec3) -> (Ray, f32, bool) {
    let r = r.map(Into::<f64>::into);
    let finite = r.iter().fold(true, |a, x| a & x.is_finite());
    let d = Vec3::new(r[3] as f32, r[4] as f32, r[5] as f32);
    let len = d.length();
    let origin = (DVec3::new(r[0], r[1], r[2]) - shift).as_vec3();
    let ok = finite & (len > 0.0) & len.is_finite() & origin.is_finite();
    // `Ray::new`'s `d * (1 / |d|)`, its length taken once.
    let dir = d * (1.0 / len);
    (Ray { origin, dir }, len, ok)
}

/// The rows `rows` (six numbers each, as many as `rays` holds) converted
/// into `rays` and `lens` ([`ray_from_row`]); false where some row is
/// not a ray.
///
/// # Panics
/// If `rows` holds fewer than `6 * rays.len()` numbers or `lens` fewer
/// than `rays.len()`.
pub fn rays_from_rows<T: Copy + Into<f64>>(rows: &[T], shift: DVec3, rays: &mut [Ray], lens: &mut [f32]) -> bool {
    let m = rays.len();
    let rows = rows[..6 * m].as_chunks::<6>().0;
    let mut good = true;
    for ((ray, len), r) in rays.iter_mut().zip(&mut lens[..m]).zip(rows) {
        let (r, l, ok) = ray_from_row(r, shift);
        (*ray, *len) = (r, l);
        good &= ok;
    }
    good
}

/// A number a ray array's rows may hold, converted on its fastest path.
pub trait RowNumber: Copy + Into<f64> + Sync {
    /// [`rays_from_rows`] of rows of this type.
    fn rays(rows: &[Self], shift: DVec3, rays: &mut [Ray], lens: &mut [f32]) -> bool;

    /// The rows as they are, read as [`Ray`]s number for number (origin,
    /// then direction, neither shifted nor normalised), where the type
    /// is `f32` ([`rows_as_rays`]); `None` for another.
    fn as_rays(rows: &[Self]) -> Option<&[Ray]>;
}

impl RowNumber for f32 {
    fn rays(rows: &[f32], shift: DVec3, rays: &mut [Ray], lens: &mut [f32]) -> bool {
        rays_from_f32_rows(rows, shift, rays, lens)
    }

    fn as_rays(rows: &[f32]) -> Option<&[Ray]> {
        Some(rows_as_rays(rows))
    }
}

impl RowNumber for f64 {
    fn rays(rows: &[f64], shift: DVec3, rays: &mut [Ray], lens: &mut [f32]) -> bool {
        rays_from_rows(rows, shift, rays, lens)
    }

    fn as_rays(_: &[f64]) -> Option<&[Ray]> {
        None
    }
}

// `Ray` is six `f32` in a row, nothing between them (`rows_as_rays`).
const _: () = assert!(size_of::<Ray>() == 24 && align_of::<Ray>() == align_of::<f32>());

/// `f32` rows of six numbers read in place as [`Ray`]s, number for number
/// (a shorter tail left out): the rays of the rows' numbers before
/// [`ray_from_row`] shifts and normalises them (a fan keys them so,
/// `crate::accel::Fan::keys_of_rows`).
#[must_use]
pub fn rows_as_rays(rows: &[f32]) -> &[Ray] {
    let n = rows.len() / 6;
    // SAFETY: `Ray` is `#[repr(C)]` of two `Vec3`, each `#[repr(C)]` of
    // three `f32`: 24 bytes with `f32`'s alignment and no padding (asserted
    // above), so `n` rays are exactly the first `6 n` numbers of `rows`,
    // which it holds, aligned as they are; every bit pattern is an `f32`,
    // and the rays borrow `rows` for its lifetime (shared, not mutable).
    unsafe { std::slice::from_raw_parts(rows.as_ptr().cast::<Ray>(), n) }
}

/// [`rays_from_rows`] of `f32` rows: four a step on SSE2, the rest one
/// at a time.
///
/// # Panics
/// As [`rays_from_rows`].
pub fn rays_from_f32_rows(rows: &[f32], shift: DVec3, rays: &mut [Ray], lens: &mut [f32]) -> bool {
    let m = rays.len();
    let (rows, lens) = (&rows[..6 * m], &mut lens[..m]);
    #[cfg(target_arch = "x86_64")]
    {
        let whole = m / 4 * 4;
        // SAFETY: SSE2 is part of x86-64's baseline, which this crate is
        // built for: every x86-64 CPU runs it.
        let good = unsafe { x86::sse2_rows(&rows[..6 * whole], shift, &mut rays[..whole], &mut lens[..whole]) };
        let rest = rays_from_rows(&rows[6 * whole..], shift, &mut rays[whole..], &mut lens[whole..]);
        good & rest
    }
    #[cfg(not(target_arch = "x86_64"))]
    rays_from_rows(rows, shift, rays, lens)
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use crate::geometry::Ray;
    use glam::DVec3;
    use std::arch::x86_64::{
        __m128, __m128d, _mm_add_ps, _mm_and_ps, _mm_castsi128_ps, _mm_cmpgt_ps, _mm_cmplt_ps, _mm_cvtpd_ps,
        _mm_cvtps_pd, _mm_div_ps, _mm_movehl_ps, _mm_movelh_ps, _mm_movemask_ps, _mm_mul_ps, _mm_set1_epi32,
        _mm_set1_pd, _mm_set1_ps, _mm_setr_ps, _mm_setzero_ps, _mm_shuffle_ps, _mm_sqrt_ps, _mm_storeu_ps,
        _mm_sub_pd, _mm_unpackhi_ps, _mm_unpacklo_ps,
    };

    /// [`super::rays_from_rows`] of `f32` rows, four a step: the rows'
    /// numbers loaded as six vectors and transposed to one vector a
    /// column, each column's operations of [`super::ray_from_row`] done on
    /// the four lanes (an `f32` is finite where its `f64` is), transposed
    /// back and stored as four rays (six `f32` each, `Ray`'s layout).
    ///
    /// Panics unless `rays` holds a multiple of four and `rows` and `lens`
    /// match it.
    #[target_feature(enable = "sse2")]
    pub(super) fn sse2_rows(rows: &[f32], shift: DVec3, rays: &mut [Ray], lens: &mut [f32]) -> bool {
        assert!(rays.len().is_multiple_of(4) && rows.len() == 6 * rays.len() && lens.len() == rays.len());
        let sh = shift.to_array().map(|s| _mm_set1_pd(s));
        let abs = _mm_castsi128_ps(_mm_set1_epi32(0x7fff_ffff));
        let inf = _mm_set1_ps(f32::INFINITY);
        let finite = |x: __m128| _mm_cmplt_ps(_mm_and_ps(x, abs), inf);
        let mut bad = 0;
        let steps = rays.chunks_exact_mut(4).zip(lens.chunks_exact_mut(4)).zip(rows.chunks_exact(24));
        for ((rays, lens), r) in steps {
            let v: [__m128; 6] = std::array::from_fn(|k| _mm_setr_ps(r[4 * k], r[4 * k + 1], r[4 * k + 2], r[4 * k + 3]));
            // Two rows in three vectors, [ox oy oz dx] [dy dz ox' oy']
            // [oz' dx' dy' dz'], to pairs of columns.
            let pairs = |a: __m128, b: __m128, c: __m128| {
                (
                    _mm_shuffle_ps::<0b11_10_01_00>(a, b),
                    _mm_shuffle_ps::<0b01_00_11_10>(a, c),
                    _mm_shuffle_ps::<0b11_10_01_00>(b, c),
                )
            };
            let (p0, p1, p2) = pairs(v[0], v[1], v[2]);
            let (q0, q1, q2) = pairs(v[3], v[4], v[5]);
            let even = |p: __m128, q: __m128| _mm_shuffle_ps::<0b10_00_10_00>(p, q);
            let odd = |p: __m128, q: __m128| _mm_shuffle_ps::<0b11_01_11_01>(p, q);
            let o = [even(p0, q0), odd(p0, q0), even(p1, q1)];
            let d = [odd(p1, q1), even(p2, q2), odd(p2, q2)];
            let sq = |x: __m128| _mm_mul_ps(x, x);
            let len = _mm_sqrt_ps(_mm_add_ps(_mm_add_ps(sq(d[0]), sq(d[1])), sq(d[2])));
            let inv = _mm_div_ps(_mm_set1_ps(1.0), len);
            let u = d.map(|x| _mm_mul_ps(x, inv));
            let shifted = |x: __m128, s: __m128d| {
                let lo = _mm_cvtpd_ps(_mm_sub_pd(_mm_cvtps_pd(x), s));
                let hi = _mm_cvtpd_ps(_mm_sub_pd(_mm_cvtps_pd(_mm_movehl_ps(x, x)), s));
                _mm_movelh_ps(lo, hi)
            };
            let s = [shifted(o[0], sh[0]), shifted(o[1], sh[1]), shifted(o[2], sh[2])];
            let mut ok = _mm_and_ps(_mm_cmpgt_ps(len, _mm_setzero_ps()), finite(len));
            for x in o.into_iter().chain(d).chain(s) {
                ok = _mm_and_ps(ok, finite(x));
            }
            bad |= _mm_movemask_ps(ok) ^ 0b1111;
            // Back to rows: [sx sy sz ux] [uy uz sx' sy'] [sz' ux' uy' uz'].
            let (p0, q0) = (_mm_unpacklo_ps(s[0], s[1]), _mm_unpackhi_ps(s[0], s[1]));
            let (p1, q1) = (_mm_unpacklo_ps(s[2], u[0]), _mm_unpackhi_ps(s[2], u[0]));
            let (p2, q2) = (_mm_unpacklo_ps(u[1], u[2]), _mm_unpackhi_ps(u[1], u[2]));
            let out = [
                _mm_movelh_ps(p0, p1),
                _mm_shuffle_ps::<0b11_10_01_00>(p2, p0),
                _mm_movehl_ps(p2, p1),
                _mm_movelh_ps(q0, q1),
                _mm_shuffle_ps::<0b11_10_01_00>(q2, q0),
                _mm_movehl_ps(q2, q1),
            ];
            let dst = rays.as_mut_ptr().cast::<f32>();
            for (k, x) in out.into_iter().enumerate() {
                // SAFETY: `rays` is four `Ray`s, `#[repr(C)]` of two
                // `Vec3` (three `f32` each, no padding): 24 `f32` from
                // `dst`, and `k < 6` writes four of them from `4k`.
                unsafe { _mm_storeu_ps(dst.add(4 * k), x) };
            }
            // SAFETY: `lens` holds four `f32` (the chunk above).
            unsafe { _mm_storeu_ps(lens.as_mut_ptr(), len) };
        }
        bad == 0
    }
}

#[cfg(test)]
mod tests {
    use super::{ray_from_row, rays_from_f32_rows, rays_from_rows};
    use crate::geometry::Ray;
    use crate::rng::SplitMix64;
    use glam::{DVec3, Vec3};

    /// Rows of every kind (ordinary, huge and tiny numbers, NaN, infinite,
    /// zero directions, origins past `f32` once shifted), in runs of every
    /// length mod 4, shifted near and far: the SSE2 path's rays, lengths
    /// and verdicts are the definition's row by row, bit for bit (a
    /// mutant swapping two of its shuffles, or taking `d / |d|`, fails).
    #[test]
    fn four_rows_a_step_are_each_row_alone_bit_for_bit() {
        let mut rng = SplitMix64::new(52);
        let special = [f32::NAN, f32::INFINITY, -f32::INFINITY, 0.0, -0.0, 1e30, -1e-30, f32::MAX, 1e-25, 3.4e38];
        let bits = |r: &Ray| [r.origin.to_array(), r.dir.to_array()].concat().iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let (mut bad_rows, mut rows_seen) = (0, 0);
        for shift in [DVec3::ZERO, DVec3::new(1000.25, -20.5, 3.0), DVec3::new(-3e38, 0.0, 1e300)] {
            for n in [0, 1, 3, 4, 5, 8, 11, 400] {
                let mut rows: Vec<f32> = (0..6 * n).map(|_| (rng.next_f32() - 0.5) * 20.0).collect();
                for k in 0..n / 3 {
                    let at = 6 * rng.below(n) + rng.below(6);
                    rows[at] = special[k % special.len()];
                }
                if n > 2 {
                    rows[6 * 2 + 3..6 * 3].fill(0.0);
                }
                let (mut rays, mut lens) = (vec![Ray::new(Vec3::ZERO, Vec3::X); n], vec![0.0; n]);
                let good = rays_from_f32_rows(&rows, shift, &mut rays, &mut lens);
                let (mut want, mut want_lens) = (rays.clone(), lens.clone());
                assert_eq!(good, rays_from_rows(&rows, shift, &mut want, &mut want_lens), "{n} rows, {shift}");
                for i in 0..n {
                    let r: &[f32; 6] = rows[6 * i..6 * i + 6].try_into().unwrap();
                    let (ray, len, ok) = ray_from_row(r, shift);
                    assert_eq!(bits(&rays[i]), bits(&ray), "row {i} of {n}: {r:?}, {shift}");
                    assert_eq!(lens[i].to_bits(), len.to_bits(), "row {i} of {n}: its length");
                    bad_rows += usize::from(!ok);
                    rows_seen += 1;
                    let mut one = [Ray::new(Vec3::ZERO, Vec3::X); 4];
                    let mut four = rows[6 * i..6 * i + 6].repeat(4);
                    four[6..].copy_from_slice(&[1.0f32, 2.0, 3.0, 0.0, 0.0, 1.0].repeat(3));
                    assert_eq!(rays_from_f32_rows(&four, shift, &mut one, &mut [0.0; 4]), ok, "row {i}'s verdict");
                }
            }
        }
        // Measured: 576 of 1,296 rows are not rays (the 432 under the third
        // shift among them: their origins leave `f32`).
        assert!(bad_rows > 500 && bad_rows < rows_seen / 2, "{bad_rows} of {rows_seen}");
    }
}
