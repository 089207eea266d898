//! Points in, splats out: readers for PLY, PCD, XYZ, LAS/LAZ and E57 point clouds, a PLY
//! mesh reader and area-uniform mesh sampler, and the splat PLY format.
//!
//! Every reader is defensive: a header's counts are never trusted for
//! allocations (reservations are capped by the file's size), non-finite
//! coordinates are skipped and counted in [`PointCloud::skipped`], and every
//! failure is one [`IoError`] whose message is a single line naming the file.
//!
//! Coordinates are parsed in double precision (PLY `double` or `float`, PCD
//! `F 8` or `F 4`, text) and re-centred, still in double precision, on the
//! cloud's per-axis medians before they become single-precision offsets
//! from [`PointCloud::origin`] (`docs/DESIGN.md`, "Precision").

mod any;
mod atomic;
mod batch;
mod e57file;
mod error;
mod folder;
mod format;
mod gaussian;
mod las;
mod lzf;
mod organised;
mod pcd;
mod ply;
mod sample;
mod source;
mod splat_ply;
mod stream;
mod trimesh;
mod xyz;

pub use crate::data::PointCloud;
pub use any::{CloudRead, is_splat_ply, read_any};
pub use atomic::{Batch, write_atomic, write_bytes};
pub use batch::{PointBatch, StreamInfo};
pub use error::{IoError, IoErrorKind};
pub use folder::{cloud_files, read_folder};
pub use format::Format;
pub use gaussian::{
    EXPORT_OPACITY, GaussianLayout, GaussianRead, MIN_OPACITY, RADIUS_PER_SIGMA, SH_C0,
    encode_gaussians, file_layout, parse_gaussians, read_gaussians, sniff_layout, write_gaussians,
};
pub use lzf::{LzfError, lzf_decompress};
pub use organised::{Organised, Pinhole, grid_misses};
pub use pcd::{encode_organised, read_organised};
pub use sample::{MeshSampler, sample_mesh, write_sample_ply};
pub use source::{STDIN, Source, is_piped};
pub use splat_ply::{
    CLIP_PROPS, COLOR_FIELD_PROPS, SPLAT_ROW_BYTES, SplatSet, encode_splats, encode_splats_layout,
    encode_splats_with, parse_splats, read_splats, splat_header, splat_header_layout,
    splat_header_with, splat_row_bytes, write_splats,
};
pub use stream::stream_points;
pub use trimesh::{
    BYTES_PER_TRIANGLE, TriangleMesh, parse_triangles, parse_triangles_within, read_triangles,
    read_triangles_within,
};

use glam::{DVec3, Vec3};
use std::path::Path;

/// The reason points with a NaN or infinite coordinate are skipped for
/// ([`PointCloud::skipped`]).
pub(crate) const NON_FINITE: &str = "non-finite coordinates";

/// A triangle mesh.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Triangles as indices into `positions`; polygons are fan-triangulated.
    pub triangles: Vec<[u32; 3]>,
    /// The positions are offsets from this point (read in f64 and
    /// re-centred, as a point cloud's: [`PointCloud::origin`]).
    pub origin: DVec3,
}

/// The first 4 KiB of a file (to sniff its format), or `None` when it
/// cannot be read.
#[must_use]
pub fn file_head(path: &Path) -> Option<Vec<u8>> {
    use std::io::Read;
    let mut buf = Vec::with_capacity(4096);
    std::fs::File::open(path)
        .ok()?
        .take(4096)
        .read_to_end(&mut buf)
        .ok()?;
    Some(buf)
}

/// The scalar property names of the `vertex` element of a PLY header, from
/// a file's first bytes (which need not hold the whole header), or `None`
/// when they do not start a PLY file.
#[must_use]
pub fn vertex_property_names(head: &[u8]) -> Option<Vec<String>> {
    if !(head.starts_with(b"ply\n") || head.starts_with(b"ply\r\n")) {
        return None;
    }
    let text = String::from_utf8_lossy(head);
    let mut in_vertex = false;
    let mut found = Vec::new();
    for line in text.lines() {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["end_header", ..] => break,
            ["element", name, ..] => in_vertex = *name == "vertex",
            ["property", "list", ..] => {}
            ["property", _, name] if in_vertex => found.push((*name).to_string()),
            _ => {}
        }
    }
    Some(found)
}

