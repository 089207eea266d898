//! The one module that speaks to Embree 4. All of the project's `unsafe` and
//! FFI lives here, behind a small safe API:
//!
//! * [`Device`]: an Embree device whose errors (reported through the error
//!   callback) become [`EmbreeError`]s, never silent zeros;
//! * [`DiscScene`]: splats registered as `RTC_GEOMETRY_TYPE_USER` primitives
//!   with tight disc bounds, queried for the candidate hits of a blending
//!   window (DESIGN §2, §7) and for occlusion.
//!
//! Raw Embree types never leave this module.

use crate::accel::{Candidate, CandidateHits, Ray, intersect_disc};
use crate::splat::{Disc, Splat};
use embree4_sys as sys;
use std::ffi::{CStr, CString, c_char, c_uint, c_void};
use std::fmt;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

/// An error reported by Embree (through the device error callback) or by
/// this wrapper.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EmbreeError(pub String);

impl fmt::Display for EmbreeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "embree: {}", self.0)
    }
}

impl std::error::Error for EmbreeError {}

/// Name of an `RTCError` code, read as a plain integer so that a code added
/// by a newer Embree than the headers know never becomes an invalid enum.
fn error_name(code: u32) -> &'static str {
    match code {
        0 => "no error",
        1 => "unknown error",
        2 => "invalid argument",
        3 => "invalid operation",
        4 => "out of memory",
        5 => "unsupported CPU",
        6 => "cancelled",
        _ => "error",
    }
}

/// Where the error callback leaves the first error until the wrapper reads it.
type ErrorSlot = Mutex<Option<EmbreeError>>;

/// The device error callback. Declared with the code as a plain `u32` (the
/// C enum's ABI) for the reason given at [`error_name`].
unsafe extern "C" fn on_error(user: *mut c_void, code: u32, msg: *const c_char) {
    if user.is_null() {
        return;
    }
    // SAFETY: `user` is the `ErrorSlot` boxed inside `DeviceInner`, which
    // outlives the device (the device is released in `DeviceInner::drop`
    // before the box is freed).
    let slot = unsafe { &*(user as *const ErrorSlot) };
    let text = if msg.is_null() {
        String::new()
    } else {
        // SAFETY: Embree passes a NUL-terminated string valid for the call.
        unsafe { CStr::from_ptr(msg) }
            .to_string_lossy()
            .into_owned()
    };
    if let Ok(mut s) = slot.lock() {
        if s.is_none() {
            *s = Some(EmbreeError(format!("{} ({text})", error_name(code))));
        }
    }
}

struct DeviceInner {
    raw: sys::RTCDevice,
    errors: Box<ErrorSlot>,
}

impl Drop for DeviceInner {
    fn drop(&mut self) {
        // SAFETY: `raw` came from `rtcNewDevice` and is released once; every
        // scene holds an `Arc<DeviceInner>`, so none outlives it.
        unsafe { sys::rtcReleaseDevice(self.raw) };
    }
}

// SAFETY: Embree devices are thread-safe; the error slot is a Mutex.
unsafe impl Send for DeviceInner {}
// SAFETY: as above.
unsafe impl Sync for DeviceInner {}

/// An Embree device. Cheap to clone (reference counted).
#[derive(Clone)]
pub struct Device {
    inner: Arc<DeviceInner>,
}

impl fmt::Debug for Device {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (a, b, c) = self.version();
        write!(f, "Device(embree {a}.{b}.{c})")
    }
}

impl Device {
    /// Creates a device with Embree's default configuration.
    pub fn new() -> Result<Device, EmbreeError> {
        Device::with_config("")
    }

