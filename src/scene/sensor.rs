//! The sensor of an organised cloud (a depth camera's or stereo rig's grid,
//! a point per pixel): its pose from the file's `VIEWPOINT` and its pinhole
//! intrinsics fitted to the grid, so that a render from it registers pixel
//! for pixel with the capture.
//!
//! The pinhole is fitted to the grid by [`Organised::pinhole`] (least
//! squares over every measured pixel, with its residual); its signs tell
//! the frame, here turned into the camera's forward and up.

use crate::io::{Organised, Pinhole};
use crate::scene::model::Intrinsics;
use glam::DVec3;

/// A camera recovered from an organised cloud.
#[derive(Clone, Debug, PartialEq)]
pub struct Sensor {
    /// Where it stood, in the file's coordinates.
    pub position: DVec3,
    /// Unit direction of its optical axis, in the file's coordinates.
    pub forward: DVec3,
    /// Unit direction of the image's up (against increasing rows).
    pub up: DVec3,
    /// Focal lengths (positive) and principal point, pixels.
    pub intrinsics: Intrinsics,
    /// The grid: pixels per row, and rows.
    pub width: u32,
    /// See `width`.
    pub height: u32,
    /// RMS distance, pixels, of the measured points from where the fitted
    /// camera projects them.
    pub residual: f64,
    /// Which frame the points are in, for people.
    pub frame: &'static str,
}

/// The sensor of an organised cloud.
///
/// # Errors
/// One line: too few measured pixels, points at the sensor's depth, a
/// grid that no pinhole explains (pixels that do not spread), or a mirrored
/// image (a frame neither right- nor left-handed as a camera's).
pub fn recover(o: &Organised) -> Result<Sensor, String> {
    let Pinhole {
        fx,
        fy,
        cx,
        cy,
        forward_z,
        residual,
    } = o.pinhole()?;
    let s = if forward_z { 1.0 } else { -1.0 };
    // Image right along +u and down along +v, in the sensor's frame.
    let right = DVec3::X * (s * fx).signum();
    let down = DVec3::Y * (s * fy).signum();
    let forward = DVec3::Z * s;
    if forward.cross(-down).dot(right) < 0.5 {
        return Err("the organised cloud's grid is a mirror image of its camera's".into());
    }
    let frame = match (forward_z, fx > 0.0, fy > 0.0) {
        (true, true, true) => "the optical frame (x right, y down, z forward)",
        (false, false, true) => "the -z frame (x right, y up, looking along -z)",
        _ => "a rotated frame",
    };
    Ok(Sensor {
        position: o.position,
        forward: o.orientation * forward,
        up: o.orientation * -down,
        intrinsics: Intrinsics {
            fx: fx.abs(),
            fy: fy.abs(),
            cx,
            cy,
        },
        width: o.width as u32,
        height: o.height as u32,
        residual,
        frame,
    })
}
