//! The `splat` workflow: a cloud in, a splat file out. One cloud read
//! whole (a file, a folder, standard input or a pipe: `io::Source`) goes
//! read -> generate (clean, normals, grow, fields) -> trim along lines of
//! sight -> colour fields -> held-out coverage; several inputs, a cloud
//! too large for memory, or a stage asked for go through tiled generation
//! (`crate::tiled`); a Gaussian splat file is read as splats as it is. The
//! splat file and the report are committed together (`io::Batch`): a
//! failure leaves neither. Options are plain values and the outcome a
//! typed, serialisable report: the command line only parses and prints.

use crate::freespace::TrimReport;
use crate::pipeline::Beside;
use crate::io::{
    Batch, Format, RADIUS_PER_SIGMA, Source, encode_splats, encode_splats_with, file_layout,
    is_piped,
};
use crate::progress::{Progress, notify};
use crate::render::output::{check_extension, check_writable};
use crate::splat::{PointCloud, SplatParams, SplatReport};
use crate::tiled::{BYTES_PER_POINT, Stage, TiledOptions, TiledReport, Tiling, generate_tiled};
use crate::validate::holdout::{
    HeldOutCoverage, Windows, heldout_coverage, heldout_coverage_windows,
};
use crate::{Error, Result};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Splat generation's options as given (built into [`SplatParams`] in one
/// place, [`crate::splat::GenerationOptions::params`]).
pub use crate::splat::GenerationOptions;

/// What [`splat`] is asked to do.
#[derive(Clone, Debug, PartialEq)]
pub struct SplatRequest {
    /// The clouds: files, folders (their point files), `-` or a pipe.
    pub inputs: Vec<PathBuf>,
    /// The format of a one-cloud input whose name says nothing.
    pub format: Option<Format>,
    /// The splat file (binary PLY).
    pub output: PathBuf,
    /// Where the report is written as JSON, with the splat file.
    pub report: Option<PathBuf>,
    /// Generation options.
    pub generation: GenerationOptions,
    /// Fraction of the points held out for the held-out coverage (0: off;
    /// else in (0, 0.5]).
    pub holdout: f32,
    /// Measure the held-out coverage over the whole cloud, not in windows.
    pub holdout_full: bool,
    /// A Gaussian input's opacity threshold.
    pub min_opacity: f32,
    /// Tiled generation within this many bytes (`None`: what the process
    /// may use; given: tiled).
    pub max_memory: Option<u64>,
    /// Tile size, stage and resuming (any given: tiled).
    pub tiling: Tiling,
}

impl SplatRequest {
    /// `inputs` to `output` with every option at its default (a held-out
    /// fraction of 0.1).
    #[must_use]
    pub fn new(inputs: Vec<PathBuf>, output: PathBuf) -> SplatRequest {
        SplatRequest {
            inputs,
            format: None,
            output,
            report: None,
            generation: GenerationOptions::default(),
            holdout: 0.1,
            holdout_full: false,
            min_opacity: crate::io::MIN_OPACITY,
            max_memory: None,
            tiling: Tiling::default(),
        }
    }
}

/// What [`splat`] did.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(untagged)]
pub enum SplatOutcome {
    /// One cloud of points, read whole.
    Points(Box<PointsOutcome>),
    /// A Gaussian splat file read as splats.
    Gaussians(GaussiansOutcome),
    /// Tiled generation (or one stage of it).
    Tiled(TiledOutcome),
}

/// The report of one cloud's generation (what `--report` writes).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PointsReport {
    /// Generation's report.
    #[serde(flatten)]
    pub generation: SplatReport,
    /// The held-out coverage, when measured.
    pub heldout_coverage: Option<HeldOutCoverage>,
    /// Where it was measured (absent when measured over the whole cloud).
    pub heldout_windows: Option<Windows>,
    /// What measuring it took (beside the stages after growth).
    pub heldout_seconds: Option<f64>,
    /// The wall seconds generation waited for it after its own last stage.
    pub heldout_waited: Option<f64>,
    /// The linear colour fields (absent: constant colours).
    pub color_fields: Option<ColorFields>,
}

