//! `splatray splat IN -o OUT.ply [--epsilon E] [--k K] [--density F]
//! [--ellipses] [--report R.json]`: parses the arguments, runs
//! `crate::workflow::splat::splat` and prints what it did.

use super::common::SplatOptions;
use super::progress::ProgressLine;
use crate::io::Format;
use crate::tiled::{Stage, TiledReport, Tiling};
use crate::workflow::splat::{
    GaussiansOutcome, PointsOutcome, SplatOutcome, SplatRequest, TiledOutcome, splat,
};
use crate::{Error, Result};
use std::path::PathBuf;

/// Arguments of `splatray splat`.
#[derive(Clone, Debug, clap::Args)]
pub struct SplatArgs {
    /// Input point cloud (.ply, .pcd, .xyz/.txt, .las/.laz, .e57, or
    /// recognised by content; `-` for standard input, or a pipe such as
    /// `<(zcat pts.xyz.gz)`, read once); a folder, or several files (e.g.
    /// a shell glob of LAZ tiles), are read as one cloud in tiles.
    #[arg(required = true, num_args = 1..)]
    pub inputs: Vec<PathBuf>,
    /// The input's format, for a name that says nothing (standard input, a
    /// pipe): ply, pcd, xyz (or txt), las (or laz), e57. Default: the
    /// extension, else the first bytes.
    #[arg(long, value_parser = parse_format)]
    pub format: Option<Format>,
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
    /// second time from all but the held-out points) instead of in up to
    /// four windows, which hold at most 8 % of the cloud at every size (a
    /// small cloud's test few points: the line gives the 95 % interval).
    #[arg(long)]
    pub holdout_full: bool,
    /// When the input is a Gaussian splat file (2DGS or 3DGS layout, read
    /// as splats without growing them): leave out Gaussians less opaque
    /// than this.
    #[arg(long, default_value_t = crate::io::MIN_OPACITY)]
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
    /// Carry a tiled run on from its work folder (after a full disk, say):
    /// refused in one line when there is no plan there or it was made for
    /// other inputs or options.
    #[arg(long)]
    pub resume: bool,
}

impl SplatArgs {}

impl SplatArgs {
    /// The workflow's request: the arguments checked and converted.
    ///
    /// # Errors
    /// A malformed viewpoint or memory bound.
    fn request(&self) -> Result<SplatRequest> {
        let max_memory = match self.max_memory {
            Some(gb) if gb.is_finite() && gb > 0.0 => Some((gb * 1e9) as u64),
            Some(gb) => {
                return Err(Error::invalid(format!(
                    "--max-memory {gb} must be a positive number of GB"
                )));
            }
            None => None,
        };
        let stage = match (self.plan_only, self.tile, self.merge_only) {
            (true, _, _) => Stage::Plan,
            (_, Some(t), _) => Stage::Tile(t),
            (_, _, true) => Stage::Merge,
            _ => Stage::All,
        };
        Ok(SplatRequest {
            format: self.format,
            report: self.report.clone(),
            generation: self.splat.generation()?,
            holdout: self.holdout,
            holdout_full: self.holdout_full,
            min_opacity: self.min_opacity,
            max_memory,
            tiling: Tiling {
                tile_points: self.tile_points,
                stage,
                resume: self.resume,
            },
            ..SplatRequest::new(self.inputs.clone(), self.output.clone())
        })
    }
}

/// Run `splatray splat`; the message of an error is one line.
///
/// # Errors
/// When the input cannot be read, no splat can be made, or an output cannot
/// be written.
pub fn run(args: &SplatArgs) -> Result<()> {
    let req = args.request()?;
    let line = ProgressLine::new();
    let outcome = splat(&req, Some(&|stage, f| line.update(stage, f)));
    line.finish();
    match outcome? {
        SplatOutcome::Points(p) => print_points(args, &p),
        SplatOutcome::Gaussians(g) => print_gaussians(args, &g),
        SplatOutcome::Tiled(t) => print_tiled(args, &t),
    }
    Ok(())
}

/// One cloud's lines: trimming, colour fields, generation, held-out.
fn print_points(args: &SplatArgs, p: &PointsOutcome) {
    if let Some(t) = p.trim.as_ref().filter(|t| t.shrunk > 0) {
        eprintln!(
            "splatray: {} splats shrunk off {} of {} lines of sight from the viewpoint and {} of \
             the scanner's {} rays that met nothing ({} still blocked; {} kept whole where \
             shrinking would open a hole in the scanned surface)",
            t.shrunk, t.blocked, t.rays, t.misses_blocked, t.misses, t.still_blocked, t.kept_whole
        );
    }
    if let Some(c) = &p.report.color_fields {
        eprintln!(
            "splatray: linear colour fields on {} splats ({} kept one colour: too few points), {:.2} s (--flat-colors: none)",
            c.fitted, c.constant, c.seconds
        );
    }
    print_generated(args, p);
    print_heldout(p);
}

