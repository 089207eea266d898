//! ASPRS LAS and LASzip-compressed LAZ point clouds through the `las` crate
//! (with its `laz` feature): coordinates come through each file's scale and
//! offset in f64 (georeferenced lidar keeps its precision until the cloud is
//! re-centred), 16-bit colours where the point format has them.

use super::batch::{BATCH, PointBatch, StreamInfo};
use super::{IoErrorKind, PointCloud, cloud_from_world, srgb_to_linear};
use glam::{DVec3, Vec3};

/// Bytes of point records read per batch: neither the header's count nor
/// its record length is trusted for one allocation (a corrupt record
/// length of 65,535 bytes times a million points asked for 68 GB).
const BATCH_BYTES: u64 = 1 << 26;

/// Bytes a read point takes at most here: an f64 position and an f32
/// colour.
const POINT_BYTES: u64 = 36;

/// Bytes of a file at any offset: the whole file in memory, or the file
/// on disk (read where asked, so a file is checked without reading it
/// whole).
trait Bytes {
    /// The file's length.
    fn len(&self) -> usize;
    /// `n` bytes at `at`, `None` past the end.
    fn get(&self, at: usize, n: usize) -> Option<Vec<u8>>;
}

/// A file's bytes in memory as [`Bytes`].
struct InMemory<'a>(&'a [u8]);

impl Bytes for InMemory<'_> {
    fn len(&self) -> usize {
        self.0.len()
    }
    fn get(&self, at: usize, n: usize) -> Option<Vec<u8>> {
        self.0.get(at..at.checked_add(n)?).map(<[u8]>::to_vec)
    }
}

/// A file on disk as [`Bytes`].
struct OnDisk {
    file: std::cell::RefCell<std::fs::File>,
    len: usize,
}

impl Bytes for OnDisk {
    fn len(&self) -> usize {
        self.len
    }
    fn get(&self, at: usize, n: usize) -> Option<Vec<u8>> {
        use std::io::{Read, Seek, SeekFrom};
        if at.checked_add(n)? > self.len {
            return None;
        }
        let mut f = self.file.borrow_mut();
        f.seek(SeekFrom::Start(at as u64)).ok()?;
        let mut buf = vec![0u8; n];
        f.read_exact(&mut buf).ok()?;
        Some(buf)
    }
}

/// Little-endian fields of a LAS file's raw bytes (`None` past its end).
struct Raw<'a>(&'a dyn Bytes);

impl Raw<'_> {
    fn at<const N: usize>(&self, at: usize) -> Option<[u8; N]> {
        self.0.get(at, N)?.try_into().ok()
    }
    fn u16(&self, at: usize) -> Option<u16> {
        self.at(at).map(u16::from_le_bytes)
    }
    fn u32(&self, at: usize) -> Option<u32> {
        self.at(at).map(u32::from_le_bytes)
    }
    fn i64(&self, at: usize) -> Option<i64> {
        self.at(at).map(i64::from_le_bytes)
    }
    /// Point data format (byte 104): LASzip sets bit 7 when compressed.
    fn compressed(&self) -> bool {
        self.at::<1>(104).is_some_and(|f| f[0] & 0x80 != 0)
    }
}

/// A LAZ body's chunk table, checked before the `laz` crate reads it: that
/// crate reserves the table's claimed entry count at once (a corrupt count
/// asked for 31 GB and aborted the process). Each entry takes at least one
/// byte of the file, so the count is bounded by the file's size.
fn check_chunk_table(raw: &Raw<'_>) -> Result<(), IoErrorKind> {
    let Some(start) = raw.u32(96) else {
        return Ok(());
    };
    // The table's offset opens the point data; -1 means it is written in
    // the file's last eight bytes.
    let mut offset = raw.i64(start as usize).unwrap_or(-1);
    if offset == -1 {
        offset = raw
            .0
            .len()
            .checked_sub(8)
            .and_then(|e| raw.i64(e))
            .unwrap_or(-1);
    }
    let Some(count) = usize::try_from(offset)
        .ok()
        .and_then(|o| raw.u32(o.checked_add(4)?))
    else {
        return Ok(());
    };
    if count as usize > raw.0.len() {
        return Err(IoErrorKind::Data(format!(
            "the LAZ chunk table claims {count} chunks in a {}-byte file",
            raw.0.len()
        )));
    }
    Ok(())
}

