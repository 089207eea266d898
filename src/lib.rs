//! splatray: ray tracing point clouds as surface splats, after Linsen et al.
//! 2007 and Botsch et al. 2004 (the report in `docs/`, cited by section and
//! equation number), with two interchangeable acceleration backends — an
//! octree and Embree 4 user-geometry discs — feeding one shading path.
//!
//! # The front door
//!
//! Everything a program needs is at the crate's root:
//!
//! | step | items |
//! |---|---|
//! | read points | [`read_points`] → [`PointCloud`] |
//! | make splats | [`generate`] with [`GenerationOptions`] → [`Generated`] ([`Splat`]s and what generation found) |
//! | build a scene | [`load_scene`] (a TOML file), [`parse_scene_file`] + [`build_scene`], [`splats_scene`] (splats and a [`Camera`]) → [`Scene`] |
//! | render | [`render`] → [`Frame`] ([`RayCounts`]), [`write_image`] |
//! | cast rays on a chosen backend | [`backend_names`], [`build_backend`] → a [`Backend`], [`SplatSurfaces`], [`cast_rays`] ([`Ray`], [`CastOutputs`]) or [`cast_rays_owned`] ([`CastAnswers`]) |
//! | nearest surface to a point | [`Nearest`] over a [`Scene`]'s splats and triangles → [`Closest`] |
//! | compare backends | [`compare`] ([`CompareOptions`]) → [`Compared`]: a [`CompareReport`] ([`BackendRun`], [`Agreement`], [`TruthReport`], [`NamedTruthErrors`], [`TruthErrors`], [`ErrorBudget`]) and the frames |
//! | speed against error | [`sweep`] ([`SweepRequest`]) → [`SweepResult`]: [`SweepRow`]s and a [`MeshRow`] ([`BackendFigures`]) |
//! | the command line | [`run_cli`] |
//!
//! Errors are one line ([`Error`]); long work reports how far it is through
//! an optional [`Progress`] callback.
//!
//! # Example
//!
//! A grid of points → splats → a scene → an image, on the octree; the
//! same rays cast on Embree give the same hits:
//!
//! ```
//! use glam::Vec3;
//! use splatray::{Camera, GenerationOptions, PointCloud, build_backend, generate, render, splats_scene};
//!
//! // A gently curved grid of points (a real program reads them: `read_points`).
//! let mut cloud = PointCloud::default();
//! for i in 0..30 {
//!     for j in 0..30 {
//!         let (x, y) = (i as f32 * 0.04, j as f32 * 0.04);
//!         cloud.positions.push(Vec3::new(x, y, 0.1 * (x * 2.0).sin()));
//!     }
//! }
//! let made = generate(&cloud, &GenerationOptions::default(), None)?;
//! assert!(!made.splats.is_empty());
//!
//! let eye = Vec3::new(0.6, 0.6, 3.0);
//! let camera = Camera::look_at(eye, Vec3::new(0.6, 0.6, 0.0), Vec3::Y, 40.0, 32, 32, 1)?;
//! let scene = splats_scene(made.splats, camera)?;
//! let octree = build_backend("octree", &scene)?;
//! let frame = render(&scene, &*octree, None);
//! assert_eq!((frame.width, frame.height), (32, 32));
//! // The centre pixel sees the surface.
//! assert_ne!(frame.splat[16 * 32 + 16], u32::MAX);
//! # Ok::<(), splatray::Error>(())
//! ```
//!
//! # Internals
//!
//! The pipeline's stages (the modules below) are private to the crate. The
//! `internals` feature makes them public, at the same paths: the crate's
//! own tests, benchmarks, examples and the Python package turn it on; their
//! API may change at any commit.

#![cfg_attr(not(feature = "internals"), warn(missing_docs))]

