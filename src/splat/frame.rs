//! The unit-scale frame splat generation runs in: positions re-centred on
//! a robust centre and divided by a robust size, in f64, so no squared
//! distance, covariance or threshold overflows or underflows whatever the
//! cloud's units, and a few far outliers cost the rest no precision
//! (`docs/DESIGN.md`, "Precision").

use crate::data::Splat;
use crate::data::robust_centre_size;
use glam::{DVec3, Vec3};
use rayon::prelude::*;

/// The largest viewpoint distance kept in the unit frame: a viewpoint only
/// orients normals, so one further away is pulled in along its direction
/// rather than overflowing f32.
const FAR_VIEWPOINT: f64 = 1e30;

/// The farthest point lies at most this many sizes from the centre in the
/// unit frame (the size grows to keep it there), so squared distances stay
/// far inside f32's range (1e24 against 3e38).
const MAX_REACH: f64 = 1e12;

/// Maps between a cloud's coordinates and a frame where it is centred on
/// zero with a size of about 1: `unit = (p - center) / scale`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct UnitFrame {
    /// The robust centre of the finite positions (per-axis medians).
    pub(crate) center: DVec3,
    /// Their robust size (see [`robust_centre_size`]), grown when needed so
    /// that no point lies more than [`MAX_REACH`] sizes from the centre; 1
    /// when there is no extent at all.
    pub(crate) scale: f64,
}

impl UnitFrame {
    /// The frame of the finite ones among `positions`.
    pub(crate) fn of(positions: &[Vec3]) -> UnitFrame {
        let Some((center, robust)) =
            robust_centre_size(positions.len(), |i| positions[i].as_dvec3())
        else {
            return UnitFrame {
                center: DVec3::ZERO,
                scale: 1.0,
            };
        };
        let reach = positions
            .par_iter()
            .filter(|p| p.is_finite())
            .map(|p| (p.as_dvec3() - center).abs().max_element())
            .reduce(|| 0f64, f64::max);
        let base = if robust > 0.0 { robust } else { reach };
        let scale = base.max(reach / MAX_REACH);
        UnitFrame {
            center,
            scale: if scale > 0.0 && scale.is_finite() {
                scale
            } else {
                1.0
            },
        }
    }

    /// A position in the unit frame (non-finite ones stay non-finite).
    pub(crate) fn unit(&self, p: Vec3) -> Vec3 {
        ((p.as_dvec3() - self.center) / self.scale).as_vec3()
    }

    /// A viewpoint in the unit frame: its direction from the cloud is kept
    /// exactly, its distance at most [`FAR_VIEWPOINT`].
    pub(crate) fn unit_viewpoint(&self, v: Vec3) -> Vec3 {
        let u = (v.as_dvec3() - self.center) / self.scale;
        let len = u.length();
        if len > FAR_VIEWPOINT {
            (u * (FAR_VIEWPOINT / len)).as_vec3()
        } else {
            u.as_vec3()
        }
    }

    /// A length in the cloud's units.
    pub(crate) fn length_from_unit(&self, l: f64) -> f64 {
        l * self.scale
    }

    /// A splat grown in the unit frame, in the cloud's coordinates: centre
    /// and radii scaled back in f64 and then made f32 (directions and the
    /// normal field, normalised by the radii, are scale-free).
    pub(crate) fn splat_from_unit(&self, s: &Splat) -> Splat {
        Splat {
            center: (self.center + s.center.as_dvec3() * self.scale).as_vec3(),
            radii: (s.radii.as_dvec2() * self.scale).as_vec2(),
            ..*s
        }
    }
}

