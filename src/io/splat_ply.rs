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

use super::ply::{PlyFile, scalar};
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

/// One splat vertex of a splat file: every property as `f32`, by the index
/// of its name in [`SPLAT_PROPS`].
pub(crate) struct SplatRow {
    pub(crate) v: [f32; SPLAT_PROPS.len()],
    /// `red green blue` made linear: from `uchar` sRGB, or taken as they
    /// are when floats (an older file's linear colour).
    pub(crate) rgb: [f32; 3],
    /// The colour field, by the index of its name in [`COLOR_FIELD_PROPS`].
    pub(crate) dc: [f32; COLOR_FIELD_PROPS.len()],
    /// The clip lines, by the index of their names in [`CLIP_PROPS`].
    pub(crate) clip: [f32; CLIP_PROPS.len()],
}

impl PropertyAccess for SplatRow {
    fn new() -> Self {
        SplatRow {
            v: [f32::NAN; SPLAT_PROPS.len()],
            rgb: [f32::NAN; 3],
            dc: [f32::NAN; COLOR_FIELD_PROPS.len()],
            clip: [f32::NAN; CLIP_PROPS.len()],
        }
    }
    fn set_property(&mut self, name: &str, p: Property) {
        // Lossless for the float32 properties the writer produces.
        let float = |p: Property| match p {
            Property::Float(f) => f,
            other => scalar(&other).map_or(f32::NAN, |d| d as f32),
        };
        if let Some(k) = SRGB_PROPS.iter().position(|n| *n == name) {
            self.rgb[k] = match p {
                Property::UChar(c) => super::srgb_to_linear(f32::from(c) / 255.0),
                other => float(other),
            };
        } else if let Some(k) = COLOR_FIELD_PROPS.iter().position(|n| *n == name) {
            self.dc[k] = float(p);
        } else if let Some(k) = CLIP_PROPS.iter().position(|n| *n == name) {
            self.clip[k] = float(p);
        } else if let Some(i) = SPLAT_PROPS.iter().position(|n| *n == name) {
            self.v[i] = float(p);
        }
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
    let file = PlyFile::open(bytes)?;
    let origin = origin_of(&file.header.comments)?.unwrap_or(DVec3::ZERO);
    let vertex = file
        .header
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
    let with_fields = full && COLOR_FIELD_PROPS.iter().all(|n| has(n));
    let with_clips = full && CLIP_PROPS.iter().all(|n| has(n));
    let rows = file.read_vertices::<SplatRow>()?;
    let mut splats = Vec::with_capacity(rows.len());
    let mut color_fields = Vec::new();
    for (i, r) in rows.iter().enumerate() {
        let mut v = r.v;
        if !linear {
            v[18..].copy_from_slice(&r.rgb);
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
            if with_fields {
                if let Some(x) =
                    r.dc.iter()
                        .find(|x| x.is_nan() || x.abs() > MAX_COLOR_FIELD)
                {
                    return Err(bad(&format!(
                        "colour field value {x:e} not finite or beyond {MAX_COLOR_FIELD:e}"
                    )));
                }
                color_fields.push(ColorField {
                    du: Vec3::new(r.dc[0], r.dc[1], r.dc[2]),
                    dv: Vec3::new(r.dc[3], r.dc[4], r.dc[5]),
                });
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
                    clip_of(&r.clip).map_err(bad)?
                } else {
                    Clip::NONE
                },
            }
        } else {
            let mut d = Splat::disc(center, normal, v[6]).ok_or_else(|| bad("zero normal"))?;
            // Discs with a colour (`red green blue`) keep it.
            if r.rgb.iter().all(|c| c.is_finite() && *c >= 0.0) {
                d.color = Vec3::from(r.rgb);
            }
            d
        };
        splats.push(splat);
    }
    if splats.is_empty() {
        return Err(IoErrorKind::NoPoints("the file holds no splats".into()));
    }
    Ok(SplatSet {
        splats,
        origin,
        color_fields,
    })
}
