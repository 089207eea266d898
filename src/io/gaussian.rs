//! Gaussian splat files: the PLY layouts 2D Gaussian Splatting (2DGS,
//! oriented elliptical surfels) and 3D Gaussian Splatting (3DGS) write, in
//! and out.
//!
//! A vertex is one Gaussian: `x y z`, `nx ny nz` (2DGS writes zeros; they
//! are not read), `f_dc_0..2` (the degree-0 spherical-harmonic colour
//! coefficient), `f_rest_*` (view-dependent colour, not read), `opacity` (a
//! logit), `scale_0 scale_1 [scale_2]` (log sigma per axis) and
//! `rot_0..3`, an unnormalised `w x y z` quaternion whose rotation's
//! columns are the Gaussian's axes. A 2DGS surfel's third column is its
//! normal; a 3DGS Gaussian's normal is taken as the axis of its smallest
//! scale.
//!
//! Converting to a splat (§2.1's elliptical disc): the axes become the
//! splat frame, each radius is [`RADIUS_PER_SIGMA`] times the sigma along
//! it, the colour is the DC term made linear (`0.5 + C0 f_dc` is sRGB, as
//! the training images were), and Gaussians whose opacity is below a
//! threshold are left out. Converting back writes the same quantities and
//! an opacity of [`EXPORT_OPACITY`]. Lost each way: our normal fields
//! (eq. 4) are not in the Gaussian layouts (exported splats are flat), and
//! a Gaussian's soft falloff and view-dependent colour are not in a splat.

use super::ply::{PlyFile, require_scalars, scalar};
use super::splat_ply::SplatSet;
use super::{IoError, IoErrorKind, linear_to_srgb, srgb_to_linear};
use crate::data::{NormalField, Splat};
use crate::primitive::clip::Clip;
use glam::{DVec3, Mat3, Quat, Vec2, Vec3};
use ply_rs_bw::ply::{Header, Property, PropertyAccess};
use std::path::Path;

/// The degree-0 spherical-harmonic basis constant, `1 / (2 sqrt(pi))`:
/// a Gaussian's base colour is `0.5 + C0 * f_dc`.
pub const SH_C0: f32 = 0.282_094_8;

/// A splat's radius along an axis per sigma of its Gaussian along that
/// axis. Chosen by measurement (`cargo run --release --example
/// gaussian_factor`, docs/usage.md "Gaussian splat files"): over the splats of
/// a sampled mesh, a raster scan and a real scan, the region where the
/// exported Gaussians composite to an opacity of at least one half best
/// matches the union of the discs at this factor.
pub const RADIUS_PER_SIGMA: f32 = 1.6;

/// The opacity written for every exported Gaussian (our splats are opaque;
/// the reference renderers clamp a Gaussian's alpha at 0.99).
pub const EXPORT_OPACITY: f32 = 0.99;

/// Gaussians less opaque than this are left out when read, by default: a
/// Gaussian whose peak alpha is under one half makes no pixel more than
/// half opaque on its own, and a splat is opaque.
pub const MIN_OPACITY: f32 = 0.5;

/// A 3DGS Gaussian whose smallest sigma is more than this fraction of its
/// middle one is a blob, not a surfel: it is still read as the disc across
/// its two largest axes, and counted.
pub const FLAT_RATIO: f32 = 0.25;

/// The thickness of an exported 3DGS Gaussian: its sigma along the normal
/// as a fraction of its smaller in-plane sigma.
pub const EXPORT_THICKNESS: f32 = 0.01;

/// The two Gaussian layouts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GaussianLayout {
    /// 2D Gaussian Splatting: `scale_0 scale_1`, the normal the third
    /// column of the rotation.
    TwoD,
    /// 3D Gaussian Splatting: `scale_0 scale_1 scale_2`.
    ThreeD,
}

impl GaussianLayout {
    /// The layout's usual name (`2dgs`, `3dgs`).
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            GaussianLayout::TwoD => "2dgs",
            GaussianLayout::ThreeD => "3dgs",
        }
    }

    fn scales(self) -> usize {
        match self {
            GaussianLayout::TwoD => 2,
            GaussianLayout::ThreeD => 3,
        }
    }
}

/// The vertex properties a Gaussian file must have.
const REQUIRED: [&str; 9] = [
    "x", "y", "z", "opacity", "scale_0", "scale_1", "rot_0", "rot_1", "rot_2",
];

/// The layout of a PLY header's vertex element, if it holds Gaussians
/// (`opacity`, `scale_0`, `scale_1`, `rot_0..3`; `scale_2` makes it 3DGS).
#[must_use]
pub fn layout_of(header: &Header) -> Option<GaussianLayout> {
    let v = header.elements.get("vertex")?;
    layout_from(|n| v.properties.contains_key(n))
}

