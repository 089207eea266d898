//! The merge stage: the tiles' orientations made to agree, and their
//! splat files joined into the one output.

use super::plan::Plan;
use super::tile::{clip_lines, color_fields, halo_path, tile_path};
use super::{data_err, io_err};
use crate::io::{IoError, splat_header_layout, splat_row_bytes, write_atomic};
use crate::progress::{Progress, notify};
use crate::splat::{Splat, SplatParams};
use glam::{DVec3, Vec3};
use std::io::{BufWriter, Read, Seek, SeekFrom, Write};
use std::path::Path;

/// Joins the tiles' splat files into `output`: one header with the total
/// count, then each tile's records in tile order.
pub(super) fn merge(
    plan: &Plan,
    params: &SplatParams,
    work: &Path,
    output: &Path,
    flips: &[bool],
    progress: Option<Progress<'_>>,
) -> Result<u64, IoError> {
    let n = plan.tiles.len();
    let with_fields = color_fields(plan, params);
    let clips = clip_lines(params);
    let row_bytes = splat_row_bytes(with_fields, clips);
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
    let header = splat_header_layout(total, DVec3::from(plan.origin), with_fields, clips);
    // A tile that does not read is named as itself, not as the output.
    let mut read_failed: Option<IoError> = None;
    let written = write_atomic(output, |tmp| -> std::io::Result<()> {
        let mut out = BufWriter::with_capacity(1 << 20, std::fs::File::create(tmp)?);
        out.write_all(header.as_bytes())?;
        let mut buf = vec![0u8; row_bytes * 4096];
        for (t, (p, head)) in bodies.iter().enumerate() {
            let flip = flips.get(t).copied().unwrap_or(false);
            match copy_tile(p, *head, flip, &mut buf, &mut out) {
                Ok(()) => {}
                Err(Fail::Write(e)) => return Err(e),
                Err(Fail::Read(e)) => {
                    read_failed = Some(io_err(p, e));
                    return Err(std::io::Error::other("a tile did not read"));
                }
            }
            notify(progress, "merging", (t + 1) as f64 / n as f64);
        }
        out.flush()
    });
    if let Some(e) = read_failed {
        return Err(e);
    }
    written?;
    Ok(total)
}

/// Which side of a copy failed.
enum Fail {
    Read(std::io::Error),
    Write(std::io::Error),
}

/// Appends the records of the tile file `p` (after its `head` bytes of
/// header) to `out`, turned over when `flip`: the normal and the field's
/// four coefficients change sign (the sign bit of each little-endian f32),
/// so the field gives the opposite normal everywhere (eq. 4). `buf` holds
/// a whole number of records.
fn copy_tile(
    p: &Path,
    head: u64,
    flip: bool,
    buf: &mut [u8],
    out: &mut impl Write,
) -> Result<(), Fail> {
    let row_bytes = buf.len() / 4096;
    let mut f = std::fs::File::open(p).map_err(Fail::Read)?;
    f.seek(SeekFrom::Start(head)).map_err(Fail::Read)?;
    loop {
        // Fill the buffer (a short read is not the end).
        let mut got = 0;
        while got < buf.len() {
            match f.read(&mut buf[got..]) {
                Ok(0) => break,
                Ok(k) => got += k,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(Fail::Read(e)),
            }
        }
        if got == 0 {
            return Ok(());
        }
        if flip {
            for row in buf[..got].chunks_exact_mut(row_bytes) {
                for k in FLIPPED_FLOATS {
                    row[4 * k + 3] ^= 0x80;
                }
            }
        }
        out.write_all(&buf[..got]).map_err(Fail::Write)?;
    }
}

/// A tile's splat file (which may hold none).
pub(super) fn tile_splats(p: &Path) -> Result<Vec<Splat>, IoError> {
    let bytes = std::fs::metadata(p).map_err(|e| io_err(p, e))?.len();
    if bytes == header_len(p)? {
        return Ok(Vec::new());
    }
    Ok(crate::io::read_splats(p)?.splats)
}

/// The floats of a splat row that change sign when the splat is turned
/// over: `nx ny nz` and `field_xc field_yc field_alpha field_beta`.
pub(super) const FLIPPED_FLOATS: [usize; 7] = [3, 4, 5, 14, 15, 16, 17];

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
pub(super) fn reconcile(plan: &Plan, work: &Path) -> Result<Vec<bool>, IoError> {
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
pub(super) fn header_len(p: &Path) -> Result<u64, IoError> {
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
