//! Phong normal fields (§4.1–4.2, eq. 4), fitted by least squares.

use super::knn::PointTree;
use super::{NormalField, Splat};
use glam::Vec3;
use kiddo::SquaredEuclidean;
use rayon::prelude::*;

/// Fewest same-side normals a field is fitted from.
pub const MIN_FIELD_POINTS: usize = 6;

/// Each normal `m` enters the fit with weight `(m·n)^ANGLE_WEIGHT_POWER`,
/// so its residual counts as an angle (see [`fit_field`]).
pub const ANGLE_WEIGHT_POWER: i32 = 4;

/// A fitted field, and for a circular splat the tangent frame it is
/// expressed in.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FieldFit {
    /// The field of eq. (4).
    pub field: NormalField,
    /// New `(u_axis, v_axis)` along the principal directions of the fitted
    /// normal variation (circular splats only; an ellipse keeps its axes).
    pub axes: Option<(Vec3, Vec3)>,
}

/// Solves the 3×3 normal equations `m · [c, a, b] = r` by Cramer's rule;
/// `None` when singular.
fn solve3(m: [[f64; 3]; 3], r: [f64; 3]) -> Option<[f64; 3]> {
    let det = |m: [[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(m);
    let scale = m.iter().flatten().fold(0f64, |a, &x| a.max(x.abs()));
    if d.is_nan() || d.abs() <= 1e-9 * scale * scale * scale {
        return None;
    }
    let mut out = [0.0; 3];
    for (k, o) in out.iter_mut().enumerate() {
        let mut mk = m;
        for i in 0..3 {
            mk[i][k] = r[i];
        }
        *o = det(mk) / d;
    }
    Some(out)
}

/// Fit the linear normal field of `splat` (eq. 4) to the normals of the
/// points within the normal-field ellipse of `factor` times the splat's radii
/// (fig. 15).
///
/// Each normal `m` is taken in the tangent-plane form of fig. 13,
/// `x = m·u / m·n`, `y = m·v / m·n`, at normalised local coordinates
/// `(u, v)` (divided by the radii). Eq. (4) has no cross terms — `x` varies
/// with `u` only and `y` with `v` only — which holds when `u` and `v` are
/// the principal directions of the surface, as for Botsch et al.'s
/// elliptical splats. So the full linear model `x = x_c + a u + b v`,
/// `y = y_c + c u + d v` is fitted by least squares first; for a circular
/// splat, whose tangent frame is arbitrary, the frame is then turned to the
/// eigenvectors of the symmetric part of `[[a, b], [c, d]]` (the principal
/// directions, where the cross terms vanish), and `α`, `β` are its
/// eigenvalues; an ellipse keeps its axes, with `α = a`, `β = d`. Normals
/// facing away (`m·n < 0.25`) or points farther from the plane than the
/// field radius are left out.
///
/// Each normal's row is weighted by `(m·n)⁴` ([`ANGLE_WEIGHT_POWER`]): a
/// tangent-plane coordinate is `tan θ` of the normal's tilt `θ`, and
/// `d(tan θ) = dθ / cos² θ`, so unweighted residuals in `x`, `y` count a
/// steep normal's angle error up to `1/cos⁴ θ` (240× at the `m·n = 0.25`
/// cut-off) more than a level one's. Unweighted, the few steep normals at
/// the rim of a large splat over a curved surface decided its field: at
/// coarse budgets Phong splats shaded worse than flat ones (issue 24,
/// `docs/development.md`). Returns `None` (the caller falls back to
/// [`NormalField::FLAT`]) with fewer than [`MIN_FIELD_POINTS`] points, a
/// singular fit or a non-finite result.
#[must_use]
pub fn fit_field(
    splat: &Splat,
    factor: f32,
    neighbours: impl Iterator<Item = usize>,
    points: &[Vec3],
    normals: &[Vec3],
) -> Option<FieldFit> {
    let (ru, rv) = (f64::from(splat.radii.x), f64::from(splat.radii.y));
    let reach = f64::from(factor) * ru.max(rv);
    let f2 = f64::from(factor) * f64::from(factor);
    let (c, n, u, v) = (
        splat.center.as_dvec3(),
        splat.normal.as_dvec3(),
        splat.u_axis.as_dvec3(),
        splat.v_axis.as_dvec3(),
    );
    // Normal equations of both fits: design rows [1, u, v].
    let mut m = [[0f64; 3]; 3];
    let (mut rx, mut ry) = ([0f64; 3], [0f64; 3]);
    let mut cnt = 0usize;
    for j in neighbours {
        let d = points[j].as_dvec3() - c;
        if d.dot(n).abs() > reach {
            continue;
        }
        let (pu, pv) = (d.dot(u) / ru, d.dot(v) / rv);
        if pu * pu + pv * pv > f2 {
            continue;
        }
        let mm = normals[j].as_dvec3();
        let mn = mm.dot(n);
        if mn.is_nan() || mn < 0.25 {
            continue;
        }
        let (x, y) = (mm.dot(u) / mn, mm.dot(v) / mn);
        let w = (mn / mm.length()).powi(ANGLE_WEIGHT_POWER);
        let row = [1.0, pu, pv];
        for a in 0..3 {
            for b in 0..3 {
                m[a][b] += w * row[a] * row[b];
            }
            rx[a] += w * row[a] * x;
            ry[a] += w * row[a] * y;
        }
        cnt += 1;
    }
    if cnt < MIN_FIELD_POINTS {
        return None;
    }
    // Both coordinates must spread: a point set along a line fits nothing
    // (weighted variances against the total weight).
    let wsum = m[0][0];
    let var_u = m[1][1] - m[0][1] * m[0][1] / wsum;
    let var_v = m[2][2] - m[0][2] * m[0][2] / wsum;
    if !(var_u > 1e-3 * wsum && var_v > 1e-3 * wsum) {
        return None;
    }
    let [xc, a, b] = solve3(m, rx)?;
    let [yc, cc, d] = solve3(m, ry)?;
    let (field, axes) = if splat.radii.x == splat.radii.y {
        let (s11, s12, s22) = (a, 0.5 * (b + cc), d);
        let theta = 0.5 * (2.0 * s12).atan2(s11 - s22);
        let (sn, cs) = theta.sin_cos();
        let alpha = s11 * cs * cs + 2.0 * s12 * sn * cs + s22 * sn * sn;
        let beta = s11 * sn * sn - 2.0 * s12 * sn * cs + s22 * cs * cs;
        let nu = (u * cs + v * sn).normalize();
        let nv = n.cross(nu).normalize();
        (
            NormalField {
                xc: (xc * cs + yc * sn) as f32,
                yc: (-xc * sn + yc * cs) as f32,
                alpha: alpha as f32,
                beta: beta as f32,
            },
            Some((nu.as_vec3(), nv.as_vec3())),
        )
    } else {
        (
            NormalField {
                xc: xc as f32,
                yc: yc as f32,
                alpha: a as f32,
                beta: d as f32,
            },
            None,
        )
    };
    let ok = [field.xc, field.yc, field.alpha, field.beta]
        .iter()
        .all(|x| x.is_finite() && x.abs() < 100.0);
    ok.then_some(FieldFit { field, axes })
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
                    s.field = f.field;
                    if let Some((u, v)) = f.axes {
                        s.u_axis = u;
                        s.v_axis = v;
                    }
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
