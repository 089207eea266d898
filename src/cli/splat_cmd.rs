//! `splatray splat IN -o OUT.ply [--epsilon E] [--k K] [--density F]
//! [--ellipses] [--report R.json]`.

use super::progress::ProgressLine;
use super::{json_text, stage_text};
use glam::DVec3;
use splatray::freespace::generate_trimmed;
use splatray::io::{
    Batch, GaussianLayout, IoError, IoErrorKind, encode_splats, encode_splats_with, file_layout,
    read_gaussians, read_points,
};
use splatray::render::output::{check_extension, check_writable};
use splatray::splat::color::fit_cloud;
use splatray::splat::{PointCloud, SplatParams};
use splatray::validate::holdout::{
    HeldOutCoverage, Windows, heldout_coverage, heldout_coverage_windows,
};
use splatray::{Error, Result};
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `splatray splat`.
#[derive(Clone, Debug, clap::Args)]
pub struct SplatArgs {
    /// Input point cloud (.ply, .pcd, .xyz/.txt, .las/.laz, .e57, or
    /// recognised by content); a folder, or several files (e.g. a shell
    /// glob of LAZ tiles), are read as one cloud in tiles.
    #[arg(required = true, num_args = 1..)]
    pub inputs: Vec<PathBuf>,
    /// Output splat file (binary PLY).
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Splat generation options.
    #[command(flatten)]
    pub splat: SplatOptions,
    /// Write the generation report as JSON here.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Also grow splats without this fraction of the points (in (0, 0.5];
    /// 0 skips it) and report how many of those lie on them: a coverage
    /// that can fail (the output splats use every point).
    #[arg(long, default_value_t = 0.1)]
    pub holdout: f32,
    /// Measure the held-out coverage over the whole cloud (splats grown a
    /// second time from all but the held-out points) instead of in four
    /// windows holding about 6 % of it (clouds of 2,000,000 points or more).
    #[arg(long)]
    pub holdout_full: bool,
    /// When the input is a Gaussian splat file (2DGS or 3DGS layout, read
    /// as splats without growing them): leave out Gaussians less opaque
    /// than this.
    #[arg(long, default_value_t = splatray::io::MIN_OPACITY)]
    pub min_opacity: f32,
    /// Generate in tiles within this many GB (the whole process): points
    /// are spilled to per-tile files beside the output and each tile
    /// generated on its own with a halo. Default: what the process may
    /// use (the least of MemAvailable, the cgroup's limit, RLIMIT_AS and
    /// RLIMIT_DATA); tiles are used when the cloud would not fit it.
    #[arg(long)]
    pub max_memory: Option<f64>,
    /// At most this many points (core and halo) per tile: forces tiled
    /// generation with tiles smaller than the memory allows.
    #[arg(long)]
    pub tile_points: Option<u64>,
    /// Tiled generation in stages, for a cluster sharing the output's
    /// folder: survey, plan and spill the tiles, then stop (the report's
    /// `cores` lists the tiles).
    #[arg(long, conflicts_with_all = ["tile", "merge_only"])]
    pub plan_only: bool,
    /// Generate this one tile of the plan `--plan-only` made with the same
    /// inputs and options (nothing when it is finished).
    #[arg(long, conflicts_with = "merge_only")]
    pub tile: Option<usize>,
    /// Merge the finished tiles of that plan into the output.
    #[arg(long)]
    pub merge_only: bool,
}

impl SplatArgs {
    /// The one input of an untiled run.
    fn input(&self) -> &std::path::Path {
        &self.inputs[0]
    }
}

/// The report `--report` writes: the generation's, and the held-out
/// coverage when it was measured.
#[derive(serde::Serialize)]
struct Report<'a> {
    #[serde(flatten)]
    generation: &'a splatray::splat::SplatReport,
    heldout_coverage: Option<HeldOutCoverage>,
    /// Where it was measured (absent when measured over the whole cloud).
    heldout_windows: Option<Windows>,
    /// What measuring it took.
    heldout_seconds: Option<f64>,
    /// The linear colour fields (absent: constant colours).
    color_fields: Option<ColorFields>,
}

