//! The spill stage: each point written to the file of every tile whose
//! core or halo holds it, and a tile's file read back as a cloud.

use super::plan::{Plan, record_bytes};
use super::report::Box3;
use super::inputs::{Kept, replay};
use super::{io_err, tile_bytes_per_point};
use crate::io::{IoError, IoErrorKind};
use crate::progress::{Progress, notify};
use crate::splat::PointCloud;
use glam::{DVec3, Vec3};
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

/// Writes every tile's spill file from `inputs` and returns each tile's
/// (points, core points). On any failure the spill files are removed (a
/// spill is whole or absent: the rerun spills again) and the error names
/// the file at fault: the input that did not read, or the spill file that
/// could not be written (a full disk, a file-size limit), as an I/O error.
///
/// # Errors
/// As above.
pub(super) fn spill(
    inputs: &[PathBuf],
    kept: Option<&Kept>,
    plan: &Plan,
    work: &Path,
    progress: Option<Progress<'_>>,
) -> Result<Vec<(u64, u64)>, IoError> {
    let r = spill_files(inputs, kept, plan, work, progress);
    if r.is_err() {
        remove_spills(work, plan.tiles.len());
    }
    r
}

/// Whether every unfinished tile's (`finished` says which are) spill file holds the records `counts`
/// says the spill wrote (files are synced before `spilled.json` is written,
/// so only something outside the run makes this false).
pub(super) fn spills_whole(
    plan: &Plan,
    work: &Path,
    counts: &[(u64, u64)],
    finished: impl Fn(usize) -> bool,
) -> bool {
    let rb = record_bytes(&plan.survey) as u64;
    counts.iter().enumerate().all(|(t, c)| {
        finished(t) || std::fs::metadata(spill_path(work, t)).is_ok_and(|m| m.len() == c.0 * rb)
    })
}

/// Removes tiles `0..n`'s spill files (those there).
pub(super) fn remove_spills(work: &Path, n: usize) {
    for t in 0..n {
        let _ = std::fs::remove_file(spill_path(work, t));
    }
}

/// The error of a spill file that could not be written: an I/O error on
/// that file, saying what was being written.
fn spill_write_err(work: &Path, t: usize, e: &std::io::Error) -> IoError {
    let p = spill_path(work, t);
    let what = format!("writing tile {t}'s spill file: {e}");
    io_err(&p, std::io::Error::new(e.kind(), what))
}

fn spill_files(
    inputs: &[PathBuf],
    kept: Option<&Kept>,
    plan: &Plan,
    work: &Path,
    progress: Option<Progress<'_>>,
) -> Result<Vec<(u64, u64)>, IoError> {
    let mut writers = Vec::with_capacity(plan.tiles.len());
    for t in 0..plan.tiles.len() {
        let p = spill_path(work, t);
        let f = std::fs::File::create(&p).map_err(|e| io_err(&p, e))?;
        writers.push(BufWriter::with_capacity(1 << 16, f));
    }
    let counts = spill_into(inputs, kept, plan, &mut writers, progress, |t, e| {
        spill_write_err(work, t, e)
    })?;
    for (t, w) in writers.into_iter().enumerate() {
        w.into_inner()
            .map_err(|e| spill_write_err(work, t, e.error()))?
            .sync_all()
            .map_err(|e| spill_write_err(work, t, &e))?;
    }
    Ok(counts)
}

/// The spill of a plan of one tile kept in memory, for the tile generated
/// in this process: the records its spill file would hold, read back as
/// [`read_spill`] reads the file (the same cloud, no file written), and
/// its (points, core points).
///
/// # Errors
/// An input that does not read, or too little memory for the tile.
pub(super) fn spill_in_memory(
    inputs: &[PathBuf],
    kept: Option<Kept>,
    plan: &Plan,
    work: &Path,
    progress: Option<Progress<'_>>,
) -> Result<(PointCloud, (u64, u64)), IoError> {
    let mut bytes = vec![Vec::new()];
    let counts = spill_into(inputs, kept.as_ref(), plan, &mut bytes, progress, |_, e| {
        io_err(work, std::io::Error::new(e.kind(), e.to_string()))
    })?;
    drop(kept);
    let p = spill_path(work, 0);
    let rb = record_bytes(&plan.survey) as u64;
    check_tile_memory(plan, &p, 0, bytes[0].len() as u64 / rb)?;
    let cloud = parse_spill(plan, &p, 0, &bytes[0][..], bytes[0].len() as u64)?;
    Ok((cloud, counts[0]))
}

