//! Out-of-core splat generation: a cloud of any size turned into splats in
//! tiles that each fit a memory budget.
//!
//! 1. **Survey** (one streaming pass over every input): the count, the
//!    bounds in f64, and a reservoir sample of 2^20 positions.
//! 2. **Plan**: `ϵ` is the whole cloud's (`epsilon_rel` times its
//!    diagonal); the halo is `HALO_EPS` (12) `ϵ` wide. The bounds are split
//!    k-d fashion at the sample's medians along the longest side until each
//!    tile's core plus halo holds at most the budget's points (estimated
//!    from the sample). The split planes give every point of space exactly
//!    one tile: the tile whose core holds it.
//! 3. **Spill** (a second streaming pass): each point is appended to the
//!    file of every tile whose core-plus-halo box holds it (positions as
//!    f32 offsets from the tile's centre, normals and colours carried).
//! 4. **Generate**, tile by tile: the tile's points become a cloud, splats
//!    are generated as for any cloud ([`generate_trimmed`]: outliers,
//!    normals, orientation, growth, fields, free-space trimming) with the
//!    shared `ϵ`, and a splat is kept when its centre lies in the tile's
//!    core. The result is a splat file per tile, written atomically: a rerun
//!    with the same plan skips finished tiles.
//! 5. **Merge**: the tiles' splat files share the cloud's origin, so the
//!    output is one header with the total count and their records in tile
//!    order. Same bytes for any thread count.
//!
//! The halo rule: a kept splat's centre lies in the core. Growth takes
//! points within `max_d` of its seed and centres the splat on the smallest
//! circle holding them (eqs. 2-3), so every point it took lies within its
//! radius of its centre, and the radius is at most `max_d`
//! (`MAX_RADIUS_EPS` `ϵ` = 8 `ϵ` on a densely sampled surface). Its normal
//! field reads points within at most 1.2 radii of the centre
//! (`field_radius_factor`; 9.6 `ϵ`), and their normals come from their
//! neighbourhoods (about `NORMALS_REACH_EPS`, 2 `ϵ`, more): 11.6 `ϵ`, within
//! the halo of 12 `ϵ`. Splats grown larger than that (sparse regions, where the
//! neighbour cap `MAX_RADIUS_FACTOR` `d_k` exceeds 8 `ϵ`) are counted in the
//! report as reaching past the halo. Which points seed splats depends on
//! the splats grown before them (§2.2), a coupling of any reach that the
//! halo bounds only in effect: measured, not proven (`docs/DESIGN.md`).

use crate::freespace::generate_trimmed;
use crate::io::{
    COLOR_FIELD_PROPS, IoError, IoErrorKind, SPLAT_ROW_BYTES, encode_splats_with,
    splat_header_with, stream_points, write_atomic, write_bytes,
};
use crate::progress::{Progress, notify};
use crate::rng::SplitMix64;
use crate::splat::color::ColorField;
use crate::splat::{PointCloud, Splat, SplatParams};
use glam::{DVec3, Vec3};
use serde::{Deserialize, Serialize};
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The halo's width in `ϵ` (see the module's text): a splat's normal
/// field reads points within at most `field_radius_factor` (1.2) times its
/// radius of its centre, and a radius reaches
/// `MAX_RADIUS_EPS` (8) `ϵ` on a densely sampled surface: 9.6 `ϵ`, plus [`NORMALS_REACH_EPS`] for the
/// neighbourhoods those points' normals were estimated from.
pub const HALO_EPS: f64 = 12.0;

/// What the neighbourhoods of a splat's points add to its reach, in `ϵ`.
pub const NORMALS_REACH_EPS: f64 = 2.0;

/// Bytes a point takes while its tile is generated, for planning: measured
/// 161 B a point for a whole 10M-point cloud read and generated in memory
/// (peak RSS 1.61 GB), rounded up.
pub const BYTES_PER_POINT: u64 = 192;

/// The most tiles generated at once in one process, when they fit the
/// budget together. The kd-tree's build and the last of the growth (the
/// seeds deferred across its regions, `splat::grow`) run on one thread,
/// so a second tile keeps the other cores busy meanwhile: 10M bunny points
/// in two tiles of 5.5M, 25.3 s one after the other, 20.3 s at once (with
/// the growth on one thread, before it took four regions at once). Tiles are planned to the whole budget
/// (halving them to run two at once spilled 170M points of 100M instead of
/// 134M: more than the overlap gains), and the output does not depend on
/// how many run at once.
pub const TILES_IN_FLIGHT: usize = 2;

/// Memory the process holds besides its tiles: the survey's sample, the
/// spill writers' buffers, the program and its libraries.
const FIXED_BYTES: u64 = 256 << 20;

/// Positions kept by the survey to plan tiles.
const SAMPLE: usize = 1 << 20;

/// The most tiles (each holds an open spill file while spilling).
const MAX_TILES: usize = 4096;

/// Which part of tiled generation a run does. A cluster runs the stages
/// as separate processes sharing the work folder: [`Stage::Plan`] once,
/// [`Stage::Tile`] once per tile (on any machine, in any order, retried
/// freely), then [`Stage::Merge`]; the output is the same bytes as
/// [`Stage::All`] in one process.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Stage {
    /// Survey, plan, spill, generate every tile, merge.
    #[default]
    All,
    /// Survey, plan and spill, then stop (a plan already spilled is kept).
    Plan,
    /// Generate this one tile of an existing plan (nothing when finished).
    Tile(usize),
    /// Merge the finished tiles of an existing plan into the output.
    Merge,
}

/// How tiled generation runs.
#[derive(Clone, Debug)]
pub struct TiledOptions {
    /// Bytes the whole process may use (`--max-memory`, else what
    /// [`crate::memory::limit`] says).
    pub max_memory: u64,
    /// At most this many points (core and halo) per tile, below what the
    /// memory allows (to force small tiles, as the tests do).
    pub tile_points: Option<u64>,
    /// The folder for the plan, spill files and finished tiles (made if
    /// missing, removed after a successful merge).
    pub work: PathBuf,
    /// Where the scanner stood, in the inputs' coordinates: given, or
    /// (`None`) a single input's own (a PCD's `VIEWPOINT`).
    pub viewpoint: Option<DVec3>,
    /// Ignore the inputs' own viewpoints.
    pub no_viewpoint: bool,
    /// Which part to run.
    pub stage: Stage,
}

