//! A synthetic range scanner: rays cast from a viewpoint onto a triangle
//! mesh, with the defects of real scans (range noise, outliers, missing
//! returns). The mesh stays the exact surface, so a scan of it can be
//! splatted and compared with `compare --truth`; the viewpoint is kept with
//! the points, as a real scanner's `VIEWPOINT`.

use crate::embree::{Device, TriangleScene};
use crate::geometry::Ray;
use crate::io::{Mesh, grid_misses};
use crate::names::Named;
use crate::primitive::Triangle;
use crate::rng::SplitMix64;
use crate::splat::PointCloud;
use crate::{Error, Result};
use glam::{DVec3, Vec3};
use rayon::prelude::*;

/// How the rays sweep the field of view.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ScanPattern {
    /// A pinhole camera's pixel grid (a depth camera or stereo rig):
    /// `columns × rows` rays, square pixels.
    #[default]
    Raster,
    /// Scan lines at equal angular steps (a line scanner or lidar): `rows`
    /// lines of `columns` samples each over a square field, so the spacing
    /// between lines is `columns / rows` times the spacing along them.
    Lines,
}

impl Named for ScanPattern {
    const WHAT: &'static str = "scan pattern";
    const ALL: &'static [Self] = &[Self::Raster, Self::Lines];
    const NAMES: &'static [&'static str] = &["raster", "lines"];
}

/// What traces the scanner's rays to the mesh.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ScanTracer {
    /// Embree's triangles. Its kernels round a range's last bits
    /// differently on each ISA (SSE4.2, AVX2, AVX-512), so the points move
    /// by an ulp or so from one machine to another.
    #[default]
    Embree,
    /// The octree's exact triangles (`crate::primitive::Triangle`): the
    /// same ranges, bit for bit, on every SIMD path. For a test whose
    /// measure hangs on the points' last bits.
    Octree,
}

/// The scanner's tracer, built over the mesh.
enum Tracer {
    Embree(TriangleScene),
    Octree(Box<dyn crate::accel::Backend>),
}

impl Tracer {
    fn new(mesh: &Mesh, which: ScanTracer) -> Result<Tracer> {
        Ok(match which {
            ScanTracer::Embree => {
                let device = Device::new()?;
                Tracer::Embree(TriangleScene::new(
                    &device,
                    &[(&mesh.positions, &mesh.triangles)],
                )?)
            }
            ScanTracer::Octree => {
                let tris: Vec<Triangle> = mesh
                    .triangles
                    .iter()
                    .map(|ix| Triangle {
                        v: ix.map(|i| mesh.positions[i as usize]),
                    })
                    .filter(Triangle::is_proper)
                    .collect();
                let octree = crate::accel::registry::lookup::<Triangle>("octree")?;
                Tracer::Octree(octree.build(&tris)?)
            }
        })
    }

    /// The range of the nearest hit along `ray`, or infinity.
    fn range(&self, ray: &Ray) -> f32 {
        match self {
            Tracer::Embree(s) => s.intersect(ray, 0.0, f32::INFINITY).map_or(f32::INFINITY, |h| h.t),
            Tracer::Octree(b) => {
                let mut hits = crate::accel::CandidateHits::new(0.0);
                b.intersect(ray, 0.0, f32::INFINITY, &mut hits);
                hits.nearest().map_or(f32::INFINITY, |c| c.t)
            }
        }
    }
}

/// Range noise: absolute, or relative to the scan's own point spacing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RangeNoise {
    /// Standard deviation in the mesh's units.
    Absolute(f32),
    /// Standard deviation as a multiple of the median point spacing (the
    /// larger angular step times the range).
    Spacing(f32),
}

/// What the scanner does.
#[derive(Clone, Debug, PartialEq)]
pub struct ScanParams {
    /// The scanner's position, in the mesh file's coordinates (f64: a far
    /// mesh's origin is subtracted before single precision).
    pub from: DVec3,
    /// The point it looks at (default: the centre of the mesh's bounding box).
    pub at: Option<DVec3>,
    /// Samples per row (per line).
    pub columns: u32,
    /// Rows (lines).
    pub rows: u32,
    /// Vertical field of view in degrees (default: the mesh's bounding sphere
    /// fills it with a 5 % margin).
    pub fov: Option<f32>,
    /// Raster or scan lines.
    pub pattern: ScanPattern,
    /// Gaussian noise along the ray on every range.
    pub range_noise: RangeNoise,
    /// Fraction of returns replaced by an outlier: a point on the same ray
    /// at a uniformly random range between half and 1.5 times the true one.
    pub outliers: f32,
    /// Fraction of returns dropped at random.
    pub missing: f32,
    /// Seed: the same seed gives the same scan on any machine.
    pub seed: u64,
    /// What traces the rays (Embree unless asked).
    pub tracer: ScanTracer,
}

