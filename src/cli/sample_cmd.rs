//! `splatray sample MESH.ply -n N -o points.ply [--noise SIGMA] [--seed S]`.

use splatray::io::{read_mesh, sample_mesh, write_points};
use std::path::PathBuf;

/// The most points `sample` makes (about 2 GB of output).
pub const MAX_SAMPLES: usize = 100_000_000;

/// Arguments of `splatray sample`.
#[derive(Clone, Debug, clap::Args)]
pub struct SampleArgs {
    /// Triangle mesh to sample (PLY with faces).
    pub mesh: PathBuf,
    /// Number of points.
    #[arg(short = 'n', long = "points")]
    pub n: usize,
    /// Output point cloud (binary PLY with x y z nx ny nz).
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Standard deviation of isotropic Gaussian noise added to positions, in
    /// the mesh's units.
    #[arg(long, default_value_t = 0.0)]
    pub noise: f32,
    /// Seed of the generator; the same seed gives the same points.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// Run `splatray sample`; the message of an error is one line.
///
/// # Errors
/// When the mesh cannot be read, has no area, or the output cannot be written.
pub fn run(args: &SampleArgs) -> Result<(), String> {
    if args.n == 0 || args.n > MAX_SAMPLES {
        return Err(format!("-n must be between 1 and {MAX_SAMPLES}"));
    }
    if !(args.noise.is_finite() && args.noise >= 0.0) {
        return Err(format!(
            "--noise {} must be a finite, non-negative number",
            args.noise
        ));
    }
    let mesh = read_mesh(&args.mesh).map_err(|e| e.to_string())?;
    let cloud = sample_mesh(&mesh, args.n, args.noise, args.seed);
    if cloud.is_empty() {
        return Err(format!(
            "{}: the mesh has no triangle with a non-zero area to sample",
            args.mesh.display()
        ));
    }
    write_points(&args.output, &cloud).map_err(|e| e.to_string())?;
    eprintln!(
        "splatray: {} points from {} triangles -> {}",
        cloud.len(),
        mesh.triangles.len(),
        args.output.display()
    );
    Ok(())
}
