//! PCL's PCD v0.7 point clouds: `ascii`, `binary` and `binary_compressed`
//! (LZF, fields stored one after another) bodies; fields `x y z`, optional
//! `normal_x normal_y normal_z`, and `rgb` or `rgba` (packed `0xAARRGGBB`).

use super::lzf::lzf_decompress;
use super::{IoErrorKind, Organised, PointCloud, cloud_from_world, srgb_to_linear};
use glam::{DVec3, Vec3};
use std::borrow::Cow;

#[derive(Clone, Debug)]
struct Field {
    name: String,
    size: usize,
    kind: u8,
    count: usize,
    /// Byte offset of this field within a binary record.
    offset: usize,
}

impl Field {
    /// Decode element `e` of this field from little-endian bytes.
    fn decode(&self, b: &[u8]) -> f64 {
        let arr4 = |b: &[u8]| [b[0], b[1], b[2], b[3]];
        let arr8 = |b: &[u8]| [b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]];
        match (self.kind, self.size) {
            (b'F', 4) => f64::from(f32::from_le_bytes(arr4(b))),
            (b'F', 8) => f64::from_le_bytes(arr8(b)),
            (b'U', 1) => f64::from(b[0]),
            (b'I', 1) => f64::from(b[0] as i8),
            (b'U', 2) => f64::from(u16::from_le_bytes([b[0], b[1]])),
            (b'I', 2) => f64::from(i16::from_le_bytes([b[0], b[1]])),
            (b'U', 4) => f64::from(u32::from_le_bytes(arr4(b))),
            (b'I', 4) => f64::from(i32::from_le_bytes(arr4(b))),
            (b'U', 8) => u64::from_le_bytes(arr8(b)) as f64,
            (b'I', 8) => i64::from_le_bytes(arr8(b)) as f64,
            _ => f64::NAN,
        }
    }

    /// The packed colour bits of an `rgb`/`rgba` field.
    fn color_bits(&self, b: &[u8]) -> u32 {
        u32::from_le_bytes([b[0], b[1], b[2], b[3]])
    }
}

struct PcdHeader {
    fields: Vec<Field>,
    /// The sensor origin of `VIEWPOINT tx ty tz qw qx qy qz`, in the file's
    /// coordinates.
    viewpoint: Option<DVec3>,
    /// The sensor's orientation of `VIEWPOINT` (w, x, y, z).
    orientation: [f64; 4],
    /// `WIDTH` and `HEIGHT`, when both are given.
    grid: Option<(usize, usize)>,
    points: usize,
    data: String,
    /// Offset of the body in the file.
    body: usize,
    record: usize,
}