/// What fitting the colour fields did (`splat::color::fit_cloud`).
#[derive(serde::Serialize)]
struct ColorFields {
    /// Splats whose field was fitted.
    fitted: usize,
    /// Splats that kept a constant colour (too few or collinear points).
    constant: usize,
    /// Seconds the fit took.
    seconds: f64,
}

/// The splat generation options `splat` and `scan-check` share.
#[derive(Clone, Debug, clap::Args)]
pub struct SplatOptions {
    /// Error threshold ϵ of §2.1 as a fraction of the bounding-box diagonal
    /// (`SplatParams::epsilon_rel`; the report gives it in the cloud's units).
    #[arg(long = "epsilon")]
    pub epsilon_rel: Option<f32>,
    /// Neighbours per point.
    #[arg(long)]
    pub k: Option<usize>,
    /// Density factor of §2.2, in (0, 1].
    #[arg(long)]
    pub density: Option<f32>,
    /// Grow elliptical splats along the minimum-curvature direction.
    #[arg(long)]
    pub ellipses: bool,
    /// One colour per splat: no linear colour field fitted to a coloured
    /// cloud's points (`splat::color`; the fields are on by default).
    #[arg(long)]
    pub flat_colors: bool,
    /// Whole discs only: no crease detection, no clip lines (splats grow
    /// across creases and overhang them, as before issue 39).
    #[arg(long)]
    pub no_creases: bool,
    /// Where the scanner stood, as X,Y,Z in the input's coordinates:
    /// normals are oriented toward it. Default: the cloud's own (a PCD's
    /// VIEWPOINT).
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    pub viewpoint: Option<Vec<f64>>,
    /// Ignore the cloud's own viewpoint (or its scanners' positions).
    #[arg(long, conflicts_with = "viewpoint")]
    pub no_viewpoint: bool,
    /// Where the cloud is denser than ϵ needs, keep one point per cell this
    /// many ϵ wide (default 0: every point is used).
    #[arg(long)]
    pub thin: Option<f64>,
}

impl SplatOptions {
    /// The viewpoint given on the command line, checked.
    ///
    /// # Errors
    /// Not three finite numbers.
    pub fn viewpoint(&self) -> Result<Option<DVec3>> {
        match self.viewpoint.as_deref() {
            None => Ok(None),
            Some([x, y, z]) if [x, y, z].iter().all(|v| v.is_finite()) => {
                Ok(Some(DVec3::new(*x, *y, *z)))
            }
            Some(v) => Err(Error::invalid(format!(
                "--viewpoint needs three finite numbers, got {v:?}"
            ))),
        }
    }

    /// The generation parameters for `cloud`: the options given, defaults
    /// for the rest, the viewpoint given (made relative to the cloud's
    /// origin, in f64) or else the cloud's own.
    ///
    /// # Errors
    /// A malformed viewpoint.
    pub fn params(&self, cloud: &PointCloud) -> Result<SplatParams> {
        let viewpoint = if self.no_viewpoint {
            None
        } else {
            self.viewpoint()?
                .map(|v| cloud.local_viewpoint(v))
                .or(cloud.viewpoint)
        };
        Ok(SplatParams {
            viewpoint,
            ..self.params_without_viewpoint()
        })
    }

    /// The generation parameters the options give before a cloud is read
    /// (tiled generation finds each tile's viewpoints itself): the options
    /// given, defaults for the rest.
    #[must_use]
    pub fn params_without_viewpoint(&self) -> SplatParams {
        let defaults = SplatParams::default();
        SplatParams {
            k: self.k.unwrap_or(defaults.k),
            epsilon_rel: self.epsilon_rel.unwrap_or(defaults.epsilon_rel),
            density: self.density.unwrap_or(defaults.density),
            ellipses: self.ellipses,
            color_fields: !self.flat_colors,
            creases: !self.no_creases,
            scan_viewpoints: !self.no_viewpoint,
            thin: self.thin.unwrap_or(defaults.thin),
            ..defaults
        }
    }
}

