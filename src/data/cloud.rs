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
    /// A cloud registered from several scans (E57): where each scanner
    /// stood and which scan each point came from. Splat generation uses a
    /// point's own scanner where [`PointCloud::viewpoint`] would be used.
    pub scans: Option<Scans>,
    /// Unit directions, from [`PointCloud::viewpoint`], of the scanner's
    /// rays that met nothing (an organised scan's empty cells beside other
    /// empty cells, not a lone dropped return): free space to infinity.
    pub misses: Option<Vec<Vec3>>,
}

/// Several scans in one cloud.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scans {
    /// Each scanner's position, in the positions' frame.
    pub positions: Vec<Vec3>,
    /// Per point: the index of its scan in `positions`.
    pub of: Vec<u16>,
    /// Unit directions of the scanners' rays that met nothing (as
    /// [`PointCloud::misses`], each from its own scanner); empty when not
    /// known (an E57 file records them only as direction-only points).
    pub misses: Vec<Vec3>,
    /// Per entry of `misses`, the index of its scan in `positions`.
    pub misses_of: Vec<u16>,
}

/// A normal facing away from the line of sight by more than this cosine
/// (past edge-on by about 11.5°; noise tilts grazing normals slightly
/// past it) counts as seen from behind.
pub const FACING_AWAY_COS: f32 = -0.2;

/// If more than this share of the points face away from the viewpoint
/// (`splat::SplatReport::facing_away`), the viewpoint is not the scanner's:
/// free-space trimming trims nothing and a warning says so. Single scans
/// measure under 0.01 % (the synthetic bunny scans, milk.pcd); the bundled
/// lamppost, points on every side of a pole and few on the side facing its
/// default `VIEWPOINT`, 14 %.
pub const FACING_AWAY_MAX: f64 = 0.05;

/// Where points were seen from: one scanner for all, or each point's own.
#[derive(Clone, Debug, PartialEq)]
pub enum Viewpoints {
    /// Every point was seen from here.
    One(Vec3),
    /// Point `i` was seen from `[i]`.
    PerPoint(Vec<Vec3>),
}

impl Viewpoints {
    /// Where point `i` was seen from.
    ///
    /// # Panics
    /// When `i` is out of range of a per-point list.
    #[must_use]
    pub fn at(&self, i: usize) -> Vec3 {
        match self {
            Viewpoints::One(v) => *v,
            Viewpoints::PerPoint(v) => v[i],
        }
    }

    /// Every viewpoint finite.
    #[must_use]
    pub fn is_finite(&self) -> bool {
        match self {
            Viewpoints::One(v) => v.is_finite(),
            Viewpoints::PerPoint(v) => v.iter().all(|p| p.is_finite()),
        }
    }

    /// The viewpoints of the points `order` picks, in that order.
    #[must_use]
    pub fn pick(&self, order: &[u32]) -> Viewpoints {
        match self {
            Viewpoints::One(v) => Viewpoints::One(*v),
            Viewpoints::PerPoint(v) => {
                Viewpoints::PerPoint(order.iter().map(|&i| v[i as usize]).collect())
            }
        }
    }

    /// Each viewpoint mapped by `f`.
    #[must_use]
    pub fn map(&self, f: impl Fn(Vec3) -> Vec3) -> Viewpoints {
        match self {
            Viewpoints::One(v) => Viewpoints::One(f(*v)),
            Viewpoints::PerPoint(v) => Viewpoints::PerPoint(v.iter().map(|p| f(*p)).collect()),
        }
    }

    /// Keeps the viewpoints of the points whose `drop` flag is false.
    pub fn retain(&mut self, drop: &[bool]) {
        if let Viewpoints::PerPoint(v) = self {
            let mut it = drop.iter();
            v.retain(|_| !it.next().copied().unwrap_or(false));
        }
    }
}

impl PointCloud {
    /// The points whose `keep` flag is true (one flag per point), with
    /// their normals, colours and scans when those have one entry per
    /// point; the origin and viewpoint kept, nothing counted as skipped.
    #[must_use]
    pub fn subset(&self, keep: &[bool]) -> PointCloud {
        let n = self.len();
        fn pick<T: Copy>(v: &[T], keep: &[bool]) -> Vec<T> {
            v.iter()
                .zip(keep)
                .filter(|(_, k)| **k)
                .map(|(x, _)| *x)
                .collect()
        }
        PointCloud {
            positions: pick(&self.positions, keep),
            origin: self.origin,
            normals: self
                .normals
                .as_ref()
                .filter(|v| v.len() == n)
                .map(|v| pick(v, keep)),
            colors: self
                .colors
                .as_ref()
                .filter(|v| v.len() == n)
                .map(|v| pick(v, keep)),
            skipped: Vec::new(),
            viewpoint: self.viewpoint,
            misses: self.misses.clone(),
            scans: self
                .scans
                .as_ref()
                .filter(|s| s.of.len() == n)
                .map(|s| Scans {
                    positions: s.positions.clone(),
                    of: pick(&s.of, keep),
                    misses: s.misses.clone(),
                    misses_of: s.misses_of.clone(),
                }),
        }
    }

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

    /// Where the points were seen from, in the positions' frame: each
    /// point's own scanner for a cloud of several scans (when the list has
    /// one entry per point), else the one viewpoint, if any.
    #[must_use]
    pub fn viewpoints(&self) -> Option<Viewpoints> {
        if let Some(s) = self
            .scans
            .as_ref()
            .filter(|s| s.of.len() == self.len() && !s.positions.is_empty())
        {
            let last = s.positions.len() - 1;
            return Some(Viewpoints::PerPoint(
                s.of.iter()
                    .map(|&k| s.positions[usize::from(k).min(last)])
                    .collect(),
            ));
        }
        self.viewpoint.map(Viewpoints::One)
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
    /// frame of `crate::splat::SplatParams::viewpoint`); subtracted in f64.
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
