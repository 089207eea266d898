//! The one list of acceleration backends. The command line (`--backend`,
//! its help), `compare`, `sweep`, the plot, the conformance tests and the
//! benchmarks all iterate [`backends`]: a backend added here is built,
//! selected, cross-validated against the brute-force oracle, benchmarked and
//! compared with no other edit (`docs/DESIGN.md`, "Adding a backend"). An
//! entry is the one source of its backend's name: reports print the
//! entry's name, whatever type built it.

use super::Backend;
use super::brute::Brute;
use super::embree::EmbreeBackend;
use super::octree::{Layout, Octree, OctreeParams, OverlapTest};
use crate::data::Splat;
use crate::embree::Device;
use crate::error::Result;
use crate::primitive::{ClippedDisc, Disc, Primitive};
use crate::simd::Isa;

/// What a registered backend is for: which commands and suites use it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// Renders scenes: `--backend`, and every one of them in `compare`,
    /// `sweep`, the benchmarks and the conformance suite (the first is the
    /// default and the reference of `compare` and `sweep`).
    Renderer,
    /// Another configuration of a renderer (a layout, an overlap test):
    /// selectable with `--backend`, benchmarked and checked by the
    /// conformance suite, but not rendered by `compare` and `sweep`.
    Variant,
    /// The reference of the conformance suite: correct by construction and
    /// too slow for anything else.
    Oracle,
    /// Correct but slow (e.g. quadratic): selectable and checked against the
    /// oracle, never benchmarked, compared or swept.
    Slow,
}

impl Role {
    /// True for the roles whose speed is measured (benchmarks): renderers
    /// and their variants.
    #[must_use]
    pub fn is_fast(self) -> bool {
        matches!(self, Role::Renderer | Role::Variant)
    }
}

/// Build parameters an entry hands its builder. Backends read the part that
/// concerns them; the octree's layouts and overlap tests are entries that
/// differ only in these.
#[derive(Clone, Copy, Debug, Default)]
pub struct Params {
    /// The octree's leaf size, depth, overlap test and layout.
    pub octree: OctreeParams,
}

/// Builds a backend over primitives (primitive `i` gets id `i`) with an
/// entry's parameters.
pub type BuildFn<P> = fn(&[P], &Params) -> Result<Box<dyn Backend>>;

/// One registered backend, for primitives of type `P`.
pub struct BackendInfo<P> {
    /// The name `--backend` takes and reports print (the one source of it).
    pub name: &'static str,
    /// One line for the help text.
    pub about: &'static str,
    /// What it is for.
    pub role: Role,
    /// The parameters its builder gets.
    pub params: Params,
    /// Builds it: see [`BackendInfo::build`].
    pub builder: BuildFn<P>,
}

impl<P> BackendInfo<P> {
    /// Builds this backend over the primitives (primitive `i` gets id `i`).
    pub fn build(&self, prims: &[P]) -> Result<Box<dyn Backend>> {
        (self.builder)(prims, &self.params)
    }
}

fn octree<P: Primitive>(p: &[P], params: &Params) -> Result<Box<dyn Backend>> {
    Ok(Box::new(Octree::new(p, &params.octree)))
}

fn embree<P: Primitive>(p: &[P], _: &Params) -> Result<Box<dyn Backend>> {
    Ok(Box::new(EmbreeBackend::new(&Device::new()?, p)?))
}

fn brute<P: Primitive>(p: &[P], _: &Params) -> Result<Box<dyn Backend>> {
    Ok(Box::new(Brute::new(p)))
}

/// Parameters with the octree's layout or overlap test changed.
fn octree_with(layout: Option<Layout>, overlap: Option<OverlapTest>) -> Params {
    let d = OctreeParams::default();
    Params {
        octree: OctreeParams {
            layout: layout.unwrap_or(d.layout),
            overlap: overlap.unwrap_or(d.overlap),
            ..d
        },
    }
}