    /// Creates a device from an Embree configuration string
    /// (e.g. `"threads=2"`).
    pub fn with_config(config: &str) -> Result<Device, EmbreeError> {
        let cfg = CString::new(config)
            .map_err(|_| EmbreeError("configuration string contains NUL".into()))?;
        // SAFETY: `cfg` is NUL-terminated and lives across the call.
        let raw = unsafe { sys::rtcNewDevice(cfg.as_ptr()) };
        if raw.is_null() {
            return Err(EmbreeError(
                "rtcNewDevice failed (unsupported CPU or bad configuration)".into(),
            ));
        }
        let errors: Box<ErrorSlot> = Box::new(Mutex::new(None));
        let callback: unsafe extern "C" fn(*mut c_void, u32, *const c_char) = on_error;
        // SAFETY: `RTCErrorFunction` takes `(void*, RTCError, const char*)`;
        // `RTCError` is a `repr(u32)` C enum, so `on_error` taking a `u32`
        // has the identical ABI.
        let callback: sys::RTCErrorFunction = unsafe { std::mem::transmute(Some(callback)) };
        let user = &*errors as *const ErrorSlot as *mut c_void;
        // SAFETY: `raw` is a live device; `user` points to the boxed slot
        // which lives as long as the device (see `DeviceInner`).
        unsafe { sys::rtcSetDeviceErrorFunction(raw, callback, user) };
        let dev = Device {
            inner: Arc::new(DeviceInner { raw, errors }),
        };
        dev.check()?;
        Ok(dev)
    }

    /// Takes the first error reported since the last check.
    fn check(&self) -> Result<(), EmbreeError> {
        match self.inner.errors.lock() {
            Ok(mut s) => s.take().map_or(Ok(()), Err),
            Err(_) => Err(EmbreeError("error slot poisoned".into())),
        }
    }

    fn property(&self, p: sys::RTCDeviceProperty) -> isize {
        // SAFETY: live device; the property is a valid enum value.
        unsafe { sys::rtcGetDeviceProperty(self.inner.raw, p) }
    }

    /// `(major, minor, patch)` as reported by the device itself.
    #[must_use]
    pub fn version(&self) -> (u32, u32, u32) {
        (
            self.property(sys::RTCDeviceProperty::VERSION_MAJOR) as u32,
            self.property(sys::RTCDeviceProperty::VERSION_MINOR) as u32,
            self.property(sys::RTCDeviceProperty::VERSION_PATCH) as u32,
        )
    }

    /// The path of the Embree shared library mapped into this process (read
    /// from `/proc/self/maps`), if it can be told.
    #[must_use]
    pub fn library_path() -> Option<PathBuf> {
        let maps = std::fs::read_to_string("/proc/self/maps").ok()?;
        maps.lines()
            .filter_map(|l| l.split_whitespace().nth(5))
            .find(|p| p.contains("libembree4"))
            .map(PathBuf::from)
    }
}

/// What the user-geometry callbacks read: the splat discs, addressed by
/// primitive id. Boxed so its address is stable while Embree holds it.
struct DiscData {
    discs: Vec<Disc>,
}

/// The per-ray query context: begins with `RTCRayQueryContext` so Embree can
/// hand it back to the callbacks, followed by where the candidates go.
#[repr(C)]
struct GatherContext {
    base: sys::RTCRayQueryContext,
    hits: *mut CandidateHits,
    t_max: f32,
}

/// `rtcInitRayQueryContext` (inline in `rtcore_ray.h`).
fn ray_query_context() -> sys::RTCRayQueryContext {
    sys::RTCRayQueryContext {
        instID: [sys::RTC_INVALID_GEOMETRY_ID; 1],
    }
}

/// `rtcInitIntersectArguments` (inline in `rtcore_scene.h`), with the
/// context set.
fn intersect_arguments(ctx: *mut sys::RTCRayQueryContext) -> sys::RTCIntersectArguments {
    sys::RTCIntersectArguments {
        flags: sys::RTCRayQueryFlags::INCOHERENT,
        feature_mask: sys::RTCFeatureFlags::RTC_FEATURE_FLAG_ALL,
        context: ctx,
        filter: None,
        intersect: None,
    }
}

/// `rtcInitOccludedArguments` (inline in `rtcore_scene.h`).
fn occluded_arguments() -> sys::RTCOccludedArguments {
    sys::RTCOccludedArguments {
        flags: sys::RTCRayQueryFlags::INCOHERENT,
        feature_mask: sys::RTCFeatureFlags::RTC_FEATURE_FLAG_ALL,
        context: std::ptr::null_mut(),
        filter: None,
        occluded: None,
    }
}

