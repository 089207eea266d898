//! Step 3, the scene text: the scene for a cloud as scene-file TOML — the
//! camera of the view, one model (the cloud), a headlight at the camera
//! (irradiance 0.25 at the centre) and a directional key light from the
//! upper left, a little in front (0.85), ambient 0.05; a grey Phong
//! material, or the points' own colours (Phong, albedo 0.85 times the
//! colour) when the file has colour; a dark blue-grey background; splat
//! parameters at their defaults (the file's viewpoint orients the normals,
//! as in any scene). The scene rendered and the scene saved for editing
//! are this one text.

use super::survey::{CloudKind, Survey};
use super::view::{View, frame};
use crate::names::Named;
use crate::resolve::ShadingMode;
use crate::{Error, Result};
use glam::DVec3;
use std::fmt::Write as _;
use std::path::{Component, Path, PathBuf};

/// Default image size of a cloud's scene.
pub const DEFAULT_SIZE: (u32, u32) = (800, 600);

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
#[must_use]
pub fn decimals(scale: f64) -> usize {
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
    camera_text(&mut t, view, o, d);
    let _ = writeln!(t, "\n[[model]]\n{} = {quoted}", s.kind.key());
    model_text(&mut t, s);
    lights_text(&mut t, view, d);
    let _ = writeln!(t, "\n[render]\nambient = 0.05");
    if let Some(m) = o.shading {
        let _ = writeln!(t, "shading = \"{}\"", m.name());
    }
    Ok(t)
}

/// `[camera]`: the view, its intrinsics scaled to the image (a sensor's) or
/// its field of view, and the image; coordinates to `d` decimals (the
/// table `splatray view` writes into a scene file it saves, too).
pub fn camera_text(t: &mut String, view: &View, o: &CloudSceneOptions, d: usize) {
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
}

/// The model's settings beyond its file: the splat defaults (points) or
/// the opacity threshold (Gaussians) as comments, and the material.
fn model_text(t: &mut String, s: &Survey) {
    let splat = crate::splat::SplatParams::default();
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
}

/// The two lights: a headlight at the camera (irradiance 0.25 at the point
/// looked at) and a directional key light from the upper left, a little in
/// front (0.85).
fn lights_text(t: &mut String, view: &View, d: usize) {
    let dist = (view.from - view.at).length();
    let head = 0.25 * dist * dist;
    let fwd = (view.at - view.from).normalize();
    let (r, u) = frame(fwd, view.up).unwrap_or((DVec3::X, DVec3::Y));
    // From the upper left, a little in front: the direction it travels.
    let key = -(u * 1.0 - r * 0.7 - fwd * 0.5).normalize();
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
