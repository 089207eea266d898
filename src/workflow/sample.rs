//! The `sample` workflow: points from a triangle mesh, either sampled
//! uniformly by area (a binary PLY written a batch at a time, or a PCD made
//! in memory) or cast as a synthetic range scan (`scanner`) from one
//! station or several (an E57 file of scans), optionally
//! written as an organised PCD with a procedural colour texture, as a depth
//! and colour camera would capture it. The front end parses and prints.

use crate::io::{Format, MeshSampler, read_mesh, sample_mesh, write_points, write_sample_ply};
use crate::progress::Progress;
use crate::scanner::{Scan, ScanParams, join_scans, scan_each};
use crate::{Error, Result};
use glam::{DVec3, Vec3};
use std::path::{Path, PathBuf};

/// The most points `sample` makes: 10^10 (240 GB of binary PLY, written a
/// batch at a time; a PCD is made in memory and checked against it first).
pub const MAX_SAMPLES: usize = 10_000_000_000;

/// Bytes a point takes while a PCD is made in memory: the positions and
/// normals (24 B), the encoded records (24 B) and their copy in the file
/// buffer.
const PCD_BYTES_PER_POINT: u64 = 72;

/// What [`sample_area`] is asked to do.
#[derive(Clone, Debug, PartialEq)]
pub struct AreaSampling {
    /// Triangle mesh to sample (PLY with faces).
    pub mesh: PathBuf,
    /// Output point cloud: binary PLY, or PCD when the name ends in .pcd.
    pub output: PathBuf,
    /// Number of points, 1 to [`MAX_SAMPLES`].
    pub points: usize,
    /// Standard deviation of isotropic Gaussian noise on positions.
    pub noise: f32,
    /// Seed of the generator.
    pub seed: u64,
}

/// What [`sample_area`] wrote.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AreaSampled {
    /// Points written.
    pub points: usize,
    /// Triangles of the mesh.
    pub triangles: usize,
}

/// Samples `req.points` points uniformly by area and writes them.
///
/// # Errors
/// Bad options, an unreadable mesh or one with no area, too little memory
/// for a PCD, an unwritable output; each one line.
pub fn sample_area(req: &AreaSampling, progress: Option<Progress<'_>>) -> Result<AreaSampled> {
    let n = req.points;
    if n == 0 || n > MAX_SAMPLES {
        return Err(Error::invalid(format!(
            "-n must be between 1 and {MAX_SAMPLES}"
        )));
    }
    if !(req.noise.is_finite() && req.noise >= 0.0) {
        return Err(Error::invalid(format!(
            "--noise {} must be a finite, non-negative number",
            req.noise
        )));
    }
    let mesh = read_mesh(&req.mesh)?;
    let no_area = || {
        Error::invalid(format!(
            "{}: the mesh has no triangle with a non-zero area to sample",
            req.mesh.display()
        ))
    };
    let points = if Format::from_extension(&req.output) == Some(Format::Pcd) {
        crate::memory::check(
            &format!("sampling {n} points into a PCD"),
            (n as u64).saturating_mul(PCD_BYTES_PER_POINT),
        )
        .map_err(|e| e.with_hint("write a .ply instead (written a batch at a time)"))?;
        let cloud = sample_mesh(&mesh, n, req.noise, req.seed);
        if cloud.is_empty() {
            return Err(no_area());
        }
        write_points(&req.output, &cloud)?;
        cloud.len()
    } else {
        let sampler = MeshSampler::new(&mesh, n, req.noise, req.seed);
        if sampler.is_empty() {
            return Err(no_area());
        }
        write_sample_ply(&req.output, &sampler, progress)?;
        sampler.len()
    };
    Ok(AreaSampled {
        points,
        triangles: mesh.triangles.len(),
    })
}

/// The frame of an organised scan's sensor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SensorFrame {
    /// x right, y down, z forward (PCL, OpenCV, ROS).
    Optical,
    /// x right, y up, looking along -z (OpenGL).
    Gl,
}

impl SensorFrame {
    /// The frame as the command's message names it.
    pub fn describe(self) -> &'static str {
        match self {
            SensorFrame::Optical => "optical",
            SensorFrame::Gl => "-z",
        }
    }
}

/// How a scan is written.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ScanOutput {
    /// The returns as a point cloud (any point format).
    Points,
    /// The raster as an organised PCD in this frame, coloured with the
    /// [`texture`] of this period where given.
    Organised(SensorFrame, Option<f64>),
}