/// The layout of a vertex element that `has` the named properties.
fn layout_from(has: impl Fn(&str) -> bool) -> Option<GaussianLayout> {
    if !(REQUIRED.iter().all(|n| has(n)) && has("rot_3")) {
        return None;
    }
    Some(if has("scale_2") {
        GaussianLayout::ThreeD
    } else {
        GaussianLayout::TwoD
    })
}

/// The layout of a PLY file's Gaussians from its first bytes (the header
/// text), or `None` when it does not look like a Gaussian file.
#[must_use]
pub fn sniff_layout(head: &[u8]) -> Option<GaussianLayout> {
    let found = super::vertex_property_names(head)?;
    layout_from(|n| found.iter().any(|f| f == n))
}

/// The layout of the Gaussians in the file at `path` (from its first
/// 4 KiB), or `None` when it cannot be read or is not a Gaussian PLY.
#[must_use]
pub fn file_layout(path: &Path) -> Option<GaussianLayout> {
    sniff_layout(&super::file_head(path)?)
}

/// Named values of one Gaussian, by index in [`ROW`].
const ROW: [&str; 14] = [
    "x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
    "rot_0", "rot_1", "rot_2", "rot_3",
];

struct GaussRow([f32; ROW.len()]);

impl PropertyAccess for GaussRow {
    fn new() -> Self {
        GaussRow([f32::NAN; ROW.len()])
    }
    fn set_property(&mut self, name: &str, p: Property) {
        if let Some(i) = ROW.iter().position(|n| *n == name) {
            self.0[i] = match p {
                Property::Float(f) => f,
                other => scalar(&other).map_or(f32::NAN, |d| d as f32),
            };
        }
    }
}

/// What reading a Gaussian file gives.
#[derive(Clone, Debug, Default)]
pub struct GaussianRead {
    /// The splats (centres relative to `origin`).
    pub set: SplatSet,
    /// The file's layout (`None` only for an empty default).
    pub layout: Option<GaussianLayout>,
    /// Gaussians in the file.
    pub gaussians: usize,
    /// Gaussians left out, by reason (opacity under the threshold,
    /// non-finite values, a zero rotation, a scale beyond f32).
    pub skipped: Vec<(String, usize)>,
    /// 3DGS Gaussians read as discs although not flat ([`FLAT_RATIO`]).
    pub not_flat: usize,
    /// `f_rest_*` properties (view-dependent colour) present and not read.
    pub sh_rest: usize,
}

impl GaussianRead {
    fn skip(&mut self, reason: &str) {
        match self.skipped.iter_mut().find(|(r, _)| r == reason) {
            Some((_, n)) => *n += 1,
            None => self.skipped.push((reason.to_string(), 1)),
        }
    }

    /// One line per thing the reader left out or changed, for warnings.
    #[must_use]
    pub fn warnings(&self) -> Vec<String> {
        let mut w: Vec<String> = self
            .skipped
            .iter()
            .map(|(r, n)| format!("{n} of {} Gaussians left out: {r}", self.gaussians))
            .collect();
        if self.not_flat > 0 {
            w.push(format!(
                "{} Gaussians are not flat (smallest sigma over {FLAT_RATIO} of the middle one): each became the disc across its two largest axes",
                self.not_flat
            ));
        }
        w
    }
}

/// Read a Gaussian PLY file (2DGS or 3DGS layout) as splats, leaving out
/// Gaussians less opaque than `min_opacity`.
///
/// # Errors
/// An [`IoError`] when the file cannot be read, is not a Gaussian PLY, or
/// no Gaussian is left.
pub fn read_gaussians(path: &Path, min_opacity: f32) -> Result<GaussianRead, IoError> {
    let bytes = super::read_file(path)?;
    parse_gaussians(&bytes, min_opacity).map_err(|k| IoError::new(path, k))
}

