//! PLY reading on top of `ply-rs-bw` (ascii, binary little and big endian).
//!
//! The parser is driven element by element with small typed rows instead of
//! its generic hash-map elements. Before a binary body is parsed its minimum
//! size is checked against the bytes that follow the header, so a header that
//! promises more elements than the file holds fails at once with a clear
//! message; `ply-rs-bw` itself caps its reservations, so a huge count never
//! turns into a huge allocation.

use super::batch::{BATCH, PointBatch, StreamInfo};
use super::{Format, IoErrorKind, Mesh, PointCloud, cloud_from_world, srgb_to_linear};
use glam::{DVec3, Vec3};
use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{
    ElementDef, Encoding, Header, Property, PropertyAccess, PropertyType, ScalarType,
};
use std::io::Cursor;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

/// A scalar property as `f64` (lists give `None`).
pub(super) fn scalar(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::Char(v) => f64::from(v),
        Property::UChar(v) => f64::from(v),
        Property::Short(v) => f64::from(v),
        Property::UShort(v) => f64::from(v),
        Property::Int(v) => f64::from(v),
        Property::UInt(v) => f64::from(v),
        Property::Float(v) => f64::from(v),
        Property::Double(v) => v,
        _ => return None,
    })
}

/// A colour property normalised to `[0, 1]` (integers by their type's range).
fn unit_color(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::UChar(v) => f64::from(v) / 255.0,
        Property::UShort(v) => f64::from(v) / 65535.0,
        Property::Char(_) | Property::Short(_) | Property::Int(_) | Property::UInt(_) => {
            scalar(p)? / 255.0
        }
        Property::Float(v) => f64::from(v),
        Property::Double(v) => v,
        _ => return None,
    })
}

/// One vertex of a point cloud: position, optional normal and colour.
pub(crate) struct PointRow {
    v: [f64; 9],
}

impl PropertyAccess for PointRow {
    fn new() -> Self {
        PointRow { v: [f64::NAN; 9] }
    }
    fn set_property(&mut self, name: &str, p: Property) {
        let Some((i, color)) = point_slot(name) else {
            return;
        };
        let val = if color { unit_color(&p) } else { scalar(&p) };
        self.v[i] = val.unwrap_or(f64::NAN);
    }
}

/// One face: its vertex index list, `None` when an index is negative.
struct FaceRow {
    idx: Option<Vec<u32>>,
}

fn list_u32<T: Copy>(v: &[T], f: impl Fn(T) -> Option<u32>) -> Option<Vec<u32>> {
    v.iter().map(|&x| f(x)).collect()
}

impl PropertyAccess for FaceRow {
    fn new() -> Self {
        FaceRow {
            idx: Some(Vec::new()),
        }
    }
    fn set_property(&mut self, name: &str, p: Property) {
        if name != "vertex_indices" && name != "vertex_index" {
            return;
        }
        self.idx = match p {
            Property::ListChar(v) => list_u32(&v, |x| u32::try_from(x).ok()),
            Property::ListUChar(v) => list_u32(&v, |x| Some(u32::from(x))),
            Property::ListShort(v) => list_u32(&v, |x| u32::try_from(x).ok()),
            Property::ListUShort(v) => list_u32(&v, |x| Some(u32::from(x))),
            Property::ListInt(v) => list_u32(&v, |x| u32::try_from(x).ok()),
            Property::ListUInt(v) => Some(v),
            _ => None,
        };
    }
}

/// An element read only to get past it.
struct SkipRow;

impl PropertyAccess for SkipRow {
    fn new() -> Self {
        SkipRow
    }
}

fn scalar_size(t: &ScalarType) -> usize {
    Scalar::of(t).size()
}

/// The fewest bytes a binary element can occupy (lists counted as empty).
fn min_element_bytes(def: &ElementDef) -> usize {
    def.properties
        .values()
        .map(|p| match &p.data_type {
            PropertyType::Scalar(t) => scalar_size(t),
            PropertyType::List(len, _) => scalar_size(len),
        })
        .sum()
}

/// Where face rows (vertex index lists, `None` for a negative index) go.
type FaceSink<'a> = &'a mut dyn FnMut(Vec<Option<Vec<u32>>>);

/// A parsed header and the body that follows it.
pub(crate) struct PlyFile<'a> {
    pub(crate) header: Header,
    cursor: Cursor<&'a [u8]>,
}

