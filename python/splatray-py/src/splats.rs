//! Point clouds and splats: `read_points`, `splat`, `PointCloud`, `Splats`.

use crate::arrays::{matrix, point3, rows, vec3s};
use crate::err;
use crate::progress::Callback;
use glam::{DVec3, Vec3};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use splatray::io::{CloudRead, SplatSet};
use splatray::splat::Splat;
use splatray::splat::color::ColorField;
use splatray::workflow::splat::GenerationOptions;
use std::path::PathBuf;

/// A point cloud: positions in the file's coordinates (f64), held as the
/// library holds them (f32 offsets from an f64 origin, the per-axis
/// medians), with optional normals, colours, viewpoint and organised grid.
#[pyclass(module = "splatray", frozen)]
pub struct PointCloud {
    pub cloud: splatray::splat::PointCloud,
    /// Rows and columns of an organised scan (a PCD with `HEIGHT` > 1).
    pub grid: Option<(usize, usize)>,
}

#[pymethods]
impl PointCloud {
    /// A cloud from arrays: `positions` (N, 3) float64 (or float32) in any
    /// coordinates; `normals`, `colors` (linear RGB in [0, 1]) (N, 3);
    /// `viewpoint` three numbers in the positions' coordinates.
    #[new]
    #[pyo3(signature = (positions, normals=None, colors=None, viewpoint=None))]
    fn new(
        positions: &Bound<'_, PyAny>,
        normals: Option<&Bound<'_, PyAny>>,
        colors: Option<&Bound<'_, PyAny>>,
        viewpoint: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<PointCloud> {
        let cloud = cloud_from_arrays(positions, normals, colors, viewpoint)?;
        Ok(PointCloud { cloud, grid: None })
    }

    /// Points.
    fn __len__(&self) -> usize {
        self.cloud.positions.len()
    }

    fn __repr__(&self) -> String {
        format!(
            "PointCloud({} points{}{}{}{})",
            self.cloud.positions.len(),
            if self.cloud.normals.is_some() {
                ", normals"
            } else {
                ""
            },
            if self.cloud.colors.is_some() {
                ", colours"
            } else {
                ""
            },
            if self.cloud.viewpoint.is_some() {
                ", viewpoint"
            } else {
                ""
            },
            self.grid
                .map_or(String::new(), |(h, w)| format!(", grid {h}x{w}"))
        )
    }

    /// (N, 3) float64: the points in the file's coordinates.
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        let o = self.cloud.origin;
        let flat: Vec<f64> = self
            .cloud
            .positions
            .iter()
            .flat_map(|p| (o + p.as_dvec3()).to_array())
            .collect();
        matrix(py, 3, flat)
    }

    /// The f64 origin the library measures positions from (the medians).
    #[getter]
    fn origin(&self) -> [f64; 3] {
        self.cloud.origin.to_array()
    }

    /// (N, 3) float32 normals as stored, or None.
    #[getter]
    fn normals<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyAny>> {
        let n = self.cloud.normals.as_ref()?;
        Some(vec3s(py, n.iter().map(|v| v.to_array())))
    }

    /// (N, 3) float32 linear RGB colours in [0, 1], or None.
    #[getter]
    fn colors<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyAny>> {
        let c = self.cloud.colors.as_ref()?;
        Some(vec3s(py, c.iter().map(|v| v.to_array())))
    }

    /// Where the scanner stood (file coordinates), or None.
    #[getter]
    fn viewpoint(&self) -> Option<[f64; 3]> {
        self.cloud
            .viewpoint
            .map(|v| (self.cloud.origin + v.as_dvec3()).to_array())
    }

    /// (rows, columns) of an organised scan, or None.
    #[getter]
    fn grid(&self) -> Option<(usize, usize)> {
        self.grid
    }

    /// Points the reader left out: a list of (reason, count).
    #[getter]
    fn skipped(&self) -> Vec<(String, usize)> {
        self.cloud.skipped.clone()
    }
}

