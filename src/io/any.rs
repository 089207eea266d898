//! A cloud file of any kind — points, a splat file from `splatray splat`,
//! or a Gaussian splat file — read whole, once, its kind told from its
//! extension and first bytes (what a point cloud given alone to `render`
//! is read by: `scene::cloud`).

use super::{
    Format, GaussianRead, IoError, Organised, PointCloud, SplatSet, parse_gaussians, parse_points,
    parse_splats, read_file, read_organised, sniff_layout, vertex_property_names,
};
use std::path::Path;

/// A cloud file as [`read_any`] read it.
#[derive(Debug)]
pub enum CloudRead {
    /// A point cloud.
    Points(PointCloud),
    /// A splat file.
    Splats(SplatSet),
    /// A Gaussian splat file (read with the default opacity threshold,
    /// [`super::MIN_OPACITY`]).
    Gaussians(GaussianRead),
}

/// Reads the file at `path` once: a PLY (by extension or first bytes) with
/// a Gaussian layout is a Gaussian splat file, one with the splat
/// properties a splat file ([`is_splat_ply`]); anything else is read as
/// points ([`super::read_points`]). A PCD's organised grid (`HEIGHT` > 1)
/// is parsed from the same bytes and given beside it. A folder is read as
/// one cloud from its point files ([`super::read_folder`]).
///
/// # Errors
/// The reader's [`IoError`], naming the file.
pub fn read_any(path: &Path) -> Result<(CloudRead, Option<Organised>), IoError> {
    if path.is_dir() {
        return Ok((CloudRead::Points(super::read_folder(path)?), None));
    }
    let bytes = read_file(path)?;
    let first = &bytes[..bytes.len().min(4096)];
    let named = Format::from_extension(path);
    let sniffed = Format::sniff(first);
    let at = |k| IoError::new(path, k);
    if named == Some(Format::Ply) || sniffed == Some(Format::Ply) {
        if sniff_layout(first).is_some() {
            let read = parse_gaussians(&bytes, super::MIN_OPACITY).map_err(at)?;
            return Ok((CloudRead::Gaussians(read), None));
        }
        if splat_ply_head(first) {
            let read = parse_splats(&bytes).map_err(at)?;
            return Ok((CloudRead::Splats(read), None));
        }
    }
    let format = named
        .or(sniffed)
        .ok_or_else(|| at(super::IoErrorKind::UnknownFormat))?;
    let cloud = parse_points(&bytes, format).map_err(at)?;
    let grid = if format == Format::Pcd || sniffed == Some(Format::Pcd) {
        read_organised(&bytes).map_err(at)?
    } else {
        None
    };
    Ok((CloudRead::Points(cloud), grid))
}

/// Whether a PLY file is a splat file: its `vertex` element has the
/// properties `read_splats` needs (`x y z nx ny nz radius`).
#[must_use]
pub fn is_splat_ply(path: &Path) -> bool {
    super::file_head(path).is_some_and(|h| splat_ply_head(&h))
}

/// [`is_splat_ply`] on a file's first bytes.
fn splat_ply_head(head: &[u8]) -> bool {
    let Some(found) = vertex_property_names(head) else {
        return false;
    };
    ["x", "y", "z", "nx", "ny", "nz", "radius"]
        .iter()
        .all(|p| found.iter().any(|f| f == p))
}