/// An axis-aligned box in the cloud's coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Box3 {
    /// Lower corner.
    pub lo: [f64; 3],
    /// Upper corner.
    pub hi: [f64; 3],
}

impl Box3 {
    fn grown(&self, by: f64) -> Box3 {
        Box3 {
            lo: self.lo.map(|v| v - by),
            hi: self.hi.map(|v| v + by),
        }
    }
    fn holds(&self, p: DVec3) -> bool {
        (0..3).all(|a| p[a] >= self.lo[a] && p[a] <= self.hi[a])
    }
    fn centre(&self) -> DVec3 {
        (DVec3::from(self.lo) + DVec3::from(self.hi)) * 0.5
    }
}

/// A node of the plan's k-d tree: a split, or a tile.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
enum Node {
    /// Points with `p[axis] < at` go to `below`, the rest to `above`.
    Split {
        axis: usize,
        at: f64,
        below: Box<Node>,
        above: Box<Node>,
    },
    /// Tile number.
    Tile(usize),
}

impl Node {
    /// The tile whose core holds `p` (every point of space has one).
    fn locate(&self, p: DVec3) -> usize {
        match self {
            Node::Tile(t) => *t,
            Node::Split {
                axis,
                at,
                below,
                above,
            } => {
                if p[*axis] < *at {
                    below.locate(p)
                } else {
                    above.locate(p)
                }
            }
        }
    }
    /// Every tile whose core lies within `halo` of `p`.
    fn near(&self, p: DVec3, halo: f64, out: &mut Vec<usize>) {
        match self {
            Node::Tile(t) => out.push(*t),
            Node::Split {
                axis,
                at,
                below,
                above,
            } => {
                if p[*axis] < *at + halo {
                    below.near(p, halo, out);
                }
                if p[*axis] >= *at - halo {
                    above.near(p, halo, out);
                }
            }
        }
    }
}

/// What the survey found: enough to plan the tiles.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Survey {
    points: u64,
    non_finite: u64,
    bounds: Box3,
    normals: bool,
    colors: bool,
    viewpoint: Option<[f64; 3]>,
    /// Where each scan was taken from, when the inputs hold several scans
    /// (an E57 file of several, or several files each with its scanner's
    /// position) and every input says where: each point carries its scan.
    scans: Vec<[f64; 3]>,
    /// Per input, the index in `scans` of its first scan.
    scan_offsets: Vec<u32>,
    #[serde(skip)]
    sample: Vec<DVec3>,
}

/// One input file as the plan records it (a changed file is a new plan).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct InputStamp {
    path: PathBuf,
    bytes: u64,
    modified_ns: u128,
}

/// Everything that decides the output; a rerun finding the same plan in
/// the work folder resumes it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Plan {
    version: String,
    inputs: Vec<InputStamp>,
    params: String,
    survey: Survey,
    epsilon: f64,
    halo: f64,
    tile_points: u64,
    tree: Node,
    tiles: Vec<Box3>,
    origin: [f64; 3],
    viewpoint: Option<[f64; 3]>,
    /// Each point seen from its own scan's position (the survey's scans,
    /// neither `--viewpoint` nor `--no-viewpoint` given).
    per_scan: bool,
}

impl Plan {
    /// Whether the tiles orient their pieces by themselves (no input
    /// normals, no viewpoint, no scans), so that the merge must make their
    /// orientations agree.
    fn reconciles(&self) -> bool {
        !self.survey.normals && self.viewpoint.is_none() && !self.per_scan
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
    /// The tiles' cores, in order, and the bounds they split.
    pub cores: Vec<Box3>,
    /// See `cores`.
    pub bounds: Option<Box3>,
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

impl TiledReport {
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

fn io_err(path: &Path, e: std::io::Error) -> IoError {
    IoError::new(path, IoErrorKind::Io(e))
}

fn data_err(path: &Path, msg: String) -> IoError {
    IoError::new(path, IoErrorKind::Data(msg))
}

/// Peak resident memory of this process (`VmHWM`), bytes.
#[must_use]
pub fn peak_rss() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            let l = s.lines().find(|l| l.starts_with("VmHWM:"))?;
            l.split_whitespace().nth(1)?.parse::<u64>().ok()
        })
        .map_or(0, |kb| kb * 1024)
}

fn stamp(path: &Path) -> Result<InputStamp, IoError> {
    let meta = std::fs::metadata(path).map_err(|e| io_err(path, e))?;
    let modified_ns = meta
        .modified()
        .ok()
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .map_or(0, |d| d.as_nanos());
    Ok(InputStamp {
        path: path.to_path_buf(),
        bytes: meta.len(),
        modified_ns,
    })
}

