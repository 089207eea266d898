//! The splat file: a binary little-endian PLY whose `vertex` element is one
//! splat, read back by [`read_splats`] without loss and readable by other
//! tools: `x y z nx ny nz` and `radius` as MeshLab, CloudCompare and Open3D
//! expect, and the colour twice, as the 8-bit sRGB `uchar red green blue`
//! those tools read and as linear floats `lin_red lin_green lin_blue` that
//! this reader prefers (files written before the colour was split hold
//! linear float `red green blue`, still read as such).
//!
//! Splats with a linear colour field (`splat::color`) carry it in six more
//! float properties, [`COLOR_FIELD_PROPS`], after the linear colour; a file
//! without them holds constant colours.
//!
//! Clipped splats (a splat at a crease or a corner, `splat::clip`) carry
//! their clip lines in six more float properties, [`CLIP_PROPS`], after
//! the colour field if any: written only when some splat is clipped, so a
//! file of whole discs is what it was.
//!
//! Splat centres are float offsets from an origin held in double precision,
//! written as the header line `comment splatray origin X Y Z` (shortest
//! round-trip decimals), so a splat file made from a georeferenced cloud
//! keeps its world position exactly. Other tools ignore the comment and
//! show the splats around their origin.

use super::ply::{PlyFile, Records, Scalar, scalar};
use super::{IoError, IoErrorKind, write_bytes};
use crate::data::ColorField;
use crate::data::{NormalField, Splat};
use crate::primitive::clip::{Clip, ClipLine};
use glam::{DVec3, Vec2, Vec3};
use ply_rs_bw::ply::{Property, PropertyAccess};
use std::path::Path;

/// The float32 vertex properties of a splat file, in order: centre, normal,
/// radius along `u` (MeshLab's `radius`), the `u` and `v` axes, the radius
/// along `v`, the normal field of eq. (4) and the linear RGB colour; the
/// writer follows them with [`SRGB_PROPS`].
pub(crate) const SPLAT_PROPS: [&str; 21] = [
    "x",
    "y",
    "z",
    "nx",
    "ny",
    "nz",
    "radius",
    "ux",
    "uy",
    "uz",
    "vx",
    "vy",
    "vz",
    "radius_v",
    "field_xc",
    "field_yc",
    "field_alpha",
    "field_beta",
    "lin_red",
    "lin_green",
    "lin_blue",
];

/// The float32 properties of a linear colour field (`splat::color`): the
/// change of the linear colour across the disc along `u`, then along `v`;
/// written after [`SPLAT_PROPS`] when the splats carry fields.
pub const COLOR_FIELD_PROPS: [&str; 6] = [
    "lin_red_du",
    "lin_green_du",
    "lin_blue_du",
    "lin_red_dv",
    "lin_green_dv",
    "lin_blue_dv",
];

/// The float32 properties of the clip lines (`splat::clip`): line `k`'s
/// `a u + b v <= d` in the splat's normalised coordinates, `(a, b) = (0,
/// 0)` where the splat carries fewer lines; written after the colour field
/// (or [`SPLAT_PROPS`]) when some splat of the file is clipped.
pub const CLIP_PROPS: [&str; 6] = [
    "clip_a0", "clip_b0", "clip_d0", "clip_a1", "clip_b1", "clip_d1",
];

/// The 8-bit sRGB colour (`uchar`), last in the vertex: what other tools
/// show. An older splat file holds the linear colour under these names as
/// floats.
pub(crate) const SRGB_PROPS: [&str; 3] = ["red", "green", "blue"];

/// Where the values of a [`SplatRow`] lie: [`SPLAT_PROPS`] from 0, then
/// `red green blue` from `RGB`, the colour field from `DC`, the clip lines
/// from `CLIP`, `ROW` in all.
const RGB: usize = SPLAT_PROPS.len();
const DC: usize = RGB + SRGB_PROPS.len();
const CLIP: usize = DC + COLOR_FIELD_PROPS.len();
const ROW: usize = CLIP + CLIP_PROPS.len();

/// One splat vertex of a splat file: every property as `f32`, by the index
/// of its name in [`SPLAT_PROPS`], then `red green blue` made linear (from
/// `uchar` sRGB, or taken as they are when floats: an older file's linear
/// colour), the colour field ([`COLOR_FIELD_PROPS`]) and the clip lines
/// ([`CLIP_PROPS`]); NaN where the file has no such property.
#[derive(Clone, Copy)]
pub(crate) struct SplatRow([f32; ROW]);

