//! The self-hit rule of secondary rays (report §3.2, fig. 9 right), defined
//! once for every backend (`docs/DESIGN.md`, "The backend contract" and
//! "Tolerances").
//!
//! A ray leaving a splat must not hit the surface it leaves: neither that
//! splat nor the overlapping neighbours that stand a little above or below
//! the departure point on a curved or noisy surface. Skipping every hit
//! within a distance of the origin would also skip other surfaces close by
//! (the floor under a resting sphere, the base of an object on a mirror),
//! so the rule skips only candidates that are *the same surface here*:
//! similarly oriented, and either beside the departure point (its
//! projection on them, their plane passing close to it) or the way out of a
//! surface the ray entered ([`Departure::skips`]).

use crate::primitive::{Hit, Primitive};
use glam::Vec3;

/// Cosine of the largest angle between the normal of a candidate *beside
/// the departure point* and the departure splat's normal for the candidate
/// to count as the same surface (75°). Overlapping neighbours on a coarse
/// curved surface differ by tens of degrees, and where a surface turns
/// within a splat (the rim of the bunny's ears in `scenes/bunny.toml`) by
/// up to about 70°; another surface touching this one, like a sphere
/// resting on a floor, a wall standing on it, or the base of an object on a
/// mirror, meets it at 90° or more. Measured on `scenes/bunny.toml`
/// (`splatray compare --truth`, PSNR against the exact surfaces): 45° 29.48
/// dB (acne along the ears), 60° 30.57, 75° 31.28, 90° 31.29.
pub const SAME_SURFACE_COS: f32 = 0.258_819_04;

/// Cosine of the largest angle between a candidate met *on the way out* and
/// the departure splat's normal (45°). The chord a ray takes out of a
/// surface it entered at `α` below the departure plane turns the normal by
/// `2α`; the terminator of smooth shading normals over flat splats is a few
/// degrees. Refraction enters far more steeply (at least 48° below the
/// plane for an index of 1.5), so the far side of a refractor is never
/// skipped.
pub const WAY_OUT_COS: f32 = std::f32::consts::FRAC_1_SQRT_2;

/// The departure point's projection must lie within this many radii of a
/// candidate's centre: its disc enlarged, because what a ray leaving a
/// convex surface nearly tangentially emerges through is the overhang of a
/// neighbour whose centre lies up to about two radii away (its plane passes
/// just above the point). Measured with 6000 rays leaving the sphere of
/// `tests/conformance/departure.rs` 0.5°–3° from tangent: 15 still hit it
/// with 2 radii (all at 2–2.25), none with 2.5; and on the noisy plane of
/// `tests/contact.rs`, 11 of 9602 lit pixels shadowed themselves with 2
/// radii, 4 with 2.5.
pub const SAME_SURFACE_RIM: f32 = 2.5;

/// The departure point must lie within this many of a candidate's (largest)
/// radii of its plane. Overlapping tangent splats of a curved surface stand
/// apart by about `r·sinθ/2` for normals `θ` apart; fitted to noisy points
/// they stand apart by about the noise, which for points displaced by half
/// their spacing (splats about two spacings wide) reaches a radius: on the
/// noisy plane of `tests/contact.rs`, 213 of 9602 lit pixels shadowed
/// themselves with half a radius, 4 with one. A surface facing the same way
/// closer than this is not told apart from the one the ray leaves.
pub const SAME_SURFACE_HEIGHT: f32 = 1.0;

/// The departure point may lie this many of a candidate's (largest) radii
/// behind its plane when the ray leaves the front of its splat and meets
/// the candidate from behind, beside the point (within
/// [`SAME_SURFACE_RIM`]) and facing within 90° of it: a neighbour standing
/// above the point, which a ray rising out of a closed, outward-facing
/// surface can only meet from behind if it is that surface (another part
/// of the object, or another object, is met from its front). Noise leaves
/// small splats beside larger ones standing just over a radius above them
/// (1.05–1.08 radii on `scenes/scan-lines.toml`), and an ear's rim turns
/// its splats by up to 78° there. Measured (`compare --truth`, 800×600):
/// 1.25 radii `scan-lines.toml` 31.11 → 31.16 dB; 2, 3 or 5 radii the same
/// and one speck fewer; requiring 75° as [`SAME_SURFACE_COS`] does, 31.12.
pub const RISING_HEIGHT: f32 = 2.0;

/// Where a secondary ray leaves the splats: the splat it leaves, the
/// departure point on it, and that splat's normal (its own side).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Departure {
    /// The splat (primitive id) the ray leaves.
    pub id: u32,
    /// The departure point (the resolved hit).
    pub point: Vec3,
    /// That splat's unit plane normal, not flipped toward any ray.
    pub normal: Vec3,
}

