//! `splatray compare`: one scene through every rendering backend of the
//! registry in one run, each compared ray for ray with the first (the
//! reference).

use super::progress::ProgressLine;
use super::view::SceneArgs;
use super::{json_text, stage_text};
use crate::io::Batch;
use crate::render::integrator::Frame;
use crate::render::output::{check_output_path, check_writable, save_into};
use crate::validate::causes::{Cause, ErrorBudget, cause_image};
use crate::validate::compare::diff_image;
use crate::workflow::compare::{
    BackendRun, CompareOptions, CompareReport, Compared, TruthReport, compare, holds,
};
use crate::{Error, Result};
use std::path::PathBuf;

/// Options of `splatray compare`.
#[derive(Clone, Debug, clap::Args)]
pub struct CompareArgs {
    /// The scene and its view overrides.
    #[command(flatten)]
    pub view: SceneArgs,
    /// Write the JSON report here.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Write a difference heat map here (PNG): the reference backend | the
    /// second backend | difference. With `--truth`, also `D-truth.png`: the
    /// reference backend | the exact surfaces | difference (rays only one
    /// hit in magenta: holes and overhang); and `D-causes.png`: each
    /// pixel's cause of error | the same scaled by its error
    /// (`validate::causes::cause_image`).
    #[arg(long)]
    pub diff: Option<PathBuf>,
    /// Samples per pixel (default 1: one primary ray per pixel centre).
    #[arg(long, default_value_t = 1)]
    pub spp: u32,
    /// Also trace the exact surfaces (meshes as Embree triangles, analytic
    /// shapes) and report each backend's errors against them.
    #[arg(long)]
    pub truth: bool,
    /// Render with every backend this many times, taking turns (the
    /// reference, the second, the reference, ...), and report each
    /// backend's median speed and the median of the rounds' speed ratios
    /// with their range: a ratio that one slow or lucky render cannot move
    /// on a busy machine. Every backend stays built meanwhile. Default 1.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub rounds: u32,
    /// Also render the scene with every model that has a mesh (`mesh`, or
    /// `truth` beside points or splats) as that mesh's triangles, on every
    /// backend in the same run: each one's speed, memory and build time on
    /// the triangles, and its splat image's PSNR against its triangle image.
    #[arg(long)]
    pub as_triangles: bool,
}

/// Where `--diff D.png` with `--truth` puts the reference backend against
/// the exact surfaces: `D-truth.png`.
fn truth_diff_path(diff: &std::path::Path) -> PathBuf {
    let stem = diff
        .file_stem()
        .map_or_else(|| "diff".to_string(), |s| s.to_string_lossy().into_owned());
    diff.with_file_name(format!("{stem}-truth.png"))
}

/// Where `--diff D.png` with `--truth` puts the causes of error:
/// `D-causes.png`.
fn causes_diff_path(diff: &std::path::Path) -> PathBuf {
    let stem = diff
        .file_stem()
        .map_or_else(|| "diff".to_string(), |s| s.to_string_lossy().into_owned());
    diff.with_file_name(format!("{stem}-causes.png"))
}

/// Runs `splatray compare`.
pub fn run(args: &CompareArgs) -> Result<()> {
    let scene_path = args.view.path();
    let tri_file = check_args(args, &scene_path)?;
    check_outputs(args)?;
    let line = ProgressLine::new();
    let progress = |stage: &str, f: f64| line.update(stage, f);
    let scene = args.view.load(Some(args.spp), &line)?;
    args.view
        .check_budget(&scene, holds(args.rounds, args.truth))?;
    let options = CompareOptions {
        rounds: args.rounds,
        truth: args.truth,
    };
    let compared = compare(
        &scene,
        &scene_path.display().to_string(),
        &options,
        Some(&progress),
    );
    line.finish();
    let Compared {
        mut report,
        frames,
        truth_frame,
        reference_causes,
    } = compared?;
    if let Some((file, models)) = tri_file {
        let base = scene_path.parent().unwrap_or(std::path::Path::new("."));
        let mut tris = crate::scene::build_scene(&file, base, Some(&progress))
            .map_err(|e| e.context(scene_path.display()))?;
        let c = &scene.camera;
        tris.set_view(
            Some(c.width),
            Some(c.height),
            Some(c.spp),
            args.view.shading,
        )?;
        let r = crate::workflow::compare::as_triangles(&tris, models, &frames, Some(&progress));
        line.finish();
        report.as_triangles = Some(r?);
    }
    write_outputs(
        args,
        &frames,
        truth_frame.as_ref(),
        reference_causes.as_deref(),
        &report,
    )?;
    print_report(&report);
    Ok(())
}

