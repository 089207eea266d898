//! A synthetic airborne survey, for scale runs a user can repeat: rolling
//! terrain with box buildings as an exact triangle mesh, scanned from
//! above as an airborne laser scanner sees it (near-nadir rays across a
//! swath, range noise), delivered as georeferenced LAZ tiles, with the
//! mesh kept as the truth.
//!
//! Everything follows from the seed: each tile's points come from a
//! generator seeded by the seed and the tile's number, so tiles can be
//! made in any order (and the same tile twice gives the same bytes).

use crate::embree::{Device, TriangleScene};
use crate::geometry::Ray;
use crate::io::{IoError, IoErrorKind, Mesh, write_atomic};
use crate::progress::{Progress, notify};
use crate::rng::SplitMix64;
use crate::{Error, Result};
use glam::DVec3;
use rayon::prelude::*;
use std::io::Write;
use std::path::{Path, PathBuf};

/// What to make.
#[derive(Clone, Debug)]
pub struct TerrainParams {
    /// Side of the square survey, metres.
    pub size: f64,
    /// Tiles per side (the survey is `tiles × tiles` LAZ files).
    pub tiles: u32,
    /// Points per square metre.
    pub density: f64,
    /// Buildings (boxes 8 to 30 m wide, 4 to 25 m tall).
    pub buildings: u32,
    /// Standard deviation of the range noise, metres.
    pub noise: f64,
    /// Seed of everything.
    pub seed: u64,
    /// Where the survey's south-west corner lies (e.g. UTM metres).
    pub origin: DVec3,
    /// How the scanner's rays look at the ground ([`ScanPattern`]).
    pub pattern: ScanPattern,
}

/// How the airborne scanner's rays look at the ground. The aircraft flies
/// along +y (north); every pattern has the same number of rays a square
/// metre, aimed at uniformly random ground positions, and differs only in
/// the directions they arrive from, which decide which walls get points.
///
/// Figures of real systems (RIEGL data sheets as quoted by vendors, and
/// the scanner models of the HELIOS++ simulator, 3dgeo-heidelberg/helios
/// `data/scanners_als.xml`): the RIEGL VQ-840-G has a "nearly elliptic"
/// scan pattern, ±20° off nadir across the flight direction and ±14° along
/// it, so every ground point is seen once looking forward and once looking
/// back; the VQ-880-G is modelled with conic (Palmer) optics, 20° off
/// nadir; the VQ-1560i has two channels, each a rotating-mirror line
/// scanner over ±30° across the track, one pitched 14° forward and one 14°
/// back (HELIOS++ also yaws both by 8°, omitted here).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub enum ScanPattern {
    /// One line scanner sweeping across the track only, up to ±15° off
    /// nadir: no ray has a component along the track, so walls facing ±y
    /// get no return at all (`docs/notes/creases.md`, "The airborne survey:
    /// walls the scan never saw"). The survey of issue 39's first figures,
    /// and the default until the scanner was made one a real system flies.
    Across,
    /// An elliptical (Palmer) scanner, as the RIEGL VQ-840-G's nearly
    /// elliptic pattern: ±20° across the track, ±14° along it, the phase
    /// round the ellipse uniform, so each wall is seen from the side of
    /// the ellipse that faces it.
    Palmer,
    /// Two line scanners as the RIEGL VQ-1560i's two channels: each sweeps
    /// ±30° across the track, one pitched 14° forward, the other 14° back;
    /// half the rays each. The default: of the patterns real systems fly it
    /// measured best on the default survey (`docs/notes/real-scans.md`, "Issue
    /// 39: a survey a real scanner makes").
    #[default]
    Oblique,
    /// Crossing strips: half the rays flown north-south (tilted across, as
    /// [`ScanPattern::Across`]), half east-west (tilted along y), ±15°.
    Cross,
}

impl crate::names::Named for ScanPattern {
    const WHAT: &'static str = "survey pattern";
    const ALL: &'static [Self] = &[Self::Across, Self::Palmer, Self::Oblique, Self::Cross];
    const NAMES: &'static [&'static str] = &["across", "palmer", "oblique", "cross"];
}

