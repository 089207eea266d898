//! `SplatScene`: rays in, resolved hits out, as the renderer resolves its
//! camera rays (the point-cloud counterpart of Open3D's
//! `RaycastingScene`). One backend and the shared resolver
//! (`SplatSurfaces`), so the octree and Embree give the same answers.

use crate::arrays::{matrix, rows_f64, vector};
use crate::err;
use crate::splats::Splats;
use glam::{DVec3, Vec3};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use rayon::prelude::*;
use splatray::accel::{Backend, CandidateHits, PACKET, Query, Ray};
use splatray::render::integrator::{ShadeHit, SplatSurfaces, Surfaces};
use splatray::scene::Scene;
use std::time::Instant;

/// Rays per rayon task.
const CHUNK: usize = 512;

/// Splats in one acceleration backend, for ray casting.
#[pyclass(module = "splatray", frozen)]
pub struct SplatScene {
    scene: Scene,
    backend: Box<dyn Backend>,
    /// The scene's frame: world = scene + `to_internal`, subtracted in f64.
    to_internal: DVec3,
    name: &'static str,
}

impl SplatScene {
    /// `scene` (its splats, shading modes and windows) in `backend` (a
    /// registry name); its world frame is its own plus `to_internal`.
    pub fn build(scene: Scene, to_internal: DVec3, backend: &str) -> splatray::Result<SplatScene> {
        let info = splatray::accel::registry::lookup(backend)?;
        let built = info.build_splats(&scene.splats)?;
        Ok(SplatScene {
            scene,
            backend: built,
            to_internal,
            name: info.name,
        })
    }

    fn surfaces(&self) -> SplatSurfaces<'_> {
        SplatSurfaces {
            scene: &self.scene,
            backend: self.backend.as_ref(),
        }
    }

    /// Checked rays in the scene's frame, and each direction's length
    /// (`t` is reported in units of it, as Open3D does).
    fn rays(&self, rays: &Bound<'_, PyAny>) -> PyResult<(Vec<Ray>, Vec<f32>)> {
        let v = rows_f64(rays, "rays", 6, true)?;
        let o = self.to_internal;
        let mut out = Vec::with_capacity(v.len() / 6);
        let mut lens = Vec::with_capacity(v.len() / 6);
        for (i, r) in v.chunks_exact(6).enumerate() {
            let d = Vec3::new(r[3] as f32, r[4] as f32, r[5] as f32);
            let len = d.length();
            if !(len > 0.0 && len.is_finite()) {
                return Err(PyValueError::new_err(format!(
                    "rays: row {i} has a zero (or too small or large) direction"
                )));
            }
            let origin = (DVec3::new(r[0], r[1], r[2]) - o).as_vec3();
            if !origin.is_finite() {
                return Err(PyValueError::new_err(format!(
                    "rays: row {i}'s origin lies beyond single precision from the splats"
                )));
            }
            out.push(Ray::new(origin, d));
            lens.push(len);
        }
        Ok((out, lens))
    }
}

/// The resolved hit of every ray (`None`: a miss), as the renderer's
/// camera rays are resolved: in packets of [`PACKET`] when the backend
/// prefers them (the same hits either way), in parallel.
pub fn cast(surfaces: &SplatSurfaces<'_>, rays: &[Ray], out: &mut [Option<ShadeHit>]) {
    let xi = surfaces.scene.options.scale.xi;
    let packets = surfaces.packets();
    rays.par_chunks(CHUNK)
        .zip(out.par_chunks_mut(CHUNK))
        .for_each(|(rays, out)| {
            let mut hits: [CandidateHits; PACKET] = std::array::from_fn(|_| CandidateHits::new(xi));
            if packets {
                for (r, o) in rays.chunks(PACKET).zip(out.chunks_mut(PACKET)) {
                    surfaces.hits(r, &mut hits, o);
                }
            } else {
                for (r, o) in rays.iter().zip(out.iter_mut()) {
                    *o = surfaces.hit(r, None, &mut hits[0]);
                }
            }
        });
}

