//! `splatray compare`: one scene through every rendering backend of the
//! registry in one run, each compared ray for ray with the first (the
//! reference).

use super::progress::ProgressLine;
use super::view::SceneArgs;
use super::{json_text, stage_text};
use splatray::accel::registry;
use splatray::io::Batch;
use splatray::progress::Progress;
use splatray::render::integrator::{Frame, render};
use splatray::render::output::{check_output_path, check_writable, save_into};
use splatray::scene::Scene;
use splatray::validate::causes::{Cause, ErrorBudget, Tolerances, cause_image, error_budget};
use splatray::validate::compare::{
    Agreement, TruthErrors, compare_frames, diff_image, orient_to_camera, render_truth,
    truth_errors,
};
use splatray::validate::truth::Truth;
use splatray::{Error, Result};
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
    /// Seconds to render.
    pub render_seconds: f64,
    /// Millions of rays (all kinds) per second.
    pub mrays_per_s: f64,
    /// The reference's rays per second over this backend's, measured in
    /// this run (absent for the reference).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reference_over_this: Option<f64>,
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
    /// Primary rays compared (one per pixel).
    pub rays: usize,
    /// Every rendering backend of the registry, the reference first.
    pub backends: Vec<BackendRun>,
    /// Errors against the exact surfaces (with `--truth`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub truth: Option<TruthReport>,
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
    if args.truth && args.view.is_cloud() {
        return Err(Error::invalid(format!(
            "{}: --truth needs exact surfaces, and a point cloud has none (write a scene with a `mesh` model or a `shape`)",
            scene_path.display()
        )));
    }
    check_outputs(args)?;
    let line = ProgressLine::new();
    let progress = |stage: &str, f: f64| line.update(stage, f);
    let scene = args.view.load(Some(args.spp), &line)?;
    // One frame per backend, and the truth's; one backend built at a time.
    let frames = registry::renderers().len() + usize::from(args.truth);
    args.view.check_budget(
        &scene,
        splatray::render::budget::Holds {
            frames: u32::try_from(frames).unwrap_or(u32::MAX),
            accelerators: 1,
        },
    )?;
    // Fail before any rendering when there is no exact surface.
    let truth = if args.truth {
        Some(Truth::new(&scene)?)
    } else {
        None
    };
    let diagonal = scene.options.scale.diagonal;
    let (frames, backends) = render_every_backend(&scene, Some(&progress))?;
    let truth_frame = truth.map(|t| render_truth(&scene, &t, Some(&progress)));
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
    line.finish();
    let report = CompareReport {
        scene: scene_path.display().to_string(),
        splats: scene.splats.len(),
        rays: frames.first().map_or(0, |f| f.depth.len()),
        backends,
        truth,
    };
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

/// Every rendering backend of the registry built (one at a time) and
/// rendering `scene`, the first the reference: each one's frame and run,
/// with its speed ratio to the reference and their agreement.
fn render_every_backend(
    scene: &Scene,
    progress: Option<Progress<'_>>,
) -> Result<(Vec<Frame>, Vec<BackendRun>)> {
    let diagonal = scene.options.scale.diagonal;
    let mut frames: Vec<Frame> = Vec::new();
    let mut backends: Vec<BackendRun> = Vec::new();
    for info in registry::renderers() {
        let backend = info.build_splats(&scene.splats)?;
        let frame = render(scene, backend.as_ref(), progress);
        let stats = backend.stats();
        let (reference_over_this, agreement) = match frames.first() {
            Some(reference) => (
                Some(mrays_per_s(reference) / mrays_per_s(&frame).max(1e-12)),
                Some(compare_frames(reference, &frame, diagonal)),
            ),
            None => (None, None),
        };
        backends.push(BackendRun {
            name: info.name,
            build_seconds: stats.build_seconds,
            memory_bytes: stats.memory_bytes,
            render_seconds: frame.seconds,
            mrays_per_s: mrays_per_s(&frame),
            reference_over_this,
            agreement,
        });
        frames.push(frame);
    }
    Ok((frames, backends))
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
    println!(
        "{}: {} splats, {} primary rays",
        report.scene, report.splats, report.rays
    );
    let Some(reference) = report.backends.first() else {
        return;
    };
    for r in &report.backends {
        println!(
            "  {}: build {:.3} s ({:.1} MB), render {:.3} s, {:.2} Mrays/s",
            r.name,
            r.build_seconds,
            r.memory_bytes as f64 / 1e6,
            r.render_seconds,
            r.mrays_per_s
        );
        let (Some(a), Some(ratio)) = (&r.agreement, r.reference_over_this) else {
            continue;
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
        println!("    {x}/{y} throughput ratio {ratio:.2} (same run)");
    }
    if let Some(t) = &report.truth {
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
        // The split by cause: the reference's, and any backend's that
        // differs from it.
        let first = t.backends.first().map(|b| &b.by_cause);
        for (k, b) in t.backends.iter().enumerate() {
            if k > 0 && Some(&b.by_cause) == first {
                println!("  {}: the same error by cause", b.name);
            } else {
                print_budget(b.name, &b.by_cause);
            }
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