/// Read the whole file, mapping failures to [`IoError`].
pub(crate) fn read_file(path: &Path) -> Result<Vec<u8>, IoError> {
    if let Ok(meta) = std::fs::metadata(path) {
        crate::memory::check("reading the file whole", meta.len())
            .map_err(|e| IoError::new(path, IoErrorKind::Memory(e)))?;
    }
    let bytes = read_whole(path).map_err(|e| IoError::new(path, IoErrorKind::Io(e)))?;
    if bytes.is_empty() {
        return Err(IoError::new(path, IoErrorKind::Empty));
    }
    Ok(bytes)
}

/// Below this many bytes a file is read on one thread.
const PARALLEL_READ_MIN: u64 = 16 << 20;

/// Pieces a large file is read in, one a thread at a time.
const READ_PIECE: usize = 8 << 20;

/// The file's bytes, as `std::fs::read` gives them. A large regular file
/// is read in pieces on every thread (positional reads into their places):
/// copying it out of the page cache and faulting its buffer's pages in
/// took one core 0.13 s for a 170 MB splat file.
fn read_whole(path: &Path) -> std::io::Result<Vec<u8>> {
    use std::io::Read;
    let mut file = std::fs::File::open(path)?;
    let mut bytes = Vec::new();
    #[cfg(unix)]
    {
        use rayon::prelude::*;
        use std::io::{Seek, SeekFrom};
        use std::os::unix::fs::FileExt;
        let meta = file.metadata()?;
        let len = meta.len();
        if let Ok(n) = usize::try_from(len)
            && meta.is_file()
            && len >= PARALLEL_READ_MIN
        {
            bytes = vec![0u8; n];
            bytes
                .par_chunks_mut(READ_PIECE)
                .enumerate()
                .try_for_each(|(i, piece)| file.read_exact_at(piece, (i * READ_PIECE) as u64))?;
            file.seek(SeekFrom::Start(len))?;
        }
    }
    // The whole file, or what it grew by since its pieces' length was read.
    file.read_to_end(&mut bytes)?;
    Ok(bytes)
}

/// Read a point cloud from a `.ply`, `.pcd`, `.xyz`, `.txt`, `.las`, `.laz` or `.e57` file; files
/// with another extension are recognised by their first bytes; a folder is
/// read as one cloud from its point files (`read_folder`).
///
/// Points with a NaN or infinite coordinate are skipped and counted in
/// [`PointCloud::skipped`]. The positions are offsets from the points'
/// per-axis medians, [`PointCloud::origin`], computed in f64.
///
/// # Errors
/// An `IoError` when the file cannot be read, is empty, has an unknown
/// format, a malformed header or body, holds no usable point, or its points
/// span more than single precision holds.
///
/// # Example
/// ```
/// // Three points far from zero and one NaN, as a text file.
/// let path = std::env::temp_dir().join(format!("doc-read-{}.xyz", std::process::id()));
/// std::fs::write(&path, "500000 10 2\n500001 10 2\n500000 11 2\nnan 0 0\n").unwrap();
/// let cloud = splatray::io::read_points(&path).unwrap();
/// assert_eq!(cloud.positions.len(), 3);
/// assert_eq!(cloud.skipped_total(), 1);
/// // The positions are f32 offsets from an f64 origin (the medians).
/// assert_eq!(cloud.origin.x, 500000.0);
/// std::fs::remove_file(&path).unwrap();
/// ```
pub fn read_points(path: &Path) -> Result<PointCloud, IoError> {
    if path.is_dir() {
        return read_folder(path);
    }
    let bytes = read_file(path)?;
    let format = Format::from_extension(path)
        .or_else(|| Format::sniff(&bytes[..bytes.len().min(4096)]))
        .ok_or_else(|| IoError::new(path, IoErrorKind::UnknownFormat))?;
    parse_points(&bytes, format).map_err(|kind| IoError::new(path, kind))
}

/// [`read_points`] on a file's bytes, in a known `format`.
///
/// # Errors
/// As [`read_points`], without the file's name.
pub fn parse_points(bytes: &[u8], format: Format) -> Result<PointCloud, IoErrorKind> {
    let cloud = format.read_cloud(bytes)?;
    if cloud.is_empty() {
        let why = if cloud.skipped.is_empty() {
            "the file holds no points".to_string()
        } else {
            let parts: Vec<String> = cloud
                .skipped
                .iter()
                .map(|(r, n)| format!("{n} skipped: {r}"))
                .collect();
            format!("no usable point ({})", parts.join(", "))
        };
        return Err(IoErrorKind::NoPoints(why));
    }
    Ok(cloud)
}

