//! The `compare` workflow: one scene through every rendering backend of
//! the registry in one run, each compared ray for ray with the first (the
//! reference): their speeds (with `rounds` > 1, taken in turns, the median
//! of each round's ratio), their memory, their agreement, and with the
//! truth, each one's errors against the exact surfaces by cause. The
//! front end loads the scene, writes the images and the report, and prints.

use crate::accel::registry;
use crate::progress::Progress;
use crate::render::budget::Holds;
use crate::render::integrator::{Frame, render};
use crate::scene::Scene;
use crate::validate::causes::{Cause, ErrorBudget, Tolerances, error_budget};
use crate::validate::compare::{
    Agreement, TruthErrors, compare_frames, orient_to_camera, render_truth, truth_errors,
};
use crate::validate::truth::Truth;
use crate::{Error, Result};

/// How [`compare`] runs.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CompareOptions {
    /// Renders per backend, taken in turns (at least 1).
    pub rounds: u32,
    /// Also trace the exact surfaces and report each backend's errors.
    pub truth: bool,
}

/// What [`compare`] gives: the report, and the frames the images are made
/// of (the reference's first).
#[derive(Debug)]
pub struct Compared {
    /// The report.
    pub report: CompareReport,
    /// Each backend's frame, in the registry's order.
    pub frames: Vec<Frame>,
    /// The exact surfaces' frame (with the truth).
    pub truth_frame: Option<Frame>,
    /// The reference backend's cause of error of every pixel (with the
    /// truth).
    pub reference_causes: Option<Vec<Cause>>,
}

/// One backend in the comparison run: its speed and memory, and (except
/// for the reference) its agreement with the reference.
#[derive(Clone, Debug, serde::Serialize)]
pub struct BackendRun {
    /// The backend's registry name.
    pub name: &'static str,
    /// Seconds to build the acceleration structure.
    pub build_seconds: f64,
    /// Bytes the structure holds (for Embree, what its memory monitor
    /// counted).
    pub memory_bytes: usize,
    /// Seconds to render (the median over the rounds).
    pub render_seconds: f64,
    /// Millions of rays (all kinds) per second (the median over the
    /// rounds).
    pub mrays_per_s: f64,
    /// The reference's rays per second over this backend's, measured in
    /// this run: the median over the rounds of the ratio within each round
    /// (absent for the reference).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reference_over_this: Option<f64>,
    /// The smallest and largest of the rounds' ratios (absent for the
    /// reference).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reference_over_this_range: Option<[f64; 2]>,
    /// Agreement of the reference (first) with this backend, primary ray
    /// for primary ray (absent for the reference).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub agreement: Option<Agreement>,
}

/// The `compare` report.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CompareReport {
    /// Scene file.
    pub scene: String,
    /// Splats.
    pub splats: usize,
    /// Triangles (left out of the report when none).
    #[serde(skip_serializing_if = "super::render::is_zero")]
    pub triangles: usize,
    /// With `--as-triangles`: the scene again, its meshes as triangles.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub as_triangles: Option<AsTriangles>,
    /// Primary rays compared (one per pixel).
    pub rays: usize,
    /// Renders per backend, taken in turns (`--rounds`).
    pub rounds: u32,
    /// Every rendering backend of the registry, the reference first.
    pub backends: Vec<BackendRun>,
    /// Errors against the exact surfaces (with `--truth`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub truth: Option<TruthReport>,
}

/// `compare --as-triangles` (issue 57): the scene rendered again with
/// every model that has a mesh (`mesh`, or `truth` beside points or
/// splats) as that mesh's triangles, on every rendering backend in the
/// same run, beside the splats' figures, with each backend's splat image
/// against its triangle image.
#[derive(Clone, Debug, serde::Serialize)]
pub struct AsTriangles {
    /// Models turned into triangles.
    pub models: usize,
    /// Triangles in that scene.
    pub triangles: usize,
    /// Splats left in it (the models without a mesh).
    pub splats: usize,
    /// Each backend on the triangles (agreement: with the reference's
    /// triangle image).
    pub backends: Vec<BackendRun>,
    /// Each backend's splat image against its triangle image, PSNR dB
    /// (`None`: identical).
    pub splats_psnr_db: Vec<Option<f64>>,
}