/// The place in a [`SplatRow`] of a property of a splat file, if it has
/// one.
fn slot_of(name: &str) -> Option<usize> {
    let at = |names: &[&str], from: usize| names.iter().position(|n| *n == name).map(|k| from + k);
    at(&SRGB_PROPS, RGB)
        .or_else(|| at(&COLOR_FIELD_PROPS, DC))
        .or_else(|| at(&CLIP_PROPS, CLIP))
        .or_else(|| at(&SPLAT_PROPS, 0))
}

impl PropertyAccess for SplatRow {
    fn new() -> Self {
        SplatRow([f32::NAN; ROW])
    }
    fn set_property(&mut self, name: &str, p: Property) {
        let Some(k) = slot_of(name) else {
            return;
        };
        // Lossless for the float32 properties the writer produces; an
        // sRGB `uchar` colour made linear.
        self.0[k] = match p {
            Property::UChar(c) if (RGB..DC).contains(&k) => super::srgb_to_linear(f32::from(c) / 255.0),
            Property::Float(f) => f,
            other => scalar(&other).map_or(f32::NAN, |d| d as f32),
        };
    }
}

/// How [`InPlace`] reads a value: as [`SplatRow::set_property`] takes it.
#[derive(Clone, Copy)]
enum Read {
    /// A float32, bit for bit.
    F32,
    /// An sRGB `uchar` colour, made linear.
    Srgb8,
    /// Any other scalar, through `f64`.
    Other(Scalar),
}

/// The vertices of a splat file read in place ([`Records`]), as
/// [`SplatRow::set_property`] takes them: the same values bit for bit in
/// every place [`splat_of`] reads for the file's [`Kind`] (the others
/// are left NaN).
struct InPlace<'a> {
    records: Records<'a>,
    /// Each property read: its place in the row, its offset in the record,
    /// how it is read.
    slots: Vec<(usize, usize, Read)>,
}

impl<'a> InPlace<'a> {
    /// `None` where the file is not read in place ([`Records::of`]).
    fn of(file: &PlyFile<'a>, kind: Kind) -> Option<InPlace<'a>> {
        let (records, props) = Records::of(file)?;
        let used = |k: usize| match k {
            // The 8-bit colour when there is no linear one, or for discs.
            RGB..DC => !(kind.linear && kind.full),
            DC..CLIP => kind.with_fields,
            CLIP..ROW => kind.with_clips,
            _ => true,
        };
        let slots = props
            .into_iter()
            .filter_map(|(name, offset, s)| {
                let k = slot_of(name).filter(|&k| used(k))?;
                let read = match s {
                    Scalar::U8 if (RGB..DC).contains(&k) => Read::Srgb8,
                    Scalar::F32 => Read::F32,
                    other => Read::Other(other),
                };
                Some((k, offset, read))
            })
            .collect();
        Some(InPlace { records, slots })
    }

    /// Record `r` as a row.
    fn row(&self, r: usize) -> SplatRow {
        let mut row = [f32::NAN; ROW];
        let record = self.records.at(r, 0);
        for &(k, offset, read) in &self.slots {
            let b = &record[offset..];
            row[k] = match read {
                Read::F32 => f32::from_le_bytes(b[..4].try_into().expect("four bytes")),
                Read::Srgb8 => super::srgb_to_linear(f32::from(b[0]) / 255.0),
                Read::Other(s) => s.read(b) as f32,
            };
        }
        SplatRow(row)
    }
}

/// What a splat file holds: the splats, their centres relative to `origin`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SplatSet {
    /// The splats; centre `i` lies at `origin + splats[i].center` in the
    /// coordinates of the cloud they were made from.
    pub splats: Vec<Splat>,
    /// Where the centres are measured from (zero when the file says nothing).
    pub origin: DVec3,
    /// Each splat's linear colour field, or empty when the file holds
    /// constant colours.
    pub color_fields: Vec<ColorField>,
}

/// The header comment that carries the origin.
pub(crate) const ORIGIN_COMMENT: &str = "splatray origin";

