//! `SplatScene`: rays in, resolved hits out, as the renderer resolves its
//! camera rays (the point-cloud counterpart of Open3D's
//! `RaycastingScene`). One backend and the shared resolver
//! (`SplatSurfaces`), so the octree and Embree give the same answers.
//! Triangles (a scene file's `triangles` models, or arrays given beside
//! the splats) are traced with the splats as the renderer traces them
//! (issue 57): hit ids from `first_triangle` on are triangles.

use crate::arrays::{index_rows, matrix, rows, vector};
use crate::err;
use crate::splats::Splats;
use glam::{DVec3, Vec3};
use numpy::{PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use rayon::prelude::*;
use splatray::accel::{Backend, CandidateHits, Ray};
use splatray::render::cast::{
    CastAnswers, CastScratch, RayRows, cast_rays_owned, cast_rows_owned, occluded_rows,
};
use splatray::render::integrator::{SplatSurfaces, Surfaces};
use splatray::render::nearest::{Closest, Nearest};
use splatray::resolve::{Silhouette, silhouettes};
use splatray::scene::Scene;
use splatray::simd::RowNumber;
use std::sync::{Mutex, OnceLock};
use std::time::Instant;

/// Splats, and triangles beside them, in one acceleration backend, for
/// ray casting.
#[pyclass(module = "splatray", frozen)]
pub struct SplatScene {
    scene: Scene,
    backend: Box<dyn Backend>,
    /// The scene's frame: world = scene + `to_internal`, subtracted in f64.
    to_internal: DVec3,
    name: &'static str,
    /// The last call's converted rays and lengths, and its scattered
    /// rays' answers in the order traced, whose memory the next call
    /// writes into: fresh vectors are pages the kernel maps and zeroes on
    /// first touch, a sixth of the CPU of a process casting camera rays
    /// (`docs/notes/backends.md`, "Issue 55, seventh session") and about
    /// 5 % of a `cast_rays` call of random rays ("fifty-fifth session").
    /// Kept up to [`KEEP_RAYS`] rays.
    scratch: Mutex<CastScratch>,
    /// The splats' silhouette constants for the resolver, built on the
    /// first call that resolves windows (`cast_rays`,
    /// `count_intersections`; 16 bytes a splat), none for `occluded`.
    kept: OnceLock<Vec<Silhouette>>,
    /// The nearest-surface search, built on the first distance query
    /// (`compute_distance` and its kin; 21-26 bytes a primitive).
    nearest: OnceLock<Nearest>,
}

/// A ray array's rows of six numbers, as its memory holds them.
enum Rows<'a> {
    F32(&'a [f32]),
    F64(&'a [f64]),
}

/// The most rays whose buffers a scene keeps between calls (28 bytes a
/// ray converted, 20 more answered in order: 192 MB).
const KEEP_RAYS: usize = 1 << 22;

impl SplatScene {
    /// `scene` (its splats and triangles, shading modes and windows) in
    /// `backend` (a registry name); its world frame is its own plus
    /// `to_internal`.
    pub fn build(scene: Scene, to_internal: DVec3, backend: &str) -> splatray::Result<SplatScene> {
        let info = splatray::accel::registry::lookup(backend)?;
        let built = info.build_scene(&scene)?;
        Ok(SplatScene {
            scene,
            backend: built,
            to_internal,
            name: info.name,
            scratch: Mutex::default(),
            kept: OnceLock::new(),
            nearest: OnceLock::new(),
        })
    }

    /// The nearest surface to each row of `points` ((N, 3) floats, the
    /// splats' coordinates), with the query points in the scene's frame.
    fn closest(
        &self,
        py: Python<'_>,
        points: &Bound<'_, PyAny>,
    ) -> PyResult<(Vec<DVec3>, Vec<Closest>)> {
        let v = rows::<f64>(points, "query_points", 3, true)?;
        Ok(py.detach(|| {
            let (splats, tris) = (&self.scene.splats[..], &self.scene.triangles.tris[..]);
            let near = self.nearest.get_or_init(|| Nearest::build(splats, tris));
            let ps: Vec<DVec3> = v
                .chunks_exact(3)
                .map(|r| DVec3::new(r[0], r[1], r[2]) - self.to_internal)
                .collect();
            let got = near.closest_all(splats, tris, &ps);
            (ps, got)
        }))
    }

    fn surfaces(&self) -> SplatSurfaces<'_> {
        SplatSurfaces {
            scene: &self.scene,
            backend: self.backend.as_ref(),
            kept: None,
        }
    }

    /// [`SplatScene::surfaces`] with the resolver's kept constants.
    fn resolving(&self) -> SplatSurfaces<'_> {
        SplatSurfaces {
            kept: Some(
                self.kept.get_or_init(|| {
                    silhouettes(&self.scene.splats, |id| self.scene.shading_for(id))
                }),
            ),
            ..self.surfaces()
        }
    }

    /// Checked rays in the scene's frame, and each direction's length
    /// (`t` is reported in units of it, as Open3D does); converted in
    /// parallel, straight from the array's memory when it is contiguous.
    fn rays(&self, rays: &Bound<'_, PyAny>) -> PyResult<(Vec<Ray>, Vec<f32>)> {
        self.with_rows(rays, |s: &Self, v: Rows<'_>| match v {
            Rows::F32(v) => s.convert(v),
            Rows::F64(v) => s.convert(v),
        })
    }

    /// `f` of the array `rays`' rows of six numbers: straight from its
    /// memory when it is a contiguous `float32` or `float64` array, else
    /// checked (and its error said) as any array and copied.
    fn with_rows<R>(
        &self,
        rays: &Bound<'_, PyAny>,
        f: impl FnOnce(&Self, Rows<'_>) -> PyResult<R>,
    ) -> PyResult<R> {
        if let Ok(a) = rays.extract::<PyReadonlyArray2<'_, f32>>()
            && a.shape()[1] == 6
            && let Ok(v) = a.as_slice()
        {
            return f(self, Rows::F32(v));
        }
        if let Ok(a) = rays.extract::<PyReadonlyArray2<'_, f64>>()
            && a.shape()[1] == 6
            && let Ok(v) = a.as_slice()
        {
            return f(self, Rows::F64(v));
        }
        f(self, Rows::F64(&rows::<f64>(rays, "rays", 6, true)?))
    }

    /// `cast_rays`' answers for the rows `v` (`cast_rows_owned`: a
    /// camera's converted window by window as they are traced, scattered
    /// rays converted whole first, into the kept buffers).
    fn cast_rows<T: RowNumber>(
        &self,
        py: Python<'_>,
        v: &[T],
        want: (bool, bool),
    ) -> PyResult<CastAnswers> {
        let rows = RayRows::new(v, self.to_internal);
        let mut buf = self.take();
        let answers = py.detach(|| cast_rows_owned(&self.resolving(), &rows, want, &mut buf));
        self.keep(buf);
        answers.map_err(|i| self.row_error(v, i))
    }

    /// `occluded`'s answers for the rows `v` over `span` (`occluded_rows`:
    /// a camera's converted window by window, only the rows its fan does
    /// not know to miss; scattered rays converted whole first, into the
    /// kept buffers).
    fn occluded_rows<T: RowNumber>(
        &self,
        py: Python<'_>,
        v: &[T],
        span: (f32, f32),
    ) -> PyResult<Vec<bool>> {
        let rows = RayRows::new(v, self.to_internal);
        let mut buf = self.take();
        let got = py.detach(|| {
            let mut out = vec![false; v.len() / 6];
            occluded_rows(&self.surfaces(), &rows, span, &mut out, &mut buf).map(|()| out)
        });
        self.keep(buf);
        got.map_err(|i| self.row_error(v, i))
    }

    /// The error of row `i` of `v`, which is not a ray.
    fn row_error<T: Copy + Into<f64>>(&self, v: &[T], i: usize) -> PyErr {
        let why = self.ray(&v[6 * i..6 * i + 6]).err().unwrap_or("is wrong");
        PyValueError::new_err(format!("rays: row {i} {why}"))
    }

    /// Rows of six numbers to rays and direction lengths, written straight
    /// into their vectors in parallel (`RayRows::convert_all`; no
    /// per-chunk lists joined and unzipped: that was a quarter of a
    /// camera-ray `cast_rays` call, `docs/notes/backends.md`, "Issue 55,
    /// round 2"; nor a parallel unzip, whose pairs went through memory:
    /// a fifth of a camera `occluded` call's misses, "seventeenth
    /// session"); the first bad row is reported.
    fn convert<T: RowNumber>(&self, v: &[T]) -> PyResult<(Vec<Ray>, Vec<f32>)> {
        let rows = RayRows::new(v, self.to_internal);
        let (mut rays, mut lens) = self.lock().take_rays();
        match rows.convert_all(&mut rays, &mut lens) {
            true => Ok((rays, lens)),
            false => Err(self.row_error(v, rows.first_bad().unwrap_or(0))),
        }
    }

    /// The kept buffers (a call running beside this one finds none and
    /// allocates); a poisoned lock still holds plain vectors. Sized once:
    /// a call as long as the last writes over its rays.
    fn take(&self) -> CastScratch {
        std::mem::take(&mut *self.lock())
    }

    /// The kept buffers' lock (a poisoned one still holds plain vectors).
    fn lock(&self) -> std::sync::MutexGuard<'_, CastScratch> {
        self.scratch.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Keeps a call's buffers for the next call (none beyond
    /// [`KEEP_RAYS`] rays).
    fn keep(&self, buf: CastScratch) {
        if buf.rays_held() <= KEEP_RAYS {
            *self.lock() = buf;
        }
    }

    /// One row as a ray in the scene's frame and its direction's length,
    /// or what is wrong with it.
    #[inline(always)]
    fn ray<T: Copy + Into<f64>>(&self, r: &[T]) -> Result<(Ray, f32), &'static str> {
        let r: [f64; 6] = std::array::from_fn(|k| r[k].into());
        if r.iter().any(|x| !x.is_finite()) {
            return Err("holds a NaN or infinite value");
        }
        let d = Vec3::new(r[3] as f32, r[4] as f32, r[5] as f32);
        let len = d.length();
        if !(len > 0.0 && len.is_finite()) {
            return Err("has a zero (or too small or large) direction");
        }
        let origin = (DVec3::new(r[0], r[1], r[2]) - self.to_internal).as_vec3();
        if !origin.is_finite() {
            return Err("has an origin beyond single precision from the splats");
        }
        Ok((Ray::new(origin, d), len))
    }
}