/// What fitting the colour fields did (`splat::color::fit_cloud`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ColorFields {
    /// Splats whose field was fitted.
    pub fitted: usize,
    /// Splats that kept a constant colour (too few or collinear points).
    pub constant: usize,
    /// Seconds the fit took.
    pub seconds: f64,
}

/// [`SplatOutcome::Points`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PointsOutcome {
    /// What `--report` holds.
    pub report: PointsReport,
    /// The cloud's origin (the splat file keeps it), in the input's
    /// coordinates.
    pub origin: [f64; 3],
    /// What trimming along the lines of sight did (with a viewpoint).
    pub trim: Option<TrimReport>,
    /// Why the held-out coverage asked for could not be measured.
    pub heldout_failed: Option<String>,
    /// Seconds the held-out pass took (also when it failed).
    pub heldout_seconds: f64,
    /// Seconds generation waited for it after its own last stage.
    pub heldout_waited: f64,
}

/// What `--report` writes for a Gaussian input.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GaussianReport {
    /// `2dgs` or `3dgs`.
    pub layout: &'static str,
    /// Gaussians in the file.
    pub gaussians: usize,
    /// Splats made.
    pub splats: usize,
    /// Gaussians left out, by reason.
    pub skipped: Vec<(String, usize)>,
    /// 3DGS Gaussians read as discs although not flat.
    pub not_flat: usize,
    /// A splat's radius in standard deviations.
    pub radius_per_sigma: f32,
    /// The opacity threshold.
    pub min_opacity: f32,
}

/// [`SplatOutcome::Gaussians`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GaussiansOutcome {
    /// What `--report` holds.
    pub report: GaussianReport,
    /// The splats' origin, in the file's coordinates.
    pub origin: [f64; 3],
    /// Point options given that do not apply to Gaussians.
    pub point_options_ignored: bool,
    /// The reader's warnings.
    pub warnings: Vec<String>,
    /// View-dependent colour coefficients per Gaussian not read.
    pub sh_rest: usize,
    /// Seconds from reading to writing.
    pub seconds: f64,
}

/// [`SplatOutcome::Tiled`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TiledOutcome {
    /// Tiled generation's report (also what `--report` holds).
    pub report: TiledReport,
    /// The stage run.
    #[serde(skip)]
    pub stage: Stage,
    /// The work folder of the tiles.
    pub work: PathBuf,
}

/// Runs the `splat` workflow of `req` (module documentation), reporting
/// progress; the splat file and the report are written together.
///
/// # Errors
/// One line: a bad option, an input that does not read, no splat made,
/// an output that cannot be written.
pub fn splat(req: &SplatRequest, progress: Option<Progress<'_>>) -> Result<SplatOutcome> {
    check_request(req)?;
    let inputs = expand_inputs(&req.inputs)?;
    if let Some(tiled) = tiled_options(req, &inputs)? {
        let params = req.generation.params_without_viewpoint();
        let report = generate_tiled(&inputs, &params, &tiled, &req.output, progress)?;
        if let Some(r) = &req.report {
            crate::io::write_text(r, &json_text(&report)?)?;
        }
        return Ok(SplatOutcome::Tiled(TiledOutcome {
            report,
            stage: tiled.tiling.stage,
            work: tiled.work,
        }));
    }
    let source = Source::open(&req.inputs[0], req.format)?;
    if let Some(layout) = source.gaussian_layout() {
        return from_gaussians(req, &source, layout.name()).map(SplatOutcome::Gaussians);
    }
    points(req, &source, progress).map(|p| SplatOutcome::Points(Box::new(p)))
}

