//! Scene files (TOML) and the loaded scene.
//!
//! A scene states only what it needs; everything omitted has a default and
//! costs nothing at render time. Unknown keys are errors naming the key and
//! the line (serde's `deny_unknown_fields`, reported by the TOML parser).

use crate::accel::SceneScale;
use crate::accel::resolve::ShadingMode;
use crate::splat::Splat;
use glam::{DVec3, Mat3, Vec2, Vec3};
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

/// `[camera]`: a pinhole camera.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    /// Eye position (f64, so far-from-origin scenes keep their precision).
    pub from: [f64; 3],
    /// Point looked at.
    pub at: [f64; 3],
    /// Up vector.
    #[serde(default = "default_up")]
    pub up: [f32; 3],
    /// Vertical field of view, degrees.
    #[serde(default = "default_fov")]
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
}

/// A model's placement: uniform scale, then rotation (degrees about x, y,
/// z, applied in that order), then translation. Uniform so discs stay discs.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransformSpec {
    /// Uniform scale.
    #[serde(default = "one_f32")]
    pub scale: f32,
    /// Rotation, degrees about x, y, z.
    #[serde(default)]
    pub rotate: [f32; 3],
    /// Translation (f64: applied before re-centring, in double precision).
    #[serde(default)]
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

impl TransformSpec {
    fn rotation(&self) -> Mat3 {
        let [x, y, z] = self.rotate.map(f32::to_radians);
        Mat3::from_rotation_z(z) * Mat3::from_rotation_y(y) * Mat3::from_rotation_x(x)
    }

    /// Applies the transform to a point, then subtracts `shift`; the
    /// translation and the shift are applied in f64, so a model placed far
    /// from the origin and shifted back keeps f32 precision (DESIGN §4).
    #[must_use]
    pub fn point(&self, p: Vec3, shift: DVec3) -> Vec3 {
        ((self.rotation() * (p * self.scale)).as_dvec3() + DVec3::from(self.translate) - shift)
            .as_vec3()
    }

    /// Applies the transform to every splat, then subtracts `shift` (in f64,
    /// as [`TransformSpec::point`]).
    pub fn apply(&self, splats: &mut [Splat], shift: DVec3) {
        let rot = self.rotation();
        for s in splats {
            s.center = self.point(s.center, shift);
            s.normal = (rot * s.normal).normalize();
            s.u_axis = (rot * s.u_axis).normalize();
            s.v_axis = (rot * s.v_axis).normalize();
            s.radii *= self.scale;
        }
    }
}

/// `splat = { ... }`: parameters of splat generation for point models.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SplatSpec {
    /// Growth error threshold, fraction of the model's bounding-box diagonal.
    pub epsilon: Option<f32>,
    /// Neighbourhood size.
    pub k: Option<usize>,
    /// Density factor `k` of §2.2.
    pub density: Option<f32>,
    /// Grow elliptical splats.
    #[serde(default)]
    pub ellipses: bool,
    /// Orient estimated normals toward this point (model space).
    pub viewpoint: Option<[f32; 3]>,
}

/// `shape = { ... }`: a procedural model.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShapeSpec {
    /// `sphere` or `quad`.
    pub kind: String,
    /// Centre.
    #[serde(default)]
    pub center: [f32; 3],
    /// Sphere radius.
    pub radius: Option<f32>,
    /// Quad size (two edge lengths).
    pub size: Option<[f32; 2]>,
    /// Quad normal.
    pub normal: Option<[f32; 3]>,
    /// Number of splats.
    pub splats: usize,
}

/// `material = { ... }`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialSpec {
    /// `diffuse`, `phong`, `mirror` or `glass`.
    #[serde(default = "default_material_kind")]
    pub kind: String,
    /// Albedo; multiplies the point colours when the data has them.
    pub color: Option<[f32; 3]>,
    /// Blinn–Phong specular strength (`phong`).
    pub specular: Option<f32>,
    /// Blinn–Phong exponent (`phong`).
    pub shininess: Option<f32>,
    /// Mirror reflectance (`mirror`).
    pub reflectance: Option<f32>,
    /// Index of refraction (`glass`).
    pub ior: Option<f32>,
    /// Shading mode for this model's splats (`flat`, `blended`, `phong`),
    /// overriding `[render] shading`.
    pub shading: Option<String>,
}

