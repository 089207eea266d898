//! Loading a scene: every model's splats (read, generated from points or a
//! sampled mesh, or built procedurally) and its exact surface, the
//! materials, lights and camera resolved, and everything re-centred.

use super::file::{
    CameraSpec, LightKind, LightSpec, MaterialKind, MaterialSpec, ModelSpec, RenderSpec, SceneFile,
    ShapeKind, ShapeSpec, TransformSpec, parse_scene_file,
};
use super::model::{
    Camera, Light, LoadReport, MAX_EXTENT, Material, RenderOptions, Scene, Triangles, TruthSource,
};
use crate::io::{CloudRead, Mesh, PointCloud, TriangleMesh};
use crate::primitive::Triangle;
use crate::progress::Progress;
use crate::resolve::ShadingMode;
use crate::scene::SceneScale;
use crate::splat::Splat;
use crate::splat::color::ColorField;
use crate::splat::standoff::Standoff;
use crate::{Error, Result};
use glam::{DMat3, DVec3, Mat3, Vec2, Vec3};
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// Loads a scene file: parses it, builds every model's splats, resolves
/// materials, lights and camera, and re-centres everything. Splat
/// generation reports to `progress`.
///
/// # Errors
/// One line naming the file (and the model, where one is at fault).
pub fn load_scene(path: &Path, progress: Option<Progress<'_>>) -> Result<Scene> {
    load_scene_within(path, progress, None)
}

/// [`load_scene`] within `max_bytes` (`--max-memory`): a `triangles`
/// model's mesh is refused while it is read when its triangles alone, with
/// those of the models before it, pass the cap
/// ([`crate::io::read_triangles_within`]).
///
/// # Errors
/// As [`load_scene`].
pub fn load_scene_within(
    path: &Path,
    progress: Option<Progress<'_>>,
    max_bytes: Option<u64>,
) -> Result<Scene> {
    let file = parse_scene_file(path)?;
    let base = path.parent().unwrap_or(Path::new("."));
    build_scene_within(&file, base, Vec::new(), progress, max_bytes)
        .map_err(|e| e.context(path.display()))
}

/// Builds a scene from a parsed file; relative model paths are resolved
/// against `base`. Splat generation reports to `progress`.
///
/// # Errors
/// One line (naming the model where one is at fault).
pub fn build_scene(file: &SceneFile, base: &Path, progress: Option<Progress<'_>>) -> Result<Scene> {
    build_scene_read(file, base, None, progress)
}

/// [`build_scene`] with one model's input already read: `read` is the file
/// at `path` (as [`crate::io::read_any`] gives it), which a model
/// naming that path (joined to `base`) takes instead of reading it again.
///
/// # Errors
/// As [`build_scene`].
pub fn build_scene_read(
    file: &SceneFile,
    base: &Path,
    read: Option<(&Path, CloudRead)>,
    progress: Option<Progress<'_>>,
) -> Result<Scene> {
    let reads = read
        .map(|(p, r)| (p.to_path_buf(), r))
        .into_iter()
        .collect();
    build_scene_reads(file, base, reads, progress)
}

/// [`build_scene`] with several models' inputs already read (or made in
/// memory, as the Python package's scenes have them): a model naming the
/// path of one of `reads` (joined to `base`) takes that input instead of
/// reading a file, once.
///
/// # Errors
/// As [`build_scene`].
pub fn build_scene_reads(
    file: &SceneFile,
    base: &Path,
    reads: Vec<(PathBuf, CloudRead)>,
    progress: Option<Progress<'_>>,
) -> Result<Scene> {
    build_scene_within(file, base, reads, progress, None)
}

/// [`build_scene_reads`] within `max_bytes` (see [`load_scene_within`]).
fn build_scene_within(
    file: &SceneFile,
    base: &Path,
    reads: Vec<(PathBuf, CloudRead)>,
    progress: Option<Progress<'_>>,
    max_bytes: Option<u64>,
) -> Result<Scene> {
    let mut read = reads;
    let c = &file.camera;
    check_camera(c)?;
    // Models, camera and lights are first shifted, in f64, by where the
    // first model's origin lands (its translation, plus a point cloud's own
    // origin placed by its transform), so that a scene placed far from the
    // origin keeps its f32 precision; what remains is re-centred below.
    finite("background", &file.background)?;
    if file.models.is_empty() {
        return Err(Error::invalid("the scene has no [[model]]"));
    }
    let mut models = load_models(&file.models, base, &mut read, progress, max_bytes)?;
    let shift = models.shift;
    let lights = file
        .lights
        .iter()
        .map(|l| light(l, shift))
        .collect::<Result<Vec<_>, _>>()?;
    // Each model's standoff, from copies, beside the re-centring (both
    // mostly serial passes over every splat).
    let (standoff, (offset, diagonal)) = rayon::join(
        || models.standoff.iter().map(Standoff::measure).collect::<Vec<_>>(),
        || recentre(&mut models.splats, &mut models.triangles.tris),
    );
    if !diagonal.is_finite() || diagonal > MAX_EXTENT {
        return Err(Error::invalid(format!(
            "the models span {:.2e} once placed, beyond the {MAX_EXTENT:e} the renderer's f32 \
             geometry holds (a model's size, scale or translate)",
            models.span
        )));
    }
    let lights = lights.into_iter().map(|l| moved(l, offset)).collect();
    let camera = scene_camera(c, shift, offset)?;
    let (options, xi_of) = render_options(&file.render, diagonal, &standoff)?;
    Ok(Scene {
        splats: models.splats,
        triangles: models.triangles,
        color_fields: models.color_fields,
        material_of: models.material_of,
        materials: models.materials,
        shading_of: models.shading_of,
        xi_of,
        camera,
        lights,
        background: v3(file.background),
        options,
        offset,
        shift,
        load: models.load,
    })
}

