//! The inputs read once: when the whole cloud's points fit a share of the
//! budget, every input file is decoded at once (one file a thread) and its
//! points kept in memory, in order, for the survey and the spill to
//! replay (the same batches of the same points, normals, colours and
//! scans); otherwise each pass streams the files from disk again.

use crate::io::{IoError, IoErrorKind, PointBatch, StreamInfo, stream_points};
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// Which attributes a kept input's records carry besides the position.
#[derive(Clone, Copy, PartialEq, Eq)]
struct Layout {
    normals: bool,
    colors: bool,
    scans: bool,
}

impl Layout {
    fn of(b: &PointBatch<'_>) -> Layout {
        Layout {
            normals: b.normals.is_some(),
            colors: b.colors.is_some(),
            scans: b.scans.is_some(),
        }
    }
    /// Bytes of one record.
    fn bytes(self) -> usize {
        24 + 12 * usize::from(self.normals)
            + 12 * usize::from(self.colors)
            + 2 * usize::from(self.scans)
    }
}

/// One input's stream kept in memory: its points as records (the f64
/// position's bytes, then the normal's, the colour's and the scan's when
/// its stream carries them) and what the stream held.
struct KeptFile {
    records: Vec<u8>,
    /// Points of each batch as streamed.
    batches: Vec<usize>,
    layout: Layout,
    info: StreamInfo,
}

/// Every input's stream kept in memory, in the inputs' order.
pub(super) struct Kept(Vec<KeptFile>);

/// Bytes a kept point takes at most: an f64 position, a normal and a
/// colour in f32, its scan.
pub(super) const KEPT_BYTES_PER_POINT: u64 = 24 + 12 + 12 + 2;

// The inputs are kept up to the budget's points at `BYTES_PER_POINT`:
// at most a sixth of the budget, freed before any tile is generated.
const _: () = assert!(6 * KEPT_BYTES_PER_POINT <= super::BYTES_PER_POINT);

/// The first capacity of an input's records: above the largest threshold
/// (32 MiB) past which the C allocator maps an allocation by itself, so the
/// records (grown and shrunk by remapping) go back to the system when
/// freed rather than staying with a decoding thread's allocator.
const FIRST_BYTES: usize = 40 << 20;

fn put_v3(out: &mut Vec<u8>, v: Vec3) {
    for c in v.to_array() {
        out.extend_from_slice(&c.to_le_bytes());
    }
}

/// Appends batch `b`'s points to `out` as records (of its [`Layout`]).
fn put_batch(out: &mut Vec<u8>, b: &PointBatch<'_>) {
    for (i, p) in b.world.iter().enumerate() {
        for c in p.to_array() {
            out.extend_from_slice(&c.to_le_bytes());
        }
        if let Some(n) = b.normals {
            put_v3(out, n[i]);
        }
        if let Some(c) = b.colors {
            put_v3(out, c[i]);
        }
        if let Some(s) = b.scans {
            out.extend_from_slice(&s[i].to_le_bytes());
        }
    }
}

/// The batch of `records` (of `layout`) into the buffers of `into`.
fn get_batch(records: &[u8], layout: Layout, into: &mut Buffers) {
    into.clear();
    let f64_at = |r: &[u8], at: usize| {
        f64::from_le_bytes(r[at..at + 8].try_into().unwrap_or_default())
    };
    let v3_at = |r: &[u8], at: usize| {
        let f = |k: usize| f32::from_le_bytes(r[at + k..at + k + 4].try_into().unwrap_or_default());
        Vec3::new(f(0), f(4), f(8))
    };
    for r in records.chunks_exact(layout.bytes()) {
        into.world.push(DVec3::new(f64_at(r, 0), f64_at(r, 8), f64_at(r, 16)));
        let mut at = 24;
        if layout.normals {
            into.normals.push(v3_at(r, at));
            at += 12;
        }
        if layout.colors {
            into.colors.push(v3_at(r, at));
            at += 12;
        }
        if layout.scans {
            into.scans.push(u16::from_le_bytes([r[at], r[at + 1]]));
        }
    }
}

/// The buffers a replayed batch is handed out from.
#[derive(Default)]
struct Buffers {
    world: Vec<DVec3>,
    normals: Vec<Vec3>,
    colors: Vec<Vec3>,
    scans: Vec<u16>,
}

impl Buffers {
    fn clear(&mut self) {
        self.world.clear();
        self.normals.clear();
        self.colors.clear();
        self.scans.clear();
    }
    fn view(&self, layout: Layout) -> PointBatch<'_> {
        PointBatch {
            world: &self.world,
            normals: layout.normals.then_some(&self.normals[..]),
            colors: layout.colors.then_some(&self.colors[..]),
            scans: layout.scans.then_some(&self.scans[..]),
        }
    }
}

/// Every input decoded at once (rayon, one file a task) and kept, when
/// they hold at most `cap` points in all; `None` when they hold more or an
/// input fails to read (the passes then stream from disk, and the failure
/// is met there, as it would be without this).
pub(super) fn keep_inputs(inputs: &[PathBuf], cap: u64) -> Option<Kept> {
    let total = AtomicU64::new(0);
    let over = AtomicBool::new(false);
    let files = inputs
        .par_iter()
        .map(|path| {
            if over.load(Ordering::Relaxed) {
                return None;
            }
            let mut records = Vec::with_capacity(FIRST_BYTES);
            let mut layout = None;
            let mut batches = Vec::new();
            let info = stream_points(path, |b| {
                let n = b.world.len() as u64;
                let here = Layout::of(b);
                // A stream whose batches differ in what they carry is not
                // kept (none does).
                if *layout.get_or_insert(here) != here
                    || total.fetch_add(n, Ordering::Relaxed) + n > cap
                    || over.load(Ordering::Relaxed)
                {
                    over.store(true, Ordering::Relaxed);
                    return Err(String::new());
                }
                put_batch(&mut records, b);
                batches.push(b.world.len());
                Ok(())
            })
            .ok()?;
            records.shrink_to_fit();
            let layout = layout.unwrap_or(Layout {
                normals: false,
                colors: false,
                scans: false,
            });
            Some(KeptFile {
                records,
                batches,
                layout,
                info,
            })
        })
        .collect::<Option<Vec<_>>>()?;
    Some(Kept(files))
}

/// Input `k` (`path`) into `each` a batch at a time, as
/// [`stream_points`] gives it: from `kept` when the inputs were kept,
/// else from disk.
///
/// # Errors
/// As [`stream_points`].
pub(super) fn replay(
    kept: Option<&Kept>,
    k: usize,
    path: &Path,
    mut each: impl FnMut(&PointBatch<'_>) -> Result<(), String>,
) -> Result<StreamInfo, IoError> {
    let Some(file) = kept.and_then(|c| c.0.get(k)) else {
        return stream_points(path, each);
    };
    let mut buffers = Buffers::default();
    let rb = file.layout.bytes();
    let mut at = 0;
    for &n in &file.batches {
        get_batch(&file.records[at..at + n * rb], file.layout, &mut buffers);
        at += n * rb;
        each(&buffers.view(file.layout)).map_err(|e| IoError::new(path, IoErrorKind::Data(e)))?;
    }
    Ok(file.info.clone())
}
