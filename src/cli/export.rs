//! `splatray export SPLATS.ply --format 2dgs|3dgs -o OUT.ply`: splats as a
//! Gaussian splat file other splat renderers and trainers read.

use crate::Result;
use crate::io::{GaussianLayout, RADIUS_PER_SIGMA};
use crate::render::output::check_extension;
use crate::workflow::export::export;
use std::path::PathBuf;

/// The Gaussian layouts `export` writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ExportFormat {
    /// 2D Gaussian Splatting: oriented elliptical surfels (`scale_0..1`).
    #[value(name = "2dgs")]
    TwoD,
    /// 3D Gaussian Splatting: flat 3D Gaussians (`scale_0..2`).
    #[value(name = "3dgs")]
    ThreeD,
}

/// Arguments of `splatray export`.
#[derive(Clone, Debug, clap::Args)]
pub struct ExportArgs {
    /// A splat file (from `splatray splat`), or a Gaussian file to convert
    /// to the other layout.
    pub input: PathBuf,
    /// The Gaussian layout to write.
    #[arg(long, value_enum)]
    pub format: ExportFormat,
    /// Output Gaussian file (binary PLY).
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Spherical-harmonic degree of the colour (0 to 3): degree 3, the
    /// reference trainers' default, writes 45 zero `f_rest_*` so their
    /// loaders accept the file; 0 writes none.
    #[arg(long, default_value_t = 3)]
    pub sh_degree: u32,
    /// When the input is a Gaussian file: leave out Gaussians less opaque
    /// than this.
    #[arg(long, default_value_t = crate::io::MIN_OPACITY)]
    pub min_opacity: f32,
}

/// Run `splatray export`; the message of an error is one line.
///
/// # Errors
/// When the input cannot be read or the output written.
pub fn run(args: &ExportArgs) -> Result<()> {
    check_extension(&args.output, &["ply"])?;
    let layout = match args.format {
        ExportFormat::TwoD => GaussianLayout::TwoD,
        ExportFormat::ThreeD => GaussianLayout::ThreeD,
    };
    let done = export(
        &args.input,
        &args.output,
        layout,
        args.sh_degree,
        args.min_opacity,
    )?;
    for w in &done.warnings {
        eprintln!("splatray: warning: {w}");
    }
    let n = done.splats;
    if done.curved > 0 {
        eprintln!(
            "splatray: warning: {} of {n} splats have a normal field (eq. 4) the Gaussian layout cannot hold: they were written flat",
            done.curved
        );
    }
    if done.clipped > 0 {
        eprintln!(
            "splatray: warning: {} of {n} splats have clip lines (a crease or a corner) the Gaussian layout cannot hold: they were written as whole discs",
            done.clipped
        );
    }
    eprintln!(
        "splatray: {n} splats -> {n} Gaussians ({}, sigma = radius / {RADIUS_PER_SIGMA}, opacity {}, SH degree {}), {} bytes -> {}",
        layout.name(),
        crate::io::EXPORT_OPACITY,
        args.sh_degree,
        done.bytes,
        args.output.display()
    );
    Ok(())
}