/// The LASzip VLR of a compressed file must describe at least one item
/// (the `laz` crate panics on none); checked by walking the VLRs.
fn check_laszip_items(raw: &Raw<'_>) -> Result<(), IoErrorKind> {
    let (Some(header_size), Some(vlrs)) = (raw.u16(94), raw.u32(100)) else {
        return Ok(());
    };
    let mut at = usize::from(header_size);
    for _ in 0..vlrs.min(1 << 16) {
        let (Some(user), Some(id), Some(len)) =
            (raw.at::<16>(at + 2), raw.u16(at + 18), raw.u16(at + 20))
        else {
            break;
        };
        let data = at + 54;
        if user.starts_with(b"laszip encoded") && id == 22204 {
            let items = raw.u16(data + 32).unwrap_or(0);
            if items == 0 || usize::from(len) < 34 + 6 * usize::from(items) {
                return Err(IoErrorKind::Data(format!(
                    "the LASzip record describes {items} point items in {len} bytes: not a \
                     readable LAZ file"
                )));
            }
            return Ok(());
        }
        at = data + usize::from(len);
    }
    Err(IoErrorKind::Data(
        "compressed points without a LASzip record: not a readable LAZ file".into(),
    ))
}

/// The decoders of the `las` and `laz` crates are third-party code on
/// hostile input: what the checks above do not catch and makes them panic
/// becomes an error here, not a crash.
fn guarded<T>(f: impl FnOnce() -> Result<T, IoErrorKind>) -> Result<T, IoErrorKind> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).unwrap_or_else(|e| {
        let why = e
            .downcast_ref::<String>()
            .cloned()
            .or_else(|| e.downcast_ref::<&str>().map(|s| (*s).to_string()))
            .unwrap_or_default();
        Err(IoErrorKind::Data(format!(
            "the LAS/LAZ decoder failed: {why}"
        )))
    })
}

/// The checks a compressed file gets before the decoder sees it.
fn check(raw: &Raw<'_>) -> Result<(), IoErrorKind> {
    if raw.compressed() {
        check_chunk_table(raw)?;
        check_laszip_items(raw)?;
    }
    Ok(())
}

/// Reads a LAS or LAZ cloud.
pub(crate) fn read_cloud(bytes: &[u8]) -> Result<PointCloud, IoErrorKind> {
    check(&Raw(&InMemory(bytes)))?;
    guarded(|| read_unchecked(bytes))
}

/// One batch of a LAS stream: positions in the file's coordinates, and
/// linear colours when the point format has them.
pub(crate) type Batch<'a> = (&'a [DVec3], Option<&'a [Vec3]>);