/// The lights of a scene file's `[[light]]` tables, placed as
/// [`build_scene`] places them (shifted by `shift`, re-centred by
/// `offset`): what a view that moves a scene's lights with its camera (a
/// cloud's headlight) reads back from its text.
///
/// # Errors
/// A light without what its kind needs, or out of range (one line).
pub fn scene_lights(specs: &[LightSpec], shift: DVec3, offset: Vec3) -> Result<Vec<Light>> {
    specs
        .iter()
        .map(|l| light(l, shift).map(|l| moved(l, offset)))
        .collect()
}

/// The camera of a scene file's `[camera]` table, placed as
/// [`build_scene`] places it: shifted by `shift` and re-centred by `offset`
/// (a built scene's [`Scene::shift`] and [`Scene::offset`]), so that a
/// camera written to scene text and read back gives the camera a render of
/// that text uses.
///
/// # Errors
/// One line: a resolution or `spp` out of range, `from` and `at` that
/// coincide in f32, an `up` along the view, a field of view or intrinsics
/// out of range.
pub fn scene_camera(c: &CameraSpec, shift: DVec3, offset: Vec3) -> Result<Camera> {
    check_camera(c)?;
    let (from, at) = (
        camera_point("from", c.from, shift, offset)?,
        camera_point("at", c.at, shift, offset)?,
    );
    if from == at && c.from != c.at {
        return Err(Error::invalid(format!(
            "camera: `from` and `at` are {:.2e} apart, too close to tell apart {:.2e} from the \
             models in f32",
            (DVec3::from(c.from) - DVec3::from(c.at)).length(),
            (DVec3::from(c.from) - shift).length()
        )));
    }
    match c.intrinsics {
        None => Camera::look_at(from, at, v3(c.up), c.fov, c.width, c.height, c.spp),
        Some(k) => {
            Camera::look_at_intrinsics(from, at, v3(c.up), k.into(), c.width, c.height, c.spp)
        }
    }
}

/// A scene of one model, `splats` (white and diffuse), seen by `camera`
/// (placed in the splats' coordinates), with no lights and the render
/// options a scene file's defaults give: what a check renders unlit AOVs
/// of.
///
/// # Errors
/// One line when the splats span more than the renderer's f32 geometry
/// holds.
pub fn splats_scene(mut splats: Vec<Splat>, camera: Camera) -> Result<Scene> {
    let standoff = Standoff::of(&splats);
    let (standoff, (offset, diagonal)) =
        rayon::join(|| standoff.measure(), || recentre(&mut splats, &mut []));
    if !diagonal.is_finite() || diagonal > MAX_EXTENT {
        return Err(Error::invalid(format!(
            "the splats span {diagonal:e}, beyond the {MAX_EXTENT:e} the renderer's f32 geometry holds"
        )));
    }
    let mut camera = camera;
    camera.origin -= offset;
    let (options, xi_of) = render_options(&RenderSpec::default(), diagonal, &[standoff])?;
    Ok(Scene {
        material_of: vec![0; splats.len()],
        color_fields: Vec::new(),
        splats,
        triangles: Triangles::default(),
        materials: vec![Material::Diffuse { color: Vec3::ONE }],
        shading_of: vec![None],
        xi_of,
        camera,
        lights: Vec::new(),
        background: Vec3::ZERO,
        options,
        offset,
        shift: DVec3::ZERO,
        load: LoadReport::default(),
    })
}

/// A camera point (f64, in the file) shifted and re-centred into the f32
/// frame of the splats; an error if f32 cannot hold it.
fn camera_point(key: &str, p: [f64; 3], shift: DVec3, offset: Vec3) -> Result<Vec3> {
    let q = DVec3::from(p) - shift - offset.as_dvec3();
    if q.abs().max_element() > f64::from(MAX_EXTENT) {
        return Err(Error::invalid(format!(
            "camera: `{key}` lies {:.2e} from the models, beyond the {MAX_EXTENT:e} the renderer's \
             f32 geometry holds",
            q.length()
        )));
    }
    Ok(q.as_vec3())
}

/// The camera's resolution, samples and position are in range.
fn check_camera(c: &CameraSpec) -> Result<()> {
    if c.width == 0 || c.height == 0 {
        return Err(Error::invalid(format!(
            "camera resolution {}x{} must be positive",
            c.width, c.height
        )));
    }
    if c.width > 1 << 15 || c.height > 1 << 15 {
        return Err(Error::invalid(format!(
            "camera resolution {}x{} is over 32768",
            c.width, c.height
        )));
    }
    if c.spp == 0 || c.spp > 4096 {
        return Err(Error::invalid(format!(
            "camera.spp {} must be in 1..=4096",
            c.spp
        )));
    }
    finite("camera.from", &c.from.map(|x| x as f32))?;
    finite("camera.at", &c.at.map(|x| x as f32))
}

