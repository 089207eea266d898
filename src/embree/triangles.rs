//! Triangle meshes in Embree's own BVH: the exact surface, for ground
//! truth and the synthetic scanner.

use super::scene::{SceneHandle, new_buffers, new_geometry};
use super::{Device, EmbreeError};
use crate::geometry::Ray;
use embree4_sys as sys;
use std::ffi::c_uint;

/// One hit on a [`TriangleScene`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriangleHit {
    /// Ray parameter.
    pub t: f32,
    /// Index of the mesh (in the order given to [`TriangleScene::new`]).
    pub mesh: u32,
    /// Triangle index within the mesh.
    pub triangle: u32,
    /// Barycentric coordinates of the hit (weights of vertices 1 and 2).
    pub u: f32,
    /// See `u`.
    pub v: f32,
}

/// Triangle meshes in Embree's own BVH: the exact surface that splats
/// approximate, for ground truth.
pub struct TriangleScene {
    scene: SceneHandle,
}

// SAFETY: a committed Embree scene may be queried concurrently; it holds no
// Rust data.
unsafe impl Send for TriangleScene {}
// SAFETY: as above.
unsafe impl Sync for TriangleScene {}

impl TriangleScene {
    /// Builds one Embree triangle geometry per mesh and commits the scene.
    /// Triangles indexing past their vertices are rejected.
    pub fn new(
        device: &Device,
        meshes: &[(&[glam::Vec3], &[[u32; 3]])],
    ) -> Result<TriangleScene, EmbreeError> {
        let out = TriangleScene {
            scene: SceneHandle::new(device)?,
        };
        let scene = out.scene.raw;
        for (i, (verts, tris)) in meshes.iter().enumerate() {
            if let Some(bad) = tris.iter().flatten().find(|&&k| k as usize >= verts.len()) {
                return Err(EmbreeError(format!(
                    "mesh {i}: vertex index {bad} out of {} vertices",
                    verts.len()
                )));
            }
            let geom = new_geometry(device, sys::RTCGeometryType::TRIANGLE)?;
            // SAFETY: `geom` is a fresh triangle geometry, written only here;
            // FLOAT3 is three f32, UINT3 three u32; the slices are filled
            // before the geometry is released.
            let (vs, is) = unsafe {
                new_buffers::<f32, 3, u32, 3>(
                    device,
                    geom,
                    (
                        sys::RTCBufferType::VERTEX,
                        sys::RTCFormat::FLOAT3,
                        verts.len(),
                    ),
                    (sys::RTCBufferType::INDEX, sys::RTCFormat::UINT3, tris.len()),
                    "mesh",
                )?
            };
            for (dst, v) in vs.iter_mut().zip(verts.iter()) {
                *dst = v.to_array();
            }
            is.copy_from_slice(tris);
            // SAFETY: `geom` filled; attaching retains it, so our reference
            // is released right after.
            unsafe {
                sys::rtcCommitGeometry(geom);
                sys::rtcAttachGeometryByID(scene, geom, i as c_uint);
                sys::rtcReleaseGeometry(geom);
            }
            device.check()?;
        }
        out.scene.commit()?;
        Ok(out)
    }

    /// The nearest triangle hit in `[t_min, t_max]`.
    #[must_use]
    pub fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<TriangleHit> {
        let slot = self.scene.intersect1(ray, t_min, t_max);
        let h = &slot.rayhit.hit;
        (h.geomID != sys::RTC_INVALID_GEOMETRY_ID).then_some(TriangleHit {
            t: slot.rayhit.ray.tfar,
            mesh: h.geomID,
            triangle: h.primID,
            u: h.u,
            v: h.v,
        })
    }

    /// True when any triangle is hit in `[t_min, t_max]`.
    #[must_use]
    pub fn occluded(&self, ray: &Ray, t_min: f32, t_max: f32) -> bool {
        // SAFETY: null context: a triangle scene has no user callbacks.
        unsafe { self.scene.occluded(ray, t_min, t_max, std::ptr::null_mut()) }
    }

    /// Errors Embree reported since the last check.
    pub fn check(&self) -> Result<(), EmbreeError> {
        self.scene.device.check()
    }
}

#[cfg(test)]
mod tests {
    use super::super::scene::{
        RayHitSlot, RayQueryContext, embree_rayhit, intersect_arguments, ray_query_context,
    };
    use super::*;
    use glam::Vec3;

    /// Regression: the 4.2 headers of `embree4-sys` declare an `RTCHit`
    /// without the `instPrimID` that Embree 4.3 and later write with every
    /// triangle hit, just past the bindings' `RTCRayHit`; a bare `RTCRayHit`
    /// on the stack had that write land on the caller's next variable (it
    /// once replaced the y component of a ray's direction). The slot's tail
    /// must take the write, and the hit must be what the ray meets.
    #[test]
    fn triangle_hits_stay_inside_the_slot() {
        let device = Device::new().unwrap();
        let positions = [
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        ];
        let scene = TriangleScene::new(&device, &[(&positions[..], &[[0, 1, 2]][..])]).unwrap();
        let ray = Ray::new(Vec3::new(0.1, 0.0, 2.0), Vec3::new(0.0, 0.0, -1.0));
        let mut ctx = ray_query_context();
        let mut args = intersect_arguments((&mut ctx as *mut RayQueryContext).cast());
        let mut slot = embree_rayhit(&ray, 0.0, f32::INFINITY);
        let sentinel = 0x5eed_5eed;
        slot.tail = [sentinel; 4];
        // SAFETY: as in `TriangleScene::intersect`.
        unsafe {
            sys::rtcIntersect1(
                scene.scene.raw,
                (&mut slot as *mut RayHitSlot).cast(),
                &mut args,
            );
        };
        assert_eq!(slot.rayhit.hit.geomID, 0);
        // Embree's triangle kernel differs by CPU (an AVX2 machine returns
        // 1.9999999): a float of Embree's is compared within a few ulps.
        let t = slot.rayhit.ray.tfar;
        assert!((t - 2.0).abs() <= 4.0 * f32::EPSILON * 2.0, "tfar {t}");
        let (major, minor, _) = device.version();
        if (major, minor) >= (4, 3) {
            // Embree copied the context's `instPrimID` into the hit: the
            // first word of the tail, which the bindings' struct lacks.
            assert_eq!(
                slot.tail[0],
                sys::RTC_INVALID_GEOMETRY_ID,
                "Embree {major}.{minor} wrote no instPrimID past RTCHit"
            );
        }
        assert_eq!(slot.tail[1..], [sentinel; 3], "nothing beyond instPrimID");
    }
}