fn default_material_kind() -> String {
    "diffuse".into()
}

impl Default for MaterialSpec {
    fn default() -> Self {
        MaterialSpec {
            kind: default_material_kind(),
            color: None,
            specular: None,
            shininess: None,
            reflectance: None,
            ior: None,
            shading: None,
        }
    }
}

/// `[[model]]`: exactly one of `points`, `splats`, `mesh` (with `samples`)
/// or `shape`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelSpec {
    /// A point file (PLY, PCD, XYZ) turned into splats.
    pub points: Option<PathBuf>,
    /// A splat PLY written by `splatray splat`.
    pub splats: Option<PathBuf>,
    /// A triangle mesh (PLY) to sample points from.
    pub mesh: Option<PathBuf>,
    /// How many points to sample from `mesh`.
    pub samples: Option<usize>,
    /// Seed for the mesh sampling.
    #[serde(default)]
    pub seed: u64,
    /// A procedural shape.
    pub shape: Option<ShapeSpec>,
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
    pub kind: String,
    /// Position (`point`, `sphere`).
    pub position: Option<[f64; 3]>,
    /// Direction the light travels (`directional`).
    pub direction: Option<[f32; 3]>,
    /// Colour.
    #[serde(default = "white")]
    pub color: [f32; 3],
    /// Intensity (radiant intensity for point lights, irradiance for
    /// directional ones).
    #[serde(default = "one_f32")]
    pub intensity: f32,
    /// Radius (`sphere`).
    pub radius: Option<f32>,
    /// Shadow samples per shading point (`sphere`).
    pub samples: Option<u32>,
}

/// `[render]`.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenderSpec {
    /// Maximum recursion depth for reflection and refraction.
    pub max_depth: Option<u32>,
    /// `flat`, `blended` or `phong`.
    pub shading: Option<String>,
    /// Blending window `xi`, fraction of the scene diagonal (§4.3).
    pub xi: Option<f32>,
    /// Self-intersection distance, fraction of the scene diagonal (§3.2).
    pub eps_self: Option<f32>,
    /// Ambient term.
    pub ambient: Option<f32>,
}

/// The whole scene file.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// The camera.
    pub camera: CameraSpec,
    /// Background radiance.
    #[serde(default)]
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

/// A surface material.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Material {
    /// Lambertian.
    Diffuse {
        /// Albedo.
        color: Vec3,
    },
    /// Lambertian plus Blinn–Phong highlight.
    Phong {
        /// Albedo.
        color: Vec3,
        /// Specular strength.
        specular: f32,
        /// Exponent.
        shininess: f32,
    },
    /// Perfect mirror.
    Mirror {
        /// Reflectance (tint).
        color: Vec3,
    },
    /// Dielectric with Fresnel reflection and refraction.
    Glass {
        /// Transmission tint.
        color: Vec3,
        /// Index of refraction.
        ior: f32,
    },
}

/// A light source.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Light {
    /// Point light at `position`, falling off as `1/d²`.
    Point {
        /// Position.
        position: Vec3,
        /// Colour × intensity.
        power: Vec3,
    },
    /// Directional light travelling along `direction`.
    Directional {
        /// Unit direction the light travels.
        direction: Vec3,
        /// Colour × irradiance.
        power: Vec3,
    },
    /// Spherical area light: soft shadows from `samples` stratified points.
    Sphere {
        /// Centre.
        position: Vec3,
        /// Radius.
        radius: f32,
        /// Colour × intensity.
        power: Vec3,
        /// Shadow rays per shading point.
        samples: u32,
    },
}

/// A pinhole camera, resolved.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Eye.
    pub origin: Vec3,
    /// Unit forward.
    pub forward: Vec3,
    /// Unit right, scaled by the half-width of the image plane at distance 1.
    pub right: Vec3,
    /// Unit up, scaled by the half-height of the image plane at distance 1.
    pub up: Vec3,
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Samples per pixel.
    pub spp: u32,
}

