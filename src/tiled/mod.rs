//! Out-of-core splat generation: a cloud of any size turned into splats in
//! tiles that each fit a memory budget.
//!
//! 1. **Survey** (one streaming pass over every input): the count, the
//!    bounds in f64, and a reservoir sample of 2^20 positions.
//! 2. **Plan**: `ϵ` is the whole cloud's (`epsilon_rel` times its
//!    diagonal, or where a few far points widen the box, the diagonal of
//!    the sample's box without its extreme thousandth); the halo is
//!    `HALO_EPS` (12) `ϵ` wide. The bounds are split k-d fashion at the
//!    sample's medians along the longest side until each tile's core plus
//!    halo holds at most the budget's points (estimated from the sample).
//!    The split planes give every point of space exactly one tile: the
//!    tile whose core holds it.
//! 3. **Spill** (a second streaming pass): each point is appended to the
//!    file of every tile whose core-plus-halo box holds it (positions as
//!    f32 offsets from the tile's centre, normals and colours carried).
//!    The inputs are decoded once, a file a thread, when the budget
//!    holds their points ([`inputs`]): the survey and the spill replay
//!    them. A new plan of one tile run whole keeps its spill in memory.
//! 4. **Generate**, tile by tile: the tile's points become a cloud, splats
//!    are generated as for any cloud ([`crate::pipeline::generate`]: outliers,
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
//!
//! The stages live in their own files: [`plan`] (survey and k-d plan),
//! [`spill`] (the points into per-tile files), [`tile`] (each tile's
//! generation) and [`merge`] (orientation across tiles and the one output
//! file); [`report`] holds what a run reports.

mod inputs;
mod merge;
mod plan;
mod report;
mod spill;
mod tile;

pub use report::{Box3, TileLayout, TileSummary, TiledReport, TiledSeconds};

use crate::io::{IoError, IoErrorKind};
use crate::progress::Progress;
use crate::splat::SplatParams;
use glam::DVec3;
use merge::{merge, reconcile};
use plan::{check_space, clear_work, found_plan, new_plan, no_plan, stamp};
use spill::{remove_spills, spill, spill_in_memory, spills_whole};
use std::path::{Path, PathBuf};
use std::time::Instant;
use tile::run_tiles;

/// The halo's width in `ϵ` (see the module's text): a splat's normal
/// field reads points within at most `field_radius_factor` (1.2) times its
/// radius of its centre, and a radius reaches
/// `MAX_RADIUS_EPS` (8) `ϵ` on a densely sampled surface: 9.6 `ϵ`, plus [`NORMALS_REACH_EPS`] for the
/// neighbourhoods those points' normals were estimated from.
pub const HALO_EPS: f64 = 12.0;

/// What the neighbourhoods of a splat's points add to its reach, in `ϵ`.
pub const NORMALS_REACH_EPS: f64 = 2.0;

/// Bytes a point takes while its tile is generated, for planning, where
/// normals are estimated: measured 292 B a point for a whole 10M-point
/// cloud (bunny samples, positions only) read and generated in memory
/// (`splat --holdout 0`, peak RSS 2.92 GB; 211 B before the graph kept
/// each point's wide neighbourhood, `splat::knn::Wide`, and 161 B before
/// that); in one tile, the peak's growth from 1M to 2M points is 299 B a
/// point on a survey with outliers, 297 on a noisy bunny sample and 302 on
/// a clean one (475 on the survey while the graph was repaired beside a
/// copy of itself, `splat::knn::Knn::retain`); rounded up.
pub const BYTES_PER_POINT: u64 = 320;

/// [`BYTES_PER_POINT`] for a cloud whose every point comes with a usable
/// normal: none is estimated, so no wide neighbourhoods are held. The
/// peak's growth from 1M to 2M bunny samples with normals in one tile is
/// 188 B a point (a 100M-point run's largest tile peaked at 162 B a point
/// of it); rounded up.
pub const BYTES_PER_POINT_GIVEN_NORMALS: u64 = 220;

/// The bytes a point of a tile is planned at: [`BYTES_PER_POINT_GIVEN_NORMALS`]
/// when the survey found a usable normal on every point, else
/// [`BYTES_PER_POINT`].
#[must_use]
pub fn tile_bytes_per_point(every_normal: bool) -> u64 {
    if every_normal {
        BYTES_PER_POINT_GIVEN_NORMALS
    } else {
        BYTES_PER_POINT
    }
}

/// How many points a tile may hold: the memory budget's (whose bytes a
/// point depend on whether normals are given, [`tile_bytes_per_point`])
/// and at most `--tile-points`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct TileSize {
    /// Bytes for tiles: the budget less [`FIXED_BYTES`].
    bytes: u64,
    /// `--tile-points`.
    forced: Option<u64>,
}

impl TileSize {
    /// The most points a tile holds when the survey found a usable normal
    /// on every point (`every_normal`) or not.
    pub(crate) fn points(self, every_normal: bool) -> u64 {
        let budget = self.bytes / tile_bytes_per_point(every_normal);
        self.forced.map_or(budget, |t| t.min(budget))
    }
}

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
pub(crate) const FIXED_BYTES: u64 = 256 << 20;

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
    /// The folder for the plan, spill files and finished tiles (made if
    /// missing, removed after a successful merge).
    pub work: PathBuf,
    /// Where the scanner stood, in the inputs' coordinates: given, or
    /// (`None`) a single input's own (a PCD's `VIEWPOINT`).
    pub viewpoint: Option<DVec3>,
    /// Ignore the inputs' own viewpoints.
    pub no_viewpoint: bool,
    /// Tile size, stage and resuming.
    pub tiling: Tiling,
}

