//! The unit-scale frame splat generation runs in: positions re-centred on
//! their bounding box and divided by its diagonal, in f64, so no squared
//! distance, covariance or threshold overflows or underflows whatever the
//! cloud's units (`docs/DESIGN.md`, "Precision").

use super::Splat;
use glam::{DVec3, Vec3};

/// The largest viewpoint distance kept in the unit frame: a viewpoint only
/// orients normals, so one further away is pulled in along its direction
/// rather than overflowing f32.
const FAR_VIEWPOINT: f64 = 1e30;

/// Maps between a cloud's coordinates and a frame where its bounding box is
/// centred on zero with a diagonal of 1: `unit = (p - center) / scale`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct UnitFrame {
    /// Centre of the finite positions' bounding box.
    pub(crate) center: DVec3,
    /// Diagonal of that box (1 when it is empty or a single point).
    pub(crate) scale: f64,
}

impl UnitFrame {
    /// The frame of the finite ones among `positions`.
    pub(crate) fn of(positions: &[Vec3]) -> UnitFrame {
        let (lo, hi) = positions.iter().filter(|p| p.is_finite()).fold(
            (DVec3::INFINITY, DVec3::NEG_INFINITY),
            |(lo, hi), p| {
                let p = p.as_dvec3();
                (lo.min(p), hi.max(p))
            },
        );
        if lo.x > hi.x {
            return UnitFrame {
                center: DVec3::ZERO,
                scale: 1.0,
            };
        }
        let diagonal = (hi - lo).length();
        UnitFrame {
            center: (lo + hi) * 0.5,
            scale: if diagonal > 0.0 && diagonal.is_finite() {
                diagonal
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
            let d = f64::from(r) * 2.0 * 3f64.sqrt();
            assert!((f.scale / d - 1.0).abs() < 1e-6, "{f:?}");
            let u = pts.map(|p| f.unit(p));
            assert!((u[1] - u[0]).length() > 0.999 && (u[1] - u[0]).length() < 1.001);
            let s = Splat::disc(u[1], Vec3::Z, 0.25).unwrap();
            let back = f.splat_from_unit(&s);
            assert!(
                (back.center - pts[1]).length() <= 1e-6 * d as f32,
                "{back:?}"
            );
            assert!((f64::from(back.radii.x) / (0.25 * d) - 1.0).abs() < 1e-6);
            assert_eq!(first_unusable(&[back]), None);
        }
        assert_eq!(UnitFrame::of(&[Vec3::NAN]).scale, 1.0);
        assert_eq!(UnitFrame::of(&[Vec3::ONE, Vec3::ONE]).scale, 1.0);
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