/// Reads a LAS or LAZ file from disk a batch at a time into `each`,
/// without holding the cloud: the same checks, decoder and guard as
/// [`read_cloud`]. Returns the points read and whether they have colour.
pub(crate) fn stream_file(
    path: &std::path::Path,
    each: &mut dyn FnMut(Batch<'_>) -> Result<(), String>,
) -> Result<(u64, bool), IoErrorKind> {
    let file = std::fs::File::open(path).map_err(IoErrorKind::Io)?;
    let len = file.metadata().map_err(IoErrorKind::Io)?.len();
    if len == 0 {
        return Err(IoErrorKind::Empty);
    }
    let on_disk = OnDisk {
        file: std::cell::RefCell::new(file),
        len: usize::try_from(len).unwrap_or(usize::MAX),
    };
    check(&Raw(&on_disk))?;
    let mut file = on_disk.file.into_inner();
    std::io::Seek::rewind(&mut file).map_err(IoErrorKind::Io)?;
    guarded(|| {
        let reader = las::Reader::new(std::io::BufReader::with_capacity(1 << 20, file))
            .map_err(|e| IoErrorKind::Header(e.to_string()))?;
        batches(reader, each)
    })
}

/// Reads every point of `reader` in batches into `each`.
fn batches(
    mut reader: las::Reader,
    each: &mut dyn FnMut(Batch<'_>) -> Result<(), String>,
) -> Result<(u64, bool), IoErrorKind> {
    let header = reader.header();
    let promised = header.number_of_points();
    let with_color = header.point_format().has_color;
    // At most a stream's batch: the decoder's buffers for a read (the
    // `las` crate's points, some 100 bytes each) stay small, so threads
    // decoding files at once (`tiled`) leave little with the allocator: a
    // whole 225,000-point file a read left the 3.6M-point survey's peak
    // 95 MB higher with two decoding threads.
    let batch_points = (BATCH_BYTES / u64::from(header.point_format().len()).max(1))
        .clamp(1, BATCH as u64);
    let cap = usize::try_from(batch_points.min(1 << 20)).unwrap_or(0);
    let mut world: Vec<DVec3> = Vec::with_capacity(cap);
    let mut colors: Vec<Vec3> = Vec::with_capacity(if with_color { cap } else { 0 });
    let mut read = 0u64;
    loop {
        let batch = reader
            .read_points(batch_points)
            .map_err(|e| IoErrorKind::Data(format!("after {read} points: {e}")))?;
        if batch.is_empty() {
            break;
        }
        world.clear();
        colors.clear();
        // The records' columns read in place (the `las` crate's own
        // scale-and-offset transform), not as whole `las::Point`s: a third
        // of reading a LAZ survey went to building those.
        let xy = batch.x().zip(batch.y());
        world.extend(xy.zip(batch.z()).map(|((x, y), z)| DVec3::new(x, y, z)));
        read += batch.len() as u64;
        if with_color {
            let lin = |v: u16| srgb_to_linear(f32::from(v) / 65535.0);
            let rgb = |(r, g, b): (u16, u16, u16)| Vec3::new(lin(r), lin(g), lin(b));
            match batch.rgb() {
                Some(c) => colors.extend(c.map(rgb)),
                None => colors.resize(world.len(), rgb((0, 0, 0))),
            }
        }
        each((&world, with_color.then_some(&colors[..]))).map_err(IoErrorKind::Data)?;
        if read >= promised {
            break;
        }
    }
    if read < promised {
        return Err(IoErrorKind::Truncated(format!(
            "the header promises {promised} points but the file holds {read}"
        )));
    }
    Ok((read, with_color))
}

/// [`read_cloud`] without its guard.
fn read_unchecked(bytes: &[u8]) -> Result<PointCloud, IoErrorKind> {
    let reader = las::Reader::new(std::io::Cursor::new(bytes.to_vec()))
        .map_err(|e| IoErrorKind::Header(e.to_string()))?;
    let promised = reader.header().number_of_points();
    crate::memory::check("reading the cloud", promised.saturating_mul(POINT_BYTES))
        .map_err(IoErrorKind::Memory)?;
    let cap = usize::try_from(promised.min(1 << 24)).unwrap_or(0);
    let mut world: Vec<DVec3> = Vec::with_capacity(cap);
    let mut colors: Vec<Vec3> = Vec::new();
    let (_, with_color) = batches(reader, &mut |(w, c)| {
        world.extend_from_slice(w);
        if let Some(c) = c {
            colors.extend_from_slice(c);
        }
        Ok(())
    })?;
    cloud_from_world(world, None, with_color.then_some(colors))
}

/// A LAS or LAZ file streamed from disk ([`stream_file`]): its points
/// in batches of at most [`BATCH`], non-finite ones left out and counted.
pub(crate) fn stream(
    path: &std::path::Path,
    each: &mut dyn FnMut(&PointBatch<'_>) -> Result<(), String>,
) -> Result<StreamInfo, IoErrorKind> {
    let mut info = StreamInfo {
        streamed: true,
        ..StreamInfo::default()
    };
    let mut world: Vec<DVec3> = Vec::with_capacity(BATCH);
    let mut colors: Vec<Vec3> = Vec::with_capacity(BATCH);
    let (_, with_color) = stream_file(path, &mut |(w, c)| {
        for start in (0..w.len()).step_by(BATCH) {
            let end = (start + BATCH).min(w.len());
            world.clear();
            colors.clear();
            for i in start..end {
                if !w[i].is_finite() {
                    info.non_finite += 1;
                    continue;
                }
                world.push(w[i]);
                if let Some(c) = c {
                    colors.push(c[i]);
                }
            }
            info.points += world.len() as u64;
            each(&PointBatch {
                world: &world,
                normals: None,
                colors: c.is_some().then_some(&colors[..]),
                scans: None,
            })?;
        }
        Ok(())
    })?;
    info.colors = with_color;
    Ok(info)
}
