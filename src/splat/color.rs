//! Linear colour fields: the colour analogue of the Phong normal field of
//! eq. (4) (§4.1–4.2). A splat's colour varies linearly over its disc,
//! `c(u, v) = c + d_u u + d_v v` at normalised local coordinates `(u, v)`
//! (divided by the radii, as eq. 4's), fitted by least squares to the
//! colours of the points the disc covers. One colour per splat averages
//! texture finer than the splat away; the field keeps its first-order
//! change (a stripe's edge across a splat, a gradient of shading baked
//! into a capture).
//!
//! Fields are a side table beside the splats (`Scene::color_fields`, the
//! splat file's `lin_red_du … lin_blue_dv` properties), present only for
//! models that carry colours and ask for them: a scene without them pays
//! nothing.

use super::generate::SplatParams;
use super::knn::{PointTree, build_tree};
use crate::data::{PointCloud, Splat};
use glam::{DVec3, Vec3};
use kiddo::SquaredEuclidean;
use rayon::prelude::*;

/// Fewest points a colour field is fitted from; fewer keep the constant
/// colour (a zero field).
pub const MIN_COLOR_POINTS: usize = 6;

/// How far from its plane a point may lie and still colour the splat, in
/// splat radii (the larger radius): a point of another sheet under a large
/// disc does not.
pub const COLOR_PLANE_REACH: f64 = 0.25;

pub use crate::data::ColorField;

/// The least-squares field of `splat` over the `(u, v, colour)` samples of
/// the points it covers, with the constant part: `(c, field)`; `None` with
/// fewer than [`MIN_COLOR_POINTS`] samples or when they do not spread in
/// both directions.
fn fit_one(samples: &[(f64, f64, DVec3)]) -> Option<(DVec3, ColorField)> {
    if samples.len() < MIN_COLOR_POINTS {
        return None;
    }
    // Normal equations of c + a u + b v, shared by the three channels.
    let mut m = [[0f64; 3]; 3];
    let mut r = [DVec3::ZERO; 3];
    for &(u, v, c) in samples {
        let d = [1.0, u, v];
        for a in 0..3 {
            for b in 0..3 {
                m[a][b] += d[a] * d[b];
            }
            r[a] += d[a] * c;
        }
    }
    let n = m[0][0];
    let var_u = m[1][1] - m[0][1] * m[0][1] / n;
    let var_v = m[2][2] - m[0][2] * m[0][2] / n;
    if !(var_u > 1e-3 * n && var_v > 1e-3 * n) {
        return None;
    }
    let inv = glam::DMat3::from_cols_array_2d(&m).inverse();
    if !inv.is_finite() {
        return None;
    }
    // Each channel: [c, a, b] = M⁻¹ r (M is symmetric).
    let solve = |k: usize| {
        let rk = DVec3::new(r[0][k], r[1][k], r[2][k]);
        inv * rk
    };
    let (x, y, z) = (solve(0), solve(1), solve(2));
    let c = DVec3::new(x.x, y.x, z.x);
    let du = DVec3::new(x.y, y.y, z.y);
    let dv = DVec3::new(x.z, y.z, z.z);
    let ok = c.is_finite() && du.is_finite() && dv.is_finite();
    ok.then(|| {
        (
            c,
            ColorField {
                du: du.as_vec3(),
                dv: dv.as_vec3(),
            },
        )
    })
}