fn to_row(s: &Splat) -> [f32; 21] {
    let f = &s.field;
    [
        s.center.x, s.center.y, s.center.z, s.normal.x, s.normal.y, s.normal.z, s.radii.x,
        s.u_axis.x, s.u_axis.y, s.u_axis.z, s.v_axis.x, s.v_axis.y, s.v_axis.z, s.radii.y, f.xc,
        f.yc, f.alpha, f.beta, s.color.x, s.color.y, s.color.z,
    ]
}

/// The [`CLIP_PROPS`] values of a splat's clip lines (zeros where absent).
fn clip_row(s: &Splat) -> [f32; 6] {
    let mut row = [0.0; 6];
    for (k, l) in s.clip.lines().iter().enumerate() {
        row[3 * k..3 * k + 3].copy_from_slice(&[l.a, l.b, l.d]);
    }
    row
}

/// The clip of [`CLIP_PROPS`] values: a line where `(a, b)` is not zero,
/// the first before the second.
fn clip_of(v: &[f32; 6]) -> Result<Clip, &'static str> {
    if v.iter().any(|x| !x.is_finite()) {
        return Err("non-finite clip line");
    }
    let line = |k: usize| {
        (v[3 * k] != 0.0 || v[3 * k + 1] != 0.0).then_some(ClipLine {
            a: v[3 * k],
            b: v[3 * k + 1],
            d: v[3 * k + 2],
        })
    };
    let blank = |k: usize| v[3 * k + 2] == 0.0;
    match (line(0), line(1)) {
        (None, None) if blank(0) && blank(1) => Ok(Clip::NONE),
        (Some(a), None) if blank(1) => Ok(Clip::one(a)),
        (Some(a), Some(b)) => Ok(Clip::two(a, b)),
        _ => Err("clip line with a zero normal, or a second line without a first"),
    }
}

/// Write `splats`, whose centres are offsets from `origin`, to `path` as a
/// binary little-endian float32 PLY (see [`SPLAT_PROPS`] for the vertex
/// properties; colours are stored linear as floats and as 8-bit sRGB; the origin
/// goes into a header comment). The file is written to a temporary file in
/// the same folder and renamed, so a failure never leaves a half-written
/// output.
///
/// # Errors
/// An [`IoError`] when a splat has a non-finite value or a radius that is
/// not positive, the origin is not finite (nothing is written then), or the
/// file cannot be written.
pub fn write_splats(path: &Path, splats: &[Splat], origin: DVec3) -> Result<(), IoError> {
    write_bytes(path, &encode_splats(path, splats, origin)?)
}

/// The bytes [`write_splats`] writes to `path` (named in errors), to write
/// them with other outputs of one run ([`super::Batch`]).
///
/// # Errors
/// As [`write_splats`], before anything is written.
pub fn encode_splats(path: &Path, splats: &[Splat], origin: DVec3) -> Result<Vec<u8>, IoError> {
    encode_splats_with(path, splats, None, origin)
}

/// [`encode_splats`] with each splat's colour field (`fields` `None`: the
/// file [`encode_splats`] writes; else one per splat, written as
/// [`COLOR_FIELD_PROPS`], and the header has them even with no splats).
/// The clip lines ([`CLIP_PROPS`]) are written when some splat is clipped.
///
/// # Errors
/// As [`write_splats`]; also when `fields` is not one per splat, or holds
/// a non-finite value.
pub fn encode_splats_with(
    path: &Path,
    splats: &[Splat],
    fields: Option<&[ColorField]>,
    origin: DVec3,
) -> Result<Vec<u8>, IoError> {
    let clips = splats.iter().any(Splat::is_clipped);
    encode_splats_layout(path, splats, fields, clips, origin)
}