fn parse_header(bytes: &[u8]) -> Result<PcdHeader, IoErrorKind> {
    let mut pos = 0usize;
    let mut names: Vec<String> = Vec::new();
    let mut sizes: Vec<usize> = Vec::new();
    let mut kinds: Vec<u8> = Vec::new();
    let mut counts: Vec<usize> = Vec::new();
    let (mut width, mut height, mut points) = (None::<usize>, None::<usize>, None::<usize>);
    let mut data = None;
    let mut viewpoint = None;
    let mut orientation = [1.0, 0.0, 0.0, 0.0];
    while pos < bytes.len() {
        let end = bytes[pos..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(bytes.len(), |i| pos + i + 1);
        let line = String::from_utf8_lossy(&bytes[pos..end]).trim().to_string();
        pos = end;
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut it = line.split_whitespace();
        let key = it.next().unwrap_or("").to_ascii_uppercase();
        let rest: Vec<&str> = it.collect();
        let num = |s: &str| -> Result<usize, IoErrorKind> {
            s.parse::<usize>()
                .map_err(|_| IoErrorKind::Header(format!("{key}: \"{s}\" is not a count")))
        };
        match key.as_str() {
            "VERSION" => {}
            "VIEWPOINT" => {
                let v: Vec<f64> = rest.iter().filter_map(|s| s.parse().ok()).collect();
                if v.len() != 7 || rest.len() != 7 || v.iter().any(|x| !x.is_finite()) {
                    return Err(IoErrorKind::Header(format!(
                        "VIEWPOINT needs 7 finite numbers (tx ty tz qw qx qy qz), got \"{}\"",
                        rest.join(" ").chars().take(60).collect::<String>()
                    )));
                }
                viewpoint = Some(DVec3::new(v[0], v[1], v[2]));
                orientation = [v[3], v[4], v[5], v[6]];
            }
            "FIELDS" | "COLUMNS" => names = rest.iter().map(|s| s.to_string()).collect(),
            "SIZE" => sizes = rest.iter().map(|s| num(s)).collect::<Result<_, _>>()?,
            "TYPE" => {
                kinds = rest
                    .iter()
                    .map(|s| s.bytes().next().unwrap_or(b'?').to_ascii_uppercase())
                    .collect();
            }
            "COUNT" => counts = rest.iter().map(|s| num(s)).collect::<Result<_, _>>()?,
            "WIDTH" => width = Some(num(rest.first().unwrap_or(&""))?),
            "HEIGHT" => height = Some(num(rest.first().unwrap_or(&""))?),
            "POINTS" => points = Some(num(rest.first().unwrap_or(&""))?),
            "DATA" => {
                data = Some(rest.first().unwrap_or(&"").to_ascii_lowercase());
                break;
            }
            _ => {
                return Err(IoErrorKind::Header(format!(
                    "unexpected line \"{}\" before DATA",
                    line.chars().take(40).collect::<String>()
                )));
            }
        }
    }
    let data = data.ok_or_else(|| IoErrorKind::Header("no DATA line".into()))?;
    if names.is_empty() {
        return Err(IoErrorKind::Header("no FIELDS line".into()));
    }
    if counts.is_empty() {
        counts = vec![1; names.len()];
    }
    if sizes.len() != names.len() || kinds.len() != names.len() || counts.len() != names.len() {
        return Err(IoErrorKind::Header(format!(
            "FIELDS has {} entries but SIZE {}, TYPE {}, COUNT {}",
            names.len(),
            sizes.len(),
            kinds.len(),
            counts.len()
        )));
    }
    let mut fields = Vec::with_capacity(names.len());
    let mut offset = 0usize;
    for i in 0..names.len() {
        let ok = matches!(
            (kinds[i], sizes[i]),
            (b'F', 4 | 8) | (b'U' | b'I', 1 | 2 | 4 | 8)
        );
        if !ok || counts[i] == 0 || counts[i] > 1 << 16 {
            return Err(IoErrorKind::Header(format!(
                "field \"{}\": unsupported TYPE {} SIZE {} COUNT {}",
                names[i], kinds[i] as char, sizes[i], counts[i]
            )));
        }
        fields.push(Field {
            name: names[i].clone(),
            size: sizes[i],
            kind: kinds[i],
            count: counts[i],
            offset,
        });
        offset += sizes[i] * counts[i];
    }
    if let (Some(p), Some(w), Some(h)) = (points, width, height)
        && w.checked_mul(h) != Some(p)
    {
        return Err(IoErrorKind::Header(format!(
            "WIDTH {w} x HEIGHT {h} is not POINTS {p}"
        )));
    }
    let points = match (points, width, height) {
        (Some(p), _, _) => p,
        (None, Some(w), Some(h)) => w.saturating_mul(h),
        _ => {
            return Err(IoErrorKind::Header(
                "no POINTS (or WIDTH and HEIGHT) line".into(),
            ));
        }
    };
    Ok(PcdHeader {
        fields,
        viewpoint,
        orientation,
        grid: width.zip(height),
        points,
        data,
        body: pos,
        record: offset,
    })
}

/// Where the values we want sit: (field index, element) for each column.
struct Columns {
    xyz: [usize; 3],
    normal: Option<[usize; 3]>,
    color: Option<usize>,
}

fn columns(h: &PcdHeader) -> Result<Columns, IoErrorKind> {
    let find = |n: &str| h.fields.iter().position(|f| f.name == n);
    let xyz = match (find("x"), find("y"), find("z")) {
        (Some(x), Some(y), Some(z)) => [x, y, z],
        _ => return Err(IoErrorKind::Header("FIELDS lacks x, y and z".into())),
    };
    let normal = match (find("normal_x"), find("normal_y"), find("normal_z")) {
        (Some(x), Some(y), Some(z)) => Some([x, y, z]),
        _ => None,
    };
    let color = find("rgb")
        .or_else(|| find("rgba"))
        .filter(|&i| h.fields[i].size == 4);
    Ok(Columns { xyz, normal, color })
}

fn unpack_color(bits: u32) -> Vec3 {
    let c = |s: u32| srgb_to_linear(((bits >> s) & 0xff) as f32 / 255.0);
    Vec3::new(c(16), c(8), c(0))
}

/// Bytes a read point takes at most: an f64 position, an f32 normal and an
/// f32 colour.
const POINT_BYTES: u64 = 48;

/// The reason an organised grid's skipped (NaN) points are given.
pub(crate) const EMPTY_PIXELS: &str = "empty pixels of the organised grid (NaN: nothing measured)";

/// Read a PCD cloud (coordinates kept in f64 until the cloud is re-centred,
/// so `F 8` fields keep their precision).
pub(crate) fn read_cloud(bytes: &[u8]) -> Result<PointCloud, IoErrorKind> {
    let (h, cols, world, normals, colors) = decode(bytes)?;
    // An organised grid's empty cells are rays from its viewpoint that met
    // nothing, cast through the pinhole fitted to its measured pixels (none
    // when no pinhole fits).
    let misses = h
        .viewpoint
        .and_then(|_| organised(&h, &cols, &world, &colors).ok().flatten())
        .and_then(|o| o.pinhole().ok().map(|p| o.misses(&p)));
    let mut cloud = cloud_from_world(
        world,
        cols.normal.is_some().then_some(normals),
        cols.color.is_some().then_some(colors),
    )?;
    // In the positions' frame, like them: relative to the origin.
    cloud.viewpoint = h.viewpoint.map(|v| cloud.local_viewpoint(v));
    cloud.misses = misses;
    // An organised grid's NaN points are its empty pixels, as expected of a
    // depth camera: said so, not as bad coordinates.
    if grid_size(&h).is_some() {
        for (reason, _) in &mut cloud.skipped {
            if reason == super::NON_FINITE {
                *reason = EMPTY_PIXELS.into();
            }
        }
    }
    Ok(cloud)
}

/// The grid of an organised PCD (`HEIGHT` > 1); `None` for any other.
///
/// # Errors
/// As [`read_cloud`].
pub fn read_organised(bytes: &[u8]) -> Result<Option<Organised>, IoErrorKind> {
    // Any other cloud's body is not decoded.
    if grid_size(&parse_header(bytes)?).is_none() {
        return Ok(None);
    }
    let (h, cols, world, _, colors) = decode(bytes)?;
    organised(&h, &cols, &world, &colors)
}

/// The grid's `WIDTH` × `HEIGHT` when the header describes one (`HEIGHT`
/// > 1).
fn grid_size(h: &PcdHeader) -> Option<(usize, usize)> {
    h.grid.filter(|&(w, h)| h > 1 && w > 1)
}

/// The grid of a decoded PCD (`HEIGHT` > 1); `None` for any other.
fn organised(
    h: &PcdHeader,
    cols: &Columns,
    world: &[DVec3],
    colors: &[Vec3],
) -> Result<Option<Organised>, IoErrorKind> {
    let Some((width, height)) = grid_size(h) else {
        return Ok(None);
    };
    let [w, x, y, z] = h.orientation;
    let q = glam::DQuat::from_xyzw(x, y, z, w);
    if q.length().is_nan() || q.length() <= 1e-12 {
        return Err(IoErrorKind::Header("VIEWPOINT's quaternion is zero".into()));
    }
    let orientation = q.normalize();
    let keep: Vec<usize> = (0..world.len()).filter(|&i| world[i].is_finite()).collect();
    Ok(Some(Organised {
        width,
        height,
        position: h.viewpoint.unwrap_or(DVec3::ZERO),
        orientation,
        pixels: keep.iter().map(|&i| (i as u32, world[i])).collect(),
        colors: cols
            .color
            .is_some()
            .then(|| keep.iter().map(|&i| colors[i]).collect()),
    }))
}

/// Every point's position, normal and colour as a PCD body stores them
/// (NaN included; normals and colours when the header has them).
#[derive(Default)]
struct Stored {
    world: Vec<DVec3>,
    normals: Vec<Vec3>,
    colors: Vec<Vec3>,
}

/// The header's columns and every point as stored (NaN included).
#[allow(clippy::type_complexity)]
fn decode(
    bytes: &[u8],
) -> Result<(PcdHeader, Columns, Vec<DVec3>, Vec<Vec3>, Vec<Vec3>), IoErrorKind> {
    let h = parse_header(bytes)?;
    let cols = columns(&h)?;
    let body = &bytes[h.body.min(bytes.len())..];
    let s = match h.data.as_str() {
        "ascii" => decode_ascii(&h, &cols, body)?,
        "binary" | "binary_compressed" => {
            let (data, soa) = binary_data(&h, body)?;
            decode_binary(&h, &cols, &data, soa)
        }
        other => {
            return Err(IoErrorKind::Header(format!(
                "DATA \"{other}\" (expected ascii, binary or binary_compressed)"
            )));
        }
    };
    Ok((h, cols, s.world, s.normals, s.colors))
}

/// The points of an `ascii` body: one line each, the fields' first
/// elements parsed as f64 (a colour as the float or integer it packs).
fn decode_ascii(h: &PcdHeader, cols: &Columns, body: &[u8]) -> Result<Stored, IoErrorKind> {
    let n = h.points;
    let mut s = Stored::default();
    let text = String::from_utf8_lossy(body);
    // A token takes at least two bytes, so the body bounds the count.
    let cap = n.min(body.len() / (2 * h.fields.len()).max(1));
    s.world.reserve(cap);
    let mut firsts = Vec::with_capacity(h.fields.len());
    let mut acc = 0usize;
    for f in &h.fields {
        firsts.push(acc);
        acc += f.count;
    }
    let mut lines = text.lines().filter(|l| !l.trim().is_empty());
    let mut toks: Vec<&str> = Vec::with_capacity(acc);
    for i in 0..n {
        let Some(line) = lines.next() else {
            return Err(IoErrorKind::Truncated(format!(
                "the header promises {n} points but the body ends after {i}"
            )));
        };
        toks.clear();
        toks.extend(line.split_whitespace());
        if toks.len() < acc {
            return Err(IoErrorKind::Data(format!(
                "point {i}: {} values, the header asks for {acc}",
                toks.len()
            )));
        }
        let val = |fi: usize| -> Result<f64, IoErrorKind> {
            let t = toks[firsts[fi]];
            t.parse::<f64>()
                .map_err(|_| IoErrorKind::Data(format!("point {i}: \"{t}\" is not a number")))
        };
        let v3 = |f: [usize; 3]| -> Result<DVec3, IoErrorKind> {
            Ok(DVec3::new(val(f[0])?, val(f[1])?, val(f[2])?))
        };
        s.world.push(v3(cols.xyz)?);
        if let Some(nf) = cols.normal {
            s.normals.push(v3(nf)?.as_vec3());
        }
        if let Some(cf) = cols.color {
            let t = toks[firsts[cf]];
            let bits = if h.fields[cf].kind == b'F' {
                t.parse::<f32>().map(f32::to_bits).ok()
            } else {
                t.parse::<u32>().ok()
            }
            .ok_or_else(|| {
                IoErrorKind::Data(format!("point {i}: colour \"{t}\" is not a number"))
            })?;
            s.colors.push(unpack_color(bits));
        }
    }
    Ok(s)
}

/// A `binary` body as it is, or a `binary_compressed` one decompressed
/// (LZF, its sizes checked first), and whether its fields lie one after
/// another for all points (compressed) rather than point by point.
fn binary_data<'a>(h: &PcdHeader, body: &'a [u8]) -> Result<(Cow<'a, [u8]>, bool), IoErrorKind> {
    let n = h.points;
    let need = (n as u128) * (h.record as u128);
    Ok(if h.data == "binary" {
        if need > body.len() as u128 {
            return Err(IoErrorKind::Truncated(format!(
                "the header promises {n} points ({need} bytes) but only {} bytes follow it",
                body.len()
            )));
        }
        (Cow::Borrowed(body), false)
    } else {
        if body.len() < 8 {
            return Err(IoErrorKind::Truncated(
                "the compressed body lacks its 8-byte size header".into(),
            ));
        }
        let comp = u32::from_le_bytes([body[0], body[1], body[2], body[3]]) as usize;
        let raw = u32::from_le_bytes([body[4], body[5], body[6], body[7]]) as usize;
        if raw as u128 != need {
            return Err(IoErrorKind::Data(format!(
                "uncompressed size {raw} bytes does not match {n} points of {} bytes",
                h.record
            )));
        }
        let Some(packed) = body.get(8..8 + comp) else {
            return Err(IoErrorKind::Truncated(format!(
                "the compressed body should be {comp} bytes, only {} follow",
                body.len() - 8
            )));
        };
        // LZF expands at most 88 times (a 3-byte back reference
        // copies 264 bytes): a size beyond that is a lie, and one
        // the memory cannot hold fails before decompressing.
        if raw as u128 > comp as u128 * 88 + 32 {
            return Err(IoErrorKind::Data(format!(
                "the header claims {raw} bytes from {comp} compressed, more than LZF can \
                 expand to"
            )));
        }
        crate::memory::check(
            "reading the cloud",
            (raw as u64).saturating_add((n as u64).saturating_mul(POINT_BYTES)),
        )
        .map_err(IoErrorKind::Memory)?;
        let decompressed = lzf_decompress(packed, raw).map_err(IoErrorKind::Lzf)?;
        (Cow::Owned(decompressed), true)
    })
}

