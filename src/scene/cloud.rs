//! A scene for a point cloud given alone (`splatray render CLOUD.pcd`): one
//! model from the cloud, a camera that shows all of it, a headlight and a key
//! light, a material and a background — written as scene-file text, so the
//! scene rendered and the scene saved for editing are the same text.
//!
//! The camera (see [`choose_view`]):
//!
//! - **At the cloud's viewpoint** (PCD `VIEWPOINT`, or the scanner position
//!   of a synthetic scan) looking at the centre of the cloud, when that is
//!   sensible: every point in front of it and the cloud seen within a
//!   100° field of view. A viewpoint so far away that the cloud would span
//!   less than 5° is kept as a direction: the camera moves in along that line
//!   of sight.
//! - **Otherwise framing the cloud**: a three-quarter view from the front
//!   right, 25° above (40° for a flat cloud), on the viewpoint's side when
//!   there is one; "front" is `+z` for a `+y` up axis, `-y` for `+z`.
//!
//! In both, the field of view (or, framing, the distance and the point
//! looked at, centring the cloud's image) is set so that every point fits
//! the frame with a 7.5 % margin. Points are a sample of at most
//! [`SURVEY_SAMPLE`], without the outliers splat generation leaves out
//! ([`crate::splat::outliers`]).
//!
//! The up vector, unless given (`--up`):
//!
//! 1. **A flat cloud** (its thinnest bounding-box side under a quarter of the
//!    middle one: terrain, a floor, a table top): its thinnest axis, on the
//!    viewpoint's side — unless the camera at the viewpoint looks along that
//!    axis (a wall seen face on).
//! 2. **Camera at the viewpoint**: `+z` when the viewpoint looks down on the
//!    cloud's centre along `+z` by at least 5° more than along `+y` (a
//!    scanner stands upright and looks level or down); else `+y`. An axis
//!    within 40° of the line of sight is never chosen.
//! 3. **Otherwise** `+y`, the convention of PLY and graphics data — or `-y`
//!    when the cloud's lowest tenth along `-y` spans more than
//!    [`UPRIGHT_RATIO`] times the area of its lowest tenth along `+y`: it
//!    stands on that wider end (a model in a y-down camera frame, as
//!    OpenCV's).
//!
//! The rest: a point light at the camera (a headlight: irradiance 0.25 at
//! the centre) and a directional key light from the upper left, a little in
//! front (0.85), ambient 0.05; a grey Phong material, or the points' own
//! colours (Phong, albedo 0.85 times the colour) when the file has colour;
//! a dark blue-grey background; splat parameters at their defaults (the
//! file's viewpoint orients the normals, as in any scene).

use crate::io::{
    Format, GaussianRead, IoError, PointCloud, SplatSet, file_head as head,
    read_points_keeping_bytes, read_splats,
};
use crate::resolve::ShadingMode;
use crate::scene::model::Intrinsics;
use crate::{Error, Result};
use glam::{DVec3, Vec3};
use std::fmt::Write as _;
use std::path::{Component, Path, PathBuf};

/// Points of the cloud used for framing, at most.
pub const SURVEY_SAMPLE: usize = 20_000;
/// Default image size of a cloud's scene.
pub const DEFAULT_SIZE: (u32, u32) = (800, 600);

/// What the file holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CloudKind {
    /// Points (PLY, PCD, XYZ; a mesh PLY gives its vertices): a `points`
    /// model.
    Points,
    /// A splat PLY written by `splatray splat`: a `splats` model.
    Splats,
    /// A Gaussian splat PLY (2DGS or 3DGS layout): a `gaussians` model.
    Gaussians,
}

impl CloudKind {
    /// The scene file's key for this kind of model.
    #[must_use]
    pub fn key(self) -> &'static str {
        match self {
            CloudKind::Points => "points",
            CloudKind::Splats => "splats",
            CloudKind::Gaussians => "gaussians",
        }
    }
}

/// Whether `path` names a point cloud rather than a scene file: a `.ply`,
/// `.pcd`, `.xyz` or `.txt` extension, or (any extension but `.toml`) a file
/// whose first bytes are PLY, PCD or XYZ.
#[must_use]
pub fn is_cloud_path(path: &Path) -> bool {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    if ext.as_deref() == Some("toml") {
        return false;
    }
    if Format::from_extension(path).is_some() {
        return true;
    }
    head(path).is_some_and(|h| Format::sniff(&h).is_some())
}

/// Whether a PLY file is a splat file: its `vertex` element has the
/// properties `read_splats` needs (`x y z nx ny nz radius`).
#[must_use]
pub fn is_splat_ply(path: &Path) -> bool {
    head(path).is_some_and(|h| splat_ply_head(&h))
}

/// [`is_splat_ply`] on a file's first bytes.
fn splat_ply_head(head: &[u8]) -> bool {
    let Some(found) = crate::io::vertex_property_names(head) else {
        return false;
    };
    ["x", "y", "z", "nx", "ny", "nz", "radius"]
        .iter()
        .all(|p| found.iter().any(|f| f == p))
}