impl<'a> PlyFile<'a> {
    /// Parse the header and check that a binary body is long enough for the
    /// header's element counts.
    pub(crate) fn open(bytes: &'a [u8]) -> Result<PlyFile<'a>, IoErrorKind> {
        if !(bytes.starts_with(b"ply\n") || bytes.starts_with(b"ply\r\n")) {
            return Err(IoErrorKind::Header(
                "a PLY file must start with \"ply\"".into(),
            ));
        }
        check_header_names(bytes)?;
        let mut cursor = Cursor::new(bytes);
        let header = Parser::<SkipRow>::new()
            .read_header(&mut cursor)
            .map_err(|e| IoErrorKind::Header(e.to_string()))?;
        if header.encoding != Encoding::Ascii {
            let rest = bytes.len() as u64 - cursor.position().min(bytes.len() as u64);
            let mut need: u128 = 0;
            for def in header.elements.values() {
                need += def.count as u128 * min_element_bytes(def) as u128;
            }
            if need > u128::from(rest) {
                let counts: Vec<String> = header
                    .elements
                    .values()
                    .map(|d| format!("{} {}", d.count, d.name))
                    .collect();
                return Err(IoErrorKind::Truncated(format!(
                    "the header promises {} (at least {need} bytes) but only {rest} bytes follow it",
                    counts.join(" and ")
                )));
            }
        }
        Ok(PlyFile { header, cursor })
    }

    /// Read every element in order, handing the rows of the ones named in
    /// `want` to the callbacks (vertex rows as `V`, face rows as lists).
    fn read<V: PropertyAccess>(
        mut self,
        mut on_vertex: impl FnMut(Vec<V>),
        mut on_face: Option<FaceSink<'_>>,
    ) -> Result<(), IoErrorKind> {
        let defs: Vec<ElementDef> = self.header.elements.values().cloned().collect();
        let mut ascii = (self.header.encoding == Encoding::Ascii).then(|| {
            let bytes = *self.cursor.get_ref();
            let start = (self.cursor.position() as usize).min(bytes.len());
            AsciiBody::new(bytes, start)
        });
        for def in &defs {
            if def.name == "vertex" {
                let rows = match ascii.as_mut() {
                    Some(a) => a.rows::<V>(def)?,
                    None => read_rows::<V>(&mut self.cursor, def, &self.header)?,
                };
                on_vertex(rows);
            } else if def.name == "face" && on_face.is_some() {
                let rows = match ascii.as_mut() {
                    Some(a) => a.rows::<FaceRow>(def)?,
                    None => read_rows::<FaceRow>(&mut self.cursor, def, &self.header)?,
                };
                if let Some(f) = on_face.as_mut() {
                    f(rows.into_iter().map(|r| r.idx).collect());
                }
            } else {
                // Elements after the last one we need are never parsed.
                let later_needed = defs
                    .iter()
                    .skip_while(|d| d.name != def.name)
                    .skip(1)
                    .any(|d| d.name == "vertex" || (d.name == "face" && on_face.is_some()));
                if !later_needed {
                    break;
                }
                match ascii.as_mut() {
                    Some(a) => drop(a.rows::<SkipRow>(def)?),
                    None => drop(read_rows::<SkipRow>(&mut self.cursor, def, &self.header)?),
                }
            }
        }
        Ok(())
    }

    /// Read the vertex element as rows of `V` (must exist).
    pub(crate) fn read_vertices<V: PropertyAccess>(self) -> Result<Vec<V>, IoErrorKind> {
        if !self.header.elements.contains_key("vertex") {
            return Err(IoErrorKind::Header("no \"vertex\" element".into()));
        }
        let mut out = Vec::new();
        self.read::<V>(|rows| out = rows, None)?;
        Ok(out)
    }
}

/// Rejects a header that declares an element twice, or a property twice
/// within one element: `ply-rs-bw` keeps one of each name, and the rows
/// would be read with shifted columns.
fn check_header_names(bytes: &[u8]) -> Result<(), IoErrorKind> {
    let mut elements: Vec<String> = Vec::new();
    let mut props: Vec<String> = Vec::new();
    for (i, line) in bytes.split(|&b| b == b'\n').enumerate() {
        let line = String::from_utf8_lossy(line);
        let mut it = line.split_whitespace();
        match it.next() {
            Some("end_header") => break,
            Some("element") => {
                let name = it.next().unwrap_or("").to_string();
                if elements.contains(&name) {
                    return Err(IoErrorKind::Header(format!(
                        "line {}: element \"{name}\" is declared twice",
                        i + 1
                    )));
                }
                elements.push(name);
                props.clear();
            }
            Some("property") => {
                let name = it.last().unwrap_or("").to_string();
                if props.contains(&name) {
                    return Err(IoErrorKind::Header(format!(
                        "line {}: property \"{name}\" is declared twice in element \"{}\"",
                        i + 1,
                        elements.last().map_or("", String::as_str)
                    )));
                }
                props.push(name);
            }
            _ => {}
        }
    }
    Ok(())
}

/// An ascii PLY body read row by row with the file's line numbers: each
/// element row on its own line, exactly the values its properties take.
/// (`ply-rs-bw`'s ascii reader numbers element rows, not file lines, and
/// rejects `nan`, which every other reader here takes as a point to skip.)
struct AsciiBody<'a> {
    lines: std::iter::Peekable<std::iter::Enumerate<std::str::Lines<'a>>>,
    /// File line number of the body's first line, less one.
    first: usize,
}