/// Run `splatray splat`; the message of an error is one line.
///
/// # Errors
/// When the input cannot be read, no splat can be made, or an output cannot
/// be written.
pub fn run(args: &SplatArgs) -> Result<()> {
    check_args(args)?;
    let inputs = expand_inputs(&args.inputs)?;
    if let Some(tiled) = tiled_options(args, &inputs)? {
        return run_tiled(args, &inputs, &tiled);
    }
    if let Some(layout) = file_layout(args.input()) {
        return from_gaussians(args, layout);
    }
    let line = ProgressLine::new();
    line.update("reading", 0.0);
    let t0 = Instant::now();
    let cloud = read_points(args.input())?;
    let read = t0.elapsed().as_secs_f64();
    let params = args.splat.params(&cloud)?;
    let (mut splats, mut report, trim) =
        generate_trimmed(&cloud, &params, Some(&|stage, f| line.update(stage, f)))
            .map_err(|e| e.context(args.input().display()))?;
    line.update("colour fields", 0.0);
    let t_colors = Instant::now();
    let (fields, zero_fields) = fit_cloud(&mut splats, &cloud, &params);
    let colors_seconds = t_colors.elapsed().as_secs_f64();
    if let Some(t) = trim.filter(|t| t.shrunk > 0) {
        eprintln!(
            "splatray: {} splats shrunk off {} of {} lines of sight from the viewpoint and {} of \
             the scanner's {} rays that met nothing ({} still blocked; {} kept whole where \
             shrinking would open a hole in the scanned surface)",
            t.shrunk, t.blocked, t.rays, t.misses_blocked, t.misses, t.still_blocked, t.kept_whole
        );
    }
    let heldout = HeldOut::measure(args, &cloud, &params, report.epsilon, &line);
    line.finish();
    report.seconds.read = read;
    report.seconds.total += read;
    let bytes = encode_splats_with(
        &args.output,
        &splats,
        (!fields.is_empty()).then_some(&fields[..]),
        cloud.origin,
    )?;
    let out = Report {
        generation: &report,
        heldout_coverage: heldout.coverage.clone(),
        heldout_windows: heldout.windows.clone(),
        heldout_seconds: heldout.coverage.is_some().then_some(heldout.seconds),
        color_fields: (!fields.is_empty()).then_some(ColorFields {
            fitted: fields.len() - zero_fields,
            constant: zero_fields,
            seconds: colors_seconds,
        }),
    };
    commit_outputs(args, &bytes, &out)?;
    if let Some(c) = &out.color_fields {
        eprintln!(
            "splatray: linear colour fields on {} splats ({} kept one colour: too few points), {:.2} s (--flat-colors: none)",
            c.fitted, c.constant, c.seconds
        );
    }
    print_generated(args, &cloud, &report);
    heldout.print(report.seconds.total);
    Ok(())
}

/// The options `run` checks before reading anything.
fn check_args(args: &SplatArgs) -> Result<()> {
    args.splat.viewpoint()?;
    check_extension(&args.output, &["ply"])?;
    if let Some(r) = &args.report {
        check_writable(r)?;
    }
    if !(args.holdout == 0.0 || (args.holdout > 0.0 && args.holdout <= 0.5)) {
        return Err(Error::invalid(format!(
            "--holdout {} must be 0 (off) or in (0, 0.5]",
            args.holdout
        )));
    }
    if !(0.0..=1.0).contains(&args.min_opacity) {
        return Err(Error::invalid(format!(
            "--min-opacity {} must be in [0, 1]",
            args.min_opacity
        )));
    }
    Ok(())
}