impl Departure {
    /// True when the hit of a ray along `dir` on primitive `id` (`prim`)
    /// belongs to the surface the ray leaves, and is skipped:
    ///
    /// - the splat it leaves; or
    /// - a candidate *beside the departure point*: its normal within 75° of
    ///   that splat's ([`SAME_SURFACE_COS`]), its disc, enlarged by
    ///   [`SAME_SURFACE_RIM`], holding the point's projection, and its plane
    ///   passing within [`SAME_SURFACE_HEIGHT`] of its radii of the point
    ///   (an overlapping neighbour standing a little above or below it); or
    /// - a candidate *on the way out*: its normal within 45° of that
    ///   splat's ([`WAY_OUT_COS`]), the ray heading into the splat it leaves
    ///   (`dir · n < 0`) and meeting the candidate from behind: it crosses
    ///   the surface it left on a short chord, which happens when the smooth
    ///   shading normal puts a light above the surface that the flat splat
    ///   puts below (the shadow terminator); another surface facing the same
    ///   way is met from its front; or
    /// - a candidate *rising* over the point: the ray leaving the front of
    ///   the splat (`dir · n > 0`) and meeting the candidate from behind,
    ///   its normal within 90° of that splat's, its enlarged disc holding
    ///   the point's projection and its plane within [`RISING_HEIGHT`] of
    ///   its radii of the point: a neighbour of the same surface standing
    ///   above the point (noise, or a rim turning within a splat).
    ///
    /// NaN anywhere: not skipped.
    #[inline]
    #[must_use]
    pub fn skips<P: Primitive>(&self, dir: Vec3, id: u32, prim: &P) -> bool {
        if id == self.id {
            return true;
        }
        let l = prim.locate(self.point);
        let cos = l.normal.dot(self.normal);
        let leaving = self.normal.dot(dir);
        let from_behind = l.normal.dot(dir) > 0.0;
        // Beside the point; rising over it (met from behind by a ray
        // leaving the front) within wider limits.
        let (least_cos, most_height) = if leaving > 0.0 && from_behind {
            (0.0, RISING_HEIGHT)
        } else {
            (SAME_SURFACE_COS, SAME_SURFACE_HEIGHT)
        };
        let beside = cos >= least_cos
            && l.radial2 <= SAME_SURFACE_RIM * SAME_SURFACE_RIM
            && l.height.abs() <= most_height;
        let way_out = cos >= WAY_OUT_COS && leaving < 0.0 && from_behind;
        beside || way_out
    }
}

/// Which hits a query skips, as backends see it: [`NoSkip`] for primary
/// rays (compiled away in monomorphised traversals), a [`Departure`] for
/// secondary rays, and [`crate::accel::Secondary`] for a query that also
/// passes some hits ([`crate::accel::PassOver`]). Every backend asks it
/// about each hit that [`Primitive::intersect`] accepts, before the hit
/// counts.
pub trait Skip: Copy {
    /// True when the hit `hit` of a ray along `dir` on primitive `id` is
    /// skipped.
    fn skips<P: Primitive>(self, dir: Vec3, id: u32, prim: &P, hit: &Hit) -> bool;
}

/// Skips nothing.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NoSkip;

impl Skip for NoSkip {
    #[inline(always)]
    fn skips<P: Primitive>(self, _dir: Vec3, _id: u32, _prim: &P, _hit: &Hit) -> bool {
        false
    }
}

impl Skip for &Departure {
    #[inline(always)]
    fn skips<P: Primitive>(self, dir: Vec3, id: u32, prim: &P, _hit: &Hit) -> bool {
        Departure::skips(self, dir, id, prim)
    }
}