/// Fits every splat's colour field to the `colors` of the `points` its
/// disc covers (within [`COLOR_PLANE_REACH`] radii of its plane, facing no
/// matter), in parallel. A splat's constant colour becomes the fit's
/// constant part (the colour at its centre, where the mean of its points
/// was before); a splat with too few or too collinear points keeps its
/// colour and a zero field. Returns the fields, one per splat, and how
/// many of them are zero.
pub fn fit_colors(
    splats: &mut [Splat],
    points: &[Vec3],
    colors: &[Vec3],
) -> (Vec<ColorField>, usize) {
    let tree: PointTree = build_tree(points);
    let fields: Vec<(ColorField, bool)> = splats
        .par_iter_mut()
        .map(|s| {
            let reach = s.radii.x.max(s.radii.y);
            let near =
                tree.within_unsorted::<SquaredEuclidean>(&s.center.to_array(), reach * reach);
            let (ru, rv) = (f64::from(s.radii.x), f64::from(s.radii.y));
            let (c0, n, u, v) = (
                s.center.as_dvec3(),
                s.normal.as_dvec3(),
                s.u_axis.as_dvec3(),
                s.v_axis.as_dvec3(),
            );
            let samples: Vec<(f64, f64, DVec3)> = near
                .iter()
                .filter_map(|nb| {
                    let j = nb.item as usize;
                    let d = points[j].as_dvec3() - c0;
                    if d.dot(n).abs() > COLOR_PLANE_REACH * ru.max(rv) {
                        return None;
                    }
                    let (pu, pv) = (d.dot(u) / ru, d.dot(v) / rv);
                    (pu * pu + pv * pv <= 1.0).then(|| (pu, pv, colors[j].as_dvec3()))
                })
                .collect();
            match fit_one(&samples) {
                Some((c, f)) => {
                    s.color = c.as_vec3().clamp(Vec3::ZERO, Vec3::ONE);
                    (f, false)
                }
                None => (ColorField::ZERO, true),
            }
        })
        .collect();
    let zero = fields.iter().filter(|f| f.1).count();
    (fields.into_iter().map(|f| f.0).collect(), zero)
}

/// The colour fields of `splats` generated from `cloud` with `params`
/// ([`fit_colors`] over the cloud's points, in the splats' frame: offsets
/// from the cloud's origin), or empty (nothing to store, nothing to pay)
/// when the cloud has no colours, all its colours are one, or
/// [`SplatParams::color_fields`] is off. Returns the fields and how many of
/// them are zero.
pub fn fit_cloud(
    splats: &mut [Splat],
    cloud: &PointCloud,
    params: &SplatParams,
) -> (Vec<ColorField>, usize) {
    match cloud.colors.as_deref() {
        Some(c) if params.color_fields && c.iter().any(|&x| x != c[0]) => {
            fit_colors(splats, &cloud.positions, c)
        }
        _ => (Vec::new(), 0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A disc over points coloured by a linear ramp: the field reproduces
    /// the ramp at the rim, and the constant part is the centre's colour.
    #[test]
    fn a_linear_ramp_is_fitted_exactly() {
        let mut s = [Splat::disc(Vec3::ZERO, Vec3::Z, 1.0).unwrap()];
        let mut points = Vec::new();
        let mut colors = Vec::new();
        for i in 0..21 {
            for j in 0..21 {
                let p = Vec3::new(i as f32 / 10.0 - 1.0, j as f32 / 10.0 - 1.0, 0.0);
                points.push(p);
                colors.push(Vec3::new(0.5 + 0.3 * p.x, 0.5 - 0.2 * p.y, 0.4));
            }
        }
        let (f, zero) = fit_colors(&mut s, &points, &colors);
        assert_eq!(zero, 0);
        let s = s[0];
        for p in [Vec3::X * 0.9, Vec3::Y * -0.7, Vec3::new(0.3, 0.4, 0.0)] {
            let want = Vec3::new(0.5 + 0.3 * p.x, 0.5 - 0.2 * p.y, 0.4);
            assert!((f[0].at(&s, p) - want).abs().max_element() < 1e-5, "{p}");
        }
        // Held at the rim beyond it, and clamped to [0, 1].
        assert!((f[0].at(&s, Vec3::X * 3.0) - f[0].at(&s, Vec3::X)).length() < 1e-6);
    }

    /// Too few points, or points along a line: the constant colour stays.
    #[test]
    fn a_degenerate_fit_keeps_the_constant_colour() {
        let mut s = [Splat::disc(Vec3::ZERO, Vec3::Z, 1.0).unwrap()];
        s[0].color = Vec3::splat(0.25);
        let points: Vec<Vec3> = (0..20).map(|i| Vec3::X * (i as f32 / 20.0)).collect();
        let colors: Vec<Vec3> = points.iter().map(|p| Vec3::splat(p.x)).collect();
        let (f, zero) = fit_colors(&mut s, &points, &colors);
        assert_eq!(
            (f[0], zero, s[0].color),
            (ColorField::ZERO, 1, Vec3::splat(0.25))
        );
    }
}
