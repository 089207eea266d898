//! E57 (ASTM E2807, what terrestrial scanners export) through the `e57`
//! crate: every scan's points placed by its pose (rotation and
//! translation, in f64; spherical coordinates converted first), and each
//! scan's position, its pose's translation, kept as the viewpoint of its
//! points: one scan (or scans taken from one place) gives
//! [`PointCloud::viewpoint`], several give [`PointCloud::scans`].
//!
//! Points flagged invalid are skipped and counted; a point that holds only
//! a direction (`cartesianInvalidState` 1: the scanner's ray met nothing)
//! is a miss of its scan ([`PointCloud::misses`], [`Scans::misses`]).
//! Colours (normalised by the file's colour limits) are sRGB, made linear,
//! and kept when every scan has them. A panic inside the decoder becomes
//! an error.
//!
//! [`encode`] writes a cloud back: one scan per scanner, its points
//! relative to it and its position as the pose's translation, its misses
//! as direction-only points (what `splatray sample --scan-from` writes for
//! several stations).

use super::batch::{BATCH, PointBatch, StreamInfo};
use super::{IoErrorKind, PointCloud, cloud_from_world, srgb_to_linear};
use crate::data::Scans;
use e57::{CartesianCoordinate, E57Reader, E57Writer, Record, RecordValue};
use glam::{DQuat, DVec3, Vec3};
use std::io::{Cursor, Read, Seek};
use std::path::Path;

/// The first bytes of every E57 file.
pub(crate) const MAGIC: &[u8] = b"ASTM-E57";

/// The bytes per point held while reading (f64 position, f32 colour, scan
/// index), for the memory check.
const BYTES_PER_POINT: u64 = 24 + 12 + 2;

/// Read an E57 file's scans as one cloud.
pub(crate) fn read_cloud(bytes: &[u8]) -> Result<PointCloud, IoErrorKind> {
    std::panic::catch_unwind(|| read(bytes)).unwrap_or_else(|_| {
        Err(IoErrorKind::Data(
            "the E57 decoder failed on this file (corrupt data)".into(),
        ))
    })
}

fn e57_error(e: &e57::Error) -> IoErrorKind {
    // The crate's messages can run over lines.
    let text = e
        .to_string()
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ");
    IoErrorKind::Data(format!("E57: {text}"))
}

fn read(bytes: &[u8]) -> Result<PointCloud, IoErrorKind> {
    if !bytes.starts_with(MAGIC) {
        return Err(IoErrorKind::Header(
            "an E57 file must start with \"ASTM-E57\"".into(),
        ));
    }
    let mut reader = E57Reader::new(Cursor::new(bytes)).map_err(|e| e57_error(&e))?;
    let (scans, claimed) = checked_scans(&reader, bytes.len() as u64)?;
    crate::memory::check(
        &format!("reading {claimed} points"),
        claimed.saturating_mul(BYTES_PER_POINT),
    )
    .map_err(IoErrorKind::Memory)?;
    let colored = scans.iter().all(e57::PointCloud::has_color);
    let mut taken = Taken::default();
    let mut positions: Vec<DVec3> = Vec::with_capacity(scans.len());
    let (mut invalid, mut non_finite) = (0usize, 0usize);
    let (mut misses, mut misses_of) = (Vec::new(), Vec::new());
    for (k, scan) in scans.iter().enumerate() {
        positions.push(scan_position(k, scan)?);
        let turn = scan_rotation(scan);
        let mut points = reader.pointcloud_simple(scan).map_err(|e| e57_error(&e))?;
        points.intensity_to_color(false);
        for p in points {
            match taken.take(k, &p.map_err(|e| e57_error(&e))?, colored) {
                Ok(()) => {}
                Err(Skipped::Invalid) => invalid += 1,
                Err(Skipped::NonFinite) => non_finite += 1,
                Err(Skipped::Miss(d)) => {
                    misses.push((turn * d).as_vec3());
                    misses_of.push(k as u16);
                }
            }
        }
    }
    let Taken {
        world,
        colors,
        scan_of,
    } = taken;
    let mut cloud = cloud_from_world(world, None, colored.then_some(colors))?;
    cloud.add_skipped("flagged invalid in the E57 file", invalid);
    cloud.add_skipped("non-finite coordinates", non_finite);
    let local: Vec<Vec3> = positions
        .iter()
        .map(|&p| cloud.local_viewpoint(p))
        .collect();
    if local.iter().all(|p| *p == local[0]) {
        cloud.viewpoint = Some(local[0]);
        cloud.misses = (!misses.is_empty()).then_some(misses);
    } else {
        cloud.scans = Some(Scans {
            positions: local,
            of: scan_of,
            misses,
            misses_of,
        });
    }
    Ok(cloud)
}