impl<'a> AsciiBody<'a> {
    fn new(bytes: &'a [u8], start: usize) -> AsciiBody<'a> {
        let text = std::str::from_utf8(&bytes[start..]).unwrap_or_else(|e| {
            // Up to the first invalid byte; a row past it is then missing.
            std::str::from_utf8(&bytes[start..start + e.valid_up_to()]).unwrap_or("")
        });
        AsciiBody {
            lines: text.lines().enumerate().peekable(),
            first: bytes[..start].iter().filter(|&&b| b == b'\n').count(),
        }
    }

    fn rows<E: PropertyAccess>(&mut self, def: &ElementDef) -> Result<Vec<E>, IoErrorKind> {
        let mut out = Vec::with_capacity(def.count.min(1 << 20));
        for row in 0..def.count {
            let (no, line) = loop {
                match self.lines.next() {
                    Some((_, l)) if l.trim().is_empty() => {}
                    Some((i, l)) => break (self.first + i + 1, l),
                    None => {
                        return Err(IoErrorKind::Truncated(format!(
                            "the file ends after {row} of the {} \"{}\" rows its header promises",
                            def.count, def.name
                        )));
                    }
                }
            };
            let mut toks = line.split_whitespace();
            let mut e = E::new();
            for p in def.properties.values() {
                let v = ascii_property(&mut toks, &p.data_type).map_err(|why| {
                    IoErrorKind::Data(format!(
                        "line {no}: {} {row}, property \"{}\": {why}",
                        def.name, p.name
                    ))
                })?;
                e.set_property(&p.name, v);
            }
            if let Some(extra) = toks.next() {
                return Err(IoErrorKind::Data(format!(
                    "line {no}: {} {row} has values past its properties (\"{extra}\" and on)",
                    def.name
                )));
            }
            out.push(e);
        }
        Ok(out)
    }
}

/// One ascii value (or list) of type `t` from `toks`.
fn ascii_property<'t>(
    toks: &mut impl Iterator<Item = &'t str>,
    t: &PropertyType,
) -> Result<Property, String> {
    fn int<T: TryFrom<i64>>(s: &str) -> Result<T, String> {
        s.parse::<i64>()
            .ok()
            .and_then(|v| T::try_from(v).ok())
            .ok_or_else(|| format!("\"{s}\" is not an integer of its type"))
    }
    fn float(s: &str) -> Result<f64, String> {
        s.parse::<f64>()
            .map_err(|_| format!("\"{s}\" is not a number"))
    }
    let mut next = || toks.next().ok_or_else(|| "the line ends early".to_string());
    Ok(match t {
        PropertyType::Scalar(s) => {
            let v = next()?;
            match s {
                ScalarType::Char => Property::Char(int(v)?),
                ScalarType::UChar => Property::UChar(int(v)?),
                ScalarType::Short => Property::Short(int(v)?),
                ScalarType::UShort => Property::UShort(int(v)?),
                ScalarType::Int => Property::Int(int(v)?),
                ScalarType::UInt => Property::UInt(int(v)?),
                ScalarType::Float => Property::Float(float(v)? as f32),
                ScalarType::Double => Property::Double(float(v)?),
            }
        }
        PropertyType::List(_, item) => {
            let n: u32 = int(next()?)?;
            let mut items = Vec::with_capacity((n as usize).min(64));
            for _ in 0..n {
                items.push(next()?);
            }
            fn each<T>(
                items: &[&str],
                f: impl Fn(&str) -> Result<T, String>,
            ) -> Result<Vec<T>, String> {
                items.iter().map(|s| f(s)).collect()
            }
            match item {
                ScalarType::Char => Property::ListChar(each(&items, int)?),
                ScalarType::UChar => Property::ListUChar(each(&items, int)?),
                ScalarType::Short => Property::ListShort(each(&items, int)?),
                ScalarType::UShort => Property::ListUShort(each(&items, int)?),
                ScalarType::Int => Property::ListInt(each(&items, int)?),
                ScalarType::UInt => Property::ListUInt(each(&items, int)?),
                ScalarType::Float => {
                    Property::ListFloat(each(&items, |s| float(s).map(|x| x as f32))?)
                }
                ScalarType::Double => Property::ListDouble(each(&items, float)?),
            }
        }
    })
}

/// Rejects list-typed properties among `names` of the vertex element: a
/// coordinate, normal or colour must be one number.
pub(crate) fn require_scalars(header: &Header, names: &[&str]) -> Result<(), IoErrorKind> {
    let Some(v) = header.elements.get("vertex") else {
        return Ok(());
    };
    for p in v.properties.values() {
        if names.contains(&p.name.as_str()) && matches!(p.data_type, PropertyType::List(..)) {
            return Err(IoErrorKind::Header(format!(
                "vertex property \"{}\" is a list; it must be a single number",
                p.name
            )));
        }
    }
    Ok(())
}

/// The vertex properties a point cloud or mesh reads.
const POINT_PROPS: [&str; 15] = [
    "x",
    "y",
    "z",
    "nx",
    "ny",
    "nz",
    "red",
    "green",
    "blue",
    "r",
    "g",
    "b",
    "diffuse_red",
    "diffuse_green",
    "diffuse_blue",
];

