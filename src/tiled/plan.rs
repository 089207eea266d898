//! The plan stage: the survey of every input (count, bounds, sample), the
//! k-d split into tiles with halos, and the spill it foresees.

use super::report::{Box3, TiledReport};
use super::{HALO_EPS, TiledOptions, data_err, io_err};
use super::inputs::{Kept, replay};
use crate::data::{WIDENED_SHARE, trimmed_diagonal};
use crate::io::IoError;
use crate::progress::{Progress, notify};
use crate::rng::SplitMix64;
use crate::splat::SplatParams;
use glam::DVec3;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Positions kept by the survey to plan tiles.
pub(super) const SAMPLE: usize = 1 << 20;

/// The most tiles (each holds an open spill file while spilling).
pub(super) const MAX_TILES: usize = 4096;

/// A node of the plan's k-d tree: a split, or a tile.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(super) enum Node {
    /// Two halves.
    Split(Split),
    /// Tile number.
    Tile(usize),
}

/// A split of the plan's k-d tree: points with `p[axis] < at` go to
/// `below`, the rest to `above`. (Serialised as the struct variant it
/// once was: a plan written before reads the same.)
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(super) struct Split {
    axis: usize,
    at: f64,
    below: Box<Node>,
    above: Box<Node>,
}

impl Node {
    /// The tile whose core holds `p` (every point of space has one).
    pub(super) fn locate(&self, p: DVec3) -> usize {
        let mut node = self;
        loop {
            match node {
                Node::Tile(t) => return *t,
                Node::Split(s) => node = if p[s.axis] < s.at { &s.below } else { &s.above },
            }
        }
    }
    /// Every tile whose core lies within `halo` of `p`.
    pub(super) fn near(&self, p: DVec3, halo: f64, out: &mut Vec<usize>) {
        match self {
            Node::Tile(t) => out.push(*t),
            Node::Split(s) => {
                if p[s.axis] < s.at + halo {
                    s.below.near(p, halo, out);
                }
                if p[s.axis] >= s.at - halo {
                    s.above.near(p, halo, out);
                }
            }
        }
    }
}

/// What the survey found: enough to plan the tiles.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(super) struct Survey {
    pub(super) points: u64,
    pub(super) non_finite: u64,
    pub(super) bounds: Box3,
    pub(super) normals: bool,
    /// Every point carries a usable normal (a finite, non-zero one):
    /// generation estimates none, and a tile is planned at
    /// [`super::BYTES_PER_POINT_GIVEN_NORMALS`] a point.
    #[serde(default)]
    pub(super) every_normal: bool,
    pub(super) colors: bool,
    pub(super) viewpoint: Option<[f64; 3]>,
    /// Where each scan was taken from, when the inputs hold several scans
    /// (an E57 file of several, or several files each with its scanner's
    /// position) and every input says where: each point carries its scan.
    pub(super) scans: Vec<[f64; 3]>,
    /// Per input, the index in `scans` of its first scan.
    pub(super) scan_offsets: Vec<u32>,
    #[serde(skip)]
    pub(super) sample: Vec<DVec3>,
}

/// One input file as the plan records it (a changed file is a new plan).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(super) struct InputStamp {
    pub(super) path: PathBuf,
    pub(super) bytes: u64,
    pub(super) modified_ns: u128,
}

/// Everything that decides the output; a rerun finding the same plan in
/// the work folder resumes it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(super) struct Plan {
    pub(super) version: String,
    pub(super) inputs: Vec<InputStamp>,
    pub(super) params: String,
    pub(super) survey: Survey,
    pub(super) epsilon: f64,
    pub(super) halo: f64,
    pub(super) tile_points: u64,
    pub(super) tree: Node,
    pub(super) tiles: Vec<Box3>,
    pub(super) origin: [f64; 3],
    pub(super) viewpoint: Option<[f64; 3]>,
    /// Each point seen from its own scan's position (the survey's scans,
    /// neither `--viewpoint` nor `--no-viewpoint` given).
    pub(super) per_scan: bool,
    /// The bytes the spill was foreseen to write (checked again against
    /// the free disk before a resumed run spills).
    #[serde(default)]
    pub(super) spill_bytes: u64,
}

impl Plan {
    /// Whether the tiles orient their pieces by themselves (no input
    /// normals, no viewpoint, no scans), so that the merge must make their
    /// orientations agree.
    pub(super) fn reconciles(&self) -> bool {
        !self.survey.normals && self.viewpoint.is_none() && !self.per_scan
    }
}