fn survey(inputs: &[PathBuf], progress: Option<Progress<'_>>) -> Result<Survey, IoError> {
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    let mut sample: Vec<DVec3> = Vec::with_capacity(SAMPLE);
    let mut rng = SplitMix64::new(0x7115_5eed);
    let (mut seen, mut non_finite) = (0u64, 0u64);
    let (mut normals, mut colors) = (false, false);
    let mut viewpoint = None;
    // Every input's scanner positions (an E57 file's scans, a PCD's
    // viewpoint); `None` once an input has none.
    let mut scans: Option<Vec<[f64; 3]>> = Some(Vec::new());
    let mut scan_offsets = Vec::with_capacity(inputs.len());
    for (k, path) in inputs.iter().enumerate() {
        let info = stream_points(path, |b| {
            for &p in b.world {
                lo = lo.min(p);
                hi = hi.max(p);
                // Reservoir sampling (Algorithm R), seeded: the same input
                // gives the same sample.
                if sample.len() < SAMPLE {
                    sample.push(p);
                } else {
                    let j = rng.next_u64() % (seen + 1);
                    if (j as usize) < SAMPLE {
                        sample[j as usize] = p;
                    }
                }
                seen += 1;
            }
            notify(progress, "survey", k as f64 / inputs.len() as f64);
            Ok(())
        })?;
        non_finite += info.non_finite;
        normals |= info.normals;
        colors |= info.colors;
        if inputs.len() == 1 {
            viewpoint = info.viewpoint.map(|v| v.to_array());
        }
        let here: Vec<[f64; 3]> = if info.scans.is_empty() {
            info.viewpoint.map(|v| v.to_array()).into_iter().collect()
        } else {
            info.scans.iter().map(|v| v.to_array()).collect()
        };
        scan_offsets.push(scans.as_ref().map_or(0, |s| s.len() as u32));
        if here.is_empty() {
            scans = None;
        } else if let Some(s) = scans.as_mut() {
            s.extend(here);
        }
    }
    let mut scans = scans.unwrap_or_default();
    if scans.len() > usize::from(u16::MAX) {
        return Err(data_err(
            &inputs[0],
            format!(
                "{} scans in all, more than the {} a tiled run carries",
                scans.len(),
                u16::MAX
            ),
        ));
    }
    if scans.iter().all(|p| Some(*p) == scans.first().copied()) {
        // One place for every point: the one viewpoint.
        if viewpoint.is_none() {
            viewpoint = scans.first().copied();
        }
        scans.clear();
    }
    if scans.is_empty() {
        scan_offsets.clear();
    } else {
        viewpoint = None;
    }
    if seen < 3 {
        return Err(data_err(
            &inputs[0],
            format!("{seen} usable points: at least 3 are needed"),
        ));
    }
    Ok(Survey {
        points: seen,
        non_finite,
        bounds: Box3 {
            lo: lo.to_array(),
            hi: hi.to_array(),
        },
        normals,
        colors,
        viewpoint,
        scans,
        scan_offsets,
        sample,
    })
}

/// Splits `bounds` k-d fashion until each tile's core plus `halo` holds at
/// most `target` points as the sample estimates them; tiles are numbered
/// in the order of the tree's leaves.
fn plan_tiles(s: &Survey, halo: f64, target: u64) -> (Node, Vec<Box3>) {
    let per_sample = s.points as f64 / s.sample.len().max(1) as f64;
    let estimate = |b: &Box3| {
        let g = b.grown(halo);
        s.sample.iter().filter(|p| g.holds(**p)).count() as f64 * per_sample
    };
    let mut tiles = Vec::new();
    fn split(
        b: Box3,
        idx: Vec<u32>,
        s: &Survey,
        halo: f64,
        target: u64,
        estimate: &dyn Fn(&Box3) -> f64,
        tiles: &mut Vec<Box3>,
    ) -> Node {
        let side = DVec3::from(b.hi) - DVec3::from(b.lo);
        let axis = if side.x >= side.y && side.x >= side.z {
            0
        } else if side.y >= side.z {
            1
        } else {
            2
        };
        // A tile narrower than two halos would hold more halo than core:
        // the budget cannot be met at this ϵ (the report shows it).
        let splittable = side[axis] > 4.0 * halo && idx.len() >= 2 && tiles.len() < MAX_TILES;
        if estimate(&b) <= target as f64 || !splittable {
            tiles.push(b);
            return Node::Tile(tiles.len() - 1);
        }
        let mut vals: Vec<f64> = idx.iter().map(|&i| s.sample[i as usize][axis]).collect();
        let mid = vals.len() / 2;
        let (_, m, _) = vals.select_nth_unstable_by(mid, f64::total_cmp);
        // Keep both halves at least a halo wide.
        let at = m.clamp(b.lo[axis] + 2.0 * halo, b.hi[axis] - 2.0 * halo);
        let (mut lo_b, mut hi_b) = (b, b);
        lo_b.hi[axis] = at;
        hi_b.lo[axis] = at;
        let (below_idx, above_idx): (Vec<u32>, Vec<u32>) = idx
            .into_iter()
            .partition(|&i| s.sample[i as usize][axis] < at);
        let below = split(lo_b, below_idx, s, halo, target, estimate, tiles);
        let above = split(hi_b, above_idx, s, halo, target, estimate, tiles);
        Node::Split {
            axis,
            at,
            below: Box::new(below),
            above: Box::new(above),
        }
    }
    let idx: Vec<u32> = (0..s.sample.len() as u32).collect();
    let tree = split(s.bounds, idx, s, halo, target, &estimate, &mut tiles);
    (tree, tiles)
}

/// Bytes free to this process on the file system holding `dir`, when
/// the system says.
fn free_space(dir: &Path) -> Option<u64> {
    let v = rustix::fs::statvfs(dir).ok()?;
    Some(v.f_bavail.saturating_mul(v.f_frsize))
}

/// The spill record of one point: position offset from the tile's centre
/// (3 × f32), then the normal and the colour (3 × f32 each) when the
/// cloud has them, then its scan (u16) when there are several.
fn record_bytes(survey: &Survey) -> usize {
    12 + 12 * usize::from(survey.normals)
        + 12 * usize::from(survey.colors)
        + 2 * usize::from(!survey.scans.is_empty())
}