/// Checked `vertices` ((V, 3) floats) and `faces` ((F, 3) integer
/// indices): the faces' corners in f64, or a one-line error naming the
/// array and the row (a NaN or infinite vertex, an index out of range or
/// negative, a face whose corners repeat).
fn mesh_arrays(vertices: &Bound<'_, PyAny>, faces: &Bound<'_, PyAny>) -> PyResult<Vec<[DVec3; 3]>> {
    let v = rows::<f64>(vertices, "vertices", 3, false)?;
    let f = index_rows(faces, "faces", 3)?;
    let n = v.len() / 3;
    f.chunks_exact(3)
        .enumerate()
        .map(|(i, ix)| {
            if let Some(&j) = ix.iter().find(|&&j| j < 0 || j as u64 >= n as u64) {
                return Err(PyValueError::new_err(format!(
                    "faces: row {i} has index {j}, not in 0..{n} (the vertices' rows)"
                )));
            }
            if ix[0] == ix[1] || ix[1] == ix[2] || ix[0] == ix[2] {
                return Err(PyValueError::new_err(format!(
                    "faces: row {i} is degenerate: its vertices {}, {} and {} repeat",
                    ix[0], ix[1], ix[2]
                )));
            }
            let at = |j: i64| {
                let k = 3 * j as usize;
                DVec3::new(v[k], v[k + 1], v[k + 2])
            };
            Ok([at(ix[0]), at(ix[1]), at(ix[2])])
        })
        .collect()
}

