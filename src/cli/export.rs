//! `splatray export SPLATS.ply --format 2dgs|3dgs -o OUT.ply`: splats as a
//! Gaussian splat file other splat renderers and trainers read.

use splatray::io::{
    GaussianLayout, RADIUS_PER_SIGMA, SplatSet, encode_gaussians, file_layout, read_gaussians,
    read_splats, write_bytes,
};
use splatray::render::output::check_extension;
use splatray::{Error, Result};
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
    #[arg(long, default_value_t = splatray::io::MIN_OPACITY)]
    pub min_opacity: f32,
}

/// Run `splatray export`; the message of an error is one line.
///
/// # Errors
/// When the input cannot be read or the output written.
pub fn run(args: &ExportArgs) -> Result<()> {
    check_extension(&args.output, &["ply"])?;
    if !(0.0..=1.0).contains(&args.min_opacity) {
        return Err(Error::invalid(format!(
            "--min-opacity {} must be in [0, 1]",
            args.min_opacity
        )));
    }
    let set: SplatSet = if file_layout(&args.input).is_some() {
        let read = read_gaussians(&args.input, args.min_opacity)?;
        for w in read.warnings() {
            eprintln!("splatray: warning: {w}");
        }
        read.set
    } else {
        read_splats(&args.input)?
    };
    let layout = match args.format {
        ExportFormat::TwoD => GaussianLayout::TwoD,
        ExportFormat::ThreeD => GaussianLayout::ThreeD,
    };
    let bytes = encode_gaussians(
        &args.output,
        &set.splats,
        set.origin,
        layout,
        args.sh_degree,
    )?;
    write_bytes(&args.output, &bytes)?;
    let curved = set
        .splats
        .iter()
        .filter(|s| s.field != splatray::splat::NormalField::FLAT)
        .count();
    if curved > 0 {
        eprintln!(
            "splatray: warning: {curved} of {} splats have a normal field (eq. 4) the Gaussian layout cannot hold: they were written flat",
            set.splats.len()
        );
    }
    let clipped = set.splats.iter().filter(|s| s.is_clipped()).count();
    if clipped > 0 {
        eprintln!(
            "splatray: warning: {clipped} of {} splats have clip lines (a crease or a corner) the Gaussian layout cannot hold: they were written as whole discs",
            set.splats.len()
        );
    }
    eprintln!(
        "splatray: {} splats -> {} Gaussians ({}, sigma = radius / {RADIUS_PER_SIGMA}, opacity {}, SH degree {}), {} bytes -> {}",
        set.splats.len(),
        set.splats.len(),
        layout.name(),
        splatray::io::EXPORT_OPACITY,
        args.sh_degree,
        bytes.len(),
        args.output.display()
    );
    Ok(())
}
