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
    /// Render with every backend this many times, taking turns (the
    /// reference, the second, the reference, ...), and report each
    /// backend's median speed and the median of the rounds' speed ratios
    /// with their range: a ratio that one slow or lucky render cannot move
    /// on a busy machine. Every backend stays built meanwhile. Default 1.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub rounds: u32,
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
    // One frame per backend, and the truth's (and a round's frame when
    // taking turns); one backend built at a time, or all of them when
    // taking turns.
    let renderers = registry::renderers().len();
    let frames = renderers + usize::from(args.truth) + usize::from(args.rounds > 1);
    args.view.check_budget(
        &scene,
        splatray::render::budget::Holds {
            frames: u32::try_from(frames).unwrap_or(u32::MAX),
            accelerators: if args.rounds > 1 {
                u32::try_from(renderers).unwrap_or(u32::MAX)
            } else {
                1
            },
        },
    )?;
    // Fail before any rendering when there is no exact surface.
    let truth = if args.truth {
        Some(Truth::new(&scene)?)
    } else {
        None
    };
    let diagonal = scene.options.scale.diagonal;
    let (frames, backends) = render_every_backend(&scene, args.rounds, Some(&progress))?;
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
        rounds: args.rounds,
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
    let mut render_one = |i: usize, backend: &dyn splatray::accel::Backend| -> Result<()> {
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
            let backend = info.build_splats(&scene.splats)?;
            render_one(i, backend.as_ref())?;
            built.push((backend.stats().build_seconds, backend.stats().memory_bytes));
        }
    } else {
        let backends = infos
            .iter()
            .map(|info| info.build_splats(&scene.splats))
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
        match (report.rounds, r.reference_over_this_range) {
            (2.., Some([lo, hi])) => println!(
                "    {x}/{y} throughput ratio {ratio:.2} (same run: median of {} rounds taken in turns, {lo:.2}-{hi:.2})",
                report.rounds
            ),
            _ => println!("    {x}/{y} throughput ratio {ratio:.2} (same run)"),
        }
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