/// The held-out coverage `--holdout` asks for: measured, or why not.
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
    /// Measures it (nothing with `--holdout 0`): over the whole cloud with
    /// `--holdout-full`, else in windows; `epsilon` is the generation's, in
    /// the cloud's units.
    fn measure(
        args: &SplatArgs,
        cloud: &PointCloud,
        params: &SplatParams,
        epsilon: f64,
        line: &ProgressLine,
    ) -> HeldOut {
        let mut out = HeldOut {
            coverage: None,
            windows: None,
            failed: None,
            seconds: 0.0,
        };
        let t = Instant::now();
        if args.holdout > 0.0 {
            line.update("held-out coverage", 0.0);
            let measured = if args.holdout_full {
                heldout_coverage(cloud, params, args.holdout, 1)
            } else {
                heldout_coverage_windows(cloud, params, args.holdout, 1, epsilon).map(|(h, w)| {
                    out.windows = Some(w);
                    h
                })
            };
            out.coverage = measured.map_err(|e| out.failed = Some(e.to_string())).ok();
        }
        out.seconds = t.elapsed().as_secs_f64();
        out
    }

    /// Its line (or a warning why there is none), against generation's
    /// `total` seconds.
    fn print(&self, total: f64) {
        if let Some(h) = self.coverage.as_ref().filter(|h| h.tested == 0) {
            eprintln!(
                "splatray: warning: held-out coverage not measured: none of the {:.0} % of the points held out could be tested ({} held-out outliers)",
                100.0 * h.fraction,
                h.outliers
            );
        } else if let Some(h) = &self.coverage {
            let whre = match self.windows.as_ref().filter(|w| w.windows > 0) {
                Some(w) => format!(
                    "in {} windows holding {:.1} % of the cloud",
                    w.windows,
                    100.0 * w.share
                ),
                None => "over the whole cloud".into(),
            };
            eprintln!(
                "splatray: held-out coverage {:.4}: splats grown without {:.0} % of the points hold {} of the {} tested (within {:.3e} of a splat's plane; {} held-out outliers not tested), {whre}: {:.2} s, {:.0} % of generation",
                h.coverage,
                100.0 * h.fraction,
                h.found,
                h.tested,
                h.tolerance,
                h.outliers,
                self.seconds,
                100.0 * self.seconds / total.max(1e-9)
            );
        }
        if let Some(e) = &self.failed {
            eprintln!("splatray: warning: held-out coverage not measured: {e}");
        }
    }
}

/// Generation's warnings and notes, and its one-line summary.
fn print_generated(args: &SplatArgs, cloud: &PointCloud, report: &splatray::splat::SplatReport) {
    for w in &report.warnings {
        eprintln!("splatray: warning: {w}");
    }
    for s in &report.skipped_points {
        // Thinning is asked for (--thin): a note, not a warning.
        let kind = if s.reason.starts_with("denser than") {
            "note: thinned"
        } else {
            "warning: skipped"
        };
        eprintln!("splatray: {kind} {} points: {}", s.count, s.reason);
    }
    eprintln!(
        "splatray: {} points -> {} splats ({} elliptical, {} clipped), coverage {:.4}, mean radius {:.4e}, largest splat {:.1}x its local spacing, epsilon {:.3e}, noise {:.3e}, {} flat normal fields, origin [{:?}, {:?}, {:?}], {:.2} s -> {}",
        report.used_points,
        report.splats,
        report.elliptical_splats,
        report.clipped,
        report.coverage,
        report.mean_radius,
        report.largest_over_spacing,
        report.epsilon,
        report.noise,
        report.fallback_normal_fields,
        cloud.origin.x,
        cloud.origin.y,
        cloud.origin.z,
        report.seconds.total,
        args.output.display()
    );
    eprintln!(
        "splatray: largest splats (> {}x median radius) whose centre is farther than half a radius from their points: {}",
        splatray::splat::HOLLOW_LARGE,
        report.hollow_large_splats
    );
}

/// What `--report` writes for a Gaussian input.
#[derive(serde::Serialize)]
struct GaussianReport {
    layout: &'static str,
    gaussians: usize,
    splats: usize,
    skipped: Vec<(String, usize)>,
    not_flat: usize,
    radius_per_sigma: f32,
    min_opacity: f32,
}