/// What is asked of tiled generation beyond its memory: the tiles' size,
/// the stage, resuming (`splat --tile-points`, `--plan-only`, `--tile`,
/// `--merge-only`, `--resume`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Tiling {
    /// At most this many points (core and halo) per tile, below what the
    /// memory allows (to force small tiles, as the tests do).
    pub tile_points: Option<u64>,
    /// Which part to run.
    pub stage: Stage,
    /// Carry on from the work folder's plan, or refuse in one line (no
    /// plan there, or one made for other inputs or options); `false`: the
    /// plan is resumed when it matches and made anew when it does not.
    pub resume: bool,
}

pub(crate) fn io_err(path: &Path, e: std::io::Error) -> IoError {
    IoError::new(path, IoErrorKind::Io(e))
}

pub(crate) fn data_err(path: &Path, msg: String) -> IoError {
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
    if opts.tiling.resume && !work.join("plan.json").exists() {
        return Err(io_err(
            work,
            std::io::Error::new(
                std::io::ErrorKind::NotFound,
                "nothing to resume: no tile plan here (run without --resume)",
            ),
        ));
    }
    std::fs::create_dir_all(work).map_err(|e| io_err(work, e))?;
    let stamps = inputs
        .iter()
        .map(|p| stamp(p))
        .collect::<Result<Vec<_>, _>>()?;
    let size = TileSize {
        bytes: opts.max_memory.saturating_sub(FIXED_BYTES),
        forced: opts.tiling.tile_points,
    };
    if size.points(false) < 1000 {
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
    let old = found_plan(&plan_file, opts, &stamps, &params_text, size)?;
    let mut report = TiledReport {
        max_memory: opts.max_memory,
        ..TiledReport::default()
    };
    let resumed = old.is_some();
    if !resumed && matches!(opts.tiling.stage, Stage::Tile(_) | Stage::Merge) {
        return Err(no_plan(work));
    }
    // The inputs decoded once, in parallel, when the budget holds their
    // points at `BYTES_PER_POINT` (kept, they take at most
    // `inputs::KEPT_BYTES_PER_POINT` each): the survey and the spill replay
    // them instead of reading the files twice.
    let mut kept = None;
    let plan = match old {
        Some(p) => p,
        None => {
            // A different plan: nothing in the folder is reusable.
            clear_work(work)?;
            kept = inputs::keep_inputs(inputs, size.bytes / BYTES_PER_POINT);
            new_plan(
                inputs,
                kept.as_ref(),
                params,
                opts,
                stamps,
                params_text,
                size,
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
    report.layout.cores.clone_from(&plan.tiles);
    report.layout.bounds = Some(plan.survey.bounds);
    // A new plan of one tile, generated here and now: its spill stays in
    // memory, the cloud `read_spill` would give (no spill file to resume:
    // a rerun spills again).
    let in_memory = !resumed && opts.tiling.stage == Stage::All && plan.tiles.len() == 1;
    let mut held = None;
    let counts_file = work.join("spilled.json");
    let spilled: Option<Vec<(u64, u64)>> = std::fs::read_to_string(&counts_file)
        .ok()
        .filter(|_| resumed)
        .and_then(|s| serde_json::from_str(&s).ok())
        // A spill file cut short or gone (its tile unfinished): spill again
        // when this stage may.
        .filter(|c: &Vec<(u64, u64)>| {
            !matches!(opts.tiling.stage, Stage::All | Stage::Plan)
                || spills_whole(&plan, work, c, |t| tile::finished_tile(work, t).is_some())
        });
    let counts: Vec<(u64, u64)> = match spilled {
        Some(c) => c,
        None if opts.tiling.stage != Stage::All && opts.tiling.stage != Stage::Plan => {
            return Err(no_plan(work));
        }
        None => {
            let json =
                serde_json::to_string(&plan).map_err(|e| data_err(&plan_file, e.to_string()))?;
            crate::io::write_text(&plan_file, &json)?;
            if resumed {
                // What an interrupted spill left, then the disk checked
                // again for the whole spill (a new plan was checked).
                remove_spills(work, plan.tiles.len());
                check_space(
                    work,
                    plan.spill_bytes,
                    &format!("the plan's {} tiles", plan.tiles.len()),
                )?;
            }
            let t1 = Instant::now();
            if in_memory {
                let (cloud, c) = spill_in_memory(inputs, kept.take(), &plan, work, progress)?;
                report.seconds.spill = t1.elapsed().as_secs_f64();
                held = Some(cloud);
                vec![c]
            } else {
                let c = spill(inputs, kept.as_ref(), &plan, work, progress)?;
                report.seconds.spill = t1.elapsed().as_secs_f64();
                let json = serde_json::to_string(&c)
                    .map_err(|e| data_err(&counts_file, e.to_string()))?;
                crate::io::write_text(&counts_file, &json)?;
                c
            }
        }
    };
    drop(kept);
    report.spilled = counts.iter().map(|c| c.0).sum();
    let t2 = Instant::now();
    let n = plan.tiles.len();
    if let Stage::Tile(t) = opts.tiling.stage
        && t >= n
    {
        return Err(data_err(
            work,
            format!("--tile {t}: the plan has tiles 0 to {}", n - 1),
        ));
    }
    run_tiles(&plan, params, opts, &counts, held, progress, &mut report)?;
    report.seconds.generate = t2.elapsed().as_secs_f64();
    if matches!(opts.tiling.stage, Stage::All | Stage::Merge) {
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
