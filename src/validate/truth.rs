//! Ground truth: the exact surfaces behind a scene's models (meshes traced
//! as Embree triangles, analytic spheres), rendered through the same
//! integrator as the splats so their figures can be compared.

use crate::accel::{CandidateHits, Ray};
use crate::embree::{Device, TriangleScene};
use crate::render::integrator::{ShadeHit, Surfaces};
use crate::resolve::SurfaceHit;
use crate::scene::{Scene, TruthSource};
use crate::{Error, Result};
use glam::Vec3;

struct TruthMesh {
    triangles: Vec<[u32; 3]>,
    positions: Vec<Vec3>,
    /// Area-weighted vertex normals: the smooth surface the mesh samples.
    normals: Vec<Vec3>,
    material: u16,
}

/// The exact surfaces of a scene, in the scene's (re-centred) coordinates.
pub struct Truth {
    triangles: TriangleScene,
    meshes: Vec<TruthMesh>,
    spheres: Vec<(Vec3, f32, u16)>,
    eps: f32,
}

impl Truth {
    /// Builds the exact surfaces of every model of `scene`, or says which
    /// model has none (point and splat files).
    pub fn new(scene: &Scene) -> Result<Truth> {
        let mut meshes = Vec::new();
        let mut spheres = Vec::new();
        for t in &scene.load.truth {
            match t {
                TruthSource::Mesh { mesh, material } => {
                    let positions: Vec<Vec3> =
                        mesh.positions.iter().map(|&p| p - scene.offset).collect();
                    meshes.push(TruthMesh {
                        normals: crate::scene::area_weighted_normals(&positions, &mesh.triangles),
                        triangles: mesh.triangles.clone(),
                        positions,
                        material: *material,
                    });
                }
                TruthSource::Sphere {
                    center,
                    radius,
                    material,
                } => spheres.push((*center - scene.offset, *radius, *material)),
                TruthSource::Unknown { model, what } => {
                    return Err(Error::invalid(format!(
                        "model {model} is {what}: it has no exact surface to compare against \
                         (use `mesh` with `samples`, or a `shape`)"
                    )));
                }
            }
        }
        let device = Device::new()?;
        let refs: Vec<(&[Vec3], &[[u32; 3]])> = meshes
            .iter()
            .map(|m| (m.positions.as_slice(), m.triangles.as_slice()))
            .collect();
        let triangles = TriangleScene::new(&device, &refs)?;
        Ok(Truth {
            triangles,
            meshes,
            spheres,
            eps: scene.options.scale.eps_self,
        })
    }

    fn sphere_hit(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<(f32, usize)> {
        let mut best: Option<(f32, usize)> = None;
        for (i, &(c, r, _)) in self.spheres.iter().enumerate() {
            let oc = ray.origin - c;
            let b = oc.dot(ray.dir);
            let disc = b * b - (oc.length_squared() - r * r);
            if disc < 0.0 {
                continue;
            }
            let sq = disc.sqrt();
            for t in [-b - sq, -b + sq] {
                if t >= t_min && t <= t_max && best.is_none_or(|(bt, _)| t < bt) {
                    best = Some((t, i));
                    break;
                }
            }
        }
        best
    }
}

/// The hit of an exact surface at `t` (`point`), shading normal `normal`,
/// face normal `geometric`: nothing blended, shadow rays leave from the
/// point itself.
fn exact_hit(id: u32, t: f32, point: Vec3, normal: Vec3, geometric: Vec3, ray: &Ray) -> SurfaceHit {
    SurfaceHit {
        id,
        t,
        point,
        normal,
        geometric_normal: geometric,
        front: geometric.dot(ray.dir) < 0.0,
        blended: 1,
        shadow_origin: point,
    }
}

impl Surfaces for Truth {
    fn hit(
        &self,
        ray: &Ray,
        from: Option<&ShadeHit>,
        _hits: &mut CandidateHits,
    ) -> Option<ShadeHit> {
        let t_min = if from.is_some() { self.eps } else { 0.0 };
        let tri = self.triangles.intersect(ray, t_min, f32::INFINITY);
        let t_max = tri.map_or(f32::INFINITY, |h| h.t);
        if let Some((t, i)) = self.sphere_hit(ray, t_min, t_max) {
            let (c, _, material) = self.spheres[i];
            let point = ray.at(t);
            let n = (point - c).normalize();
            return Some(ShadeHit {
                surface: exact_hit(i as u32, t, point, n, n, ray),
                material,
                color: Vec3::ONE,
            });
        }
        let h = tri?;
        let m = &self.meshes[h.mesh as usize];
        let [a, b, c] = m.triangles[h.triangle as usize];
        let (pa, pb, pc) = (
            m.positions[a as usize],
            m.positions[b as usize],
            m.positions[c as usize],
        );
        let ng = (pb - pa).cross(pc - pa).normalize_or_zero();
        let ns = ((1.0 - h.u - h.v) * m.normals[a as usize]
            + h.u * m.normals[b as usize]
            + h.v * m.normals[c as usize])
            .try_normalize()
            .unwrap_or(ng);
        let ns = if ns.dot(ng) < 0.0 { -ns } else { ns };
        let point = ray.at(h.t);
        Some(ShadeHit {
            surface: exact_hit(h.triangle, h.t, point, ns, ng, ray),
            material: m.material,
            color: Vec3::ONE,
        })
    }

    /// Exact surfaces need no self-hit rule: a shadow ray skips only the
    /// first `eps_self`.
    fn occluded(&self, ray: &Ray, _from: &ShadeHit, t_max: f32) -> bool {
        let t_min = self.eps;
        self.sphere_hit(ray, t_min, t_max).is_some() || self.triangles.occluded(ray, t_min, t_max)
    }

    fn eps_self(&self) -> f32 {
        self.eps
    }
}