fn read_rows<E: PropertyAccess>(
    cursor: &mut Cursor<&[u8]>,
    def: &ElementDef,
    header: &Header,
) -> Result<Vec<E>, IoErrorKind> {
    Parser::<E>::new()
        .read_payload_for_element(cursor, def, header)
        .map_err(|e| {
            // ply-rs-bw sometimes wraps the end of file in another error.
            let text = e.to_string();
            if e.kind() == std::io::ErrorKind::UnexpectedEof
                || text.contains("UnexpectedEof")
                || text.contains("fill whole buffer")
            {
                IoErrorKind::Truncated(format!(
                    "the file ends inside element \"{}\" (header promises {}): {e}",
                    def.name, def.count
                ))
            } else {
                IoErrorKind::Data(format!("in element \"{}\": {e}", def.name))
            }
        })
}

/// Does the vertex element declare all of `names`?
fn has_props(header: &Header, names: &[&str]) -> bool {
    header
        .elements
        .get("vertex")
        .is_some_and(|v| names.iter().all(|n| v.properties.contains_key(*n)))
}

fn has_any_prop(header: &Header, names: &[&str]) -> bool {
    header
        .elements
        .get("vertex")
        .is_some_and(|v| names.iter().any(|n| v.properties.contains_key(*n)))
}

/// Read a PLY point cloud: `x y z` (any scalar type, kept in f64 until the
/// cloud is re-centred), optional `nx ny nz` and colour.
pub(crate) fn read_cloud(bytes: &[u8]) -> Result<PointCloud, IoErrorKind> {
    let file = PlyFile::open(bytes)?;
    if !has_props(&file.header, &["x", "y", "z"]) {
        return Err(IoErrorKind::Header(
            "the \"vertex\" element lacks x, y and z properties".into(),
        ));
    }
    require_scalars(&file.header, &POINT_PROPS)?;
    let with_normals = has_props(&file.header, &["nx", "ny", "nz"]);
    let with_colors = has_any_prop(&file.header, &["red", "r", "diffuse_red"])
        && has_any_prop(&file.header, &["green", "g", "diffuse_green"])
        && has_any_prop(&file.header, &["blue", "b", "diffuse_blue"]);
    if let Some(columns) = VertexColumns::of(&file) {
        return columns.cloud(with_normals, with_colors);
    }
    cloud_from_rows(file, with_normals, with_colors)
}

/// [`read_cloud`] through `ply-rs-bw`'s rows: any encoding and layout.
fn cloud_from_rows(
    file: PlyFile<'_>,
    with_normals: bool,
    with_colors: bool,
) -> Result<PointCloud, IoErrorKind> {
    let rows = file.read_vertices::<PointRow>()?;
    let world = rows
        .iter()
        .map(|r| DVec3::new(r.v[0], r.v[1], r.v[2]))
        .collect();
    let normals = with_normals.then(|| {
        rows.iter()
            .map(|r| Vec3::new(r.v[3] as f32, r.v[4] as f32, r.v[5] as f32))
            .collect()
    });
    let colors = with_colors.then(|| {
        rows.iter()
            .map(|r| {
                let c = |x: f64| srgb_to_linear(if x.is_finite() { x as f32 } else { 0.0 });
                Vec3::new(c(r.v[6]), c(r.v[7]), c(r.v[8]))
            })
            .collect()
    });
    cloud_from_world(world, normals, colors)
}

/// Each property of a vertex element: its name, offset in a record and
/// type ([`Records::of`]).
pub(crate) type Properties<'f> = Vec<(&'f str, usize, Scalar)>;

/// The records of a binary little-endian vertex element of scalar
/// properties that comes first in its file, read in place (in parallel by
/// the callers): the point reader's [`VertexColumns`] and the splat
/// file's reader (`super::splat_ply`).
pub(crate) struct Records<'a> {
    body: &'a [u8],
    /// Records in the element.
    pub(crate) count: usize,
    record: usize,
}

impl<'a> Records<'a> {
    /// `None` when the file is not such a file (ascii, big-endian, a list
    /// property, another element first): it is read row by row instead.
    /// With the records, each property's name, offset in a record and type,
    /// in the header's order.
    pub(crate) fn of<'f>(file: &'f PlyFile<'a>) -> Option<(Records<'a>, Properties<'f>)> {
        if file.header.encoding != Encoding::BinaryLittleEndian {
            return None;
        }
        let (name, def) = file.header.elements.get_index(0)?;
        if name != "vertex" {
            return None;
        }
        let mut props = Vec::with_capacity(def.properties.len());
        let mut record = 0;
        for (name, p) in &def.properties {
            let PropertyType::Scalar(t) = &p.data_type else {
                return None;
            };
            let s = Scalar::of(t);
            props.push((name.as_str(), record, s));
            record += s.size();
        }
        let bytes = *file.cursor.get_ref();
        let start = usize::try_from(file.cursor.position()).ok()?;
        let len = def.count.checked_mul(record)?;
        let body = bytes.get(start..start.checked_add(len)?)?;
        Some((
            Records {
                body,
                count: def.count,
                record,
            },
            props,
        ))
    }

    /// The bytes of record `r` from `offset` on.
    #[inline]
    pub(crate) fn at(&self, r: usize, offset: usize) -> &'a [u8] {
        &self.body[r * self.record + offset..]
    }
}