fn spill(
    inputs: &[PathBuf],
    plan: &Plan,
    work: &Path,
    progress: Option<Progress<'_>>,
) -> Result<Vec<(u64, u64)>, IoError> {
    let n = plan.tiles.len();
    let centres: Vec<DVec3> = plan.tiles.iter().map(Box3::centre).collect();
    let grown: Vec<Box3> = plan.tiles.iter().map(|b| b.grown(plan.halo)).collect();
    let mut writers = Vec::with_capacity(n);
    for t in 0..n {
        let p = spill_path(work, t);
        let f = std::fs::File::create(&p).map_err(|e| io_err(&p, e))?;
        writers.push(BufWriter::with_capacity(1 << 16, f));
    }
    let mut counts = vec![(0u64, 0u64); n];
    let mut near = Vec::new();
    let mut rec = Vec::with_capacity(36);
    let mut done = 0u64;
    let (with_n, with_c) = (plan.survey.normals, plan.survey.colors);
    let with_s = !plan.survey.scans.is_empty();
    for (k, path) in inputs.iter().enumerate() {
        let first_scan = plan.survey.scan_offsets.get(k).copied().unwrap_or(0);
        stream_points(path, |b| {
            for (i, &p) in b.world.iter().enumerate() {
                near.clear();
                plan.tree.near(p, plan.halo, &mut near);
                let core = plan.tree.locate(p);
                for &t in &near {
                    if !grown[t].holds(p) {
                        continue;
                    }
                    rec.clear();
                    for c in (p - centres[t]).as_vec3().to_array() {
                        rec.extend_from_slice(&c.to_le_bytes());
                    }
                    if with_n {
                        let v = b.normals.map_or(Vec3::NAN, |v| v[i]);
                        for c in v.to_array() {
                            rec.extend_from_slice(&c.to_le_bytes());
                        }
                    }
                    if with_c {
                        let v = b.colors.map_or(Vec3::ONE, |v| v[i]);
                        for c in v.to_array() {
                            rec.extend_from_slice(&c.to_le_bytes());
                        }
                    }
                    if with_s {
                        let scan = first_scan + b.scans.map_or(0, |s| u32::from(s[i]));
                        rec.extend_from_slice(&(scan as u16).to_le_bytes());
                    }
                    writers[t].write_all(&rec).map_err(|e| e.to_string())?;
                    counts[t].0 += 1;
                    if t == core {
                        counts[t].1 += 1;
                    }
                }
            }
            done += b.world.len() as u64;
            notify(
                progress,
                "spilling to tiles",
                done as f64 / plan.survey.points as f64,
            );
            Ok(())
        })?;
    }
    for (t, w) in writers.into_iter().enumerate() {
        let p = spill_path(work, t);
        w.into_inner()
            .map_err(|e| io_err(&p, e.into_error()))?
            .sync_all()
            .map_err(|e| io_err(&p, e))?;
    }
    Ok(counts)
}

fn spill_path(work: &Path, t: usize) -> PathBuf {
    work.join(format!("spill-{t:05}.bin"))
}

fn tile_path(work: &Path, t: usize) -> PathBuf {
    work.join(format!("tile-{t:05}.ply"))
}

fn halo_path(work: &Path, t: usize) -> PathBuf {
    work.join(format!("halo-{t:05}.ply"))
}

fn tile_report_path(work: &Path, t: usize) -> PathBuf {
    work.join(format!("tile-{t:05}.json"))
}

/// The tile's points as a cloud centred on the tile.
fn read_spill(plan: &Plan, work: &Path, t: usize) -> Result<PointCloud, IoError> {
    let p = spill_path(work, t);
    let rb = record_bytes(&plan.survey);
    let bytes = std::fs::metadata(&p).map_err(|e| io_err(&p, e))?.len();
    crate::memory::check(&format!("tile {t}"), bytes / rb as u64 * BYTES_PER_POINT)
        .map_err(|e| IoError::new(&p, IoErrorKind::Memory(e)))?;
    let mut r =
        BufReader::with_capacity(1 << 20, std::fs::File::open(&p).map_err(|e| io_err(&p, e))?);
    let n = (bytes / rb as u64) as usize;
    let (with_n, with_c) = (plan.survey.normals, plan.survey.colors);
    let with_s = !plan.survey.scans.is_empty();
    let mut positions = Vec::with_capacity(n);
    let mut normals = Vec::with_capacity(if with_n { n } else { 0 });
    let mut colors = Vec::with_capacity(if with_c { n } else { 0 });
    let mut scan_of = Vec::with_capacity(if with_s { n } else { 0 });
    let mut rec = vec![0u8; rb];
    let v3 = |b: &[u8]| {
        let f = |i: usize| f32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
        Vec3::new(f(0), f(4), f(8))
    };
    for _ in 0..n {
        r.read_exact(&mut rec).map_err(|e| io_err(&p, e))?;
        positions.push(v3(&rec[0..12]));
        let mut at = 12;
        if with_n {
            normals.push(v3(&rec[at..at + 12]));
            at += 12;
        }
        if with_c {
            colors.push(v3(&rec[at..at + 12]));
            at += 12;
        }
        if with_s {
            scan_of.push(u16::from_le_bytes([rec[at], rec[at + 1]]));
        }
    }
    let origin = plan.tiles[t].centre();
    let local = |v: [f64; 3]| (DVec3::from(v) - origin).as_vec3();
    Ok(PointCloud {
        positions,
        origin,
        normals: with_n.then_some(normals),
        colors: with_c.then_some(colors),
        viewpoint: plan.viewpoint.map(local),
        scans: (with_s && plan.per_scan).then(|| crate::splat::Scans {
            positions: plan.survey.scans.iter().map(|&v| local(v)).collect(),
            of: scan_of,
        }),
        ..PointCloud::default()
    })
}