/// Every model's splats (transformed, shifted, not yet re-centred) with
/// their materials, the shift, and what loading measured.
struct Models {
    splats: Vec<Splat>,
    /// The triangle models' faces, placed.
    triangles: Triangles,
    /// One per splat when a model carries colour fields (zero for the
    /// others), else empty.
    color_fields: Vec<ColorField>,
    shift: DVec3,
    material_of: Vec<u16>,
    materials: Vec<Material>,
    shading_of: Vec<Option<ShadingMode>>,
    /// What each model's splat standoff is measured from
    /// (`splat::standoff`).
    standoff: Vec<Standoff>,
    /// The diagonal of the placed splats' centres, in f64 (for a message
    /// when f32 cannot hold it).
    span: f64,
    load: LoadReport,
}

/// Loads every model in order; model `i` gets material `i`. The shift is
/// where the first model's origin lands.
fn load_models(
    specs: &[ModelSpec],
    base: &Path,
    read: &mut Vec<(PathBuf, CloudRead)>,
    progress: Option<Progress<'_>>,
    max_bytes: Option<u64>,
) -> Result<Models> {
    let start = std::time::Instant::now();
    let mut shift = None;
    let mut out = Models {
        splats: Vec::new(),
        triangles: Triangles::default(),
        color_fields: Vec::new(),
        shift: DVec3::ZERO,
        material_of: Vec::new(),
        materials: Vec::new(),
        shading_of: Vec::new(),
        standoff: Vec::new(),
        span: 0.0,
        load: LoadReport::default(),
    };
    let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for (i, m) in specs.iter().enumerate() {
        let number = i + 1;
        let in_model = |e: Error| e.context(format_args!("model {number}"));
        let mid = u16::try_from(i).map_err(|_| Error::invalid("more than 65535 models"))?;
        // What the cap leaves once the triangles of the models before it are held.
        let left = max_bytes.map(|b| {
            b.saturating_sub(
                (out.triangles.tris.len() as u64).saturating_mul(crate::io::BYTES_PER_TRIANGLE),
            )
        });
        let mut src =
            model_source(m, base, read, &mut out.load, progress, left).map_err(in_model)?;
        if !(m.transform.scale > 0.0 && m.transform.scale.is_finite()) {
            return Err(in_model(Error::invalid(format!(
                "transform.scale must be positive, got {}",
                m.transform.scale
            ))));
        }
        let shift = *shift.get_or_insert_with(|| m.transform.world_of(src.origin));
        out.load
            .truth
            .push(truth_of(src.truth, m, number, mid, shift));
        if let Some(tm) = src.tris.take() {
            let placed = place_triangles(&tm, m, shift, mid, &mut out.triangles)
                .map_err(in_model)?;
            lo = lo.min(placed.0);
            hi = hi.max(placed.1);
        }
        let s = &mut src.splats;
        m.transform.apply(s, src.origin, shift);
        // The span is for a message: its length is the same whichever
        // zero (+0 or -0) a tie leaves in the box.
        let (l, h) = s
            .par_iter()
            .map(|sp| {
                let (c, r) = (sp.center.as_dvec3(), f64::from(sp.radii.max_element()));
                (c - r, c + r)
            })
            .reduce(
                || (DVec3::INFINITY, DVec3::NEG_INFINITY),
                |(a, b), (c, d)| (a.min(c), b.max(d)),
            );
        (lo, hi) = (lo.min(l), hi.max(h));
        if let Some(bad) = s.par_iter().position_first(|sp| !placed_ok(sp)) {
            return Err(in_model(Error::invalid(format!(
                "splat {} is not finite once placed (transform.scale {}, translate {:?}): \
                 beyond what the renderer's f32 geometry holds",
                bad + 1,
                m.transform.scale,
                m.transform.translate
            ))));
        }
        out.standoff.push(Standoff::of(s));
        out.materials.push(material(&m.material).map_err(in_model)?);
        out.shading_of.push(m.material.shading);
        out.material_of.extend(std::iter::repeat_n(mid, s.len()));
        if !src.color_fields.is_empty() || !out.color_fields.is_empty() {
            // Aligned with the splats: zero fields for the models without.
            out.color_fields.resize(out.splats.len(), ColorField::ZERO);
            if src.color_fields.is_empty() {
                out.color_fields
                    .resize(out.splats.len() + s.len(), ColorField::ZERO);
            } else {
                out.color_fields.append(&mut src.color_fields);
            }
        }
        if out.splats.is_empty() {
            // The first model's splats kept where they are (not copied).
            std::mem::swap(&mut out.splats, s);
        } else {
            out.splats.append(s);
        }
    }
    out.shift = shift.unwrap_or(DVec3::ZERO);
    out.span = if lo.x <= hi.x {
        (hi - lo).length()
    } else {
        0.0
    };
    out.load.splat_seconds = start.elapsed().as_secs_f64();
    Ok(out)
}

/// One model's splats in model space, before its transform: centres are
/// offsets from `origin` (a point cloud's or splat file's origin; zero for
/// meshes and shapes).
struct Source<'a> {
    splats: Vec<Splat>,
    /// A `triangles` model's mesh, in model space (its splats are none).
    tris: Option<TriangleMesh>,
    /// The splats' colour fields, or empty (constant colours).
    color_fields: Vec<ColorField>,
    origin: DVec3,
    truth: PendingTruth<'a>,
}

