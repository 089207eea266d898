//! What every scene of the module shares: the owned `RTCScene`, and rays,
//! hits and query contexts as Embree 4.3 and later lay them out.

use super::{Device, EmbreeError};
use crate::geometry::Ray;
use embree4_sys as sys;
use std::ffi::c_uint;

/// `RTCRayQueryContext` as Embree 4.3 and later lay it out: the
/// `embree4-sys` bindings come from the 4.2 headers, which lack the
/// `instPrimID` stack that a library built with instance arrays (the
/// default, and the PyPI build `scripts/setup.sh` installs) reads after
/// `instID` and copies into every hit. Without this field Embree reads past
/// the context.
#[repr(C)]
pub(super) struct RayQueryContext {
    base: sys::RTCRayQueryContext,
    inst_prim_id: [c_uint; 1],
}

/// `rtcInitRayQueryContext` (inline in `rtcore_ray.h`), for the layout of
/// [`RayQueryContext`].
pub(super) fn ray_query_context() -> RayQueryContext {
    RayQueryContext {
        base: sys::RTCRayQueryContext {
            instID: [sys::RTC_INVALID_GEOMETRY_ID; 1],
        },
        inst_prim_id: [sys::RTC_INVALID_GEOMETRY_ID; 1],
    }
}

/// An `RTCRayHit` with room after it for the fields Embree 4.3 and later
/// append to `RTCHit` (`instPrimID`, then padding to 16 bytes), which the
/// 4.2 bindings lack: Embree writes `instPrimID` with every triangle hit, so
/// a bare `RTCRayHit` would have it overwrite whatever follows on the stack.
#[repr(C)]
pub(super) struct RayHitSlot {
    pub(super) rayhit: sys::RTCRayHit,
    pub(super) tail: [c_uint; 4],
}

/// `rtcInitIntersectArguments` (inline in `rtcore_scene.h`), with the
/// context set.
pub(super) fn intersect_arguments(ctx: *mut sys::RTCRayQueryContext) -> sys::RTCIntersectArguments {
    sys::RTCIntersectArguments {
        flags: sys::RTCRayQueryFlags::INCOHERENT,
        feature_mask: sys::RTCFeatureFlags::RTC_FEATURE_FLAG_ALL,
        context: ctx,
        filter: None,
        intersect: None,
    }
}

/// `rtcInitOccludedArguments` (inline in `rtcore_scene.h`), with the
/// context set (null: Embree's default).
pub(super) fn occluded_arguments(ctx: *mut sys::RTCRayQueryContext) -> sys::RTCOccludedArguments {
    sys::RTCOccludedArguments {
        flags: sys::RTCRayQueryFlags::INCOHERENT,
        feature_mask: sys::RTCFeatureFlags::RTC_FEATURE_FLAG_ALL,
        context: ctx,
        filter: None,
        occluded: None,
    }
}

pub(super) fn embree_ray(ray: &Ray, t_min: f32, t_max: f32) -> sys::RTCRay {
    sys::RTCRay {
        org_x: ray.origin.x,
        org_y: ray.origin.y,
        org_z: ray.origin.z,
        tnear: t_min,
        dir_x: ray.dir.x,
        dir_y: ray.dir.y,
        dir_z: ray.dir.z,
        time: 0.0,
        tfar: t_max,
        mask: u32::MAX,
        id: 0,
        flags: 0,
    }
}

/// A ray with an empty hit record, as `rtcIntersect1` expects it, in a
/// [`RayHitSlot`].
pub(super) fn embree_rayhit(ray: &Ray, t_min: f32, t_max: f32) -> RayHitSlot {
    RayHitSlot {
        rayhit: sys::RTCRayHit {
            ray: embree_ray(ray, t_min, t_max),
            hit: sys::RTCHit {
                Ng_x: 0.0,
                Ng_y: 0.0,
                Ng_z: 0.0,
                u: 0.0,
                v: 0.0,
                primID: sys::RTC_INVALID_GEOMETRY_ID,
                geomID: sys::RTC_INVALID_GEOMETRY_ID,
                instID: [sys::RTC_INVALID_GEOMETRY_ID; 1],
            },
        },
        tail: [sys::RTC_INVALID_GEOMETRY_ID; 4],
    }
}