/// [`read_gaussians`] on a file's bytes.
///
/// # Errors
/// As [`read_gaussians`], without the file's name.
pub fn parse_gaussians(bytes: &[u8], min_opacity: f32) -> Result<GaussianRead, IoErrorKind> {
    let file = PlyFile::open(bytes)?;
    let layout = layout_of(&file.header).ok_or_else(|| {
        IoErrorKind::Header(
            "not a Gaussian splat file: the vertex element needs opacity, scale_0, scale_1 and rot_0..3"
                .into(),
        )
    })?;
    require_scalars(&file.header, &ROW)?;
    let origin = super::splat_ply::origin_of(&file.header.comments)?.unwrap_or(DVec3::ZERO);
    let sh_rest = file.header.elements.get("vertex").map_or(0, |v| {
        v.properties
            .keys()
            .filter(|k| k.starts_with("f_rest_"))
            .count()
    });
    let has_dc = file
        .header
        .elements
        .get("vertex")
        .is_some_and(|v| ROW[3..6].iter().all(|n| v.properties.contains_key(*n)));
    let rows = file.read_vertices::<GaussRow>()?;
    let mut out = GaussianRead {
        layout: Some(layout),
        gaussians: rows.len(),
        sh_rest,
        set: SplatSet {
            splats: Vec::with_capacity(rows.len()),
            origin,
            color_fields: Vec::new(),
        },
        ..GaussianRead::default()
    };
    for GaussRow(v) in &rows {
        let n_scales = layout.scales();
        let used = v[..3]
            .iter()
            .chain(&v[6..9])
            .chain(&v[9..9 + n_scales - 2])
            .chain(&v[10..14])
            .chain(if has_dc { &v[3..6] } else { &v[..0] });
        if used.into_iter().any(|x| !x.is_finite()) {
            out.skip("a value is not finite");
            continue;
        }
        let opacity = 1.0 / (1.0 + (-v[6]).exp());
        if opacity.is_nan() || opacity < min_opacity {
            out.skip(&format!("opacity below {min_opacity}"));
            continue;
        }
        let q = Quat::from_xyzw(v[11], v[12], v[13], v[10]);
        // Scaled before normalising so a huge quaternion does not overflow.
        let m = q.to_array().iter().fold(0f32, |a, c| a.max(c.abs()));
        let Some(q) = (m > 0.0)
            .then(|| Quat::from_vec4(glam::Vec4::from(q) / m))
            .and_then(|q| (q.length_squared() > 0.0).then(|| q.normalize()))
        else {
            out.skip("a zero rotation");
            continue;
        };
        let r = Mat3::from_quat(q);
        let sigma: Vec<f32> = v[7..7 + n_scales].iter().map(|s| s.exp()).collect();
        if sigma
            .iter()
            .any(|s| !(s.is_finite() && *s > 0.0 && (s * RADIUS_PER_SIGMA).is_finite()))
        {
            out.skip("a scale beyond single precision");
            continue;
        }
        let axes = [r.x_axis, r.y_axis, r.z_axis];
        // Indices of the normal axis and the two in-plane axes, the major
        // (larger sigma) first.
        let (ni, a, b) = match layout {
            GaussianLayout::TwoD => (2, 0, 1),
            GaussianLayout::ThreeD => {
                let mut order = [0usize, 1, 2];
                order.sort_by(|&i, &j| sigma[i].total_cmp(&sigma[j]));
                if sigma[order[0]] > FLAT_RATIO * sigma[order[1]] {
                    out.not_flat += 1;
                }
                // The in-plane axes in file order, so a circle keeps its u.
                let (a, b) = match order[0] {
                    0 => (1, 2),
                    1 => (0, 2),
                    _ => (0, 1),
                };
                (order[0], a, b)
            }
        };
        let (major, minor) = if sigma[a] >= sigma[b] { (a, b) } else { (b, a) };
        let normal = axes[ni];
        let u_axis = axes[major];
        let v_axis = normal.cross(u_axis);
        let color = if has_dc {
            Vec3::new(v[3], v[4], v[5]).map(|c| srgb_to_linear(0.5 + SH_C0 * c))
        } else {
            Vec3::ONE
        };
        out.set.splats.push(Splat {
            center: Vec3::new(v[0], v[1], v[2]),
            normal,
            u_axis,
            v_axis,
            radii: Vec2::new(sigma[major], sigma[minor]) * RADIUS_PER_SIGMA,
            color,
            field: NormalField::FLAT,
            clip: Clip::NONE,
        });
    }
    if out.set.splats.is_empty() {
        let why: Vec<String> = out
            .skipped
            .iter()
            .map(|(r, n)| format!("{n} {r}"))
            .collect();
        return Err(IoErrorKind::NoPoints(if why.is_empty() {
            "the file holds no Gaussians".into()
        } else {
            format!("no Gaussian left ({})", why.join(", "))
        }));
    }
    Ok(out)
}

/// The highest spherical-harmonic degree [`encode_gaussians`] writes
/// coefficients for (all zero above degree 0).
pub const MAX_SH_DEGREE: u32 = 3;

