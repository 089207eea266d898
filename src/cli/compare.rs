//! `splatray compare`: one scene through the octree and Embree in one run.

use super::render::{apply_overrides, default_scene, write_json};
use crate::accel::BackendKind;
use crate::accel::resolve::ShadingMode;
use crate::render::integrator::{Frame, render};
use crate::render::output::{check_output_path, write_atomic};
use crate::render::scene::load_scene;
use crate::validate::compare::{Agreement, compare_frames, diff_image};
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
    let mut scene = load_scene(&scene_path)?;
    apply_overrides(
        &mut scene,
        args.width,
        args.height,
        Some(args.spp),
        args.shading,
    )?;
    let mut runs = Vec::new();
    for kind in [BackendKind::Octree, BackendKind::Embree] {
        let backend = kind.build(&scene.splats)?;
        let frame = render(&scene, backend.as_ref(), true);
        runs.push((backend.stats().build_seconds, frame));
    }
    let (ob, of) = &runs[0];
    let (eb, ef) = &runs[1];
    let agreement = compare_frames(of, ef, scene.options.scale.diagonal);
    let octree = BackendRun::of(*ob, of);
    let embree = BackendRun::of(*eb, ef);
    let report = CompareReport {
        scene: scene_path.display().to_string(),
        splats: scene.splats.len(),
        octree_over_embree: octree.mrays_per_s / embree.mrays_per_s.max(1e-12),
        agreement,
        octree,
        embree,
    };
    if let Some(d) = &args.diff {
        let img = diff_image(of, ef);
        write_atomic(d, |tmp| {
            img.save_with_format(tmp, image::ImageFormat::Png)
                .map_err(|e| format!("{}: {e}", d.display()))
        })?;
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
    Ok(())
}