/// A binary little-endian vertex element of scalar properties that comes
/// first in its file ([`Records`]): its records are read in place, in
/// parallel, with the values [`PointRow`] would take (a property's
/// last-named slot wins, as it does there; the slots are [`PointRow`]'s
/// nine).
struct VertexColumns<'a> {
    records: Records<'a>,
    /// (offset in the record, type, a colour's normalisation) of each slot.
    slots: [Option<(usize, Scalar, bool)>; 9],
}

impl<'a> VertexColumns<'a> {
    /// `None` when the file is not such a file ([`Records::of`]).
    fn of(file: &PlyFile<'a>) -> Option<VertexColumns<'a>> {
        let (records, props) = Records::of(file)?;
        let mut slots = [None; 9];
        for (name, offset, s) in props {
            if let Some((slot, color)) = point_slot(name) {
                slots[slot] = Some((offset, s, color));
            }
        }
        Some(VertexColumns { records, slots })
    }

    /// Slot `i` of every record (NaN where the file has no such property).
    fn column(&self, i: usize) -> impl Fn(usize) -> f64 + Sync + '_ {
        move |r| match self.slots[i] {
            Some((o, s, false)) => s.read(self.records.at(r, o)),
            Some((o, s, true)) => s.unit(self.records.at(r, o)),
            None => f64::NAN,
        }
    }

    fn cloud(&self, with_normals: bool, with_colors: bool) -> Result<PointCloud, IoErrorKind> {
        use rayon::prelude::*;
        let v3 = |a: usize| {
            let (x, y, z) = (self.column(a), self.column(a + 1), self.column(a + 2));
            move |r: usize| DVec3::new(x(r), y(r), z(r))
        };
        let count = self.records.count;
        let world: Vec<DVec3> = (0..count).into_par_iter().map(v3(0)).collect();
        let normals = with_normals.then(|| {
            let n = v3(3);
            (0..count).into_par_iter().map(|r| n(r).as_vec3()).collect()
        });
        let colors = with_colors.then(|| {
            let c = v3(6);
            let lin = |x: f64| srgb_to_linear(if x.is_finite() { x as f32 } else { 0.0 });
            (0..count)
                .into_par_iter()
                .map(|r| {
                    let c = c(r);
                    Vec3::new(lin(c.x), lin(c.y), lin(c.z))
                })
                .collect()
        });
        cloud_from_world(world, normals, colors)
    }
}

/// [`PointRow`]'s slot for a property name, and whether it is a colour.
fn point_slot(name: &str) -> Option<(usize, bool)> {
    Some(match name {
        "x" => (0, false),
        "y" => (1, false),
        "z" => (2, false),
        "nx" => (3, false),
        "ny" => (4, false),
        "nz" => (5, false),
        "red" | "r" | "diffuse_red" => (6, true),
        "green" | "g" | "diffuse_green" => (7, true),
        "blue" | "b" | "diffuse_blue" => (8, true),
        _ => return None,
    })
}

/// Read a PLY mesh: vertices and fan-triangulated faces.
pub(crate) fn read_mesh(bytes: &[u8]) -> Result<Mesh, IoErrorKind> {
    read_mesh_full(bytes).map(|m| m.mesh)
}

/// A PLY mesh as [`read_mesh`] reads it, with what a mesh rendered as
/// triangles also needs: the vertex normals where the file has `nx ny nz`,
/// and the file's face each triangle comes from (0-based).
pub(crate) struct MeshRead {
    pub(crate) mesh: Mesh,
    pub(crate) normals: Option<Vec<Vec3>>,
    pub(crate) face_of: Vec<u32>,
}