/// A cloud from checked arrays: origin at the per-axis medians (as the
/// readers put it), positions f32 offsets from it.
fn cloud_from_arrays(
    positions: &Bound<'_, PyAny>,
    normals: Option<&Bound<'_, PyAny>>,
    colors: Option<&Bound<'_, PyAny>>,
    viewpoint: Option<&Bound<'_, PyAny>>,
) -> PyResult<splatray::splat::PointCloud> {
    let p = rows::<f64>(positions, "positions", 3, false)?;
    let n = p.len() / 3;
    let world: Vec<DVec3> = p.chunks_exact(3).map(DVec3::from_slice).collect();
    let per_point = |a: Option<&Bound<'_, PyAny>>, name: &str| -> PyResult<Option<Vec<Vec3>>> {
        let Some(a) = a.filter(|a| !a.is_none()) else {
            return Ok(None);
        };
        let v = rows::<f32>(a, name, 3, false)?;
        if v.len() != 3 * n {
            return Err(PyValueError::new_err(format!(
                "{name} has {} rows, positions {n}",
                v.len() / 3
            )));
        }
        Ok(Some(v.chunks_exact(3).map(Vec3::from_slice).collect()))
    };
    let normals = per_point(normals, "normals")?;
    let colors = per_point(colors, "colors")?;
    let origin =
        splatray::splat::robust_centre_size(n, |i| world[i]).map_or(DVec3::ZERO, |(c, _)| c);
    let local: Vec<Vec3> = world.iter().map(|w| (*w - origin).as_vec3()).collect();
    if local.iter().any(|p| !p.is_finite()) {
        return Err(PyValueError::new_err(
            "positions: a point lies farther from the cloud's median than single precision holds",
        ));
    }
    let mut cloud = splatray::splat::PointCloud {
        positions: local,
        origin,
        normals,
        colors,
        ..Default::default()
    };
    if let Some(v) = viewpoint.filter(|v| !v.is_none()) {
        let v = point3(v, "viewpoint")?;
        cloud.viewpoint = Some(cloud.local_viewpoint(DVec3::from_array(v)));
    }
    Ok(cloud)
}

/// Reads a point cloud (.ply, .pcd, .xyz/.txt, .las/.laz, .e57, or known by
/// its first bytes).
#[pyfunction]
pub fn read_points(py: Python<'_>, path: PathBuf) -> PyResult<PointCloud> {
    py.detach(|| {
        match splatray::io::read_any(&path) {
            Ok((CloudRead::Points(cloud), grid)) => Ok(PointCloud {
                cloud,
                grid: grid.map(|g| (g.height, g.width)),
            }),
            // A splat or Gaussian PLY read as the points it also is.
            Ok(_) => splatray::io::read_points(&path)
                .map(|cloud| PointCloud { cloud, grid: None })
                .map_err(err),
            Err(e) => Err(err(e)),
        }
    })
}

/// Splats with Phong normal fields: centres as f32 offsets from an f64
/// origin, as the library and the splat PLY hold them.
#[pyclass(module = "splatray", frozen)]
pub struct Splats {
    pub set: SplatSet,
    /// The generation report (JSON text), for splats made by `splat`.
    pub report: Option<String>,
}

impl Splats {
    fn rows<'py, const C: usize>(
        &self,
        py: Python<'py>,
        f: impl Fn(&Splat) -> [f32; C],
    ) -> Bound<'py, PyAny> {
        matrix(py, C, self.set.splats.iter().flat_map(f).collect())
    }
}

#[pymethods]
impl Splats {
    /// Reads a splat PLY (`splatray splat`'s output, or `Splats.save`'s).
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Splats> {
        py.detach(|| splatray::io::read_splats(&path))
            .map(|set| Splats { set, report: None })
            .map_err(err)
    }

