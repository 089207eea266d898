//! Range noise: how far the points scatter about the surface, and moving
//! them onto it. Each point's neighbourhood (the growth graph of §2) is fitted
//! with a quadratic height field over the point's tangent plane,
//! `h(x, y) = a + b x + c y + d x² + e xy + f y²`; the fit follows the
//! surface's curvature, so what is left is noise. The noise of the cloud is
//! the median scatter; a noisy cloud has its points moved to `h(0, 0)`
//! along their normals (a moving-least-squares projection of degree two),
//! and their normals are then fitted again to the moved points
//! ([`normals_after`]).

use super::fit::{
    COLLINEAR, MIN_QUADRIC_POINTS as MIN_POINTS, height_rows, normal_equations, plane_fit, solve6,
};
use super::knn::Knn;
use glam::{DVec3, Vec3};
use rayon::prelude::*;

/// One point's quadratic fit: the height of the fitted surface above the
/// point (along its normal) and the standard deviation of the neighbourhood
/// about it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Local {
    /// `h(0, 0)`: where the fitted surface lies along the point's normal.
    pub offset: f32,
    /// Scatter of the neighbourhood about the fitted surface (unbiased for
    /// its six parameters).
    pub sd: f32,
}

/// The quadratic fit at every point over its graph neighbours facing the
/// same way (consistently oriented `normals`; see the module notes); `None`
/// where the neighbourhood is too small or degenerate (one scan line) to fit.
#[must_use]
pub fn fit_all(points: &[Vec3], normals: &[Vec3], knn: &Knn) -> Vec<Option<Local>> {
    (0..points.len())
        .into_par_iter()
        .with_min_len(1024)
        .map_init(
            || (Vec::new(), Vec::new()),
            |(nb, rows), i| {
                // The point's own side only: the far face of a thin plate
                // has its normals turned the other way.
                nb.clear();
                nb.extend(same_facing(knn, normals, i));
                fit(points, normals[i], i, nb, rows)
            },
        )
        .collect()
}

/// The share of [`quiet_noise`]'s points whose fits it lets lie above
/// their bound or fail: the order statistic it bounds the median by sits
/// this share of the points above the middle.
pub const BOUND_SLACK: f64 = 0.01;

/// About how many points [`quiet_noise`] fits for the figure it reports.
pub const NOISE_SAMPLE: usize = 8192;

/// The noise (the median of [`fit_all`]'s `sd` over the points not
/// `skip`ped) where a bound proves it at most `below`: then the median of
/// a sample (every point in a stride that fits about [`NOISE_SAMPLE`]),
/// for the report; `None` where the bound does not hold (then fit all).
///
/// The bound: each point's least-squares quadric leaves at most the
/// scatter of the zero quadric (its heights above its own tangent plane,
/// `h = (q − p)·n`), `sd ≤ u = (Σh² / (N − 6))^½` over the same
/// neighbours, a dozen dot products where the fit solves six equations.
/// Order statistics keep the order of their values, so the median of `sd`
/// is at most `u`'s at the middle; taken [`BOUND_SLACK`] of the points
/// above it, the few fits that fail (a singular system, dropped from the
/// median) or that rounding leaves above `u` cannot move it past.
#[must_use]
pub fn quiet_noise(
    points: &[Vec3],
    normals: &[Vec3],
    knn: &Knn,
    skip: &[bool],
    below: f64,
) -> Option<f64> {
    let asked: Vec<usize> = (0..points.len()).filter(|&i| !skip[i]).collect();
    let stride = (asked.len() / NOISE_SAMPLE).max(1);
    let sample: Vec<usize> = asked.iter().copied().step_by(stride).collect();
    // The bound of the sample first: above (a noisy cloud: the noisy
    // scan's 4.5 times the noise asked for, the bunny sample's 0.82), no
    // answer without bounding every point. Each point is bounded once: the
    // sample's bounds are kept for the whole cloud's (the order statistic
    // does not depend on the order the bounds come in).
    // Not a number is not within `below`.
    let within = |u: f64| u <= below;
    if asked.is_empty() {
        return None;
    }
    let upper: Vec<f64> = (sample.par_iter().with_min_len(1024))
        .map(|&i| zero_quadric(points, normals, knn, i))
        .collect();
    if !within(order_stat(&mut upper.clone())) {
        return None;
    }
    if stride > 1 {
        // Every point's, the sample's (each `stride`th) as they were.
        let mut all: Vec<f64> = (asked.par_iter().enumerate().with_min_len(1024))
            .map(|(k, &i)| {
                if k % stride == 0 {
                    upper[k / stride]
                } else {
                    zero_quadric(points, normals, knn, i)
                }
            })
            .collect();
        if !within(order_stat(&mut all)) {
            return None;
        }
    }
    let mut sd: Vec<f32> = sample
        .into_par_iter()
        .map_init(
            || (Vec::new(), Vec::new()),
            |(nb, rows), i| {
                nb.clear();
                nb.extend(same_facing(knn, normals, i));
                fit(points, normals[i], i, nb, rows).map(|l| l.sd)
            },
        )
        .flatten()
        .collect();
    if sd.is_empty() {
        return Some(0.0);
    }
    let mid = sd.len() / 2;
    let (_, m, _) = sd.select_nth_unstable_by(mid, f32::total_cmp);
    Some(f64::from(*m))
}