/// `corners` (world frame) placed in `scene`'s frame (world less
/// `to_internal`, in f64) as its triangles, of the splats' first material:
/// ids from `scene.first_triangle()` on, in the rows' order. A face that
/// spans no area, or is not finite, once in f32 is a one-line error.
fn add_triangles(
    scene: &mut Scene,
    corners: &[[DVec3; 3]],
    to_internal: DVec3,
) -> Result<(), String> {
    let t = &mut scene.triangles;
    for (i, c) in corners.iter().enumerate() {
        let tri = splatray::primitive::Triangle {
            v: c.map(|p| (p - to_internal).as_vec3()),
        };
        if !tri.is_proper() {
            return Err(format!(
                "faces: row {i} spans no area (its corners are collinear, or too far from \
                 the splats for single precision)"
            ));
        }
        t.face.push(tri.unit_normal());
        t.tris.push(tri);
        t.normals.push([Vec3::ZERO; 3]);
        t.material_of.push(0);
    }
    u32::try_from(scene.splats.len() + t.tris.len())
        .map(|_| ())
        .map_err(|_| "too many splats and triangles for 32-bit ids".to_string())
}

#[pymethods]
impl SplatScene {
    /// `splats` in the backend `backend` (`splatray.BACKENDS`; the first
    /// is the default), resolved with the defaults of a scene file (Phong
    /// shading, each model's measured window). With `vertices` ((V, 3)
    /// float32 or float64, in the splats' coordinates) and `faces` ((F, 3)
    /// int32, int64, uint32 or uint64 indices into `vertices`), those
    /// triangles too, traced and resolved with the splats as the renderer
    /// does (a triangle hit is a window of one; shaded with its face
    /// normal): face `i` is hit id `first_triangle + i`. A NaN or
    /// infinite vertex, an index out of range or negative, or a face
    /// spanning no area raises ValueError naming the row; a wrong shape
    /// or dtype, TypeError or ValueError.
    #[new]
    #[pyo3(signature = (splats, backend=None, *, vertices=None, faces=None))]
    fn new(
        py: Python<'_>,
        splats: &Bound<'_, Splats>,
        backend: Option<&str>,
        vertices: Option<&Bound<'_, PyAny>>,
        faces: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<SplatScene> {
        let set = &splats.get().set;
        let backend = backend.unwrap_or(splatray::accel::registry::names()[0]);
        if set.splats.is_empty() {
            return Err(PyValueError::new_err("splats: no splats"));
        }
        let corners = match (vertices, faces) {
            (None, None) => Vec::new(),
            (Some(v), Some(f)) => mesh_arrays(v, f)?,
            _ => {
                return Err(PyValueError::new_err(
                    "triangles need both `vertices` and `faces`",
                ));
            }
        };
        py.detach(|| {
            let camera =
                splatray::scene::Camera::look_at(Vec3::Z, Vec3::ZERO, Vec3::Y, 40.0, 1, 1, 1)
                    .map_err(err)?;
            let mut scene =
                splatray::scene::load::splats_scene(set.splats.clone(), camera).map_err(err)?;
            scene.color_fields = set.color_fields.clone();
            let to_internal = set.origin + scene.offset.as_dvec3();
            add_triangles(&mut scene, &corners, to_internal).map_err(PyValueError::new_err)?;
            SplatScene::build(scene, to_internal, backend).map_err(err)
        })
    }

    /// The hit id of the first triangle (the splats' count): ids below it
    /// are splats, ids from it on triangles (face `id - first_triangle`
    /// of the faces given, or of the scene's `triangles` models in their
    /// order).
    #[getter]
    fn first_triangle(&self) -> u32 {
        self.scene.first_triangle()
    }

    /// Triangles in the scene.
    #[getter]
    fn triangles(&self) -> usize {
        self.scene.triangles.tris.len()
    }

    /// The backend's name.
    #[getter]
    fn backend(&self) -> &'static str {
        self.name
    }