/// What the camera and materials need to know of a cloud.
#[derive(Clone, Debug)]
pub struct Survey {
    /// Points or splats.
    pub kind: CloudKind,
    /// Points (or splats) in the file.
    pub points: usize,
    /// Where the scanner stood, when the file says.
    pub viewpoint: Option<DVec3>,
    /// Whether the points carry colour.
    pub colors: bool,
    /// The framing sample without its outliers.
    pub sample: Vec<DVec3>,
    /// Sample points left out as outliers.
    pub outliers: usize,
    /// Bounding box of [`Survey::sample`].
    pub lo: DVec3,
    /// Bounding box of [`Survey::sample`].
    pub hi: DVec3,
    /// The sensor of an organised cloud (a PCD with `HEIGHT` > 1), or why
    /// none could be fitted.
    pub sensor: Option<std::result::Result<super::sensor::Sensor, String>>,
}

impl Survey {
    /// Centre of the bounding box.
    #[must_use]
    pub fn center(&self) -> DVec3 {
        0.5 * (self.lo + self.hi)
    }

    /// Half the bounding box's diagonal (never zero).
    #[must_use]
    pub fn radius(&self) -> f64 {
        (0.5 * (self.hi - self.lo).length()).max(1e-30)
    }
}

/// A cloud file as [`read_and_survey`] read it: what the scene made for it
/// takes instead of reading the file again.
#[derive(Debug)]
pub enum CloudRead {
    /// A point cloud.
    Points(PointCloud),
    /// A splat file.
    Splats(SplatSet),
    /// A Gaussian splat file (read with the default opacity threshold).
    Gaussians(GaussianRead),
}

/// Reads a cloud (points or a splat file) and surveys it.
///
/// # Errors
/// The reader's one-line error (no usable point among them).
pub fn survey_file(path: &Path) -> Result<Survey> {
    read_and_survey(path).map(|(s, _)| s)
}

/// [`survey_file`], and what was read, for the scene built from the survey
/// (`build_scene_read`): the file is read once.
///
/// # Errors
/// As [`survey_file`].
pub fn read_and_survey(path: &Path) -> Result<(Survey, CloudRead)> {
    let (s, read) = survey_unchecked(path)?;
    let span = 2.0 * s.radius();
    if span.is_nan() || span > f64::from(super::load::MAX_EXTENT) {
        return Err(Error::invalid(format!(
            "{}: the {} span {span:.2e}, beyond the {:e} the renderer's f32 geometry holds",
            path.display(),
            s.kind.key(),
            super::load::MAX_EXTENT
        )));
    }
    Ok((s, read))
}

/// [`read_and_survey`] without the extent check. The file's first bytes are
/// read once to tell its kind, then the whole file once.
fn survey_unchecked(path: &Path) -> Result<(Survey, CloudRead)> {
    let first = head(path).unwrap_or_default();
    let sniffed = Format::sniff(&first);
    let is_ply = Format::from_extension(path) == Some(Format::Ply) || sniffed == Some(Format::Ply);
    let read = if !is_ply {
        None
    } else if crate::io::sniff_layout(&first).is_some() {
        let read = crate::io::read_gaussians(path, crate::io::MIN_OPACITY)?;
        Some((CloudKind::Gaussians, CloudRead::Gaussians(read)))
    } else if splat_ply_head(&first) {
        Some((CloudKind::Splats, CloudRead::Splats(read_splats(path)?)))
    } else {
        None
    };
    if let Some((kind, read)) = read {
        let set = match &read {
            CloudRead::Gaussians(g) => &g.set,
            CloudRead::Splats(s) => s,
            CloudRead::Points(_) => unreachable!("a splat file"),
        };
        let centres: Vec<Vec3> = set.splats.iter().map(|s| s.center).collect();
        let colors = set.splats.iter().any(|s| s.color != Vec3::ONE);
        let s = survey(kind, &centres, set.origin, None, colors)
            .map_err(|e| e.context(path.display()))?;
        return Ok((s, read));
    }
    let (cloud, bytes, format) = read_points_keeping_bytes(path)?;
    let colors = cloud
        .colors
        .as_ref()
        .is_some_and(|c| c.len() == cloud.len());
    let mut s = survey(
        CloudKind::Points,
        &cloud.positions,
        cloud.origin,
        cloud.viewpoint,
        colors,
    )
    .map_err(|e| e.context(path.display()))?;
    if format == Format::Pcd || sniffed == Some(Format::Pcd) {
        let grid = crate::io::read_organised(&bytes).map_err(|k| IoError::new(path, k))?;
        s.sensor = grid.map(|g| super::sensor::recover(&g));
    }
    Ok((s, CloudRead::Points(cloud)))
}

/// Surveys positions, offsets from `origin` (as the readers give them; the
/// viewpoint is in the same frame): a sample of at most [`SURVEY_SAMPLE`]
/// (every n-th point), its outliers removed, and its bounding box, all in
/// the file's coordinates.
///
/// # Errors
/// When no position is finite.
pub fn survey(
    kind: CloudKind,
    positions: &[Vec3],
    origin: DVec3,
    viewpoint: Option<Vec3>,
    colors: bool,
) -> Result<Survey> {
    let finite: Vec<Vec3> = positions
        .iter()
        .copied()
        .filter(|p| p.is_finite())
        .collect();
    if finite.is_empty() {
        return Err(Error::invalid("the cloud has no usable point"));
    }
    let stride = finite.len().div_ceil(SURVEY_SAMPLE);
    let sample: Vec<Vec3> = finite.iter().step_by(stride).copied().collect();
    let viewpoint = viewpoint.filter(|v| v.is_finite());
    let keep = inliers(&sample, viewpoint);
    let outliers = keep.iter().filter(|k| !**k).count();
    let sample: Vec<DVec3> = sample
        .iter()
        .zip(&keep)
        .filter(|(_, k)| **k)
        .map(|(p, _)| origin + p.as_dvec3())
        .collect();
    let (lo, hi) = sample.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    Ok(Survey {
        kind,
        points: positions.len(),
        viewpoint: viewpoint.map(|v| origin + v.as_dvec3()),
        colors,
        sample,
        outliers,
        lo,
        hi,
        sensor: None,
    })
}