/// The rotation of scan `k`'s pose (identity without one), which turns its
/// misses' directions into the file's frame (the crate places points by
/// the pose, directions not).
fn scan_rotation(scan: &e57::PointCloud) -> DQuat {
    scan.transform
        .as_ref()
        .map(|t| {
            let q = &t.rotation;
            DQuat::from_xyzw(q.x, q.y, q.z, q.w)
        })
        .filter(|q| q.is_finite() && q.length_squared() > 0.5)
        .map_or(DQuat::IDENTITY, DQuat::normalize)
}

/// `cloud` as an E57 file: one scan per scanner (each of [`Scans`], or
/// the cloud's viewpoint), its points as
/// f64 offsets from its position and that position as its pose's
/// translation, 8-bit sRGB colour when the cloud has colour, and its
/// misses as direction-only points (`cartesianInvalidState` 1), which
/// [`read_cloud`] reads back as misses.
///
/// # Errors
/// A cloud with normals (E57 has no field for them) or without a scanner
/// (no viewpoint, no scans), or the writer's error.
pub(crate) fn encode(cloud: &PointCloud) -> Result<Vec<u8>, IoErrorKind> {
    if cloud.normals.is_some() {
        return Err(IoErrorKind::Data(
            "an E57 file holds no normals: write a .ply or .pcd".into(),
        ));
    }
    let n = cloud.len();
    let colors = cloud.colors.as_ref().filter(|c| c.len() == n);
    // (position in the file's frame, points, misses) per scan.
    let mut scans: Vec<(DVec3, Vec<usize>, Vec<Vec3>)> = match (&cloud.scans, cloud.viewpoint) {
        (Some(s), _) => s
            .positions
            .iter()
            .map(|p| (cloud.origin + p.as_dvec3(), Vec::new(), Vec::new()))
            .collect(),
        (None, Some(v)) => vec![(
            cloud.origin + v.as_dvec3(),
            Vec::new(),
            cloud.misses.clone().unwrap_or_default(),
        )],
        // (A reader takes a scan's pose as where its scanner stood.)
        (None, None) => {
            return Err(IoErrorKind::Data(
                "an E57 scan is placed at its scanner and this cloud has no viewpoint: \
                 write a .ply or .pcd"
                    .into(),
            ));
        }
    };
    let last = scans.len() - 1;
    match &cloud.scans {
        Some(s) => {
            for (i, &k) in s.of.iter().enumerate().take(n) {
                scans[usize::from(k).min(last)].1.push(i);
            }
            for (d, &k) in s.misses.iter().zip(&s.misses_of) {
                scans[usize::from(k).min(last)].2.push(*d);
            }
        }
        None => scans[0].1.extend(0..n),
    }
    let e = |e: e57::Error| e57_error(&e);
    let mut bytes = Cursor::new(Vec::new());
    let mut w = E57Writer::new(&mut bytes, "splatray-e57").map_err(e)?;
    for (k, (at, points, misses)) in scans.iter().enumerate() {
        let mut proto = vec![
            Record::CARTESIAN_X_F64,
            Record::CARTESIAN_Y_F64,
            Record::CARTESIAN_Z_F64,
            Record::CARTESIAN_INVALID_STATE,
        ];
        if colors.is_some() {
            proto.extend([
                Record::COLOR_RED_U8,
                Record::COLOR_GREEN_U8,
                Record::COLOR_BLUE_U8,
            ]);
        }
        let mut pc = w
            .add_pointcloud(&format!("splatray-e57-scan-{k}"), proto)
            .map_err(e)?;
        pc.set_transform(Some(e57::Transform {
            rotation: e57::Quaternion {
                w: 1.0,
                x: 0.0,
                y: 0.0,
                z: 0.0,
            },
            translation: e57::Translation {
                x: at.x,
                y: at.y,
                z: at.z,
            },
        }));
        let record = |p: DVec3, state: i64, rgb: Vec3| {
            let mut v = vec![
                RecordValue::Double(p.x),
                RecordValue::Double(p.y),
                RecordValue::Double(p.z),
                RecordValue::Integer(state),
            ];
            if colors.is_some() {
                v.extend(
                    rgb.to_array()
                        .map(|c| RecordValue::Integer(i64::from(super::linear_to_srgb8(c)))),
                );
            }
            v
        };
        for &i in points {
            let rgb = colors.map_or(Vec3::ZERO, |c| c[i]);
            pc.add_point(record(cloud.world(i) - *at, 0, rgb))
                .map_err(e)?;
        }
        for d in misses {
            pc.add_point(record(d.as_dvec3(), 1, Vec3::ZERO))
                .map_err(e)?;
        }
        pc.finalize().map_err(e)?;
    }
    w.finalize().map_err(e)?;
    drop(w);
    Ok(bytes.into_inner())
}