/// [`quiet_noise`]'s order statistic of the bounds `upper` ([`BOUND_SLACK`]
/// of them above the middle); it reorders them.
fn order_stat(upper: &mut [f64]) -> f64 {
    let len = upper.len();
    let at = (len / 2 + (BOUND_SLACK * len as f64).ceil() as usize).min(len.max(1) - 1);
    *upper.select_nth_unstable_by(at, f64::total_cmp).1
}

/// [`quiet_noise`]'s bound at point `i`: the scatter its [`fit`] leaves
/// with every coefficient zero, in the fit's `f64` (infinite where the
/// fit has too few points).
fn zero_quadric(points: &[Vec3], normals: &[Vec3], knn: &Knn, i: usize) -> f64 {
    let Some(n) = normals[i].as_dvec3().try_normalize() else {
        return f64::INFINITY;
    };
    let p = points[i].as_dvec3();
    let (mut count, mut sum) = (1usize, 0f64);
    for j in same_facing(knn, normals, i) {
        let h = (points[j as usize].as_dvec3() - p).dot(n);
        sum += h * h;
        count += 1;
    }
    if count < MIN_POINTS {
        return f64::INFINITY;
    }
    (sum / count.saturating_sub(6).max(1) as f64).sqrt()
}

/// Point `i`'s graph neighbours whose normals face its way: a surface's
/// own side, not the far face of a thin plate.
fn same_facing<'a>(
    knn: &'a Knn,
    normals: &'a [Vec3],
    i: usize,
) -> impl Iterator<Item = u32> + Clone + 'a {
    knn.of(i)
        .iter()
        .copied()
        .filter(move |&j| normals[j as usize].dot(normals[i]) > 0.0)
}

