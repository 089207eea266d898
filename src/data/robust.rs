//! A robust centre and size of a point set: the origin a reader stores a
//! cloud relative to, and the unit frame generation runs in.

use glam::DVec3;
use rayon::prelude::*;

/// At most this many points (a regular stride through the finite ones)
/// estimate the robust centre and size.
const ROBUST_SAMPLE: usize = 1 << 20;

/// A centre and a size of a point set that a few far outliers do not move:
/// per axis the median and the 10th-to-90th percentile range (from at most
/// [`ROBUST_SAMPLE`] points), the size being the largest range. `point(i)`
/// gives point `i` of `n`; non-finite ones are left out. `None` when no
/// point is finite.
pub fn robust_centre_size(n: usize, point: impl Fn(usize) -> DVec3) -> Option<(DVec3, f64)> {
    let stride = n.div_ceil(ROBUST_SAMPLE).max(1);
    // Every `stride`-th finite point, one buffer an axis, gathered on the
    // calling thread (buffers a worker allocates stay in its arena and
    // raised the 2M bunny's peak: docs/notes/generation.md, eighteenth
    // session, h18d).
    let mut axes: [Vec<f64>; 3] = Default::default();
    for p in (0..n).map(&point).filter(|p| p.is_finite()).step_by(stride) {
        for (v, c) in axes.iter_mut().zip(p.to_array()) {
            v.push(c);
        }
    }
    if axes[0].is_empty() {
        return None;
    }
    // The three axes' selects at once: each axis the same selects on the
    // same array as one after another, so the same bits.
    let mut per_axis = [(0.0, 0.0); 3];
    axes.par_iter_mut()
        .zip(per_axis.par_iter_mut())
        .for_each(|(vals, out)| *out = centre_and_range(vals));
    let centre = per_axis.map(|a| a.0);
    let size = per_axis.iter().fold(0f64, |size, a| size.max(a.1));
    Some((DVec3::from(centre), size))
}

/// A box whose diagonal is under this share of the bounding box's is
/// widened by a few far points: `ϵ` is then taken from the box without
/// them ([`trimmed_diagonal`]), by whole-cloud generation's lean growth
/// and by a tiled plan alike.
pub const WIDENED_SHARE: f64 = 0.98;

/// The diagonal of the box holding all but the 0.1 % most extreme of
/// `points` along each axis (0 when there are none): a tiled plan's, over
/// the survey's sample.
pub fn trimmed_diagonal(points: &[DVec3]) -> f64 {
    let mut axes: [Vec<f64>; 3] = std::array::from_fn(|a| points.iter().map(|p| p[a]).collect());
    trimmed_diagonal_of(&mut axes, f64::total_cmp, |v| v)
}

/// [`trimmed_diagonal`] of points given as one buffer of coordinates an
/// axis (the same length; reordered), compared by `cmp` and widened to
/// f64 by `wide` (whole-cloud generation keeps them in f32): the three
/// axes' selects at once, the squares summed in axis order.
pub fn trimmed_diagonal_of<T: Copy + Send>(
    axes: &mut [Vec<T>; 3],
    cmp: fn(&T, &T) -> std::cmp::Ordering,
    wide: fn(T) -> f64,
) -> f64 {
    let n = axes[0].len();
    if n == 0 {
        return 0.0;
    }
    let cut = n / 1000;
    let mut sq = [0f64; 3];
    axes.par_iter_mut().zip(sq.par_iter_mut()).for_each(|(axis, sq)| {
        // The high rank selected among the values above the low one (an
        // order statistic is one value: the bits of a select over all).
        let (_, &mut lo, above) = axis.select_nth_unstable_by(cut, cmp);
        let hi = if n - 1 - cut > cut { *above.select_nth_unstable_by(n - 2 - 2 * cut, cmp).1 } else { lo };
        *sq = (wide(hi) - wide(lo)).powi(2);
    });
    sq.iter().fold(0.0, |d2, s| d2 + s).sqrt()
}

