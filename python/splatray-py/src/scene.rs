//! `Scene` (from a TOML file, or built in Python with models from `Splats`
//! and `PointCloud` objects), its renders (`Image`), and `read_image`.

use crate::arrays::{image, matrix, plane};
use crate::cast::SplatScene;
use crate::err;
use crate::progress::Callback;
use crate::splats::{PointCloud, Splats};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList};
use splatray::io::CloudRead;
use splatray::render::integrator::Frame;
use splatray::render::output::Aov;
use splatray::resolve::ShadingMode;
use splatray::scene::SceneFile;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// An input a model takes from Python instead of a file.
#[derive(Clone)]
enum Input {
    Splats(splatray::io::SplatSet),
    Points(splatray::splat::PointCloud),
}

/// A scene: camera, lights, materials and models, as a scene file states
/// them; loaded (splats generated, re-centred) on first use and kept.
#[pyclass(module = "splatray", frozen)]
pub struct Scene {
    file: SceneFile,
    base: PathBuf,
    inputs: Vec<(PathBuf, Input)>,
    loaded: Mutex<Option<splatray::scene::Scene>>,
}

impl Scene {
    /// The loaded scene (loading it the first time), with the view
    /// overrides applied to a copy.
    fn view(
        &self,
        py: Python<'_>,
        width: Option<u32>,
        height: Option<u32>,
        spp: Option<u32>,
        shading: Option<&str>,
        cb: &Callback,
    ) -> PyResult<splatray::scene::Scene> {
        let shading = match shading {
            None => None,
            Some(s) => Some(splatray::names::parse::<ShadingMode>(s).map_err(|_| {
                PyValueError::new_err(format!("shading {s:?}: expected flat, blended or phong"))
            })?),
        };
        py.detach(|| {
            let mut loaded = self
                .loaded
                .lock()
                .map_err(|_| splatray::Error::invalid("scene lock poisoned"))?;
            if loaded.is_none() {
                let reads = self
                    .inputs
                    .iter()
                    .map(|(p, i)| {
                        let r = match i {
                            Input::Splats(s) => CloudRead::Splats(s.clone()),
                            Input::Points(c) => CloudRead::Points(c.clone()),
                        };
                        (p.clone(), r)
                    })
                    .collect();
                let report = |s: &str, f: f64| cb.report(s, f);
                *loaded = Some(splatray::scene::build_scene_reads(
                    &self.file,
                    &self.base,
                    reads,
                    Some(&report),
                )?);
            }
            let mut scene = loaded.as_ref().expect("loaded above").clone();
            scene.set_view(width, height, spp, shading)?;
            Ok::<_, splatray::Error>(scene)
        })
        .map_err(err)
    }
}

/// `value` with the `Splats` or `PointCloud` of key `key` replaced by a
/// placeholder path, recorded in `inputs`.
fn take_input(
    model: &Bound<'_, PyDict>,
    key: &str,
    inputs: &mut Vec<(PathBuf, Input)>,
) -> PyResult<()> {
    let Some(v) = model.get_item(key)? else {
        return Ok(());
    };
    let input = if let Ok(s) = v.cast::<Splats>() {
        Input::Splats(s.get().set.clone())
    } else if let Ok(c) = v.cast::<PointCloud>() {
        Input::Points(c.get().cloud.clone())
    } else {
        return Ok(());
    };
    match (&input, key) {
        (Input::Splats(_), "splats") | (Input::Points(_), "points") => {}
        _ => {
            return Err(PyValueError::new_err(format!(
                "model {key}: give Splats as `splats` and a PointCloud as `points`"
            )));
        }
    }
    let path = PathBuf::from(format!("<python input {}>", inputs.len()));
    model.set_item(key, path.to_string_lossy().as_ref())?;
    inputs.push((path, input));
    Ok(())
}