/// Rays in one packet of `rtcIntersect8` / `rtcOccluded8`.
pub(super) const LANES8: usize = 8;

/// An `RTCRayHit8` with room after it for the `instPrimID` lanes Embree
/// 4.3 and later append to `RTCHit8` (as [`RayHitSlot`] for one ray).
#[repr(C, align(32))]
pub(super) struct RayHit8Slot {
    pub(super) rayhit: sys::RTCRayHit8,
    pub(super) tail: [c_uint; LANES8],
}

/// The valid mask of a packet as Embree reads it: `-1` on active lanes,
/// `0` elsewhere, aligned to 32 bytes.
#[repr(C, align(32))]
pub(super) struct Valid8(pub(super) [i32; LANES8]);

/// The rays `(ray, t_min, t_max)` (at most 8) as an `RTCRay8` and its
/// valid mask; lane `k` carries `id = k`, which the callbacks read to find
/// the lane's query whether Embree hands them the packet or one ray of it.
pub(super) fn embree_ray8(rays: &[(Ray, f32, f32)]) -> (sys::RTCRay8, Valid8) {
    let mut r = sys::RTCRay8 {
        org_x: [0.0; LANES8],
        org_y: [0.0; LANES8],
        org_z: [0.0; LANES8],
        tnear: [0.0; LANES8],
        dir_x: [0.0; LANES8],
        dir_y: [0.0; LANES8],
        dir_z: [1.0; LANES8],
        time: [0.0; LANES8],
        tfar: [f32::NEG_INFINITY; LANES8],
        mask: [u32::MAX; LANES8],
        id: [0; LANES8],
        flags: [0; LANES8],
    };
    let mut valid = Valid8([0; LANES8]);
    for (k, (ray, t_min, t_max)) in rays.iter().enumerate().take(LANES8) {
        r.org_x[k] = ray.origin.x;
        r.org_y[k] = ray.origin.y;
        r.org_z[k] = ray.origin.z;
        r.tnear[k] = *t_min;
        r.dir_x[k] = ray.dir.x;
        r.dir_y[k] = ray.dir.y;
        r.dir_z[k] = ray.dir.z;
        r.tfar[k] = *t_max;
        r.id[k] = k as c_uint;
        valid.0[k] = -1;
    }
    (r, valid)
}

/// [`embree_ray8`] with empty hit records, as `rtcIntersect8` expects
/// them, in a [`RayHit8Slot`].
pub(super) fn embree_rayhit8(rays: &[(Ray, f32, f32)]) -> (RayHit8Slot, Valid8) {
    let (ray, valid) = embree_ray8(rays);
    let none = [sys::RTC_INVALID_GEOMETRY_ID; LANES8];
    let slot = RayHit8Slot {
        rayhit: sys::RTCRayHit8 {
            ray,
            hit: sys::RTCHit8 {
                Ng_x: [0.0; LANES8],
                Ng_y: [0.0; LANES8],
                Ng_z: [0.0; LANES8],
                u: [0.0; LANES8],
                v: [0.0; LANES8],
                primID: none,
                geomID: none,
                instID: [none; 1],
            },
        },
        tail: none,
    };
    (slot, valid)
}

/// The ray of a callback's `RTCRay` (the native discs' filter).
#[cfg(any(test, feature = "native-discs"))]
pub(super) fn ray_of(r: &sys::RTCRay) -> Ray {
    Ray {
        origin: glam::Vec3::new(r.org_x, r.org_y, r.org_z),
        dir: glam::Vec3::new(r.dir_x, r.dir_y, r.dir_z),
    }
}

/// An owned `RTCScene` of a device: released on drop.
pub(super) struct SceneHandle {
    pub(super) device: Device,
    pub(super) raw: sys::RTCScene,
}

