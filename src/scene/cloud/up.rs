//! The up vector of a cloud's camera, unless given (`--up`):
//!
//! 0. **A LAS or LAZ file**: `+z`, its elevation (the ASPRS format's
//!    axes: a projected x-y and z up), whatever the box's shape.
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

use super::survey::Survey;
use glam::DVec3;

/// The up axes the rules give a surveyed cloud, decided before any camera
/// is placed: the view ([`super::view::choose_view`]) takes the one of the
/// camera it places.
pub(super) struct Ups {
    /// The thinnest axis of a flat cloud (rule 1).
    pub flat: Option<DVec3>,
    /// The up of the camera at the viewpoint, and why (`None` without a
    /// viewpoint, or one at the cloud's centre).
    pub at_viewpoint: Option<(DVec3, String)>,
    /// The up of a framing camera, and why.
    pub framing: (DVec3, String),
}

/// [`Ups`] of `s`; `given_up` (unit), when there is one, wins everywhere,
/// then a LAS file's `+z` (rule 0).
pub(super) fn ups(s: &Survey, given_up: Option<DVec3>) -> Ups {
    let given_up = given_up.map(|u| (u, "given")).or(s
        .z_is_elevation
        .then_some((DVec3::Z, "a LAS file: z is elevation")));
    let flat = flat_axis(s.hi - s.lo);
    let c = s.center();
    let at_viewpoint = s.viewpoint.and_then(|v| {
        let f = (c - v).try_normalize()?;
        Some(viewpoint_up(v, c, f, given_up, flat))
    });
    Ups {
        flat,
        at_viewpoint,
        framing: framing_up(s, given_up, flat),
    }
}

/// The up axis of a framing camera (rules 1 and 3), and why: `given_up`, else
/// the thinnest side of a `flat` cloud (toward the viewpoint), else `+y`
/// or `-y`.
fn framing_up(s: &Survey, given_up: Option<(DVec3, &str)>, flat: Option<DVec3>) -> (DVec3, String) {
    let c = s.center();
    match (given_up, flat) {
        (Some((u, why)), _) => (u, why.to_string()),
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
    }
}

/// The up axis of the camera at the viewpoint `v` looking along `f` at the
/// cloud's centre `c` (rules 1 and 2), and why: `given_up`, else the thinnest
/// side of a `flat` cloud, else `+z`, `+y` or `+x`.
fn viewpoint_up(
    v: DVec3,
    c: DVec3,
    f: DVec3,
    given_up: Option<(DVec3, &str)>,
    flat: Option<DVec3>,
) -> (DVec3, String) {
    // An up axis must be at least 40° away from the line of sight.
    let usable = |a: DVec3| a.dot(f).abs() < 40f64.to_radians().cos();
    if let Some((u, why)) = given_up {
        (u, why.to_string())
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
