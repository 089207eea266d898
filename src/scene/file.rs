//! The scene file format (TOML): one serde struct per table, and the
//! parser.
//!
//! A scene states only what it needs; everything omitted has a default and
//! costs nothing at render time. Unknown keys and unknown kinds (material,
//! light, shape, shading mode) are errors naming the key or value and the
//! line (serde's `deny_unknown_fields` and enums, reported by the TOML
//! parser).

use super::num;
use crate::resolve::ShadingMode;
use crate::{Error, Result};
use serde::Deserialize;
use std::path::{Path, PathBuf};

fn default_up() -> [f32; 3] {
    [0.0, 1.0, 0.0]
}
fn default_fov() -> f32 {
    40.0
}
fn default_width() -> u32 {
    640
}
fn default_height() -> u32 {
    480
}
fn one_u32() -> u32 {
    1
}
fn one_f32() -> f32 {
    1.0
}
fn white() -> [f32; 3] {
    [1.0, 1.0, 1.0]
}

/// `material.kind`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MaterialKind {
    /// Lambertian.
    #[default]
    Diffuse,
    /// Lambertian plus a Blinn–Phong highlight.
    Phong,
    /// Perfect mirror.
    Mirror,
    /// Dielectric with Fresnel reflection and refraction.
    Glass,
}

/// `light.kind`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LightKind {
    /// A point light (needs `position`).
    Point,
    /// A directional light (needs `direction`).
    Directional,
    /// A spherical area light (needs `position` and `radius`).
    Sphere,
}

impl std::fmt::Display for LightKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            LightKind::Point => "point",
            LightKind::Directional => "directional",
            LightKind::Sphere => "sphere",
        })
    }
}

/// `shape.kind`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ShapeKind {
    /// A sphere (needs `radius`).
    Sphere,
    /// A rectangle (needs `size`; `normal` defaults to +y).
    Quad,
}

/// `[camera]`: a pinhole camera.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    /// Eye position (f64, so far-from-origin scenes keep their precision).
    #[serde(deserialize_with = "num::finite")]
    pub from: [f64; 3],
    /// Point looked at.
    #[serde(deserialize_with = "num::finite")]
    pub at: [f64; 3],
    /// Up vector.
    #[serde(default = "default_up", deserialize_with = "num::finite")]
    pub up: [f32; 3],
    /// Vertical field of view, degrees.
    #[serde(default = "default_fov", deserialize_with = "num::fov")]
    pub fov: f32,
    /// Image width, pixels.
    #[serde(default = "default_width")]
    pub width: u32,
    /// Image height, pixels.
    #[serde(default = "default_height")]
    pub height: u32,
    /// Samples per pixel (stratified when > 1).
    #[serde(default = "one_u32")]
    pub spp: u32,
    /// A pinhole's intrinsics, pixels, instead of `fov`: the image plane
    /// of a real camera, its principal point anywhere.
    #[serde(default)]
    pub intrinsics: Option<IntrinsicsSpec>,
}

/// `camera.intrinsics = { fx, fy, cx, cy }`: focal lengths and principal
/// point in pixels (`u = fx·x/z + cx`, `v = fy·y/z + cy`, `x` right, `y`
/// down, `z` forward in the camera's frame; pixel centres at integer
/// `(u, v)`, as calibrations give them).
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct IntrinsicsSpec {
    /// Focal length along the rows, pixels (positive).
    #[serde(deserialize_with = "num::positive")]
    pub fx: f64,
    /// Focal length along the columns, pixels (positive).
    #[serde(deserialize_with = "num::positive")]
    pub fy: f64,
    /// Principal point from the left edge, pixels.
    #[serde(deserialize_with = "num::finite")]
    pub cx: f64,
    /// Principal point from the top edge, pixels.
    #[serde(deserialize_with = "num::finite")]
    pub cy: f64,
}

impl From<IntrinsicsSpec> for super::model::Intrinsics {
    fn from(k: IntrinsicsSpec) -> Self {
        super::model::Intrinsics {
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
        }
    }
}