/// Scans the mesh at `mesh` from each of `stations` (`params.from` is
/// replaced by each in turn; station `k`'s seed is `params.seed + k`) and
/// writes the scans to `output`; returns them for their counts. One
/// station's scan goes to any point format (the PCD's `VIEWPOINT` and an
/// E57 file's pose keep the scanner; E57 keeps its misses too); several
/// stations' need an E57 file, which keeps each scan with its scanner.
///
/// # Errors
/// An unreadable mesh, a scan that sees nothing, several stations not
/// written to E57, an organised output that is not one raster written to a
/// PCD, an unwritable output; each one line.
pub fn sample_scan(
    mesh: &Path,
    params: &ScanParams,
    stations: &[DVec3],
    output: &Path,
    how: ScanOutput,
) -> Result<Vec<Scan>> {
    if let ScanOutput::Organised(_, Some(period)) = how
        && !(period.is_finite() && period > 0.0)
    {
        return Err(Error::invalid(format!(
            "--texture {period} must be a positive period"
        )));
    }
    let format = Format::from_extension(output);
    if let ScanOutput::Organised(..) = how
        && (format != Some(Format::Pcd) || stations.len() != 1)
    {
        return Err(Error::invalid(format!(
            "{}: --organised writes one scan's raster to a PCD (a name ending in .pcd)",
            output.display()
        )));
    }
    if stations.len() > 1 && format != Some(Format::E57) {
        return Err(Error::invalid(format!(
            "{}: {} stations make {} scans, each with its own scanner: write them to an \
             E57 file (a name ending in .e57); a PLY or PCD holds one viewpoint",
            output.display(),
            stations.len(),
            stations.len()
        )));
    }
    let mesh = read_mesh(mesh)?;
    let scans = scan_each(&mesh, params, stations)?;
    match how {
        ScanOutput::Points => write_points(output, &join_scans(mesh.origin, &scans))?,
        ScanOutput::Organised(frame, texture) => {
            let bytes = encode_organised_scan(&scans[0], frame, texture)?;
            crate::io::write_bytes(output, &bytes)?;
        }
    }
    Ok(scans)
}

/// The organised PCD of a raster scan: the grid of rays (NaN where a ray
/// missed), VIEWPOINT the sensor's pose in `frame`, coloured with the
/// [`texture`] of period `texture` where given.
///
/// # Errors
/// The scan is not a raster (no pinhole).
pub fn encode_organised_scan(
    scan: &Scan,
    frame: SensorFrame,
    texture_period: Option<f64>,
) -> Result<Vec<u8>> {
    if scan.pinhole.is_none() {
        return Err("--organised needs the raster pattern (a camera's pixel grid)".into());
    }
    let [forward, right, up] = scan.axes.map(Vec3::as_dvec3);
    let (y, z) = match frame {
        SensorFrame::Optical => (-up, forward),
        SensorFrame::Gl => (up, -forward),
    };
    let rotation = glam::DQuat::from_mat3(&glam::DMat3::from_cols(right, y, z));
    let origin = scan.cloud.origin;
    let grid: Vec<Option<DVec3>> = scan
        .grid
        .iter()
        .map(|p| p.map(|p| origin + p.as_dvec3()))
        .collect();
    let position = origin + scan.cloud.viewpoint.unwrap_or_default().as_dvec3();
    let colors: Option<Vec<Vec3>> = texture_period.map(|period| {
        grid.iter()
            .map(|p| p.map_or(Vec3::ZERO, |p| texture(p, period)))
            .collect()
    });
    Ok(crate::io::encode_organised(
        scan.columns,
        scan.rows,
        &grid,
        position,
        rotation,
        colors.as_deref(),
    ))
}

/// The procedural texture of `--texture`: at world point `p`, three
/// sinusoidal bands of period `period` along different directions, one per
/// channel (linear RGB in 0.1 … 0.9).
pub fn texture(p: DVec3, period: f64) -> Vec3 {
    let w = std::f64::consts::TAU / period;
    let band = |x: f64| (0.5 + 0.4 * x.sin()) as f32;
    Vec3::new(
        band(w * p.x),
        band(w * (0.8 * p.y + 0.6 * p.z) + 1.0),
        band(w * (0.6 * p.x - 0.8 * p.z) + 2.0),
    )
}