pub(super) fn stamp(path: &Path) -> Result<InputStamp, IoError> {
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

pub(super) fn survey(
    inputs: &[PathBuf],
    kept: Option<&Kept>,
    progress: Option<Progress<'_>>,
) -> Result<Survey, IoError> {
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    let mut sample: Vec<DVec3> = Vec::with_capacity(SAMPLE);
    let mut rng = SplitMix64::new(0x7115_5eed);
    let (mut seen, mut non_finite) = (0u64, 0u64);
    let (mut normals, mut colors) = (false, false);
    let mut every_normal = true;
    let mut viewpoint = None;
    // Every input's scanner positions (an E57 file's scans, a PCD's
    // viewpoint); `None` once an input has none.
    let mut scans: Option<Vec<[f64; 3]>> = Some(Vec::new());
    let mut scan_offsets = Vec::with_capacity(inputs.len());
    for (k, path) in inputs.iter().enumerate() {
        let info = replay(kept, k, path, |b| {
            every_normal &= b
                .normals
                .is_some_and(|n| n.iter().all(|v| v.try_normalize().is_some()));
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
        every_normal,
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
pub(super) fn plan_tiles(s: &Survey, halo: f64, target: u64) -> (Node, Vec<Box3>) {
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
        Node::Split(Split {
            axis,
            at,
            below: Box::new(below),
            above: Box::new(above),
        })
    }
    let idx: Vec<u32> = (0..s.sample.len() as u32).collect();
    let tree = split(s.bounds, idx, s, halo, target, &estimate, &mut tiles);
    (tree, tiles)
}

/// Bytes free to this process on the file system holding `dir`, when
/// the system says.
pub(super) fn free_space(dir: &Path) -> Option<u64> {
    let v = rustix::fs::statvfs(dir).ok()?;
    Some(v.f_bavail.saturating_mul(v.f_frsize))
}

/// The length `ϵ` is a fraction of: the bounding box's diagonal, or
/// where a few far points widen that box past [`WIDENED_SHARE`] of it (a
/// scan's stray returns), the diagonal of the survey sample's box without
/// its 0.1 % most extreme points along each axis, as whole-cloud
/// generation takes it (`report` then warns). The solids scanned with 0.2 %
/// stray returns took a 1.6 times wider `ϵ` in tiles than whole before.
fn epsilon_scale(s: &Survey, report: &mut TiledReport) -> f64 {
    let diagonal = (DVec3::from(s.bounds.hi) - DVec3::from(s.bounds.lo)).length();
    let trimmed = trimmed_diagonal(&s.sample);
    if trimmed < WIDENED_SHARE * diagonal && trimmed > 0.0 {
        report.warnings.push(format!(
            "a few far points widen the bounding box by {:.1} %: epsilon is taken from the box of \
             all but the 0.1 % most extreme points along each axis (of the survey's sample)",
            100.0 * (diagonal / trimmed - 1.0)
        ));
        trimmed
    } else {
        diagonal
    }
}

/// A new plan for `inputs` (replayed from `kept` when there): the survey,
/// the tiles of at most `size`'s points with their halos, and the spill it
/// will write, estimated from the survey's sample and checked against the
/// work folder's free disk; the survey's seconds (since `t0`), the
/// estimate and its warnings go to `report`.
#[allow(clippy::too_many_arguments)]
pub(super) fn new_plan(
    inputs: &[PathBuf],
    kept: Option<&Kept>,
    params: &SplatParams,
    opts: &TiledOptions,
    stamps: Vec<InputStamp>,
    params_text: String,
    size: super::TileSize,
    progress: Option<Progress<'_>>,
    t0: Instant,
    report: &mut TiledReport,
) -> Result<Plan, IoError> {
    let work = &opts.work;
    let s = survey(inputs, kept, progress)?;
    let target = size.points(s.every_normal);
    report.seconds.survey = t0.elapsed().as_secs_f64();
    let epsilon = match params.epsilon_abs {
        Some(e) => e,
        None => f64::from(params.epsilon_rel) * epsilon_scale(&s, report),
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
    let spill_bytes = bytes;
    check_space(
        work,
        bytes,
        &format!(
            "{} points in {} tiles, {factor:.2} times the cloud with the halos",
            report.spill_estimate,
            tiles.len()
        ),
    )?;
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
        spill_bytes,
    })
}

/// A byte count for people: bytes, kB, MB or GB with one decimal (not
/// "0.0 GB" for a small spill).
pub(super) fn size_text(bytes: u64) -> String {
    let b = bytes as f64;
    if bytes < 1000 {
        format!("{bytes} bytes")
    } else if b < 1e6 {
        format!("{:.1} kB", b / 1e3)
    } else if b < 1e9 {
        format!("{:.1} MB", b / 1e6)
    } else {
        format!("{:.1} GB", b / 1e9)
    }
}

/// Refuses, before anything is written, a spill of `bytes` larger than
/// the free space of `work`'s disk: an I/O error (storage full) on the
/// work folder, `what` saying where the figure comes from.
///
/// # Errors
/// As above.
pub(super) fn check_space(work: &Path, bytes: u64, what: &str) -> Result<(), IoError> {
    match free_space(work) {
        Some(free) if bytes > free => Err(io_err(
            work,
            std::io::Error::new(
                std::io::ErrorKind::StorageFull,
                format!(
                    "the spill needs about {} ({what}) and its folder's disk has {} free",
                    size_text(bytes),
                    size_text(free)
                ),
            ),
        )),
        _ => Ok(()),
    }
}

/// Why `plan` cannot be resumed for `stamps` and `params` with tiles of
/// as many points as `size` gives its survey (`None`: it can). A tile or the merge may run on
/// another machine, with another memory: there the plan's tiles stand (a
/// tile too large for that machine is refused when read).
pub(super) fn mismatch(
    plan: &Plan,
    stamps: &[InputStamp],
    params: &str,
    size: super::TileSize,
    stage: super::Stage,
) -> Option<String> {
    let target = size.points(plan.survey.every_normal);
    use super::Stage;
    if plan.version != env!("CARGO_PKG_VERSION") {
        return Some(format!(
            "the plan was made by splatray {}, this is {}",
            plan.version,
            env!("CARGO_PKG_VERSION")
        ));
    }
    if plan.inputs.len() != stamps.len() {
        return Some(format!(
            "the plan was made for {} inputs, this run has {}",
            plan.inputs.len(),
            stamps.len()
        ));
    }
    for (a, b) in plan.inputs.iter().zip(stamps) {
        if a.path != b.path {
            return Some(format!(
                "the plan was made for {}, not {}",
                a.path.display(),
                b.path.display()
            ));
        }
        if a != b {
            return Some(format!(
                "{} changed since the plan was made ({} bytes then, {} now, or a new modification time)",
                b.path.display(),
                a.bytes,
                b.bytes
            ));
        }
    }
    if plan.params != params {
        return Some("the splat options differ from the plan's".into());
    }
    if plan.tile_points != target && !matches!(stage, Stage::Tile(_) | Stage::Merge) {
        return Some(format!(
            "the plan's tiles hold at most {} points, this run's {target} (--max-memory or --tile-points changed)",
            plan.tile_points
        ));
    }
    None
}

/// The plan in `plan_file` when this run carries it on: it matches the
/// inputs (`stamps`), the options (`params`) and the tile size (`size`).
/// One that does not match (or does not read) is `None`, a fresh start,
/// unless `opts.tiling.resume` asks to carry on: then it is refused in one line
/// saying what changed.
///
/// # Errors
/// With `opts.tiling.resume`: a plan that does not read or does not match.
pub(super) fn found_plan(
    plan_file: &Path,
    opts: &TiledOptions,
    stamps: &[InputStamp],
    params: &str,
    size: super::TileSize,
) -> Result<Option<Plan>, IoError> {
    let refuse = |why: String| {
        io_err(
            plan_file,
            std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!("cannot resume: {why} (run without --resume to start over)"),
            ),
        )
    };
    let plan = match std::fs::read_to_string(plan_file) {
        Ok(text) => match serde_json::from_str::<Plan>(&text) {
            Ok(p) => p,
            Err(e) if opts.tiling.resume => {
                return Err(refuse(format!("the plan does not read ({e})")));
            }
            Err(_) => return Ok(None),
        },
        Err(e) if opts.tiling.resume => return Err(io_err(plan_file, e)),
        Err(_) => return Ok(None),
    };
    match mismatch(&plan, stamps, params, size, opts.tiling.stage) {
        None => Ok(Some(plan)),
        Some(why) if opts.tiling.resume => Err(refuse(why)),
        Some(_) => Ok(None),
    }
}

/// The error of a stage that needs a plan where there is none (or one made
/// for other inputs or options).
pub(super) fn no_plan(work: &Path) -> IoError {
    data_err(
        work,
        "no tile plan for these inputs and options here: run the same command with --plan-only first"
            .into(),
    )
}

/// Removes what an earlier plan left in the work folder.
pub(super) fn clear_work(work: &Path) -> Result<(), IoError> {
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

/// The spill record of one point: position offset from the tile's centre
/// (3 × f32), then the normal and the colour (3 × f32 each) when the
/// cloud has them, then its scan (u16) when there are several.
pub(super) fn record_bytes(survey: &Survey) -> usize {
    12 + 12 * usize::from(survey.normals)
        + 12 * usize::from(survey.colors)
        + 2 * usize::from(!survey.scans.is_empty())
}

#[cfg(test)]
mod tests {
    use super::size_text;

    #[test]
    fn sizes_read_as_people_write_them() {
        assert_eq!(size_text(612), "612 bytes");
        assert_eq!(size_text(1_440_000), "1.4 MB");
        assert_eq!(size_text(48_300), "48.3 kB");
        assert_eq!(size_text(42_000_000_000), "42.0 GB");
    }
}