impl Camera {
    /// Builds a camera looking from `from` at `at`.
    pub fn look_at(
        from: Vec3,
        at: Vec3,
        up: Vec3,
        fov_deg: f32,
        width: u32,
        height: u32,
        spp: u32,
    ) -> Result<Camera, String> {
        let forward = (at - from)
            .try_normalize()
            .ok_or("camera: `from` and `at` coincide")?;
        let right = forward
            .cross(up)
            .try_normalize()
            .ok_or("camera: `up` is parallel to the view direction")?;
        let true_up = right.cross(forward);
        if !(fov_deg > 0.0 && fov_deg < 180.0) {
            return Err(format!("camera: fov {fov_deg} must be in (0, 180) degrees"));
        }
        let half_h = (fov_deg.to_radians() * 0.5).tan();
        let half_w = half_h * width as f32 / height as f32;
        Ok(Camera {
            origin: from,
            forward,
            right: right * half_w,
            up: true_up * half_h,
            width,
            height,
            spp,
        })
    }

    /// The primary ray through image position `(px, py)` in pixels (pixel
    /// centres at `+0.5`; `y` down).
    #[must_use]
    pub fn ray(&self, px: f32, py: f32) -> crate::accel::Ray {
        let sx = 2.0 * px / self.width as f32 - 1.0;
        let sy = 1.0 - 2.0 * py / self.height as f32;
        crate::accel::Ray::new(self.origin, self.forward + self.right * sx + self.up * sy)
    }
}

/// Render options, resolved.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderOptions {
    /// Maximum recursion depth.
    pub max_depth: u32,
    /// Shading mode.
    pub shading: ShadingMode,
    /// `xi`, `eps_self` and the diagonal.
    pub scale: SceneScale,
    /// Ambient term.
    pub ambient: f32,
}

impl Scene {
    /// The splats' bounding box in world coordinates (as the scene file
    /// states them), or `None` without splats.
    #[must_use]
    pub fn world_bounds(&self) -> Option<(DVec3, DVec3)> {
        let (lo, hi) = self.splats.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), s| (lo.min(s.center), hi.max(s.center)),
        );
        let to_world = |v: Vec3| (v + self.offset).as_dvec3() + self.shift;
        (lo.x <= hi.x).then(|| (to_world(lo), to_world(hi)))
    }

    /// The shading mode for a window whose nearest hit is splat `id`: the
    /// model's override, else the scene's.
    #[must_use]
    pub fn shading_for(&self, id: u32) -> ShadingMode {
        let m = self.material_of[id as usize] as usize;
        self.shading_of[m].unwrap_or(self.options.shading)
    }
}

/// What loading measured.
#[derive(Clone, Debug, Default)]
pub struct LoadReport {
    /// Seconds spent reading and generating splats.
    pub splat_seconds: f64,
    /// Input points across point models.
    pub input_points: usize,
    /// One line per warning (skipped points and the like).
    pub warnings: Vec<String>,
    /// Coverage of each generated point model (§2.2).
    pub coverage: Vec<f64>,
    /// The exact surface of each model where one is known (mesh models and
    /// shapes), in world space before re-centring: ground truth for
    /// `compare --truth`.
    pub truth: Vec<TruthSource>,
}

/// The exact surface behind one model.
#[derive(Clone, Debug)]
pub enum TruthSource {
    /// A triangle mesh (mesh models), world space.
    Mesh {
        /// The mesh, transformed.
        mesh: crate::io::Mesh,
        /// Material index.
        material: u16,
    },
    /// An analytic sphere.
    Sphere {
        /// Centre, world space.
        center: Vec3,
        /// Radius.
        radius: f32,
        /// Material index.
        material: u16,
    },
    /// A model with no exact surface (a point or splat file), and why.
    Unknown {
        /// 1-based model number.
        model: usize,
        /// What it is.
        what: String,
    },
}