/// Generates tile `t` and writes its kept splats (centres as offsets from
/// the plan's origin) and its summary.
fn generate_tile(
    plan: &Plan,
    params: &SplatParams,
    work: &Path,
    t: usize,
    counts: (u64, u64),
    progress: Option<Progress<'_>>,
) -> Result<TileSummary, IoError> {
    let t0 = Instant::now();
    let cloud = read_spill(plan, work, t)?;
    let mut summary = TileSummary {
        points: counts.0,
        core_points: counts.1,
        ..TileSummary::default()
    };
    let origin = DVec3::from(plan.origin);
    let mut kept: Vec<Splat> = Vec::new();
    // The kept splats' colour fields, fitted to the tile's points (its
    // halo too, so a field at a tile's border reads both sides).
    let with_fields = color_fields(plan, params);
    let mut kept_fields: Vec<ColorField> = Vec::new();
    // Splats grown in the halo, where a neighbour keeps its own: they tell
    // whether the two tiles turned the surface the same way.
    let mut halo: Vec<Splat> = Vec::new();
    let grown = plan.tiles[t].grown(plan.halo);
    if counts.1 > 0 && cloud.len() >= 3 {
        let tile_params = SplatParams {
            epsilon_abs: Some(plan.epsilon),
            viewpoint: cloud.viewpoint,
            ..params.clone()
        };
        let generated = generate_trimmed(&cloud, &tile_params, progress);
        match generated {
            Ok((mut splats, report, _)) => {
                summary.grown = splats.len();
                summary.warnings = report.warnings;
                let mut fields = if with_fields {
                    crate::splat::color::fit_cloud(&mut splats, &cloud, &tile_params).0
                } else {
                    Vec::new()
                };
                fields.resize(splats.len(), ColorField::ZERO);
                for (s, f) in splats.into_iter().zip(fields) {
                    let world = cloud.origin + s.center.as_dvec3();
                    if plan.tree.locate(world) != t {
                        if plan.reconciles() && grown.holds(world) {
                            halo.push(Splat {
                                center: (world - origin).as_vec3(),
                                ..s
                            });
                        }
                        continue;
                    }
                    let reach = f64::from(params.field_radius_factor)
                        * f64::from(s.radii.max_element())
                        + NORMALS_REACH_EPS * plan.epsilon;
                    if reach > plan.halo {
                        summary.past_halo += 1;
                    }
                    kept.push(Splat {
                        center: (world - origin).as_vec3(),
                        ..s
                    });
                    kept_fields.push(f);
                }
            }
            // A tile whose points are too few or degenerate (a corner of a
            // halo, a line) makes no splat; said in its warnings.
            Err(e) => summary.warnings.push(format!("no splats: {e}")),
        }
    }
    summary.kept = kept.len();
    summary.seconds = t0.elapsed().as_secs_f64();
    let out = tile_path(work, t);
    let fields = with_fields.then_some(&kept_fields[..]);
    write_bytes(&out, &encode_splats_with(&out, &kept, fields, origin)?)?;
    if plan.reconciles() {
        crate::io::write_splats(&halo_path(work, t), &halo, origin)?;
    }
    let json = serde_json::to_string(&summary).map_err(|e| data_err(&out, e.to_string()))?;
    crate::io::write_text(&tile_report_path(work, t), &json)?;
    let _ = std::fs::remove_file(spill_path(work, t));
    Ok(summary)
}

/// Generates splats from `inputs` in tiles within `opts.max_memory`, and
/// writes them to `output` as one splat file (see the module's text).
///
/// # Errors
/// An [`IoError`] when an input cannot be read, the work folder or the
/// output cannot be written, or the budget cannot hold even one tile.
pub fn generate_tiled(
    inputs: &[PathBuf],
    params: &SplatParams,
    opts: &TiledOptions,
    output: &Path,
    progress: Option<Progress<'_>>,
) -> Result<TiledReport, IoError> {
    let t0 = Instant::now();
    let work = &opts.work;
    std::fs::create_dir_all(work).map_err(|e| io_err(work, e))?;
    let stamps = inputs
        .iter()
        .map(|p| stamp(p))
        .collect::<Result<Vec<_>, _>>()?;
    let budget_points = opts
        .max_memory
        .checked_sub(FIXED_BYTES)
        .map_or(0, |b| b / BYTES_PER_POINT);
    let target = opts
        .tile_points
        .map_or(budget_points, |t| t.min(budget_points));
    if target < 1000 {
        return Err(data_err(
            work,
            format!(
                "a memory budget of {:.2} GB holds no tile (each point takes about {BYTES_PER_POINT} \
                 bytes while its tile is generated, besides {} MB for the program)",
                opts.max_memory as f64 / 1e9,
                FIXED_BYTES >> 20
            ),
        ));
    }
    let params_text = format!("{params:?} {:?} {}", opts.viewpoint, opts.no_viewpoint);
    let plan_file = work.join("plan.json");
    let old: Option<Plan> = std::fs::read_to_string(&plan_file)
        .ok()
        .and_then(|s| serde_json::from_str(&s).ok())
        .filter(|p: &Plan| {
            p.inputs == stamps
                && p.params == params_text
                // A tile or the merge may run on another machine, with
                // another memory: the plan's tiles stand (a tile too large
                // for this one is refused when read).
                && (p.tile_points == target || matches!(opts.stage, Stage::Tile(_) | Stage::Merge))
                && p.version == env!("CARGO_PKG_VERSION")
        });
    let mut report = TiledReport {
        max_memory: opts.max_memory,
        ..TiledReport::default()
    };
    let resumed = old.is_some();
    if !resumed && matches!(opts.stage, Stage::Tile(_) | Stage::Merge) {
        return Err(no_plan(work));
    }
    let plan = match old {
        Some(p) => p,
        None => {
            // A different plan: nothing in the folder is reusable.
            clear_work(work)?;
            new_plan(
                inputs,
                params,
                opts,
                stamps,
                params_text,
                target,
                progress,
                t0,
                &mut report,
            )?
        }
    };
    let diag = (DVec3::from(plan.survey.bounds.hi) - DVec3::from(plan.survey.bounds.lo)).length();
    report.points = plan.survey.points;
    report.non_finite = plan.survey.non_finite;
    report.epsilon = plan.epsilon;
    report.halo = plan.halo;
    report.bbox_diagonal = diag;
    report.tile_points = plan.tile_points;
    report.origin = plan.origin;
    report.cores.clone_from(&plan.tiles);
    report.bounds = Some(plan.survey.bounds);
    let counts_file = work.join("spilled.json");
    let spilled: Option<Vec<(u64, u64)>> = std::fs::read_to_string(&counts_file)
        .ok()
        .filter(|_| resumed)
        .and_then(|s| serde_json::from_str(&s).ok());
    let counts: Vec<(u64, u64)> = match spilled {
        Some(c) => c,
        None if opts.stage != Stage::All && opts.stage != Stage::Plan => {
            return Err(no_plan(work));
        }
        None => {
            let json =
                serde_json::to_string(&plan).map_err(|e| data_err(&plan_file, e.to_string()))?;
            crate::io::write_text(&plan_file, &json)?;
            let t1 = Instant::now();
            let c = spill(inputs, &plan, work, progress)?;
            report.seconds.spill = t1.elapsed().as_secs_f64();
            let json =
                serde_json::to_string(&c).map_err(|e| data_err(&counts_file, e.to_string()))?;
            crate::io::write_text(&counts_file, &json)?;
            c
        }
    };
    report.spilled = counts.iter().map(|c| c.0).sum();
    let t2 = Instant::now();
    let n = plan.tiles.len();
    if let Stage::Tile(t) = opts.stage
        && t >= n
    {
        return Err(data_err(
            work,
            format!("--tile {t}: the plan has tiles 0 to {}", n - 1),
        ));
    }
    run_tiles(&plan, params, opts, &counts, progress, &mut report)?;
    report.seconds.generate = t2.elapsed().as_secs_f64();
    if matches!(opts.stage, Stage::All | Stage::Merge) {
        let t3 = Instant::now();
        let flips = if plan.reconciles() {
            let f = reconcile(&plan, work)?;
            report.flipped_tiles = f.iter().filter(|&&x| x).count();
            report.flipped_splats = f
                .iter()
                .zip(&report.tiles)
                .filter(|(x, _)| **x)
                .map(|(_, s)| s.kept as u64)
                .sum();
            f
        } else {
            vec![false; plan.tiles.len()]
        };
        report.splats = merge(&plan, params, work, output, &flips, progress)?;
        report.seconds.merge = t3.elapsed().as_secs_f64();
        let _ = std::fs::remove_dir_all(work);
    }
    report.peak_rss = peak_rss();
    report.seconds.total = t0.elapsed().as_secs_f64();
    Ok(report)
}