/// A model's placement: uniform scale, then rotation (degrees about x, y,
/// z, applied in that order), then translation. Uniform so discs stay discs.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransformSpec {
    /// Uniform scale.
    #[serde(default = "one_f32", deserialize_with = "num::positive")]
    pub scale: f32,
    /// Rotation, degrees about x, y, z.
    #[serde(default)]
    #[serde(deserialize_with = "num::finite")]
    pub rotate: [f32; 3],
    /// Translation (f64: applied before re-centring, in double precision).
    #[serde(default)]
    #[serde(deserialize_with = "num::finite")]
    pub translate: [f64; 3],
}

impl Default for TransformSpec {
    fn default() -> Self {
        TransformSpec {
            scale: 1.0,
            rotate: [0.0; 3],
            translate: [0.0; 3],
        }
    }
}

/// `splat = { ... }`: parameters of splat generation for point models.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SplatSpec {
    /// Growth error threshold, fraction of the model's bounding-box diagonal
    /// (`SplatParams::epsilon_rel`; the key is `epsilon`).
    #[serde(default, rename = "epsilon", deserialize_with = "num::positive")]
    pub epsilon_rel: Option<f32>,
    /// Neighbourhood size.
    pub k: Option<usize>,
    /// Density factor `k` of §2.2.
    #[serde(default, deserialize_with = "num::positive")]
    pub density: Option<f32>,
    /// Grow elliptical splats.
    #[serde(default)]
    pub ellipses: bool,
    /// Fit a linear colour field to each splat of a coloured cloud
    /// (`SplatParams::color_fields`; default true).
    pub color_fields: Option<bool>,
    /// Find creases and clip splats at them (`SplatParams::creases`):
    /// true everywhere, false nowhere; absent, the default
    /// (`Creases::Auto`: on but for a cloud sampled along scan lines).
    pub creases: Option<bool>,
    /// `false`: never lean growth, the stages on any cloud
    /// (`SplatParams::lean`; absent or true: lean growth where its gate
    /// finds the cloud suits it).
    pub lean: Option<bool>,
    /// Orient estimated normals toward this point (model space: the point
    /// file's coordinates).
    #[serde(default, deserialize_with = "num::finite")]
    pub viewpoint: Option<[f32; 3]>,
}

/// `scan = { ... }`: a synthetic range scan of a mesh model (see
/// [`crate::scanner`]); the mesh stays the exact surface.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScanSpec {
    /// The scanner's position (model space): `[x, y, z]`, or several
    /// stations `[[x, y, z], ...]`, each scanned with the same settings,
    /// which make one cloud of several scans (as an E57 survey's).
    #[serde(deserialize_with = "num::stations")]
    pub from: Vec<[f32; 3]>,
    /// The point it looks at (default: the mesh's centre).
    #[serde(default, deserialize_with = "num::finite")]
    pub at: Option<[f32; 3]>,
    /// Rays per row and rows (per station).
    #[serde(default, deserialize_with = "num::generated")]
    pub rays: Option<[u32; 2]>,
    /// `raster` or `lines`.
    #[serde(default)]
    pub pattern: crate::scanner::ScanPattern,
    /// Vertical field of view, degrees (default: the mesh fills it).
    #[serde(default, deserialize_with = "num::fov")]
    pub fov: Option<f32>,
    /// Range noise, absolute (model units).
    #[serde(default, deserialize_with = "num::non_negative")]
    pub range_noise: Option<f32>,
    /// Range noise as a multiple of the scan's point spacing.
    #[serde(default, deserialize_with = "num::non_negative")]
    pub range_noise_spacing: Option<f32>,
    /// Fraction of returns replaced by outliers.
    #[serde(default, deserialize_with = "num::fraction")]
    pub outliers: f32,
    /// Fraction of returns dropped.
    #[serde(default, deserialize_with = "num::fraction")]
    pub missing: f32,
    /// What traces the rays: `embree` (default) or `octree` (the same
    /// points on every SIMD path).
    #[serde(default)]
    pub tracer: crate::scanner::ScanTracer,
}

/// `shape = { ... }`: a procedural model.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShapeSpec {
    /// `sphere` or `quad`.
    pub kind: ShapeKind,
    /// Centre.
    #[serde(default, deserialize_with = "num::finite")]
    pub center: [f32; 3],
    /// Sphere radius.
    #[serde(default, deserialize_with = "num::positive")]
    pub radius: Option<f32>,
    /// Quad size (two edge lengths).
    #[serde(default, deserialize_with = "num::positive")]
    pub size: Option<[f32; 2]>,
    /// Quad normal.
    #[serde(default, deserialize_with = "num::finite")]
    pub normal: Option<[f32; 3]>,
    /// Number of splats.
    #[serde(deserialize_with = "num::generated")]
    pub splats: usize,
}