/// The scene file with every model that has a mesh made a `triangles`
/// model of it ([`crate::scene::SceneFile::meshes_as_triangles`]).
#[must_use]
pub fn meshes_as_triangles(file: &crate::scene::SceneFile) -> (crate::scene::SceneFile, usize) {
    file.meshes_as_triangles(false)
}

/// [`AsTriangles`] of `tris` (the scene of [`meshes_as_triangles`], with
/// the view of the splats' scene), against the splats' `frames`.
///
/// # Errors
/// A backend that does not build.
pub fn as_triangles(
    tris: &Scene,
    models: usize,
    frames: &[Frame],
    progress: Option<Progress<'_>>,
) -> Result<AsTriangles> {
    let (tri_frames, backends) = render_every_backend(tris, 1, progress)?;
    let diagonal = tris.options.scale.diagonal;
    Ok(AsTriangles {
        models,
        triangles: tris.triangles.tris.len(),
        splats: tris.splats.len(),
        backends,
        splats_psnr_db: frames
            .iter()
            .zip(&tri_frames)
            .map(|(s, t)| compare_frames(s, t, diagonal).image_psnr_db)
            .collect(),
    })
}

/// Errors of each backend against the exact surfaces.
#[derive(Clone, Debug, serde::Serialize)]
pub struct TruthReport {
    /// Seconds to render the exact surfaces.
    pub render_seconds: f64,
    /// Each backend's splats against the surface, in the order of
    /// [`CompareReport::backends`].
    pub backends: Vec<NamedTruthErrors>,
}

/// One backend's errors against the exact surface.
#[derive(Clone, Debug, serde::Serialize)]
pub struct NamedTruthErrors {
    /// The backend's registry name.
    pub name: &'static str,
    /// Its errors.
    #[serde(flatten)]
    pub errors: TruthErrors,
    /// Its squared error by cause (`validate::causes`).
    pub by_cause: ErrorBudget,
}

fn mrays_per_s(f: &Frame) -> f64 {
    f.rays.total() as f64 / f.seconds.max(1e-9) / 1e6
}

/// What a comparison holds at once, for the budget check before it: a
/// frame per backend, the truth's, and a round's when taking turns; one
/// backend built at a time, or every one when taking turns.
#[must_use]
pub fn holds(rounds: u32, truth: bool) -> Holds {
    let renderers = registry::renderers().len();
    let frames = renderers + usize::from(truth) + usize::from(rounds > 1);
    Holds {
        frames: u32::try_from(frames).unwrap_or(u32::MAX),
        accelerators: if rounds > 1 {
            u32::try_from(renderers).unwrap_or(u32::MAX)
        } else {
            1
        },
    }
}

/// Compares every rendering backend on `scene` (named `name` in the
/// report), as the module documentation says.
///
/// # Errors
/// No exact surface with `options.truth`, a backend that does not build,
/// a repeated render that differs from the first.
pub fn compare(
    scene: &Scene,
    name: &str,
    options: &CompareOptions,
    progress: Option<Progress<'_>>,
) -> Result<Compared> {
    // Fail before any rendering when there is no exact surface.
    let truth = if options.truth {
        Some(Truth::new(scene)?)
    } else {
        None
    };
    let diagonal = scene.options.scale.diagonal;
    let (frames, backends) = render_every_backend(scene, options.rounds, progress)?;
    let truth_frame = truth.map(|t| render_truth(scene, &t, progress));
    let tolerances = Tolerances::default();
    // The reference backend's cause of every pixel, for `D-causes.png`.
    let mut reference_causes: Option<Vec<Cause>> = None;
    let truth = truth_frame.as_ref().map(|tf| TruthReport {
        render_seconds: tf.seconds,
        backends: backends
            .iter()
            .zip(&frames)
            .map(|(b, f)| {
                let mut oriented = f.clone();
                orient_to_camera(&mut oriented, &scene.camera);
                let (by_cause, causes) =
                    error_budget(&oriented, tf, diagonal, &tolerances, &scene.material_of);
                reference_causes.get_or_insert(causes);
                NamedTruthErrors {
                    name: b.name,
                    errors: truth_errors(oriented, tf, &scene.camera, diagonal),
                    by_cause,
                }
            })
            .collect(),
    });
    let report = CompareReport {
        scene: name.to_string(),
        splats: scene.splats.len(),
        triangles: scene.triangles.tris.len(),
        as_triangles: None,
        rays: frames.first().map_or(0, |f| f.depth.len()),
        rounds: options.rounds,
        backends,
        truth,
    };
    Ok(Compared {
        report,
        frames,
        truth_frame,
        reference_causes,
    })
}