/// Which sample points are not outliers, by the test splat generation
/// uses before growing splats ([`crate::splat::outliers`], on the sample's
/// 8 nearest neighbours; ranges from `viewpoint` when there is one). Exact
/// duplicates are kept with the point they repeat. Small samples (under 32
/// points) keep everything.
fn inliers(sample: &[Vec3], viewpoint: Option<Vec3>) -> Vec<bool> {
    const K: usize = 8;
    // Distinct points (the neighbour graph needs them), each with the
    // indices of the sample points at its position.
    let mut order: Vec<usize> = (0..sample.len()).collect();
    let key = |i: usize| sample[i].to_array().map(f32::to_bits);
    order.sort_by_key(|&i| key(i));
    let mut distinct: Vec<Vec3> = Vec::new();
    let mut slot = vec![0usize; sample.len()];
    for (j, &i) in order.iter().enumerate() {
        if j == 0 || key(order[j - 1]) != key(i) {
            distinct.push(sample[i]);
        }
        slot[i] = distinct.len() - 1;
    }
    if distinct.len() < 32 {
        return vec![true; sample.len()];
    }
    let out = crate::splat::outliers::find(
        &distinct,
        K,
        viewpoint.map(crate::splat::Viewpoints::One).as_ref(),
    );
    slot.iter().map(|&d| !out[d]).collect()
}

/// A camera for a cloud, and why it was chosen.
#[derive(Clone, Debug, PartialEq)]
pub struct View {
    /// Eye.
    pub from: DVec3,
    /// Point looked at: the centre of the cloud's bounding box, or (when
    /// framing) the point level with it in the middle of the cloud's image.
    pub at: DVec3,
    /// Up vector (unit).
    pub up: DVec3,
    /// Vertical field of view, degrees.
    pub fov: f64,
    /// A sensor's intrinsics and image size (pixels) instead of `fov`: the
    /// view of an organised cloud's camera.
    pub sensor: Option<(Intrinsics, u32, u32)>,
    /// One line: where the camera is and which way is up, and why.
    pub note: String,
}

/// Unit axis names for notes.
fn axis_name(a: DVec3) -> String {
    for (v, n) in [
        (DVec3::X, "+x"),
        (DVec3::Y, "+y"),
        (DVec3::Z, "+z"),
        (DVec3::NEG_X, "-x"),
        (DVec3::NEG_Y, "-y"),
        (DVec3::NEG_Z, "-z"),
    ] {
        if a == v {
            return n.to_string();
        }
    }
    format!("[{:.3}, {:.3}, {:.3}]", a.x, a.y, a.z)
}

/// Right and true up of a camera looking along `f` with up hint `up`, as
/// `Camera::look_at` forms them; `None` when they are parallel.
fn frame(f: DVec3, up: DVec3) -> Option<(DVec3, DVec3)> {
    let r = f.cross(up).try_normalize()?;
    Some((r, r.cross(f)))
}

/// Tangents of the half angles (vertical, horizontal) the points need seen
/// from `eye` along `f`, or `None` when a point is not in front of it.
fn needed_tangents(points: &[DVec3], eye: DVec3, f: DVec3, up: DVec3) -> Option<(f64, f64)> {
    let (r, u) = frame(f, up)?;
    let mut t = (0.0f64, 0.0f64);
    for p in points {
        let q = *p - eye;
        let z = q.dot(f);
        if z <= 0.0 {
            return None;
        }
        t.0 = t.0.max(q.dot(u).abs() / z);
        t.1 = t.1.max(q.dot(r).abs() / z);
    }
    Some(t)
}

/// The distance from `at` along `-f` at which every point fits a frame of
/// half-angle tangents `ty` (vertical) and `tx` (horizontal).
fn fit_distance(points: &[DVec3], at: DVec3, f: DVec3, up: DVec3, tx: f64, ty: f64) -> f64 {
    let Some((r, u)) = frame(f, up) else {
        return 0.0;
    };
    let mut d = 0.0f64;
    let mut near = 0.0f64;
    for p in points {
        let q = *p - at;
        let z = q.dot(f);
        d = d.max((q.dot(r).abs() / tx).max(q.dot(u).abs() / ty) - z);
        near = near.max(-z);
    }
    d.max(near)
}

