//! A folder of point files (e.g. the LAZ tiles of a survey) read as one
//! cloud: what `splat DIR` takes in tiles, and `render DIR` (or a scene's
//! `points = "DIR"`) reads whole.

use super::{Format, IoError, IoErrorKind, PointCloud, cloud_from_world, read_points};
use glam::{DVec3, Vec3};
use std::path::{Path, PathBuf};

/// The point files of the folder `dir`, by name: the files whose extension
/// names a point format ([`Format::from_extension`]).
///
/// # Errors
/// An [`IoError`] naming the folder when it cannot be listed or holds no
/// point file.
pub fn cloud_files(dir: &Path) -> Result<Vec<PathBuf>, IoError> {
    let mut found: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| IoError::new(dir, IoErrorKind::Io(e)))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|f| f.is_file() && Format::from_extension(f).is_some())
        .collect();
    found.sort();
    if found.is_empty() {
        return Err(IoError::new(
            dir,
            IoErrorKind::NoPoints("no point cloud files in the folder".into()),
        ));
    }
    Ok(found)
}

/// The point files of `dir` ([`cloud_files`]) read as one cloud, in the
/// files' coordinates re-centred together: normals and colours kept when
/// every file has them, the points each file skipped counted, the
/// viewpoint kept when every file has the same one.
///
/// # Errors
/// As [`cloud_files`], or the first file that does not read.
pub fn read_folder(dir: &Path) -> Result<PointCloud, IoError> {
    let clouds = cloud_files(dir)?
        .iter()
        .map(|p| read_points(p))
        .collect::<Result<Vec<_>, _>>()?;
    let world: Vec<DVec3> = clouds
        .iter()
        .flat_map(|c| (0..c.len()).map(move |i| c.world(i)))
        .collect();
    let every = |f: fn(&PointCloud) -> Option<&Vec<Vec3>>| -> Option<Vec<Vec3>> {
        clouds
            .iter()
            .map(|c| f(c).filter(|v| v.len() == c.len()).cloned())
            .collect::<Option<Vec<_>>>()
            .map(|v| v.concat())
    };
    let normals = every(|c| c.normals.as_ref());
    let colors = every(|c| c.colors.as_ref());
    let mut cloud = cloud_from_world(world, normals, colors).map_err(|k| IoError::new(dir, k))?;
    for c in &clouds {
        for (reason, n) in &c.skipped {
            cloud.add_skipped(reason, *n);
        }
    }
    let viewpoints: Vec<Option<DVec3>> = clouds
        .iter()
        .map(|c| c.viewpoint.map(|v| c.origin + v.as_dvec3()))
        .collect();
    if let Some(Some(v)) = viewpoints
        .first()
        .filter(|_| viewpoints.windows(2).all(|w| w[0] == w[1]))
    {
        cloud.viewpoint = Some((*v - cloud.origin).as_vec3());
    }
    Ok(cloud)
}