/// Every backend, for primitives of type `P`: the renderers first (the
/// first one is the default and the reference of `compare`), then their
/// variants, then the oracle and the slow ones.
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
/// // Every backend gives the same candidate (the backend contract).
/// for info in registry::backends() {
///     let backend = info.build_splats(&splats).unwrap();
///     backend.intersect(&ray, 0.0, f32::INFINITY, &mut hits);
///     let c = hits.nearest().unwrap();
///     assert_eq!((c.id, c.t), (0, 5.0), "{}", info.name);
/// }
/// ```
#[must_use]
pub fn backends<P: Primitive>() -> Vec<BackendInfo<P>> {
    let mut all = vec![
        BackendInfo {
            name: "octree",
            about: "the octree of §3.1 (default)",
            role: Role::Renderer,
            params: Params::default(),
            builder: octree,
        },
        BackendInfo {
            name: "embree",
            about: "Embree 4, primitives as user geometry",
            role: Role::Renderer,
            params: Params::default(),
            builder: embree,
        },
        BackendInfo {
            name: "octree-copies",
            about: "the octree with a copy of each primitive in every leaf it meets",
            role: Role::Variant,
            params: octree_with(Some(Layout::Copies), None),
            builder: octree,
        },
        BackendInfo {
            name: "octree-shared",
            about: "the octree with one shared array of primitives (least memory)",
            role: Role::Variant,
            params: octree_with(Some(Layout::Shared), None),
            builder: octree,
        },
        BackendInfo {
            name: "octree-square",
            about: "the octree with the report's bounding-square overlap test",
            role: Role::Variant,
            params: octree_with(None, Some(OverlapTest::BoundingSquare)),
            builder: octree,
        },
    ];
    // The octree on each SIMD path this CPU runs (`crate::simd`): the
    // conformance suite checks every path.
    all.extend(
        SIMD_PATHS
            .into_iter()
            .filter(|(isa, ..)| isa.supported())
            .map(|(isa, name, about)| BackendInfo {
                name,
                about,
                role: Role::Variant,
                params: Params {
                    octree: OctreeParams {
                        simd: Some(isa),
                        ..OctreeParams::default()
                    },
                },
                builder: octree,
            }),
    );
    all.extend([
        BackendInfo {
            name: "brute",
            about: "every ray against every primitive (the oracle; small scenes only)",
            role: Role::Oracle,
            params: Params::default(),
            builder: brute,
        },
        #[cfg(feature = "test-backends")]
        BackendInfo {
            name: "brute-reversed",
            about: "test only: brute force offering hits in reverse order",
            role: Role::Slow,
            params: Params::default(),
            builder: |p, _| Ok(Box::new(super::brute::BruteReversed::new(p))),
        },
    ]);
    all
}

/// The octree forced to each SIMD path: the path, the entry's name, its
/// help line.
const SIMD_PATHS: [(Isa, &str, &str); 3] = [
    (
        Isa::Portable,
        "octree-portable",
        "the octree with its baseline (SSE2) leaf filter",
    ),
    (
        Isa::Avx2,
        "octree-avx2",
        "the octree with its AVX2 leaf filter (8 discs at once)",
    ),
    (
        Isa::Avx512,
        "octree-avx512",
        "the octree with its AVX-512 leaf filter (16 discs at once)",
    ),
];

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

/// The registered backend called `name`, or a one-line error listing the
/// names there are.
pub fn lookup<P: Primitive>(name: &str) -> Result<BackendInfo<P>> {
    find(name).ok_or_else(|| {
        crate::Error::invalid(format!(
            "unknown backend '{name}' (expected one of: {})",
            names().join(", ")
        ))
    })
}

/// The backends of one role, in registry order.
#[must_use]
pub fn with_role<P: Primitive>(role: Role) -> Vec<BackendInfo<P>> {
    backends::<P>()
        .into_iter()
        .filter(|b| b.role == role)
        .collect()
}

/// The backends that render scenes in `compare` and `sweep`, in registry
/// order (the first is their reference).
#[must_use]
pub fn renderers() -> Vec<BackendInfo<Disc>> {
    with_role(Role::Renderer)
}

/// The oracle of the conformance suite (the first [`Role::Oracle`] entry).
///
/// # Panics
/// If the registry lists none (a registry without an oracle is a bug).
#[must_use]
pub fn oracle<P: Primitive>() -> BackendInfo<P> {
    with_role(Role::Oracle)
        .into_iter()
        .next()
        .expect("the registry lists an oracle")
}

impl BackendInfo<Disc> {
    /// Builds this backend over the discs of `splats`: [`Disc`]s when no
    /// splat is clipped (the scene pays nothing for clipping), else every
    /// splat as a [`ClippedDisc`], built by the same-named entry's builder
    /// for that primitive with this entry's parameters (`docs/DESIGN.md`, "The primitive contract").
    pub fn build_splats(&self, splats: &[Splat]) -> Result<Box<dyn Backend>> {
        if splats.iter().any(Splat::is_clipped) {
            let prims: Vec<ClippedDisc> = splats.iter().map(Splat::clipped_geometry).collect();
            let clipped = lookup::<ClippedDisc>(self.name)?;
            return (clipped.builder)(&prims, &self.params);
        }
        let discs: Vec<Disc> = splats.iter().map(Splat::disc_geometry).collect();
        self.build(&discs)
    }
}