/// The scans of an E57 file, checked: at least one, at most what a `u16`
/// counts, and no more points claimed than `file_bytes` can hold (each
/// record takes at least one bit). With the points they claim.
fn checked_scans<T: Read + Seek>(
    reader: &E57Reader<T>,
    file_bytes: u64,
) -> Result<(Vec<e57::PointCloud>, u64), IoErrorKind> {
    let scans = reader.pointclouds();
    if scans.is_empty() {
        return Err(IoErrorKind::NoPoints("the E57 file holds no scans".into()));
    }
    if scans.len() > usize::from(u16::MAX) {
        return Err(IoErrorKind::Data(format!(
            "{} scans, more than the {} one cloud holds",
            scans.len(),
            u16::MAX
        )));
    }
    let claimed: u64 = scans.iter().map(|s| s.records).sum();
    if claimed > 8 * file_bytes {
        return Err(IoErrorKind::Data(format!(
            "the scans claim {claimed} points, more than the file's {file_bytes} bytes can hold"
        )));
    }
    Ok((scans, claimed))
}

/// Where scan `k` was taken from: its pose's translation.
fn scan_position(k: usize, scan: &e57::PointCloud) -> Result<DVec3, IoErrorKind> {
    let at = scan.transform.as_ref().map_or(DVec3::ZERO, |t| {
        DVec3::new(t.translation.x, t.translation.y, t.translation.z)
    });
    if at.is_finite() {
        Ok(at)
    } else {
        Err(IoErrorKind::Data(format!(
            "scan {k}: its pose's translation {at} is not finite"
        )))
    }
}