/// Read a triangle mesh from a PLY file with a `face` element
/// (`vertex_indices` or `vertex_index` lists); polygons are triangulated as
/// fans, faces with fewer than three vertices are dropped.
///
/// # Errors
/// An [`IoError`] when the file cannot be read or parsed, has no faces, a
/// face index out of range, or a non-finite vertex used by a face.
pub fn read_mesh(path: &Path) -> Result<Mesh, IoError> {
    let bytes = read_file(path)?;
    parse_mesh(&bytes).map_err(|kind| IoError::new(path, kind))
}

/// [`read_mesh`] on a file's bytes.
///
/// # Errors
/// As [`read_mesh`], without the file's name.
pub fn parse_mesh(bytes: &[u8]) -> Result<Mesh, IoErrorKind> {
    if Format::sniff(&bytes[..bytes.len().min(4096)]) != Some(Format::Ply) {
        return Err(IoErrorKind::Header(
            "a mesh must be a PLY file (it does not start with \"ply\")".into(),
        ));
    }
    ply::read_mesh(bytes)
}

/// [`parse_mesh`] with the vertex normals and each triangle's face.
pub(crate) fn parse_mesh_full(bytes: &[u8]) -> Result<ply::MeshRead, IoErrorKind> {
    if Format::sniff(&bytes[..bytes.len().min(4096)]) != Some(Format::Ply) {
        return Err(IoErrorKind::Header(
            "a mesh must be a PLY or OBJ file (it does not start with \"ply\")".into(),
        ));
    }
    ply::read_mesh_full(bytes)
}

/// Write a point cloud, atomically (a temporary file in the same folder,
/// then renamed): a `.pcd` path gets binary PCD with the cloud's
/// `VIEWPOINT` (see [`pcd::encode`]); a `.e57` path an E57 file of the
/// cloud's scans with their misses (`e57file::encode`; not a cloud with
/// normals); any other path binary little-endian PLY (`x y z`, plus `nx ny nz` and float `red green blue` when present).
/// Positions (and the viewpoint) are written in the file's coordinates,
/// `origin + positions[i]`: as `float` (PCD `F 4`) when the origin is zero,
/// else as `double` (`F 8`), so a far cloud keeps its precision.
///
/// # Errors
/// An [`IoError`] when the file cannot be written, or a position or the
/// origin is not finite.
pub fn write_points(path: &Path, cloud: &PointCloud) -> Result<(), IoError> {
    let n = cloud.len();
    if let Some(i) = (0..n).find(|&i| !cloud.world(i).is_finite()) {
        let what = format!("point {i} is not finite ({})", cloud.world(i));
        return Err(IoError::not_written(path, &what));
    }
    match Format::from_extension(path) {
        Some(Format::Pcd) => return write_bytes(path, &pcd::encode(cloud)),
        Some(Format::E57) => {
            let bytes = e57file::encode(cloud).map_err(|k| IoError::new(path, k))?;
            return write_bytes(path, &bytes);
        }
        _ => {}
    }
    let normals = cloud.normals.as_ref().filter(|v| v.len() == n);
    let colors = cloud.colors.as_ref().filter(|v| v.len() == n);
    let wide = cloud.origin != DVec3::ZERO;
    let header = ply_points_header(n, wide, normals.is_some(), colors.is_some());
    let per = if wide { 24 } else { 12 }
        + 12 * usize::from(normals.is_some())
        + 12 * usize::from(colors.is_some());
    let mut out = Vec::with_capacity(header.len() + n * per);
    out.extend_from_slice(header.as_bytes());
    encode_records(&mut out, cloud, wide, normals, colors);
    write_bytes(path, &out)
}

/// The header of a binary PLY of `n` points as [`write_points`] writes it:
/// positions as `double` when `wide` (a far cloud) else `float`, then
/// float normals and colours when present.
pub(crate) fn ply_points_header(n: usize, wide: bool, normals: bool, colors: bool) -> String {
    let coord = if wide { "double" } else { "float" };
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment written by splatray {}\nelement vertex {n}\nproperty {coord} x\nproperty {coord} y\nproperty {coord} z\n",
        env!("CARGO_PKG_VERSION")
    );
    if normals {
        header.push_str("property float nx\nproperty float ny\nproperty float nz\n");
    }
    if colors {
        header.push_str("property float red\nproperty float green\nproperty float blue\n");
    }
    header.push_str("end_header\n");
    header
}