/// The held-out coverage's line (or a warning why there is none).
fn print_heldout(p: &PointsOutcome) {
    let total = p.report.generation.seconds.total;
    if let Some(h) = p.report.heldout_coverage.as_ref().filter(|h| h.tested == 0) {
        eprintln!(
            "splatray: warning: held-out coverage not measured: none of the {:.0} % of the points held out could be tested ({} held-out outliers)",
            100.0 * h.fraction,
            h.outliers
        );
    } else if let Some(h) = &p.report.heldout_coverage {
        let whre = match p.report.heldout_windows.as_ref().filter(|w| w.windows > 0) {
            Some(w) => format!(
                "in {} window{} holding {:.1} % of the cloud",
                w.windows,
                if w.windows == 1 { "" } else { "s" },
                100.0 * w.share
            ),
            None => "over the whole cloud".into(),
        };
        eprintln!(
            "splatray: held-out coverage {:.4} (95 % interval {:.4}-{:.4}): splats grown without {:.0} % of the points hold {} of the {} tested (within {:.3e} of a splat's plane; {} held-out outliers not tested), {whre}: {:.2} s beside the stages after growth ({:.0} % of generation), {:.2} s waited for after them",
            h.coverage,
            h.interval[0],
            h.interval[1],
            100.0 * h.fraction,
            h.found,
            h.tested,
            h.tolerance,
            h.outliers,
            p.heldout_seconds,
            100.0 * p.heldout_seconds / total.max(1e-9),
            p.heldout_waited
        );
    }
    if let Some(e) = &p.heldout_failed {
        eprintln!("splatray: warning: held-out coverage not measured: {e}");
    }
}

/// Generation's warnings and notes, and its one-line summary.
fn print_generated(args: &SplatArgs, p: &PointsOutcome) {
    let report = &p.report.generation;
    for w in &report.warnings {
        eprintln!("splatray: warning: {w}");
    }
    for s in &report.skipped_points {
        // Thinning (asked for, or unasked where the cloud is far denser
        // than epsilon needs): a note, not a warning.
        let kind = if s.reason.starts_with("denser than") {
            "note: thinned"
        } else {
            "warning: skipped"
        };
        eprintln!("splatray: {kind} {} points: {}", s.count, s.reason);
    }
    eprintln!(
        "splatray: {} points -> {} splats ({} elliptical, {} clipped: {} crease lines met across, {} whole discs cut), coverage {:.4}, mean radius {:.4e}, largest splat {:.1}x its local spacing, epsilon {:.3e}, noise {:.3e}, {} flat normal fields, origin [{:?}, {:?}, {:?}], {:.2} s -> {}",
        report.used_points,
        report.splats,
        report.elliptical_splats,
        report.clipped,
        report.partner_lines,
        report.partner_cut,
        report.coverage,
        report.mean_radius,
        report.largest_over_spacing,
        report.epsilon,
        report.noise,
        report.fallback_normal_fields,
        p.origin[0],
        p.origin[1],
        p.origin[2],
        report.seconds.total,
        args.output.display()
    );
    if report.flat_faces > 0 {
        eprintln!(
            "splatray: {} flat faces fitted under strong range noise: {} points moved onto their planes",
            report.flat_faces, report.face_points
        );
    }
    if print_lean(report) {
        return;
    }
    eprintln!(
        "splatray: large splats over holes: {} (> {}x median radius, centre farther than half a radius from their points), {} (> {}x, kept disc less than half covered by points; {} shrunk to what their points cover, {} small splats added for the points they left)",
        report.hollow_large_splats,
        crate::splat::HOLLOW_LARGE,
        report.uncovered_large_splats,
        crate::splat::UNCOVERED_LARGE,
        report.shrunk_over_holes,
        report.added_for_holes,
    );
}