/// The exact surface behind a model, before it is placed.
enum PendingTruth<'a> {
    /// The model's procedural shape.
    Shape(&'a ShapeSpec),
    /// The sampled mesh, in model space.
    Mesh(Mesh),
    /// None known: what the model was made from.
    Unknown(&'static str),
}

/// The exact surface of model `number` (material `material`), placed by its
/// transform and shifted.
fn truth_of(
    pending: PendingTruth<'_>,
    spec: &ModelSpec,
    number: usize,
    material: u16,
    shift: DVec3,
) -> TruthSource {
    match pending {
        PendingTruth::Shape(shape) => shape_truth(shape, &spec.transform, material, shift),
        PendingTruth::Mesh(mesh) => TruthSource::Mesh {
            mesh: Mesh {
                positions: mesh
                    .positions
                    .iter()
                    .map(|&p| spec.transform.point_from(mesh.origin, p, shift))
                    .collect(),
                triangles: mesh.triangles,
                origin: DVec3::ZERO,
            },
            material,
        },
        PendingTruth::Unknown(what) => TruthSource::Unknown {
            model: number,
            what: what.into(),
        },
    }
}

/// Splats of one model in model space, before its transform, and the exact
/// surface behind it (placed later, by [`truth_of`]).
fn model_source<'a>(
    spec: &'a ModelSpec,
    base: &Path,
    read: &mut Vec<(PathBuf, CloudRead)>,
    load: &mut LoadReport,
    progress: Option<Progress<'_>>,
    max_bytes: Option<u64>,
) -> Result<Source<'a>> {
    let sources = [
        spec.points.is_some(),
        spec.splats.is_some(),
        spec.gaussians.is_some(),
        spec.mesh.is_some(),
        spec.shape.is_some(),
        spec.triangles.is_some(),
    ];
    if sources.iter().filter(|&&b| b).count() != 1 {
        return Err(Error::invalid(
            "a model needs exactly one of `points`, `splats`, `gaussians`, `mesh`, `triangles` or \
             `shape`",
        ));
    }
    if spec.truth.is_some()
        && (spec.mesh.is_some() || spec.shape.is_some() || spec.triangles.is_some())
    {
        return Err(Error::invalid(
            "`truth` applies to `points`, `splats` and `gaussians` models: a mesh or shape is its own truth",
        ));
    }
    let given_truth = |what: &'static str| -> Result<PendingTruth<'a>> {
        match &spec.truth {
            Some(t) => Ok(PendingTruth::Mesh(crate::io::read_mesh(&base.join(t))?)),
            None => Ok(PendingTruth::Unknown(what)),
        }
    };
    if spec.min_opacity.is_some() && spec.gaussians.is_none() {
        return Err(Error::invalid(
            "`min_opacity` applies to `gaussians` models only",
        ));
    }
    if spec.smooth && spec.triangles.is_none() {
        return Err(Error::invalid("`smooth` applies to `triangles` models only"));
    }
    if let Some(p) = &spec.triangles {
        if spec.samples.is_some() || spec.scan.is_some() {
            return Err(Error::invalid(
                "`samples` and `scan` apply to `mesh` models only: a `triangles` model is rendered \
                 as its triangles",
            ));
        }
        let tm = crate::io::read_triangles_within(&base.join(p), max_bytes)?;
        return Ok(Source {
            splats: Vec::new(),
            color_fields: Vec::new(),
            origin: tm.mesh.origin,
            truth: PendingTruth::Mesh(tm.mesh.clone()),
            tris: Some(tm),
        });
    }
    if let Some(shape) = &spec.shape {
        return Ok(Source {
            tris: None,
            splats: shape_splats(shape)?,
            color_fields: Vec::new(),
            origin: DVec3::ZERO,
            truth: PendingTruth::Shape(shape),
        });
    }
    if let Some(p) = &spec.splats {
        let path = base.join(p);
        let set = match take_read(read, &path) {
            Some(CloudRead::Splats(set)) => set,
            _ => crate::io::read_splats(&path)?,
        };
        return Ok(Source {
            tris: None,
            splats: set.splats,
            color_fields: set.color_fields,
            origin: set.origin,
            truth: given_truth("a splat file")?,
        });
    }
    if let Some(p) = &spec.gaussians {
        let path = base.join(p);
        let min_opacity = spec.min_opacity.unwrap_or(crate::io::MIN_OPACITY);
        let gaussians = match take_read(read, &path) {
            Some(CloudRead::Gaussians(g)) if min_opacity == crate::io::MIN_OPACITY => g,
            _ => crate::io::read_gaussians(&path, min_opacity)?,
        };
        load.warnings.extend(gaussians.warnings());
        return Ok(Source {
            tris: None,
            splats: gaussians.set.splats,
            color_fields: Vec::new(),
            origin: gaussians.set.origin,
            truth: given_truth("a Gaussian splat file")?,
        });
    }
    if let Some(p) = &spec.points {
        if spec.samples.is_some() || spec.scan.is_some() {
            return Err(Error::invalid(
                "`samples` and `scan` apply to `mesh` models only",
            ));
        }
        let path = base.join(p);
        let cloud = match take_read(read, &path) {
            Some(CloudRead::Points(cloud)) => cloud,
            _ => crate::io::read_points(&path)?,
        };
        let (splats, color_fields) = generate_splats(spec, &cloud, load, progress)?;
        return Ok(Source {
            splats,
            tris: None,
            color_fields,
            origin: cloud.origin,
            truth: given_truth("a point file")?,
        });
    }
    let Some(p) = &spec.mesh else {
        unreachable!("exactly one source is set")
    };
    let (cloud, mesh) = sample_mesh_model(spec, &base.join(p))?;
    let (splats, color_fields) = generate_splats(spec, &cloud, load, progress)?;
    Ok(Source {
        splats,
        tris: None,
        color_fields,
        origin: cloud.origin,
        truth: PendingTruth::Mesh(mesh),
    })
}