/// [`read_mesh`] with the vertex normals and each triangle's face.
pub(crate) fn read_mesh_full(bytes: &[u8]) -> Result<MeshRead, IoErrorKind> {
    let file = PlyFile::open(bytes)?;
    if !has_props(&file.header, &["x", "y", "z"]) {
        return Err(IoErrorKind::Header(
            "the \"vertex\" element lacks x, y and z properties".into(),
        ));
    }
    let face_ok = file.header.elements.get("face").is_some_and(|f| {
        f.properties.contains_key("vertex_indices") || f.properties.contains_key("vertex_index")
    });
    if !face_ok {
        return Err(IoErrorKind::Header(
            "no \"face\" element with a vertex_indices list: not a mesh".into(),
        ));
    }
    require_scalars(&file.header, &POINT_PROPS)?;
    if let Some(p) = file.header.elements.get("face").and_then(|f| {
        f.properties
            .values()
            .find(|p| p.name == "vertex_indices" || p.name == "vertex_index")
    }) && !matches!(
        p.data_type,
        PropertyType::List(
            _,
            ScalarType::Char
                | ScalarType::UChar
                | ScalarType::Short
                | ScalarType::UShort
                | ScalarType::Int
                | ScalarType::UInt
        )
    ) {
        return Err(IoErrorKind::Header(format!(
            "face property \"{}\" must be a list of integers, got {:?}",
            p.name, p.data_type
        )));
    }
    let with_normals = has_props(&file.header, &["nx", "ny", "nz"]);
    let mut world: Vec<DVec3> = Vec::new();
    let mut normals = None;
    let mut faces = Vec::new();
    let mut take_faces = |rows: Vec<Option<Vec<u32>>>| faces = rows;
    file.read::<PointRow>(
        |rows| {
            world = rows
                .iter()
                .map(|r| DVec3::new(r.v[0], r.v[1], r.v[2]))
                .collect();
            normals = with_normals.then(|| {
                rows.iter()
                    .map(|r| Vec3::new(r.v[3] as f32, r.v[4] as f32, r.v[5] as f32))
                    .collect()
            });
        },
        Some(&mut take_faces),
    )?;
    // Re-centred in f64 before single precision, as a point cloud is.
    let finite: Vec<DVec3> = world.iter().copied().filter(|p| p.is_finite()).collect();
    let origin = crate::data::robust_centre_size(finite.len(), |i| finite[i])
        .map_or(DVec3::ZERO, |(centre, _)| centre);
    let positions: Vec<Vec3> = world.iter().map(|p| (*p - origin).as_vec3()).collect();
    let n = positions.len();
    let mut triangles = Vec::with_capacity(faces.len());
    let mut face_of = Vec::with_capacity(faces.len());
    for (fi, face) in faces.iter().enumerate() {
        let Some(idx) = face else {
            return Err(IoErrorKind::Data(format!(
                "face {fi} has a negative vertex index"
            )));
        };
        if let Some(&bad) = idx.iter().find(|&&i| i as usize >= n) {
            return Err(IoErrorKind::Data(format!(
                "face {fi} uses vertex {bad} but there are only {n} vertices"
            )));
        }
        if let Some(&bad) = idx.iter().find(|&&i| !positions[i as usize].is_finite()) {
            return Err(IoErrorKind::Data(format!(
                "face {fi} uses vertex {bad}, which has a non-finite coordinate"
            )));
        }
        for k in 1..idx.len().saturating_sub(1) {
            triangles.push([idx[0], idx[k], idx[k + 1]]);
            face_of.push(fi as u32);
        }
    }
    if triangles.is_empty() {
        return Err(IoErrorKind::NoPoints("the mesh has no triangles".into()));
    }
    Ok(MeshRead {
        mesh: Mesh {
            positions,
            triangles,
            origin,
        },
        normals,
        face_of,
    })
}

/// A scalar type of a binary little-endian PLY.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }
    fn of(t: &ScalarType) -> Scalar {
        match t {
            ScalarType::Char => Scalar::I8,
            ScalarType::UChar => Scalar::U8,
            ScalarType::Short => Scalar::I16,
            ScalarType::UShort => Scalar::U16,
            ScalarType::Int => Scalar::I32,
            ScalarType::UInt => Scalar::U32,
            ScalarType::Float => Scalar::F32,
            ScalarType::Double => Scalar::F64,
        }
    }
    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
    pub(crate) fn read(self, b: &[u8]) -> f64 {
        let a = |n: usize| -> [u8; 8] {
            let mut x = [0u8; 8];
            x[..n].copy_from_slice(&b[..n]);
            x
        };
        match self {
            Scalar::I8 => f64::from(b[0] as i8),
            Scalar::U8 => f64::from(b[0]),
            Scalar::I16 => f64::from(i16::from_le_bytes([b[0], b[1]])),
            Scalar::U16 => f64::from(u16::from_le_bytes([b[0], b[1]])),
            Scalar::I32 => f64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Scalar::U32 => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Scalar::F32 => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            Scalar::F64 => f64::from_le_bytes(a(8)),
        }
    }
    /// A colour value normalised to `[0, 1]` as the whole-file reader does.
    fn unit(self, b: &[u8]) -> f64 {
        match self {
            Scalar::U16 => self.read(b) / 65535.0,
            Scalar::F32 | Scalar::F64 => self.read(b),
            _ => self.read(b) / 255.0,
        }
    }
}

/// Where a binary PLY's vertex fields lie.
pub(crate) struct PlyLayout {
    header_bytes: u64,
    count: u64,
    record: usize,
    /// (offset, type) of x, y, z.
    xyz: [(usize, Scalar); 3],
    normal: Option<[(usize, Scalar); 3]>,
    color: Option<[(usize, Scalar); 3]>,
}

