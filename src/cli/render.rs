//! `splatray render`.

use super::common::default_backend;
use super::progress::ProgressLine;
use super::view::SceneArgs;
use super::{json_text, stage_text};
use crate::accel::registry;
use crate::io::Batch;
use crate::render::output::{
    Aov, aov_path, check_output_path, check_writable, write_aov_into, write_image_into,
};
use crate::scene::Scene;
use crate::workflow::render::{Rendered, band_rows, render_scene};
use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// Options of `splatray render`.
#[derive(Clone, Debug, clap::Args)]
pub struct RenderArgs {
    /// The scene and its view overrides.
    #[command(flatten)]
    pub view: SceneArgs,
    /// Acceleration backend (every backend of the registry; the first is
    /// the default).
    #[arg(
        long,
        default_value_t = default_backend(),
        value_parser = clap::builder::PossibleValuesParser::new(registry::names()),
    )]
    pub backend: String,
    /// Output image (.png, or .exr for linear radiance). Default: the
    /// scene's name with .png, in the current folder.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Override samples per pixel.
    #[arg(long)]
    pub spp: Option<u32>,
    /// Write a JSON report here.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Also write these AOVs as EXR beside the image (comma separated:
    /// depth,normal,splat,albedo).
    #[arg(long, value_delimiter = ',', value_parser = crate::names::parse::<Aov>)]
    pub aov: Vec<Aov>,
    /// Render band I of N (I from 0): rows I·H/N to (I+1)·H/N of the image,
    /// the same pixels a whole render gives them; `splatray stitch` joins
    /// the bands (what a cluster's render tasks do).
    #[arg(long, value_name = "I/N", value_parser = parse_band)]
    pub band: Option<(u32, u32)>,
}

/// `I/N` with `I < N`.
fn parse_band(s: &str) -> Result<(u32, u32), String> {
    let (i, n) = s
        .split_once('/')
        .ok_or_else(|| format!("'{s}': expected I/N, e.g. 0/4"))?;
    let i: u32 = i
        .trim()
        .parse()
        .map_err(|_| format!("'{s}': expected I/N, e.g. 0/4"))?;
    let n: u32 = n
        .trim()
        .parse()
        .map_err(|_| format!("'{s}': expected I/N, e.g. 0/4"))?;
    if n == 0 || i >= n {
        return Err(format!(
            "'{s}': the band I must be below N, and N at least 1"
        ));
    }
    Ok((i, n))
}

/// Says where the splats are when no primary ray met any: the usual cause
/// is a camera placed for another model's coordinates.
fn warn_nothing_hit(scene: &Scene) {
    if let Some((lo, hi)) = scene.world_bounds() {
        let f = |v: glam::DVec3| format!("[{:.4}, {:.4}, {:.4}]", v.x, v.y, v.z);
        eprintln!(
            "warning: no primary ray hit a splat; the splat centres span {} to {} in the scene's coordinates; check camera.from and camera.at",
            f(lo),
            f(hi)
        );
    }
}

/// The image's path (default: the scene's name with .png, in the current
/// folder), every output checked before the work starts.
fn checked_outputs(args: &RenderArgs, scene_path: &Path) -> Result<PathBuf> {
    let output = args.output.clone().unwrap_or_else(|| {
        let stem = scene_path
            .file_stem()
            .map_or("render".into(), |s| s.to_string_lossy().into_owned());
        PathBuf::from(format!("{stem}.png"))
    });
    check_output_path(&output)?;
    if args.band.is_some() && !args.aov.is_empty() {
        return Err(Error::invalid(
            "--aov is written by a whole render, not with --band",
        ));
    }
    for &a in &args.aov {
        check_output_path(&aov_path(&output, a))?;
    }
    if let Some(r) = &args.report {
        check_writable(r)?;
    }
    Ok(output)
}

/// Runs `splatray render`.
pub fn run(args: &RenderArgs) -> Result<()> {
    let scene_path = args.view.path();
    let output = checked_outputs(args, &scene_path)?;
    let line = ProgressLine::new();
    let progress = |stage: &str, f: f64| line.update(stage, f);
    let scene = args.view.load(args.spp, &line)?;
    args.view
        .check_budget(&scene, crate::render::budget::Holds::ONE)?;
    let rendered = render_scene(&scene, &args.backend, args.band, Some(&progress));
    line.finish();
    let Rendered { frame, report } = rendered?;
    if args.band.is_none() && frame.splat.iter().all(|&id| id == u32::MAX) {
        warn_nothing_hit(&scene);
    }
    // The image, its AOVs and the report are committed together: a failure
    // in any leaves none.
    let mut batch = Batch::new();
    write_image_into(&mut batch, &frame, &output)?;
    for &a in &args.aov {
        write_aov_into(&mut batch, &frame, a, &aov_path(&output, a))?;
    }
    if let Some(r) = &args.report {
        stage_text(&mut batch, r, &(json_text(&report)? + "\n"))?;
    }
    batch.commit()?;
    let band = args.band.map_or(String::new(), |(i, n)| {
        let r = band_rows(scene.camera.height, (i, n));
        format!(" (band {i}/{n}: rows {} to {})", r.start, r.end)
    });
    let triangles = match scene.triangles.tris.len() {
        0 => String::new(),
        n => format!(" and {n} triangles"),
    };
    println!(
        "{}: {}x{}{band} spp {}, {} splats{triangles} ({:.2} s to make), {} build {:.3} s, render {:.3} s, {} rays ({:.2} Mrays/s) -> {}",
        scene_path.display(),
        frame.width,
        frame.height,
        scene.camera.spp,
        scene.splats.len(),
        scene.load.splat_seconds,
        report.backend,
        report.build_seconds,
        frame.seconds,
        frame.rays.total(),
        report.mrays_per_s,
        output.display()
    );
    Ok(())
}