/// The nearest eye looking along `f` whose frame (half-angle tangents `ty`
/// vertical, `tx` horizontal) holds every point, with the points' extremes
/// centred in the frame, and the point it looks at (level with `c`).
///
/// Across each image axis, the two frustum planes must pass through the
/// extreme points: with `x` along the axis and `z` along `f`, the left plane
/// `x + t z = min(x + t z)` and the right `x - t z = max(x - t z)` meet at
/// the eye's `x` and `z`; of the two axes' `z`, the one further back wins.
fn fit_centred(
    points: &[DVec3],
    c: DVec3,
    f: DVec3,
    up: DVec3,
    tx: f64,
    ty: f64,
) -> Option<(DVec3, DVec3)> {
    let (r, u) = frame(f, up)?;
    let across = |axis: DVec3, t: f64| {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for p in points {
            let q = *p - c;
            let (x, z) = (q.dot(axis), q.dot(f));
            lo = lo.min(x + t * z);
            hi = hi.max(x - t * z);
        }
        (0.5 * (lo + hi), 0.5 * (lo - hi) / t)
    };
    let (ex, zx) = across(r, tx);
    let (ey, zy) = across(u, ty);
    let ez = zx.min(zy);
    let eye = c + r * ex + u * ey + f * ez;
    (eye.is_finite() && ez < 0.0).then_some((eye, eye - f * ez))
}

/// The share of the frame the cloud's points may fill (7.5 % margins, for
/// the splats' radii and a little air).
const MARGIN: f64 = 0.85;
/// The field of view of a framing camera, degrees.
const FRAMING_FOV: f64 = 35.0;

/// Chooses the camera for a surveyed cloud and an image of `aspect`
/// (width / height); `up` replaces the up rule (module documentation).
#[must_use]
pub fn choose_view(s: &Survey, up: Option<DVec3>, aspect: f64) -> View {
    if up.is_none()
        && let Some(Ok(sensor)) = &s.sensor
    {
        return sensor_view(s, sensor);
    }
    let c = s.center();
    let ext = s.hi - s.lo;
    let flat = flat_axis(ext);
    let given_up = up.and_then(DVec3::try_normalize);
    if let Some(v) = s.viewpoint
        && let Some(view) = viewpoint_view(s, v, given_up, flat, aspect)
    {
        return view;
    }
    // Framing: the up axis first, then a three-quarter view around it.
    let (up, why) = match (given_up, flat) {
        (Some(u), _) => (u, "given".to_string()),
        (None, Some(axis)) => {
            let up = match s.viewpoint {
                Some(v) if (v - c).dot(axis) < 0.0 => -axis,
                _ => axis,
            };
            (up, "the thinnest side of a flat cloud".to_string())
        }
        (None, None) => {
            let (up_base, down_base) = (base_area(s, DVec3::Y), base_area(s, DVec3::NEG_Y));
            if down_base > UPRIGHT_RATIO * up_base {
                (
                    DVec3::NEG_Y,
                    "it stands on its wider end: the cloud is y-down".to_string(),
                )
            } else {
                (DVec3::Y, "the default".to_string())
            }
        }
    };
    // Front: +z for a y axis, -y for a z axis, +z for an x axis, whatever
    // the sign of up; made perpendicular to up.
    let a = up.abs();
    let front0 = if a.z >= a.x && a.z >= a.y {
        DVec3::NEG_Y
    } else {
        DVec3::Z
    };
    let mut front = (front0 - up * front0.dot(up)).normalize();
    // On the viewpoint's side, when there is one.
    let toward = s
        .viewpoint
        .and_then(|v| (v - c - up * (v - c).dot(up)).try_normalize());
    if let Some(t) = toward {
        front = t;
    }
    let right = up.cross(front).normalize();
    let elevation = if flat.is_some() { 40f64 } else { 25f64 }.to_radians();
    let azimuth = 35f64.to_radians();
    let e =
        (front * azimuth.cos() + right * azimuth.sin()) * elevation.cos() + up * elevation.sin();
    let f = -e;
    let ty = (0.5 * FRAMING_FOV.to_radians()).tan();
    let tx = ty * aspect;
    let (from, at) =
        fit_centred(&s.sample, c, f, up, MARGIN * tx, MARGIN * ty).unwrap_or_else(|| {
            let d = fit_distance(&s.sample, c, f, up, MARGIN * tx, MARGIN * ty);
            (c - f * d.max(s.radius()), c)
        });
    let side = if toward.is_some() {
        "on the viewpoint's side"
    } else {
        "from the front right"
    };
    View {
        from,
        at,
        up,
        fov: FRAMING_FOV,
        sensor: None,
        note: format!(
            "camera framing the cloud {side}, {:.0}° above; up {} ({why})",
            elevation.to_degrees(),
            axis_name(up)
        ),
    }
}

/// How many times wider the base at the `-y` end must be than the one at
/// the `+y` end for a cloud to be turned y-down.
pub const UPRIGHT_RATIO: f64 = 4.0;

/// The area of the rectangle (across `up`) spanned by the sample points in
/// the lowest tenth of the cloud along `up`: what it would stand on.
fn base_area(s: &Survey, up: DVec3) -> f64 {
    let h: Vec<f64> = s.sample.iter().map(|p| p.dot(up)).collect();
    let (lo, hi) = h
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    let cut = lo + 0.1 * (hi - lo);
    let (a, b) = crate::splat::tangent_frame(up.as_vec3());
    let (a, b) = (a.as_dvec3(), b.as_dvec3());
    let (mut min, mut max) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for (p, &x) in s.sample.iter().zip(&h) {
        if x <= cut {
            let q = DVec3::new(p.dot(a), p.dot(b), 0.0);
            min = min.min(q);
            max = max.max(q);
        }
    }
    let e = (max - min).max(DVec3::ZERO);
    e.x * e.y
}