/// The layout of `path` when it is a binary little-endian PLY whose first
/// element is `vertex` with scalar `x y z` (and maybe normals and colours),
/// `None` for any other file (read whole instead).
pub(crate) fn binary_ply_layout(path: &Path) -> Result<Option<PlyLayout>, IoErrorKind> {
    let sniffed = super::file_head(path).and_then(|h| Format::sniff(&h));
    if sniffed != Some(Format::Ply) {
        return Ok(None);
    }
    let file = std::fs::File::open(path).map_err(IoErrorKind::Io)?;
    let mut r = BufReader::new(file.take(1 << 20));
    let mut header_bytes = 0u64;
    let mut line = String::new();
    let mut binary_le = false;
    let mut count = None;
    let mut props: Vec<(String, Scalar)> = Vec::new();
    let mut in_vertex = false;
    let mut seen_element = false;
    loop {
        line.clear();
        let n = r.read_line(&mut line).map_err(IoErrorKind::Io)?;
        if n == 0 {
            return Ok(None);
        }
        header_bytes += n as u64;
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["end_header"] => break,
            ["format", f, _] => binary_le = *f == "binary_little_endian",
            ["element", name, c] => {
                if !seen_element {
                    seen_element = true;
                    in_vertex = *name == "vertex";
                    count = c.parse::<u64>().ok();
                } else {
                    in_vertex = false;
                }
            }
            ["property", "list", ..] if in_vertex => return Ok(None),
            ["property", t, name] if in_vertex => match Scalar::parse(t) {
                Some(s) => props.push(((*name).to_string(), s)),
                None => return Ok(None),
            },
            _ => {}
        }
    }
    let (Some(count), true) = (count, binary_le) else {
        return Ok(None);
    };
    let mut offset = 0;
    let mut at = std::collections::HashMap::new();
    for (name, s) in &props {
        at.insert(name.as_str(), (offset, *s));
        offset += s.size();
    }
    let find = |names: [&str; 3]| -> Option<[(usize, Scalar); 3]> {
        Some([*at.get(names[0])?, *at.get(names[1])?, *at.get(names[2])?])
    };
    let Some(xyz) = find(["x", "y", "z"]) else {
        return Ok(None);
    };
    let color = find(["red", "green", "blue"])
        .or_else(|| find(["r", "g", "b"]))
        .or_else(|| find(["diffuse_red", "diffuse_green", "diffuse_blue"]));
    Ok(Some(PlyLayout {
        header_bytes,
        count,
        record: offset,
        xyz,
        normal: find(["nx", "ny", "nz"]),
        color,
    }))
}

