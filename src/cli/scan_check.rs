//! `splatray scan-check CLOUD [--viewpoint X,Y,Z] [--tolerance 0.01]
//! [--holdout 0.1] [--report R.json]`: the scan as its own ground truth.

use super::progress::ProgressLine;
use super::render::write_json;
use super::splat_cmd::SplatOptions;
use splatray::io::read_points;
use splatray::render::output::check_writable;
use splatray::validate::scan_check::{ScanCheckParams, scan_check};
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
}

/// Runs `splatray scan-check`.
///
/// # Errors
/// An unreadable cloud, no viewpoint, bad options, an unwritable report.
pub fn run(args: &ScanCheckArgs) -> Result<(), String> {
    if let Some(r) = &args.report {
        check_writable(r)?;
    }
    let cloud = read_points(&args.input).map_err(|e| e.to_string())?;
    let splat = args.splat.params(&cloud)?;
    if args.splat.no_viewpoint {
        return Err("scan-check needs the scanner's viewpoint: drop --no-viewpoint".into());
    }
    let params = ScanCheckParams {
        viewpoint: splat.viewpoint,
        splat,
        tolerance: args.tolerance,
        holdout: args.holdout,
        seed: args.seed,
    };
    let line = ProgressLine::new();
    let r = scan_check(
        &cloud,
        &params,
        Some(&|stage: &str, f: f64| line.update(stage, f)),
    )
    .map_err(|e| format!("{}: {e}", args.input.display()))?;
    line.finish();
    for w in &r.generation.warnings {
        eprintln!("splatray: warning: {w}");
    }
    let pct = |f: f64| 100.0 * f;
    println!(
        "{}: {} points, {} held out ({} of them outliers, not checked), {} splats; lines of sight at tolerance {}: consistent {:.2} %, early {:.2} %, gross early {:.2} %, late {:.2} %, miss {:.2} %; largest splat {:.1}x its local spacing ({:.1}x the median radius)",
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
        r.generation.largest_over_spacing,
        r.max_over_median_radius
    );
    if !r.viewpoint_is_scanner {
        eprintln!(
            "splatray: warning: the viewpoint is not the scanner's position, so these lines of sight \
             check nothing: give the scanner's position with --viewpoint X,Y,Z"
        );
    }
    if let Some(path) = &args.report {
        write_json(path, &r)?;
    }
    Ok(())
}