/// A loaded scene, re-centred so that its splats' bounding box is centred at
/// the origin (DESIGN §4: far-from-origin scenes keep their precision).
#[derive(Clone, Debug)]
pub struct Scene {
    /// All splats of all models.
    pub splats: Vec<Splat>,
    /// Material index of each splat.
    pub material_of: Vec<u16>,
    /// Materials.
    pub materials: Vec<Material>,
    /// Shading-mode override of each material (`None`: the scene's mode).
    pub shading_of: Vec<Option<ShadingMode>>,
    /// Camera.
    pub camera: Camera,
    /// Lights.
    pub lights: Vec<Light>,
    /// Background radiance.
    pub background: Vec3,
    /// Options.
    pub options: RenderOptions,
    /// The re-centring translation subtracted on load, after `shift`
    /// (world = scene + offset + shift).
    pub offset: Vec3,
    /// The first model's translation, subtracted in f64 before re-centring.
    pub shift: DVec3,
    /// Load figures.
    pub load: LoadReport,
}

/// Reads and parses a scene file. Errors are one line (the TOML parser's
/// message, which names the key and the line, is folded onto it).
pub fn parse_scene_file(path: &Path) -> Result<SceneFile, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("{}: cannot read scene: {e}", path.display()))?;
    parse_scene_str(&text).map_err(|e| format!("{}: {e}", path.display()))
}

/// Parses scene TOML text.
pub fn parse_scene_str(text: &str) -> Result<SceneFile, String> {
    toml::from_str::<SceneFile>(text).map_err(|e| {
        let msg = e.message().to_string();
        match e.span() {
            Some(span) => {
                let line = text[..span.start.min(text.len())].matches('\n').count() + 1;
                format!("line {line}: {msg}")
            }
            None => msg,
        }
    })
}

fn v3(a: [f32; 3]) -> Vec3 {
    Vec3::from(a)
}

fn finite(name: &str, v: &[f32]) -> Result<(), String> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(format!("{name}: values must be finite, got {v:?}"))
    }
}

fn material(spec: &MaterialSpec) -> Result<Material, String> {
    let color = v3(spec.color.unwrap_or([0.8, 0.8, 0.8]));
    finite("material.color", &color.to_array())?;
    Ok(match spec.kind.as_str() {
        "diffuse" => Material::Diffuse { color },
        "phong" => Material::Phong {
            color,
            specular: spec.specular.unwrap_or(0.4),
            shininess: spec.shininess.unwrap_or(40.0),
        },
        "mirror" => Material::Mirror {
            color: Vec3::splat(spec.reflectance.unwrap_or(0.9)) * spec.color.map_or(Vec3::ONE, v3),
        },
        "glass" => {
            let ior = spec.ior.unwrap_or(1.5);
            if !(ior > 0.0 && ior.is_finite()) {
                return Err(format!("material.ior must be positive, got {ior}"));
            }
            Material::Glass {
                color: spec.color.map_or(Vec3::ONE, v3),
                ior,
            }
        }
        k => {
            return Err(format!(
                "material.kind '{k}' unknown (expected diffuse, phong, mirror or glass)"
            ));
        }
    })
}

/// A position given in f64, shifted (in f64) and then made f32.
fn shifted(p: [f64; 3], shift: DVec3) -> Vec3 {
    (DVec3::from(p) - shift).as_vec3()
}