/// Generates this run's tiles of `plan` (`counts`: each tile's spilled
/// points and core points), up to [`TILES_IN_FLIGHT`] at once when the
/// largest fit the memory budget together, and puts every tile's summary in
/// `report`: made now, finished before (resumed), or only planned.
fn run_tiles(
    plan: &Plan,
    params: &SplatParams,
    opts: &TiledOptions,
    counts: &[(u64, u64)],
    progress: Option<Progress<'_>>,
    report: &mut TiledReport,
) -> Result<(), IoError> {
    let work = &opts.work;
    let n = plan.tiles.len();
    // This run's tiles, up to TILES_IN_FLIGHT at a time when the largest
    // of them fit the budget together (each worker takes the next): each
    // tile's bytes are its own, whichever worker made them.
    let mine: Vec<usize> = (0..n)
        .filter(|&t| {
            (opts.stage == Stage::All || opts.stage == Stage::Tile(t))
                && finished_tile(work, t).is_none()
        })
        .collect();
    let made: Vec<std::sync::Mutex<Option<Result<TileSummary, IoError>>>> =
        (0..n).map(|_| std::sync::Mutex::new(None)).collect();
    let next = std::sync::atomic::AtomicUsize::new(0);
    let mut sizes: Vec<u64> = mine.iter().map(|&t| counts[t].0).collect();
    sizes.sort_unstable_by(|a, b| b.cmp(a));
    let largest: u64 = sizes.iter().take(TILES_IN_FLIGHT).sum();
    let fits =
        largest.saturating_mul(BYTES_PER_POINT) <= opts.max_memory.saturating_sub(FIXED_BYTES);
    let workers = if fits { TILES_IN_FLIGHT } else { 1 }
        .min(rayon::current_num_threads())
        .min(mine.len())
        .max(1);
    std::thread::scope(|scope| {
        for _ in 0..workers {
            scope.spawn(|| {
                loop {
                    let j = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    let Some(&t) = mine.get(j) else { break };
                    let tile_progress = |stage: &str, f: f64| {
                        notify(progress, &format!("tile {}/{n}: {stage}", t + 1), f);
                    };
                    let r = generate_tile(plan, params, work, t, counts[t], Some(&tile_progress));
                    let failed = r.is_err();
                    if let Ok(mut slot) = made[t].lock() {
                        *slot = Some(r);
                    }
                    if failed {
                        // The others finish the tile they hold; no new one.
                        next.store(mine.len(), std::sync::atomic::Ordering::Relaxed);
                    }
                }
            });
        }
    });
    for (t, (&c, slot)) in counts.iter().zip(made).enumerate() {
        let made = slot.into_inner().ok().flatten();
        let summary = match (made, finished_tile(work, t)) {
            (Some(Ok(s)), _) => s,
            // Another process finished it meanwhile (a retried task on a
            // cluster while the first still ran): its spill file is gone,
            // its result is here.
            (Some(Err(e)), done) => done.ok_or(e)?,
            (None, Some(mut s)) => {
                s.resumed = true;
                s
            }
            (None, None) if opts.stage == Stage::Merge => {
                return Err(data_err(
                    work,
                    format!("tile {t} of {n} is not finished: run it with --tile {t}"),
                ));
            }
            (None, None) if opts.stage == Stage::All || opts.stage == Stage::Tile(t) => {
                // A tile after one that failed.
                return Err(data_err(work, format!("tile {t} of {n} was not generated")));
            }
            // Not this run's tile: its plan only.
            (None, None) => TileSummary {
                points: c.0,
                core_points: c.1,
                ..TileSummary::default()
            },
        };
        report.past_halo += summary.past_halo;
        report.tiles.push(summary);
    }
    Ok(())
}

