//! A robust centre and size of a point set: the origin a reader stores a
//! cloud relative to, and the unit frame generation runs in.

use glam::DVec3;

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
    let mut centre = [0.0; 3];
    let mut size = 0f64;
    // Every `stride`-th finite point, gathered once for the three axes.
    let sample: Vec<DVec3> = (0..n)
        .map(&point)
        .filter(|p| p.is_finite())
        .step_by(stride)
        .collect();
    let mut vals: Vec<f64> = Vec::with_capacity(sample.len());
    for (axis, c) in centre.iter_mut().enumerate() {
        vals.clear();
        vals.extend(sample.iter().map(|p| p[axis]));
        if vals.is_empty() {
            return None;
        }
        let last = (vals.len() - 1) as f64;
        // Linear between the two nearest ranks (the median of two is their
        // midpoint).
        let mut quantile = |f: f64| {
            let at = last * f;
            let k = at.floor() as usize;
            let (_, &mut a, above) = vals.select_nth_unstable_by(k, f64::total_cmp);
            let t = at - k as f64;
            if t > 0.0 {
                let b = above.iter().copied().fold(f64::INFINITY, f64::min);
                a * (1.0 - t) + b * t
            } else {
                a
            }
        };
        *c = quantile(0.5);
        // Halves first: the difference of two coordinates near f64::MAX
        // overflows.
        size = size.max(2.0 * (quantile(0.9) * 0.5 - quantile(0.1) * 0.5));
    }
    Some((DVec3::from(centre), size))
}
