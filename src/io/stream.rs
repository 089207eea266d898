//! Point clouds read a batch at a time, for work that must not hold a whole
//! cloud in memory (tiled splat generation). A binary little-endian PLY
//! whose vertex element comes first with scalar properties, as `sample`
//! and most converters write it, is streamed from disk, and so are LAS/LAZ
//! and E57 files; any other file is read whole by [`super::read_points`]
//! (checked against the memory this process may use) and handed out in
//! batches from there.

use super::{Format, IoError, IoErrorKind, read_points, srgb_to_linear};
use glam::{DVec3, Vec3};
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

/// Points handed to the consumer at once.
pub const BATCH: usize = 1 << 16;

/// One batch: positions in the file's coordinates (f64), and normals and
/// linear colours when the file has them, one per position.
pub struct PointBatch<'a> {
    /// Positions, in the file's coordinates; non-finite ones are left out
    /// before the batch is made (and counted in [`StreamInfo::non_finite`]).
    pub world: &'a [DVec3],
    /// Normals as stored, when the file has them.
    pub normals: Option<&'a [Vec3]>,
    /// Linear RGB colours in `[0, 1]`, when the file has them.
    pub colors: Option<&'a [Vec3]>,
    /// Per point, its scan in [`StreamInfo::scans`], when the file holds
    /// several scans.
    pub scans: Option<&'a [u16]>,
}

/// What a stream held.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StreamInfo {
    /// Finite points handed out.
    pub points: u64,
    /// Points left out for a non-finite coordinate.
    pub non_finite: u64,
    /// Whether batches carried normals, and colours.
    pub normals: bool,
    /// See `normals`.
    pub colors: bool,
    /// Where the scanner stood (a PCD's `VIEWPOINT`), in the file's
    /// coordinates; the first scan's position for a file of several.
    pub viewpoint: Option<DVec3>,
    /// Where each scan of a file of several scans (E57) was taken from, in
    /// the file's coordinates; empty for other files.
    pub scans: Vec<DVec3>,
    /// True when the file was streamed from disk; false when it was read
    /// whole first.
    pub streamed: bool,
}