fn light(spec: &LightSpec, shift: DVec3) -> Result<Light, String> {
    let power = v3(spec.color) * spec.intensity;
    finite("light.color × intensity", &power.to_array())?;
    let need = |v: Option<[f32; 3]>, what: &str| {
        v.map(v3)
            .ok_or_else(|| format!("a {} light needs `{what}`", spec.kind))
    };
    let position = || {
        let p = spec
            .position
            .ok_or_else(|| format!("a {} light needs `position`", spec.kind))?;
        finite("light.position", &p.map(|x| x as f32))?;
        Ok::<Vec3, String>(shifted(p, shift))
    };
    Ok(match spec.kind.as_str() {
        "point" => Light::Point {
            position: position()?,
            power,
        },
        "directional" => Light::Directional {
            direction: need(spec.direction, "direction")?
                .try_normalize()
                .ok_or("light.direction must be non-zero")?,
            power,
        },
        "sphere" => {
            let radius = spec.radius.ok_or("a sphere light needs `radius`")?;
            if !(radius > 0.0 && radius.is_finite()) {
                return Err(format!("light.radius must be positive, got {radius}"));
            }
            Light::Sphere {
                position: position()?,
                radius,
                power,
                samples: spec.samples.unwrap_or(16).max(1),
            }
        }
        k => {
            return Err(format!(
                "light.kind '{k}' unknown (expected point, directional or sphere)"
            ));
        }
    })
}

/// Splats of one model in model space, before its transform.
fn model_splats(
    spec: &ModelSpec,
    base: &Path,
    load: &mut LoadReport,
    shift: DVec3,
) -> Result<Vec<Splat>, String> {
    let sources = [
        spec.points.is_some(),
        spec.splats.is_some(),
        spec.mesh.is_some(),
        spec.shape.is_some(),
    ];
    if sources.iter().filter(|&&b| b).count() != 1 {
        return Err("a model needs exactly one of `points`, `splats`, `mesh` or `shape`".into());
    }
    if let Some(shape) = &spec.shape {
        return shape_splats(shape);
    }
    let resolve = |p: &PathBuf| base.join(p);
    model_splats_from_files(spec, &resolve, load, shift)
}

fn shape_splats(shape: &ShapeSpec) -> Result<Vec<Splat>, String> {
    if shape.splats == 0 {
        return Err("shape.splats must be at least 1".into());
    }
    let center = v3(shape.center);
    finite("shape.center", &shape.center)?;
    match shape.kind.as_str() {
        "sphere" => {
            let r = shape.radius.ok_or("a sphere shape needs `radius`")?;
            if !(r > 0.0 && r.is_finite()) {
                return Err(format!("shape.radius must be positive, got {r}"));
            }
            Ok(super::shapes::sphere(center, r, shape.splats))
        }
        "quad" => {
            let size = shape.size.ok_or("a quad shape needs `size`")?;
            if !(size[0] > 0.0 && size[1] > 0.0 && size[0].is_finite() && size[1].is_finite()) {
                return Err(format!("shape.size must be positive, got {size:?}"));
            }
            let normal = v3(shape.normal.unwrap_or([0.0, 1.0, 0.0]));
            Ok(super::shapes::quad(
                center,
                normal,
                Vec2::from(size),
                shape.splats,
            ))
        }
        k => Err(format!(
            "shape.kind '{k}' unknown (expected sphere or quad)"
        )),
    }
}

/// The exact surface of a shape model (or why there is none).
fn shape_truth(m: &ModelSpec, model: usize, material: u16, shift: DVec3) -> TruthSource {
    let t = &m.transform;
    match &m.shape {
        Some(sh) if sh.kind == "sphere" => TruthSource::Sphere {
            center: t.point(v3(sh.center), shift),
            radius: sh.radius.unwrap_or(1.0) * t.scale,
            material,
        },
        Some(sh) if sh.kind == "quad" => {
            let n = v3(sh.normal.unwrap_or([0.0, 1.0, 0.0]))
                .try_normalize()
                .unwrap_or(Vec3::Y);
            let (a, b) = crate::splat::tangent_frame(n);
            let [sx, sy] = sh.size.unwrap_or([1.0, 1.0]);
            let c = v3(sh.center);
            let corners = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
                .map(|(x, y)| t.point(c + a * (0.5 * sx * x) + b * (0.5 * sy * y), shift));
            TruthSource::Mesh {
                mesh: crate::io::Mesh {
                    positions: corners.to_vec(),
                    triangles: vec![[0, 1, 2], [0, 2, 3]],
                },
                material,
            }
        }
        _ => TruthSource::Unknown {
            model,
            what: if m.points.is_some() {
                "a point file".into()
            } else {
                "a splat file".into()
            },
        },
    }
}