impl ScanPattern {
    /// The unit direction of a ray (pointing down) drawn with `rng`.
    fn direction(self, rng: &mut SplitMix64) -> DVec3 {
        let deg = f64::to_radians;
        match self {
            ScanPattern::Across => {
                let tilt = (rng.next_f64() * 2.0 - 1.0) * deg(15.0);
                DVec3::new(tilt.sin(), 0.0, -tilt.cos())
            }
            ScanPattern::Palmer => {
                let phase = std::f64::consts::TAU * rng.next_f64();
                DVec3::new(
                    deg(20.0).tan() * phase.sin(),
                    deg(14.0).tan() * phase.cos(),
                    -1.0,
                )
                .normalize()
            }
            ScanPattern::Oblique => {
                let s = (rng.next_f64() * 2.0 - 1.0) * deg(30.0);
                let pitch = if rng.next_f64() < 0.5 {
                    deg(14.0)
                } else {
                    -deg(14.0)
                };
                DVec3::new(s.sin(), s.cos() * pitch.sin(), -s.cos() * pitch.cos())
            }
            ScanPattern::Cross => {
                let tilt = (rng.next_f64() * 2.0 - 1.0) * deg(15.0);
                if rng.next_f64() < 0.5 {
                    DVec3::new(tilt.sin(), 0.0, -tilt.cos())
                } else {
                    DVec3::new(0.0, tilt.sin(), -tilt.cos())
                }
            }
        }
    }
}

impl Default for TerrainParams {
    fn default() -> Self {
        TerrainParams {
            size: 200.0,
            tiles: 2,
            density: 10.0,
            buildings: 12,
            noise: 0.03,
            seed: 1,
            origin: DVec3::new(500_000.0, 4_000_000.0, 100.0),
            pattern: ScanPattern::default(),
        }
    }
}

/// What was made.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct TerrainReport {
    /// The LAZ tiles, in order.
    pub tiles: Vec<PathBuf>,
    /// Points written in all.
    pub points: u64,
    /// The truth mesh (PLY, f64 world coordinates) and its triangles.
    pub truth: PathBuf,
    /// See `truth`.
    pub triangles: usize,
}

/// The ground's height at `(x, y)` (metres from the survey's corner):
/// rolling hills from a few seeded waves, up to about 12 m.
fn ground(x: f64, y: f64, waves: &[[f64; 4]]) -> f64 {
    waves
        .iter()
        .map(|w| w[0] * (w[1] * x + w[2] * y + w[3]).sin())
        .sum()
}

/// The survey's exact surface: the ground as a grid (cells at most 2 m,
/// and at most 2000 a side) and each building as a closed box standing
/// on it, in metres from the survey's corner.
#[must_use]
pub fn terrain_mesh(p: &TerrainParams) -> Mesh {
    let mut rng = SplitMix64::new(p.seed ^ 0x7e22_a1f5);
    let waves: Vec<[f64; 4]> = (0..6)
        .map(|i| {
            let wavelength = p.size.max(1.0) / (1.0 + 1.5 * f64::from(i) + 2.0 * rng.next_f64());
            let angle = std::f64::consts::TAU * rng.next_f64();
            let k = std::f64::consts::TAU / wavelength;
            [
                4.0 / (1.0 + f64::from(i)),
                k * angle.cos(),
                k * angle.sin(),
                std::f64::consts::TAU * rng.next_f64(),
            ]
        })
        .collect();
    let n = ((p.size / 2.0).ceil() as usize).clamp(1, 2000);
    let cell = p.size / n as f64;
    let mut positions = Vec::with_capacity((n + 1) * (n + 1));
    let mut triangles = Vec::with_capacity(2 * n * n);
    for j in 0..=n {
        for i in 0..=n {
            let (x, y) = (i as f64 * cell, j as f64 * cell);
            positions.push(DVec3::new(x, y, ground(x, y, &waves)));
        }
    }
    let at = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    for j in 0..n {
        for i in 0..n {
            triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    for _ in 0..p.buildings {
        let w = 8.0 + 22.0 * rng.next_f64();
        let d = 8.0 + 22.0 * rng.next_f64();
        let h = 4.0 + 21.0 * rng.next_f64();
        let x0 = (p.size - w).max(0.0) * rng.next_f64();
        let y0 = (p.size - d).max(0.0) * rng.next_f64();
        let (x1, y1) = ((x0 + w).min(p.size), (y0 + d).min(p.size));
        // Founded below the lowest ground under it, roofed h above the
        // highest.
        let corners = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)];
        let heights: Vec<f64> = corners
            .iter()
            .chain(&[(0.5 * (x0 + x1), 0.5 * (y0 + y1))])
            .map(|&(x, y)| ground(x, y, &waves))
            .collect();
        let base = heights.iter().copied().fold(f64::INFINITY, f64::min) - 1.0;
        let roof = heights.iter().copied().fold(f64::NEG_INFINITY, f64::max) + h;
        // Each face its own four corners: the truth's vertex normals are
        // then the faces' own, and the box keeps its sharp edges.
        let lo: Vec<DVec3> = corners
            .iter()
            .map(|&(x, y)| DVec3::new(x, y, base))
            .collect();
        let hi: Vec<DVec3> = corners
            .iter()
            .map(|&(x, y)| DVec3::new(x, y, roof))
            .collect();
        let mut faces = vec![[hi[0], hi[1], hi[2], hi[3]], [lo[0], lo[3], lo[2], lo[1]]];
        for k in 0..4 {
            let m = (k + 1) % 4;
            faces.push([lo[k], lo[m], hi[m], hi[k]]);
        }
        for q in faces {
            let first = positions.len() as u32;
            positions.extend_from_slice(&q);
            triangles.push([first, first + 1, first + 2]);
            triangles.push([first, first + 2, first + 3]);
        }
    }
    let centre = DVec3::new(0.5 * p.size, 0.5 * p.size, 0.0);
    Mesh {
        positions: positions.iter().map(|q| (*q - centre).as_vec3()).collect(),
        triangles,
        origin: p.origin + centre,
    }
}