/// Reads the points of `path` a batch at a time into `each`.
///
/// # Errors
/// An [`IoError`] as [`super::read_points`] gives it, a file that ends
/// before its header's count, or `each`'s error (as a data error).
pub fn stream_points(
    path: &Path,
    mut each: impl FnMut(&PointBatch<'_>) -> Result<(), String>,
) -> Result<StreamInfo, IoError> {
    let err = |k: IoErrorKind| IoError::new(path, k);
    if let Some(layout) = binary_ply_layout(path).map_err(err)? {
        return stream_binary_ply(path, &layout, &mut each).map_err(err);
    }
    if is_las(path) {
        return stream_las(path, &mut each).map_err(err);
    }
    if is_e57(path) {
        return super::e57file::stream(path, &mut each).map_err(err);
    }
    let cloud = read_points(path)?;
    let mut info = StreamInfo {
        scans: cloud.scans.as_ref().map_or_else(Vec::new, |s| {
            s.positions
                .iter()
                .map(|v| cloud.origin + v.as_dvec3())
                .collect()
        }),
        normals: cloud.normals.is_some(),
        colors: cloud.colors.is_some(),
        viewpoint: cloud
            .viewpoint
            .map(|v| cloud.origin + v.as_dvec3())
            .or_else(|| {
                cloud
                    .scans
                    .as_ref()
                    .and_then(|s| s.positions.first())
                    .map(|v| cloud.origin + v.as_dvec3())
            }),
        non_finite: cloud
            .skipped
            .iter()
            .filter(|(r, _)| r == super::NON_FINITE || r == super::pcd::EMPTY_PIXELS)
            .map(|(_, c)| *c as u64)
            .sum(),
        ..StreamInfo::default()
    };
    let mut world = Vec::with_capacity(BATCH);
    for start in (0..cloud.len()).step_by(BATCH) {
        let end = (start + BATCH).min(cloud.len());
        world.clear();
        world.extend(
            cloud.positions[start..end]
                .iter()
                .map(|p| cloud.origin + p.as_dvec3()),
        );
        each(&PointBatch {
            world: &world,
            normals: cloud.normals.as_ref().map(|n| &n[start..end]),
            colors: cloud.colors.as_ref().map(|c| &c[start..end]),
            scans: cloud.scans.as_ref().map(|s| &s.of[start..end]),
        })
        .map_err(|e| err(IoErrorKind::Data(e)))?;
        info.points += (end - start) as u64;
    }
    Ok(info)
}

/// A LAS or LAZ file, by its extension or its first bytes.
fn is_las(path: &Path) -> bool {
    is_format(path, Format::Las)
}

/// An E57 file, by its extension or its first bytes.
fn is_e57(path: &Path) -> bool {
    is_format(path, Format::E57)
}

fn is_format(path: &Path, format: Format) -> bool {
    let sniffed = || {
        let mut head = [0u8; 8];
        std::fs::File::open(path)
            .and_then(|mut f| f.read_exact(&mut head))
            .is_ok()
            && Format::sniff(&head) == Some(format)
    };
    match Format::from_extension(path) {
        Some(f) => f == format,
        None => sniffed(),
    }
}

/// A LAS or LAZ file streamed from disk (`las::stream_file`): its points
/// in batches of at most [`BATCH`], non-finite ones left out and counted.
fn stream_las(
    path: &Path,
    each: &mut impl FnMut(&PointBatch<'_>) -> Result<(), String>,
) -> Result<StreamInfo, IoErrorKind> {
    let mut info = StreamInfo {
        streamed: true,
        ..StreamInfo::default()
    };
    let mut world: Vec<DVec3> = Vec::with_capacity(BATCH);
    let mut colors: Vec<Vec3> = Vec::with_capacity(BATCH);
    let (_, with_color) = super::las::stream_file(path, &mut |(w, c)| {
        for start in (0..w.len()).step_by(BATCH) {
            let end = (start + BATCH).min(w.len());
            world.clear();
            colors.clear();
            for i in start..end {
                if !w[i].is_finite() {
                    info.non_finite += 1;
                    continue;
                }
                world.push(w[i]);
                if let Some(c) = c {
                    colors.push(c[i]);
                }
            }
            info.points += world.len() as u64;
            each(&PointBatch {
                world: &world,
                normals: None,
                colors: c.is_some().then_some(&colors[..]),
                scans: None,
            })?;
        }
        Ok(())
    })?;
    info.colors = with_color;
    Ok(info)
}

/// A scalar type of a binary little-endian PLY.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }
    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
    fn read(self, b: &[u8]) -> f64 {
        let a = |n: usize| -> [u8; 8] {
            let mut x = [0u8; 8];
            x[..n].copy_from_slice(&b[..n]);
            x
        };
        match self {
            Scalar::I8 => f64::from(b[0] as i8),
            Scalar::U8 => f64::from(b[0]),
            Scalar::I16 => f64::from(i16::from_le_bytes([b[0], b[1]])),
            Scalar::U16 => f64::from(u16::from_le_bytes([b[0], b[1]])),
            Scalar::I32 => f64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Scalar::U32 => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Scalar::F32 => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Scalar::F64 => f64::from_le_bytes(a(8)),
        }
    }
    /// A colour value normalised to `[0, 1]` as the whole-file reader does.
    fn unit(self, b: &[u8]) -> f64 {
        match self {
            Scalar::U16 => self.read(b) / 65535.0,
            Scalar::F32 | Scalar::F64 => self.read(b),
            _ => self.read(b) / 255.0,
        }
    }
}

/// Where a binary PLY's vertex fields lie.
struct PlyLayout {
    header_bytes: u64,
    count: u64,
    record: usize,
    /// (offset, type) of x, y, z.
    xyz: [(usize, Scalar); 3],
    normal: Option<[(usize, Scalar); 3]>,
    color: Option<[(usize, Scalar); 3]>,
}

/// The layout of `path` when it is a binary little-endian PLY whose first
/// element is `vertex` with scalar `x y z` (and maybe normals and colours),
/// `None` for any other file (read whole instead).
fn binary_ply_layout(path: &Path) -> Result<Option<PlyLayout>, IoErrorKind> {
    let sniffed = super::file_head(path).and_then(|h| Format::sniff(&h));
    if sniffed != Some(Format::Ply) {
        return Ok(None);
    }
    let file = std::fs::File::open(path).map_err(IoErrorKind::Io)?;
    let mut r = BufReader::new(file.take(1 << 20));
    let mut header_bytes = 0u64;
    let mut line = String::new();
    let mut binary_le = false;
    let mut count = None;
    let mut props: Vec<(String, Scalar)> = Vec::new();
    let mut in_vertex = false;
    let mut seen_element = false;
    loop {
        line.clear();
        let n = r.read_line(&mut line).map_err(IoErrorKind::Io)?;
        if n == 0 {
            return Ok(None);
        }
        header_bytes += n as u64;
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["end_header"] => break,
            ["format", f, _] => binary_le = *f == "binary_little_endian",
            ["element", name, c] => {
                if !seen_element {
                    seen_element = true;
                    in_vertex = *name == "vertex";
                    count = c.parse::<u64>().ok();
                } else {
                    in_vertex = false;
                }
            }
            ["property", "list", ..] if in_vertex => return Ok(None),
            ["property", t, name] if in_vertex => match Scalar::parse(t) {
                Some(s) => props.push(((*name).to_string(), s)),
                None => return Ok(None),
            },
            _ => {}
        }
    }
    let (Some(count), true) = (count, binary_le) else {
        return Ok(None);
    };
    let mut offset = 0;
    let mut at = std::collections::HashMap::new();
    for (name, s) in &props {
        at.insert(name.as_str(), (offset, *s));
        offset += s.size();
    }
    let find = |names: [&str; 3]| -> Option<[(usize, Scalar); 3]> {
        Some([*at.get(names[0])?, *at.get(names[1])?, *at.get(names[2])?])
    };
    let Some(xyz) = find(["x", "y", "z"]) else {
        return Ok(None);
    };
    let color = find(["red", "green", "blue"])
        .or_else(|| find(["r", "g", "b"]))
        .or_else(|| find(["diffuse_red", "diffuse_green", "diffuse_blue"]));
    Ok(Some(PlyLayout {
        header_bytes,
        count,
        record: offset,
        xyz,
        normal: find(["nx", "ny", "nz"]),
        color,
    }))
}