impl Skip for Option<&Departure> {
    #[inline(always)]
    fn skips<P: Primitive>(self, dir: Vec3, id: u32, prim: &P, _hit: &Hit) -> bool {
        self.is_some_and(|d| d.skips(dir, id, prim))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::splat::Splat;

    /// Leaving splat 0, a disc of radius 1 at the origin facing +z, from
    /// `(0.2, 0.1, 0)`.
    fn from() -> Departure {
        Departure {
            id: 0,
            point: Vec3::new(0.2, 0.1, 0.0),
            normal: Vec3::Z,
        }
    }

    fn disc(center: Vec3, normal: Vec3, radius: f32) -> crate::primitive::Disc {
        Splat::disc(center, normal, radius).unwrap().disc_geometry()
    }

    const UP: Vec3 = Vec3::new(0.3, 0.0, 1.0);

    #[test]
    fn the_splat_it_leaves_is_skipped_whatever_its_geometry() {
        let far = disc(Vec3::splat(50.0), -Vec3::Z, 1.0);
        assert!(from().skips(UP, 0, &far));
        assert!(!from().skips(UP, 1, &far));
    }

    #[test]
    fn overlapping_similar_neighbours_are_skipped() {
        let f = from();
        // Coplanar, tilted 30°, a little above or below: the same surface.
        assert!(f.skips(UP, 1, &disc(Vec3::new(1.0, 0.0, 0.0), Vec3::Z, 1.0)));
        let tilted = Vec3::new(0.5, 0.0, 0.75f32.sqrt());
        assert!(f.skips(UP, 1, &disc(Vec3::new(0.8, 0.0, 0.1), tilted, 1.0)));
        assert!(f.skips(UP, 1, &disc(Vec3::new(0.5, 0.5, 0.3), Vec3::Z, 0.5)));
        assert!(f.skips(UP, 1, &disc(Vec3::new(0.5, 0.5, -0.3), Vec3::Z, 0.5)));
    }

    #[test]
    fn other_surfaces_are_not_skipped() {
        let f = from();
        // Facing away (a sphere resting on this floor), at the very point.
        assert!(!f.skips(UP, 1, &disc(f.point, -Vec3::Z, 1.0)));
        // Tilted 80° toward the point: a crease, another surface (tilted
        // 60°, the surface turning within a splat, it is skipped; turned 80°
        // away from the point, a rim met from behind, it is skipped too:
        // `a_neighbour_rising_over_the_point_is_skipped`).
        let (s80, c80) = 80f32.to_radians().sin_cos();
        let steep = Vec3::new(-s80, 0.0, c80);
        assert!(!f.skips(UP, 1, &disc(Vec3::new(0.8, 0.0, 0.1), steep, 1.0)));
        let turning = Vec3::new(0.75f32.sqrt(), 0.0, 0.5);
        assert!(f.skips(UP, 1, &disc(Vec3::new(0.8, 0.0, 0.1), turning, 1.0)));
        // Parallel, more than a radius above, met from its front (a ray
        // into the surface): a layer of its own; more than two radii above,
        // met from behind by a ray rising out of it: one too.
        let layer = disc(Vec3::new(0.5, 0.5, 0.6), Vec3::Z, 0.5);
        assert!(!f.skips(Vec3::new(0.3, 0.0, -1.0), 1, &layer));
        assert!(!f.skips(UP, 1, &disc(Vec3::new(0.5, 0.5, 1.1), Vec3::Z, 0.5)));
        // Coplanar but its centre more than 2.5 radii away.
        assert!(!f.skips(UP, 1, &disc(Vec3::new(1.5, 0.1, 0.0), Vec3::Z, 0.5)));
        // NaN: never skipped (but the splat it leaves).
        let nan = Departure {
            point: Vec3::NAN,
            ..from()
        };
        assert!(!nan.skips(UP, 1, &disc(Vec3::ZERO, Vec3::Z, 1.0)));
    }

    #[test]
    fn a_neighbour_rising_over_the_point_is_skipped() {
        // Met from behind by a ray rising out of the splat it leaves: the
        // same surface standing over the point, up to two of its radii
        // (1.2 here), turned by up to 90° (78° here, an ear's rim).
        let f = from();
        let layer = disc(Vec3::new(0.5, 0.5, 0.6), Vec3::Z, 0.5);
        assert!(f.skips(UP, 1, &layer));
        let (s78, c78) = 78f32.to_radians().sin_cos();
        let rim = disc(Vec3::new(0.25, 0.1, 0.0), Vec3::new(-s78, 0.0, c78), 0.3);
        assert!(f.skips(Vec3::new(-0.5, 0.0, 1.0), 1, &rim));
        // Not when the ray leaves the splat's back, nor past 90°.
        let back = Departure {
            normal: -Vec3::Z,
            ..f
        };
        assert!(!back.skips(UP, 1, &layer));
        let (s100, c100) = 100f32.to_radians().sin_cos();
        let past = disc(Vec3::new(0.25, 0.1, 0.0), Vec3::new(-s100, 0.0, c100), 0.3);
        assert!(!f.skips(Vec3::new(-1.0, 0.0, 0.2), 1, &past));
    }

    #[test]
    fn the_way_out_of_a_surface_entered_is_skipped() {
        // A similar splat far off and well above the point, met from behind:
        // skipped only when the ray heads into the splat it leaves.
        let f = from();
        let beyond = disc(Vec3::new(5.0, 0.0, 1.0), Vec3::new(0.2, 0.0, 1.0), 1.0);
        let into = Vec3::new(1.0, 0.0, -0.05);
        let out = Vec3::new(1.0, 0.0, 0.05);
        assert!(f.skips(into, 1, &beyond));
        assert!(!f.skips(out, 1, &beyond));
        // Met from its front it is another surface even then, and so is one
        // turned by more than 45° (the far side of a refractor).
        let facing = disc(Vec3::new(5.0, 0.0, 1.0), Vec3::new(-0.2, 0.0, 1.0), 1.0);
        assert!(!f.skips(Vec3::new(1.0, 0.0, -0.3), 1, &facing));
        let turned = disc(Vec3::new(5.0, 0.0, 1.0), Vec3::new(1.2, 0.0, 1.0), 1.0);
        assert!(!f.skips(into, 1, &turned));
    }
}