    fn __repr__(&self) -> String {
        format!(
            "SplatScene({} splats, {} triangles, backend {:?})",
            self.scene.splats.len(),
            self.scene.triangles.tris.len(),
            self.name
        )
    }

    /// Casts `rays` ((N, 6) float32 or float64: origin, direction, in the
    /// splats' coordinates; directions need not be unit) and returns a dict
    /// of `t_hit` (N,) float32 (in units of each direction's length; inf on
    /// a miss), and when asked for (both are by default) `splat_ids` (N,)
    /// uint32 (`INVALID_ID` on a miss) and `normals` (N, 3) float32 (the
    /// resolved shading normal; 0 on a miss). Rays sharing an origin
    /// (camera rays) are found and traced in packets by the library
    /// (`splatray::render::cast`).
    #[pyo3(signature = (rays, splat_ids=true, normals=true))]
    fn cast_rays<'py>(
        &self,
        py: Python<'py>,
        rays: &Bound<'py, PyAny>,
        splat_ids: bool,
        normals: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        let want = (splat_ids, normals);
        let CastAnswers {
            t,
            ids,
            normals: nrm,
        } = self.with_rows(rays, |s: &Self, v: Rows<'_>| match v {
            Rows::F32(v) => s.cast_rows(py, v, want),
            Rows::F64(v) => s.cast_rows(py, v, want),
        })?;
        // The vectors are handed to numpy as they are (no copy).
        let d = pyo3::types::PyDict::new(py);
        d.set_item("t_hit", vector(py, t))?;
        if let Some(ids) = ids {
            d.set_item("splat_ids", vector(py, ids))?;
        }
        if let Some(nrm) = nrm {
            d.set_item("normals", matrix(py, 3, nrm))?;
        }
        Ok(d.into_any())
    }

    /// How many surfaces each ray passes through (N,) int32: the resolved
    /// surface it meets, then the next one beyond it (leaving each surface
    /// as a refracted ray leaves it), and so on (at most `limit`).
    #[pyo3(signature = (rays, limit=1024))]
    fn count_intersections<'py>(
        &self,
        py: Python<'py>,
        rays: &Bound<'py, PyAny>,
        limit: u32,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (rays, _) = self.rays(rays)?;
        let counts = py.detach(|| {
            let s = self.resolving();
            let xi = self.scene.options.scale.xi;
            rays.par_iter()
                .map_init(
                    || CandidateHits::new(xi),
                    |hits, ray| {
                        let mut n = 0i32;
                        let mut at = s.hit(ray, None, hits);
                        while let Some(h) = at {
                            n += 1;
                            if n as u32 >= limit {
                                break;
                            }
                            let next = Ray {
                                origin: h.surface.point,
                                dir: ray.dir,
                            };
                            at = s.hit(&next, Some(&h), hits);
                        }
                        n
                    },
                )
                .collect::<Vec<i32>>()
        });
        Ok(vector(py, counts))
    }

    /// Whether each ray meets a surface with `t` in `[tnear, tfar]` (in
    /// units of its direction's length), (N,) bool: what a shadow ray asks
    /// (Phong splats seen as the curved surfaces the resolver shows).
    #[pyo3(signature = (rays, tnear=0.0, tfar=f32::INFINITY))]
    fn occluded<'py>(
        &self,
        py: Python<'py>,
        rays: &Bound<'py, PyAny>,
        tnear: f32,
        tfar: f32,
    ) -> PyResult<Bound<'py, PyAny>> {
        if !(tnear >= 0.0 && tfar >= tnear) {
            return Err(PyValueError::new_err(format!(
                "tnear {tnear} and tfar {tfar} must satisfy 0 <= tnear <= tfar"
            )));
        }
        let out = self.with_rows(rays, |s: &Self, v: Rows<'_>| match v {
            Rows::F32(v) => s.occluded_rows(py, v, (tnear, tfar)),
            Rows::F64(v) => s.occluded_rows(py, v, (tnear, tfar)),
        })?;
        Ok(vector(py, out))
    }

    /// The point of the nearest surface (a splat's disc within its clip
    /// lines, or a triangle) to each of `query_points` ((N, 3) float32 or
    /// float64, the splats' coordinates): a dict of `points` (N, 3)
    /// float64, `splat_ids` (N,) uint32 (ids as `cast_rays` gives them;
    /// on equal distances the lowest) and `normals` (N, 3) float32 (the
    /// surface's geometric normal). A NaN or infinite row raises
    /// ValueError naming it.
    fn compute_closest_points<'py>(
        &self,
        py: Python<'py>,
        query_points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (_, got) = self.closest(py, query_points)?;
        let mut points = Vec::with_capacity(3 * got.len());
        let mut normals = Vec::with_capacity(3 * got.len());
        for c in &got {
            points.extend((c.point + self.to_internal).to_array());
            normals.extend(c.normal.to_array());
        }
        let d = pyo3::types::PyDict::new(py);
        d.set_item("points", matrix(py, 3, points))?;
        d.set_item("splat_ids", vector(py, got.iter().map(|c| c.id).collect()))?;
        d.set_item("normals", matrix(py, 3, normals))?;
        Ok(d.into_any())
    }

    /// The distance from each of `query_points` ((N, 3) floats) to the
    /// nearest surface, (N,) float32 (as `compute_closest_points` finds it).
    fn compute_distance<'py>(
        &self,
        py: Python<'py>,
        query_points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (_, got) = self.closest(py, query_points)?;
        Ok(vector(py, got.iter().map(|c| c.distance as f32).collect()))
    }

    /// `compute_distance`, negative where the point lies behind the
    /// nearest surface (against its normal: inside a closed object whose
    /// normals face out).
    fn compute_signed_distance<'py>(
        &self,
        py: Python<'py>,
        query_points: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (ps, got) = self.closest(py, query_points)?;
        let signed = ps
            .iter()
            .zip(&got)
            .map(|(p, c)| c.signed(*p) as f32)
            .collect();
        Ok(vector(py, signed))
    }

    /// Seconds the Rust call of `cast_rays` takes on `rays`, without the
    /// conversion of arrays in and out (the benchmark's reference): wall
    /// seconds and the process's CPU seconds.
    fn _cast_seconds(&self, py: Python<'_>, rays: &Bound<'_, PyAny>) -> PyResult<(f64, f64)> {
        let (rays, lens) = self.rays(rays)?;
        Ok(py.detach(|| {
            let (t0, c0) = (Instant::now(), process_cpu());
            let answers = cast_rays_owned(&self.resolving(), &rays, &lens, (true, true));
            let took = (t0.elapsed().as_secs_f64(), process_cpu() - c0);
            drop(answers);
            took
        }))
    }
}

/// The process's CPU seconds (all threads).
fn process_cpu() -> f64 {
    let t = rustix::time::clock_gettime(rustix::time::ClockId::ProcessCPUTime);
    t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9
}