impl SceneHandle {
    pub(super) fn new(device: &Device) -> Result<SceneHandle, EmbreeError> {
        // SAFETY: live device.
        let raw = unsafe { sys::rtcNewScene(device.inner.raw) };
        device.check()?;
        if raw.is_null() {
            return Err(EmbreeError("rtcNewScene returned null".into()));
        }
        Ok(SceneHandle {
            device: device.clone(),
            raw,
        })
    }

    pub(super) fn commit(&self) -> Result<(), EmbreeError> {
        // SAFETY: live scene, its geometries attached and committed.
        unsafe { sys::rtcCommitScene(self.raw) };
        self.device.check()
    }

    /// The nearest hit in `[t_min, t_max]` with Embree's default context
    /// (for scenes without user geometry: triangles, native discs).
    pub(super) fn intersect1(&self, ray: &Ray, t_min: f32, t_max: f32) -> RayHitSlot {
        let mut ctx = ray_query_context();
        let mut args = intersect_arguments((&mut ctx as *mut RayQueryContext).cast());
        let mut slot = embree_rayhit(ray, t_min, t_max);
        // SAFETY: committed scene (every constructor commits); all pointers
        // live across the call; the context and the slot have the layout and
        // room Embree 4.3+ uses; a scene with user callbacks does not come
        // here (it needs its own context).
        unsafe {
            sys::rtcIntersect1(self.raw, (&mut slot as *mut RayHitSlot).cast(), &mut args);
        };
        slot
    }

    /// True when anything is hit in `[t_min, t_max]`; `ctx` is handed to
    /// the user callbacks (null for Embree's default context).
    ///
    /// # Safety
    /// A non-null `ctx` must point to a live context of the type the
    /// scene's user callbacks read, valid for the whole call.
    pub(super) unsafe fn occluded(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        ctx: *mut sys::RTCRayQueryContext,
    ) -> bool {
        let mut r = embree_ray(ray, t_min, t_max);
        let mut args = occluded_arguments(ctx);
        // SAFETY: committed scene; `r` and `args` live across the call;
        // `ctx` as the caller guarantees.
        unsafe { sys::rtcOccluded1(self.raw, &mut r, &mut args) };
        r.tfar == f32::NEG_INFINITY
    }
}

impl Drop for SceneHandle {
    fn drop(&mut self) {
        // SAFETY: `raw` came from `rtcNewScene` and is released once.
        unsafe { sys::rtcReleaseScene(self.raw) };
    }
}

/// A new geometry of `kind` on `device`: the caller's reference, to fill,
/// commit, attach and release.
pub(super) fn new_geometry(
    device: &Device,
    kind: sys::RTCGeometryType,
) -> Result<sys::RTCGeometry, EmbreeError> {
    // SAFETY: live device; `kind` is one of Embree's geometry types.
    let geom = unsafe { sys::rtcNewGeometry(device.inner.raw, kind) };
    device.check()?;
    if geom.is_null() {
        return Err(EmbreeError("rtcNewGeometry returned null".into()));
    }
    Ok(geom)
}

/// A new buffer of `geom` holding `len` items of `N` values of `T` each (the
/// item Embree's `format` names: three `f32` for `FLOAT3`, three `u32` for
/// `UINT3`), as a slice to fill; `None` when Embree could not allocate it.
///
/// # Safety
/// `geom` is a live geometry, not yet committed, whose buffer of `kind`
/// nothing else writes; `format` is an item of `N` values of `T`; the slice
/// is not used after the geometry is released.
pub(super) unsafe fn new_buffer<'g, T, const N: usize>(
    geom: sys::RTCGeometry,
    kind: sys::RTCBufferType,
    format: sys::RTCFormat,
    len: usize,
) -> Option<&'g mut [[T; N]]> {
    let stride = N * std::mem::size_of::<T>();
    // SAFETY: `geom` as the caller guarantees; Embree allocates `len` items
    // of this stride (with its own padding, aligned to 16 bytes) and returns
    // a pointer valid until the geometry is released, or null.
    let p = unsafe { sys::rtcSetNewGeometryBuffer(geom, kind, 0, format, stride, len) };
    let p = p.cast::<[T; N]>();
    // SAFETY: a non-null `p` holds `len` items of `[T; N]` (the stride is
    // their size), aligned, and this slice is the only way to them.
    (!p.is_null()).then(|| unsafe { std::slice::from_raw_parts_mut(p, len) })
}