#[pymethods]
impl Scene {
    /// A scene built in Python: `camera` as a scene file's `[camera]`
    /// (`from`, `at`, `up`, `fov`, `width`, `height`, `spp`), `models` a
    /// list of `[[model]]` dicts whose `splats` may be a `Splats` and
    /// `points` a `PointCloud` (or paths), with `material`, `transform`,
    /// `splat`; `lights` a list of `[[light]]` dicts; `render` the
    /// `[render]` table; `background` linear RGB.
    #[new]
    #[pyo3(signature = (camera, models, lights=None, render=None, background=None))]
    fn new(
        py: Python<'_>,
        camera: &Bound<'_, PyDict>,
        models: &Bound<'_, PyList>,
        lights: Option<&Bound<'_, PyList>>,
        render: Option<&Bound<'_, PyDict>>,
        background: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Scene> {
        let spec = PyDict::new(py);
        spec.set_item("camera", camera)?;
        let mut inputs = Vec::new();
        let list = PyList::empty(py);
        for m in models.iter() {
            let m = m
                .cast::<PyDict>()
                .map_err(|_| PyValueError::new_err("models must be a list of dicts"))?
                .copy()?;
            take_input(&m, "splats", &mut inputs)?;
            take_input(&m, "points", &mut inputs)?;
            list.append(m)?;
        }
        spec.set_item("model", list)?;
        if let Some(l) = lights {
            spec.set_item("light", l)?;
        }
        if let Some(r) = render {
            spec.set_item("render", r)?;
        }
        if let Some(b) = background {
            let b: Vec<f64> = b.extract()?;
            spec.set_item("background", b)?;
        }
        let text: String = py
            .import("json")?
            .call_method1("dumps", (spec,))?
            .extract()?;
        let file: SceneFile =
            serde_json::from_str(&text).map_err(|e| err(format!("scene: {e}")))?;
        Ok(Scene {
            file,
            base: PathBuf::new(),
            inputs,
            loaded: Mutex::new(None),
        })
    }

    /// A scene file (TOML); relative model paths are the file's folder's.
    #[staticmethod]
    fn from_toml(path: PathBuf) -> PyResult<Scene> {
        let file = splatray::scene::parse_scene_file(&path).map_err(err)?;
        Ok(Scene {
            file,
            base: path.parent().unwrap_or(Path::new(".")).to_path_buf(),
            inputs: Vec::new(),
            loaded: Mutex::new(None),
        })
    }

    fn __repr__(&self) -> String {
        let c = &self.file.camera;
        format!(
            "Scene({} models, {} lights, {}x{} spp {})",
            self.file.models.len(),
            self.file.lights.len(),
            c.width,
            c.height,
            c.spp
        )
    }

    /// Renders the camera's view with `backend` (`splatray.BACKENDS`),
    /// `width`, `height`, `spp` and `shading` overriding the scene's; the
    /// image is linear RGB, with the AOVs named in `aov` (depth, normal,
    /// splat, albedo) of the first sample of each pixel.
    #[pyo3(signature = (backend=None, width=None, height=None, spp=None, shading=None, aov=None, progress=None))]
    #[allow(clippy::too_many_arguments)]
    fn render(
        &self,
        py: Python<'_>,
        backend: Option<&str>,
        width: Option<u32>,
        height: Option<u32>,
        spp: Option<u32>,
        shading: Option<&str>,
        aov: Option<Vec<String>>,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<Image> {
        let aovs = aov
            .unwrap_or_default()
            .iter()
            .map(|a| {
                splatray::names::parse::<Aov>(a).map_err(|e| PyValueError::new_err(e.to_string()))
            })
            .collect::<PyResult<Vec<_>>>()?;
        let cb = Callback::new(progress);
        let scene = self.view(py, width, height, spp, shading, &cb);
        let scene = match scene {
            Ok(s) => s,
            Err(e) => {
                cb.finish()?;
                return Err(e);
            }
        };
        let backend = backend.unwrap_or(splatray::accel::registry::names()[0]);
        let out = py.detach(|| {
            let info = splatray::accel::registry::lookup(backend)?;
            let built = info.build_scene(&scene)?;
            let report = |s: &str, f: f64| cb.report(s, f);
            let frame = splatray::render::integrator::render(&scene, built.as_ref(), Some(&report));
            let build_seconds = built.stats().build_seconds;
            Ok::<_, splatray::Error>((frame, info.name, build_seconds))
        });
        cb.finish()?;
        let (frame, name, build_seconds) = out.map_err(err)?;
        Ok(Image {
            frame,
            aovs,
            backend: name,
            build_seconds,
        })
    }

    /// Renders the view with every renderer backend of the registry in one
    /// run (`rounds` renders each, in turns) and returns the report of
    /// `splatray compare` as a dict: each backend's speed and memory and
    /// its agreement with the first ray for ray; with `truth`, each one's
    /// errors against the exact surfaces.
    #[pyo3(signature = (rounds=1, truth=false, width=None, height=None, spp=None, progress=None))]
    #[allow(clippy::too_many_arguments)]
    fn compare<'py>(
        &self,
        py: Python<'py>,
        rounds: u32,
        truth: bool,
        width: Option<u32>,
        height: Option<u32>,
        spp: Option<u32>,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        if rounds == 0 {
            return Err(PyValueError::new_err("rounds must be at least 1"));
        }
        let cb = Callback::new(progress);
        let scene = match self.view(py, width, height, spp, None, &cb) {
            Ok(s) => s,
            Err(e) => {
                cb.finish()?;
                return Err(e);
            }
        };
        let out = py.detach(|| {
            let report = |s: &str, f: f64| cb.report(s, f);
            let options = splatray::workflow::compare::CompareOptions { rounds, truth };
            splatray::workflow::compare::compare(&scene, "python", &options, Some(&report))
                .and_then(|c| serde_json::to_string(&c.report).map_err(splatray::Error::other))
        });
        cb.finish()?;
        let text = out.map_err(err)?;
        py.import("json")?.call_method1("loads", (text,))
    }

    /// The camera's rays through the pixel centres ((H·W, 6) float64, row
    /// by row from the top; origin and direction, not unit: the direction
    /// the camera normalises), in the models' coordinates (the first
    /// model's origin placed by its transform): what `SplatScene.cast_rays`
    /// of `splat_scene()` takes.
    #[pyo3(signature = (width=None, height=None))]
    fn camera_rays<'py>(
        &self,
        py: Python<'py>,
        width: Option<u32>,
        height: Option<u32>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let cb = Callback::new(None);
        let scene = self.view(py, width, height, None, None, &cb)?;
        let c = scene.camera;
        let to_world = scene.offset.as_dvec3() + scene.shift;
        let mut flat = Vec::with_capacity(c.width as usize * c.height as usize * 6);
        for y in 0..c.height {
            for x in 0..c.width {
                let (px, py_) = (x as f32 + 0.5, y as f32 + 0.5);
                // As `Camera::ray` computes it, before normalising.
                let (sx, sy) = match c.principal {
                    None => (
                        2.0 * px / c.width as f32 - 1.0,
                        1.0 - 2.0 * py_ / c.height as f32,
                    ),
                    Some(p) => (
                        (px - p.x) / (0.5 * c.width as f32),
                        (p.y - py_) / (0.5 * c.height as f32),
                    ),
                };
                let d = c.forward + c.right * sx + c.up * sy;
                let o = c.origin.as_dvec3() + to_world;
                flat.extend([
                    o.x,
                    o.y,
                    o.z,
                    f64::from(d.x),
                    f64::from(d.y),
                    f64::from(d.z),
                ]);
            }
        }
        Ok(matrix(py, 6, flat))
    }