/// `material = { ... }`.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialSpec {
    /// `diffuse` (the default), `phong`, `mirror` or `glass`.
    #[serde(default)]
    pub kind: MaterialKind,
    /// Albedo; multiplies the point colours when the data has them.
    #[serde(default, deserialize_with = "num::non_negative")]
    pub color: Option<[f32; 3]>,
    /// Blinn–Phong specular strength (`phong`).
    #[serde(default, deserialize_with = "num::non_negative")]
    pub specular: Option<f32>,
    /// Blinn–Phong exponent (`phong`).
    #[serde(default, deserialize_with = "num::non_negative")]
    pub shininess: Option<f32>,
    /// Mirror reflectance (`mirror`).
    #[serde(default, deserialize_with = "num::fraction")]
    pub reflectance: Option<f32>,
    /// Index of refraction (`glass`).
    #[serde(default, deserialize_with = "num::positive")]
    pub ior: Option<f32>,
    /// Shading mode for this model's splats (`flat`, `blended`, `phong`),
    /// overriding `[render] shading`.
    pub shading: Option<ShadingMode>,
}

/// `[[model]]`: exactly one of `points`, `splats`, `gaussians`, `mesh`
/// (with `samples`), `triangles` or `shape`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelSpec {
    /// A point file (PLY, PCD, XYZ) turned into splats.
    pub points: Option<PathBuf>,
    /// A splat PLY written by `splatray splat`.
    pub splats: Option<PathBuf>,
    /// A Gaussian splat PLY (2DGS or 3DGS layout), its Gaussians read as
    /// splats.
    pub gaussians: Option<PathBuf>,
    /// Gaussians less opaque than this are left out (`gaussians` models
    /// only; default 0.5).
    #[serde(default, deserialize_with = "num::fraction")]
    pub min_opacity: Option<f32>,
    /// A triangle mesh (PLY) to sample points from.
    pub mesh: Option<PathBuf>,
    /// How many points to sample from `mesh` uniformly by area.
    #[serde(default, deserialize_with = "num::generated")]
    pub samples: Option<usize>,
    /// Or: scan `mesh` from a viewpoint, like a range scanner.
    pub scan: Option<ScanSpec>,
    /// Seed for the mesh sampling or scan.
    #[serde(default)]
    pub seed: u64,
    /// A procedural shape.
    pub shape: Option<ShapeSpec>,
    /// A triangle mesh (PLY or OBJ) rendered as its triangles, beside the
    /// splats (issue 57): shaded with its vertex normals where it has
    /// them, else its face normals.
    pub triangles: Option<PathBuf>,
    /// A `triangles` mesh without vertex normals shaded with area-weighted
    /// vertex normals (the smooth surface it samples, as `compare --truth`
    /// shades a mesh) instead of its face normals; `triangles` models only.
    #[serde(default)]
    pub smooth: bool,
    /// The exact surface behind a `points`, `splats` or `gaussians` model
    /// (a triangle mesh PLY in the model's own coordinates), for
    /// `compare --truth`: e.g. the mesh a scan was simulated from.
    pub truth: Option<PathBuf>,
    /// Placement.
    #[serde(default)]
    pub transform: TransformSpec,
    /// Splat generation parameters.
    #[serde(default)]
    pub splat: SplatSpec,
    /// Surface material.
    #[serde(default)]
    pub material: MaterialSpec,
}

/// `[[light]]`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightSpec {
    /// `point`, `directional` or `sphere`.
    pub kind: LightKind,
    /// Position (`point`, `sphere`).
    #[serde(default, deserialize_with = "num::finite")]
    pub position: Option<[f64; 3]>,
    /// Direction the light travels (`directional`).
    #[serde(default, deserialize_with = "num::finite")]
    pub direction: Option<[f32; 3]>,
    /// Colour.
    #[serde(default = "white", deserialize_with = "num::non_negative")]
    pub color: [f32; 3],
    /// Intensity (radiant intensity for point lights, irradiance for
    /// directional ones).
    #[serde(default = "one_f32", deserialize_with = "num::non_negative")]
    pub intensity: f32,
    /// Radius (`sphere`).
    #[serde(default, deserialize_with = "num::positive")]
    pub radius: Option<f32>,
    /// Shadow samples per shading point (`sphere`).
    #[serde(default, deserialize_with = "num::light_samples")]
    pub samples: Option<u32>,
}