    /// Writes the splat PLY the command line writes (atomically: a failure
    /// leaves nothing).
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        py.detach(|| {
            let fields = (!self.set.color_fields.is_empty()).then_some(&self.set.color_fields[..]);
            let bytes =
                splatray::io::encode_splats_with(&path, &self.set.splats, fields, self.set.origin)?;
            splatray::io::write_bytes(&path, &bytes)
        })
        .map_err(err)
    }

    fn __len__(&self) -> usize {
        self.set.splats.len()
    }

    fn __repr__(&self) -> String {
        format!(
            "Splats({} splats{}, origin [{}, {}, {}])",
            self.set.splats.len(),
            if self.set.color_fields.is_empty() {
                ""
            } else {
                ", colour fields"
            },
            self.set.origin.x,
            self.set.origin.y,
            self.set.origin.z
        )
    }

    /// (N, 3) float64: centres in the cloud's coordinates.
    #[getter]
    fn centers<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        let o = self.set.origin;
        let flat = self
            .set
            .splats
            .iter()
            .flat_map(|s| (o + s.center.as_dvec3()).to_array())
            .collect();
        matrix::<f64>(py, 3, flat)
    }

    /// The f64 origin centres are stored as offsets from.
    #[getter]
    fn origin(&self) -> [f64; 3] {
        self.set.origin.to_array()
    }

    /// (N, 3) float32 unit normals.
    #[getter]
    fn normals<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        self.rows(py, |s| s.normal.to_array())
    }

    /// (N, 3) float32 unit major axes.
    #[getter]
    fn u_axes<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        self.rows(py, |s| s.u_axis.to_array())
    }

    /// (N, 3) float32 unit minor axes.
    #[getter]
    fn v_axes<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        self.rows(py, |s| s.v_axis.to_array())
    }

    /// (N, 2) float32 radii along the axes.
    #[getter]
    fn radii<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        self.rows(py, |s| s.radii.to_array())
    }

    /// (N, 4) float32 Phong normal fields (x_c, y_c, alpha, beta), eq. (4).
    #[getter]
    fn normal_fields<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        self.rows(py, |s| {
            [s.field.xc, s.field.yc, s.field.alpha, s.field.beta]
        })
    }

    /// (N, 6) float32 clip lines `(a, b, d)` twice: a splat keeps the
    /// part of its disc with `a u + b v <= d` in its normalised coordinates
    /// (`u`, `v` along the axes in units of the radii); a line of zeros
    /// keeps all (a whole disc has two, an edge's splat one).
    #[getter]
    fn clip_lines<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        self.rows(py, |s| {
            let mut row = [0f32; 6];
            for (k, l) in s.clip.lines().iter().enumerate() {
                row[3 * k..3 * k + 3].copy_from_slice(&[l.a, l.b, l.d]);
            }
            row
        })
    }

    /// (N, 3) float32 linear RGB colours.
    #[getter]
    fn colors<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        self.rows(py, |s| s.color.to_array())
    }

    /// (N, 6) float32 linear colour fields (du, dv), or None.
    #[getter]
    fn color_fields<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyAny>> {
        let f: &[ColorField] = &self.set.color_fields;
        (!f.is_empty()).then(|| {
            matrix(
                py,
                6,
                f.iter()
                    .flat_map(|c| [c.du.x, c.du.y, c.du.z, c.dv.x, c.dv.y, c.dv.z])
                    .collect(),
            )
        })
    }

    /// The generation report as a dict (None for loaded splats).
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        let Some(r) = &self.report else {
            return Ok(None);
        };
        Ok(Some(py.import("json")?.call_method1("loads", (r,))?))
    }
}

/// Splats from a point cloud, as `splatray splat` makes them (read, clean,
/// normals, grow, fields, free-space trimming with a viewpoint, colour
/// fields); the options are the command's.
#[pyfunction]
#[pyo3(signature = (points, normals=None, colors=None, viewpoint=None, *, epsilon=None, k=None,
    density=None, ellipses=false, flat_colors=false, creases=None, no_viewpoint=false, thin=None,
    lean=true, progress=None))]
#[allow(clippy::too_many_arguments)]
pub fn splat(
    py: Python<'_>,
    points: &Bound<'_, PyAny>,
    normals: Option<&Bound<'_, PyAny>>,
    colors: Option<&Bound<'_, PyAny>>,
    viewpoint: Option<&Bound<'_, PyAny>>,
    epsilon: Option<f32>,
    k: Option<usize>,
    density: Option<f32>,
    ellipses: bool,
    flat_colors: bool,
    creases: Option<bool>,
    no_viewpoint: bool,
    thin: Option<f64>,
    lean: bool,
    progress: Option<Py<PyAny>>,
) -> PyResult<Splats> {
    let given = points.cast::<PointCloud>().ok();
    let owned;
    let cloud = match &given {
        Some(c) => {
            if [normals, colors]
                .iter()
                .any(|a| a.is_some_and(|a| !a.is_none()))
            {
                return Err(PyValueError::new_err(
                    "normals and colors come with the PointCloud; give them with positions only",
                ));
            }
            &c.get().cloud
        }
        None => {
            owned = cloud_from_arrays(points, normals, colors, None)?;
            &owned
        }
    };
    let vp = match viewpoint.filter(|v| !v.is_none()) {
        Some(v) => Some(DVec3::from_array(point3(v, "viewpoint")?)),
        None => None,
    };
    let p = GenerationOptions {
        epsilon_rel: epsilon,
        k,
        density,
        ellipses,
        flat_colors,
        creases,
        viewpoint: vp,
        no_viewpoint,
        thin,
        no_lean: !lean,
    }
    .params(cloud);
    let cb = Callback::new(progress);
    let out = py.detach(|| {
        let report_to = |s: &str, f: f64| cb.report(s, f);
        let g = splatray::pipeline::generate(cloud, &p, Some(&report_to))?;
        let json = serde_json::json!({ "generation": g.report, "trim": g.trim });
        Ok::<_, splatray::Error>((g.splats, g.color_fields, json.to_string()))
    });
    cb.finish()?;
    let (splats, color_fields, report) = out.map_err(err)?;
    Ok(Splats {
        set: SplatSet {
            splats,
            origin: cloud.origin,
            color_fields,
        },
        report: Some(report),
    })
}