impl Default for ScanParams {
    fn default() -> Self {
        ScanParams {
            from: DVec3::new(0.0, 0.0, 4.0),
            at: None,
            columns: 640,
            rows: 480,
            fov: None,
            pattern: ScanPattern::Raster,
            range_noise: RangeNoise::Absolute(0.0),
            outliers: 0.0,
            missing: 0.0,
            seed: 1,
            tracer: ScanTracer::Embree,
        }
    }
}

/// The most rays a scan casts.
pub const MAX_SCAN_RAYS: u64 = 100_000_000;

/// A scan and what happened to its rays.
#[derive(Clone, Debug, PartialEq)]
pub struct Scan {
    /// The points, with `viewpoint` set to the scanner's position.
    pub cloud: PointCloud,
    /// Rays cast.
    pub rays: usize,
    /// Rays that met the mesh.
    pub returns: usize,
    /// Returns dropped as missing.
    pub missing: usize,
    /// Returns replaced by outliers.
    pub outliers: usize,
    /// Median point spacing: the larger angular step times the range.
    pub spacing: f32,
    /// The range noise's standard deviation, in the mesh's units.
    pub noise_sigma: f32,
    /// Per ray, row by row: its point (the mesh's frame, offset from the
    /// cloud's origin), `None` where it missed or its return went missing.
    pub grid: Vec<Option<Vec3>>,
    /// Rays per row, and rows.
    pub columns: usize,
    /// See `columns`.
    pub rows: usize,
    /// The scanner's axes in the mesh's frame: forward, image right, image
    /// up (unit).
    pub axes: [Vec3; 3],
    /// For a raster: the focal length (pixels) and principal point of the
    /// pinhole whose pixel grid the rays sample (pixel centres at integers).
    pub pinhole: Option<(f64, f64, f64)>,
}

fn check(p: &ScanParams) -> Result<()> {
    let bad = |s: String| Err(Error::invalid(s));
    if !p.from.is_finite() || p.at.is_some_and(|a| !a.is_finite()) {
        return bad("the scanner position and target must be finite".into());
    }
    if p.columns == 0 || p.rows == 0 {
        return bad(format!(
            "a scan needs at least one ray per row and one row, got {}x{}",
            p.columns, p.rows
        ));
    }
    if u64::from(p.columns) * u64::from(p.rows) > MAX_SCAN_RAYS {
        return bad(format!(
            "{}x{} rays is more than the {MAX_SCAN_RAYS} a scan may cast",
            p.columns, p.rows
        ));
    }
    if p.fov.is_some_and(|f| !(f > 0.0 && f < 179.0)) {
        return bad(format!(
            "scan field of view {:?} degrees must be in (0, 179)",
            p.fov
        ));
    }
    let sigma = match p.range_noise {
        RangeNoise::Absolute(s) | RangeNoise::Spacing(s) => s,
    };
    if !(sigma.is_finite() && sigma >= 0.0) {
        return bad(format!(
            "range noise {sigma} must be finite and non-negative"
        ));
    }
    for (what, f) in [("outliers", p.outliers), ("missing", p.missing)] {
        if !(0.0..=0.5).contains(&f) {
            return bad(format!("the {what} fraction {f} must be in [0, 0.5]"));
        }
    }
    Ok(())
}

/// Where the scanner stands and looks, in the mesh's frame (offsets from
/// its origin), and its vertical field of view (radians).
#[derive(Clone, Copy)]
struct Aim {
    from: Vec3,
    forward: Vec3,
    right: Vec3,
    up: Vec3,
    vfov: f32,
}

/// The scanner of `params` placed on `mesh`: looking at `params.at` (else
/// the mesh's centre), up as near `+y` as the view allows (`+z` looking
/// along y), the field of view given or the mesh's bounding sphere's
/// (widened 5 %, 90° from inside it, at most 170°).
fn aim(mesh: &Mesh, params: &ScanParams) -> Result<Aim> {
    let (lo, hi) = mesh.positions.iter().fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(a, b), p| (a.min(*p), b.max(*p)),
    );
    if mesh.triangles.is_empty() || !(lo.is_finite() && hi.is_finite()) {
        return Err(Error::invalid("the mesh has no finite triangles to scan"));
    }
    let center = 0.5 * (lo + hi);
    // In the mesh's frame: offsets from its origin.
    let from = (params.from - mesh.origin).as_vec3();
    let at = params.at.map_or(center, |a| (a - mesh.origin).as_vec3());
    if !from.is_finite() || !at.is_finite() {
        return Err(Error::invalid(
            "the scanner is farther from the mesh than single precision holds",
        ));
    }
    let forward = (at - from)
        .try_normalize()
        .ok_or_else(|| Error::invalid("the scanner looks at its own position"))?;
    let up_hint = if forward.y.abs() > 0.99 {
        Vec3::Z
    } else {
        Vec3::Y
    };
    let right = forward.cross(up_hint).normalize();
    let up = right.cross(forward);
    let vfov = match params.fov {
        Some(f) => f.to_radians(),
        None => {
            let dist = (center - from).length();
            let radius = 0.5 * (hi - lo).length();
            if dist <= radius {
                90f32.to_radians()
            } else {
                (2.0 * (radius / dist).asin() * 1.05).min(170f32.to_radians())
            }
        }
    };
    Ok(Aim {
        from,
        forward,
        right,
        up,
        vfov,
    })
}

