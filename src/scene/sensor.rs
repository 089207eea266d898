//! The sensor of an organised cloud (a depth camera's or stereo rig's grid,
//! a point per pixel): its pose from the file's `VIEWPOINT` and its pinhole
//! intrinsics fitted to the grid, so that a render from it registers pixel
//! for pixel with the capture.
//!
//! In the sensor's frame (`p_s = R⁻¹ (p - t)`), the point of pixel
//! `(u, v)` (column and row, pixel centres at integers) satisfies
//! `u = fx·x/z + cx` and `v = fy·y/z + cy`: two straight-line fits, by
//! least squares over every measured pixel, with their RMS residual. The
//! signs tell the frame: the optical frame of PCL, OpenCV and ROS (`x`
//! right, `y` down, `z` forward: `z > 0`, `fx, fy > 0`) or the OpenGL one
//! (`y` up, looking along `-z`: `z < 0`, `fx < 0`, `fy > 0`).

use crate::io::Organised;
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

/// Least-squares line `y = a x + b` through `(x, y)` pairs, with the RMS
/// residual; `None` when the `x` do not spread.
fn line(pairs: impl Iterator<Item = (f64, f64)> + Clone) -> Option<(f64, f64, f64)> {
    let (mut n, mut sx, mut sy) = (0f64, 0f64, 0f64);
    for (x, y) in pairs.clone() {
        n += 1.0;
        sx += x;
        sy += y;
    }
    if n < 2.0 {
        return None;
    }
    let (mx, my) = (sx / n, sy / n);
    let (mut sxx, mut sxy) = (0f64, 0f64);
    for (x, y) in pairs.clone() {
        sxx += (x - mx) * (x - mx);
        sxy += (x - mx) * (y - my);
    }
    if sxx.is_nan() || sxx <= 1e-18 * n {
        return None;
    }
    let a = sxy / sxx;
    let b = my - a * mx;
    let ss: f64 = pairs.map(|(x, y)| (y - a * x - b).powi(2)).sum();
    Some((a, b, (ss / n).sqrt()))
}

/// The sensor of an organised cloud.
///
/// # Errors
/// One line: too few measured pixels, points at the sensor's depth, a
/// grid that no pinhole explains (pixels that do not spread), or a mirrored
/// image (a frame neither right- nor left-handed as a camera's).
pub fn recover(o: &Organised) -> Result<Sensor, String> {
    let inv = o.orientation.inverse();
    let w = o.width as u64;
    // Points in the sensor's frame, with their pixel.
    let pts: Vec<(f64, f64, DVec3)> = o
        .pixels
        .iter()
        .map(|&(i, p)| {
            let i = u64::from(i);
            ((i % w) as f64, (i / w) as f64, inv * (p - o.position))
        })
        .filter(|(_, _, p)| p.z.abs() > 1e-9 * p.length())
        .collect();
    if pts.len() < 16 {
        return Err(format!(
            "an organised cloud needs at least 16 measured pixels off the sensor's plane to fit \
             its camera, this one has {}",
            pts.len()
        ));
    }
    let forward_z = pts.iter().filter(|(_, _, p)| p.z > 0.0).count() * 2 >= pts.len();
    let s = if forward_z { 1.0 } else { -1.0 };
    // Points behind the sensor are not on its grid.
    let front: Vec<&(f64, f64, DVec3)> = pts.iter().filter(|(_, _, p)| p.z * s > 0.0).collect();
    let fit_u = line(front.iter().map(|(u, _, p)| (p.x / p.z, *u)));
    let fit_v = line(front.iter().map(|(_, v, p)| (p.y / p.z, *v)));
    let (Some((fx, cx, ru)), Some((fy, cy, rv))) = (fit_u, fit_v) else {
        return Err(
            "the organised cloud's points do not spread across its grid: no camera fits".into(),
        );
    };
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
        residual: (0.5 * (ru * ru + rv * rv)).sqrt(),
        frame,
    })
}