fn stream_binary_ply(
    path: &Path,
    l: &PlyLayout,
    each: &mut impl FnMut(&PointBatch<'_>) -> Result<(), String>,
) -> Result<StreamInfo, IoErrorKind> {
    let mut file =
        BufReader::with_capacity(1 << 22, std::fs::File::open(path).map_err(IoErrorKind::Io)?);
    std::io::copy(&mut (&mut file).take(l.header_bytes), &mut std::io::sink())
        .map_err(IoErrorKind::Io)?;
    let mut info = StreamInfo {
        normals: l.normal.is_some(),
        colors: l.color.is_some(),
        streamed: true,
        ..StreamInfo::default()
    };
    let mut buf = vec![0u8; l.record * BATCH];
    let (mut world, mut normals, mut colors) = (
        Vec::with_capacity(BATCH),
        Vec::with_capacity(BATCH),
        Vec::with_capacity(BATCH),
    );
    let mut left = l.count;
    while left > 0 {
        let take = left.min(BATCH as u64) as usize;
        let bytes = &mut buf[..take * l.record];
        file.read_exact(bytes).map_err(|e| {
            if e.kind() == std::io::ErrorKind::UnexpectedEof {
                IoErrorKind::Truncated(format!(
                    "the header promises {} points, the file ends within point {}",
                    l.count,
                    l.count - left + 1
                ))
            } else {
                IoErrorKind::Io(e)
            }
        })?;
        world.clear();
        normals.clear();
        colors.clear();
        for rec in bytes.chunks_exact(l.record) {
            let v = |f: [(usize, Scalar); 3]| f.map(|(o, s)| s.read(&rec[o..]));
            let p = DVec3::from(v(l.xyz));
            if !p.is_finite() {
                info.non_finite += 1;
                continue;
            }
            world.push(p);
            if let Some(n) = l.normal {
                normals.push(DVec3::from(v(n)).as_vec3());
            }
            if let Some(c) = l.color {
                let c = c.map(|(o, s)| {
                    let x = s.unit(&rec[o..]);
                    srgb_to_linear(if x.is_finite() { x as f32 } else { 0.0 })
                });
                colors.push(Vec3::from(c));
            }
        }
        each(&PointBatch {
            world: &world,
            normals: l.normal.map(|_| &normals[..]),
            colors: l.color.map(|_| &colors[..]),
            scans: None,
        })
        .map_err(IoErrorKind::Data)?;
        info.points += world.len() as u64;
        left -= take as u64;
    }
    Ok(info)
}