fn io_err(path: &Path, e: impl std::fmt::Display) -> Error {
    Error::from(IoError::new(path, IoErrorKind::Data(e.to_string())))
}

/// Writes `mesh` as a binary PLY with f64 coordinates in the world's
/// frame (what [`crate::io::read_mesh`] reads back to the millimetre).
///
/// # Errors
/// When the file cannot be written.
pub fn write_mesh_ply(mesh: &Mesh, path: &Path) -> Result<()> {
    write_atomic(path, |tmp| -> std::io::Result<()> {
        let mut w = std::io::BufWriter::new(std::fs::File::create(tmp)?);
        write!(
            w,
            "ply\nformat binary_little_endian 1.0\ncomment splatray terrain truth\n\
             element vertex {}\nproperty double x\nproperty double y\nproperty double z\n\
             element face {}\nproperty list uchar int vertex_indices\nend_header\n",
            mesh.positions.len(),
            mesh.triangles.len()
        )?;
        for p in &mesh.positions {
            for c in (mesh.origin + p.as_dvec3()).to_array() {
                w.write_all(&c.to_le_bytes())?;
            }
        }
        for t in &mesh.triangles {
            w.write_all(&[3])?;
            for i in t {
                w.write_all(&(*i as i32).to_le_bytes())?;
            }
        }
        w.flush()
    })
    .map_err(Error::from)
}

/// Points an airborne scan of tile `(tx, ty)` sees: `count` rays from
/// 500 m above, at uniformly random ground positions of the tile, in the
/// directions of the scan pattern ([`ScanPattern`]), each meeting the
/// surface first there, with Gaussian range noise; in the survey's corner
/// frame, metres.
fn scan_tile(
    p: &TerrainParams,
    scene: &TriangleScene,
    centre: DVec3,
    (tx, ty): (u32, u32),
    range: std::ops::Range<u64>,
) -> Vec<DVec3> {
    let tile = p.size / f64::from(p.tiles);
    let number = u64::from(ty) * u64::from(p.tiles) + u64::from(tx);
    (range.start as usize..range.end as usize)
        .into_par_iter()
        .with_min_len(4096)
        .filter_map(|k| {
            let k = k as u64;
            let mut rng =
                SplitMix64::new(p.seed ^ number.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ (k << 20));
            let x = (f64::from(tx) + rng.next_f64()) * tile;
            let y = (f64::from(ty) + rng.next_f64()) * tile;
            let dir = p.pattern.direction(&mut rng);
            let height = 500.0;
            let target = DVec3::new(x, y, 0.0);
            let from = target - dir * (height / -dir.z);
            let ray = Ray {
                origin: (from - centre).as_vec3(),
                dir: dir.as_vec3(),
            };
            let hit = scene.intersect(&ray, 0.0, f32::INFINITY)?;
            let t = f64::from(hit.t) + p.noise * rng.next_gaussian();
            Some(from + dir * t)
        })
        .collect()
}

