//! `splatray compare`: one scene through the octree and Embree in one run.

use super::progress::ProgressLine;
use super::render::{default_scene, write_json};
use splatray::accel::BackendKind;
use splatray::render::integrator::{Frame, render};
use splatray::render::output::{check_output_path, save};
use splatray::resolve::ShadingMode;
use splatray::scene::load_scene;
use splatray::validate::compare::{
    Agreement, TruthErrors, compare_frames, diff_image, render_truth, truth_errors,
};
use splatray::validate::truth::Truth;
use std::path::PathBuf;

/// Options of `splatray compare`.
#[derive(Clone, Debug, clap::Args)]
pub struct CompareArgs {
    /// Scene file (TOML). Default: the bundled scenes/bunny.toml.
    pub scene: Option<PathBuf>,
    /// Write the JSON report here.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Write a difference heat map here (PNG): octree | embree | difference.
    #[arg(long)]
    pub diff: Option<PathBuf>,
    /// Override the camera's width.
    #[arg(long)]
    pub width: Option<u32>,
    /// Override the camera's height.
    #[arg(long)]
    pub height: Option<u32>,
    /// Samples per pixel (default 1: one primary ray per pixel centre).
    #[arg(long, default_value_t = 1)]
    pub spp: u32,
    /// Override the shading mode: flat, blended or phong.
    #[arg(long)]
    pub shading: Option<ShadingMode>,
    /// Also trace the exact surfaces (meshes as Embree triangles, analytic
    /// shapes) and report each backend's errors against them.
    #[arg(long)]
    pub truth: bool,
}

/// Speed of one backend in the comparison run.
#[derive(Clone, Debug, serde::Serialize)]
pub struct BackendRun {
    /// Seconds to build the acceleration structure.
    pub build_seconds: f64,
    /// Seconds to render.
    pub render_seconds: f64,
    /// Millions of rays (all kinds) per second.
    pub mrays_per_s: f64,
}

impl BackendRun {
    fn of(build_seconds: f64, f: &Frame) -> BackendRun {
        BackendRun {
            build_seconds,
            render_seconds: f.seconds,
            mrays_per_s: f.rays.total() as f64 / f.seconds.max(1e-9) / 1e6,
        }
    }
}

/// The `compare` report.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CompareReport {
    /// Scene file.
    pub scene: String,
    /// Splats.
    pub splats: usize,
    /// Agreement figures (octree first, Embree second).
    #[serde(flatten)]
    pub agreement: Agreement,
    /// The octree's speed.
    pub octree: BackendRun,
    /// Embree's speed.
    pub embree: BackendRun,
    /// Octree rays per second over Embree's, measured in this run.
    pub octree_over_embree: f64,
    /// Errors against the exact surfaces (with `--truth`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub truth: Option<TruthReport>,
}

/// Errors of each backend against the exact surfaces.
#[derive(Clone, Debug, serde::Serialize)]
pub struct TruthReport {
    /// Seconds to render the exact surfaces.
    pub render_seconds: f64,
    /// The octree's splats against the surface.
    pub octree: TruthErrors,
    /// Embree's splats against the surface.
    pub embree: TruthErrors,
}

/// Runs `splatray compare`.
pub fn run(args: &CompareArgs) -> Result<(), String> {
    let scene_path = args.scene.clone().unwrap_or_else(default_scene);
    if let Some(d) = &args.diff {
        check_output_path(d)?;
    }
    if let Some(r) = &args.report {
        check_output_path(&r.with_extension("png"))?;
    }
    let line = ProgressLine::new();
    let progress = |stage: &str, f: f64| line.update(stage, f);
    let mut scene = load_scene(&scene_path, Some(&progress))?;
    line.finish();
    scene.set_view(args.width, args.height, Some(args.spp), args.shading)?;
    // Fail before any rendering when there is no exact surface.
    let truth = if args.truth {
        Some(Truth::new(&scene)?)
    } else {
        None
    };
    let mut runs = Vec::new();
    for kind in [BackendKind::Octree, BackendKind::Embree] {
        let backend = kind.build(&scene.splats)?;
        let frame = render(&scene, backend.as_ref(), Some(&progress));
        runs.push((backend.stats().build_seconds, frame));
    }
    let (ob, of) = &runs[0];
    let (eb, ef) = &runs[1];
    let agreement = compare_frames(of, ef, scene.options.scale.diagonal);
    let octree = BackendRun::of(*ob, of);
    let embree = BackendRun::of(*eb, ef);
    let diagonal = scene.options.scale.diagonal;
    let truth = truth.map(|t| {
        let tf = render_truth(&scene, &t, Some(&progress));
        let errors = |f: &Frame| truth_errors(f.clone(), &tf, &scene.camera, diagonal);
        TruthReport {
            render_seconds: tf.seconds,
            octree: errors(of),
            embree: errors(ef),
        }
    });
    line.finish();
    let report = CompareReport {
        scene: scene_path.display().to_string(),
        splats: scene.splats.len(),
        octree_over_embree: octree.mrays_per_s / embree.mrays_per_s.max(1e-12),
        agreement,
        octree,
        embree,
        truth,
    };
    if let Some(d) = &args.diff {
        save(&diff_image(of, ef), d, image::ImageFormat::Png)?;
    }
    if let Some(r) = &args.report {
        write_json(r, &report)?;
    }
    let a = &report.agreement;
    println!(
        "{}: {} splats, {} primary rays",
        report.scene, report.splats, a.rays
    );
    println!(
        "  hit agreement {:.6}, same splat {:.6}, only octree {}, only embree {}",
        a.hit_agreement, a.same_splat, a.only_first, a.only_second
    );
    println!(
        "  |dt|/diagonal p50 {:.3e} p99 {:.3e} max {:.3e}; normal deg p99 {:.3e} max {:.3e}",
        a.dt_rel_p50, a.dt_rel_p99, a.dt_rel_max, a.normal_deg_p99, a.normal_deg_max
    );
    println!(
        "  image PSNR {} dB, max |diff| {:.3e}",
        a.image_psnr_db
            .map_or("inf (identical)".to_string(), |p| format!("{p:.2}")),
        a.image_max_abs
    );
    for (name, r) in [("octree", &report.octree), ("embree", &report.embree)] {
        println!(
            "  {name}: build {:.3} s, render {:.3} s, {:.2} Mrays/s",
            r.build_seconds, r.render_seconds, r.mrays_per_s
        );
    }
    println!(
        "  octree/embree throughput ratio {:.2} (same run)",
        report.octree_over_embree
    );
    if let Some(t) = &report.truth {
        println!(
            "  against the exact surface (rendered in {:.3} s):",
            t.render_seconds
        );
        for (name, e) in [("octree", &t.octree), ("embree", &t.embree)] {
            println!(
                "  {name}: coverage {:.5}, false hits {:.5}, depth/diag p50 {:.2e} p99 {:.2e}, normal deg mean {:.3} p99 {:.3}, PSNR {}",
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
    }
    Ok(())
}