/// A new plan for `inputs`: the survey, the tiles of at most `target`
/// points with their halos, and the spill it will write, estimated from the
/// survey's sample and checked against the work folder's free disk; the
/// survey's seconds (since `t0`), the estimate and its warnings go to
/// `report`.
#[allow(clippy::too_many_arguments)]
fn new_plan(
    inputs: &[PathBuf],
    params: &SplatParams,
    opts: &TiledOptions,
    stamps: Vec<InputStamp>,
    params_text: String,
    target: u64,
    progress: Option<Progress<'_>>,
    t0: Instant,
    report: &mut TiledReport,
) -> Result<Plan, IoError> {
    let work = &opts.work;
    let s = survey(inputs, progress)?;
    report.seconds.survey = t0.elapsed().as_secs_f64();
    let diagonal = (DVec3::from(s.bounds.hi) - DVec3::from(s.bounds.lo)).length();
    let epsilon = match params.epsilon_abs {
        Some(e) => e,
        None => f64::from(params.epsilon_rel) * diagonal,
    };
    let halo = HALO_EPS * epsilon;
    let (tree, tiles) = plan_tiles(&s, halo, target);
    // What the spill will write, from the sample: each sampled
    // point stands for points / sample of the cloud's, in every
    // tile whose core or halo holds it.
    let grown: Vec<Box3> = tiles.iter().map(|b| b.grown(halo)).collect();
    let mut near = Vec::new();
    let mut held = 0u64;
    for &p in &s.sample {
        near.clear();
        tree.near(p, halo, &mut near);
        held += near.iter().filter(|&&t| grown[t].holds(p)).count() as u64;
    }
    let factor = held as f64 / s.sample.len().max(1) as f64;
    report.spill_estimate = (factor * s.points as f64).round() as u64;
    let bytes = report
        .spill_estimate
        .saturating_mul(record_bytes(&s) as u64);
    if let Some(free) = free_space(work)
        && bytes > free
    {
        return Err(data_err(
            work,
            format!(
                "the spill needs about {:.1} GB ({} points in {} tiles, {factor:.2} times the \
                 cloud with the halos) and its folder's disk has {:.1} GB free",
                bytes as f64 / 1e9,
                report.spill_estimate,
                tiles.len(),
                free as f64 / 1e9
            ),
        ));
    }
    if factor > 2.0 {
        report.warnings.push(format!(
            "the tiles' halos ({HALO_EPS} epsilon wide) hold {:.0} % more points than their \
             cores: {} tiles of at most {target} points are small against epsilon at this \
             density; --thin 0.25 (the cloud is denser than epsilon needs), a finer \
             --epsilon or a larger --max-memory would spill less",
            100.0 * (factor - 1.0),
            tiles.len()
        ));
    }
    let origin = s.bounds.centre().to_array();
    let viewpoint = if opts.no_viewpoint {
        None
    } else {
        opts.viewpoint.map(|v| v.to_array()).or(s.viewpoint)
    };
    let per_scan = !opts.no_viewpoint && opts.viewpoint.is_none() && !s.scans.is_empty();
    Ok(Plan {
        viewpoint,
        version: env!("CARGO_PKG_VERSION").into(),
        inputs: stamps,
        params: params_text,
        survey: s,
        epsilon,
        halo,
        tile_points: target,
        tree,
        tiles,
        origin,
        per_scan,
    })
}

/// The error of a stage that needs a plan where there is none (or one made
/// for other inputs or options).
fn no_plan(work: &Path) -> IoError {
    data_err(
        work,
        "no tile plan for these inputs and options here: run the same command with --plan-only first"
            .into(),
    )
}

/// Tile `t`'s summary when it is finished: the splat file is written
/// before the summary, so a summary means a finished tile.
fn finished_tile(work: &Path, t: usize) -> Option<TileSummary> {
    std::fs::read_to_string(tile_report_path(work, t))
        .ok()
        .and_then(|s| serde_json::from_str::<TileSummary>(&s).ok())
        .filter(|_| tile_path(work, t).exists())
}

/// Removes what an earlier plan left in the work folder.
fn clear_work(work: &Path) -> Result<(), IoError> {
    for e in std::fs::read_dir(work)
        .map_err(|e| io_err(work, e))?
        .flatten()
    {
        let name = e.file_name().to_string_lossy().into_owned();
        if name.starts_with("spill-")
            || name.starts_with("tile-")
            || name.starts_with("halo-")
            || name == "plan.json"
            || name == "spilled.json"
        {
            std::fs::remove_file(e.path()).map_err(|err| io_err(&e.path(), err))?;
        }
    }
    Ok(())
}

/// Joins the tiles' splat files into `output`: one header with the total
/// count, then each tile's records in tile order.
fn merge(
    plan: &Plan,
    params: &SplatParams,
    work: &Path,
    output: &Path,
    flips: &[bool],
    progress: Option<Progress<'_>>,
) -> Result<u64, IoError> {
    let n = plan.tiles.len();
    let with_fields = color_fields(plan, params);
    let row_bytes = SPLAT_ROW_BYTES
        + if with_fields {
            4 * COLOR_FIELD_PROPS.len()
        } else {
            0
        };
    let mut bodies = Vec::with_capacity(n);
    let mut total = 0u64;
    for t in 0..n {
        let p = tile_path(work, t);
        let bytes = std::fs::metadata(&p).map_err(|e| io_err(&p, e))?.len();
        let head = header_len(&p)?;
        let body = bytes - head;
        if body % row_bytes as u64 != 0 {
            return Err(data_err(&p, "a tile's splat file is cut short".into()));
        }
        total += body / row_bytes as u64;
        bodies.push((p, head));
    }
    let header = splat_header_with(total, DVec3::from(plan.origin), with_fields);
    write_atomic(output, |tmp| -> std::io::Result<()> {
        let mut out = BufWriter::with_capacity(1 << 20, std::fs::File::create(tmp)?);
        out.write_all(header.as_bytes())?;
        for (t, (p, head)) in bodies.iter().enumerate() {
            let mut f = BufReader::new(std::fs::File::open(p)?);
            std::io::copy(&mut (&mut f).take(*head), &mut std::io::sink())?;
            if flips.get(t).copied().unwrap_or(false) {
                // The normal and the field's four coefficients change sign
                // (the sign bit of each little-endian f32): the field then
                // gives the opposite normal everywhere (eq. 4).
                let mut row = vec![0u8; row_bytes];
                loop {
                    match f.read_exact(&mut row) {
                        Ok(()) => {}
                        Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => break,
                        Err(e) => return Err(e),
                    }
                    for k in FLIPPED_FLOATS {
                        row[4 * k + 3] ^= 0x80;
                    }
                    out.write_all(&row)?;
                }
            } else {
                std::io::copy(&mut f, &mut out)?;
            }
            notify(progress, "merging", (t + 1) as f64 / n as f64);
        }
        out.flush()
    })?;
    Ok(total)
}

