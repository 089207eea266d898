//! `splatray scan-check CLOUD [--viewpoint X,Y,Z] [--tolerance 0.01]
//! [--holdout 0.1] [--report R.json]`: the scan as its own ground truth.

use super::common::{SplatOptions, default_backend, write_json};
use super::progress::ProgressLine;
use crate::Result;
use crate::render::output::check_writable;
use crate::validate::photo::PhotoReport;
use crate::validate::scan_check::ScanCheckReport;
use crate::workflow::scan_check::{ScanCheckOutcome, ScanCheckRequest, scan_check};
use std::path::PathBuf;

/// Arguments of `splatray scan-check`.
#[derive(Clone, Debug, clap::Args)]
pub struct ScanCheckArgs {
    /// The scan (.pcd with VIEWPOINT, or any point file with --viewpoint).
    pub input: PathBuf,
    /// Splat generation options (as `splat`); --viewpoint is also the
    /// position the lines of sight start from.
    #[command(flatten)]
    pub splat: SplatOptions,
    /// A hit within this fraction of the point's distance is consistent.
    #[arg(long, default_value_t = 0.01)]
    pub tolerance: f32,
    /// Fraction of the points held out of splat generation and checked.
    #[arg(long, default_value_t = 0.1)]
    pub holdout: f32,
    /// Seed of the hold-out choice.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Write the JSON report here.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// The photo check of an organised colour scan (a depth camera's grid,
    /// PCD HEIGHT > 1): hold out pixels, grow splats from the rest, see
    /// them from the sensor and compare their colours with the captured
    /// ones (PSNR at full, 1/2 and 1/4 resolution; pixels covered and
    /// filled).
    #[arg(long)]
    pub photo: bool,
    /// The backend the photo check renders with.
    #[arg(long, default_value_t = default_backend())]
    pub backend: String,
}

/// Runs `splatray scan-check`.
///
/// # Errors
/// An unreadable cloud, no viewpoint, bad options, an unwritable report.
pub fn run(args: &ScanCheckArgs) -> Result<()> {
    if let Some(r) = &args.report {
        check_writable(r)?;
    }
    let req = ScanCheckRequest {
        input: args.input.clone(),
        generation: args.splat.generation()?,
        tolerance: args.tolerance,
        holdout: args.holdout,
        seed: args.seed,
        photo: args.photo,
        backend: args.backend.clone(),
    };
    let line = ProgressLine::new();
    let outcome = scan_check(&req, Some(&|stage: &str, f: f64| line.update(stage, f)));
    line.finish();
    let outcome = outcome?;
    match &outcome {
        ScanCheckOutcome::Lines(r) => print_lines(args, r),
        ScanCheckOutcome::Photo(r) => print_photo(args, r),
    }
    if let Some(path) = &args.report {
        write_json(path, &outcome)?;
    }
    Ok(())
}

/// The lines of sight's line, and the warnings.
fn print_lines(args: &ScanCheckArgs, r: &ScanCheckReport) {
    for w in &r.generation.warnings {
        eprintln!("splatray: warning: {w}");
    }
    let pct = |f: f64| 100.0 * f;
    println!(
        "{}: {} points, {} held out ({} of them outliers, not checked), {} splats; lines of sight at tolerance {}: consistent {:.2} %, early {:.2} %, gross early {:.2} %, late {:.2} %, miss {:.2} % ({} of {} at a rim of the scanned surface) (against the rendered surface: consistent {:.2} %, early {:.2} %, late {:.2} %); largest splat {:.1}x its local spacing ({:.1}x the median radius)",
        args.input.display(),
        r.points,
        r.held_out,
        r.held_out_outliers,
        r.splats,
        args.tolerance,
        pct(r.consistent_fraction),
        pct(r.early_fraction),
        pct(r.gross_early_fraction),
        pct(r.late_fraction),
        pct(r.miss_fraction),
        r.miss_at_rim,
        r.miss,
        pct(r.surface.consistent_fraction),
        pct(r.surface.early_fraction),
        pct(r.surface.late_fraction),
        r.generation.largest_over_spacing,
        r.max_over_median_radius
    );
    if !r.viewpoint_is_scanner {
        eprintln!(
            "splatray: warning: the viewpoint is not the scanner's position, so these lines of sight \
             check nothing: give the scanner's position with --viewpoint X,Y,Z"
        );
    }
}

/// `scan-check --photo`'s line.
fn print_photo(args: &ScanCheckArgs, r: &PhotoReport) {
    println!(
        "{}: photo check of the organised {}x{} capture: {} measured pixels, {} held out, {} splats \
         ({} with a linear colour field); \
         the splats cover {:.2} % of the held-out pixels and fill {:.2} % of the held-out empty ones; albedo \
         against the captured colours: PSNR {:.2} dB at full resolution, {:.2} dB at 1/2, {:.2} dB at 1/4 \
         (sensor fit residual {:.3} px)",
        args.input.display(),
        r.width,
        r.height,
        r.measured,
        r.held_out,
        r.splats,
        r.color_fields,
        100.0 * r.covered,
        100.0 * r.filled,
        r.psnr[0],
        r.psnr[1],
        r.psnr[2],
        r.residual
    );
}