/// What was read of `path` already, taken out of `read` (once): `None`
/// when `read` holds no such file or it was taken.
fn take_read(read: &mut Vec<(PathBuf, CloudRead)>, path: &Path) -> Option<CloudRead> {
    let at = read.iter().position(|(p, _)| p == path)?;
    Some(read.swap_remove(at).1)
}

/// A mesh model's points (sampled by area, or scanned, with the model's
/// seed) and the mesh itself, in model space.
fn sample_mesh_model(spec: &ModelSpec, path: &Path) -> Result<(PointCloud, Mesh)> {
    if let Some(scan) = &spec.scan {
        if spec.samples.is_some() {
            return Err(Error::invalid(format!(
                "{}: a mesh model takes `samples` or `scan`, not both",
                path.display()
            )));
        }
        if scan.range_noise.is_some() && scan.range_noise_spacing.is_some() {
            return Err(Error::invalid(
                "scan: give `range_noise` or `range_noise_spacing`, not both",
            ));
        }
        let [columns, rows] = scan.rays.unwrap_or([640, 480]);
        let params = crate::scanner::ScanParams {
            at: scan.at.map(|a| Vec3::from(a).as_dvec3()),
            columns,
            rows,
            fov: scan.fov,
            pattern: scan.pattern,
            range_noise: match (scan.range_noise, scan.range_noise_spacing) {
                (_, Some(f)) => crate::scanner::RangeNoise::Spacing(f),
                (s, None) => crate::scanner::RangeNoise::Absolute(s.unwrap_or(0.0)),
            },
            outliers: scan.outliers,
            missing: scan.missing,
            seed: spec.seed,
            tracer: scan.tracer,
            ..crate::scanner::ScanParams::default()
        };
        let stations: Vec<DVec3> = scan
            .from
            .iter()
            .map(|&p| Vec3::from(p).as_dvec3())
            .collect();
        let mesh = crate::io::read_mesh(path)?;
        let cloud = crate::scanner::scan_stations(&mesh, &params, &stations)
            .map_err(|e| e.context(path.display()))?;
        return Ok((cloud, mesh));
    }
    let samples = spec.samples.ok_or_else(|| {
        Error::invalid(format!(
            "{}: a mesh model needs `samples` or `scan`",
            path.display()
        ))
    })?;
    if samples == 0 || samples > 50_000_000 {
        return Err(Error::invalid(format!(
            "samples {samples} must be in 1..=50000000"
        )));
    }
    let mesh = crate::io::read_mesh(path)?;
    let cloud = crate::io::sample_mesh(&mesh, samples, 0.0, spec.seed);
    Ok((cloud, mesh))
}

/// Splat generation (§2, §4.1–4.2) of a point or mesh model with its
/// `splat` parameters; what it reports is added to `load`.
fn generate_splats(
    spec: &ModelSpec,
    cloud: &PointCloud,
    load: &mut LoadReport,
    progress: Option<Progress<'_>>,
) -> Result<(Vec<Splat>, Vec<ColorField>)> {
    let params = crate::splat::GenerationOptions {
        epsilon_rel: spec.splat.epsilon_rel,
        k: spec.splat.k,
        density: spec.splat.density,
        ellipses: spec.splat.ellipses,
        flat_colors: spec.splat.color_fields == Some(false),
        creases: spec.splat.creases,
        viewpoint: spec.splat.viewpoint.map(|v| Vec3::from(v).as_dvec3()),
        no_lean: spec.splat.lean == Some(false),
        ..crate::splat::GenerationOptions::default()
    }
    .params(cloud);
    let crate::pipeline::Generated {
        splats,
        report,
        trim,
        color_fields: fields,
        ..
    } = crate::pipeline::generate(cloud, &params, progress)?;
    if let Some(t) = trim.filter(|t| t.shrunk > 0) {
        load.warnings.push(format!(
            "{} splats shrunk off {} blocked lines of sight from the viewpoint and {} of the \
             scanner's rays that met nothing",
            t.shrunk, t.blocked, t.misses_blocked
        ));
    }
    load.input_points += report.input_points;
    for s in &report.skipped_points {
        load.warnings
            .push(format!("{} points skipped: {}", s.count, s.reason));
    }
    load.warnings.extend(report.warnings.iter().cloned());
    load.coverage.push(report.coverage);
    Ok((splats, fields))
}

/// The splats of a procedural shape, in model space.
fn shape_splats(shape: &ShapeSpec) -> Result<Vec<Splat>> {
    if shape.splats == 0 {
        return Err(Error::invalid("shape.splats must be at least 1"));
    }
    let center = v3(shape.center);
    finite("shape.center", &shape.center)?;
    match shape.kind {
        ShapeKind::Sphere => {
            let r = required_positive(shape.radius, "a sphere shape", "shape", "radius")?;
            Ok(super::shapes::sphere(center, r, shape.splats))
        }
        ShapeKind::Quad => {
            let size = shape
                .size
                .ok_or_else(|| Error::invalid("a quad shape needs `size`"))?;
            if !(size[0] > 0.0 && size[1] > 0.0 && size[0].is_finite() && size[1].is_finite()) {
                return Err(Error::invalid(format!(
                    "shape.size must be positive, got {size:?}"
                )));
            }
            let normal = v3(shape.normal.unwrap_or([0.0, 1.0, 0.0]))
                .try_normalize()
                .ok_or_else(|| Error::invalid("shape.normal must be non-zero"))?;
            Ok(super::shapes::quad(
                center,
                normal,
                Vec2::from(size),
                shape.splats,
            ))
        }
    }
}