/// Appends every point of `inputs` (replayed from `kept` when there) to
/// `writers[t]` for every tile `t` whose core or halo holds it; returns each
/// tile's (points, core points). A failed write is `write_err(t, e)`.
fn spill_into<W: Write>(
    inputs: &[PathBuf],
    kept: Option<&Kept>,
    plan: &Plan,
    writers: &mut [W],
    progress: Option<Progress<'_>>,
    write_err: impl Fn(usize, &std::io::Error) -> IoError,
) -> Result<Vec<(u64, u64)>, IoError> {
    let n = plan.tiles.len();
    let centres: Vec<DVec3> = plan.tiles.iter().map(Box3::centre).collect();
    let grown: Vec<Box3> = plan.tiles.iter().map(|b| b.grown(plan.halo)).collect();
    let mut counts = vec![(0u64, 0u64); n];
    let mut near = Vec::new();
    let mut rec = Vec::with_capacity(36);
    let mut done = 0u64;
    let (with_n, with_c) = (plan.survey.normals, plan.survey.colors);
    let with_s = !plan.survey.scans.is_empty();
    // A spill write that fails stops the stream; its error (on the spill
    // file, not the input) is kept here.
    let mut failed: Option<IoError> = None;
    for (k, path) in inputs.iter().enumerate() {
        let first_scan = plan.survey.scan_offsets.get(k).copied().unwrap_or(0);
        let streamed = replay(kept, k, path, |b| {
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
                    if let Err(e) = writers[t].write_all(&rec) {
                        failed = Some(write_err(t, &e));
                        return Err(e.to_string());
                    }
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
        });
        if let Some(e) = failed.take() {
            return Err(e);
        }
        streamed?;
    }
    Ok(counts)
}

pub(super) fn spill_path(work: &Path, t: usize) -> PathBuf {
    work.join(format!("spill-{t:05}.bin"))
}

/// Refuses tile `t` of `points` points (spill file `p`) when the memory
/// this process may use cannot generate it.
fn check_tile_memory(plan: &Plan, p: &Path, t: usize, points: u64) -> Result<(), IoError> {
    crate::memory::check(
        &format!("tile {t}"),
        points * tile_bytes_per_point(plan.survey.every_normal),
    )
    .map_err(|e| IoError::new(p, IoErrorKind::Memory(e)))
}

/// The tile's points as a cloud centred on the tile.
pub(super) fn read_spill(plan: &Plan, work: &Path, t: usize) -> Result<PointCloud, IoError> {
    let p = spill_path(work, t);
    let rb = record_bytes(&plan.survey);
    let bytes = std::fs::metadata(&p).map_err(|e| io_err(&p, e))?.len();
    check_tile_memory(plan, &p, t, bytes / rb as u64)?;
    let r =
        BufReader::with_capacity(1 << 20, std::fs::File::open(&p).map_err(|e| io_err(&p, e))?);
    parse_spill(plan, &p, t, r, bytes)
}

/// Tile `t`'s spill records, `bytes` of them read from `r` (the file `p`
/// or its bytes in memory), as a cloud centred on the tile.
fn parse_spill(
    plan: &Plan,
    p: &Path,
    t: usize,
    mut r: impl Read,
    bytes: u64,
) -> Result<PointCloud, IoError> {
    let rb = record_bytes(&plan.survey);
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
        r.read_exact(&mut rec).map_err(|e| io_err(p, e))?;
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
            ..crate::splat::Scans::default()
        }),
        ..PointCloud::default()
    })
}