/// Whether the tiles write colour fields: the survey found colours and the
/// parameters ask for fields (every tile the same layout, so the merge can
/// join their records; a tile of one colour writes zero fields).
fn color_fields(plan: &Plan, params: &SplatParams) -> bool {
    plan.survey.colors && params.color_fields
}

/// A tile's splat file (which may hold none).
fn tile_splats(p: &Path) -> Result<Vec<Splat>, IoError> {
    let bytes = std::fs::metadata(p).map_err(|e| io_err(p, e))?.len();
    if bytes == header_len(p)? {
        return Ok(Vec::new());
    }
    Ok(crate::io::read_splats(p)?.splats)
}

/// The floats of a splat row that change sign when the splat is turned
/// over: `nx ny nz` and `field_xc field_yc field_alpha field_beta`.
const FLIPPED_FLOATS: [usize; 7] = [3, 4, 5, 14, 15, 16, 17];

/// Which tiles to turn over so that neighbours agree. Each tile's halo
/// splats meet the splats its neighbours kept there: a halo splat votes
/// for "same" or "opposite" with the nearest kept splat of another tile
/// when it lies within either's radius and their planes agree (|n·m| ≥
/// 0.5, so a thin sheet's other side does not vote). The tiles are then
/// joined along their strongest votes first (a spanning tree by vote
/// margin, ties by tile number), each with its orientation relative to
/// its neighbour's; of every connected set, the side holding fewer kept
/// splats is turned over (the tiles whose own rule chose wrong are the
/// few).
fn reconcile(plan: &Plan, work: &Path) -> Result<Vec<bool>, IoError> {
    let n = plan.tiles.len();
    let mut centres: Vec<[f32; 3]> = Vec::new();
    let mut kept: Vec<(u32, Vec3, f32)> = Vec::new();
    let mut sizes = vec![0u64; n];
    for (t, size) in sizes.iter_mut().enumerate() {
        let splats = tile_splats(&tile_path(work, t))?;
        *size = splats.len() as u64;
        for s in splats {
            centres.push(s.center.to_array());
            kept.push((t as u32, s.normal, s.radii.max_element()));
        }
    }
    if kept.is_empty() {
        return Ok(vec![false; n]);
    }
    let tree: kiddo::immutable::float::kdtree::ImmutableKdTree<f32, u32, 3, 32> =
        kiddo::immutable::float::kdtree::ImmutableKdTree::new_from_slice(&centres);
    // (same, opposite) votes per pair of tiles (lower number first).
    let mut votes: std::collections::BTreeMap<(u32, u32), (u64, u64)> =
        std::collections::BTreeMap::new();
    for t in 0..n {
        let p = halo_path(work, t);
        if !p.exists() {
            continue;
        }
        for h in tile_splats(&p)? {
            let near = tree.nearest_one::<kiddo::SquaredEuclidean>(&h.center.to_array());
            let (u, m, r) = kept[near.item as usize];
            let reach = h.radii.max_element().max(r);
            let dot = h.normal.dot(m);
            if u as usize == t || near.distance > reach * reach || dot.abs() < 0.5 {
                continue;
            }
            let key = ((t as u32).min(u), (t as u32).max(u));
            let v = votes.entry(key).or_default();
            if dot > 0.0 {
                v.0 += 1;
            } else {
                v.1 += 1;
            }
        }
    }
    let mut edges: Vec<(u64, u32, u32, bool)> = votes
        .into_iter()
        .filter(|(_, (a, b))| a != b)
        .map(|((t, u), (a, b))| (a.abs_diff(b), t, u, b > a))
        .collect();
    edges.sort_by(|x, y| y.0.cmp(&x.0).then((x.1, x.2).cmp(&(y.1, y.2))));
    // Union-find with each tile's parity against its root.
    let mut parent: Vec<usize> = (0..n).collect();
    let mut parity = vec![false; n];
    fn root(parent: &mut [usize], parity: &mut [bool], x: usize) -> (usize, bool) {
        let mut path = Vec::new();
        let mut r = x;
        while parent[r] != r {
            path.push(r);
            r = parent[r];
        }
        // Compress, accumulating parities from the top.
        let mut acc = false;
        for &y in path.iter().rev() {
            acc ^= parity[y];
            parity[y] = acc;
            parent[y] = r;
        }
        (r, if path.is_empty() { false } else { parity[x] })
    }
    for (_, t, u, opposite) in edges {
        let (rt, pt) = root(&mut parent, &mut parity, t as usize);
        let (ru, pu) = root(&mut parent, &mut parity, u as usize);
        if rt != ru {
            parent[ru] = rt;
            parity[ru] = pt ^ pu ^ opposite;
        }
    }
    let mut flips = vec![false; n];
    let mut sides: std::collections::BTreeMap<usize, (u64, u64)> =
        std::collections::BTreeMap::new();
    let mut of = vec![(0usize, false); n];
    for t in 0..n {
        of[t] = root(&mut parent, &mut parity, t);
        let e = sides.entry(of[t].0).or_default();
        if of[t].1 {
            e.1 += sizes[t];
        } else {
            e.0 += sizes[t];
        }
    }
    for t in 0..n {
        let (r, odd) = of[t];
        let (even, oddsum) = sides[&r];
        // Turn over the smaller side (the odd one on a tie).
        flips[t] = if oddsum <= even { odd } else { !odd };
    }
    Ok(flips)
}

/// Bytes of a splat file's header (through `end_header\n`).
fn header_len(p: &Path) -> Result<u64, IoError> {
    let mut head = vec![0u8; 4096];
    let mut f = std::fs::File::open(p).map_err(|e| io_err(p, e))?;
    let got = f.read(&mut head).map_err(|e| io_err(p, e))?;
    let text = &head[..got];
    let end = b"end_header\n";
    text.windows(end.len())
        .position(|w| w == end)
        .map(|i| (i + end.len()) as u64)
        .ok_or_else(|| data_err(p, "no end_header in a tile's splat file".into()))
}
