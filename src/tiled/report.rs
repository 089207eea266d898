//! What tiled generation reports: per tile, and for the whole run.

use glam::DVec3;
use serde::{Deserialize, Serialize};

/// An axis-aligned box in the cloud's coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Box3 {
    /// Lower corner.
    pub lo: [f64; 3],
    /// Upper corner.
    pub hi: [f64; 3],
}

impl Box3 {
    pub(super) fn grown(&self, by: f64) -> Box3 {
        Box3 {
            lo: self.lo.map(|v| v - by),
            hi: self.hi.map(|v| v + by),
        }
    }
    pub(super) fn holds(&self, p: DVec3) -> bool {
        (0..3).all(|a| p[a] >= self.lo[a] && p[a] <= self.hi[a])
    }
    pub(super) fn centre(&self) -> DVec3 {
        (DVec3::from(self.lo) + DVec3::from(self.hi)) * 0.5
    }
}

/// One tile's figures.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TileSummary {
    /// Points spilled to it (core and halo).
    pub points: u64,
    /// Of those, in its core.
    pub core_points: u64,
    /// Splats generated from its points, and kept (centre in the core).
    pub grown: usize,
    /// See `grown`.
    pub kept: usize,
    /// Kept splats whose reach (seed to centre plus growth, about 2.2
    /// radii) may pass the halo.
    pub past_halo: usize,
    /// Seconds generating it (0 when a rerun found it finished).
    pub seconds: f64,
    /// True when a rerun found it finished.
    pub resumed: bool,
    /// Its generation's warnings.
    pub warnings: Vec<String>,
    /// Points its generation left out as denser than `ϵ` needs (`--thin`,
    /// or unasked: `crate::splat::thin`).
    #[serde(default)]
    pub thinned: u64,
    /// Grown by lean growth (`crate::splat::lean`), its gate reading the
    /// core's points.
    #[serde(default)]
    pub lean: bool,
}

/// What tiled generation reports.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct TiledReport {
    /// Finite input points.
    pub points: u64,
    /// Points with a non-finite coordinate, left out.
    pub non_finite: u64,
    /// Splats written.
    pub splats: u64,
    /// `ϵ`, absolute (the whole cloud's), and the halo's width.
    pub epsilon: f64,
    /// See `epsilon`.
    pub halo: f64,
    /// The bounding box's diagonal.
    pub bbox_diagonal: f64,
    /// The most points a tile (core and halo) was planned to hold.
    pub tile_points: u64,
    /// The memory budget, bytes.
    pub max_memory: u64,
    /// Peak resident memory of this process (`VmHWM`), bytes.
    pub peak_rss: u64,
    /// Points spilled in all (a point in several tiles' halos counts in each).
    pub spilled: u64,
    /// Kept splats whose reach may pass the halo, over all tiles.
    pub past_halo: usize,
    /// The splat file's origin.
    pub origin: [f64; 3],
    /// Seconds: survey, spill, generation, merge, total.
    pub seconds: TiledSeconds,
    /// Per tile, in order.
    pub tiles: Vec<TileSummary>,
    /// The tiles' cores and the bounds they split.
    #[serde(flatten)]
    pub layout: TileLayout,
    /// The points the plan expected to spill, from the survey's sample
    /// (0 when a rerun found the plan).
    pub spill_estimate: u64,
    /// What the plan found worth saying (e.g. halos holding more points
    /// than the cores).
    pub warnings: Vec<String>,
    /// Tiles whose splats the merge turned over to agree with their
    /// neighbours (orientation decided per tile), and those splats.
    pub flipped_tiles: usize,
    /// See `flipped_tiles`.
    pub flipped_splats: u64,
}

/// The tiles' cores, in order, and the bounds they split (where the seams
/// between tiles lie).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct TileLayout {
    /// Each tile's core, in order.
    pub cores: Vec<Box3>,
    /// The bounds the cores split.
    pub bounds: Option<Box3>,
}

impl TileLayout {
    /// Whether `p` lies within `width` of a seam: a face of its tile's core
    /// that another tile shares (not the cloud's bounds).
    #[must_use]
    pub fn seams_within(&self, p: DVec3, width: f64) -> bool {
        let Some(bounds) = self.bounds else {
            return false;
        };
        let Some(core) = self.cores.iter().find(|b| b.holds(p)) else {
            return false;
        };
        (0..3).any(|a| {
            (core.lo[a] > bounds.lo[a] && p[a] - core.lo[a] < width)
                || (core.hi[a] < bounds.hi[a] && core.hi[a] - p[a] < width)
        })
    }
}

/// Where the time went.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct TiledSeconds {
    /// Reading every input once for count, bounds and sample.
    pub survey: f64,
    /// Reading them again into the tiles' spill files.
    pub spill: f64,
    /// Generating the tiles.
    pub generate: f64,
    /// Joining the tiles' splats into the output.
    pub merge: f64,
    /// All of it.
    pub total: f64,
}