/// One cloud read whole, generated, trimmed, coloured, checked.
fn points(
    req: &SplatRequest,
    source: &Source,
    progress: Option<Progress<'_>>,
) -> Result<PointsOutcome> {
    notify(progress, "reading", 0.0);
    let t0 = Instant::now();
    let cloud = source.read_points()?;
    let read = t0.elapsed().as_secs_f64();
    let params = req.generation.params(&cloud);
    // The held-out check beside the stages after growth (it reads what
    // growth leaves: `pipeline::generate_beside`).
    let measure = |whole: &SplatReport, left_out: &[u32]| {
        HeldOut::measure(req, &cloud, &params, (whole, left_out))
    };
    let (generated, beside) = if req.holdout > 0.0 {
        crate::pipeline::generate_beside(&cloud, &params, progress, "held-out coverage", measure)
    } else {
        crate::pipeline::generate(&cloud, &params, progress).map(|g| (g, Beside::none()))
    }
    .map_err(|e| e.context(source.path().display()))?;
    let (splats, mut generation, trim) = (generated.splats, generated.report, generated.trim);
    let (fields, zero_fields) = (generated.color_fields, generated.constant_color_fields);
    let colors_seconds = generation.seconds.colors;
    let heldout = beside.value.unwrap_or_else(HeldOut::none);
    generation.seconds.read = read;
    generation.seconds.total += read;
    let bytes = encode_splats_with(
        &req.output,
        &splats,
        (!fields.is_empty()).then_some(&fields[..]),
        cloud.origin,
    )?;
    let report = PointsReport {
        generation,
        heldout_seconds: heldout.coverage.is_some().then_some(heldout.seconds),
        heldout_waited: heldout.coverage.is_some().then_some(beside.waited),
        heldout_coverage: heldout.coverage,
        heldout_windows: heldout.windows,
        color_fields: (!fields.is_empty()).then_some(ColorFields {
            fitted: fields.len() - zero_fields,
            constant: zero_fields,
            seconds: colors_seconds,
        }),
    };
    commit_outputs(req, &bytes, &report)?;
    Ok(PointsOutcome {
        report,
        origin: cloud.origin.to_array(),
        trim,
        heldout_failed: heldout.failed,
        heldout_seconds: heldout.seconds,
        heldout_waited: beside.waited,
    })
}

/// The options checked before anything is read.
fn check_request(req: &SplatRequest) -> Result<()> {
    if req.inputs.is_empty() {
        return Err("no input".into());
    }
    check_extension(&req.output, &["ply"])?;
    if let Some(r) = &req.report {
        check_writable(r)?;
    }
    if !(req.holdout == 0.0 || (req.holdout > 0.0 && req.holdout <= 0.5)) {
        return Err(Error::invalid(format!(
            "--holdout {} must be 0 (off) or in (0, 0.5]",
            req.holdout
        )));
    }
    if !(0.0..=1.0).contains(&req.min_opacity) {
        return Err(Error::invalid(format!(
            "--min-opacity {} must be in [0, 1]",
            req.min_opacity
        )));
    }
    Ok(())
}

/// The held-out coverage asked for: measured, or why not.
struct HeldOut {
    coverage: Option<HeldOutCoverage>,
    /// Where it was measured (`None` over the whole cloud).
    windows: Option<Windows>,
    /// Why it could not be measured.
    failed: Option<String>,
    /// What measuring it took.
    seconds: f64,
}

impl HeldOut {
    /// Nothing measured.
    fn none() -> HeldOut {
        HeldOut {
            coverage: None,
            windows: None,
            failed: None,
            seconds: 0.0,
        }
    }

    /// Measures it (nothing with a held-out fraction of 0): over the whole
    /// cloud with `holdout_full`, else in windows; `generation` is the
    /// report of the cloud's own generation (its `ϵ`, mean radius and
    /// tolerance, as growth leaves them) and the points it left out as
    /// outliers.
    fn measure(
        req: &SplatRequest,
        cloud: &PointCloud,
        params: &SplatParams,
        generation: (&SplatReport, &[u32]),
    ) -> HeldOut {
        let mut out = HeldOut::none();
        let t = Instant::now();
        if req.holdout > 0.0 {
            let measured = if req.holdout_full {
                heldout_coverage(cloud, params, req.holdout, 1)
            } else {
                heldout_coverage_windows(cloud, params, req.holdout, 1, generation).map(|(h, w)| {
                    out.windows = Some(w);
                    h
                })
            };
            out.coverage = measured.map_err(|e| out.failed = Some(e.to_string())).ok();
        }
        out.seconds = t.elapsed().as_secs_f64();
        out
    }
}