/// The ray direction of sample (column, row).
type DirOf = Box<dyn Fn(usize, usize) -> Vec3 + Sync>;

/// The ray direction of sample (column, row) of `params.pattern`, the
/// larger angular step between samples, and for a raster its pinhole
/// (focal length and principal point, pixels).
fn pattern(params: &ScanParams, aim: &Aim) -> (DirOf, f32, Option<(f64, f64, f64)>) {
    let Aim {
        forward,
        right,
        up,
        vfov,
        ..
    } = *aim;
    let (cols, rows) = (params.columns as usize, params.rows as usize);
    match params.pattern {
        ScanPattern::Raster => {
            let half_h = (0.5 * vfov).tan();
            let half_w = half_h * cols as f32 / rows as f32;
            // x = (2 (u + 0.5) / cols - 1) half_w: u = f x + (cols - 1) / 2.
            let pinhole = Some((
                f64::from(rows as f32) / (2.0 * f64::from(half_h)),
                (cols as f64 - 1.0) / 2.0,
                (rows as f64 - 1.0) / 2.0,
            ));
            let f = move |c: usize, r: usize| {
                let x = ((c as f32 + 0.5) / cols as f32 * 2.0 - 1.0) * half_w;
                let y = (1.0 - (r as f32 + 0.5) / rows as f32 * 2.0) * half_h;
                (forward + right * x + up * y).normalize()
            };
            (Box::new(f), 2.0 * half_h / rows as f32, pinhole)
        }
        ScanPattern::Lines => {
            let f = move |c: usize, r: usize| {
                let az = ((c as f32 + 0.5) / cols as f32 - 0.5) * vfov;
                let el = (0.5 - (r as f32 + 0.5) / rows as f32) * vfov;
                (forward * (el.cos() * az.cos()) + right * (el.cos() * az.sin()) + up * el.sin())
                    .normalize()
            };
            (Box::new(f), vfov / cols.min(rows) as f32, None)
        }
    }
}