/// `splat` on a Gaussian file: its Gaussians as splats (frame from the
/// rotation, radii from the scales, colour from the DC term), written as a
/// splat file; the point options do not apply.
fn from_gaussians(args: &SplatArgs, layout: GaussianLayout) -> Result<()> {
    let o = &args.splat;
    if o.epsilon_rel.is_some() || o.k.is_some() || o.density.is_some() || o.ellipses {
        eprintln!(
            "splatray: warning: {} is a {} Gaussian file: its Gaussians become splats as they are, and --epsilon, --k, --density and --ellipses do not apply",
            args.input().display(),
            layout.name()
        );
    }
    let t0 = Instant::now();
    let read = read_gaussians(args.input(), args.min_opacity)?;
    let set = &read.set;
    let bytes = encode_splats(&args.output, &set.splats, set.origin)?;
    let report = GaussianReport {
        layout: layout.name(),
        gaussians: read.gaussians,
        splats: set.splats.len(),
        skipped: read.skipped.clone(),
        not_flat: read.not_flat,
        radius_per_sigma: splatray::io::RADIUS_PER_SIGMA,
        min_opacity: args.min_opacity,
    };
    commit_outputs(args, &bytes, &report)?;
    for w in read.warnings() {
        eprintln!("splatray: warning: {w}");
    }
    if read.sh_rest > 0 {
        eprintln!(
            "splatray: {} view-dependent colour coefficients (f_rest_*) per Gaussian not read: splats take the base colour",
            read.sh_rest
        );
    }
    eprintln!(
        "splatray: {} {} Gaussians -> {} splats (radius = {} sigma), origin [{:?}, {:?}, {:?}], {:.2} s -> {}",
        read.gaussians,
        layout.name(),
        set.splats.len(),
        splatray::io::RADIUS_PER_SIGMA,
        set.origin.x,
        set.origin.y,
        set.origin.z,
        t0.elapsed().as_secs_f64(),
        args.output.display()
    );
    Ok(())
}

/// Writes the splat file and, with `--report`, `report` as JSON, as one
/// batch: a failure in either leaves neither.
fn commit_outputs(args: &SplatArgs, splats: &[u8], report: &impl serde::Serialize) -> Result<()> {
    let mut batch = Batch::new();
    batch.stage(&args.output, |t| std::fs::write(t, splats))?;
    if let Some(path) = &args.report {
        stage_text(&mut batch, path, &json_text(report)?)?;
    }
    batch.commit()?;
    Ok(())
}

/// The inputs: files as given, and the point files of a folder (by name).
fn expand_inputs(given: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for p in given {
        if p.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(p)
                .map_err(|e| IoError::new(p, IoErrorKind::Io(e)))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| f.is_file() && splatray::io::Format::from_extension(f).is_some())
                .collect();
            found.sort();
            if found.is_empty() {
                return Err(Error::invalid(format!(
                    "{}: no point cloud files in the folder",
                    p.display()
                )));
            }
            out.extend(found);
        } else {
            out.push(p.clone());
        }
    }
    Ok(out)
}

/// Tiled generation's options when this run takes it: `--max-memory` or
/// `--tile-points` given, several inputs, or a cloud that would not fit
/// the memory this process may use (estimated from its size on disk).
fn tiled_options(
    args: &SplatArgs,
    inputs: &[PathBuf],
) -> Result<Option<splatray::tiled::TiledOptions>> {
    let limit = splatray::memory::available();
    let max_memory = match args.max_memory {
        Some(gb) if gb.is_finite() && gb > 0.0 => (gb * 1e9) as u64,
        Some(gb) => {
            return Err(Error::invalid(format!(
                "--max-memory {gb} must be a positive number of GB"
            )));
        }
        None => limit.unwrap_or(u64::MAX),
    };
    if args.tile_points == Some(0) {
        return Err("--tile-points must be at least 1".into());
    }
    // At least 12 bytes a point on disk: a file of B bytes holds at most
    // B / 12 points.
    let disk: u64 = inputs
        .iter()
        .filter_map(|p| std::fs::metadata(p).ok())
        .map(|m| m.len())
        .sum();
    let too_big = (disk / 12).saturating_mul(splatray::tiled::BYTES_PER_POINT) > max_memory;
    let stage = match (args.plan_only, args.tile, args.merge_only) {
        (true, _, _) => splatray::tiled::Stage::Plan,
        (_, Some(t), _) => splatray::tiled::Stage::Tile(t),
        (_, _, true) => splatray::tiled::Stage::Merge,
        _ => splatray::tiled::Stage::All,
    };
    let tiled = args.max_memory.is_some()
        || args.tile_points.is_some()
        || inputs.len() > 1
        || too_big
        || stage != splatray::tiled::Stage::All;
    if !tiled {
        return Ok(None);
    }
    if inputs.iter().any(|p| file_layout(p).is_some()) {
        return Err(
            "a Gaussian splat file is read as splats as it is: tiles are for point clouds".into(),
        );
    }
    let name = args
        .output
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    Ok(Some(splatray::tiled::TiledOptions {
        max_memory,
        tile_points: args.tile_points,
        work: args.output.with_file_name(format!(".{name}.tiles")),
        viewpoint: args.splat.viewpoint()?,
        no_viewpoint: args.splat.no_viewpoint,
        stage,
    }))
}