/// The points of binary `data` (`soa`: fields one after another, each for
/// all points), every field decoded as its type.
fn decode_binary(h: &PcdHeader, cols: &Columns, data: &[u8], soa: bool) -> Stored {
    let n = h.points;
    let mut s = Stored::default();
    // Field f, element 0 of point i starts at:
    let at = |f: usize, i: usize| -> usize {
        let fd = &h.fields[f];
        if soa {
            // Fields one after another, each for all points.
            n * fd.offset + i * fd.size * fd.count
        } else {
            i * h.record + fd.offset
        }
    };
    s.world.reserve(n);
    for i in 0..n {
        let v3 = |f: [usize; 3]| {
            let g = |k: usize| {
                let o = at(f[k], i);
                h.fields[f[k]].decode(&data[o..o + h.fields[f[k]].size])
            };
            DVec3::new(g(0), g(1), g(2))
        };
        s.world.push(v3(cols.xyz));
        if let Some(nf) = cols.normal {
            s.normals.push(v3(nf).as_vec3());
        }
        if let Some(cf) = cols.color {
            let o = at(cf, i);
            s.colors
                .push(unpack_color(h.fields[cf].color_bits(&data[o..o + 4])));
        }
    }
    s
}

/// Encode an organised cloud (a sensor's grid, row by row, NaN where
/// nothing was measured) as a binary PCD v0.7 with f64 coordinates in the
/// file's frame and `VIEWPOINT` the sensor's pose (`position`, and the
/// rotation from its frame to the file's); with `colors` (linear RGB, one
/// per grid pixel), a packed 8-bit sRGB `rgb` field too.
#[must_use]
pub fn encode_organised(
    width: usize,
    height: usize,
    points: &[Option<DVec3>],
    position: DVec3,
    rotation: glam::DQuat,
    colors: Option<&[Vec3]>,
) -> Vec<u8> {
    let q = rotation.normalize();
    let (fields, size, kind, count) = if colors.is_some() {
        ("x y z rgb", "8 8 8 4", "F F F U", "1 1 1 1")
    } else {
        ("x y z", "8 8 8", "F F F", "1 1 1")
    };
    let mut out = format!(
        "# .PCD v0.7 - Point Cloud Data file format (written by splatray {}, an organised scan)\n\
         VERSION 0.7\nFIELDS {fields}\nSIZE {size}\nTYPE {kind}\nCOUNT {count}\nWIDTH {width}\nHEIGHT {height}\n\
         VIEWPOINT {} {} {} {} {} {} {}\nPOINTS {}\nDATA binary\n",
        env!("CARGO_PKG_VERSION"),
        position.x,
        position.y,
        position.z,
        q.w,
        q.x,
        q.y,
        q.z,
        width * height
    )
    .into_bytes();
    for (i, p) in points.iter().enumerate() {
        let p = p.unwrap_or(DVec3::NAN);
        for c in p.to_array() {
            out.extend_from_slice(&c.to_le_bytes());
        }
        if let Some(c) = colors {
            let [r, g, b] = c
                .get(i)
                .copied()
                .unwrap_or(Vec3::ZERO)
                .to_array()
                .map(super::linear_to_srgb8);
            let packed = (u32::from(r) << 16) | (u32::from(g) << 8) | u32::from(b);
            out.extend_from_slice(&packed.to_le_bytes());
        }
    }
    out
}