/// The bytes of `splats` (centres relative to `origin`) as a Gaussian PLY
/// of `layout`, binary little-endian float32: `x y z nx ny nz f_dc_0..2
/// f_rest_* opacity scale_* rot_0..3`, the order the reference loaders
/// and strict viewers expect; `f_rest_*` are zeros for `sh_degree` (0 to
/// [`MAX_SH_DEGREE`]; 3, the reference trainers' default, writes 45).
/// Each splat's frame becomes the rotation, each radius a sigma
/// ([`RADIUS_PER_SIGMA`]), its linear colour the DC term; normal fields are
/// dropped. The origin goes into the same header comment as a splat
/// file's, so a georeferenced set reads back in place.
///
/// # Errors
/// An [`IoError`] naming `path` when `sh_degree` is above
/// [`MAX_SH_DEGREE`], the origin or a splat is not finite, or a radius is
/// not positive; nothing is written then.
pub fn encode_gaussians(
    path: &Path,
    splats: &[Splat],
    origin: DVec3,
    layout: GaussianLayout,
    sh_degree: u32,
) -> Result<Vec<u8>, IoError> {
    let bad = |what: String| Err(IoError::not_written(path, &what));
    if sh_degree > MAX_SH_DEGREE {
        return bad(format!(
            "spherical-harmonic degree {sh_degree} is above {MAX_SH_DEGREE}"
        ));
    }
    if !origin.is_finite() {
        return bad(format!("the splats' origin {origin} is not finite"));
    }
    if let Some(i) = splats.iter().position(|s| {
        let finite = [s.center, s.normal, s.u_axis, s.v_axis, s.color]
            .iter()
            .all(|v| v.is_finite());
        !(finite && s.radii.is_finite() && s.radii.min_element() > 0.0)
    }) {
        return bad(format!(
            "splat {i} has a non-finite value or a radius that is not positive"
        ));
    }
    let rest = 3 * ((sh_degree + 1).pow(2) - 1) as usize;
    let mut names: Vec<String> = [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
    ]
    .iter()
    .map(|s| (*s).to_string())
    .collect();
    names.extend((0..rest).map(|i| format!("f_rest_{i}")));
    names.push("opacity".into());
    names.extend((0..layout.scales()).map(|i| format!("scale_{i}")));
    names.extend((0..4).map(|i| format!("rot_{i}")));
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment splatray {} splats as {} Gaussians: sigma = radius / {RADIUS_PER_SIGMA}\ncomment {} {:?} {:?} {:?}\nelement vertex {}\n",
        env!("CARGO_PKG_VERSION"),
        layout.name(),
        super::splat_ply::ORIGIN_COMMENT,
        origin.x,
        origin.y,
        origin.z,
        splats.len()
    );
    for n in &names {
        header.push_str("property float ");
        header.push_str(n);
        header.push('\n');
    }
    header.push_str("end_header\n");
    let mut out = Vec::with_capacity(header.len() + splats.len() * names.len() * 4);
    out.extend_from_slice(header.as_bytes());
    let logit = (EXPORT_OPACITY / (1.0 - EXPORT_OPACITY)).ln();
    let put = |out: &mut Vec<u8>, x: f32| out.extend_from_slice(&x.to_le_bytes());
    for s in splats {
        let (sigma, q) = frame_quat(s);
        for x in s.center.to_array() {
            put(&mut out, x);
        }
        for x in s.normal.to_array() {
            put(&mut out, x);
        }
        for c in s.color.to_array() {
            put(&mut out, (linear_to_srgb(c) - 0.5) / SH_C0);
        }
        for _ in 0..rest {
            put(&mut out, 0.0);
        }
        put(&mut out, logit);
        put(&mut out, sigma.x.ln());
        put(&mut out, sigma.y.ln());
        if layout == GaussianLayout::ThreeD {
            put(&mut out, (sigma.min_element() * EXPORT_THICKNESS).ln());
        }
        for x in [q.w, q.x, q.y, q.z] {
            put(&mut out, x);
        }
    }
    Ok(out)
}

/// A splat's in-plane sigmas and the rotation whose columns are its `u`,
/// `v` and normal (`v` negated when the frame is left-handed: an ellipse
/// is symmetric about its axes).
fn frame_quat(s: &Splat) -> (Vec2, Quat) {
    let v = if s.u_axis.cross(s.v_axis).dot(s.normal) < 0.0 {
        -s.v_axis
    } else {
        s.v_axis
    };
    let q = Quat::from_mat3(&Mat3::from_cols(s.u_axis, v, s.normal)).normalize();
    (s.radii / RADIUS_PER_SIGMA, q)
}

/// Write `splats` as a Gaussian PLY (see [`encode_gaussians`]), atomically.
///
/// # Errors
/// As [`encode_gaussians`], or when the file cannot be written.
pub fn write_gaussians(
    path: &Path,
    splats: &[Splat],
    origin: DVec3,
    layout: GaussianLayout,
    sh_degree: u32,
) -> Result<(), IoError> {
    super::write_bytes(
        path,
        &encode_gaussians(path, splats, origin, layout, sh_degree)?,
    )
}