/// The exact surface of a shape placed by `t` (world space, shifted): the
/// analytic sphere, or the quad's two triangles.
fn shape_truth(sh: &ShapeSpec, t: &TransformSpec, material: u16, shift: DVec3) -> TruthSource {
    match sh.kind {
        ShapeKind::Sphere => TruthSource::Sphere {
            center: t.point(v3(sh.center), shift),
            radius: sh.radius.unwrap_or(1.0) * t.scale,
            material,
        },
        ShapeKind::Quad => {
            let n = v3(sh.normal.unwrap_or([0.0, 1.0, 0.0]))
                .try_normalize()
                .unwrap_or(Vec3::Y);
            let (a, b) = crate::splat::tangent_frame(n);
            let [sx, sy] = sh.size.unwrap_or([1.0, 1.0]);
            let c = v3(sh.center);
            let corners = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
                .map(|(x, y)| t.point(c + a * (0.5 * sx * x) + b * (0.5 * sy * y), shift));
            TruthSource::Mesh {
                mesh: Mesh {
                    positions: corners.to_vec(),
                    triangles: vec![[0, 1, 2], [0, 2, 3]],
                    origin: DVec3::ZERO,
                },
                material,
            }
        }
    }
}

/// Places a `triangles` model's faces by its transform (positions as
/// [`TransformSpec::point_from`] places a mesh's, normals rotated) with
/// material `material` into `out`; returns the placed vertices' box (f64).
/// A face whose vertex normals face away from its winding's normal is
/// turned to face with them. A mesh without normals gets area-weighted
/// vertex normals of its placed vertices when `spec.smooth` asks.
///
/// # Errors
/// A triangle that is no longer finite or spans no area once placed in f32
/// (a scale or translate beyond what it holds), naming the triangle.
fn place_triangles(
    tm: &TriangleMesh,
    spec: &ModelSpec,
    shift: DVec3,
    material: u16,
    out: &mut Triangles,
) -> Result<(DVec3, DVec3)> {
    let t = &spec.transform;
    let rot = t.rotation();
    let m = &tm.mesh;
    let placed: Vec<Vec3> = m
        .positions
        .iter()
        .map(|&p| t.point_from(m.origin, p, shift))
        .collect();
    let smooth = (spec.smooth && tm.normals.is_none())
        .then(|| crate::scene::area_weighted_normals(&placed, &m.triangles));
    let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for (k, ix) in m.triangles.iter().enumerate() {
        let tri = Triangle {
            v: ix.map(|i| placed[i as usize]),
        };
        if !tri.is_proper() {
            return Err(Error::invalid(format!(
                "triangle {k} is not finite or spans no area once placed (transform.scale {}, \
                 translate {:?}): beyond what the renderer's f32 geometry holds",
                t.scale, t.translate
            )));
        }
        for v in tri.v {
            lo = lo.min(v.as_dvec3());
            hi = hi.max(v.as_dvec3());
        }
        let mut face = tri.unit_normal();
        let corners = match (&tm.normals, &smooth) {
            (Some(n), _) if n[k][0] != Vec3::ZERO => n[k].map(|c| (rot * c).normalize()),
            (None, Some(vn)) => ix.map(|i| vn[i as usize]),
            _ => [Vec3::ZERO; 3],
        };
        if face.dot(corners[0] + corners[1] + corners[2]) < 0.0 {
            face = -face;
        }
        out.tris.push(tri);
        out.face.push(face);
        out.normals.push(corners);
        out.material_of.push(material);
    }
    Ok((lo, hi))
}

/// A placed splat the renderer can use: finite centre, frame and field,
/// radii finite and above zero.
fn placed_ok(s: &Splat) -> bool {
    s.center.is_finite()
        && s.normal.is_finite()
        && s.u_axis.is_finite()
        && s.v_axis.is_finite()
        && s.radii.is_finite()
        && s.radii.min_element() > 0.0
        && [s.field.xc, s.field.yc, s.field.alpha, s.field.beta]
            .iter()
            .all(|x| x.is_finite())
}

fn v3(a: [f32; 3]) -> Vec3 {
    Vec3::from(a)
}

/// The value of `table.key`, which `what` needs: given, finite and
/// above zero.
fn required_positive(value: Option<f32>, what: &str, table: &str, key: &str) -> Result<f32> {
    let v = value.ok_or_else(|| Error::invalid(format!("{what} needs `{key}`")))?;
    if v > 0.0 && v.is_finite() {
        Ok(v)
    } else {
        Err(Error::invalid(format!(
            "{table}.{key} must be positive, got {v}"
        )))
    }
}

fn finite(name: &str, v: &[f32]) -> Result<()> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(Error::invalid(format!(
            "{name}: values must be finite, got {v:?}"
        )))
    }
}

/// A position given in f64, shifted (in f64) and then made f32.
fn shifted(p: [f64; 3], shift: DVec3) -> Vec3 {
    (DVec3::from(p) - shift).as_vec3()
}