/// Declares each module `pub` with the `internals` feature and `pub(crate)`
/// without it. Without it the items only tests and benchmarks use are dead
/// code to the compiler, which is expected: `dead_code` is allowed there
/// (with the feature, as before, every `pub` item counts as used).
macro_rules! internal_mods {
    ($($name:ident),* $(,)?) => {
        $(
            #[cfg(feature = "internals")]
            pub mod $name;
            #[cfg(not(feature = "internals"))]
            #[allow(dead_code, unused_imports)]
            pub(crate) mod $name;
        )*
    };
}

internal_mods!(
    accel, config, data, embree, error, freespace, geometry, io, memory, names, pipeline,
    primitive, progress, render, resolve, rng, scanner, scene, simd, splat, terrain, tiled,
    validate, viewer, workflow,
);

// The command line: its arguments and commands, called by the `splatray`
// binary and the Python package's `splatray` command through `run_cli`.
#[allow(dead_code)]
mod cli;

pub use error::{Error, Result};

// Reading points.
pub use data::PointCloud;
pub use io::read_points;

// Making splats.
pub use data::Splat;
pub use pipeline::Generated;
pub use splat::GenerationOptions;

// Building a scene.
pub use scene::load::splats_scene;
pub use scene::{Camera, Scene, SceneFile, build_scene, load_scene, parse_scene_file};

// Rendering.
pub use render::integrator::{Frame, RayCounts, render};
pub use render::output::write_image;
pub use resolve::ShadingMode;

// Casting rays on a chosen backend.
pub use accel::{Backend, CandidateHits, FAN_ELSEWHERE, FAN_MISS, Fan, Ray};
pub use render::cast::{CastAnswers, CastOutputs, cast_rays, cast_rays_owned};
pub use render::integrator::SplatSurfaces;
pub use render::nearest::{Closest, Nearest};

// Comparing backends, speed against error.
pub use validate::causes::ErrorBudget;
pub use validate::compare::{Agreement, TruthErrors};
pub use validate::sweep::{BackendFigures, MeshRow, SweepResult, SweepRow};
pub use workflow::compare::{
    BackendRun, CompareOptions, CompareReport, Compared, NamedTruthErrors, TruthReport, compare,
};
pub use workflow::sweep::{SweepRequest, sweep};

pub use progress::Progress;

/// The splats of `cloud`, made with `options` (defaults for what they
/// leave out) through every stage of generation: outliers left out,
/// normals oriented toward the scanner, splats grown and fitted with their
/// normal and colour fields, free space trimmed (`docs/DESIGN.md`, "Data
/// flow"). Positions are relative to the cloud's origin, as the cloud's.
///
/// # Errors
/// An empty cloud or one too small to make splats of, options out of range,
/// a viewpoint that is not finite: one line each.
pub fn generate(
    cloud: &PointCloud,
    options: &GenerationOptions,
    progress: Option<Progress<'_>>,
) -> Result<Generated> {
    pipeline::generate(cloud, &options.params(cloud), progress)
}

/// The names of the registered backends, the default (`"octree"`) first:
/// what [`build_backend`] and the command line's `--backend` take.
#[must_use]
pub fn backend_names() -> Vec<&'static str> {
    accel::registry::names()
}

/// The backend named `name` (one of [`backend_names`]) built over the
/// splats of `scene`: what [`render`] and [`SplatSurfaces`] trace. Every
/// backend gives the same candidate hits, bit for bit (`docs/DESIGN.md`,
/// "The backend contract").
///
/// # Errors
/// An unknown name (one line listing the known ones); a backend that does
/// not build (Embree's device or memory).
pub fn build_backend(name: &str, scene: &Scene) -> Result<Box<dyn Backend>> {
    accel::registry::lookup(name)?.build_scene(scene)
}

/// Runs the `splatray` command line with `args` (the program's name first),
/// as the `splatray` binary does, and returns its exit status (0: success).
/// Output goes to the process's stdout and stderr.
pub fn run_cli<I, T>(args: I) -> u8
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    cli::app::run(args)
}