/// One axis's median and 10th-to-90th percentile range (`vals` reordered).
/// Each quantile is linear between the two nearest ranks (the median of
/// two is their midpoint). The median's select leaves the values below it
/// before it and those above after it, so the 90th percentile is selected
/// among the values above and the 10th among those below: an order
/// statistic is one value, so the bits are those of three selects over all
/// of them, in two thirds of the work.
fn centre_and_range(vals: &mut [f64]) -> (f64, f64) {
    let last = (vals.len() - 1) as f64;
    let rank = |f: f64| {
        let at = last * f;
        (at.floor() as usize, at - at.floor())
    };
    // Rank `k` of `part`, interpolated by `t` toward the next value up: the
    // least after it in `part`, or `past` (the least value beyond `part`).
    let quantile = |part: &mut [f64], (k, t): (usize, f64), past: f64| {
        let (_, &mut a, above) = part.select_nth_unstable_by(k, f64::total_cmp);
        if t > 0.0 {
            let b = above.iter().copied().fold(past, f64::min);
            a * (1.0 - t) + b * t
        } else {
            a
        }
    };
    let (k5, t5) = rank(0.5);
    let centre = quantile(vals, (k5, t5), f64::INFINITY);
    let at_median = vals[k5];
    let (lower, rest) = vals.split_at_mut(k5);
    let above = &mut rest[1..];
    // A percentile on the median's own rank (two or three values) leans
    // toward the least value above the median.
    let on_median = |t, above: &[f64]| quantile(&mut [at_median], (0, t), above.iter().copied().fold(f64::INFINITY, f64::min));
    let (k9, t9) = rank(0.9);
    let q9 = if k9 == k5 { on_median(t9, above) } else { quantile(above, (k9 - k5 - 1, t9), f64::INFINITY) };
    let (k1, t1) = rank(0.1);
    let q1 = if k1 == k5 { on_median(t1, above) } else { quantile(lower, (k1, t1), at_median) };
    // Halves first: the difference of two coordinates near f64::MAX
    // overflows.
    (centre, 2.0 * (q9 * 0.5 - q1 * 0.5))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The axes at once give the bits of the axes one after another (the
    /// code before, kept here), on scattered points with repeats, a stride
    /// (more points than the sample), non-finite points and none finite.
    #[test]
    fn the_axes_at_once_give_the_serial_bits() {
        fn serial(n: usize, point: impl Fn(usize) -> DVec3) -> Option<(DVec3, f64)> {
            let stride = n.div_ceil(ROBUST_SAMPLE).max(1);
            let sample: Vec<DVec3> = (0..n).map(&point).filter(|p| p.is_finite()).step_by(stride).collect();
            let mut centre = [0.0; 3];
            let mut size = 0f64;
            for (axis, c) in centre.iter_mut().enumerate() {
                let mut vals: Vec<f64> = sample.iter().map(|p| p[axis]).collect();
                if vals.is_empty() {
                    return None;
                }
                let (m, r) = centre_and_range(&mut vals);
                *c = m;
                size = size.max(r);
            }
            Some((DVec3::from(centre), size))
        }
        let mut s = 0x853c_49e6_748f_ea9b_u64;
        let pts: Vec<DVec3> = (0..ROBUST_SAMPLE + ROBUST_SAMPLE / 3)
            .map(|i| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                let f = (s % 1000) as f64 * 0.37;
                match i % 501 {
                    0 => DVec3::new(f64::NAN, f, 1.0),
                    1 => DVec3::splat(1e300),
                    _ => DVec3::new(f, -2.0 * f + (s % 7) as f64, (s >> 20) as f64 * 1e-9),
                }
            })
            .collect();
        for n in [1, 2, 3, 10, 1000, pts.len()] {
            let bits = |r: Option<(DVec3, f64)>| r.map(|(c, s)| (c.to_array().map(f64::to_bits), s.to_bits()));
            assert_eq!(bits(robust_centre_size(n, |i| pts[i])), bits(serial(n, |i| pts[i])), "{n}");
        }
        assert!(robust_centre_size(3, |_| DVec3::NAN).is_none());
    }

    /// An axis's quantiles are those of its values sorted: linear between
    /// the two nearest ranks, at every length from one value up, with
    /// repeats, and with the 10th and 90th percentiles on the median's own
    /// rank (two and three values).
    #[test]
    fn an_axis_quantiles_are_its_sorted_values_quantiles() {
        let mut s = 0x2545_f491_4f6c_dd1d_u64;
        for n in (1..40).chain([101, 1000, 1001, 4097]) {
            let vals: Vec<f64> = (0..n)
                .map(|_| {
                    s ^= s << 13;
                    s ^= s >> 7;
                    s ^= s << 17;
                    ((s % 64) as f64 - 20.0) * 0.37
                })
                .collect();
            let mut sorted = vals.clone();
            sorted.sort_by(f64::total_cmp);
            let last = (n - 1) as f64;
            let q = |f: f64| {
                let at = last * f;
                let (k, t) = (at.floor() as usize, at - at.floor());
                if t > 0.0 { sorted[k] * (1.0 - t) + sorted[k + 1] * t } else { sorted[k] }
            };
            let want = (q(0.5), 2.0 * (q(0.9) * 0.5 - q(0.1) * 0.5));
            let got = centre_and_range(&mut vals.clone());
            assert_eq!((got.0.to_bits(), got.1.to_bits()), (want.0.to_bits(), want.1.to_bits()), "{n}: {got:?} against {want:?}");
        }
    }

    /// The trimmed box leaves out the extreme thousandth on each side of
    /// each axis: 3,000 points on a unit cube's diagonal give its diagonal
    /// less the three trimmed at each end (0.2 %), and as much with three
    /// far points added; 903 points (no cut) keep them.
    #[test]
    fn the_trimmed_diagonal_leaves_out_the_extreme_thousandth() {
        let mut pts: Vec<DVec3> = (0..3000).map(|i| DVec3::splat(i as f64 / 2999.0)).collect();
        let cube = 3f64.sqrt();
        assert!((trimmed_diagonal(&pts) - cube).abs() < 3e-3 * cube);
        pts.extend([DVec3::splat(-50.0), DVec3::new(80.0, 0.5, 0.5), DVec3::new(0.5, 0.5, 1e6)]);
        assert!((trimmed_diagonal(&pts) - cube).abs() < 3e-3 * cube, "{}", trimmed_diagonal(&pts));
        assert!(trimmed_diagonal(&pts[2100..]) > 1e6);
        assert_eq!(trimmed_diagonal(&[]), 0.0);
    }
}