/// The thinnest axis of a flat box (thinnest side under a quarter of the
/// middle one), as a unit axis.
fn flat_axis(ext: DVec3) -> Option<DVec3> {
    let mut sides = [(ext.x, DVec3::X), (ext.y, DVec3::Y), (ext.z, DVec3::Z)];
    sides.sort_by(|a, b| a.0.total_cmp(&b.0));
    (sides[0].0 < 0.25 * sides[1].0).then_some(sides[0].1)
}

/// The camera at the viewpoint, or `None` when the viewpoint is not
/// sensible (a point behind it or beside it: inside the cloud; the cloud
/// wider than 100° from there).
fn viewpoint_view(
    s: &Survey,
    v: DVec3,
    given_up: Option<DVec3>,
    flat: Option<DVec3>,
    aspect: f64,
) -> Option<View> {
    let c = s.center();
    let f = (c - v).try_normalize()?;
    // An up axis must be at least 40° away from the line of sight.
    let usable = |a: DVec3| a.dot(f).abs() < 40f64.to_radians().cos();
    let (up, why) = if let Some(u) = given_up {
        (u, "given".to_string())
    } else if let Some(axis) = flat.filter(|a| usable(*a)) {
        let up = if (v - c).dot(axis) < 0.0 { -axis } else { axis };
        (up, "the thinnest side of a flat cloud".to_string())
    } else {
        // How far the viewpoint looks down on the centre along an axis.
        let down = |a: DVec3| (v - c).normalize().dot(a);
        let margin = 5f64.to_radians().sin();
        if usable(DVec3::Z)
            && (!usable(DVec3::Y) || down(DVec3::Z) > down(DVec3::Y).max(0.0) + margin)
        {
            let why = if usable(DVec3::Y) {
                "the viewpoint looks down along +z"
            } else {
                "+y is along the line of sight"
            };
            (DVec3::Z, why.to_string())
        } else if usable(DVec3::Y) {
            (DVec3::Y, "the default".to_string())
        } else {
            (
                DVec3::X,
                "+y and +z are along the line of sight".to_string(),
            )
        }
    };
    let (ty, tx) = needed_tangents(&s.sample, v, f, up)?;
    let t = ty.max(tx / aspect) / MARGIN;
    let fov = 2.0 * t.atan().to_degrees();
    if fov > 100.0 {
        return None;
    }
    if fov >= 5.0 {
        return Some(View {
            from: v,
            at: c,
            up,
            fov,
            sensor: None,
            note: format!(
                "camera at the cloud's viewpoint, looking at its centre; up {} ({why})",
                axis_name(up)
            ),
        });
    }
    // Far away: along the same line of sight, close enough for 35°.
    let ty = (0.5 * FRAMING_FOV.to_radians()).tan();
    let d = fit_distance(&s.sample, c, f, up, MARGIN * ty * aspect, MARGIN * ty);
    Some(View {
        from: c - f * d,
        at: c,
        up,
        fov: FRAMING_FOV,
        sensor: None,
        note: format!(
            "camera on the line of sight from the cloud's viewpoint (moved in: it is far away); up {} ({why})",
            axis_name(up)
        ),
    })
}

/// The view from an organised cloud's sensor: its pose, its fitted
/// intrinsics and its grid's size, so that the image registers with the
/// capture.
fn sensor_view(s: &Survey, sensor: &super::sensor::Sensor) -> View {
    let k = sensor.intrinsics;
    // Any point on the optical axis will do; level with the cloud's centre.
    let depth = (s.center() - sensor.position)
        .dot(sensor.forward)
        .abs()
        .max(s.radius());
    let fov = 2.0 * (0.5 * f64::from(sensor.height) / k.fy).atan().to_degrees();
    View {
        from: sensor.position,
        at: sensor.position + sensor.forward * depth,
        up: sensor.up,
        fov,
        sensor: Some((k, sensor.width, sensor.height)),
        note: format!(
            "camera at the sensor of the organised {}x{} grid, in {}: fx {:.2}, fy {:.2}, \
             cx {:.2}, cy {:.2} px fitted to its pixels (residual {:.3} px)",
            sensor.width, sensor.height, sensor.frame, k.fx, k.fy, k.cx, k.cy, sensor.residual
        ),
    }
}

/// What the scene text holds beyond the view: the image and render
/// overrides.
#[derive(Clone, Copy, Debug)]
pub struct CloudSceneOptions {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Samples per pixel.
    pub spp: u32,
    /// Shading mode (`None`: the default, phong).
    pub shading: Option<ShadingMode>,
}

impl Default for CloudSceneOptions {
    fn default() -> Self {
        CloudSceneOptions {
            width: DEFAULT_SIZE.0,
            height: DEFAULT_SIZE.1,
            spp: 1,
            shading: None,
        }
    }
}

/// Background radiance of a cloud's scene.
pub const BACKGROUND: [f64; 3] = [0.12, 0.13, 0.16];

/// A number rounded to `digits` decimals (the shortest text that reads
/// back as the same number after rounding).
fn num(x: f64, digits: usize) -> String {
    // Beyond an i64, an integer's text is no TOML number: an exponent.
    if x.abs() >= 1e15 {
        return format!("{x:e}");
    }
    let s = format!("{x:.digits$}");
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    };
    if s == "-0" { "0".into() } else { s }
}

/// Decimals that keep a coordinate to 1e-6 of `scale`.
fn decimals(scale: f64) -> usize {
    let e = (scale.max(1e-30)).log10().floor() as i64;
    usize::try_from(6 - e).unwrap_or(0).min(12)
}

