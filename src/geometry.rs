//! The geometry every other module builds on: rays and tangent frames.

use glam::Vec3;

/// A ray `origin + t * dir`. `dir` is expected to be unit length, so `t` is a
/// distance; nothing here divides by its length. Six `f32` in this order
/// (`crate::simd`'s conversion of rows writes them so).
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct Ray {
    /// Ray origin.
    pub origin: Vec3,
    /// Ray direction (unit length by convention).
    pub dir: Vec3,
}

impl Ray {
    /// A ray from `origin` along `dir` (normalised here; a zero or NaN `dir`
    /// gives a NaN direction, which every intersection routine treats as a
    /// miss).
    #[must_use]
    pub fn new(origin: Vec3, dir: Vec3) -> Ray {
        Ray {
            origin,
            dir: dir.normalize(),
        }
    }

    /// The point at parameter `t`.
    #[must_use]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }
}

/// Rays read one at a time by index: a slice of rays, or a batch's rows
/// converted as they are read (`render::cast`), so that a fan can sample
/// a run of rays that was never written out whole.
pub trait RaySet: Sync {
    /// How many rays.
    fn len(&self) -> usize;

    /// Ray `i` (below [`RaySet::len`]).
    fn ray(&self, i: usize) -> Ray;

    /// Ray `i`'s origin (its [`RaySet::ray`]'s, perhaps without the rest).
    fn origin(&self, i: usize) -> Vec3 {
        self.ray(i).origin
    }

    /// Whether there are none.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

impl RaySet for &[Ray] {
    fn len(&self) -> usize {
        <[Ray]>::len(self)
    }

    fn ray(&self, i: usize) -> Ray {
        self[i]
    }
}

/// A right-handed orthonormal tangent frame `(u, v)` for unit normal `n`
/// (Duff et al. 2017, branchless).
#[must_use]
pub fn tangent_frame(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    let u = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
    let v = Vec3::new(b, sign + n.y * n.y * a, -n.y);
    (u, v)
}