/// The first splat that is not usable in f32 (a non-finite value or a
/// radius that overflowed or underflowed), as a one-line reason.
pub(crate) fn first_unusable(splats: &[Splat]) -> Option<String> {
    splats.iter().enumerate().find_map(|(i, s)| {
        let finite = [s.center, s.normal, s.u_axis, s.v_axis, s.color]
            .iter()
            .all(|v| v.is_finite())
            && s.radii.is_finite()
            && [s.field.xc, s.field.yc, s.field.alpha, s.field.beta]
                .iter()
                .all(|v| v.is_finite());
        (!finite || s.radii.min_element() <= 0.0).then(|| {
            format!(
                "splat {i} does not fit single precision (centre {}, radii {})",
                s.center, s.radii
            )
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec2;

    #[test]
    fn unit_frame_round_trips_far_and_extreme_clouds() {
        for (c, r) in [
            (Vec3::new(5e5, 4e6, 100.0), 10.0f32),
            (Vec3::splat(3e20), 1e20),
            (Vec3::splat(-2e-20), 1e-20),
        ] {
            let pts = [c - Vec3::splat(r), c + Vec3::splat(r), c];
            let f = UnitFrame::of(&pts);
            // Three points c - r, c, c + r per axis: the 10th and 90th
            // percentiles are c ∓ 0.8 r.
            let d = f64::from(r) * 2.0 * 3f64.sqrt();
            assert!((f.scale / (1.6 * f64::from(r)) - 1.0).abs() < 1e-6, "{f:?}");
            assert!((f.center - c.as_dvec3()).length() <= 1e-6 * d, "{f:?}");
            let u = pts.map(|p| f.unit(p));
            let l = (u[1] - u[0]).length();
            assert!((l - 3f32.sqrt() / 0.8).abs() < 1e-5, "{l}");
            let s = Splat::disc(u[1], Vec3::Z, 0.25).unwrap();
            let back = f.splat_from_unit(&s);
            assert!(
                (back.center - pts[1]).length() <= 1e-6 * d as f32,
                "{back:?}"
            );
            assert!((f64::from(back.radii.x) / (0.25 * f.scale) - 1.0).abs() < 1e-6);
            assert_eq!(first_unusable(&[back]), None);
        }
        assert_eq!(UnitFrame::of(&[Vec3::NAN]).scale, 1.0);
        assert_eq!(UnitFrame::of(&[Vec3::ONE, Vec3::ONE]).scale, 1.0);
    }

    #[test]
    fn a_far_outlier_moves_neither_centre_nor_size() {
        // 1000 points in the unit cube around (5, 5, 5), one at 1e7.
        let mut pts: Vec<Vec3> = (0..1000)
            .map(|i| Vec3::new((i % 10) as f32, (i / 10 % 10) as f32, (i / 100) as f32) / 9.0)
            .map(|p| p + Vec3::splat(4.5))
            .collect();
        pts.push(Vec3::new(1e7, 0.0, 0.0));
        let f = UnitFrame::of(&pts);
        assert!((f.center - DVec3::splat(5.0)).length() < 0.1, "{f:?}");
        assert!(f.scale > 0.7 && f.scale < 1.0, "{f:?}");
        // Far beyond MAX_REACH sizes, the size grows to keep it in range.
        pts.push(Vec3::new(-3e38, 0.0, 0.0));
        let f = UnitFrame::of(&pts);
        assert!((f.scale / (3e38 / MAX_REACH) - 1.0).abs() < 1e-6, "{f:?}");
        assert!(pts.iter().all(|&p| f.unit(p).is_finite()));
        // A cloud that is one point but for one other: no percentile range,
        // the size is the reach.
        let mut one = vec![Vec3::ZERO; 20];
        one.push(Vec3::X * 4.0);
        let f = UnitFrame::of(&one);
        assert_eq!((f.center, f.scale), (DVec3::ZERO, 4.0), "{f:?}");
    }

    #[test]
    fn overflow_and_underflow_are_found() {
        let f = UnitFrame {
            center: DVec3::ZERO,
            scale: 1e39,
        };
        let s = Splat::disc(Vec3::X, Vec3::Z, 0.5).unwrap();
        let big = f.splat_from_unit(&s);
        assert!(first_unusable(&[s, big]).unwrap().starts_with("splat 1 "));
        let tiny = UnitFrame {
            center: DVec3::ZERO,
            scale: 1e-46,
        }
        .splat_from_unit(&s);
        assert_eq!(tiny.radii, Vec2::ZERO);
        assert!(first_unusable(&[tiny]).is_some());
        let vp = UnitFrame {
            center: DVec3::ZERO,
            scale: 1e-20,
        }
        .unit_viewpoint(Vec3::new(0.0, 3e20, 0.0));
        assert!(vp.is_finite() && vp.y > 1e29 && vp.x == 0.0, "{vp}");
    }
}
