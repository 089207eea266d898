//! Phong normal fields (§4.1–4.2, eq. 4), fitted by least squares.

use super::knn::PointTree;
use super::{NormalField, Splat};
use glam::Vec3;
use kiddo::SquaredEuclidean;
use rayon::prelude::*;

/// Fewest same-side normals a field is fitted from.
pub const MIN_FIELD_POINTS: usize = 6;

/// Fit the linear normal field of `splat` (eq. 4) to the normals of the
/// points within the normal-field ellipse of `factor` times the splat's radii
/// (fig. 15).
///
/// Each normal `m` is taken in the tangent-plane form of fig. 13,
/// `x = m·u / m·n`, `y = m·v / m·n`, at normalised local coordinates
/// `(u, v)` (divided by the radii). The two equations
/// `x_c + α u_i = x_i`, `y_c + β v_i = y_i` of §4.2 are independent line
/// fits. Normals facing away (`m·n < 0.25`) or points farther from the plane
/// than the field radius are left out. Returns `None` (the caller falls back
/// to [`NormalField::FLAT`]) with fewer than [`MIN_FIELD_POINTS`] points, a
/// singular fit or a non-finite result.
#[must_use]
pub fn fit_field(
    splat: &Splat,
    factor: f32,
    neighbours: impl Iterator<Item = usize>,
    points: &[Vec3],
    normals: &[Vec3],
) -> Option<NormalField> {
    let (ru, rv) = (f64::from(splat.radii.x), f64::from(splat.radii.y));
    let reach = f64::from(factor) * ru.max(rv);
    let f2 = f64::from(factor) * f64::from(factor);
    let (c, n, u, v) = (
        splat.center.as_dvec3(),
        splat.normal.as_dvec3(),
        splat.u_axis.as_dvec3(),
        splat.v_axis.as_dvec3(),
    );
    // Sums for the two line fits.
    let (mut cnt, mut su, mut sv, mut suu, mut svv) = (0f64, 0f64, 0f64, 0f64, 0f64);
    let (mut sx, mut sy, mut sux, mut svy) = (0f64, 0f64, 0f64, 0f64);
    for j in neighbours {
        let d = points[j].as_dvec3() - c;
        if d.dot(n).abs() > reach {
            continue;
        }
        let (pu, pv) = (d.dot(u) / ru, d.dot(v) / rv);
        if pu * pu + pv * pv > f2 {
            continue;
        }
        let m = normals[j].as_dvec3();
        let mn = m.dot(n);
        if mn.is_nan() || mn < 0.25 {
            continue;
        }
        let (x, y) = (m.dot(u) / mn, m.dot(v) / mn);
        cnt += 1.0;
        su += pu;
        sv += pv;
        suu += pu * pu;
        svv += pv * pv;
        sx += x;
        sy += y;
        sux += pu * x;
        svy += pv * y;
    }
    if cnt < MIN_FIELD_POINTS as f64 {
        return None;
    }
    let var_u = suu - su * su / cnt;
    let var_v = svv - sv * sv / cnt;
    if var_u.is_nan() || var_v.is_nan() || var_u <= 1e-3 * cnt || var_v <= 1e-3 * cnt {
        return None;
    }
    let alpha = (sux - su * sx / cnt) / var_u;
    let beta = (svy - sv * sy / cnt) / var_v;
    let xc = (sx - alpha * su) / cnt;
    let yc = (sy - beta * sv) / cnt;
    let field = NormalField {
        xc: xc as f32,
        yc: yc as f32,
        alpha: alpha as f32,
        beta: beta as f32,
    };
    let ok = [field.xc, field.yc, field.alpha, field.beta]
        .iter()
        .all(|x| x.is_finite() && x.abs() < 100.0);
    ok.then_some(field)
}

/// Fit every splat's normal field in parallel (neighbours found with the
/// point kd-tree); returns how many fell back to [`NormalField::FLAT`].
pub fn fit_all(
    splats: &mut [Splat],
    factor: f32,
    tree: &PointTree,
    points: &[Vec3],
    normals: &[Vec3],
) -> usize {
    splats
        .par_iter_mut()
        .map(|s| {
            let reach = factor * s.radii.x.max(s.radii.y);
            let found =
                tree.within_unsorted::<SquaredEuclidean>(&s.center.to_array(), reach * reach);
            match fit_field(
                s,
                factor,
                found.iter().map(|nb| nb.item as usize),
                points,
                normals,
            ) {
                Some(f) => {
                    s.field = f;
                    0
                }
                None => {
                    s.field = NormalField::FLAT;
                    1
                }
            }
        })
        .sum()
}