    /// The scene's splats and triangles (all models, placed) in `backend`,
    /// for `cast_rays` resolved exactly as this scene's renders resolve
    /// (triangle `i` of the `triangles` models, in their order, is hit id
    /// `first_triangle + i`).
    #[pyo3(signature = (backend=None))]
    fn splat_scene(&self, py: Python<'_>, backend: Option<&str>) -> PyResult<SplatScene> {
        let cb = Callback::new(None);
        let scene = self.view(py, None, None, None, None, &cb)?;
        let backend = backend.unwrap_or(splatray::accel::registry::names()[0]);
        let to_world = scene.offset.as_dvec3() + scene.shift;
        py.detach(|| SplatScene::build(scene, to_world, backend))
            .map_err(err)
    }
}

/// A rendered image: linear RGB and the AOVs, as numpy arrays; shown as an
/// image in a notebook.
#[pyclass(module = "splatray", frozen)]
pub struct Image {
    frame: Frame,
    aovs: Vec<Aov>,
    backend: &'static str,
    build_seconds: f64,
}

fn aov_name(a: Aov) -> &'static str {
    match a {
        Aov::Depth => "depth",
        Aov::Normal => "normal",
        Aov::Splat => "splat",
        Aov::Albedo => "albedo",
    }
}

impl Image {
    fn dims(&self) -> (usize, usize) {
        (self.frame.height as usize, self.frame.width as usize)
    }

