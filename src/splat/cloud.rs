//! The input of splat generation: points with optional normals and colours.

use glam::Vec3;

/// A point cloud as read from a file (or sampled from a mesh).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointCloud {
    /// Point positions; all finite.
    pub positions: Vec<Vec3>,
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