/// A Gaussian file's Gaussians as splats (frame from the rotation, radii
/// from the scales, colour from the DC term); the point options do not
/// apply.
fn from_gaussians(
    req: &SplatRequest,
    source: &Source,
    layout: &'static str,
) -> Result<GaussiansOutcome> {
    let t0 = Instant::now();
    let read = source.read_gaussians(req.min_opacity)?;
    let set = &read.set;
    let bytes = encode_splats(&req.output, &set.splats, set.origin)?;
    let report = GaussianReport {
        layout,
        gaussians: read.gaussians,
        splats: set.splats.len(),
        skipped: read.skipped.clone(),
        not_flat: read.not_flat,
        radius_per_sigma: RADIUS_PER_SIGMA,
        min_opacity: req.min_opacity,
    };
    commit_outputs(req, &bytes, &report)?;
    Ok(GaussiansOutcome {
        report,
        origin: set.origin.to_array(),
        point_options_ignored: req.generation.point_options_given(),
        warnings: read.warnings(),
        sh_rest: read.sh_rest,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// `value` as pretty JSON (a report).
fn json_text<T: Serialize>(value: &T) -> Result<String> {
    serde_json::to_string_pretty(value).map_err(Error::other)
}

/// Writes the splat file and the report (when asked for) as one batch: a
/// failure in either leaves neither.
fn commit_outputs(req: &SplatRequest, splats: &[u8], report: &impl Serialize) -> Result<()> {
    let mut batch = Batch::new();
    batch.stage(&req.output, |t| std::fs::write(t, splats))?;
    if let Some(path) = &req.report {
        let text = json_text(report)?;
        batch.stage(path, |t| std::fs::write(t, &text))?;
    }
    batch.commit()?;
    Ok(())
}

/// The inputs: files as given, and the point files of a folder (by name).
fn expand_inputs(given: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for p in given {
        if p.is_dir() {
            out.extend(crate::io::cloud_files(p)?);
        } else {
            out.push(p.clone());
        }
    }
    Ok(out)
}

/// Tiled generation's options when this run takes it: a memory bound or
/// tile size given, several inputs, a stage asked for, or a cloud that
/// would not fit the memory this process may use (estimated from its size
/// on disk).
fn tiled_options(req: &SplatRequest, inputs: &[PathBuf]) -> Result<Option<TiledOptions>> {
    let max_memory = match req.max_memory {
        Some(0) => return Err("--max-memory must be a positive number of GB".into()),
        Some(b) => b,
        None => crate::memory::available().unwrap_or(u64::MAX),
    };
    if req.tiling.tile_points == Some(0) {
        return Err("--tile-points must be at least 1".into());
    }
    // At least 12 bytes a point on disk: a file of B bytes holds at most
    // B / 12 points.
    let disk: u64 = inputs
        .iter()
        .filter_map(|p| std::fs::metadata(p).ok())
        .map(|m| m.len())
        .sum();
    let too_big = (disk / 12).saturating_mul(BYTES_PER_POINT) > max_memory;
    let tiled =
        req.max_memory.is_some() || req.tiling != Tiling::default() || inputs.len() > 1 || too_big;
    if !tiled {
        return Ok(None);
    }
    if let Some(p) = inputs.iter().find(|p| is_piped(p)) {
        return Err(Error::invalid(format!(
            "{}: standard input or a pipe is read whole, once: tiled generation reads its inputs twice (write the cloud to a file)",
            p.display()
        )));
    }
    if req.format.is_some() {
        return Err(
            "--format names the format of one cloud read whole: tiled generation takes files named by their format".into(),
        );
    }
    if inputs.iter().any(|p| file_layout(p).is_some()) {
        return Err(
            "a Gaussian splat file is read as splats as it is: tiles are for point clouds".into(),
        );
    }
    Ok(Some(TiledOptions {
        max_memory,
        work: work_folder(&req.output),
        viewpoint: req.generation.viewpoint,
        no_viewpoint: req.generation.no_viewpoint,
        tiling: req.tiling,
    }))
}

/// The work folder of tiled generation: `.NAME.tiles` beside the output.
fn work_folder(output: &Path) -> PathBuf {
    let name = output
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    output.with_file_name(format!(".{name}.tiles"))
}