fn material(spec: &MaterialSpec) -> Result<Material> {
    let color = v3(spec.color.unwrap_or([0.8, 0.8, 0.8]));
    finite("material.color", &color.to_array())?;
    Ok(match spec.kind {
        MaterialKind::Diffuse => Material::Diffuse { color },
        MaterialKind::Phong => Material::Phong {
            color,
            specular: spec.specular.unwrap_or(0.4),
            shininess: spec.shininess.unwrap_or(40.0),
        },
        MaterialKind::Mirror => Material::Mirror {
            color: Vec3::splat(spec.reflectance.unwrap_or(0.9)) * spec.color.map_or(Vec3::ONE, v3),
        },
        MaterialKind::Glass => {
            let ior = spec.ior.unwrap_or(1.5);
            if !(ior > 0.0 && ior.is_finite()) {
                return Err(Error::invalid(format!(
                    "material.ior must be positive, got {ior}"
                )));
            }
            Material::Glass {
                color: spec.color.map_or(Vec3::ONE, v3),
                ior,
            }
        }
    })
}

fn light(spec: &LightSpec, shift: DVec3) -> Result<Light> {
    let power = v3(spec.color) * spec.intensity;
    finite("light.color × intensity", &power.to_array())?;
    let position = || {
        let p = spec
            .position
            .ok_or_else(|| Error::invalid(format!("a {} light needs `position`", spec.kind)))?;
        finite("light.position", &p.map(|x| x as f32))?;
        Ok::<Vec3, Error>(shifted(p, shift))
    };
    Ok(match spec.kind {
        LightKind::Point => Light::Point {
            position: position()?,
            power,
        },
        LightKind::Directional => Light::Directional {
            direction: spec
                .direction
                .map(v3)
                .ok_or_else(|| Error::invalid("a directional light needs `direction`"))?
                .try_normalize()
                .ok_or_else(|| Error::invalid("light.direction must be non-zero"))?,
            power,
        },
        LightKind::Sphere => {
            let radius = required_positive(spec.radius, "a sphere light", "light", "radius")?;
            Light::Sphere {
                position: position()?,
                radius,
                power,
                samples: spec.samples.unwrap_or(16).max(1),
            }
        }
    })
}

/// Placing a model (`docs/DESIGN.md`, "Precision"): its transform in f64,
/// what lands far from the origin shifted back before it becomes f32.
impl TransformSpec {
    fn rotation(&self) -> Mat3 {
        let [x, y, z] = self.rotate.map(f32::to_radians);
        Mat3::from_rotation_z(z) * Mat3::from_rotation_y(y) * Mat3::from_rotation_x(x)
    }

    fn rotation_f64(&self) -> DMat3 {
        let [x, y, z] = self.rotate.map(|a| f64::from(a).to_radians());
        DMat3::from_rotation_z(z) * DMat3::from_rotation_y(y) * DMat3::from_rotation_x(x)
    }

    /// Where the model-space point `p` lands, all in f64 (a far point
    /// cloud's origin, see [`crate::splat::PointCloud::origin`]).
    #[must_use]
    pub fn world_of(&self, p: DVec3) -> DVec3 {
        self.rotation_f64() * (p * f64::from(self.scale)) + DVec3::from(self.translate)
    }

    /// Applies the transform to a point, then subtracts `shift`; the
    /// translation and the shift are applied in f64, so a model placed far
    /// from the origin and shifted back keeps f32 precision (`docs/DESIGN.md`, "Precision").
    #[must_use]
    pub fn point(&self, p: Vec3, shift: DVec3) -> Vec3 {
        self.point_from(DVec3::ZERO, p, shift)
    }

    /// [`TransformSpec::point`] for the model-space point `origin + p`: the
    /// origin is placed and shifted in f64 before the small offset `p` is
    /// added, so a cloud far from zero lands where it is with the precision
    /// of its size.
    #[must_use]
    pub fn point_from(&self, origin: DVec3, p: Vec3, shift: DVec3) -> Vec3 {
        self.point_at(self.world_of(origin) - shift, self.rotation(), p)
    }

    /// `base + R (s p)`, the f32 part rotated in f32 and added in f64.
    fn point_at(&self, base: DVec3, rot: Mat3, p: Vec3) -> Vec3 {
        ((rot * (p * self.scale)).as_dvec3() + base).as_vec3()
    }

    /// Applies the transform to every splat, whose centres are offsets from
    /// the model-space point `origin`, then subtracts `shift` (in f64, as
    /// [`TransformSpec::point_from`]).
    pub fn apply(&self, splats: &mut [Splat], origin: DVec3, shift: DVec3) {
        let rot = self.rotation();
        let base = self.world_of(origin) - shift;
        splats.par_iter_mut().for_each(|s| {
            s.center = self.point_at(base, rot, s.center);
            s.normal = (rot * s.normal).normalize();
            s.u_axis = (rot * s.u_axis).normalize();
            s.v_axis = (rot * s.v_axis).normalize();
            s.radii *= self.scale;
        });
    }
}

/// Re-centres the splats and triangles on their bounding box
/// (`docs/DESIGN.md`, "Precision": far-from-origin scenes keep their
/// precision); returns the offset subtracted and the box's diagonal (1
/// without either).
fn recentre(splats: &mut [Splat], tris: &mut [Triangle]) -> (Vec3, f32) {
    let (lo, hi) = splats.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), s| {
            let h = s.half_extent();
            (lo.min(s.center - h), hi.max(s.center + h))
        },
    );
    let (lo, hi) = tris
        .iter()
        .flat_map(|t| t.v)
        .fold((lo, hi), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let (offset, diagonal) = if lo.x <= hi.x {
        ((lo + hi) * 0.5, (hi - lo).length().max(f32::MIN_POSITIVE))
    } else {
        (Vec3::ZERO, 1.0)
    };
    splats.par_iter_mut().for_each(|s| s.center -= offset);
    for t in tris {
        t.v = t.v.map(|v| v - offset);
    }
    (offset, diagonal)
}

