//! Splats as stored, rendered and written: an oriented disc or ellipse
//! with a linear "Phong" normal field (eq. 4 of §4.1) and clip lines, and
//! the linear colour field beside it (§4.1–4.2's analogue for colour).

use crate::geometry::tangent_frame;
use crate::primitive::clip::Clip;
use crate::primitive::{ClippedDisc, Disc};
use glam::{Vec2, Vec3};

/// The linear normal field of a Phong splat, eq. (4) of §4.1–4.2.
///
/// A normal is stored in the two-parameter tangent-plane form of fig. 13:
/// the point `(x, y, 1)` where it pierces the plane at unit distance above the
/// splat, in the splat's frame `(u_axis, v_axis, normal)`. The field is
/// `N(u, v) = (x_c + alpha * u, y_c + beta * v, 1)`, with `(u, v)` the
/// splat-local coordinates *normalised by the radii* (so `|(u,v)| = 1` on the
/// rim), which keeps `alpha` and `beta` scale-free.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C)]
pub struct NormalField {
    /// Centre normal, tangent-plane form `(x_c, y_c)` (eq. 4).
    pub xc: f32,
    /// Centre normal, tangent-plane form `(x_c, y_c)` (eq. 4).
    pub yc: f32,
    /// Slope of the field along `u_axis` (eq. 4).
    pub alpha: f32,
    /// Slope of the field along `v_axis` (eq. 4).
    pub beta: f32,
}

impl NormalField {
    /// A constant field equal to the splat normal (a flat splat).
    pub const FLAT: NormalField = NormalField {
        xc: 0.0,
        yc: 0.0,
        alpha: 0.0,
        beta: 0.0,
    };
}

/// One surface splat: an oriented elliptical disc with a colour and a
/// linear normal field (§2.1, §4.1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Splat {
    /// Centre `c_i`, eq. (2).
    pub center: Vec3,
    /// Unit normal `n_i`.
    pub normal: Vec3,
    /// Unit tangent of the major axis `u_i` (§2.1).
    pub u_axis: Vec3,
    /// Unit tangent of the minor axis `v_i`, `normal × u_axis`.
    pub v_axis: Vec3,
    /// Radii `(r_u, r_v)`, eq. (3); equal for circular splats.
    pub radii: Vec2,
    /// Linear RGB colour in `[0, 1]`.
    pub color: Vec3,
    /// Phong normal field, eq. (4).
    pub field: NormalField,
    /// Clip lines at a sharp feature; `Clip::NONE` for a whole disc.
    pub clip: Clip,
}

impl Splat {
    /// A circular flat splat with an arbitrary tangent frame. `normal` need not
    /// be unit length; a zero or NaN normal gives `None`.
    #[must_use]
    pub fn disc(center: Vec3, normal: Vec3, radius: f32) -> Option<Splat> {
        let n = normal.try_normalize()?;
        let (u, v) = tangent_frame(n);
        Some(Splat {
            center,
            normal: n,
            u_axis: u,
            v_axis: v,
            radii: Vec2::splat(radius),
            color: Vec3::ONE,
            field: NormalField::FLAT,
            clip: Clip::NONE,
        })
    }

    /// The hot-loop description of this splat's surface.
    #[must_use]
    pub fn disc_geometry(&self) -> Disc {
        Disc {
            center: self.center,
            normal: self.normal,
            u_scaled: self.u_axis / self.radii.x,
            v_scaled: self.v_axis / self.radii.y,
        }
    }

    /// The clipped primitive of this splat: its disc and its clip lines
    /// (used for every splat of a scene where some splat is clipped).
    #[must_use]
    pub fn clipped_geometry(&self) -> ClippedDisc {
        ClippedDisc {
            disc: self.disc_geometry(),
            clip: self.clip,
        }
    }

    /// Whether this splat carries a clip line.
    #[must_use]
    pub fn is_clipped(&self) -> bool {
        !self.clip.is_none()
    }

    /// Half extents of the tight axis-aligned box around the (elliptical) disc:
    /// along world axis `i`, `sqrt((r_u u_i)^2 + (r_v v_i)^2)`.
    #[must_use]
    pub fn half_extent(&self) -> Vec3 {
        let a = self.u_axis * self.radii.x;
        let b = self.v_axis * self.radii.y;
        (a * a + b * b).map(f32::sqrt)
    }

    /// The normal of the Phong field at normalised local coordinates `(u, v)`,
    /// eq. (4), as a unit world-space vector.
    #[must_use]
    pub fn field_normal(&self, u: f32, v: f32) -> Vec3 {
        let f = &self.field;
        let x = f.xc + f.alpha * u;
        let y = f.yc + f.beta * v;
        (self.u_axis * x + self.v_axis * y + self.normal).normalize()
    }
}

/// The change of a splat's linear RGB colour across its disc: `du` from
/// its centre to the rim along `u_axis`, `dv` along `v_axis`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ColorField {
    /// Colour change per unit of the normalised coordinate `u`.
    pub du: Vec3,
    /// Colour change per unit of the normalised coordinate `v`.
    pub dv: Vec3,
}

impl ColorField {
    /// No change: the splat's constant colour.
    pub const ZERO: ColorField = ColorField {
        du: Vec3::ZERO,
        dv: Vec3::ZERO,
    };

    /// The colour of `splat` with this field at world point `p` (on or
    /// near its plane), clamped to `[0, 1]`; beyond the rim (within the
    /// blending window of §4.3) the field is held at the rim's value.
    #[must_use]
    pub fn at(&self, splat: &Splat, p: Vec3) -> Vec3 {
        let d = p - splat.center;
        let (mut u, mut v) = (
            d.dot(splat.u_axis) / splat.radii.x,
            d.dot(splat.v_axis) / splat.radii.y,
        );
        let r2 = u * u + v * v;
        if r2 > 1.0 {
            let s = r2.sqrt().recip();
            (u, v) = (u * s, v * s);
        }
        (splat.color + self.du * u + self.dv * v).clamp(Vec3::ZERO, Vec3::ONE)
    }
}