/// [`encode_splats_with`] with the [`CLIP_PROPS`] written when `clips`
/// (whether or not a splat is clipped: files to be joined record by
/// record, like the tiles of `tiled`, must share one layout; see
/// [`splat_row_bytes`]). A clipped splat with `clips` false is an error.
///
/// # Errors
/// As [`encode_splats_with`]; also when a splat is clipped and `clips` is
/// false, or a clip line is not finite or has a zero normal.
pub fn encode_splats_layout(
    path: &Path,
    splats: &[Splat],
    fields: Option<&[ColorField]>,
    clips: bool,
    origin: DVec3,
) -> Result<Vec<u8>, IoError> {
    let bad = |what: String| Err(IoError::not_written(path, &what));
    if !origin.is_finite() {
        return bad(format!("the splats' origin {origin} is not finite"));
    }
    if let Some(i) = splats
        .iter()
        .position(|s| !to_row(s).iter().all(|v| v.is_finite()) || s.radii.min_element() <= 0.0)
    {
        return bad(format!(
            "splat {i} has a non-finite value or a radius that is not positive (centre {}, radii {})",
            splats[i].center, splats[i].radii
        ));
    }
    if let Some(f) = fields.filter(|f| f.len() != splats.len()) {
        return bad(format!(
            "{} colour fields for {} splats",
            f.len(),
            splats.len()
        ));
    }
    if let Some(i) = fields
        .unwrap_or_default()
        .iter()
        .position(|f| !(f.du.is_finite() && f.dv.is_finite()))
    {
        return bad(format!("splat {i} has a non-finite colour field"));
    }
    if let Some(i) = splats.iter().position(|s| {
        s.is_clipped()
            && (!clips
                || s.clip.lines().iter().any(|l| {
                    !(l.a.is_finite() && l.b.is_finite() && l.d.is_finite())
                        || (l.a == 0.0 && l.b == 0.0)
                }))
    }) {
        return bad(format!(
            "splat {i} has a clip line that is not finite, has a zero normal, or is not written ({:?})",
            splats[i].clip
        ));
    }
    let with = fields.is_some();
    let header = splat_header_layout(splats.len() as u64, origin, with, clips);
    let row = splat_row_bytes(with, clips);
    let mut out = Vec::with_capacity(header.len() + splats.len() * row);
    out.extend_from_slice(header.as_bytes());
    for (i, s) in splats.iter().enumerate() {
        for v in to_row(s) {
            out.extend_from_slice(&v.to_le_bytes());
        }
        if let Some(f) = fields.and_then(|f| f.get(i)) {
            for v in f.du.to_array().into_iter().chain(f.dv.to_array()) {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        if clips {
            for v in clip_row(s) {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        out.extend(s.color.to_array().map(super::linear_to_srgb8));
    }
    Ok(out)
}

/// Bytes of one splat record in a splat file: the float properties and
/// the 8-bit sRGB colour.
pub const SPLAT_ROW_BYTES: usize = SPLAT_PROPS.len() * 4 + SRGB_PROPS.len();

/// The header of a splat file of `count` splats whose centres are offsets
/// from `origin`; the records follow it, [`SPLAT_ROW_BYTES`] each, so
/// splat files of one origin join by adding their counts and concatenating
/// their bodies.
#[must_use]
pub fn splat_header(count: u64, origin: DVec3) -> String {
    splat_header_with(count, origin, false)
}

/// Bytes of one splat record in a splat file with colour fields and clip
/// lines as given.
#[must_use]
pub fn splat_row_bytes(color_fields: bool, clips: bool) -> usize {
    SPLAT_ROW_BYTES
        + if color_fields {
            4 * COLOR_FIELD_PROPS.len()
        } else {
            0
        }
        + if clips { 4 * CLIP_PROPS.len() } else { 0 }
}

/// [`splat_header`], with the [`COLOR_FIELD_PROPS`] after the linear colour
/// when `color_fields`.
#[must_use]
pub fn splat_header_with(count: u64, origin: DVec3, color_fields: bool) -> String {
    splat_header_layout(count, origin, color_fields, false)
}

/// [`splat_header_with`], with the [`CLIP_PROPS`] after the colour field
/// when `clips`.
#[must_use]
pub fn splat_header_layout(count: u64, origin: DVec3, color_fields: bool, clips: bool) -> String {
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment splatray {} splats: Linsen et al. 2007 discs with Botsch et al. 2004 normal fields\ncomment {ORIGIN_COMMENT} {:?} {:?} {:?}\nelement vertex {count}\n",
        env!("CARGO_PKG_VERSION"),
        origin.x,
        origin.y,
        origin.z,
    );
    let fields = if color_fields {
        &COLOR_FIELD_PROPS[..]
    } else {
        &[]
    };
    let clip: &[&str] = if clips { &CLIP_PROPS[..] } else { &[] };
    for p in SPLAT_PROPS.iter().chain(fields).chain(clip) {
        header.push_str("property float ");
        header.push_str(p);
        header.push('\n');
    }
    for p in SRGB_PROPS {
        header.push_str("property uchar ");
        header.push_str(p);
        header.push('\n');
    }
    header.push_str("end_header\n");
    header
}

/// The largest normal-field value read (eq. 4's `x_c, y_c, alpha, beta`,
/// in units of the splat's radii; a sphere's splats have `alpha = r/R`,
/// well below 1).
const MAX_FIELD: f32 = 1e3;

/// The largest colour-field value read (a change of linear colour across
/// the disc; the renderer clamps the colour it gives to `[0, 1]`).
const MAX_COLOR_FIELD: f32 = 1e3;

/// The origin of a `comment splatray origin X Y Z` header line, if any.
pub(crate) fn origin_of(comments: &[String]) -> Result<Option<DVec3>, IoErrorKind> {
    let Some(rest) = comments
        .iter()
        .find_map(|c| c.trim().strip_prefix(ORIGIN_COMMENT))
    else {
        return Ok(None);
    };
    let vals: Vec<f64> = rest
        .split_whitespace()
        .map(str::parse::<f64>)
        .collect::<Result<_, _>>()
        .map_err(|_| {
            IoErrorKind::Header(format!("\"{ORIGIN_COMMENT}{rest}\" is not three numbers"))
        })?;
    match vals[..] {
        [x, y, z] if vals.iter().all(|v| v.is_finite()) => Ok(Some(DVec3::new(x, y, z))),
        _ => Err(IoErrorKind::Header(format!(
            "\"{ORIGIN_COMMENT}{rest}\" is not three finite numbers"
        ))),
    }
}

/// Read splats written by [`write_splats`] (any PLY encoding with the same
/// property names), with the origin of their centres (zero when the header
/// has no `comment splatray origin`). A file with only
/// `x y z nx ny nz radius` gives circular flat grey splats.
///
/// # Errors
/// An [`IoError`] when the file cannot be read or parsed, lacks the
/// properties, has a malformed origin comment, or holds a splat with a
/// non-finite value, a zero normal or a non-positive radius, axes that are
/// zero or not across the normal, a normal field or colour out of range;
/// or no splats at all. (Far or huge splats are read: a scene's transform
/// may bring them in; the scene checks what it places.)
pub fn read_splats(path: &Path) -> Result<SplatSet, IoError> {
    let bytes = super::read_file(path)?;
    parse_splats(&bytes).map_err(|k| IoError::new(path, k))
}

/// [`read_splats`] on a file's bytes.
///
/// # Errors
/// As [`read_splats`], without the file's name.
pub fn parse_splats(bytes: &[u8]) -> Result<SplatSet, IoErrorKind> {
    parse(bytes, true)
}

/// [`parse_splats`], the records read in place where `in_place` and the
/// file allows ([`InPlace`]), else row by row (`ply-rs-bw`).
fn parse(bytes: &[u8], in_place: bool) -> Result<SplatSet, IoErrorKind> {
    let file = PlyFile::open(bytes)?;
    let origin = origin_of(&file.header.comments)?.unwrap_or(DVec3::ZERO);
    let kind = Kind::of(&file.header)?;
    // Read in place and in parallel where the file allows (a binary
    // little-endian vertex element first: what the writer makes), else
    // row by row; the same rows either way.
    let (splats, color_fields) = match InPlace::of(&file, kind).filter(|_| in_place) {
        Some(rows) => splats_of(rows.records.count, |r| rows.row(r), kind)?,
        None => {
            let rows = file.read_vertices::<SplatRow>()?;
            splats_of(rows.len(), |r| rows[r], kind)?
        }
    };
    if splats.is_empty() {
        return Err(IoErrorKind::NoPoints("the file holds no splats".into()));
    }
    Ok(SplatSet {
        splats,
        origin,
        color_fields,
    })
}

/// What a splat file's vertex element holds ([`parse_splats`]).
#[derive(Clone, Copy)]
struct Kind {
    /// The linear colour as `lin_red lin_green lin_blue`.
    linear: bool,
    /// Every property of a splat, not only `x y z nx ny nz radius`.
    full: bool,
    /// The colour field ([`COLOR_FIELD_PROPS`]).
    with_fields: bool,
    /// The clip lines ([`CLIP_PROPS`]).
    with_clips: bool,
}

impl Kind {
    /// What the vertex element of a splat file's `header` holds; an error
    /// when it is not a splat file.
    fn of(header: &ply_rs_bw::ply::Header) -> Result<Kind, IoErrorKind> {
        let vertex = header
            .elements
            .get("vertex")
            .ok_or_else(|| IoErrorKind::Header("no \"vertex\" element".into()))?;
        let has = |n: &str| vertex.properties.contains_key(n);
        if let Some(missing) = SPLAT_PROPS[..7].iter().find(|n| !has(n)) {
            return Err(IoErrorKind::Header(format!(
                "not a splat file: the vertex element lacks \"{missing}\""
            )));
        }
        // Linear floats when written by this version, else `red green blue`.
        let linear = SPLAT_PROPS[18..].iter().all(|n| has(n));
        let full =
            SPLAT_PROPS[..18].iter().all(|n| has(n)) && (linear || SRGB_PROPS.iter().all(|n| has(n)));
        Ok(Kind {
            linear,
            full,
            with_fields: full && COLOR_FIELD_PROPS.iter().all(|n| has(n)),
            with_clips: full && CLIP_PROPS.iter().all(|n| has(n)),
        })
    }
}

/// The fewest rows a parallel task of [`splats_of`] checks.
const PARSE_CHUNK: usize = 4096;

/// The splats of the `n` rows `row(i)` and, with `kind.with_fields`,
/// their colour fields, checked in parallel: the first bad row's error (in
/// the file's order), as a reading row after row gives it.
fn splats_of(
    n: usize,
    row: impl Fn(usize) -> SplatRow + Sync,
    kind: Kind,
) -> Result<(Vec<Splat>, Vec<ColorField>), IoErrorKind> {
    use rayon::prelude::*;
    use std::sync::atomic::{AtomicUsize, Ordering};
    // Every row made in place (an indexed collect), a bad one as a stand-in
    // splat and its index kept: the least is the first in the file's order.
    let first_bad = AtomicUsize::new(usize::MAX);
    let stand_in = Splat::disc(Vec3::ZERO, Vec3::Z, 1.0).expect("a disc");
    let splats: Vec<Splat> = (0..n)
        .into_par_iter()
        .with_min_len(PARSE_CHUNK)
        .map(|i| {
            splat_of(i, &row(i), kind).unwrap_or_else(|_| {
                first_bad.fetch_min(i, Ordering::Relaxed);
                stand_in
            })
        })
        .collect();
    let i = first_bad.into_inner();
    if i != usize::MAX {
        return Err(splat_of(i, &row(i), kind).expect_err("a bad row"));
    }
    let color_fields = if kind.with_fields {
        (0..n)
            .into_par_iter()
            .with_min_len(PARSE_CHUNK)
            .map(|i| {
                let r = row(i);
                let dc = &r.0[DC..CLIP];
                ColorField {
                    du: Vec3::new(dc[0], dc[1], dc[2]),
                    dv: Vec3::new(dc[3], dc[4], dc[5]),
                }
            })
            .collect()
    } else {
        Vec::new()
    };
    Ok((splats, color_fields))
}

/// Row `i` as a splat, checked ([`read_splats`]'s errors).
fn splat_of(i: usize, r: &SplatRow, kind: Kind) -> Result<Splat, IoErrorKind> {
    let Kind {
        linear,
        full,
        with_fields,
        with_clips,
    } = kind;
    let mut v: [f32; RGB] = r.0[..RGB].try_into().expect("the splat's values");
    let rgb = &r.0[RGB..DC];
    if !linear {
        v[18..].copy_from_slice(rgb);
    }
    let bad = |what: &str| IoErrorKind::Data(format!("splat {i}: {what}"));
    let used = if full { &v[..] } else { &v[..7] };
    if used.iter().any(|x| !x.is_finite()) {
        return Err(bad("non-finite value"));
    }
    let center = Vec3::new(v[0], v[1], v[2]);
    let normal = Vec3::new(v[3], v[4], v[5]);
    if v[6] <= 0.0 || normal.length_squared() == 0.0 {
        return Err(bad("zero normal or non-positive radius"));
    }
    // Scaled before normalising: a normal of length 1e30 would
    // overflow its squared length.
    // Unit vectors are kept bit for bit.
    let unit = |a: Vec3| {
        if (a.length_squared() - 1.0).abs() < 1e-5 {
            Some(a)
        } else {
            (a / a.abs().max_element()).try_normalize()
        }
    };
    let normal = unit(normal).ok_or_else(|| bad("zero normal"))?;
    let splat = if full {
        if v[13] <= 0.0 {
            return Err(bad("radius_v must be above 0"));
        }
        if let Some(x) = v[14..18].iter().find(|x| x.abs() > MAX_FIELD) {
            return Err(bad(&format!(
                "normal field value {x:e} beyond {MAX_FIELD:e} (a slope across the splat)"
            )));
        }
        if v[18..21].iter().any(|&c| c < 0.0) {
            return Err(bad("negative colour"));
        }
        if with_fields
            && let Some(x) = r.0[DC..CLIP]
                .iter()
                .find(|x| x.is_nan() || x.abs() > MAX_COLOR_FIELD)
        {
            return Err(bad(&format!(
                "colour field value {x:e} not finite or beyond {MAX_COLOR_FIELD:e}"
            )));
        }
        let u = Vec3::new(v[7], v[8], v[9]);
        let u_axis = unit(u)
            .filter(|a| a.dot(normal).abs() < 1e-4)
            .or_else(|| unit(u - normal * normal.dot(u)))
            .ok_or_else(|| bad("u axis zero or along the normal"))?;
        let w = normal.cross(u_axis);
        let given_v = Vec3::new(v[10], v[11], v[12]);
        let v_axis = match unit(given_v) {
            Some(g) if g.dot(w) > 0.9999 => g,
            Some(g) if g.dot(w) < -0.9999 => g,
            Some(g) if g.dot(w).abs() >= 0.99 => w * g.dot(w).signum(),
            _ => {
                return Err(bad("v axis zero or not across the normal and the u axis"));
            }
        };
        Splat {
            center,
            normal,
            u_axis,
            v_axis,
            radii: Vec2::new(v[6], v[13]),
            field: NormalField {
                xc: v[14],
                yc: v[15],
                alpha: v[16],
                beta: v[17],
            },
            color: Vec3::new(v[18], v[19], v[20]),
            clip: if with_clips {
                clip_of(r.0[CLIP..].try_into().expect("six clip values")).map_err(bad)?
            } else {
                Clip::NONE
            },
        }
    } else {
        let mut d = Splat::disc(center, normal, v[6]).ok_or_else(|| bad("zero normal"))?;
        // Discs with a colour (`red green blue`) keep it.
        if rgb.iter().all(|c| c.is_finite() && *c >= 0.0) {
            d.color = Vec3::from_slice(rgb);
        }
        d
    };
    Ok(splat)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Splats of every kind a file holds: discs and ellipses, with Phong
    /// fields, clipped by one and two lines, far from the origin.
    fn sample() -> (Vec<Splat>, Vec<ColorField>) {
        let mut splats = Vec::new();
        let mut fields = Vec::new();
        for k in 0..37u16 {
            let f = f32::from(k);
            let n = Vec3::new(0.3 * f.sin(), 0.2 + 0.1 * f.cos(), 1.0);
            let mut s = Splat::disc(Vec3::new(1e4 + f * 0.37, -2.0 * f, 0.5), n, 0.01 + 0.001 * f).unwrap();
            s.radii.y *= 1.0 + 0.05 * f;
            s.field = NormalField {
                xc: 0.01 * f,
                yc: -0.02 * f,
                alpha: 0.3,
                beta: -0.1 * f,
            };
            s.color = Vec3::new(0.1 * (f % 7.0), 0.5, 1.0 / (1.0 + f));
            let line = |a: f32| ClipLine { a, b: 1.0 - a, d: 0.2 };
            s.clip = match k % 3 {
                0 => Clip::NONE,
                1 => Clip::one(line(0.6)),
                _ => Clip::two(line(0.6), line(-0.8)),
            };
            splats.push(s);
            fields.push(ColorField {
                du: Vec3::splat(0.01 * f),
                dv: Vec3::new(0.0, -0.02, f),
            });
        }
        (splats, fields)
    }

    /// A header with `props` (type, name), then each splat's record of the
    /// values the writer's row gives them by name (doubles, integers and
    /// `uchar` colours as those types hold them).
    fn file_of(props: &[(&str, &str)], splats: &[Splat], fields: &[ColorField]) -> Vec<u8> {
        let mut head = format!("ply\nformat binary_little_endian 1.0\nelement vertex {}\n", splats.len());
        for (t, name) in props {
            head += &format!("property {t} {name}\n");
        }
        head += "end_header\n";
        let mut bytes = head.into_bytes();
        for (s, f) in splats.iter().zip(fields) {
            let row = to_row(s);
            let clip = clip_row(s);
            let dc = [f.du.x, f.du.y, f.du.z, f.dv.x, f.dv.y, f.dv.z];
            for (t, name) in props {
                let at = |names: &[&str]| names.iter().position(|n| n == name);
                let x = at(&SPLAT_PROPS)
                    .map(|k| row[k])
                    .or_else(|| at(&COLOR_FIELD_PROPS).map(|k| dc[k]))
                    .or_else(|| at(&CLIP_PROPS).map(|k| clip[k]))
                    .or_else(|| at(&SRGB_PROPS).map(|k| row[18 + k]))
                    .unwrap_or(7.5);
                match *t {
                    "float" => bytes.extend(x.to_le_bytes()),
                    "double" => bytes.extend((f64::from(x) + 1e-9).to_le_bytes()),
                    "uchar" => bytes.push((x * 200.0) as u8),
                    "short" => bytes.extend((x as i16).to_le_bytes()),
                    _ => unreachable!(),
                }
            }
        }
        bytes
    }

    /// Whether `bytes` are read in place.
    fn in_place(bytes: &[u8]) -> bool {
        let file = PlyFile::open(bytes).unwrap();
        let kind = Kind::of(&file.header).unwrap();
        InPlace::of(&file, kind).is_some()
    }

    /// Both ways of reading `bytes`: in place, row by row.
    fn both(bytes: &[u8]) -> (String, String) {
        let read = |in_place: bool| format!("{:?}", parse(bytes, in_place));
        (read(true), read(false))
    }

    #[test]
    fn splats_read_in_place_are_the_rows_bit_for_bit() {
        let (splats, fields) = sample();
        let written = encode_splats_with(Path::new("t.ply"), &splats, Some(&fields), DVec3::new(5e5, 0.0, -1.0)).unwrap();
        assert!(in_place(&written), "the writer's file reads in place");
        let (fast, rows) = both(&written);
        assert_eq!(fast, rows);
        let back = parse(&written, true).unwrap();
        assert_eq!((back.splats, back.color_fields), (splats.clone(), fields.clone()));
        let f = |n: &'static str| ("float", n);
        let all: Vec<(&str, &str)> = SPLAT_PROPS.iter().map(|n| f(n)).collect();
        let cases: Vec<Vec<(&str, &str)>> = vec![
            // Doubles, an extra property, sRGB `uchar` colours, the clip
            // lines without the colour field, in another order.
            [
                vec![("double", "z"), ("double", "x"), ("short", "label"), ("double", "y")],
                all[3..18].to_vec(),
                vec![("uchar", "red"), ("uchar", "green"), ("uchar", "blue")],
                CLIP_PROPS.iter().map(|n| f(n)).collect(),
            ]
            .concat(),
            // An older file: linear colour as float `red green blue`, and
            // a colour field.
            [
                all[..18].to_vec(),
                vec![f("red"), f("green"), f("blue")],
                COLOR_FIELD_PROPS.iter().map(|n| f(n)).collect(),
            ]
            .concat(),
            // Discs: `x y z nx ny nz radius` and an 8-bit colour.
            [all[..7].to_vec(), vec![("uchar", "red"), ("uchar", "green"), ("uchar", "blue")]].concat(),
            // Discs with a short coordinate.
            vec![f("x"), ("short", "y"), f("z"), f("nx"), f("ny"), f("nz"), f("radius")],
        ];
        for props in &cases {
            let bytes = file_of(props, &splats, &fields);
            assert!(in_place(&bytes));
            let (fast, rows) = both(&bytes);
            assert!(fast.starts_with("Ok"), "{fast}");
            assert_eq!(fast, rows, "{props:?}");
        }
        // Bad splats among good ones, the first near the end of the first
        // half of the rows and the next at the start of the second (where
        // the other thread begins): the first in the file's order is named,
        // read either way.
        let mut many: Vec<Splat> = (0..600).flat_map(|_| splats.iter().copied()).collect();
        let many_fields: Vec<ColorField> = (0..600).flat_map(|_| fields.iter().copied()).collect();
        many[11_050].radii.y = 0.0;
        many[11_150].color.x = -1.0;
        many[20_000].color.y = -3.0;
        let bytes = file_of(&all, &many, &many_fields);
        let (fast, rows) = both(&bytes);
        assert_eq!(fast, rows);
        assert!(fast.contains("splat 11050: radius_v"), "{fast}");
    }
}