fn vec3(v: DVec3, digits: usize) -> String {
    format!(
        "[{}, {}, {}]",
        num(v.x, digits),
        num(v.y, digits),
        num(v.z, digits)
    )
}

/// The scene-file text for a cloud: `model_path` is written as given
/// (relative to the folder the text will be read from, or absolute).
///
/// # Errors
/// When `model_path` is not valid UTF-8 (a TOML string cannot hold it).
pub fn scene_text(
    model_path: &Path,
    s: &Survey,
    view: &View,
    o: &CloudSceneOptions,
) -> Result<String> {
    let p = model_path.to_str().ok_or_else(|| {
        Error::invalid(format!(
            "{}: the path is not UTF-8 and cannot go in a scene file",
            model_path.display()
        ))
    })?;
    let quoted = toml::Value::String(p.to_string()).to_string();
    let d = decimals(s.radius());
    let dist = (view.from - view.at).length();
    // The headlight gives irradiance 0.25 at the centre; the key light 0.85.
    let head = 0.25 * dist * dist;
    let fwd = (view.at - view.from).normalize();
    let (r, u) = frame(fwd, view.up).unwrap_or((DVec3::X, DVec3::Y));
    // From the upper left, a little in front: the direction it travels.
    let key = -(u * 1.0 - r * 0.7 - fwd * 0.5).normalize();
    let splat = crate::splat::SplatParams::default();
    let mut t = String::new();
    let _ = writeln!(
        t,
        "# A scene for one point cloud, written by splatray {}: edit it and\n\
         # render it with `splatray render THIS.toml`.\n\
         # {}.\n",
        env!("CARGO_PKG_VERSION"),
        view.note
    );
    let _ = writeln!(t, "background = {}\n", vec3(DVec3::from(BACKGROUND), 3));
    let _ = writeln!(t, "[camera]");
    let _ = writeln!(t, "from = {}", vec3(view.from, d));
    let _ = writeln!(t, "at = {}", vec3(view.at, d));
    let _ = writeln!(t, "up = {}", vec3(view.up, 6));
    match view.sensor {
        Some((k, w, h)) => {
            // The sensor's intrinsics, scaled to the image asked for
            // (pixel centres at integers, as the intrinsics count them).
            let (sx, sy) = (
                f64::from(o.width) / f64::from(w),
                f64::from(o.height) / f64::from(h),
            );
            let _ = writeln!(
                t,
                "intrinsics = {{ fx = {}, fy = {}, cx = {}, cy = {} }}",
                num(k.fx * sx, 6),
                num(k.fy * sy, 6),
                num((k.cx + 0.5) * sx - 0.5, 6),
                num((k.cy + 0.5) * sy - 0.5, 6)
            );
        }
        None => {
            let _ = writeln!(t, "fov = {}", num(view.fov, 3));
        }
    }
    let _ = writeln!(t, "width = {}\nheight = {}", o.width, o.height);
    if o.spp != 1 {
        let _ = writeln!(t, "spp = {}", o.spp);
    }
    let _ = writeln!(t, "\n[[model]]\n{} = {quoted}", s.kind.key());
    if s.kind == CloudKind::Points {
        let _ = writeln!(
            t,
            "# splat = {{ epsilon = {}, k = {}, density = {}, ellipses = false }}  # the defaults{}",
            splat.epsilon_rel,
            splat.k,
            splat.density,
            if s.viewpoint.is_some() {
                "; normals face the file's viewpoint"
            } else {
                ""
            }
        );
    }
    if s.kind == CloudKind::Gaussians {
        let _ = writeln!(
            t,
            "# min_opacity = {}  # the default: less opaque Gaussians are left out",
            crate::io::MIN_OPACITY
        );
    }
    if s.colors {
        let _ = writeln!(
            t,
            "material = {{ kind = \"phong\", color = [0.85, 0.85, 0.85], specular = 0.08, shininess = 30 }}  # the points' colours"
        );
    } else {
        let _ = writeln!(
            t,
            "material = {{ kind = \"phong\", color = [0.78, 0.76, 0.72], specular = 0.15, shininess = 30 }}"
        );
    }
    let _ = writeln!(
        t,
        "\n[[light]]  # a headlight, at the camera\nkind = \"point\"\nposition = {}\nintensity = {}",
        vec3(view.from, d),
        num(head, decimals(head) + 3)
    );
    let _ = writeln!(
        t,
        "\n[[light]]  # the key light, from the upper left\nkind = \"directional\"\ndirection = {}\nintensity = 0.85",
        vec3(key, 4)
    );
    let _ = writeln!(t, "\n[render]\nambient = 0.05");
    if let Some(m) = o.shading {
        let name = match m {
            ShadingMode::Flat => "flat",
            ShadingMode::Blended => "blended",
            ShadingMode::Phong => "phong",
        };
        let _ = writeln!(t, "shading = \"{name}\"");
    }
    Ok(t)
}