/// Streams an E57 file from disk, a batch of at most [`BATCH`] points at a
/// time, each with its scan (when there are several) and colour (when every
/// scan has one): what [`read_cloud`] reads, in constant memory. A panic
/// inside the decoder becomes an error.
pub(crate) fn stream(
    path: &Path,
    each: &mut dyn FnMut(&PointBatch<'_>) -> Result<(), String>,
) -> Result<StreamInfo, IoErrorKind> {
    let each = std::panic::AssertUnwindSafe(each);
    std::panic::catch_unwind(move || {
        let each = each;
        stream_inner(path, each.0)
    })
    .unwrap_or_else(|_| {
        Err(IoErrorKind::Data(
            "the E57 decoder failed on this file (corrupt data)".into(),
        ))
    })
}

fn stream_inner(
    path: &Path,
    each: &mut dyn FnMut(&PointBatch<'_>) -> Result<(), String>,
) -> Result<StreamInfo, IoErrorKind> {
    let io = IoErrorKind::Io;
    let file_bytes = std::fs::metadata(path).map_err(io)?.len();
    let mut head = [0u8; 8];
    std::fs::File::open(path)
        .and_then(|mut f| f.read_exact(&mut head))
        .map_err(io)?;
    if !head.starts_with(MAGIC) {
        return Err(IoErrorKind::Header(
            "an E57 file must start with \"ASTM-E57\"".into(),
        ));
    }
    let mut reader = E57Reader::from_file(path).map_err(|e| e57_error(&e))?;
    let (scans, _) = checked_scans(&reader, file_bytes)?;
    let colored = scans.iter().all(e57::PointCloud::has_color);
    let positions = scans
        .iter()
        .enumerate()
        .map(|(k, s)| scan_position(k, s))
        .collect::<Result<Vec<_>, _>>()?;
    let several = positions.iter().any(|p| *p != positions[0]);
    let mut info = StreamInfo {
        viewpoint: Some(positions[0]),
        scans: if several { positions } else { Vec::new() },
        colors: colored,
        streamed: true,
        ..StreamInfo::default()
    };
    let mut batch = Taken {
        world: Vec::with_capacity(BATCH),
        colors: Vec::with_capacity(BATCH),
        scan_of: Vec::with_capacity(BATCH),
    };
    let mut flush = |b: &mut Taken, info: &mut StreamInfo| -> Result<(), IoErrorKind> {
        if b.world.is_empty() {
            return Ok(());
        }
        each(&PointBatch {
            world: &b.world,
            normals: None,
            colors: colored.then_some(&b.colors[..]),
            scans: several.then_some(&b.scan_of[..]),
        })
        .map_err(IoErrorKind::Data)?;
        info.points += b.world.len() as u64;
        b.world.clear();
        b.colors.clear();
        b.scan_of.clear();
        Ok(())
    };
    for (k, scan) in scans.iter().enumerate() {
        let mut points = reader.pointcloud_simple(scan).map_err(|e| e57_error(&e))?;
        points.intensity_to_color(false);
        for p in points {
            match batch.take(k, &p.map_err(|e| e57_error(&e))?, colored) {
                Ok(()) if batch.world.len() == BATCH => flush(&mut batch, &mut info)?,
                // (Streaming, as tiled generation does, keeps no misses.)
                Ok(()) | Err(Skipped::Invalid | Skipped::Miss(_)) => {}
                Err(Skipped::NonFinite) => info.non_finite += 1,
            }
        }
    }
    flush(&mut batch, &mut info)?;
    Ok(info)
}

/// The points taken from the scans, in f64 world coordinates, each with
/// its scan and (when every scan has one) its colour: what [`read_cloud`]
/// reads whole and [`stream`] a batch at a time.
#[derive(Default)]
struct Taken {
    world: Vec<DVec3>,
    colors: Vec<Vec3>,
    scan_of: Vec<u16>,
}

/// Why a point of a scan was not taken.
enum Skipped {
    /// Flagged invalid in the file.
    Invalid,
    /// A coordinate is NaN or infinite.
    NonFinite,
    /// Only a direction: a ray of the scanner's that met nothing.
    Miss(DVec3),
}

impl Taken {
    /// Takes point `p` of scan `k` (its colour too when `colored`: sRGB
    /// made linear, grey where a point has none), or says why not.
    fn take(&mut self, k: usize, p: &e57::Point, colored: bool) -> Result<(), Skipped> {
        let (x, y, z) = match p.cartesian {
            CartesianCoordinate::Valid { x, y, z } => (x, y, z),
            CartesianCoordinate::Direction { x, y, z } => {
                let d = DVec3::new(x, y, z);
                return Err(match d.try_normalize() {
                    Some(d) => Skipped::Miss(d),
                    None => Skipped::NonFinite,
                });
            }
            CartesianCoordinate::Invalid => return Err(Skipped::Invalid),
        };
        let w = DVec3::new(x, y, z);
        if !w.is_finite() {
            return Err(Skipped::NonFinite);
        }
        self.world.push(w);
        self.scan_of.push(k as u16);
        if colored {
            self.colors
                .push(p.color.as_ref().map_or(Vec3::splat(0.2), |c| {
                    Vec3::new(c.red, c.green, c.blue).map(srgb_to_linear)
                }));
        }
        Ok(())
    }
}
