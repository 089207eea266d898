//! `splatray sweep`: render time against error over the splat budget and the
//! shading mode — the report's resolution scaling (§4.4, fig. 16) measured,
//! flat splats against blended (eq. 5) and Phong splats (eq. 4).

use super::progress::ProgressLine;
use super::view::default_scene;
use crate::names::Named;
use crate::render::output::check_output_path;
use crate::validate::sweep::{MODES, SweepResult, SweepRow, csv_text, pareto};
use crate::workflow::sweep::SweepRequest;
use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// Coarsest default `ϵ` (fraction of the bounding-box diagonal, §2.1).
pub const EPS_COARSE: f32 = 0.05;
/// Finest default `ϵ`.
pub const EPS_FINE: f32 = 0.0005;

/// Options of `splatray sweep`.
#[derive(Clone, Debug, clap::Args)]
pub struct SweepArgs {
    /// Scene file (TOML). Default: the bundled scenes/bunny.toml.
    pub scene: Option<PathBuf>,
    /// Write one CSV row per (budget step, shading mode) here.
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Draw render time against error here (.png; an .svg of the same stem
    /// is written beside it).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Image width for every render (the scene's is overridden).
    #[arg(long, default_value_t = 320)]
    pub width: u32,
    /// Image height for every render.
    #[arg(long, default_value_t = 240)]
    pub height: u32,
    /// Budget steps, spaced geometrically in epsilon (at least 5).
    #[arg(long, default_value_t = 6)]
    pub steps: usize,
    /// Coarsest epsilon (fraction of each model's bounding-box diagonal).
    #[arg(long, default_value_t = EPS_COARSE)]
    pub eps_coarse: f32,
    /// Finest epsilon.
    #[arg(long, default_value_t = EPS_FINE)]
    pub eps_fine: f32,
}

fn check_csv_path(path: &Path) -> Result<()> {
    if path.extension().and_then(|e| e.to_str()) != Some("csv") {
        return Err(Error::invalid(format!(
            "{}: the CSV output must end in .csv",
            path.display()
        )));
    }
    crate::render::output::check_writable(path)
}

/// Runs `splatray sweep`: checks every output first, then measures (printing
/// each figure as it is measured), then writes the CSV and the plot.
pub fn run(args: &SweepArgs) -> Result<()> {
    let req = SweepRequest {
        scene: args.scene.clone().unwrap_or_else(default_scene),
        width: args.width,
        height: args.height,
        steps: args.steps,
        eps_coarse: args.eps_coarse,
        eps_fine: args.eps_fine,
    };
    req.check()?;
    check_outputs(args)?;
    let prepared = req.prepare()?;
    println!(
        "{}: sweeping epsilon {} .. {} in {} steps, {}x{} pixels, shading {}",
        req.scene.display(),
        args.eps_coarse,
        args.eps_fine,
        args.steps,
        args.width,
        args.height,
        MODES.map(Named::name).join(", ")
    );
    let line = ProgressLine::new();
    let progress = |stage: &str, f: f64| line.update(stage, f);
    let result = prepared.run(Some(&progress), &mut |text| {
        line.finish();
        println!("{text}");
    })?;
    summary(&result);
    write_outputs(args, &result)
}

/// The CSV and the plot can be written where asked.
fn check_outputs(args: &SweepArgs) -> Result<()> {
    if let Some(c) = &args.csv {
        check_csv_path(c)?;
    }
    if let Some(p) = &args.plot {
        check_output_path(p)?;
        if p.extension().and_then(|e| e.to_str()) != Some("png") {
            return Err(Error::invalid(format!(
                "{}: the plot must end in .png",
                p.display()
            )));
        }
    }
    Ok(())
}

/// The CSV and the plot, committed together: a failure in either leaves
/// neither.
fn write_outputs(args: &SweepArgs, result: &SweepResult) -> Result<()> {
    let mut batch = crate::io::Batch::new();
    if let Some(c) = &args.csv {
        super::stage_text(&mut batch, c, &csv_text(result))?;
    }
    if let Some(p) = &args.plot {
        crate::workflow::plot::plot_sweep(&mut batch, result, p)?;
    }
    batch.commit()?;
    if let Some(c) = &args.csv {
        println!("wrote {}", c.display());
    }
    if let Some(p) = &args.plot {
        println!(
            "wrote {} and {}",
            p.display(),
            p.with_extension("svg").display()
        );
    }
    Ok(())
}

/// The summary lines: the span of the budget, per mode the normal error
/// and PSNR at the coarsest and finest steps, each backend's Pareto front
/// and its speed on the mesh's triangles (all from this run's rows).
fn summary(result: &SweepResult) {
    let rows = &result.rows;
    let (Some(first), Some(last)) = (rows.first(), rows.last()) else {
        return;
    };
    println!(
        "summary: {} .. {} splats ({:.1}x), backends identical in {}/{} rows",
        first.splats,
        last.splats,
        last.splats as f64 / first.splats.max(1) as f64,
        rows.iter().filter(|r| r.backends_identical).count(),
        rows.len()
    );
    summary_modes(rows);
    for b in &first.backends {
        summary_pareto(rows, b.name);
    }
    if let Some(m) = &result.mesh {
        let speeds: Vec<String> = m
            .backends
            .iter()
            .map(|b| {
                let psnr = b
                    .errors
                    .image_psnr_db
                    .map_or("inf".to_string(), |p| format!("{p:.1} dB"));
                format!(
                    "{} {:.3} s ({:.4} deg, {psnr})",
                    b.name, b.render_s, b.errors.normal_deg_mean
                )
            })
            .collect();
        println!(
            "  mesh ({} triangles, smooth-shaded, against the exact surface): render {}",
            m.triangles,
            speeds.join(", ")
        );
    }
}

/// Per mode, the normal error and PSNR at the coarsest and finest steps.
fn summary_modes(rows: &[SweepRow]) {
    for mode in MODES {
        let of: Vec<&SweepRow> = rows.iter().filter(|r| r.shading == mode).collect();
        if let (Some(a), Some(b)) = (of.first(), of.last()) {
            let p = |r: &SweepRow| {
                r.reference()
                    .errors
                    .image_psnr_db
                    .map_or("inf".to_string(), |p| format!("{p:.2}"))
            };
            let renders: Vec<String> = a
                .backends
                .iter()
                .zip(&b.backends)
                .map(|(x, y)| format!("{} render {:.3} -> {:.3} s", x.name, x.render_s, y.render_s))
                .collect();
            println!(
                "  {:<7} normal deg mean {:.3} -> {:.3}, PSNR {} -> {} dB, {}",
                mode.name(),
                a.reference().errors.normal_deg_mean,
                b.reference().errors.normal_deg_mean,
                p(a),
                p(b),
                renders.join(", ")
            );
        }
    }
}

/// Backend `name`'s Pareto front of render time against PSNR.
fn summary_pareto(rows: &[SweepRow], name: &str) {
    let front = pareto(rows, name);
    let points: Vec<String> = front
        .iter()
        .map(|p| {
            format!(
                "{} {} splats {:.3} s {:.2} dB",
                p.shading.name(),
                p.splats,
                p.render_s,
                p.psnr_db
            )
        })
        .collect();
    println!(
        "  pareto {} (render time against PSNR; nothing else is both faster and closer): {}",
        name,
        points.join("; ")
    );
}