/// Appends one little-endian record per point: the position (world f64
/// when `wide`, else the f32 offset), then the normal and the colour (f32)
/// when given. Shared by the PLY and PCD writers.
pub(crate) fn encode_records(
    out: &mut Vec<u8>,
    cloud: &PointCloud,
    wide: bool,
    normals: Option<&Vec<Vec3>>,
    colors: Option<&Vec<Vec3>>,
) {
    let put = |out: &mut Vec<u8>, v: Vec3| {
        for c in v.to_array() {
            out.extend_from_slice(&c.to_le_bytes());
        }
    };
    for i in 0..cloud.len() {
        if wide {
            for c in cloud.world(i).to_array() {
                out.extend_from_slice(&c.to_le_bytes());
            }
        } else {
            put(out, cloud.positions[i]);
        }
        if let Some(ns) = normals {
            put(out, ns[i]);
        }
        if let Some(cs) = colors {
            put(out, cs[i]);
        }
    }
}

/// A linear component as an 8-bit sRGB value (clamped to `[0, 1]`; NaN is
/// 0).
#[must_use]
pub fn linear_to_srgb8(x: f32) -> u8 {
    (linear_to_srgb(x) * 255.0 + 0.5) as u8
}

/// A linear component sRGB-encoded, in `[0, 1]` (clamped; NaN is 0).
#[must_use]
pub fn linear_to_srgb(x: f32) -> f32 {
    let x = if x.is_finite() {
        x.clamp(0.0, 1.0)
    } else {
        0.0
    };
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// sRGB-encoded component in `[0, 1]` to linear.
#[must_use]
pub fn srgb_to_linear(c: f32) -> f32 {
    let c = c.clamp(0.0, 1.0);
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// A cloud from positions in the file's coordinates, in f64: points with a
/// non-finite coordinate are dropped (with their normals and colours) and
/// counted in `skipped`; the rest are re-centred, in f64, on their per-axis
/// medians (which a few far outliers do not move), which become the
/// cloud's origin, and only then made f32 (`docs/DESIGN.md`, "Precision").
///
/// `normals` and `colors`, when given, have one entry per position.
pub(crate) fn cloud_from_world(
    world: Vec<DVec3>,
    normals: Option<Vec<Vec3>>,
    colors: Option<Vec<Vec3>>,
) -> Result<PointCloud, IoErrorKind> {
    let keep: Vec<bool> = world.iter().map(|p| p.is_finite()).collect();
    let dropped = keep.iter().filter(|k| !**k).count();
    fn kept<T: Copy>(v: &[T], keep: &[bool]) -> Vec<T> {
        v.iter()
            .zip(keep)
            .filter(|(_, k)| **k)
            .map(|(x, _)| *x)
            .collect()
    }
    let (world, normals, colors) = if dropped == 0 {
        (world, normals, colors)
    } else {
        (
            kept(&world, &keep),
            normals.map(|n| kept(&n, &keep)),
            colors.map(|c| kept(&c, &keep)),
        )
    };
    let origin = crate::data::robust_centre_size(world.len(), |i| world[i])
        .map_or(DVec3::ZERO, |(centre, _)| centre);
    let positions: Vec<Vec3> = world.iter().map(|p| (*p - origin).as_vec3()).collect();
    if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
        return Err(IoErrorKind::Data(format!(
            "a point lies {:e} units from the cloud's median, more than single precision holds ({:e})",
            (world[i] - origin).abs().max_element(),
            f32::MAX
        )));
    }
    let mut cloud = PointCloud {
        positions,
        origin,
        normals,
        colors,
        ..PointCloud::default()
    };
    cloud.add_skipped(NON_FINITE, dropped);
    Ok(cloud)
}

/// Write a text file atomically (see [`write_atomic`]).
///
/// # Errors
/// An [`IoError`] when the file cannot be written.
pub fn write_text(path: &Path, text: &str) -> Result<(), IoError> {
    write_bytes(path, text.as_bytes())
}

#[cfg(test)]
mod tests {
    /// A file past the parallel read's size reads, in its pieces, as
    /// `std::fs::read` gives it (an odd length: the last piece short),
    /// and so does a small one.
    #[test]
    fn a_large_file_reads_whole_in_pieces() {
        let dir = std::env::temp_dir().join(format!("splatray-read-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for len in [super::PARALLEL_READ_MIN as usize + 3 * super::READ_PIECE + 12_345, 1_000] {
            let mut x = 0x9e37_79b9_7f4a_7c15u64;
            let bytes: Vec<u8> = (0..len)
                .map(|_| {
                    x ^= x << 13;
                    x ^= x >> 7;
                    x ^= x << 17;
                    x as u8
                })
                .collect();
            let path = dir.join(format!("f{len}.bin"));
            std::fs::write(&path, &bytes).unwrap();
            let read = super::read_file(&path).unwrap();
            assert!(read == bytes, "{len} bytes read differ");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
