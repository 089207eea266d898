//! `splatray sample MESH.ply -n N -o points.ply [--noise SIGMA] [--seed S]`,
//! or a synthetic scan: `splatray sample MESH.ply --scan-from X,Y,Z -o
//! scan.pcd [--pattern raster|lines] [--rays W,H] [--range-noise S |
//! --range-noise-spacing F] [--outliers F] [--missing F]`.

use super::progress::ProgressLine;
use glam::Vec3;
use splatray::io::{Format, MeshSampler, read_mesh, sample_mesh, write_points, write_sample_ply};
use splatray::scanner::{RangeNoise, ScanParams, ScanPattern, scan_mesh};
use splatray::{Error, Result};
use std::path::PathBuf;

/// The most points `sample` makes: 10^10 (240 GB of binary PLY, written a
/// batch at a time; a PCD is made in memory and checked against it first).
pub const MAX_SAMPLES: usize = 10_000_000_000;

/// Bytes a point takes while a PCD is made in memory: the positions and
/// normals (24 B), the encoded records (24 B) and their copy in the file
/// buffer.
const PCD_BYTES_PER_POINT: u64 = 72;

/// Arguments of `splatray sample`.
#[derive(Clone, Debug, clap::Args)]
pub struct SampleArgs {
    /// Triangle mesh to sample (PLY with faces).
    pub mesh: PathBuf,
    /// Number of points sampled uniformly by area (not with --scan-from).
    #[arg(short = 'n', long = "points", required_unless_present = "scan_from")]
    pub n: Option<usize>,
    /// Output point cloud: binary PLY (x y z nx ny nz), or PCD when the
    /// name ends in .pcd (a scan's VIEWPOINT is kept only there).
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Standard deviation of isotropic Gaussian noise added to positions, in
    /// the mesh's units (area sampling).
    #[arg(long, default_value_t = 0.0, conflicts_with = "scan_from")]
    pub noise: f32,
    /// Seed of the generator; the same seed gives the same points.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Scan the mesh from this point (X,Y,Z) like a range scanner instead of
    /// sampling its area: points where the rays meet it, no normals, the
    /// viewpoint written as the PCD's VIEWPOINT.
    #[arg(
        long,
        value_delimiter = ',',
        allow_negative_numbers = true,
        num_args = 1
    )]
    pub scan_from: Option<Vec<f64>>,
    /// The point the scanner looks at (X,Y,Z). Default: the mesh's centre.
    #[arg(
        long,
        value_delimiter = ',',
        allow_negative_numbers = true,
        requires = "scan_from"
    )]
    pub scan_at: Option<Vec<f64>>,
    /// raster (a camera's pixel grid) or lines (equal angular steps, the
    /// lines `W/H` times farther apart than the samples along them).
    #[arg(long, default_value = "raster", requires = "scan_from")]
    pub pattern: ScanPattern,
    /// Rays per row and rows, as W,H.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "640,480",
        requires = "scan_from"
    )]
    pub rays: Vec<u32>,
    /// Vertical field of view, degrees. Default: the mesh fills it.
    #[arg(long, requires = "scan_from")]
    pub fov: Option<f32>,
    /// Gaussian range noise along each ray, in the mesh's units.
    #[arg(long, requires = "scan_from", conflicts_with = "range_noise_spacing")]
    pub range_noise: Option<f32>,
    /// Gaussian range noise as a multiple of the scan's median point spacing.
    #[arg(long, requires = "scan_from")]
    pub range_noise_spacing: Option<f32>,
    /// Fraction of returns replaced by outliers on the same ray.
    #[arg(long, default_value_t = 0.0, requires = "scan_from")]
    pub outliers: f32,
    /// Fraction of returns dropped.
    #[arg(long, default_value_t = 0.0, requires = "scan_from")]
    pub missing: f32,
    /// Write the raster as an organised PCD, as a depth camera does: the
    /// grid of rays, NaN where a ray missed, VIEWPOINT the sensor's pose
    /// from this frame: optical (x right, y down, z forward, as PCL, OpenCV
    /// and ROS) or gl (y up, looking along -z).
    #[arg(long, requires = "scan_from")]
    pub organised: Option<Frame>,
    /// Colour an organised scan's points with a procedural texture, as a
    /// colour camera would: smooth bands of colour about this many mesh
    /// units apart (`sample::texture`), to check colour reproduction with
    /// `scan-check --photo`.
    #[arg(long, requires = "organised")]
    pub texture: Option<f64>,
}

/// The procedural texture of `--texture`: at world point `p`, three
/// sinusoidal bands of period `period` along different directions, one per
/// channel (linear RGB in 0.1 … 0.9).
fn texture(p: glam::DVec3, period: f64) -> Vec3 {
    let w = std::f64::consts::TAU / period;
    let band = |x: f64| (0.5 + 0.4 * x.sin()) as f32;
    Vec3::new(
        band(w * p.x),
        band(w * (0.8 * p.y + 0.6 * p.z) + 1.0),
        band(w * (0.6 * p.x - 0.8 * p.z) + 2.0),
    )
}

/// The frame of an organised scan's sensor.
#[derive(Clone, Copy, Debug, PartialEq, clap::ValueEnum)]
pub enum Frame {
    /// x right, y down, z forward.
    Optical,
    /// x right, y up, looking along -z.
    Gl,
}

fn vec3(v: &[f64], what: &str) -> Result<glam::DVec3> {
    match v {
        [x, y, z] => Ok(glam::DVec3::new(*x, *y, *z)),
        _ => Err(Error::invalid(format!(
            "{what} needs three numbers X,Y,Z, got {}",
            v.len()
        ))),
    }
}