/// The quadratic fit of point `i` (normal `n`) over its neighbours `nb`,
/// `samples` a buffer for its least-squares rows.
fn fit(
    points: &[Vec3],
    n: Vec3,
    i: usize,
    nb: &[u32],
    samples: &mut Vec<([f64; 6], f64)>,
) -> Option<Local> {
    let n = n.as_dvec3().try_normalize()?;
    let p = points[i].as_dvec3();
    let u = n.any_orthonormal_vector();
    let v = n.cross(u);
    // Scale the coordinates by the neighbourhood's size so the normal
    // equations are well conditioned at any scale.
    // The root of the largest square: the largest length bit for bit
    // (as in `height_rows`).
    let scale = nb
        .iter()
        .map(|&j| (points[j as usize].as_dvec3() - p).length_squared())
        .fold(0.0f64, f64::max)
        .sqrt();
    if scale.is_nan() || scale <= 0.0 || nb.len() + 1 < MIN_POINTS {
        return None;
    }
    samples.clear();
    samples.extend(
        std::iter::once(p)
            .chain(nb.iter().map(|&j| points[j as usize].as_dvec3()))
            .map(|q| {
                let d: DVec3 = (q - p) / scale;
                let (x, y, h) = (d.dot(u), d.dot(v), d.dot(n));
                ([1.0, x, y, x * x, x * y, y * y], h)
            }),
    );
    let (ata, atb) = normal_equations(samples);
    let coef = solve6(ata, atb)?;
    let ssr: f64 = samples
        .iter()
        .map(|(row, h)| {
            let f: f64 = row.iter().zip(&coef).map(|(a, b)| a * b).sum();
            (h - f) * (h - f)
        })
        .sum();
    let dof = samples.len().saturating_sub(6).max(1) as f64;
    let local = Local {
        offset: (coef[0] * scale) as f32,
        sd: ((ssr / dof).sqrt() * scale) as f32,
    };
    (local.offset.is_finite() && local.sd.is_finite()).then_some(local)
}

/// The normal of every point's fitted surface after the projection: the
/// least-squares plane of the projected point and its graph neighbours
/// facing the same way (the set [`fit_all`] fits), turned to the side of
/// `normals`; `None` where that set is too small or collinear
/// ([`COLLINEAR`]).
///
/// The normals the points were moved along were estimated from the noisy
/// points, whose scatter across a scan line tilts the plane of a
/// neighbourhood that spans two or three lines. The same neighbourhood
/// fitted again after the projection gives the surface's tilt: on the
/// coarse scan-line bunny of issue 23 the median angle to the exact mesh's
/// normal falls from 11.8° to 7.1° (5.3° for the same fit to the
/// noise-free scan).
#[must_use]
pub fn normals_after(points: &[Vec3], normals: &[Vec3], knn: &Knn) -> Vec<Option<Vec3>> {
    (0..points.len())
        .into_par_iter()
        .with_min_len(1024)
        .map(|i| {
            let n = normals[i];
            let nb = same_facing(knn, normals, i).map(|j| points[j as usize]);
            if nb.clone().count() + 1 < MIN_POINTS {
                return None;
            }
            let (_, vals, vecs) = plane_fit(std::iter::once(points[i]).chain(nb));
            let m = vecs[0].as_vec3();
            let m = if m.dot(n) < 0.0 { -m } else { m };
            (m.is_finite() && m.length_squared() > 0.5 && vals[1] > COLLINEAR * vals[2])
                .then_some(m)
        })
        .collect()
}