/// The flags checked against what is compared, before any rendering:
/// with `--as-triangles`, the triangles' scene file and how many models
/// it turns to triangles.
fn check_args(
    args: &CompareArgs,
    scene_path: &std::path::Path,
) -> Result<Option<(crate::scene::SceneFile, usize)>> {
    if args.as_triangles && args.view.is_cloud() {
        return Err(Error::invalid(format!(
            "{}: --as-triangles needs a scene file with a `mesh` model (or a `truth` mesh), not a \
             point cloud",
            scene_path.display()
        )));
    }
    if args.truth && args.view.is_cloud() {
        return Err(Error::invalid(format!(
            "{}: --truth needs exact surfaces, and a point cloud has none (write a scene with a `mesh` model or a `shape`)",
            scene_path.display()
        )));
    }
    if !args.as_triangles {
        return Ok(None);
    }
    let file = crate::scene::parse_scene_file(scene_path)?;
    let (f, n) = crate::workflow::compare::meshes_as_triangles(&file);
    if n == 0 {
        return Err(Error::invalid(format!(
            "{}: --as-triangles: no model has a mesh (`mesh`, or `truth` beside points or \
             splats)",
            scene_path.display()
        )));
    }
    Ok(Some((f, n)))
}

/// The output paths `--diff` (with `--truth`, its truth and causes images
/// too) and `--report` will write can be written.
fn check_outputs(args: &CompareArgs) -> Result<()> {
    if let Some(d) = &args.diff {
        check_output_path(d)?;
        if args.truth {
            check_output_path(&truth_diff_path(d))?;
            check_output_path(&causes_diff_path(d))?;
        }
    }
    if let Some(r) = &args.report {
        check_writable(r)?;
    }
    Ok(())
}

/// The diff images (`--diff`: reference against the second backend; with
/// the truth, reference against it and the causes) and the report,
/// committed together: a failure in any leaves none.
fn write_outputs(
    args: &CompareArgs,
    frames: &[Frame],
    truth_frame: Option<&Frame>,
    reference_causes: Option<&[Cause]>,
    report: &CompareReport,
) -> Result<()> {
    let mut batch = Batch::new();
    if let (Some(d), [a, b, ..]) = (&args.diff, frames) {
        save_into(&mut batch, &diff_image(a, b), d, image::ImageFormat::Png)?;
    }
    if let (Some(d), Some(tf), Some(a)) = (&args.diff, truth_frame, frames.first()) {
        save_into(
            &mut batch,
            &diff_image(a, tf),
            &truth_diff_path(d),
            image::ImageFormat::Png,
        )?;
        if let Some(causes) = reference_causes {
            save_into(
                &mut batch,
                &cause_image(a, tf, causes),
                &causes_diff_path(d),
                image::ImageFormat::Png,
            )?;
        }
    }
    if let Some(r) = &args.report {
        stage_text(&mut batch, r, &(json_text(report)? + "\n"))?;
    }
    batch.commit()?;
    Ok(())
}

/// The report as lines on stdout.
fn print_report(report: &CompareReport) {
    let triangles = if report.triangles > 0 {
        format!(", {} triangles", report.triangles)
    } else {
        String::new()
    };
    println!(
        "{}: {} splats{triangles}, {} primary rays",
        report.scene, report.splats, report.rays
    );
    let Some(reference) = report.backends.first() else {
        return;
    };
    for r in &report.backends {
        print_backend(reference, r, report.rounds);
    }
    if let Some(t) = &report.truth {
        print_truth(t);
    }
    if let Some(t) = &report.as_triangles {
        println!(
            "  as triangles: {} model(s) -> {} triangles ({} splats left)",
            t.models, t.triangles, t.splats
        );
        for ((r, s), p) in report
            .backends
            .iter()
            .zip(&t.backends)
            .zip(&t.splats_psnr_db)
        {
            let psnr = p.map_or("inf (identical)".to_string(), |p| format!("{p:.2}"));
            println!(
                "    {}: splats {:.2} Mrays/s, {:.1} MB, build {:.3} s | triangles {:.2} Mrays/s, \
                 {:.1} MB, build {:.3} s | splats vs triangles PSNR {psnr} dB",
                r.name,
                r.mrays_per_s,
                r.memory_bytes as f64 / 1e6,
                r.build_seconds,
                s.mrays_per_s,
                s.memory_bytes as f64 / 1e6,
                s.build_seconds
            );
        }
        if let Some(a) = t.backends.get(1).and_then(|b| b.agreement.as_ref()) {
            println!(
                "    triangles, {} vs {}: hit agreement {:.6}, same triangle {:.6}",
                t.backends[0].name, t.backends[1].name, a.hit_agreement, a.same_splat
            );
        }
    }
}