/// Encode `cloud` as a binary PCD v0.7 (`x y z`, plus `normal_x normal_y
/// normal_z` when present), with `VIEWPOINT` set to the cloud's viewpoint
/// (identity orientation) when it has one. Positions and the viewpoint are
/// in the file's coordinates (`origin + ...`): `F 4` when the origin is
/// zero, else `F 8`.
#[must_use]
pub fn encode(cloud: &PointCloud) -> Vec<u8> {
    let n = cloud.len();
    let normals = cloud.normals.as_ref().filter(|v| v.len() == n);
    let wide = cloud.origin != DVec3::ZERO;
    let vp = cloud
        .viewpoint
        .map_or(DVec3::ZERO, |v| cloud.origin + v.as_dvec3());
    let xyz = if wide { "8 8 8" } else { "4 4 4" };
    let (fields, sizes, types, counts) = if normals.is_some() {
        (
            "x y z normal_x normal_y normal_z",
            format!("{xyz} 4 4 4"),
            "F F F F F F",
            "1 1 1 1 1 1",
        )
    } else {
        ("x y z", xyz.to_string(), "F F F", "1 1 1")
    };
    let header = format!(
        "# .PCD v0.7 - Point Cloud Data file format (written by splatray {})\nVERSION 0.7\nFIELDS {fields}\nSIZE {sizes}\nTYPE {types}\nCOUNT {counts}\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT {} {} {} 1 0 0 0\nPOINTS {n}\nDATA binary\n",
        env!("CARGO_PKG_VERSION"),
        vp.x,
        vp.y,
        vp.z
    );
    let per = if wide { 24 } else { 12 } + if normals.is_some() { 12 } else { 0 };
    let mut out = Vec::with_capacity(header.len() + n * per);
    out.extend_from_slice(header.as_bytes());
    super::encode_records(&mut out, cloud, wide, normals, None);
    out
}