/// `[render]`.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenderSpec {
    /// Maximum recursion depth for reflection and refraction.
    #[serde(default, deserialize_with = "num::depth")]
    pub max_depth: Option<u32>,
    /// `flat`, `blended` or `phong` (default `phong`).
    pub shading: Option<ShadingMode>,
    /// Blending window `xi` of every model, fraction of the scene diagonal
    /// (§4.3); by default each model's is measured on its splats.
    #[serde(default, deserialize_with = "num::non_negative")]
    pub xi: Option<f32>,
    /// Self-intersection distance, fraction of the scene diagonal (§3.2).
    #[serde(default, deserialize_with = "num::non_negative")]
    pub eps_self: Option<f32>,
    /// Ambient term.
    #[serde(default, deserialize_with = "num::non_negative")]
    pub ambient: Option<f32>,
}

/// The whole scene file.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// The camera.
    pub camera: CameraSpec,
    /// Background radiance.
    #[serde(default, deserialize_with = "num::non_negative")]
    pub background: [f32; 3],
    /// Models.
    #[serde(default, rename = "model")]
    pub models: Vec<ModelSpec>,
    /// Lights.
    #[serde(default, rename = "light")]
    pub lights: Vec<LightSpec>,
    /// Render options.
    #[serde(default)]
    pub render: RenderSpec,
}

impl SceneFile {
    /// This file with every model that has a mesh (a `mesh` model, or a
    /// `truth` beside `points`, `splats` or `gaussians`) made a `triangles`
    /// model of that mesh, its material and transform kept; and how many
    /// (issue 57: `compare --as-triangles` and the sweep's mesh row);
    /// `smooth` sets their `smooth` key (area-weighted vertex normals).
    #[must_use]
    pub fn meshes_as_triangles(&self, smooth: bool) -> (SceneFile, usize) {
        let mut out = self.clone();
        let mut n = 0;
        for m in &mut out.models {
            let Some(mesh) = m.mesh.take().or_else(|| m.truth.take()) else {
                continue;
            };
            m.triangles = Some(mesh);
            m.smooth = smooth;
            (m.points, m.splats, m.gaussians) = (None, None, None);
            (m.samples, m.scan, m.min_opacity) = (None, None, None);
            n += 1;
        }
        (out, n)
    }
}

/// Reads and parses a scene file. Errors are one line (the TOML parser's
/// message, which names the key and the line, is folded onto it).
pub fn parse_scene_file(path: &Path) -> Result<SceneFile> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        Error::other(e).context(format_args!("{}: cannot read scene", path.display()))
    })?;
    parse_scene_str(&text).map_err(|e| e.context(path.display()))
}

/// Parses scene TOML text.
pub fn parse_scene_str(text: &str) -> Result<SceneFile> {
    toml::from_str::<SceneFile>(text).map_err(|e| {
        let msg = e.message().to_string();
        match e.span() {
            Some(span) => {
                let mut start = span.start.min(text.len());
                while !text.is_char_boundary(start) {
                    start -= 1;
                }
                let line = text[..start].matches('\n').count() + 1;
                match key_before(&text[..start]) {
                    Some(key) => Error::invalid(format!("line {line}: `{key}` {msg}")),
                    None => Error::invalid(format!("line {line}: {msg}")),
                }
            }
            None => Error::invalid(msg),
        }
    })
}