/// Scans `mesh` from `params.from`.
///
/// # Errors
/// Parameters out of range, a target at the scanner's position, a mesh
/// Embree cannot build, or a scan that sees nothing.
pub fn scan_mesh(mesh: &Mesh, params: &ScanParams) -> Result<Scan> {
    check(params)?;
    let aim = aim(mesh, params)?;
    let Aim {
        from,
        forward,
        right,
        up,
        ..
    } = aim;
    let (cols, rows) = (params.columns as usize, params.rows as usize);
    let (dir_of, step, pinhole) = pattern(params, &aim);
    let tracer = Tracer::new(mesh, params.tracer)?;
    // Exact ranges first (the noise may be relative to the spacing).
    let ranges: Vec<f32> = (0..rows * cols)
        .into_par_iter()
        .with_min_len(1024)
        .map(|k| {
            let ray = Ray {
                origin: from,
                dir: dir_of(k % cols, k / cols),
            };
            tracer.range(&ray)
        })
        .collect();
    let mut hit_ranges: Vec<f32> = ranges.iter().copied().filter(|t| t.is_finite()).collect();
    if hit_ranges.is_empty() {
        return Err(Error::invalid(format!(
            "no ray of the scan from {:?} meets the mesh",
            params.from.to_array()
        )));
    }
    let mid = hit_ranges.len() / 2;
    let median_range = *hit_ranges.select_nth_unstable_by(mid, f32::total_cmp).1;
    let spacing = median_range * step;
    let sigma = match params.range_noise {
        RangeNoise::Absolute(s) => s,
        RangeNoise::Spacing(f) => f * spacing,
    };
    // Per-ray defects, from a generator seeded per ray (thread-independent).
    let samples: Vec<Option<(Vec3, u8)>> = ranges
        .par_iter()
        .enumerate()
        .with_min_len(1024)
        .map(|(k, &t)| {
            if !t.is_finite() {
                return None;
            }
            let mut rng =
                SplitMix64::new(params.seed ^ (k as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
            if rng.next_f32() < params.missing {
                return Some((Vec3::ZERO, 1));
            }
            let dir = dir_of(k % cols, k / cols);
            if rng.next_f32() < params.outliers {
                let r = t * rng.range(0.5, 1.5);
                return Some((from + dir * r, 2));
            }
            let r = t + (rng.next_gaussian() as f32) * sigma;
            Some((from + dir * r, 0))
        })
        .collect();
    let mut scan = Scan {
        cloud: PointCloud {
            viewpoint: Some(from),
            origin: mesh.origin,
            ..PointCloud::default()
        },
        rays: rows * cols,
        returns: hit_ranges.len(),
        missing: 0,
        outliers: 0,
        spacing,
        noise_sigma: sigma,
        grid: Vec::with_capacity(rows * cols),
        columns: cols,
        rows,
        axes: [forward, right, up],
        pinhole,
    };
    for sample in samples {
        let point = match sample {
            None => None,
            Some((_, 1)) => {
                scan.missing += 1;
                None
            }
            Some((p, kind)) => {
                scan.outliers += usize::from(kind == 2);
                scan.cloud.positions.push(p);
                Some(p)
            }
        };
        scan.grid.push(point);
    }
    if scan.cloud.is_empty() {
        return Err(Error::invalid("every return of the scan went missing"));
    }
    let misses = grid_misses(&scan.grid, cols, rows);
    scan.cloud.misses = Some(
        misses
            .into_iter()
            .map(|k| dir_of(k % cols, k / cols))
            .collect(),
    );
    Ok(scan)
}

/// Scans `mesh` from each of `stations` with `params`' other settings
/// (station `k`'s seed is `params.seed + k`, so the first station's scan is
/// `scan_mesh`'s) and joins them ([`join_scans`]): one station gives its
/// scan's cloud as it is (its viewpoint and misses); several give one cloud
/// of several scans ([`crate::splat::Scans`], each point with its own
/// scanner, as an E57 survey's), each scan's misses kept with it
/// ([`crate::splat::Scans::misses`]).
///
/// # Errors
/// No station, more than `u16` indexes, or a station's [`scan_mesh`]
/// error (naming the station when there are several).
pub fn scan_stations(mesh: &Mesh, params: &ScanParams, stations: &[DVec3]) -> Result<PointCloud> {
    Ok(join_scans(mesh.origin, &scan_each(mesh, params, stations)?))
}

/// The scans of [`scan_stations`], one per station, each with its counts.
///
/// # Errors
/// As [`scan_stations`].
pub fn scan_each(mesh: &Mesh, params: &ScanParams, stations: &[DVec3]) -> Result<Vec<Scan>> {
    if stations.is_empty() {
        return Err(Error::invalid("a scan needs at least one station"));
    }
    if stations.len() > usize::from(u16::MAX) + 1 {
        return Err(Error::invalid(format!(
            "{} scan stations is more than the {} a cloud indexes",
            stations.len(),
            usize::from(u16::MAX) + 1
        )));
    }
    let several = stations.len() > 1;
    stations
        .iter()
        .enumerate()
        .map(|(k, &from)| {
            let p = ScanParams {
                from,
                seed: params.seed.wrapping_add(k as u64),
                ..params.clone()
            };
            scan_mesh(mesh, &p).map_err(|e| {
                if several {
                    e.context(format!(
                        "station {} of {} at {:?}",
                        k + 1,
                        stations.len(),
                        from.to_array()
                    ))
                } else {
                    e
                }
            })
        })
        .collect()
}

/// One cloud of `scans` (of a mesh whose origin is `origin`): one scan's
/// cloud as it is; several scans' points and misses each kept with their
/// scanner ([`crate::splat::Scans`]).
///
/// # Panics
/// When `scans` is empty or holds more than `u16` indexes.
#[must_use]
pub fn join_scans(origin: DVec3, scans: &[Scan]) -> PointCloud {
    assert!(
        !scans.is_empty() && scans.len() <= usize::from(u16::MAX) + 1,
        "join_scans takes 1 to 65536 scans"
    );
    if let [one] = scans {
        return one.cloud.clone();
    }
    let mut cloud = PointCloud {
        origin,
        ..PointCloud::default()
    };
    let mut joined = crate::splat::Scans::default();
    for (k, scan) in scans.iter().enumerate() {
        let n = scan.cloud.len();
        let misses = scan.cloud.misses.as_deref().unwrap_or_default();
        joined
            .misses_of
            .extend(std::iter::repeat_n(k as u16, misses.len()));
        joined.misses.extend_from_slice(misses);
        cloud.positions.extend_from_slice(&scan.cloud.positions);
        // (`scan_mesh` always sets the viewpoint.)
        joined
            .positions
            .push(scan.cloud.viewpoint.unwrap_or_default());
        joined.of.extend(std::iter::repeat_n(k as u16, n));
    }
    cloud.scans = Some(joined);
    cloud
}