/// Makes the survey in `dir`: `tiles/tile_X_Y.laz` (millimetre
/// resolution, the survey's corner as the offset) and `truth.ply`.
///
/// # Errors
/// Parameters out of range, or files that cannot be written.
pub fn write_terrain(
    p: &TerrainParams,
    dir: &Path,
    progress: Option<Progress<'_>>,
) -> Result<TerrainReport> {
    if !(p.size.is_finite() && p.size >= 10.0 && p.size <= 1.0e6) {
        return Err(Error::invalid(format!(
            "--size {} must be 10 to 1e6 metres",
            p.size
        )));
    }
    if p.tiles == 0 || p.tiles > 1000 {
        return Err(Error::invalid(format!(
            "--tiles {} must be 1 to 1000",
            p.tiles
        )));
    }
    if !(p.density.is_finite() && p.density > 0.0 && p.density <= 10_000.0) {
        return Err(Error::invalid(format!(
            "--density {} must be in (0, 10000] points a square metre",
            p.density
        )));
    }
    if !(p.noise.is_finite() && p.noise >= 0.0 && p.noise <= 10.0) {
        return Err(Error::invalid(format!(
            "--noise {} must be 0 to 10 metres",
            p.noise
        )));
    }
    if !p.origin.is_finite() {
        return Err(Error::invalid("--origin must be finite"));
    }
    let tile = p.size / f64::from(p.tiles);
    let per_tile = (p.density * tile * tile).round() as u64;
    let tiles_dir = dir.join("tiles");
    std::fs::create_dir_all(&tiles_dir).map_err(|e| io_err(&tiles_dir, e))?;
    let mesh = terrain_mesh(p);
    let truth = dir.join("truth.ply");
    write_mesh_ply(&mesh, &truth)?;
    let device = Device::new()?;
    let scene = TriangleScene::new(&device, &[(&mesh.positions, &mesh.triangles)])?;
    let centre = mesh.origin - p.origin;
    let mut report = TerrainReport {
        truth,
        triangles: mesh.triangles.len(),
        ..TerrainReport::default()
    };
    let total = u64::from(p.tiles) * u64::from(p.tiles);
    for ty in 0..p.tiles {
        for tx in 0..p.tiles {
            let path = tiles_dir.join(format!("tile_{tx:03}_{ty:03}.laz"));
            let mut header = las::Builder::from((1, 2));
            header.point_format = las::point::Format::new(0).map_err(|e| io_err(&path, e))?;
            header.point_format.is_compressed = true;
            header.transforms = las::Vector {
                x: las::Transform {
                    scale: 0.001,
                    offset: p.origin.x,
                },
                y: las::Transform {
                    scale: 0.001,
                    offset: p.origin.y,
                },
                z: las::Transform {
                    scale: 0.001,
                    offset: p.origin.z,
                },
            };
            header.generating_software = "splatray terrain".into();
            let header = header.into_header().map_err(|e| io_err(&path, e))?;
            let mut written = 0u64;
            write_atomic(&path, |tmp| -> std::result::Result<(), String> {
                let f = std::fs::File::create(tmp).map_err(|e| e.to_string())?;
                let mut w = las::Writer::new(std::io::BufWriter::new(f), header)
                    .map_err(|e| e.to_string())?;
                let chunk = 1u64 << 20;
                let mut start = 0;
                while start < per_tile {
                    let end = (start + chunk).min(per_tile);
                    for q in scan_tile(p, &scene, centre, (tx, ty), start..end) {
                        let world = p.origin + q;
                        w.write_point(las::Point {
                            x: world.x,
                            y: world.y,
                            z: world.z,
                            ..las::Point::default()
                        })
                        .map_err(|e| e.to_string())?;
                        written += 1;
                    }
                    start = end;
                }
                w.close().map_err(|e| e.to_string())
            })?;
            report.points += written;
            report.tiles.push(path);
            notify(
                progress,
                "scanning tiles",
                report.tiles.len() as f64 / total as f64,
            );
        }
    }
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_mesh_is_a_ground_grid_and_closed_boxes() {
        let p = TerrainParams {
            size: 40.0,
            buildings: 2,
            ..TerrainParams::default()
        };
        let m = terrain_mesh(&p);
        // 20 × 20 cells of 2 m, two triangles each, and 12 per building.
        assert_eq!(m.triangles.len(), 2 * 20 * 20 + 2 * 12);
        assert_eq!(m.positions.len(), 21 * 21 + 2 * 24);
        // The same seed, the same mesh; another seed, another.
        assert_eq!(terrain_mesh(&p).positions, m.positions);
        let q = TerrainParams { seed: 2, ..p };
        assert_ne!(terrain_mesh(&q).positions, m.positions);
        assert!(m.positions.iter().all(|v| v.is_finite()));
    }

    /// Each pattern's rays point down, unit length; only `across` never
    /// looks along the track (walls facing ±y get no return), the others
    /// look both forward and back.
    #[test]
    fn patterns_look_along_the_track_except_across() {
        use crate::names::Named;
        for &pattern in ScanPattern::ALL {
            let name = pattern.name();
            let mut rng = SplitMix64::new(7);
            let dirs: Vec<DVec3> = (0..2000).map(|_| pattern.direction(&mut rng)).collect();
            assert!(
                dirs.iter()
                    .all(|d| (d.length() - 1.0).abs() < 1e-12 && d.z < -0.8),
                "{name}"
            );
            let fore = dirs.iter().filter(|d| d.y > 0.05).count();
            let aft = dirs.iter().filter(|d| d.y < -0.05).count();
            let east = dirs.iter().filter(|d| d.x > 0.05).count();
            let west = dirs.iter().filter(|d| d.x < -0.05).count();
            if pattern == ScanPattern::Across {
                assert_eq!((fore, aft), (0, 0), "{name}");
            } else {
                assert!(
                    fore > 300 && aft > 300,
                    "{name}: {fore} forward, {aft} back"
                );
            }
            assert!(east > 300 && west > 300, "{name}: {east} east, {west} west");
        }
    }
}
