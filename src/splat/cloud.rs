//! The input of splat generation: points with optional normals and colours.

use glam::{DVec3, Vec3};

/// A point cloud as read from a file (or sampled from a mesh).
///
/// Positions are single-precision offsets from an `origin` held in double
/// precision: point `i` lies at `origin + positions[i]` in the file's
/// coordinates. The readers put the origin at the cloud's per-axis medians
/// (a robust centre: a few far outliers do not move it), so a georeferenced
/// scan millions of units from zero keeps the precision of its size, not of
/// its distance (`docs/DESIGN.md`, "Precision").
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointCloud {
    /// Point positions relative to `origin`; all finite.
    pub positions: Vec<Vec3>,
    /// Where the positions are measured from, in the file's coordinates
    /// (zero for a cloud built in memory).
    pub origin: DVec3,
    /// Per-point normals when the file has them, as stored (not necessarily
    /// unit length; zero or NaN ones are re-estimated by the splat generator).
    pub normals: Option<Vec<Vec3>>,
    /// Per-point linear RGB colour in `[0, 1]` when the file has colour.
    pub colors: Option<Vec<Vec3>>,
    /// Points left out while reading, as `(reason, count)`.
    pub skipped: Vec<(String, usize)>,
    /// Where the scanner stood (PCD `VIEWPOINT`), in the positions' frame:
    /// every point was seen from here, so the segment from it to a point is
    /// free space.
    pub viewpoint: Option<Vec3>,
}

impl PointCloud {
    /// Number of points kept.
    #[must_use]
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// `true` when no point was kept.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Point `i` in the file's coordinates: `origin + positions[i]`, in f64.
    ///
    /// # Panics
    /// When `i` is out of range.
    #[must_use]
    pub fn world(&self, i: usize) -> DVec3 {
        self.origin + self.positions[i].as_dvec3()
    }

    /// A viewpoint given in the file's coordinates, relative to `origin` (the
    /// frame of [`crate::splat::SplatParams::viewpoint`]); subtracted in f64.
    /// One further than `1e30` is pulled in along its direction, which is
    /// all that orienting normals uses.
    #[must_use]
    pub fn local_viewpoint(&self, world: DVec3) -> Vec3 {
        let d = world - self.origin;
        let len = d.length();
        if len > 1e30 {
            (d * (1e30 / len)).as_vec3()
        } else {
            d.as_vec3()
        }
    }

    /// Total number of skipped points over all reasons.
    #[must_use]
    pub fn skipped_total(&self) -> usize {
        self.skipped.iter().map(|(_, n)| n).sum()
    }

    /// Add `count` skipped points under `reason` (merged with an existing
    /// entry of the same reason; a zero count is not recorded).
    pub fn add_skipped(&mut self, reason: &str, count: usize) {
        if count == 0 {
            return;
        }
        match self.skipped.iter_mut().find(|(r, _)| r == reason) {
            Some((_, n)) => *n += count,
            None => self.skipped.push((reason.to_string(), count)),
        }
    }
}