/// Whether `offsets` (points minus a point on the surface) curve
/// significantly against their scatter: the F statistic of the quadratic
/// height field over the plane of normal `n` (six parameters) against the
/// tilted plane (three), both fitted by least squares, `((RSS₃ − RSS₆) / 3)
/// / (RSS₆ / (N − 6))`; `None` where they do not determine a quadric. On a
/// flat face with range noise it is about 1; a curved surface whose bend
/// across the neighbourhood exceeds the noise gives far more.
#[must_use]
pub fn curvature_f(offsets: &[Vec3], n: Vec3) -> Option<f64> {
    let (rows, _) = height_rows(offsets, n, MIN_POINTS)?;
    let (ata, atb) = normal_equations(&rows);
    let a3 = glam::DMat3::from_cols_array_2d(&[
        [ata[0][0], ata[0][1], ata[0][2]],
        [ata[1][0], ata[1][1], ata[1][2]],
        [ata[2][0], ata[2][1], ata[2][2]],
    ]);
    if a3.determinant().abs() <= 1e-12 * ata[0][0].powi(3) {
        return None;
    }
    let plane = a3.inverse() * glam::DVec3::new(atb[0], atb[1], atb[2]);
    let quad = solve6(ata, atb)?;
    // Each row's fitted height sums its terms in order, the plane's first
    // three only: its quadratic coefficients are zero, and a zero product
    // added changes no sum but a zero's sign, which the squared residual
    // drops (a row's quadratic terms are finite, or not a number only
    // where its linear ones are not), so the sums are the six terms'.
    let rss = |coef: &[f64]| -> f64 {
        rows.iter()
            .map(|(row, h)| {
                let f: f64 = row.iter().zip(coef).map(|(a, b)| a * b).sum();
                (h - f) * (h - f)
            })
            .sum()
    };
    let (rss3, rss6) = (rss(&plane.to_array()), rss(&quad));
    let dof = (rows.len() - 6).max(1) as f64;
    let f = ((rss3 - rss6) / 3.0) / (rss6 / dof).max(f64::MIN_POSITIVE);
    f.is_finite().then_some(f)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use crate::splat::fit::height_fit;
    use crate::splat::knn::build_tree;

    /// [`curvature_f`] as it was, the plane's residuals summed over all
    /// six terms (its quadratic ones zero).
    fn curvature_f_six(offsets: &[Vec3], n: Vec3) -> Option<f64> {
        let (rows, _) = height_rows(offsets, n, MIN_POINTS)?;
        let (ata, atb) = normal_equations(&rows);
        let a3 = glam::DMat3::from_cols_array_2d(&[
            [ata[0][0], ata[0][1], ata[0][2]],
            [ata[1][0], ata[1][1], ata[1][2]],
            [ata[2][0], ata[2][1], ata[2][2]],
        ]);
        if a3.determinant().abs() <= 1e-12 * ata[0][0].powi(3) {
            return None;
        }
        let plane = a3.inverse() * glam::DVec3::new(atb[0], atb[1], atb[2]);
        let plane = [plane.x, plane.y, plane.z, 0.0, 0.0, 0.0];
        let quad = solve6(ata, atb)?;
        let rss = |coef: &[f64; 6]| -> f64 {
            rows.iter()
                .map(|(row, h)| {
                    let f: f64 = row.iter().zip(coef).map(|(a, b)| a * b).sum();
                    (h - f) * (h - f)
                })
                .sum()
        };
        let (rss3, rss6) = (rss(&plane), rss(&quad));
        let dof = (rows.len() - 6).max(1) as f64;
        let f = ((rss3 - rss6) / 3.0) / (rss6 / dof).max(f64::MIN_POSITIVE);
        f.is_finite().then_some(f)
    }

    /// The plane's residuals over its three terms are the six terms' bit
    /// for bit: 2,400 neighbourhoods of 0 to 59 offsets at three scales,
    /// flat (some exactly, heights zero), curved and scattered, a NaN or an
    /// infinite offset in some; most give an F (measured: 1,657).
    #[test]
    fn curvature_f_sums_the_planes_three_terms_as_six() {
        let mut rng = SplitMix64::new(54);
        let mut answered = 0;
        for c in 0..2400usize {
            let scale = [1e-3f32, 1.0, 1e3][c % 3];
            let len = c % 60;
            let kind = (c / 3) % 4;
            let mut offsets: Vec<Vec3> = (0..len)
                .map(|_| {
                    let (x, y) = (scale * rng.range(-1.0, 1.0), scale * rng.range(-1.0, 1.0));
                    let z = match kind {
                        0 => 0.0,
                        1 => 0.01 * scale * rng.next_gaussian() as f32,
                        2 => (x * x + y * y) / scale,
                        _ => scale * rng.range(-1.0, 1.0),
                    };
                    Vec3::new(x, y, z)
                })
                .collect();
            if len > 20 && c % 7 == 0 {
                offsets[3].y = f32::NAN;
            }
            if len > 20 && c % 11 == 0 {
                offsets[4].z = f32::INFINITY;
            }
            let n = (Vec3::Z + 0.2 * rng.unit()).normalize();
            let (got, want) = (curvature_f(&offsets, n), curvature_f_six(&offsets, n));
            assert_eq!(got.map(f64::to_bits), want.map(f64::to_bits), "case {c}");
            answered += usize::from(got.is_some());
        }
        assert!(answered > 1500, "answered {answered}");
    }

    /// A patch of the sphere of radius 1 around its north pole, with range
    /// noise `sigma` along the radius.
    fn cap(sigma: f32) -> (Vec<Vec3>, Vec<Vec3>) {
        let mut rng = SplitMix64::new(3);
        let mut pts = Vec::new();
        for i in 0..60 {
            for j in 0..60 {
                let (x, y) = ((i as f32 - 30.0) * 0.01, (j as f32 - 30.0) * 0.01);
                let dir = Vec3::new(x, y, 1.0).normalize();
                pts.push(dir * (1.0 + sigma * rng.next_gaussian() as f32));
            }
        }
        let normals = pts.iter().map(|p| p.normalize()).collect();
        (pts, normals)
    }

    /// `height_fit` with 3 terms fits a plane, with 6 a quadric: a tilted
    /// plane's points score in full under both, a paraboloid's under the
    /// quadric only, and a crease (two planes) under neither.
    #[test]
    fn height_fit_takes_a_plane_or_a_quadric() {
        let grid = |h: &dyn Fn(f32, f32) -> f32| -> Vec<Vec3> {
            (0..11)
                .flat_map(|i| (0..11).map(move |j| (i as f32 * 0.1 - 0.5, j as f32 * 0.1 - 0.5)))
                .map(|(x, y)| Vec3::new(x, y, h(x, y)))
                .collect()
        };
        let tol = 1e-3;
        let n = grid(&|_, _| 0.0).len() as f32;
        let plane = grid(&|x, y| 0.3 * x - 0.2 * y + 0.1);
        let bowl = grid(&|x, y| x * x + 0.5 * y * y);
        let crease = grid(&|x, _| x.abs());
        let fit = |p: &[Vec3], terms| height_fit(p, Vec3::Z, tol, terms, 6).unwrap();
        assert!(fit(&plane, 3) > n - 0.01 && fit(&plane, 6) > n - 0.01);
        eprintln!(
            "bowl plane {} quadric {}, crease quadric {}",
            fit(&bowl, 3),
            fit(&bowl, 6),
            fit(&crease, 6)
        );
        // Measured: the bowl's plane 0 of 121, its quadric 121; the
        // crease's quadric 0.
        assert!(fit(&bowl, 3) < 0.1 * n && fit(&bowl, 6) > n - 0.01);
        assert!(fit(&crease, 6) < 0.1 * n, "{}", fit(&crease, 6));
        assert!(height_fit(&plane[..5], Vec3::Z, tol, 6, 6).is_none());
    }

    #[test]
    fn curvature_is_not_noise_and_noise_is_measured() {
        for sigma in [0.0f32, 0.002] {
            let (pts, nrm) = cap(sigma);
            let knn = Knn::build(&build_tree(&pts), &pts, 24);
            let fits: Vec<Local> = fit_all(&pts, &nrm, &knn).into_iter().flatten().collect();
            assert!(fits.len() > pts.len() * 9 / 10);
            let mut sd: Vec<f32> = fits.iter().map(|f| f.sd).collect();
            sd.sort_by(f32::total_cmp);
            let med = sd[sd.len() / 2];
            // Clean: the quadric follows the sphere (a plane would leave
            // the sagitta, ~1e-4 here). Noisy: about sigma.
            if sigma == 0.0 {
                assert!(med < 2e-6, "clean sphere scatter {med}");
            } else {
                assert!(
                    (med / sigma - 1.0).abs() < 0.25,
                    "scatter {med} for noise {sigma}"
                );
            }
            // Projection lands closer to the sphere than the points were.
            let before: f32 = pts.iter().map(|p| (p.length() - 1.0).abs()).sum();
            let after: f32 = pts
                .iter()
                .zip(&nrm)
                .zip(fit_all(&pts, &nrm, &knn))
                .map(|((p, n), f)| ((*p + *n * f.map_or(0.0, |f| f.offset)).length() - 1.0).abs())
                .sum();
            if sigma > 0.0 {
                assert!(after < 0.5 * before, "{after} vs {before}");
            } else {
                assert!(after < 1e-3 * pts.len() as f32 * 1e-3, "{after}");
            }
        }
    }

    /// Every point's quadric leaves at most its zero quadric's scatter
    /// ([`quiet_noise`]'s bound), and under a bound that holds the noise
    /// is the full median (fewer points than a stride's sample: all fit).
    #[test]
    fn the_zero_quadric_bounds_the_fit() {
        for sigma in [0.0f32, 0.002] {
            let (pts, nrm) = cap(sigma);
            let knn = Knn::build(&build_tree(&pts), &pts, 24);
            let fits = fit_all(&pts, &nrm, &knn);
            let mut sd = Vec::new();
            for (i, f) in fits.iter().enumerate() {
                let u = zero_quadric(&pts, &nrm, &knn, i);
                let f = f.expect("a cap's neighbourhoods fit");
                assert!(f64::from(f.sd) <= u * (1.0 + 1e-6), "{} over {u}", f.sd);
                sd.push(f.sd);
            }
            let mid = sd.len() / 2;
            let median = f64::from(*sd.select_nth_unstable_by(mid, f32::total_cmp).1);
            let skip = vec![false; pts.len()];
            assert_eq!(quiet_noise(&pts, &nrm, &knn, &skip, 1.0), Some(median));
            // Below the bound's order statistic: no answer (fit all).
            let bound = quiet_bound(&pts, &nrm, &knn);
            assert!(quiet_noise(&pts, &nrm, &knn, &skip, 0.99 * bound).is_none());
            assert_eq!(quiet_noise(&pts, &nrm, &knn, &skip, bound), Some(median));
        }
    }

    /// The order statistic [`quiet_noise`] compares, as it takes it.
    fn quiet_bound(pts: &[Vec3], nrm: &[Vec3], knn: &Knn) -> f64 {
        let mut u: Vec<f64> = (0..pts.len()).map(|i| zero_quadric(pts, nrm, knn, i)).collect();
        let at = u.len() / 2 + (BOUND_SLACK * u.len() as f64).ceil() as usize;
        *u.select_nth_unstable_by(at, f64::total_cmp).1
    }

    #[test]
    fn normals_after_the_projection_are_nearer_the_surface() {
        let (pts, _) = cap(0.004);
        // Normals as a noisy neighbourhood gives them: tilted by the noise.
        let knn = Knn::build(&build_tree(&pts), &pts, 24);
        let nrm: Vec<Vec3> = crate::splat::normals::estimate(&pts, &knn)
            .into_iter()
            .map(|n| if n.z < 0.0 { -n } else { n })
            .collect();
        let moved: Vec<Vec3> = pts
            .iter()
            .zip(&nrm)
            .zip(fit_all(&pts, &nrm, &knn))
            .map(|((p, n), f)| *p + *n * f.map_or(0.0, |f| f.offset))
            .collect();
        let after = normals_after(&moved, &nrm, &knn);
        let angle = |n: Vec3, p: Vec3| n.dot(p.normalize()).clamp(-1.0, 1.0).acos();
        let (mut before, mut now) = (0f32, 0f32);
        for ((p, n), a) in moved.iter().zip(&nrm).zip(&after) {
            let a = a.expect("a cap's neighbourhoods are planar enough");
            assert!(a.dot(*n) > 0.0, "turned to the other side");
            before += angle(*n, *p);
            now += angle(a, *p);
        }
        assert!(now < 0.7 * before, "{now} vs {before}");
    }

    #[test]
    fn one_line_has_no_quadric() {
        let pts: Vec<Vec3> = (0..40)
            .map(|i| Vec3::new(i as f32 * 0.01, 0.0, 0.0))
            .collect();
        let nrm = vec![Vec3::Z; pts.len()];
        let knn = Knn::build(&build_tree(&pts), &pts, 12);
        assert!(fit_all(&pts, &nrm, &knn).iter().all(Option::is_none));
    }
}
