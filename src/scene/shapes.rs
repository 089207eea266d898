//! Procedural splat models with analytic surfaces: a sphere and a quad.
//! Their splats are built directly (no point cloud), so a scene can control
//! the splat count exactly and the exact surface is known for tests.

use crate::splat::{NormalField, Splat, tangent_frame};
use glam::{Vec2, Vec3};

/// Splat cover factor over the equal-area radius: discs of the equal-area
/// radius leave holes between lattice points; 1.35× closes them on a
/// Fibonacci lattice and on a square grid.
const COVER: f32 = 1.35;

/// `n` splats on the sphere `|p - center| = radius`, centred on a Fibonacci
/// lattice, tangent to the sphere, with outward normals.
///
/// The Phong field is the exact sphere normal (eq. 4): the point
/// `c_i + a·u + b·v` of a tangent disc sees the radial direction
/// `R·n + a·u + b·v`, i.e. tangent-plane form `(a/R, b/R)`; with `(u, v)`
/// normalised by the splat radius `r`, `x_c = y_c = 0` and
/// `alpha = beta = r / R`.
#[must_use]
pub fn sphere(center: Vec3, radius: f32, n: usize) -> Vec<Splat> {
    let n = n.max(1);
    let r = COVER * 2.0 * radius / (n as f32).sqrt();
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let ring = (1.0 - y * y).max(0.0).sqrt();
            let phi = golden * i as f64;
            let dir = Vec3::new(
                (phi.cos() * ring) as f32,
                y as f32,
                (phi.sin() * ring) as f32,
            )
            .normalize();
            let (u, v) = tangent_frame(dir);
            Splat {
                center: center + dir * radius,
                normal: dir,
                u_axis: u,
                v_axis: v,
                radii: Vec2::splat(r),
                color: Vec3::ONE,
                field: NormalField {
                    xc: 0.0,
                    yc: 0.0,
                    alpha: r / radius,
                    beta: r / radius,
                },
            }
        })
        .collect()
}

/// About `n` flat splats on a square grid covering the rectangle centred at
/// `center`, spanning `size.x` and `size.y` along the two tangents of
/// [`tangent_frame`]`(normal)` (for `normal = +y`: along x and z), facing
/// `normal`.
#[must_use]
pub fn quad(center: Vec3, normal: Vec3, size: Vec2, n: usize) -> Vec<Splat> {
    let normal = normal.try_normalize().unwrap_or(Vec3::Y);
    let (tu, tv) = tangent_frame(normal);
    let n = n.max(1) as f32;
    let h = (size.x * size.y / n).sqrt().max(f32::MIN_POSITIVE);
    let nx = (size.x / h).ceil().max(1.0) as usize;
    let ny = (size.y / h).ceil().max(1.0) as usize;
    let (hx, hy) = (size.x / nx as f32, size.y / ny as f32);
    // Half the cell diagonal reaches the cell corners; 15% more overlaps.
    let r = 1.15 * 0.5 * (hx * hx + hy * hy).sqrt();
    let mut out = Vec::with_capacity(nx * ny);
    for j in 0..ny {
        for i in 0..nx {
            let a = -0.5 * size.x + (i as f32 + 0.5) * hx;
            let b = -0.5 * size.y + (j as f32 + 0.5) * hy;
            out.push(Splat {
                center: center + tu * a + tv * b,
                normal,
                u_axis: tu,
                v_axis: tv,
                radii: Vec2::splat(r),
                color: Vec3::ONE,
                field: NormalField::FLAT,
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_field_is_the_exact_sphere_normal() {
        let s = sphere(Vec3::new(1.0, 2.0, 3.0), 2.0, 500);
        for sp in s.iter().step_by(37) {
            for &(u, v) in &[(0.0, 0.0), (0.7, 0.0), (-0.3, 0.6), (0.5, -0.5)] {
                let p = sp.center + sp.u_axis * (u * sp.radii.x) + sp.v_axis * (v * sp.radii.y);
                let exact = (p - Vec3::new(1.0, 2.0, 3.0)).normalize();
                let got = sp.field_normal(u, v);
                assert!(
                    got.angle_between(exact) < 1e-3,
                    "splat {sp:?} at ({u},{v}): got {got}, exact {exact}"
                );
            }
        }
    }

    #[test]
    fn quad_covers_its_rectangle() {
        let q = quad(Vec3::ZERO, Vec3::Y, Vec2::new(4.0, 2.0), 200);
        assert!(q.len() >= 200 && q.len() < 260, "{}", q.len());
        // Every point of a fine grid lies inside some splat.
        for i in 0..=40 {
            for j in 0..=20 {
                let p = Vec3::new(-2.0 + 0.1 * i as f32, 0.0, -1.0 + 0.1 * j as f32);
                let covered = q.iter().any(|s| (p - s.center).length() <= s.radii.x);
                assert!(covered, "hole at {p}");
            }
        }
    }
}