/// Loads a scene file: parses it, builds every model's splats, resolves
/// materials, lights and camera, and re-centres everything.
pub fn load_scene(path: &Path) -> Result<Scene, String> {
    let file = parse_scene_file(path)?;
    let base = path.parent().unwrap_or(Path::new("."));
    build_scene(&file, base).map_err(|e| format!("{}: {e}", path.display()))
}

/// Builds a scene from a parsed file; relative model paths are resolved
/// against `base`.
pub fn build_scene(file: &SceneFile, base: &Path) -> Result<Scene, String> {
    let c = &file.camera;
    if c.width == 0 || c.height == 0 {
        return Err(format!(
            "camera resolution {}x{} must be positive",
            c.width, c.height
        ));
    }
    if c.width > 1 << 15 || c.height > 1 << 15 {
        return Err(format!(
            "camera resolution {}x{} is over 32768",
            c.width, c.height
        ));
    }
    if c.spp == 0 || c.spp > 4096 {
        return Err(format!("camera.spp {} must be in 1..=4096", c.spp));
    }
    finite("camera.from", &c.from.map(|x| x as f32))?;
    finite("camera.at", &c.at.map(|x| x as f32))?;
    // Models, camera and lights are first shifted, in f64, by the first
    // model's translation, so that a scene placed far from the origin keeps
    // its f32 precision; what remains is re-centred below.
    let shift = file
        .models
        .first()
        .map_or(DVec3::ZERO, |m| DVec3::from(m.transform.translate));
    finite("background", &file.background)?;
    if file.models.is_empty() {
        return Err("the scene has no [[model]]".into());
    }
    let start = std::time::Instant::now();
    let mut load = LoadReport::default();
    let mut splats = Vec::new();
    let mut material_of = Vec::new();
    let mut materials = Vec::new();
    let mut shading_of = Vec::new();
    for (i, m) in file.models.iter().enumerate() {
        let truth_before = load.truth.len();
        let mut s =
            model_splats(m, base, &mut load, shift).map_err(|e| format!("model {}: {e}", i + 1))?;
        let mid = u16::try_from(i).map_err(|_| "more than 65535 models".to_string())?;
        if load.truth.len() == truth_before {
            load.truth.push(shape_truth(m, i + 1, mid, shift));
        } else if let Some(TruthSource::Mesh { material, .. }) = load.truth.last_mut() {
            *material = mid;
        }
        if !(m.transform.scale > 0.0 && m.transform.scale.is_finite()) {
            return Err(format!(
                "model {}: transform.scale must be positive, got {}",
                i + 1,
                m.transform.scale
            ));
        }
        m.transform.apply(&mut s, shift);
        materials.push(material(&m.material).map_err(|e| format!("model {}: {e}", i + 1))?);
        shading_of.push(match &m.material.shading {
            Some(s) => Some(s.parse().map_err(|e| format!("model {}: {e}", i + 1))?),
            None => None,
        });
        material_of.extend(std::iter::repeat_n(mid, s.len()));
        splats.extend(s);
    }
    load.splat_seconds = start.elapsed().as_secs_f64();
    let lights = file
        .lights
        .iter()
        .map(|l| light(l, shift))
        .collect::<Result<Vec<_>, _>>()?;

    // Re-centre on the splats' bounding box.
    let (lo, hi) = splats.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), s| {
            let h = s.half_extent();
            (lo.min(s.center - h), hi.max(s.center + h))
        },
    );
    let (offset, diagonal) = if lo.x <= hi.x {
        ((lo + hi) * 0.5, (hi - lo).length().max(f32::MIN_POSITIVE))
    } else {
        (Vec3::ZERO, 1.0)
    };
    for s in &mut splats {
        s.center -= offset;
    }
    let lights = lights
        .into_iter()
        .map(|l| match l {
            Light::Point { position, power } => Light::Point {
                position: position - offset,
                power,
            },
            Light::Sphere {
                position,
                radius,
                power,
                samples,
            } => Light::Sphere {
                position: position - offset,
                radius,
                power,
                samples,
            },
            d @ Light::Directional { .. } => d,
        })
        .collect();
    let camera = Camera::look_at(
        shifted(c.from, shift) - offset,
        shifted(c.at, shift) - offset,
        v3(c.up),
        c.fov,
        c.width,
        c.height,
        c.spp,
    )?;
    let r = &file.render;
    let mut scale = SceneScale::from_diagonal(diagonal);
    if let Some(xi) = r.xi {
        if !(xi >= 0.0 && xi.is_finite()) {
            return Err(format!("render.xi must be >= 0, got {xi}"));
        }
        scale.xi = xi * diagonal;
    }
    if let Some(e) = r.eps_self {
        if !(e >= 0.0 && e.is_finite()) {
            return Err(format!("render.eps_self must be >= 0, got {e}"));
        }
        scale.eps_self = e * diagonal;
    }
    let shading = match &r.shading {
        Some(s) => s.parse()?,
        None => ShadingMode::Phong,
    };
    Ok(Scene {
        splats,
        material_of,
        materials,
        shading_of,
        camera,
        lights,
        background: v3(file.background),
        options: RenderOptions {
            max_depth: r.max_depth.unwrap_or(5),
            shading,
            scale,
            ambient: r.ambient.unwrap_or(0.03),
        },
        offset,
        shift,
        load,
    })
}