#[pymethods]
impl SplatScene {
    /// `splats` in the backend `backend` (`splatray.BACKENDS`; the first
    /// is the default), resolved with the defaults of a scene file (Phong
    /// shading, each model's measured window).
    #[new]
    #[pyo3(signature = (splats, backend=None))]
    fn new(
        py: Python<'_>,
        splats: &Bound<'_, Splats>,
        backend: Option<&str>,
    ) -> PyResult<SplatScene> {
        let set = &splats.get().set;
        let backend = backend.unwrap_or(splatray::accel::registry::names()[0]);
        if set.splats.is_empty() {
            return Err(PyValueError::new_err("splats: no splats"));
        }
        py.detach(|| {
            let camera =
                splatray::scene::Camera::look_at(Vec3::Z, Vec3::ZERO, Vec3::Y, 40.0, 1, 1, 1)?;
            let mut scene = splatray::scene::load::splats_scene(set.splats.clone(), camera)?;
            scene.color_fields = set.color_fields.clone();
            let to_internal = set.origin + scene.offset.as_dvec3();
            SplatScene::build(scene, to_internal, backend)
        })
        .map_err(err)
    }

    /// The backend's name.
    #[getter]
    fn backend(&self) -> &'static str {
        self.name
    }

    fn __repr__(&self) -> String {
        format!(
            "SplatScene({} splats, backend {:?})",
            self.scene.splats.len(),
            self.name
        )
    }

    /// Casts `rays` ((N, 6) float32 or float64: origin, direction, in the
    /// splats' coordinates; directions need not be unit) and returns a dict
    /// of `t_hit` (N,) float32 (in units of each direction's length; inf on
    /// a miss), `splat_ids` (N,) uint32 (`INVALID_ID` on a miss) and
    /// `normals` (N, 3) float32 (the resolved shading normal; 0 on a miss).
    fn cast_rays<'py>(
        &self,
        py: Python<'py>,
        rays: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (rays, lens) = self.rays(rays)?;
        let (t, ids, normals) = py.detach(|| {
            let mut out = vec![None; rays.len()];
            cast(&self.surfaces(), &rays, &mut out);
            let t: Vec<f32> = out
                .iter()
                .zip(&lens)
                .map(|(h, l)| h.map_or(f32::INFINITY, |h| if *l == 1.0 { h.t } else { h.t / l }))
                .collect();
            let ids: Vec<u32> = out.iter().map(|h| h.map_or(u32::MAX, |h| h.id)).collect();
            let normals: Vec<f32> = out
                .iter()
                .flat_map(|h| h.map_or([0.0; 3], |h| h.normal.to_array()))
                .collect();
            (t, ids, normals)
        });
        let d = pyo3::types::PyDict::new(py);
        d.set_item("t_hit", vector(py, t))?;
        d.set_item("splat_ids", vector(py, ids))?;
        d.set_item("normals", matrix(py, 3, normals))?;
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
            let s = self.surfaces();
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
                                origin: h.point,
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
        let (rays, lens) = self.rays(rays)?;
        let out = py.detach(|| {
            let pass = self
                .scene
                .has_phong()
                .then_some(&self.scene as &dyn splatray::accel::PassOver);
            rays.par_iter()
                .zip(&lens)
                .map(|(ray, l)| {
                    self.backend.occluded_from(&Query {
                        ray: *ray,
                        t_min: tnear * l,
                        t_max: tfar * l,
                        from: None,
                        pass,
                    })
                })
                .collect::<Vec<bool>>()
        });
        Ok(vector(py, out))
    }

    /// Seconds the Rust call of `cast_rays` takes on `rays`, without the
    /// conversion of arrays in and out (the benchmark's reference).
    fn _cast_seconds(&self, py: Python<'_>, rays: &Bound<'_, PyAny>) -> PyResult<f64> {
        let (rays, _) = self.rays(rays)?;
        Ok(py.detach(|| {
            let mut out = vec![None; rays.len()];
            let t0 = Instant::now();
            cast(&self.surfaces(), &rays, &mut out);
            t0.elapsed().as_secs_f64()
        }))
    }
}