/// `target` as seen from `folder`: relative (with `..` where needed) when
/// their absolute paths share a folder below the root, else absolute.
#[must_use]
pub fn path_from(folder: &Path, target: &Path) -> PathBuf {
    let abs = |p: &Path| {
        std::fs::canonicalize(p).unwrap_or_else(|_| {
            std::env::current_dir()
                .map(|d| d.join(p))
                .unwrap_or_else(|_| p.to_path_buf())
        })
    };
    let folder = abs(if folder.as_os_str().is_empty() {
        Path::new(".")
    } else {
        folder
    });
    let target = abs(target);
    let a: Vec<Component<'_>> = folder.components().collect();
    let b: Vec<Component<'_>> = target.components().collect();
    let common = a.iter().zip(&b).take_while(|(x, y)| x == y).count();
    // Sharing no more than the root (or a drive): absolute.
    if common < 2 {
        return target;
    }
    let mut rel = PathBuf::new();
    for _ in common..a.len() {
        rel.push("..");
    }
    for c in &b[common..] {
        rel.push(c.as_os_str());
    }
    rel
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points on the surface of a box `size`, centred at `c`, `n` per face
    /// side (a deterministic grid).
    fn box_points(c: Vec3, size: Vec3, n: usize) -> Vec<Vec3> {
        let mut out = Vec::new();
        for axis in 0..3 {
            for side in [-0.5f32, 0.5] {
                for i in 0..n {
                    for j in 0..n {
                        let a = i as f32 / (n - 1) as f32 - 0.5;
                        let b = j as f32 / (n - 1) as f32 - 0.5;
                        let mut p = Vec3::ZERO;
                        p[axis] = side;
                        p[(axis + 1) % 3] = a;
                        p[(axis + 2) % 3] = b;
                        out.push(c + p * size);
                    }
                }
            }
        }
        out
    }

    /// Projects `p` with the camera of `v`; true when inside the frame.
    fn in_frame(v: &View, p: DVec3, aspect: f64) -> bool {
        let f = (v.at - v.from).normalize();
        let (r, u) = frame(f, v.up).unwrap();
        let q = p - v.from;
        let z = q.dot(f);
        let ty = (0.5 * v.fov.to_radians()).tan();
        z > 0.0 && (q.dot(u) / z).abs() <= ty && (q.dot(r) / z).abs() <= ty * aspect
    }

    #[test]
    fn outliers_are_left_out_of_the_framing() {
        let mut pts = box_points(Vec3::new(10.0, 0.0, 0.0), Vec3::ONE, 30);
        let clean = survey(CloudKind::Points, &pts, DVec3::ZERO, None, false).unwrap();
        assert_eq!(clean.outliers, 0);
        // A few stray points far out.
        for k in 0..5 {
            pts.push(Vec3::new(10.0 + 20.0 * k as f32, 15.0, -9.0));
        }
        let s = survey(CloudKind::Points, &pts, DVec3::ZERO, None, false).unwrap();
        assert_eq!(s.outliers, 5);
        assert!((s.hi - s.lo - DVec3::ONE).abs().max_element() < 1e-5);
    }

    #[test]
    fn framing_shows_every_point_and_fills_the_frame() {
        for (size, aspect) in [
            (Vec3::new(1.0, 2.0, 0.5), 4.0 / 3.0),
            (Vec3::new(30.0, 3.0, 5.0), 1.0),
            (Vec3::new(0.01, 0.02, 0.015), 0.5),
        ] {
            let pts = box_points(Vec3::new(3.0, -1.0, 100.0), size, 10);
            let s = survey(CloudKind::Points, &pts, DVec3::ZERO, None, false).unwrap();
            let v = choose_view(&s, None, aspect);
            assert!(s.sample.iter().all(|p| in_frame(&v, *p, aspect)), "{v:?}");
            // Not too small: a narrower frame cuts points off.
            let tight = View {
                fov: v.fov * 0.8,
                ..v.clone()
            };
            assert!(!s.sample.iter().all(|p| in_frame(&tight, *p, aspect)));
            assert!(v.from.y > s.center().y, "from above: {v:?}");
        }
    }

    #[test]
    fn up_axis_rules() {
        // Flat: a terrain patch in x-y, seen by a viewpoint above it (+z).
        let mut ground = Vec::new();
        for i in 0..40 {
            for j in 0..40 {
                let h = ((i * 7 + j * 3) % 5) as f32 * 0.01;
                ground.push(Vec3::new(i as f32, j as f32, h));
            }
        }
        let s = survey(
            CloudKind::Points,
            &ground,
            DVec3::ZERO,
            Some(Vec3::new(20.0, 20.0, 2.0)),
            false,
        )
        .unwrap();
        let v = choose_view(&s, None, 1.0);
        assert_eq!(v.up, DVec3::Z, "{}", v.note);
        // The same terrain seen from below: the other side is up.
        let below = Survey {
            viewpoint: Some(DVec3::new(20.0, 20.0, -2.0)),
            ..s.clone()
        };
        assert_eq!(choose_view(&below, None, 1.0).up, DVec3::NEG_Z);
        // A pole along z, scanned from 10 units away along x, looked down on:
        // z is up (the lamppost).
        let pole = box_points(Vec3::new(-10.0, 0.0, -2.5), Vec3::new(1.0, 0.8, 6.0), 12);
        let s = survey(
            CloudKind::Points,
            &pole,
            DVec3::ZERO,
            Some(Vec3::ZERO),
            false,
        )
        .unwrap();
        let v = choose_view(&s, None, 4.0 / 3.0);
        assert_eq!(v.from, DVec3::ZERO, "{}", v.note);
        assert_eq!(v.up, DVec3::Z, "{}", v.note);
        // The same pole scanned level: no reason to leave +y.
        let level = Survey {
            viewpoint: Some(DVec3::new(0.0, 0.0, -2.5)),
            ..s.clone()
        };
        assert_eq!(choose_view(&level, None, 1.0).up, DVec3::Y);
        // A viewpoint looking along -z at an object: +z is along the line
        // of sight, +y is up (the milk carton, the synthetic scans).
        let obj = box_points(Vec3::new(0.25, -0.1, -0.7), Vec3::splat(0.15), 10);
        let s = survey(
            CloudKind::Points,
            &obj,
            DVec3::ZERO,
            Some(Vec3::ZERO),
            false,
        )
        .unwrap();
        let v = choose_view(&s, None, 1.0);
        assert_eq!((v.from, v.up), (DVec3::ZERO, DVec3::Y), "{}", v.note);
        assert!(s.sample.iter().all(|p| in_frame(&v, *p, 1.0)));
        // A given up wins.
        assert_eq!(choose_view(&s, Some(DVec3::X * 2.0), 1.0).up, DVec3::X);
        // No viewpoint: +y, unless the cloud stands on its -y end.
        let cone = |wide_at_top: bool| {
            let mut pts = Vec::new();
            for i in 0..40 {
                let y = i as f32 / 39.0;
                let r = 0.05 + if wide_at_top { y } else { 1.0 - y };
                for j in 0..40 {
                    let a = j as f32 * std::f32::consts::TAU / 40.0;
                    pts.push(Vec3::new(r * a.cos(), y, r * a.sin()));
                }
            }
            survey(CloudKind::Points, &pts, DVec3::ZERO, None, false).unwrap()
        };
        assert_eq!(choose_view(&cone(false), None, 1.0).up, DVec3::Y);
        let v = choose_view(&cone(true), None, 1.0);
        assert_eq!(v.up, DVec3::NEG_Y, "{}", v.note);
        assert!(cone(true).sample.iter().all(|p| in_frame(&v, *p, 1.0)));
    }

    #[test]
    fn viewpoints_that_are_not_sensible() {
        let obj = box_points(Vec3::ZERO, Vec3::ONE, 10);
        // Inside the cloud: framing instead.
        let s = survey(
            CloudKind::Points,
            &obj,
            DVec3::ZERO,
            Some(Vec3::new(0.1, 0.0, 0.0)),
            false,
        )
        .unwrap();
        let v = choose_view(&s, None, 1.0);
        assert_ne!(v.from, DVec3::new(0.1, 0.0, 0.0));
        assert!(v.note.contains("framing"), "{}", v.note);
        assert!(s.sample.iter().all(|p| in_frame(&v, *p, 1.0)));
        // Very far away along +x: moved in on the same line of sight.
        let far = DVec3::new(1e5, 0.0, 0.0);
        let s = Survey {
            viewpoint: Some(far),
            ..s
        };
        let v = choose_view(&s, None, 1.0);
        assert!(v.from.x > 1.0 && v.from.x < 10.0, "{v:?}");
        assert!(v.from.y.abs() < 1e-9 && v.from.z.abs() < 1e-9, "{v:?}");
        assert!(s.sample.iter().all(|p| in_frame(&v, *p, 1.0)));
    }

    #[test]
    fn scene_text_parses_and_keeps_the_view() {
        // Offsets from a far origin, as the readers give them: the view is
        // in the file's coordinates.
        let obj = box_points(Vec3::new(0.0, 2.0, -3.0), Vec3::splat(0.5), 8);
        let origin = DVec3::new(5e6, -3e6, 100.0);
        let s = survey(CloudKind::Points, &obj, origin, None, true).unwrap();
        assert!((s.center() - origin - DVec3::new(0.0, 2.0, -3.0)).length() < 1e-6);
        let v = choose_view(&s, None, 4.0 / 3.0);
        assert!((v.at - s.center()).length() < 1.0, "{v:?}");
        let o = CloudSceneOptions {
            spp: 4,
            shading: Some(ShadingMode::Flat),
            ..CloudSceneOptions::default()
        };
        let text = scene_text(Path::new("dir with \"quotes\"/c.ply"), &s, &v, &o).unwrap();
        let f = crate::scene::parse_scene_str(&text).unwrap();
        assert_eq!(
            f.models[0].points.as_deref(),
            Some(Path::new("dir with \"quotes\"/c.ply"))
        );
        let from = DVec3::from(f.camera.from);
        assert!((from - v.from).length() < 1e-5 * s.radius(), "{text}");
        assert_eq!(f.camera.spp, 4);
        assert_eq!(f.render.shading, Some(ShadingMode::Flat));
        assert_eq!(f.lights.len(), 2);
    }

    #[test]
    fn relative_paths() {
        let d = std::env::temp_dir().join(format!("splatray-cloud-rel-{}", std::process::id()));
        std::fs::create_dir_all(d.join("a/b")).unwrap();
        std::fs::create_dir_all(d.join("c")).unwrap();
        std::fs::write(d.join("c/x.ply"), "ply\n").unwrap();
        assert_eq!(
            path_from(&d.join("a/b"), &d.join("c/x.ply")),
            Path::new("../../c/x.ply")
        );
        assert_eq!(
            path_from(&d.join("c"), &d.join("c/x.ply")),
            Path::new("x.ply")
        );
        let _ = std::fs::remove_dir_all(&d);
    }
}
