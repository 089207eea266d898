//! `splatray sample MESH.ply -n N -o points.ply [--noise SIGMA] [--seed S]`,
//! or a synthetic scan: `splatray sample MESH.ply --scan-from X,Y,Z -o
//! scan.pcd [--pattern raster|lines] [--rays W,H] [--range-noise S |
//! --range-noise-spacing F] [--outliers F] [--missing F]`, from several
//! stations with `--scan-from` repeated and `-o scans.e57`.

use super::progress::ProgressLine;
use crate::scanner::{RangeNoise, ScanParams, ScanPattern};
use crate::workflow::sample::{AreaSampling, ScanOutput, SensorFrame, sample_area, sample_scan};
use crate::{Error, Result};
use std::path::PathBuf;

/// Arguments of `splatray sample`.
#[derive(Clone, Debug, clap::Args)]
pub struct SampleArgs {
    /// Triangle mesh to sample (PLY with faces).
    pub mesh: PathBuf,
    /// Number of points sampled uniformly by area (not with --scan-from).
    #[arg(short = 'n', long = "points", required_unless_present = "scan_from")]
    pub n: Option<usize>,
    /// Output point cloud: binary PLY (x y z nx ny nz), or PCD when the
    /// name ends in .pcd (a scan's VIEWPOINT is kept there), or for a scan
    /// E57 when it ends in .e57 (each station's scan with its pose and the
    /// directions of its rays that met nothing).
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
    /// viewpoint written as the PCD's VIEWPOINT. Repeated, a scan from each
    /// station (station k's seed is --seed plus k), written to an E57 file.
    #[arg(long, value_parser = parse_xyz, allow_hyphen_values = true, action = clap::ArgAction::Append)]
    pub scan_from: Vec<glam::DVec3>,
    /// The point the scanner looks at (X,Y,Z). Default: the mesh's centre.
    #[arg(long, value_parser = parse_xyz, allow_hyphen_values = true, requires = "scan_from")]
    pub scan_at: Option<glam::DVec3>,
    /// raster (a camera's pixel grid) or lines (equal angular steps, the
    /// lines `W/H` times farther apart than the samples along them).
    #[arg(long, default_value = "raster", requires = "scan_from", value_parser = crate::names::parse::<ScanPattern>)]
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

/// The frame of an organised scan's sensor.
#[derive(Clone, Copy, Debug, PartialEq, clap::ValueEnum)]
pub enum Frame {
    /// x right, y down, z forward.
    Optical,
    /// x right, y up, looking along -z.
    Gl,
}

/// `X,Y,Z` as a point (`--scan-from`, `--scan-at`).
fn parse_xyz(s: &str) -> std::result::Result<glam::DVec3, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| format!("{s:?} is not three numbers X,Y,Z"))?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(glam::DVec3::new(x, y, z)),
        [_, _, _] => Err(format!("{s:?}: a point must be finite")),
        _ => Err(format!("{s:?} needs three numbers X,Y,Z, got {}", v.len())),
    }
}

impl From<Frame> for SensorFrame {
    fn from(f: Frame) -> Self {
        match f {
            Frame::Optical => SensorFrame::Optical,
            Frame::Gl => SensorFrame::Gl,
        }
    }
}

/// Run `splatray sample`; the message of an error is one line.
///
/// # Errors
/// When the mesh cannot be read, has no area, the scan sees nothing, or the
/// output cannot be written.
pub fn run(args: &SampleArgs) -> Result<()> {
    if !args.scan_from.is_empty() {
        crate::render::output::check_extension(&args.output, &["ply", "pcd", "e57"])?;
        return scan(args);
    }
    crate::render::output::check_extension(&args.output, &["ply", "pcd"])?;
    let req = AreaSampling {
        mesh: args.mesh.clone(),
        output: args.output.clone(),
        points: args.n.unwrap_or(0),
        noise: args.noise,
        seed: args.seed,
    };
    let line = ProgressLine::new();
    let made = sample_area(&req, Some(&|stage, f| line.update(stage, f)));
    line.finish();
    let made = made?;
    eprintln!(
        "splatray: {} points from {} triangles -> {}",
        made.points,
        made.triangles,
        args.output.display()
    );
    Ok(())
}

/// The scan's parameters from the arguments.
fn scan_params(args: &SampleArgs) -> Result<ScanParams> {
    let [columns, rows] = args.rays[..] else {
        return Err(Error::invalid(format!(
            "--rays needs two numbers W,H, got {}",
            args.rays.len()
        )));
    };
    Ok(ScanParams {
        from: args.scan_from[0],
        at: args.scan_at,
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
        tracer: crate::scanner::ScanTracer::Embree,
    })
}

fn scan(args: &SampleArgs) -> Result<()> {
    if args.n.is_some() {
        return Err("-n and --scan-from exclude each other: a scan's rays set the points".into());
    }
    let how = match args.organised {
        None => ScanOutput::Points,
        Some(frame) => ScanOutput::Organised(frame.into(), args.texture),
    };
    let stations = &args.scan_from;
    let scans = sample_scan(&args.mesh, &scan_params(args)?, stations, &args.output, how)?;
    if let (ScanOutput::Organised(frame, _), Some((f, cx, cy))) = (how, scans[0].pinhole) {
        eprintln!(
            "splatray: an organised {}x{} grid in the {} frame, a pinhole of focal length \
             {f:.4} px centred at ({cx:.2}, {cy:.2})",
            scans[0].columns,
            scans[0].rows,
            frame.describe()
        );
    }
    for (scan, at) in scans.iter().zip(stations) {
        let from = if stations.len() > 1 {
            format!(" from {}", at.to_array().map(|c| format!("{c}")).join(","))
        } else {
            String::new()
        };
        eprintln!(
            "splatray: scan of {} rays{from}: {} returns, {} missing, {} outliers, {} points (spacing {:.3e}, range noise {:.3e}){}",
            scan.rays,
            scan.returns,
            scan.missing,
            scan.outliers,
            scan.cloud.len(),
            scan.spacing,
            scan.noise_sigma,
            if stations.len() > 1 {
                String::new()
            } else {
                format!(" -> {}", args.output.display())
            }
        );
    }
    if stations.len() > 1 {
        let points: usize = scans.iter().map(|s| s.cloud.len()).sum();
        eprintln!(
            "splatray: {} scans, {points} points -> {}",
            scans.len(),
            args.output.display()
        );
    }
    Ok(())
}