/// What lean growth's gate found; true when lean growth grew the
/// splats (the stages' figures about holes then were not measured).
fn print_lean(report: &crate::splat::SplatReport) -> bool {
    let Some(lean) = &report.lean else {
        return false;
    };
    let g = &lean.gate;
    let measured = format!(
        "{} points sampled: scatter {:.3} epsilon, {:.1} % curving off the growth slab, {:.2} % off the epsilon slab, {:.2} % across a crease, {:.2} % along lines, {:.2} % at a border",
        g.sampled,
        g.sigma,
        100.0 * g.hard,
        100.0 * g.hard_eps,
        100.0 * g.crease,
        100.0 * g.line,
        100.0 * g.border
    );
    match &lean.refused {
        Some(why) => {
            eprintln!(
                "splatray: lean growth refused: {why} ({measured}); the stages grew the splats"
            );
            false
        }
        None if lean.settled => {
            eprintln!(
                "splatray: lean growth on the points settled onto their surfaces first (a dense noisy scan; --no-lean: the stages): {measured}; {} outlier seeds; {} splats clipped at creases and borders, {} discs widened over pinholes",
                lean.outliers, report.clipped, report.widened_at_pinholes
            );
            true
        }
        None if lean.sharp => {
            eprintln!(
                "splatray: lean growth with clip lines: {measured}; {} outlier seeds; {} splats clipped at creases and borders, {} discs widened over pinholes (a clean cloud: no noise looked for)",
                lean.outliers, report.clipped, report.widened_at_pinholes
            );
            true
        }
        None => {
            eprintln!(
                "splatray: lean growth: {measured}; {} outlier seeds; {} discs widened over pinholes; no creases, noise or holes looked for (the gate found none)",
                lean.outliers, report.widened_at_pinholes
            );
            true
        }
    }
}

/// A Gaussian file's lines.
fn print_gaussians(args: &SplatArgs, g: &GaussiansOutcome) {
    let layout = g.report.layout;
    if g.point_options_ignored {
        eprintln!(
            "splatray: warning: {} is a {layout} Gaussian file: its Gaussians become splats as they are, and --epsilon, --k, --density and --ellipses do not apply",
            args.inputs[0].display(),
        );
    }
    for w in &g.warnings {
        eprintln!("splatray: warning: {w}");
    }
    if g.sh_rest > 0 {
        eprintln!(
            "splatray: {} view-dependent colour coefficients (f_rest_*) per Gaussian not read: splats take the base colour",
            g.sh_rest
        );
    }
    eprintln!(
        "splatray: {} {layout} Gaussians -> {} splats (radius = {} sigma), origin [{:?}, {:?}, {:?}], {:.2} s -> {}",
        g.report.gaussians,
        g.report.splats,
        g.report.radius_per_sigma,
        g.origin[0],
        g.origin[1],
        g.origin[2],
        g.seconds,
        args.output.display()
    );
}

/// A `--format` name.
fn parse_format(s: &str) -> std::result::Result<Format, String> {
    Format::parse(s).ok_or_else(|| {
        let names: Vec<&str> = Format::ALL.iter().map(|f| f.name()).collect();
        format!("'{s}': expected one of {}", names.join(", "))
    })
}

/// Tiled generation's warnings, then its stage's line.
fn print_tiled(args: &SplatArgs, t: &TiledOutcome) {
    let report = &t.report;
    for w in &report.warnings {
        eprintln!("splatray: warning: {w}");
    }
    let mut warnings: Vec<&String> = report.tiles.iter().flat_map(|t| &t.warnings).collect();
    warnings.sort();
    warnings.dedup();
    for w in warnings {
        eprintln!("splatray: warning (in a tile): {w}");
    }
    match t.stage {
        Stage::Plan => print_plan(report, &t.work),
        Stage::Tile(k) => print_tile(report, k),
        Stage::All | Stage::Merge => print_merged(args, report),
    }
}

/// `--plan-only`'s line.
fn print_plan(report: &TiledReport, work: &std::path::Path) {
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
        work.display(),
        report.tiles.len() - 1
    );
}

/// `--tile T`'s line.
fn print_tile(report: &TiledReport, t: usize) {
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
}

/// A whole run's (or `--merge-only`'s) lines.
fn print_merged(args: &SplatArgs, report: &TiledReport) {
    if args.holdout > 0.0 {
        eprintln!("splatray: note: held-out coverage is not measured in tiled generation");
    }
    let resumed = report.tiles.iter().filter(|t| t.resumed).count();
    let lean = report.tiles.iter().filter(|t| t.lean).count();
    if lean > 0 {
        eprintln!(
            "splatray: lean growth grew {lean} of the {} tiles (its gate passed on their cores' points); the stages the rest",
            report.tiles.len()
        );
    }
    let thinned: u64 = report.tiles.iter().map(|t| t.thinned).sum();
    if thinned > 0 {
        eprintln!(
            "splatray: note: thinned {thinned} of the {} spilled points: denser than epsilon needs, \
             one point kept per cell (--thin 0 keeps every point)",
            report.spilled
        );
    }
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
}
