//! The tile stage: each tile's points generated as a cloud, its splats
//! kept where their centre lies in its core.

use super::plan::Plan;
use super::report::{TileSummary, TiledReport};
use super::spill::{read_spill, spill_path};
use super::{
    FIXED_BYTES, NORMALS_REACH_EPS, Stage, TILES_IN_FLIGHT, TiledOptions, data_err,
    tile_bytes_per_point,
};
use crate::io::{IoError, encode_splats_layout, write_bytes};
use crate::progress::{Progress, notify};
use crate::splat::color::ColorField;
use crate::splat::{PointCloud, Splat, SplatParams};
use glam::DVec3;
use std::path::{Path, PathBuf};
use std::time::Instant;

pub(super) fn tile_path(work: &Path, t: usize) -> PathBuf {
    work.join(format!("tile-{t:05}.ply"))
}

pub(super) fn halo_path(work: &Path, t: usize) -> PathBuf {
    work.join(format!("halo-{t:05}.ply"))
}

pub(super) fn tile_report_path(work: &Path, t: usize) -> PathBuf {
    work.join(format!("tile-{t:05}.json"))
}

/// Generates tile `t` (its cloud `held` in memory, else read from its
/// spill file) and writes its kept splats (centres as offsets from the
/// plan's origin) and its summary.
pub(super) fn generate_tile(
    plan: &Plan,
    params: &SplatParams,
    work: &Path,
    t: usize,
    counts: (u64, u64),
    held: Option<PointCloud>,
    progress: Option<Progress<'_>>,
) -> Result<TileSummary, IoError> {
    let t0 = Instant::now();
    let cloud = match held {
        Some(c) => c,
        None => read_spill(plan, work, t)?,
    };
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
        let core = &plan.tiles[t];
        let local = |c: [f64; 3]| (DVec3::from(c) - cloud.origin).as_vec3();
        let tile_params = SplatParams {
            epsilon_abs: Some(plan.epsilon),
            viewpoint: cloud.viewpoint,
            color_fields: with_fields,
            // Lean growth's gate reads the core: the halo's cut edges are
            // no border of the surface.
            gate_within: Some([local(core.lo), local(core.hi)]),
            ..params.clone()
        };
        let generated = crate::pipeline::generate(&cloud, &tile_params, progress);
        match generated {
            Ok(g) => {
                let (splats, mut fields) = (g.splats, g.color_fields);
                summary.grown = splats.len();
                summary.lean = g.report.lean.as_ref().is_some_and(|l| l.used);
                summary.warnings = g.report.warnings;
                summary.thinned = (g.report.skipped_points.iter())
                    .filter(|s| s.reason.starts_with("denser than"))
                    .map(|s| s.count as u64)
                    .sum();
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
                    let r = f64::from(s.radii.max_element());
                    // Lean growth's field reads its points within `REACH`
                    // of its radius before the `SCALE`, and no normal a
                    // point; the stages' reads normals of neighbourhoods.
                    let reach = if summary.lean {
                        f64::from(crate::splat::lean::REACH / crate::splat::lean::SCALE) * r
                    } else {
                        f64::from(params.field_radius_factor) * r + NORMALS_REACH_EPS * plan.epsilon
                    };
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
    write_bytes(
        &out,
        &encode_splats_layout(&out, &kept, fields, clip_lines(params), origin)?,
    )?;
    if plan.reconciles() {
        crate::io::write_splats(&halo_path(work, t), &halo, origin)?;
    }
    let json = serde_json::to_string(&summary).map_err(|e| data_err(&out, e.to_string()))?;
    crate::io::write_text(&tile_report_path(work, t), &json)?;
    let _ = std::fs::remove_file(spill_path(work, t));
    Ok(summary)
}

/// Generates this run's tiles of `plan` (`counts`: each tile's spilled
/// points and core points; `held`: a plan of one tile's cloud, spilled in
/// memory), up to [`TILES_IN_FLIGHT`] at once when the
/// largest fit the memory budget together, and puts every tile's summary in
/// `report`: made now, finished before (resumed), or only planned.
pub(super) fn run_tiles(
    plan: &Plan,
    params: &SplatParams,
    opts: &TiledOptions,
    counts: &[(u64, u64)],
    held: Option<PointCloud>,
    progress: Option<Progress<'_>>,
    report: &mut TiledReport,
) -> Result<(), IoError> {
    let held = std::sync::Mutex::new(held);
    let work = &opts.work;
    let n = plan.tiles.len();
    // This run's tiles, up to TILES_IN_FLIGHT at a time when the largest
    // of them fit the budget together (each worker takes the next): each
    // tile's bytes are its own, whichever worker made them.
    let mine: Vec<usize> = (0..n)
        .filter(|&t| {
            (opts.tiling.stage == Stage::All || opts.tiling.stage == Stage::Tile(t))
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
        largest.saturating_mul(tile_bytes_per_point(plan.survey.every_normal))
            <= opts.max_memory.saturating_sub(FIXED_BYTES);
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
                    let cloud = held.lock().ok().and_then(|mut h| h.take());
                    let r = generate_tile(
                        plan,
                        params,
                        work,
                        t,
                        counts[t],
                        cloud,
                        Some(&tile_progress),
                    );
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
            (None, None) if opts.tiling.stage == Stage::Merge => {
                return Err(data_err(
                    work,
                    format!("tile {t} of {n} is not finished: run it with --tile {t}"),
                ));
            }
            (None, None)
                if opts.tiling.stage == Stage::All || opts.tiling.stage == Stage::Tile(t) =>
            {
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

/// Tile `t`'s summary when it is finished: the splat file is written
/// before the summary, so a summary means a finished tile.
pub(super) fn finished_tile(work: &Path, t: usize) -> Option<TileSummary> {
    std::fs::read_to_string(tile_report_path(work, t))
        .ok()
        .and_then(|s| serde_json::from_str::<TileSummary>(&s).ok())
        .filter(|_| tile_path(work, t).exists())
}

/// Whether the tiles write clip lines: every tile of a run with creases
/// does, clipped splats or not, so the merge joins records of one size.
pub(super) fn clip_lines(params: &SplatParams) -> bool {
    params.creases != crate::splat::Creases::Off
}

/// Whether the tiles write colour fields: the survey found colours and the
/// parameters ask for fields (every tile the same layout, so the merge can
/// join their records; a tile of one colour writes zero fields).
pub(super) fn color_fields(plan: &Plan, params: &SplatParams) -> bool {
    plan.survey.colors && params.color_fields
}
