//! The one list of acceleration backends. The command line (`--backend`,
//! its help), `compare`, `sweep`, the plot, the conformance tests and the
//! benchmarks all iterate [`backends`]: a backend added here is built,
//! selected, cross-validated against the brute-force oracle, benchmarked and
//! compared with no other edit (`docs/DESIGN.md`, "Adding a backend").

use super::Backend;
use super::brute::Brute;
use super::embree::EmbreeBackend;
use super::octree::{Octree, OctreeParams};
use crate::embree::{Device, EmbreeError};
use crate::primitive::{Disc, Primitive};
use crate::splat::Splat;

/// Builds a backend over primitives (primitive `i` gets id `i`).
pub type BuildFn<P> = fn(&[P]) -> Result<Box<dyn Backend>, EmbreeError>;

/// One registered backend, for primitives of type `P`.
pub struct BackendInfo<P> {
    /// The name `--backend` takes and reports print.
    pub name: &'static str,
    /// One line for the help text.
    pub about: &'static str,
    /// True for a brute force that tests every primitive for every ray:
    /// quadratic, so left out of `compare`, `sweep` and the benchmarks; the
    /// first one is the oracle of the conformance tests, any other is tested
    /// against it like every backend.
    pub oracle: bool,
    /// Builds the backend over the primitives (primitive `i` gets id `i`).
    pub build: BuildFn<P>,
}

/// Every backend, for primitives of type `P`: the scene's backends first
/// (the first one is the default and the reference of `compare`), then the
/// brute forces (the first of them is the oracle).
///
/// # Example
/// ```
/// use glam::Vec3;
/// use splatray::accel::{CandidateHits, registry};
/// use splatray::geometry::Ray;
/// use splatray::splat::Splat;
/// // One disc of radius 1 at the origin, facing +z.
/// let splats = vec![Splat::disc(Vec3::ZERO, Vec3::Z, 1.0).unwrap()];
/// let ray = Ray::new(Vec3::new(0.2, 0.0, 5.0), -Vec3::Z);
/// let mut hits = CandidateHits::new(0.0);
/// // Every renderer gives the same candidate (the backend contract).
/// for info in registry::renderers() {
///     let backend = info.build_splats(&splats).unwrap();
///     backend.intersect(&ray, 0.0, f32::INFINITY, &mut hits);
///     let c = hits.nearest().unwrap();
///     assert_eq!((c.id, c.t), (0, 5.0), "{}", info.name);
/// }
/// ```
#[must_use]
pub fn backends<P: Primitive>() -> Vec<BackendInfo<P>> {
    vec![
        BackendInfo {
            name: "octree",
            about: "the octree of §3.1 (default)",
            oracle: false,
            build: |p| Ok(Box::new(Octree::new(p, &OctreeParams::default()))),
        },
        BackendInfo {
            name: "embree",
            about: "Embree 4, primitives as user geometry",
            oracle: false,
            build: |p| Ok(Box::new(EmbreeBackend::new(&Device::new()?, p)?)),
        },
        BackendInfo {
            name: "brute",
            about: "every ray against every primitive (the oracle; small scenes only)",
            oracle: true,
            build: |p| Ok(Box::new(Brute::new(p))),
        },
        #[cfg(feature = "test-backends")]
        BackendInfo {
            name: "brute-reversed",
            about: "test only: brute force offering hits in reverse order",
            oracle: true,
            build: |p| Ok(Box::new(super::brute::BruteReversed::new(p))),
        },
    ]
}

/// The names of every backend, in registry order.
#[must_use]
pub fn names() -> Vec<&'static str> {
    backends::<Disc>().iter().map(|b| b.name).collect()
}

/// The registered backend called `name`.
#[must_use]
pub fn find<P: Primitive>(name: &str) -> Option<BackendInfo<P>> {
    backends::<P>().into_iter().find(|b| b.name == name)
}

/// The one-line message for a backend name the registry does not list.
#[must_use]
pub fn unknown(name: &str) -> String {
    format!(
        "unknown backend '{name}' (expected one of: {})",
        names().join(", ")
    )
}

/// The backends that render scenes: every registered one but the oracle,
/// in registry order (the first is the reference of `compare` and `sweep`).
#[must_use]
pub fn renderers() -> Vec<BackendInfo<Disc>> {
    backends::<Disc>()
        .into_iter()
        .filter(|b| !b.oracle)
        .collect()
}

impl BackendInfo<Disc> {
    /// Builds this backend over the discs of `splats`.
    pub fn build_splats(&self, splats: &[Splat]) -> Result<Box<dyn Backend>, EmbreeError> {
        let discs: Vec<Disc> = splats.iter().map(Splat::disc_geometry).collect();
        (self.build)(&discs)
    }
}