/// The key whose value starts at the end of `before` (`key = ` on the same
/// line, inline tables included), for a message about that value.
fn key_before(before: &str) -> Option<&str> {
    let line = &before[before.rfind('\n').map_or(0, |i| i + 1)..];
    let lhs = line[..line.rfind('=')?].trim_end();
    // Past the last character that cannot be part of a key (one of
    // several bytes, as `§`, included).
    let from = lhs
        .char_indices()
        .rev()
        .find(|&(_, c)| !(c.is_alphanumeric() || c == '_' || c == '-' || c == '.'))
        .map_or(0, |(i, c)| i + c.len_utf8());
    let key = &lhs[from..];
    (!key.is_empty()).then_some(key)
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEAD: &str = "[camera]\nfrom = [0.0, 0.0, 3.0]\nat = [0.0, 0.0, 0.0]\n[[model]]\n";

    /// An error on a line whose text before `=` ends in a character of
    /// several bytes (`§`, found by the fuzzer in a mutated comment) is a
    /// one-line error naming the line, not a panic slicing inside it.
    #[test]
    fn an_error_after_a_multibyte_character_names_its_line() {
        let e = parse_scene_str("# x\n# report \u{a7}4e=\u{7f}\n").unwrap_err();
        assert!(e.to_string().starts_with("line 2: "), "{e}");
        let e = parse_scene_str("[camera]\nfov\u{a7} = \"x\"\n").unwrap_err();
        assert!(e.to_string().starts_with("line 2"), "{e}");
    }

    /// `scan.from` takes one station or a list; an empty list, a
    /// non-finite coordinate or another shape is a one-line error.
    #[test]
    fn scan_stations_one_or_several() {
        let scan = |from: &str| {
            parse_scene_str(&format!(
                "{HEAD}mesh = \"m.ply\"\nscan = {{ from = {from} }}\n"
            ))
            .map(|f| f.models[0].scan.as_ref().unwrap().from.clone())
            .map_err(|e| e.to_string())
        };
        assert_eq!(scan("[1.0, 2.0, 3.0]").unwrap(), [[1.0, 2.0, 3.0]]);
        assert_eq!(
            scan("[[1.0, 2.0, 3.0], [-1.0, 0.5, 2.0]]").unwrap(),
            [[1.0, 2.0, 3.0], [-1.0, 0.5, 2.0]]
        );
        for (from, expect) in [
            ("[]", "must list 1..=1024 stations, got 0"),
            ("[[1.0, 2.0, nan]]", "must be finite, got [1.0, 2.0, NaN]"),
            ("[1.0, inf, 3.0]", "must be finite, got [1.0, inf, 3.0]"),
            (
                "[1.0, 2.0]",
                "must be a position [x, y, z] or a list of them",
            ),
            ("[[1.0, 2.0, 3.0], [1.0]]", "must be a position [x, y, z]"),
        ] {
            let e = scan(from).unwrap_err();
            assert!(
                e.starts_with("line 6: `from` ") && e.contains(expect),
                "{from}: {e}"
            );
            assert_eq!(e.lines().count(), 1, "{e}");
        }
    }

    #[test]
    fn unknown_kinds_are_line_numbered_parse_errors() {
        for (line, expect) in [
            (
                "shape = { kind = \"cube\", radius = 1.0, splats = 10 }",
                "line 5: `kind` unknown variant `cube`",
            ),
            (
                "shape = { kind = \"sphere\", radius = 1.0, splats = 10 }\nmaterial = { kind = \"glas\" }",
                "line 6: `kind` unknown variant `glas`, expected one of `diffuse`, `phong`, `mirror`, `glass`",
            ),
            (
                "shape = { kind = \"sphere\", radius = 1.0, splats = 10 }\n[render]\nshading = \"smooth\"",
                "line 7: `shading` unknown variant `smooth`, expected one of `flat`, `blended`, `phong`",
            ),
        ] {
            let e = parse_scene_str(&format!("{HEAD}{line}\n"))
                .unwrap_err()
                .to_string();
            assert!(e.starts_with(expect), "{e}");
            assert_eq!(e.lines().count(), 1, "{e}");
        }
        let f = parse_scene_str(&format!(
            "{HEAD}shape = {{ kind = \"quad\", size = [1.0, 1.0], splats = 10 }}\n\
             material = {{ shading = \"flat\" }}\n[[light]]\nkind = \"directional\"\n\
             direction = [0.0, -1.0, 0.0]\n"
        ))
        .unwrap();
        let m = &f.models[0];
        assert_eq!(m.shape.as_ref().map(|s| s.kind), Some(ShapeKind::Quad));
        assert_eq!(m.material.kind, MaterialKind::Diffuse);
        assert_eq!(m.material.shading, Some(ShadingMode::Flat));
        assert_eq!(f.lights[0].kind, LightKind::Directional);
    }
}