/// One backend's lines: speed and memory, and its agreement with the
/// reference.
fn print_backend(reference: &BackendRun, r: &BackendRun, rounds: u32) {
    println!(
        "  {}: build {:.3} s ({:.1} MB), render {:.3} s, {:.2} Mrays/s",
        r.name,
        r.build_seconds,
        r.memory_bytes as f64 / 1e6,
        r.render_seconds,
        r.mrays_per_s
    );
    let (Some(a), Some(ratio)) = (&r.agreement, r.reference_over_this) else {
        return;
    };
    let (x, y) = (reference.name, r.name);
    println!(
        "    {x} vs {y}: hit agreement {:.6}, same splat {:.6}, only {x} {}, only {y} {}",
        a.hit_agreement, a.same_splat, a.only_first, a.only_second
    );
    println!(
        "    |dt|/diagonal p50 {:.3e} p99 {:.3e} max {:.3e}; normal deg p99 {:.3e} max {:.3e}",
        a.dt_rel_p50, a.dt_rel_p99, a.dt_rel_max, a.normal_deg_p99, a.normal_deg_max
    );
    println!(
        "    image PSNR {} dB, max |diff| {:.3e}",
        a.image_psnr_db
            .map_or("inf (identical)".to_string(), |p| format!("{p:.2}")),
        a.image_max_abs
    );
    match (rounds, r.reference_over_this_range) {
        (2.., Some([lo, hi])) => println!(
            "    {x}/{y} throughput ratio {ratio:.2} (same run: median of {rounds} rounds taken in turns, {lo:.2}-{hi:.2})"
        ),
        _ => println!("    {x}/{y} throughput ratio {ratio:.2} (same run)"),
    }
}

/// The errors against the exact surface, and their split by cause: the
/// reference's, and any backend's that differs from it.
fn print_truth(t: &TruthReport) {
    println!(
        "  against the exact surface (rendered in {:.3} s):",
        t.render_seconds
    );
    for b in &t.backends {
        let e = &b.errors;
        println!(
            "  {}: coverage {:.5}, false hits {:.5}, depth/diag p50 {:.2e} p99 {:.2e}, normal deg mean {:.3} p99 {:.3}, PSNR {}",
            b.name,
            e.coverage,
            e.false_hits,
            e.depth_rel_p50,
            e.depth_rel_p99,
            e.normal_deg_mean,
            e.normal_deg_p99,
            e.image_psnr_db
                .map_or("inf".to_string(), |p| format!("{p:.2} dB"))
        );
    }
    let first = t.backends.first().map(|b| &b.by_cause);
    for (k, b) in t.backends.iter().enumerate() {
        if k > 0 && Some(&b.by_cause) == first {
            println!("  {}: the same error by cause", b.name);
        } else {
            print_budget(b.name, &b.by_cause);
        }
    }
}

/// One backend's squared error by cause, a line per cause.
fn print_budget(name: &str, b: &ErrorBudget) {
    let db = |p: Option<f64>| p.map_or("inf".to_string(), |p| format!("{p:.2}"));
    println!(
        "  {name}: squared error by cause (PSNR {} dB; cause, pixels, % of the image, share of the squared error, PSNR if exact, mean normal error and its part of the whole mean):",
        db(b.psnr_db)
    );
    for c in &b.causes {
        println!(
            "    {:<11} {:>9} {:>7.2} % {:>9.3} % {:>8} dB {:>8.3} deg {:>7.3} deg",
            c.cause.name(),
            c.pixels,
            100.0 * c.pixels as f64 / b.pixels.max(1) as f64,
            100.0 * c.share,
            db(c.psnr_if_exact_db),
            c.normal_deg_mean,
            c.normal_deg_part
        );
    }
    for (what, c, of) in [
        ("holes", &b.holes, "a pixel the surface misses"),
        ("false hits", &b.false_hits, "a pixel the surface hits"),
    ] {
        println!(
            "    {what} by distance to {of}: 1 px {}, 2-3 px {}, farther {}",
            c.at_1px, c.at_2_3px, c.farther
        );
    }
    for m in &b.by_material {
        let parts: Vec<String> = m
            .causes
            .iter()
            .filter(|c| c.pixels > 0)
            .map(|c| {
                format!(
                    "{} {} px {:.2} %",
                    c.cause.name(),
                    c.pixels,
                    100.0 * c.share
                )
            })
            .collect();
        println!("    material {}: {}", m.material, parts.join(", "));
    }
}