/// One buffer [`new_buffers`] makes: its kind, its format and how many
/// items.
pub(super) type BufferSpec = (sys::RTCBufferType, sys::RTCFormat, usize);

/// Two buffers of a geometry, to fill.
pub(super) type Buffers<'g, A, const N: usize, B, const M: usize> =
    (&'g mut [[A; N]], &'g mut [[B; M]]);

/// The two buffers `a` and `b` of `geom` ([`new_buffer`]) as slices to
/// fill; when Embree could not allocate either, `geom` is released (the
/// caller's reference to it is gone) and the error says which geometry's
/// (`what`) buffers failed.
///
/// # Safety
/// As [`new_buffer`], for both; `geom` is the caller's fresh geometry,
/// not used again after an error.
pub(super) unsafe fn new_buffers<'g, A, const N: usize, B, const M: usize>(
    device: &Device,
    geom: sys::RTCGeometry,
    a: BufferSpec,
    b: BufferSpec,
    what: &str,
) -> Result<Buffers<'g, A, N, B, M>, EmbreeError> {
    // SAFETY: as the caller guarantees.
    let buffers = unsafe {
        (
            new_buffer::<A, N>(geom, a.0, a.1, a.2),
            new_buffer::<B, M>(geom, b.0, b.1, b.2),
        )
    };
    let (Some(x), Some(y)) = buffers else {
        // SAFETY: the caller's reference to the fresh geometry, released
        // once (the caller uses it no more).
        unsafe { sys::rtcReleaseGeometry(geom) };
        device.check()?;
        return Err(EmbreeError(format!("could not allocate {what} buffers")));
    };
    Ok((x, y))
}

/// How far past the query's span Embree traverses, relative to the span's
/// ends and the ray origin's largest coordinate: 2⁻¹².
///
/// The span `[t_min, t_max]` is exact, and tested in the callbacks on the
/// `t` the primitive's intersection rounds (as the octree and the oracle
/// test it). Embree culls a box whose interval along the ray misses the
/// span it traverses; on a splat whose normal is an axis the box is a slab
/// a few ulps thick, and a hit's rounded `t` can lie just past the box's
/// exit (by a few ulps of the origin's coordinates over the ray's slope
/// through the slab). A span that starts at that very `t` (the resolver
/// gathering again from a candidate, [`crate::resolve::Resolved::Beyond`])
/// then lost the hit on Embree alone. Traversing a slightly wider span
/// costs a few more exact tests near its ends and changes no answer.
const SPAN_SLACK: f32 = 1.0 / 4096.0;

/// The span Embree traverses for the exact span `[t_min, t_max]` of `ray`:
/// each finite end moved out by [`SPAN_SLACK`] of its size and the origin's,
/// a start at or below 0 kept (Embree takes `tnear >= 0`).
pub(crate) fn traversal_span(ray: &Ray, t_min: f32, t_max: f32) -> (f32, f32) {
    let m = ray.origin.abs().max_element();
    let lo = if t_min > 0.0 && t_min.is_finite() {
        (t_min - (t_min + m) * SPAN_SLACK).max(0.0)
    } else {
        t_min
    };
    (lo, traversal_end(ray, t_max))
}

/// The far end Embree traverses to for the exact far end `t`.
pub(crate) fn traversal_end(ray: &Ray, t: f32) -> f32 {
    if t.is_finite() {
        t + (t.abs() + ray.origin.abs().max_element()) * SPAN_SLACK
    } else {
        t
    }
}