/// Streams a binary PLY of layout `l` from disk (moved from `stream`).
pub(crate) fn stream_binary_ply(
    path: &Path,
    l: &PlyLayout,
    each: &mut dyn FnMut(&PointBatch<'_>) -> Result<(), String>,
) -> Result<StreamInfo, IoErrorKind> {
    let mut file =
        BufReader::with_capacity(1 << 22, std::fs::File::open(path).map_err(IoErrorKind::Io)?);
    std::io::copy(&mut (&mut file).take(l.header_bytes), &mut std::io::sink())
        .map_err(IoErrorKind::Io)?;
    let mut info = StreamInfo {
        normals: l.normal.is_some(),
        colors: l.color.is_some(),
        streamed: true,
        ..StreamInfo::default()
    };
    let mut buf = vec![0u8; l.record * BATCH];
    let (mut world, mut normals, mut colors) = (
        Vec::with_capacity(BATCH),
        Vec::with_capacity(BATCH),
        Vec::with_capacity(BATCH),
    );
    let mut left = l.count;
    while left > 0 {
        let take = left.min(BATCH as u64) as usize;
        let bytes = &mut buf[..take * l.record];
        file.read_exact(bytes).map_err(|e| {
            if e.kind() == std::io::ErrorKind::UnexpectedEof {
                IoErrorKind::Truncated(format!(
                    "the header promises {} points, the file ends within point {}",
                    l.count,
                    l.count - left + 1
                ))
            } else {
                IoErrorKind::Io(e)
            }
        })?;
        world.clear();
        normals.clear();
        colors.clear();
        for rec in bytes.chunks_exact(l.record) {
            let v = |f: [(usize, Scalar); 3]| f.map(|(o, s)| s.read(&rec[o..]));
            let p = DVec3::from(v(l.xyz));
            if !p.is_finite() {
                info.non_finite += 1;
                continue;
            }
            world.push(p);
            if let Some(n) = l.normal {
                normals.push(DVec3::from(v(n)).as_vec3());
            }
            if let Some(c) = l.color {
                let c = c.map(|(o, s)| {
                    let x = s.unit(&rec[o..]);
                    srgb_to_linear(if x.is_finite() { x as f32 } else { 0.0 })
                });
                colors.push(Vec3::from(c));
            }
        }
        each(&PointBatch {
            world: &world,
            normals: l.normal.map(|_| &normals[..]),
            colors: l.color.map(|_| &colors[..]),
            scans: None,
        })
        .map_err(IoErrorKind::Data)?;
        info.points += world.len() as u64;
        left -= take as u64;
    }
    Ok(info)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A binary little-endian PLY: a header of `props` (type, name), then
    /// `n` records of the `value(row, column)` each type holds, then `tail`.
    fn binary_ply(props: &[(&str, &str)], n: usize, tail: &str, extra: &[u8]) -> Vec<u8> {
        let mut out = format!("ply\nformat binary_little_endian 1.0\nelement vertex {n}\n");
        for (t, name) in props {
            out += &format!("property {t} {name}\n");
        }
        out += tail;
        out += "end_header\n";
        let mut bytes = out.into_bytes();
        for r in 0..n {
            for (c, (t, _)) in props.iter().enumerate() {
                let v = ((r * 7 + c * 13) % 251) as f64 * 0.37 - 20.0;
                match *t {
                    "double" => bytes.extend((1e6 + v * 1.000_001).to_le_bytes()),
                    "float" if r == 3 && c == 1 => bytes.extend(f32::NAN.to_le_bytes()),
                    "float" => bytes.extend((v as f32 * 0.01).to_le_bytes()),
                    "uchar" => bytes.push((r * 31 + c) as u8),
                    "char" => bytes.push((r * 31 + c) as u8),
                    "ushort" => bytes.extend(((r * 977 + c) as u16).to_le_bytes()),
                    "short" => bytes.extend(((r * 977 + c) as i16 - 9000).to_le_bytes()),
                    "int" => bytes.extend(((r * 99_991) as i32 - 7).to_le_bytes()),
                    "uint" => bytes.extend(((r * 99_991) as u32).to_le_bytes()),
                    _ => unreachable!(),
                }
            }
        }
        bytes.extend_from_slice(extra);
        bytes
    }

    fn both(bytes: &[u8]) -> (String, String) {
        let read = |fast: bool| {
            let file = PlyFile::open(bytes).unwrap();
            let n = has_props(&file.header, &["nx", "ny", "nz"]);
            let c = has_any_prop(&file.header, &["red", "r", "diffuse_red"])
                && has_any_prop(&file.header, &["green", "g", "diffuse_green"])
                && has_any_prop(&file.header, &["blue", "b", "diffuse_blue"]);
            let cloud = if fast {
                VertexColumns::of(&file).expect("read in place").cloud(n, c)
            } else {
                cloud_from_rows(file, n, c)
            };
            format!("{:?}", cloud.unwrap())
        };
        (read(true), read(false))
    }

    #[test]
    fn vertices_read_in_place_are_the_rows_bit_for_bit() {
        let cases: Vec<Vec<u8>> = vec![
            // Doubles far from zero, float normals, uchar colours, extras, faces.
            binary_ply(
                &[
                    ("double", "x"),
                    ("float", "intensity"),
                    ("double", "y"),
                    ("double", "z"),
                    ("float", "nx"),
                    ("float", "ny"),
                    ("float", "nz"),
                    ("uchar", "red"),
                    ("uchar", "green"),
                    ("uchar", "blue"),
                    ("ushort", "label"),
                ],
                40,
                "element face 1\nproperty list uchar int vertex_indices\n",
                &[3, 0, 0, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0],
            ),
            // Every integer type, colours under two names (the last wins),
            // a NaN coordinate (row 3, column 1) dropped and counted.
            binary_ply(
                &[
                    ("float", "x"),
                    ("float", "y"),
                    ("int", "z"),
                    ("ushort", "red"),
                    ("short", "g"),
                    ("char", "diffuse_blue"),
                    ("uint", "b"),
                    ("uchar", "diffuse_red"),
                ],
                25,
                "",
                &[],
            ),
            // Positions alone; half a normal (nx) is no normal.
            binary_ply(
                &[("float", "x"), ("float", "y"), ("float", "z"), ("float", "nx")],
                9,
                "",
                &[],
            ),
        ];
        for bytes in &cases {
            let (fast, rows) = both(bytes);
            assert_eq!(fast, rows);
        }
        assert!(both(&cases[1]).0.contains("non-finite"), "{}", both(&cases[1]).0);
    }

    #[test]
    fn only_a_first_binary_little_endian_vertex_element_of_scalars_reads_in_place() {
        let xyz = [("float", "x"), ("float", "y"), ("float", "z")];
        let ok = binary_ply(&xyz, 4, "", &[]);
        assert!(VertexColumns::of(&PlyFile::open(&ok).unwrap()).is_some());
        let xyz_props = "property float x\nproperty float y\nproperty float z\n";
        let big = format!("ply\nformat binary_big_endian 1.0\nelement vertex 1\n{xyz_props}end_header\n");
        let big = [big.as_bytes(), &[0; 12]].concat();
        assert!(VertexColumns::of(&PlyFile::open(&big).unwrap()).is_none());
        let later = format!(
            "ply\nformat binary_little_endian 1.0\nelement camera 1\nproperty float k\nelement vertex 1\n{xyz_props}end_header\n"
        );
        let later = [later.as_bytes(), &[0; 16]].concat();
        assert!(VertexColumns::of(&PlyFile::open(&later).unwrap()).is_none());
        let list = binary_ply(&xyz, 0, "property list uchar int extra\n", &[]);
        assert!(VertexColumns::of(&PlyFile::open(&list).unwrap()).is_none());
    }
}
