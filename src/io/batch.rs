//! The batch a streamed point cloud is handed out in, and what a stream
//! held: the types every format's streamer and the dispatch
//! (`super::stream`) share.

use glam::{DVec3, Vec3};

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