/// Run `splatray sample`; the message of an error is one line.
///
/// # Errors
/// When the mesh cannot be read, has no area, the scan sees nothing, or the
/// output cannot be written.
pub fn run(args: &SampleArgs) -> Result<()> {
    splatray::render::output::check_extension(&args.output, &["ply", "pcd"])?;
    if let Some(from) = &args.scan_from {
        return scan(args, vec3(from, "--scan-from")?);
    }
    let n = args.n.unwrap_or(0);
    if n == 0 || n > MAX_SAMPLES {
        return Err(Error::invalid(format!(
            "-n must be between 1 and {MAX_SAMPLES}"
        )));
    }
    if !(args.noise.is_finite() && args.noise >= 0.0) {
        return Err(Error::invalid(format!(
            "--noise {} must be a finite, non-negative number",
            args.noise
        )));
    }
    let mesh = read_mesh(&args.mesh)?;
    let no_area = || {
        Error::invalid(format!(
            "{}: the mesh has no triangle with a non-zero area to sample",
            args.mesh.display()
        ))
    };
    let made = if Format::from_extension(&args.output) == Some(Format::Pcd) {
        splatray::memory::check(
            &format!("sampling {n} points into a PCD"),
            (n as u64).saturating_mul(PCD_BYTES_PER_POINT),
        )
        .map_err(|e| e.with_hint("write a .ply instead (written a batch at a time)"))?;
        let cloud = sample_mesh(&mesh, n, args.noise, args.seed);
        if cloud.is_empty() {
            return Err(no_area());
        }
        write_points(&args.output, &cloud)?;
        cloud.len()
    } else {
        let sampler = MeshSampler::new(&mesh, n, args.noise, args.seed);
        if sampler.is_empty() {
            return Err(no_area());
        }
        let line = ProgressLine::new();
        let written = write_sample_ply(
            &args.output,
            &sampler,
            Some(&|stage, f| line.update(stage, f)),
        );
        line.finish();
        written?;
        sampler.len()
    };
    eprintln!(
        "splatray: {made} points from {} triangles -> {}",
        mesh.triangles.len(),
        args.output.display()
    );
    Ok(())
}

fn scan(args: &SampleArgs, from: glam::DVec3) -> Result<()> {
    if args.n.is_some() {
        return Err("-n and --scan-from exclude each other: a scan's rays set the points".into());
    }
    if let Some(period) = args.texture.filter(|p| !(p.is_finite() && *p > 0.0)) {
        return Err(Error::invalid(format!(
            "--texture {period} must be a positive period"
        )));
    }
    let [columns, rows] = args.rays[..] else {
        return Err(Error::invalid(format!(
            "--rays needs two numbers W,H, got {}",
            args.rays.len()
        )));
    };
    let params = ScanParams {
        from,
        at: args
            .scan_at
            .as_deref()
            .map(|v| vec3(v, "--scan-at"))
            .transpose()?,
        columns,
        rows,
        fov: args.fov,
        pattern: args.pattern,
        range_noise: match (args.range_noise, args.range_noise_spacing) {
            (_, Some(f)) => RangeNoise::Spacing(f),
            (s, None) => RangeNoise::Absolute(s.unwrap_or(0.0)),
        },
        outliers: args.outliers,
        missing: args.missing,
        seed: args.seed,
    };
    let mesh = read_mesh(&args.mesh)?;
    let scan = scan_mesh(&mesh, &params)?;
    match args.organised {
        None => write_points(&args.output, &scan.cloud)?,
        Some(frame) => {
            if Format::from_extension(&args.output) != Some(Format::Pcd) {
                return Err(Error::invalid(format!(
                    "{}: --organised writes a PCD (a name ending in .pcd)",
                    args.output.display()
                )));
            }
            let Some((f, cx, cy)) = scan.pinhole else {
                return Err("--organised needs the raster pattern (a camera's pixel grid)".into());
            };
            let [forward, right, up] = scan.axes.map(Vec3::as_dvec3);
            let (y, z) = match frame {
                Frame::Optical => (-up, forward),
                Frame::Gl => (up, -forward),
            };
            let rotation = glam::DQuat::from_mat3(&glam::DMat3::from_cols(right, y, z));
            let origin = scan.cloud.origin;
            let grid: Vec<Option<glam::DVec3>> = scan
                .grid
                .iter()
                .map(|p| p.map(|p| origin + p.as_dvec3()))
                .collect();
            let position = origin + scan.cloud.viewpoint.unwrap_or_default().as_dvec3();
            let colors: Option<Vec<Vec3>> = args.texture.map(|period| {
                grid.iter()
                    .map(|p| p.map_or(Vec3::ZERO, |p| texture(p, period)))
                    .collect()
            });
            let bytes = splatray::io::encode_organised(
                scan.columns,
                scan.rows,
                &grid,
                position,
                rotation,
                colors.as_deref(),
            );
            splatray::io::write_bytes(&args.output, &bytes)?;
            eprintln!(
                "splatray: an organised {}x{} grid in the {} frame, a pinhole of focal length \
                 {f:.4} px centred at ({cx:.2}, {cy:.2})",
                scan.columns,
                scan.rows,
                match frame {
                    Frame::Optical => "optical",
                    Frame::Gl => "-z",
                }
            );
        }
    }
    eprintln!(
        "splatray: scan of {} rays: {} returns, {} missing, {} outliers, {} points (spacing {:.3e}, range noise {:.3e}) -> {}",
        scan.rays,
        scan.returns,
        scan.missing,
        scan.outliers,
        scan.cloud.len(),
        scan.spacing,
        scan.noise_sigma,
        args.output.display()
    );
    Ok(())
}