    fn aov_array<'py>(&self, py: Python<'py>, a: Aov) -> Bound<'py, PyAny> {
        let (h, w) = self.dims();
        let f = &self.frame;
        let rgb = |v: &[glam::Vec3]| image(py, h, w, v.iter().flat_map(|p| p.to_array()).collect());
        match a {
            Aov::Depth => plane(py, h, w, f.depth.clone()),
            Aov::Splat => plane(py, h, w, f.splat.clone()),
            Aov::Normal => rgb(&f.normal),
            Aov::Albedo => rgb(&f.albedo),
        }
    }
}

#[pymethods]
impl Image {
    /// (H, W, 3) float32 linear RGB radiance.
    #[getter]
    fn rgb<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        let (h, w) = self.dims();
        image(
            py,
            h,
            w,
            self.frame.rgb.iter().flat_map(|p| p.to_array()).collect(),
        )
    }

    /// The AOVs asked for: `depth` (H, W) float32 (inf on a miss), `normal`
    /// and `albedo` (H, W, 3) float32, `splat` (H, W) uint32 ids
    /// (`INVALID_ID` on a miss).
    #[getter]
    fn aov<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for &a in &self.aovs {
            d.set_item(aov_name(a), self.aov_array(py, a))?;
        }
        Ok(d)
    }

    /// Width and height.
    #[getter]
    fn shape(&self) -> (usize, usize) {
        self.dims()
    }

    /// The render's figures: backend, rays by kind, seconds.
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let r = &self.frame.rays;
        let j = serde_json::json!({
            "backend": self.backend,
            "width": self.frame.width,
            "height": self.frame.height,
            "build_seconds": self.build_seconds,
            "render_seconds": self.frame.seconds,
            "rays": r,
            "mrays_per_s": r.total() as f64 / self.frame.seconds.max(1e-9) / 1e6,
        });
        py.import("json")?.call_method1("loads", (j.to_string(),))
    }

    /// Writes the image as `splatray render` does (.png 8-bit sRGB, .exr
    /// linear float), atomically.
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        py.detach(|| splatray::render::output::write_image(&self.frame, &path))
            .map_err(err)
    }

    /// Writes one AOV as `render --aov` does (EXR).
    fn save_aov(&self, py: Python<'_>, name: &str, path: PathBuf) -> PyResult<()> {
        let a = splatray::names::parse::<Aov>(name)
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        py.detach(|| splatray::render::output::write_aov(&self.frame, a, &path))
            .map_err(err)
    }

    /// PNG bytes (8-bit sRGB), for notebooks.
    fn _repr_png_<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        let img = splatray::render::output::to_srgb8(&self.frame);
        let mut bytes = Vec::new();
        img.write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )
        .map_err(err)?;
        Ok(PyBytes::new(py, &bytes))
    }

    fn __repr__(&self) -> String {
        format!(
            "Image({}x{}, {}, aov [{}])",
            self.frame.width,
            self.frame.height,
            self.backend,
            self.aovs
                .iter()
                .map(|a| aov_name(*a))
                .collect::<Vec<_>>()
                .join(", ")
        )
    }
}

/// Reads an image (.exr linear float, .png 8-bit as written, scaled to
/// [0, 1]) as (H, W, 3) float32: e.g. the AOVs of `splatray render --aov`.
#[pyfunction]
pub fn read_image<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyAny>> {
    let img = py
        .detach(|| image::open(&path))
        .map_err(|e| err(format!("{}: {e}", path.display())))?
        .to_rgb32f();
    let (w, h) = (img.width() as usize, img.height() as usize);
    Ok(image(py, h, w, img.into_raw()))
}