/// A light moved by the re-centring `offset` (directional lights have no
/// position).
fn moved(l: Light, offset: Vec3) -> Light {
    match l {
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
    }
}

/// `[render]` resolved, with each model's blending window: `eps_self`
/// (§3.2) is a fraction of the scene diagonal; each model's `xi` (§4.3) is
/// [`XI_STANDOFFS`] times its splats' standoff
/// ([`crate::splat::standoff::standoff`]), at least `eps_self`, unless
/// `render.xi` sets one for every model as a fraction of the diagonal. The
/// scale's `xi`, the window the backends gather, is the widest.
fn render_options(
    r: &RenderSpec,
    diagonal: f32,
    standoff: &[f32],
) -> Result<(RenderOptions, Vec<f32>)> {
    let mut scale = SceneScale::from_diagonal(diagonal);
    if let Some(e) = r.eps_self {
        if !(e >= 0.0 && e.is_finite()) {
            return Err(Error::invalid(format!(
                "render.eps_self must be >= 0, got {e}"
            )));
        }
        scale.eps_self = e * diagonal;
    }
    let xi_of: Vec<f32> = match r.xi {
        Some(xi) if !(xi >= 0.0 && xi.is_finite()) => {
            return Err(Error::invalid(format!("render.xi must be >= 0, got {xi}")));
        }
        Some(xi) => vec![xi * diagonal; standoff.len()],
        None => standoff
            .iter()
            .map(|s| (XI_STANDOFFS * s).max(scale.eps_self))
            .collect(),
    };
    scale.xi = xi_of.iter().copied().fold(0.0, f32::max);
    let options = RenderOptions {
        max_depth: r.max_depth.unwrap_or(5),
        shading: r.shading.unwrap_or(ShadingMode::Phong),
        scale,
        ambient: r.ambient.unwrap_or(0.03),
    };
    Ok((options, xi_of))
}

/// A model's blending window `xi` in standoffs of its splats: the
/// neighbours a ray meets together lie about one standoff apart along the
/// normal, three times that along a ray 70° off the normal. Measured with
/// `splatray compare --truth` (PSNR against the exact surfaces, mean normal
/// error) over the bundled scenes: 1, 2, 3, 4 and 8 standoffs give on
/// `scenes/shading.toml` 32.19, 32.27, 32.34, 32.38, 32.42 dB (2.61°,
/// 2.55°, 2.54°, 2.54°, 2.54°) and on `scenes/bunny.toml` 31.23, 31.27,
/// 31.28, 31.26, 31.25 dB (0.971°, 0.945°, 0.949°, 0.952°, 0.969°); the
/// other scenes move by 0.04 dB at most.
pub const XI_STANDOFFS: f32 = 3.0;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::parse_scene_str;
    use std::sync::atomic::{AtomicUsize, Ordering};

    #[test]
    fn every_model_yields_one_truth_with_its_material() {
        let text = "[camera]\nfrom = [0.0, 0.0, 3.0]\nat = [0.0, 0.0, 0.0]\n\
            [[model]]\nshape = { kind = \"sphere\", radius = 1.0, splats = 50 }\n\
            [[model]]\nmesh = \"data/bunny-mesh.ply\"\nsamples = 2000\n\
            [[model]]\nshape = { kind = \"quad\", size = [1.0, 1.0], splats = 20 }\n";
        let base = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
        let calls = AtomicUsize::new(0);
        let progress = |_: &str, f: f64| {
            assert!((0.0..=1.0).contains(&f));
            calls.fetch_add(1, Ordering::Relaxed);
        };
        let s = build_scene(&parse_scene_str(text).unwrap(), &base, Some(&progress)).unwrap();
        assert!(
            calls.load(Ordering::Relaxed) > 0,
            "splat generation reports"
        );
        let materials: Vec<(&str, u16)> = s
            .load
            .truth
            .iter()
            .map(|t| match t {
                TruthSource::Sphere { material, .. } => ("sphere", *material),
                TruthSource::Mesh { material, .. } => ("mesh", *material),
                TruthSource::Unknown { .. } => ("unknown", u16::MAX),
            })
            .collect();
        assert_eq!(materials, [("sphere", 0), ("mesh", 1), ("mesh", 2)]);
    }

    /// Shadow rays get the pass-over rule only in scenes with Phong
    /// splats: a scene whose materials all shade flat has none.
    #[test]
    fn phong_splats_are_known_per_scene() {
        let base = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
        let scene = |shading: &str| {
            let text = format!(
                "[camera]\nfrom = [0.0, 0.0, 3.0]\nat = [0.0, 0.0, 0.0]\n\
                 [[model]]\nshape = {{ kind = \"sphere\", radius = 1.0, splats = 50 }}\n\
                 material = {{ kind = \"phong\", color = [0.5, 0.5, 0.5]{shading} }}\n\
                 [[model]]\nshape = {{ kind = \"quad\", size = [1.0, 1.0], splats = 20 }}\n\
                 material = {{ kind = \"diffuse\", color = [0.5, 0.5, 0.5], shading = \"flat\" }}\n"
            );
            build_scene(&parse_scene_str(&text).unwrap(), &base, None).unwrap()
        };
        assert!(scene("").has_phong());
        assert!(!scene(", shading = \"flat\"").has_phong());
    }
}
