//! How far apart overlapping neighbouring splats of one model stand along
//! their normals: the depth the blending window of §4.3 must reach to
//! gather them (`docs/DESIGN.md`, "Tolerances").

use super::knn::build_tree;
use crate::data::Splat;
use glam::Vec3;
use kiddo::SquaredEuclidean;
use rayon::prelude::*;
use std::num::NonZero;

/// Neighbours measured per splat.
const NEIGHBOURS: usize = 6;

/// Splats measured at most (every `n / SAMPLES`-th; the median needs no
/// more).
const SAMPLES: usize = 20_000;

/// The *standoff* of a set of splats (one model): the median, over the
/// splats, of the largest distance of a neighbour's centre from the splat's
/// plane, `max_j |n_i · (c_j - c_i)|` over its 6 nearest neighbours.
///
/// On a smooth surface this is the sagitta of the neighbours' spacing
/// (`d²/2R` for spacing `d` and curvature radius `R`), on a noisy one about
/// the noise, on a plane zero: how far apart along the normal the splats a
/// ray meets together stand, which is what the blending window must reach.
/// It is measured on the splats themselves, so it serves splat files and
/// shapes as well as generated models, and it does not depend on the
/// scene around the model. Fewer than two splats: 0.
#[must_use]
pub fn standoff(splats: &[Splat]) -> f32 {
    Standoff::of(splats).measure()
}

/// What [`standoff`] reads of the splats, copied: every centre and the
/// measured splats' normals. It is measured from these alone, so the
/// splats may move meanwhile (a scene re-centres them while it is
/// measured: `scene::load`).
#[derive(Clone, Debug, Default)]
pub struct Standoff {
    centres: Vec<Vec3>,
    /// The splats measured (every `stride`-th), with their normals.
    measured: Vec<(u32, Vec3)>,
}

impl Standoff {
    /// The copies [`standoff`] measures `splats` from.
    #[must_use]
    pub fn of(splats: &[Splat]) -> Standoff {
        if splats.len() < 2 {
            return Standoff::default();
        }
        let stride = splats.len().div_ceil(SAMPLES);
        Standoff {
            centres: splats.par_iter().map(|s| s.center).collect(),
            measured: (0..splats.len())
                .step_by(stride)
                .map(|i| (i as u32, splats[i].normal))
                .collect(),
        }
    }

    /// The standoff ([`standoff`]).
    #[must_use]
    pub fn measure(&self) -> f32 {
        if self.centres.len() < 2 {
            return 0.0;
        }
        let centres = &self.centres;
        let tree = build_tree(centres);
        let nearest = NonZero::new(NEIGHBOURS + 1).unwrap_or(NonZero::<usize>::MIN);
        let mut largest: Vec<f32> = self
            .measured
            .par_iter()
            .map(|&(i, normal)| {
                let c = centres[i as usize];
                tree.nearest_n::<SquaredEuclidean>(&c.to_array(), nearest)
                    .into_iter()
                    .filter(|nb| nb.item != i)
                    .map(|nb| normal.dot(centres[nb.item as usize] - c).abs())
                    .filter(|d| d.is_finite())
                    .fold(0.0, f32::max)
            })
            .collect();
        let mid = largest.len() / 2;
        *largest.select_nth_unstable_by(mid, f32::total_cmp).1
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use crate::scene::shapes;
    use glam::Vec2;

    #[test]
    fn a_plane_stands_off_by_nothing() {
        let q = shapes::quad(Vec3::new(0.3, -2.0, 1.0), Vec3::Y, Vec2::new(4.0, 3.0), 900);
        let r = q[0].radii.x;
        assert!(standoff(&q) <= 1e-6 * r, "{} for radius {r}", standoff(&q));
        assert_eq!(standoff(&q[..1]), 0.0);
        assert_eq!(standoff(&[]), 0.0);
    }

    #[test]
    fn a_sphere_stands_off_by_the_sagitta_of_its_spacing() {
        // Centres `d` apart on a sphere of radius R stand d²/2R off each
        // other's tangent planes: the standoff scales with R and, for a
        // fixed R, with 1/n (d² ~ 4πR²/n).
        let at = |r: f32, n: usize| standoff(&shapes::sphere(Vec3::new(1.0, 2.0, 3.0), r, n));
        let (a, b) = (at(1.0, 2000), at(10.0, 2000));
        assert!(a > 0.0 && (b / a - 10.0).abs() < 0.01, "{a} {b}");
        let c = at(1.0, 500);
        assert!((c / a - 4.0).abs() < 0.8, "500 splats {c}, 2000 splats {a}");
        // Within the spacing's sagitta: d = 2 sqrt(π/n) R is about the
        // nearest-neighbour spacing; the sixth neighbour lies a little
        // farther.
        let d2 = 4.0 * std::f32::consts::PI / 2000.0;
        assert!(a > 0.5 * d2 / 2.0 && a < 4.0 * d2 / 2.0, "{a}");
    }

    #[test]
    fn noise_stands_off_by_about_the_noise() {
        let mut rng = SplitMix64::new(11);
        let noisy = |sigma: f32, rng: &mut SplitMix64| -> Vec<Splat> {
            shapes::quad(Vec3::ZERO, Vec3::Y, Vec2::new(2.0, 2.0), 2500)
                .into_iter()
                .map(|mut s| {
                    s.center.y += sigma * rng.next_gaussian() as f32;
                    s
                })
                .collect()
        };
        let small = standoff(&noisy(0.001, &mut rng));
        let large = standoff(&noisy(0.01, &mut rng));
        assert!(small > 0.001 && small < 0.005, "{small}");
        assert!((large / small - 10.0).abs() < 1.5, "{small} {large}");
    }
}
