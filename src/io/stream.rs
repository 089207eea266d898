//! Point clouds read a batch at a time, for work that must not hold a whole
//! cloud in memory (tiled splat generation). A binary little-endian PLY
//! whose vertex element comes first with scalar properties, as `sample`
//! and most converters write it, is streamed from disk, and so are LAS/LAZ
//! and E57 files; any other file is read whole by [`super::read_points`]
//! (checked against the memory this process may use) and handed out in
//! batches from there.

use super::batch::{BATCH, PointBatch, StreamInfo};
use super::{Format, IoError, IoErrorKind, read_points};
use std::path::Path;

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
    let format = Format::from_extension(path)
        .or_else(|| super::file_head(path).and_then(|h| Format::sniff(&h)));
    if let Some(format) = format
        && let Some(info) = format.stream(path, &mut each).map_err(err)?
    {
        return Ok(info);
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
