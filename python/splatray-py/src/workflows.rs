//! The command line's checks as functions returning its reports as dicts:
//! `scan_check` (`splatray scan-check`'s JSON report) and `sweep` (the rows
//! of `splatray sweep`, one dict per CSV row, every figure of the row). The
//! library's workflows (`splatray::workflow::{scan_check, sweep}`) do the
//! work with the GIL released; the reports pass through JSON, so a dict
//! holds what the CLI's JSON holds.

use crate::arrays::point3;
use crate::err;
use crate::progress::Callback;
use glam::DVec3;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use splatray::workflow::scan_check::ScanCheckRequest;
use splatray::workflow::splat::GenerationOptions;
use splatray::workflow::sweep::SweepRequest;
use std::path::PathBuf;

/// Runs `work` with the GIL released, reporting to `progress`; the JSON
/// text it returns as Python objects.
fn detached<'py>(
    py: Python<'py>,
    progress: Option<Py<PyAny>>,
    work: impl FnOnce(&(dyn Fn(&str, f64) + Sync)) -> splatray::Result<String> + Send,
) -> PyResult<Bound<'py, PyAny>> {
    let cb = Callback::new(progress);
    let out = py.detach(|| work(&|s: &str, f: f64| cb.report(s, f)));
    cb.finish()?;
    let text = out.map_err(err)?;
    py.import("json")?.call_method1("loads", (text,))
}

/// `splatray scan-check` as a dict: the report `--report` writes. Points
/// are held out, splats grown from the rest and a line of sight cast from
/// the scanner to each held-out point; with `photo`, the photo check of an
/// organised colour capture. The generation options are `splat`'s.
#[pyfunction]
#[pyo3(signature = (path, *, tolerance=0.01, holdout=0.1, seed=1, photo=false, backend=None,
    epsilon=None, k=None, density=None, ellipses=false, flat_colors=false, creases=None,
    viewpoint=None, no_viewpoint=false, thin=None, progress=None))]
#[allow(clippy::too_many_arguments)]
pub fn scan_check<'py>(
    py: Python<'py>,
    path: PathBuf,
    tolerance: f32,
    holdout: f32,
    seed: u64,
    photo: bool,
    backend: Option<String>,
    epsilon: Option<f32>,
    k: Option<usize>,
    density: Option<f32>,
    ellipses: bool,
    flat_colors: bool,
    creases: Option<bool>,
    viewpoint: Option<&Bound<'_, PyAny>>,
    no_viewpoint: bool,
    thin: Option<f64>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    let viewpoint = match viewpoint.filter(|v| !v.is_none()) {
        Some(v) => Some(DVec3::from_array(point3(v, "viewpoint")?)),
        None => None,
    };
    let req = ScanCheckRequest {
        input: path,
        generation: GenerationOptions {
            epsilon_rel: epsilon,
            k,
            density,
            ellipses,
            flat_colors,
            creases,
            viewpoint,
            no_viewpoint,
            thin,
            no_lean: false,
        },
        tolerance,
        holdout,
        seed,
        photo,
        backend: backend.unwrap_or_else(|| splatray::accel::registry::names()[0].to_string()),
    };
    detached(py, progress, |p| {
        let report = splatray::workflow::scan_check::scan_check(&req, Some(p))?;
        serde_json::to_string(&report).map_err(splatray::Error::other)
    })
}

/// `splatray sweep` as a list of dicts, one per (budget step, shading
/// mode): the splat counts, every backend's build and render seconds and
/// errors against the exact surface, and whether the backends agree bit
/// for bit. The scene's generated models are swept from `eps_coarse` to
/// `eps_fine` (fractions of the bounding-box diagonal) in `steps` steps.
#[pyfunction]
#[pyo3(signature = (scene, *, width=320, height=240, steps=6, eps_coarse=0.05, eps_fine=0.0005,
    progress=None))]
#[allow(clippy::too_many_arguments)]
pub fn sweep<'py>(
    py: Python<'py>,
    scene: PathBuf,
    width: u32,
    height: u32,
    steps: usize,
    eps_coarse: f32,
    eps_fine: f32,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    let req = SweepRequest {
        scene,
        width,
        height,
        steps,
        eps_coarse,
        eps_fine,
    };
    // The option checks raise before any work, as ValueError.
    req.check()
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    detached(py, progress, |p| {
        let result = splatray::workflow::sweep::sweep(&req, Some(p), &mut |_| {})?;
        // The CSV's rows: the budget rows, then the mesh row (its shading
        // `mesh`, its errors measured against the exact surface).
        let mut rows = serde_json::to_value(&result.rows).map_err(splatray::Error::other)?;
        if let (Some(m), Some(list)) = (&result.mesh, rows.as_array_mut()) {
            list.push(mesh_dict(m));
        }
        serde_json::to_string(&rows).map_err(splatray::Error::other)
    })
}

/// The mesh row as `sweep`'s dict: `shading` "mesh", step and epsilon 0,
/// no varied splats, every backend's speed and measured errors.
fn mesh_dict(m: &splatray::MeshRow) -> serde_json::Value {
    let backends = serde_json::to_value(&m.backends).unwrap_or_default();
    serde_json::json!({
        "step": 0,
        "epsilon_rel": 0.0,
        "shading": "mesh",
        "splats": 0,
        "scene_splats": m.scene_splats,
        "triangles": m.triangles,
        "splat_seconds": 0.0,
        "backends": backends,
        "backends_identical": m.backends_identical,
    })
}
