//! Step 2, the view: the camera for a surveyed cloud ([`choose_view`]).
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
//! - **An organised cloud's sensor**, when one was fitted (and no up is
//!   given): its pose, intrinsics and grid size, so that the image
//!   registers with the capture.
//!
//! In the first two, the field of view (or, framing, the distance and the
//! point looked at, centring the cloud's image) is set so that every point
//! of the survey's sample fits the frame with a 7.5 % margin. The up vector
//! follows the rules of [`super::up`].

use super::survey::Survey;
use super::up::ups;
use crate::scene::model::Intrinsics;
use crate::scene::sensor::Sensor;
use glam::DVec3;

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
pub(super) fn frame(f: DVec3, up: DVec3) -> Option<(DVec3, DVec3)> {
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
/// (width / height); `up` replaces the up rules of [`super::up`].
#[must_use]
pub fn choose_view(s: &Survey, up: Option<DVec3>, aspect: f64) -> View {
    if up.is_none()
        && let Some(Ok(sensor)) = &s.sensor
    {
        return sensor_view(s, sensor);
    }
    let c = s.center();
    let ups = ups(s, up.and_then(DVec3::try_normalize));
    if let (Some(v), Some(up)) = (s.viewpoint, &ups.at_viewpoint)
        && let Some(view) = viewpoint_view(s, v, up, aspect)
    {
        return view;
    }
    // Framing: a three-quarter view around the up axis.
    let (up, why) = ups.framing;
    let flat = ups.flat;
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

/// The camera at the viewpoint with `up` (and why), or `None` when the
/// viewpoint is not sensible (a point behind it or beside it: inside the
/// cloud; the cloud wider than 100° from there).
fn viewpoint_view(s: &Survey, v: DVec3, up: &(DVec3, String), aspect: f64) -> Option<View> {
    let c = s.center();
    let f = (c - v).try_normalize()?;
    let (up, why) = (up.0, &up.1);
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
fn sensor_view(s: &Survey, sensor: &Sensor) -> View {
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