fn embree_ray(ray: &Ray, t_min: f32, t_max: f32) -> sys::RTCRay {
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

/// A ray with an empty hit record, as `rtcIntersect1` expects it.
fn embree_rayhit(ray: &Ray, t_min: f32, t_max: f32) -> sys::RTCRayHit {
    sys::RTCRayHit {
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
    }
}

/// Bounds callback: the tight box of the disc, padded by a few ulps of its
/// coordinates so that rounding can never cull a real hit.
unsafe extern "C" fn disc_bounds(args: *const sys::RTCBoundsFunctionArguments) {
    // SAFETY: Embree passes valid arguments for the duration of the call;
    // `geometryUserPtr` is the `DiscData` set in `DiscScene::new`, alive
    // while the scene is.
    let args = unsafe { &*args };
    let data = unsafe { &*(args.geometryUserPtr as *const DiscData) };
    let d = &data.discs[args.primID as usize];
    // Half extents from the scaled axes: |u_scaled| = 1/r_u.
    let ru = 1.0 / d.u_scaled.length();
    let rv = 1.0 / d.v_scaled.length();
    let a = d.u_scaled * (ru * ru);
    let b = d.v_scaled * (rv * rv);
    let h = (a * a + b * b).map(f32::sqrt);
    let pad = (d.center.abs() + h) * 4.0 * f32::EPSILON;
    let lo = d.center - h - pad;
    let hi = d.center + h + pad;
    // SAFETY: `bounds_o` points to one writable RTCBounds.
    let out = unsafe { &mut *args.bounds_o };
    out.lower_x = lo.x;
    out.lower_y = lo.y;
    out.lower_z = lo.z;
    out.upper_x = hi.x;
    out.upper_y = hi.y;
    out.upper_z = hi.z;
}

/// Intersect callback, following Embree's user-geometry contract: skip
/// invalid lanes, accept only hits with `tnear <= t <= tfar`, and update
/// `tfar` together with the hit. Instead of keeping only the closest hit it
/// records every hit into the [`GatherContext`]'s window and moves `tfar` to
/// `min(t_max, nearest + xi)`, so Embree culls everything beyond the window.
/// The same primitive may be offered twice; the window dedupes by id.
unsafe extern "C" fn disc_intersect(args: *const sys::RTCIntersectFunctionNArguments) {
    // SAFETY: valid for the call; `N == 1` since only `rtcIntersect1` is used
    // (checked), so `rayhit` is an `RTCRayHit` and `valid` has one lane.
    let args = unsafe { &*args };
    if args.N != 1 || unsafe { *args.valid } == 0 {
        return;
    }
    // SAFETY: user pointer is the scene's `DiscData` (see `disc_bounds`).
    let data = unsafe { &*(args.geometryUserPtr as *const DiscData) };
    // SAFETY: the context is the `GatherContext` passed by
    // `DiscScene::intersect` (it begins with `RTCRayQueryContext`, repr(C)),
    // and its `hits` pointer is a live `&mut CandidateHits` for this query.
    let ctx = unsafe { &mut *(args.context as *mut GatherContext) };
    let hits = unsafe { &mut *ctx.hits };
    let rayhit = unsafe { &mut *(args.rayhit as *mut sys::RTCRayHit) };
    let r = &mut rayhit.ray;
    let ray = Ray {
        origin: glam::Vec3::new(r.org_x, r.org_y, r.org_z),
        dir: glam::Vec3::new(r.dir_x, r.dir_y, r.dir_z),
    };
    let d = &data.discs[args.primID as usize];
    if let Some((t, u, v)) = intersect_disc(d, &ray, r.tnear, r.tfar) {
        let far = hits.offer(Candidate {
            id: args.primID,
            t,
            u,
            v,
        });
        r.tfar = far.min(ctx.t_max);
        let h = &mut rayhit.hit;
        h.Ng_x = d.normal.x;
        h.Ng_y = d.normal.y;
        h.Ng_z = d.normal.z;
        h.u = u;
        h.v = v;
        h.primID = args.primID;
        h.geomID = args.geomID;
    }
}

/// Occluded callback: any hit in `[tnear, tfar]` ends the query, signalled
/// by setting `tfar = -inf` as Embree requires.
unsafe extern "C" fn disc_occluded(args: *const sys::RTCOccludedFunctionNArguments) {
    // SAFETY: as in `disc_intersect`; `ray` is an `RTCRay` for `N == 1`.
    let args = unsafe { &*args };
    if args.N != 1 || unsafe { *args.valid } == 0 {
        return;
    }
    let data = unsafe { &*(args.geometryUserPtr as *const DiscData) };
    let r = unsafe { &mut *(args.ray as *mut sys::RTCRay) };
    let ray = Ray {
        origin: glam::Vec3::new(r.org_x, r.org_y, r.org_z),
        dir: glam::Vec3::new(r.dir_x, r.dir_y, r.dir_z),
    };
    let d = &data.discs[args.primID as usize];
    if intersect_disc(d, &ray, r.tnear, r.tfar).is_some() {
        r.tfar = f32::NEG_INFINITY;
    }
}

/// An owned `RTCScene` of a device: released on drop.
struct SceneHandle {
    device: Device,
    raw: sys::RTCScene,
}

impl SceneHandle {
    fn new(device: &Device) -> Result<SceneHandle, EmbreeError> {
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

    fn commit(&self) -> Result<(), EmbreeError> {
        // SAFETY: live scene, its geometries attached and committed.
        unsafe { sys::rtcCommitScene(self.raw) };
        self.device.check()
    }

    /// True when anything is hit in `[t_min, t_max]`.
    fn occluded(&self, ray: &Ray, t_min: f32, t_max: f32) -> bool {
        let mut r = embree_ray(ray, t_min, t_max);
        let mut args = occluded_arguments();
        // SAFETY: committed scene; `r` and `args` live across the call.
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

/// Splats as Embree user-geometry discs, committed and ready to query from
/// any number of threads.
pub struct DiscScene {
    // Declared first, so dropped (released) before `_data`.
    scene: SceneHandle,
    // Read by the callbacks through the raw pointer given to Embree; must
    // outlive `scene`.
    _data: Box<DiscData>,
}

// SAFETY: a committed Embree scene may be queried concurrently; `DiscData`
// is only read.
unsafe impl Send for DiscScene {}
// SAFETY: as above.
unsafe impl Sync for DiscScene {}

impl DiscScene {
    /// Registers every splat as one user primitive and commits the scene.
    pub fn new(device: &Device, splats: &[Splat]) -> Result<DiscScene, EmbreeError> {
        let count = c_uint::try_from(splats.len())
            .map_err(|_| EmbreeError(format!("{} splats exceed 2^32", splats.len())))?;
        let data = Box::new(DiscData {
            discs: splats.iter().map(Splat::disc_geometry).collect(),
        });
        let raw = device.inner.raw;
        let out = DiscScene {
            scene: SceneHandle::new(device)?,
            _data: data,
        };
        let scene = out.scene.raw;
        if count > 0 {
            // SAFETY: live device; USER is a valid geometry type.
            let geom = unsafe { sys::rtcNewGeometry(raw, sys::RTCGeometryType::USER) };
            device.check()?;
            let user = &*out._data as *const DiscData as *mut c_void;
            // SAFETY: `geom` is a fresh user geometry; the callbacks have the
            // signatures Embree expects; `user` stays valid as long as the
            // scene (owned by `out`). Attaching retains the geometry, so our
            // reference is released right after.
            unsafe {
                sys::rtcSetGeometryUserPrimitiveCount(geom, count);
                sys::rtcSetGeometryUserData(geom, user);
                sys::rtcSetGeometryBoundsFunction(geom, Some(disc_bounds), std::ptr::null_mut());
                sys::rtcSetGeometryIntersectFunction(geom, Some(disc_intersect));
                sys::rtcSetGeometryOccludedFunction(geom, Some(disc_occluded));
                sys::rtcCommitGeometry(geom);
                sys::rtcAttachGeometry(scene, geom);
                sys::rtcReleaseGeometry(geom);
            }
            device.check()?;
        }
        out.scene.commit()?;
        Ok(out)
    }

    /// Fills `hits` (cleared first) with the candidate window of `ray` in
    /// `[t_min, t_max]` (DESIGN §2).
    pub fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32, hits: &mut CandidateHits) {
        hits.clear();
        let mut ctx = GatherContext {
            base: ray_query_context(),
            hits: hits as *mut CandidateHits,
            t_max,
        };
        let mut args = intersect_arguments(&mut ctx.base as *mut sys::RTCRayQueryContext);
        let mut rayhit = embree_rayhit(ray, t_min, t_max);
        // SAFETY: committed scene; `rayhit` and `args` live across the call;
        // `args.context` points at `ctx.base`, the first field of the repr(C)
        // `GatherContext` whose `hits` borrows `hits` mutably for the call.
        unsafe { sys::rtcIntersect1(self.scene.raw, &mut rayhit, &mut args) };
    }

    /// True when any splat is hit in `[t_min, t_max]`.
    #[must_use]
    pub fn occluded(&self, ray: &Ray, t_min: f32, t_max: f32) -> bool {
        self.scene.occluded(ray, t_min, t_max)
    }

    /// Errors reported by Embree since the last check (queries do not report
    /// errors per call: check after a batch).
    pub fn check(&self) -> Result<(), EmbreeError> {
        self.scene.device.check()
    }
}

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
        let raw = device.inner.raw;
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
            // SAFETY: live device; TRIANGLE is a valid type.
            let geom = unsafe { sys::rtcNewGeometry(raw, sys::RTCGeometryType::TRIANGLE) };
            device.check()?;
            if geom.is_null() {
                return Err(EmbreeError("rtcNewGeometry returned null".into()));
            }
            // SAFETY: `geom` is a fresh triangle geometry; Embree allocates
            // each buffer for `len` items of the given stride (with its own
            // padding) and returns a pointer valid until the geometry is
            // released; we check it for null and fill exactly `len` items.
            unsafe {
                let vb = sys::rtcSetNewGeometryBuffer(
                    geom,
                    sys::RTCBufferType::VERTEX,
                    0,
                    sys::RTCFormat::FLOAT3,
                    12,
                    verts.len(),
                ) as *mut f32;
                let ib = sys::rtcSetNewGeometryBuffer(
                    geom,
                    sys::RTCBufferType::INDEX,
                    0,
                    sys::RTCFormat::UINT3,
                    12,
                    tris.len(),
                ) as *mut u32;
                if vb.is_null() || ib.is_null() {
                    sys::rtcReleaseGeometry(geom);
                    device.check()?;
                    return Err(EmbreeError("could not allocate mesh buffers".into()));
                }
                let vs = std::slice::from_raw_parts_mut(vb, verts.len() * 3);
                for (dst, v) in vs.chunks_exact_mut(3).zip(verts.iter()) {
                    dst.copy_from_slice(&v.to_array());
                }
                let is = std::slice::from_raw_parts_mut(ib, tris.len() * 3);
                for (dst, t) in is.chunks_exact_mut(3).zip(tris.iter()) {
                    dst.copy_from_slice(t);
                }
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
        let mut ctx = ray_query_context();
        let mut args = intersect_arguments(&mut ctx as *mut sys::RTCRayQueryContext);
        let mut rayhit = embree_rayhit(ray, t_min, t_max);
        // SAFETY: committed scene; all pointers live across the call.
        unsafe { sys::rtcIntersect1(self.scene.raw, &mut rayhit, &mut args) };
        let h = &rayhit.hit;
        (h.geomID != sys::RTC_INVALID_GEOMETRY_ID).then_some(TriangleHit {
            t: rayhit.ray.tfar,
            mesh: h.geomID,
            triangle: h.primID,
            u: h.u,
            v: h.v,
        })
    }

    /// True when any triangle is hit in `[t_min, t_max]`.
    #[must_use]
    pub fn occluded(&self, ray: &Ray, t_min: f32, t_max: f32) -> bool {
        self.scene.occluded(ray, t_min, t_max)
    }

    /// Errors Embree reported since the last check.
    pub fn check(&self) -> Result<(), EmbreeError> {
        self.scene.device.check()
    }
}