fn run_tiled(
    args: &SplatArgs,
    inputs: &[PathBuf],
    opts: &splatray::tiled::TiledOptions,
) -> Result<()> {
    let params = args.splat.params_without_viewpoint();
    let line = ProgressLine::new();
    let report = splatray::tiled::generate_tiled(
        inputs,
        &params,
        opts,
        &args.output,
        Some(&|stage, f| line.update(stage, f)),
    );
    line.finish();
    let report = report?;
    if let Some(r) = &args.report {
        splatray::io::write_text(r, &json_text(&report)?)?;
    }
    for w in &report.warnings {
        eprintln!("splatray: warning: {w}");
    }
    let mut warnings: Vec<&String> = report.tiles.iter().flat_map(|t| &t.warnings).collect();
    warnings.sort();
    warnings.dedup();
    for w in warnings {
        eprintln!("splatray: warning (in a tile): {w}");
    }
    match opts.stage {
        splatray::tiled::Stage::Plan => {
            eprintln!(
                "splatray: {} points planned in {} tiles (at most {} points each with a halo of {:.3e}; {} spilled), epsilon {:.3e}; survey {:.1} s, spill {:.1} s, in {}: run each tile with --tile T (0 to {}), then --merge-only",
                report.points,
                report.tiles.len(),
                report.tile_points,
                report.halo,
                report.spilled,
                report.epsilon,
                report.seconds.survey,
                report.seconds.spill,
                opts.work.display(),
                report.tiles.len() - 1
            );
            return Ok(());
        }
        splatray::tiled::Stage::Tile(t) => {
            let s = &report.tiles[t];
            eprintln!(
                "splatray: tile {t} of {}: {} points ({} in its core) -> {} splats kept of {} grown{}, {:.1} s, peak memory {:.2} GB",
                report.tiles.len(),
                s.points,
                s.core_points,
                s.kept,
                s.grown,
                if s.resumed { " (already finished)" } else { "" },
                s.seconds,
                report.peak_rss as f64 / 1e9,
            );
            return Ok(());
        }
        splatray::tiled::Stage::All | splatray::tiled::Stage::Merge => {}
    }
    if args.holdout > 0.0 {
        eprintln!("splatray: note: held-out coverage is not measured in tiled generation");
    }
    let resumed = report.tiles.iter().filter(|t| t.resumed).count();
    if report.flipped_tiles > 0 {
        eprintln!(
            "splatray: note: {} tiles had turned their piece of the surface the other way from their \
             neighbours (no normals or viewpoint to orient by): their {} splats were turned over",
            report.flipped_tiles, report.flipped_splats
        );
    }
    eprintln!(
        "splatray: {} points in {} tiles (at most {} points each with a halo of {:.3e}; {} spilled; {} resumed) -> {} splats, epsilon {:.3e}, {} splats may reach past the halo; survey {:.1} s, spill {:.1} s, generation {:.1} s, merge {:.1} s, total {:.1} s, peak memory {:.2} GB of {:.2} GB -> {}",
        report.points,
        report.tiles.len(),
        report.tile_points,
        report.halo,
        report.spilled,
        resumed,
        report.splats,
        report.epsilon,
        report.past_halo,
        report.seconds.survey,
        report.seconds.spill,
        report.seconds.generate,
        report.seconds.merge,
        report.seconds.total,
        report.peak_rss as f64 / 1e9,
        report.max_memory as f64 / 1e9,
        args.output.display()
    );
    Ok(())
}