/// Point, splat and mesh models: read from files (paths relative to the
/// scene file). Point and mesh models go through splat generation (§2, §4.1–4.2).
fn model_splats_from_files(
    spec: &ModelSpec,
    resolve: &dyn Fn(&PathBuf) -> PathBuf,
    load: &mut LoadReport,
    shift: DVec3,
) -> Result<Vec<Splat>, String> {
    if let Some(p) = &spec.splats {
        return crate::io::read_splats(&resolve(p)).map_err(|e| e.to_string());
    }
    let cloud = if let Some(p) = &spec.points {
        if spec.samples.is_some() {
            return Err("`samples` applies to `mesh` models only".into());
        }
        crate::io::read_points(&resolve(p)).map_err(|e| e.to_string())?
    } else if let Some(p) = &spec.mesh {
        let path = resolve(p);
        let samples = spec
            .samples
            .ok_or_else(|| format!("{}: a mesh model needs `samples`", path.display()))?;
        if samples == 0 || samples > 50_000_000 {
            return Err(format!("samples {samples} must be in 1..=50000000"));
        }
        let mesh = crate::io::read_mesh(&path).map_err(|e| e.to_string())?;
        let cloud = crate::io::sample_mesh(&mesh, samples, 0.0, spec.seed);
        load.truth.push(TruthSource::Mesh {
            mesh: crate::io::Mesh {
                positions: mesh
                    .positions
                    .iter()
                    .map(|&p| spec.transform.point(p, shift))
                    .collect(),
                triangles: mesh.triangles.clone(),
            },
            material: 0, // set by the caller
        });
        cloud
    } else {
        return Err("a model needs exactly one of `points`, `splats`, `mesh` or `shape`".into());
    };
    let d = crate::splat::SplatParams::default();
    let params = crate::splat::SplatParams {
        k: spec.splat.k.unwrap_or(d.k),
        epsilon_rel: spec.splat.epsilon.unwrap_or(d.epsilon_rel),
        density: spec.splat.density.unwrap_or(d.density),
        ellipses: spec.splat.ellipses,
        viewpoint: spec.splat.viewpoint.map(Vec3::from),
        ..d
    };
    let mut progress = crate::cli::progress::Progress::new();
    let (splats, report) =
        crate::splat::generate_with_progress(&cloud, &params, |stage, f| progress.update(stage, f))
            .map_err(|e| e.to_string())?;
    progress.finish();
    load.input_points += report.input_points;
    for s in &report.skipped_points {
        load.warnings
            .push(format!("{} points skipped: {}", s.count, s.reason));
    }
    load.warnings.extend(report.warnings.iter().cloned());
    load.coverage.push(report.coverage);
    Ok(splats)
}