/// Every rendering backend of the registry built and rendering `scene`,
/// the first the reference: each one's frame and run, with its speed ratio
/// to the reference and their agreement. With one round, one backend is
/// built at a time; with more, every backend is built first and they take
/// turns, `rounds` times, each round's speed ratios taken within the round
/// (a render repeats the first bit for bit: the frames kept are the first
/// round's, and a later one that differs is an error).
fn render_every_backend(
    scene: &Scene,
    rounds: u32,
    progress: Option<Progress<'_>>,
) -> Result<(Vec<Frame>, Vec<BackendRun>)> {
    let diagonal = scene.options.scale.diagonal;
    let infos = registry::renderers();
    let mut frames: Vec<Frame> = Vec::new();
    // Per backend: its build figures, and its rays per second per round.
    let mut built = Vec::new();
    let mut speeds: Vec<Vec<f64>> = vec![Vec::new(); infos.len()];
    let mut seconds: Vec<Vec<f64>> = vec![Vec::new(); infos.len()];
    let mut render_one = |i: usize, backend: &dyn crate::accel::Backend| -> Result<()> {
        let frame = render(scene, backend, progress);
        speeds[i].push(mrays_per_s(&frame));
        seconds[i].push(frame.seconds);
        match frames.get(i) {
            None => frames.push(frame),
            Some(first) if same_image(first, &frame) => {}
            Some(_) => {
                return Err(Error::invalid(format!(
                    "{}: a repeated render differs from the first (the comparison needs renders that repeat)",
                    infos[i].name
                )));
            }
        }
        Ok(())
    };
    if rounds <= 1 {
        for (i, info) in infos.iter().enumerate() {
            let backend = info.build_scene(scene)?;
            render_one(i, backend.as_ref())?;
            built.push((backend.stats().build_seconds, backend.stats().memory_bytes));
        }
    } else {
        let backends = infos
            .iter()
            .map(|info| info.build_scene(scene))
            .collect::<Result<Vec<_>>>()?;
        for _ in 0..rounds {
            for (i, backend) in backends.iter().enumerate() {
                render_one(i, backend.as_ref())?;
            }
        }
        built.extend(
            backends
                .iter()
                .map(|b| (b.stats().build_seconds, b.stats().memory_bytes)),
        );
    }
    let runs = infos
        .iter()
        .enumerate()
        .map(|(i, info)| {
            let (ratio, range) = if i == 0 {
                (None, None)
            } else {
                let ratios: Vec<f64> = speeds[0]
                    .iter()
                    .zip(&speeds[i])
                    .map(|(r, s)| r / s.max(1e-12))
                    .collect();
                let lo = ratios.iter().copied().fold(f64::INFINITY, f64::min);
                let hi = ratios.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                (Some(median(ratios)), Some([lo, hi]))
            };
            BackendRun {
                name: info.name,
                build_seconds: built[i].0,
                memory_bytes: built[i].1,
                render_seconds: median(seconds[i].clone()),
                mrays_per_s: median(speeds[i].clone()),
                reference_over_this: ratio,
                reference_over_this_range: range,
                agreement: (i > 0).then(|| compare_frames(&frames[0], &frames[i], diagonal)),
            }
        })
        .collect();
    Ok((frames, runs))
}

/// The median of `v` (the mean of the middle two for an even count; 0 for
/// none).
fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => 0.0,
        n if n % 2 == 1 => v[n / 2],
        n => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}

/// True when two renders of one scene give the same image, depths and
/// splats, bit for bit.
fn same_image(a: &Frame, b: &Frame) -> bool {
    let bits = |x: &f32| x.to_bits();
    let rgb = |c: &glam::Vec3| c.to_array().map(f32::to_bits);
    a.rgb.iter().map(rgb).eq(b.rgb.iter().map(rgb))
        && a.depth.iter().map(bits).eq(b.depth.iter().map(bits))
        && a.splat == b.splat
}
