//! The one module that speaks to Embree 4. All of the project's `unsafe` and
//! FFI lives here, behind a small safe API:
//!
//! * [`Device`]: an Embree device whose errors (reported through the error
//!   callback) become [`EmbreeError`]s, never silent zeros;
//!   Its memory monitor counts the bytes Embree allocates
//!   ([`Device::memory`]);
//! * [`UserScene`]: a scene of one `RTC_GEOMETRY_TYPE_USER` geometry whose
//!   bounds, intersect and occluded callbacks call a [`UserGeometry`]
//!   implemented in safe code (the splat backend implements it beside the
//!   backend, in `accel::embree`): this module knows nothing of splats;
//! * [`TriangleScene`]: triangle meshes in Embree's own BVH (ground truth).
//!
//! Raw Embree types never leave this module.

use crate::geometry::Ray;
use embree4_sys as sys;
use std::ffi::{CStr, CString, c_char, c_uint, c_void};
use std::fmt;
use std::path::PathBuf;
use std::sync::atomic::{AtomicI64, Ordering};
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

unsafe extern "C" {
    /// `rtcGetDeviceError`, declared returning the `RTCError` C enum as a
    /// plain `u32` (its ABI) for the reason given at [`error_name`].
    #[allow(clashing_extern_declarations)]
    #[link_name = "rtcGetDeviceError"]
    fn device_error_code(device: sys::RTCDevice) -> u32;
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
    if let Ok(mut s) = slot.lock()
        && s.is_none()
    {
        *s = Some(EmbreeError(format!("{} ({text})", error_name(code))));
    }
}

/// What the memory monitor callback counts: bytes Embree holds now, and the
/// most it held since the last [`Device::reset_peak`].
#[derive(Default)]
struct MemoryCount {
    current: AtomicI64,
    peak: AtomicI64,
}

/// The device memory monitor: Embree reports each allocation (positive
/// `bytes`) and each release (negative) once; nothing is refused.
unsafe extern "C" fn on_memory(user: *mut c_void, bytes: isize, _post: bool) -> bool {
    if user.is_null() {
        return true;
    }
    // SAFETY: `user` is the `MemoryCount` boxed inside `DeviceInner`, which
    // outlives the device (released in `DeviceInner::drop` before the box).
    let count = unsafe { &*(user as *const MemoryCount) };
    let now = count.current.fetch_add(bytes as i64, Ordering::Relaxed) + bytes as i64;
    count.peak.fetch_max(now, Ordering::Relaxed);
    true
}

struct DeviceInner {
    raw: sys::RTCDevice,
    errors: Box<ErrorSlot>,
    memory: Box<MemoryCount>,
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

/// The environment variable whose value, when set, is the configuration
/// [`Device::new`] hands to `rtcNewDevice`: e.g. `isa=sse4.2`, `isa=avx2`,
/// `isa=avx512` to force the kernels Embree runs (it otherwise picks the
/// widest the CPU has, so float results of its native primitives differ in
/// the last bits from machine to machine), or `threads=2`.
pub const CONFIG_VAR: &str = "SPLATRAY_EMBREE_CONFIG";

/// The configuration [`Device::new`] uses: the value of [`CONFIG_VAR`], or
/// the empty string (Embree's defaults) when it is unset or not UTF-8.
#[must_use]
pub fn config_in_force() -> String {
    std::env::var(CONFIG_VAR).unwrap_or_default()
}

/// The ISAs of Embree's kernels (the names its `isa=` option takes) that
/// this CPU can run, narrowest first. Embree's own grouping: `avx2` needs
/// FMA, BMI1/2, LZCNT and F16C besides AVX2; `avx512` the SKX set (F, CD,
/// DQ, BW, VL) besides.
#[must_use]
pub fn cpu_isas() -> Vec<&'static str> {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::is_x86_feature_detected as has;
        let mut isas = vec!["sse2"];
        if has!("sse4.2") {
            isas.push("sse4.2");
            if has!("avx") {
                isas.push("avx");
                if has!("avx2")
                    && has!("fma")
                    && has!("bmi1")
                    && has!("bmi2")
                    && has!("lzcnt")
                    && has!("f16c")
                {
                    isas.push("avx2");
                    if has!("avx512f")
                        && has!("avx512cd")
                        && has!("avx512dq")
                        && has!("avx512bw")
                        && has!("avx512vl")
                    {
                        isas.push("avx512");
                    }
                }
            }
        }
        isas
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        Vec::new()
    }
}

/// The ISA names Embree's `isa=`, `max_isa=` and `max_builder_isa=` options
/// know. Embree reads any other name as `sse2` without a word, so a typo
/// would quietly run the narrowest kernels: refused here instead.
const ISA_NAMES: [&str; 13] = [
    "sse", "sse2", "sse3", "ssse3", "sse41", "sse4.1", "sse42", "sse4.2", "avx", "avxi", "avx2",
    "avx512", "apx",
];

fn check_isa_names(config: &str) -> Result<(), EmbreeError> {
    for part in config.split(',') {
        let Some((key, value)) = part.split_once('=') else {
            continue;
        };
        let key = key.trim();
        let value = value.trim().to_ascii_lowercase();
        if matches!(key, "isa" | "max_isa" | "max_builder_isa")
            && !ISA_NAMES.contains(&value.as_str())
        {
            return Err(EmbreeError(format!(
                "unknown ISA `{value}` for `{key}` in configuration `{config}` \
                 (Embree knows {}; this CPU runs {})",
                ISA_NAMES.join(", "),
                cpu_isas().join(", ")
            )));
        }
    }
    Ok(())
}

impl Device {
    /// Creates a device with the configuration in force: the value of
    /// [`CONFIG_VAR`] when set, Embree's defaults otherwise.
    pub fn new() -> Result<Device, EmbreeError> {
        let config = config_in_force();
        Device::with_config(&config).map_err(|e| {
            if config.is_empty() {
                e
            } else {
                EmbreeError(format!("{} (from {CONFIG_VAR})", e.0))
            }
        })
    }

    /// Creates a device from an Embree configuration string
    /// (e.g. `"threads=2"`, `"isa=avx2"`).
    pub fn with_config(config: &str) -> Result<Device, EmbreeError> {
        check_isa_names(config)?;
        let cfg = CString::new(config)
            .map_err(|_| EmbreeError("configuration string contains NUL".into()))?;
        // SAFETY: `cfg` is NUL-terminated and lives across the call.
        let raw = unsafe { sys::rtcNewDevice(cfg.as_ptr()) };
        if raw.is_null() {
            // SAFETY: a null device asks for the error of the failed
            // `rtcNewDevice` on this thread, which Embree keeps for it; the
            // code is read as a plain integer (see `device_error_code`).
            let code = unsafe { device_error_code(std::ptr::null_mut()) };
            let why = match error_name(code) {
                "unsupported CPU" => "this CPU lacks the ISA the configuration asks for",
                "no error" | "error" | "unknown error" => "unknown reason",
                other => other,
            };
            return Err(EmbreeError(format!(
                "rtcNewDevice failed: {why} (configuration `{config}`; \
                 this CPU runs {})",
                cpu_isas().join(", ")
            )));
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
        let memory: Box<MemoryCount> = Box::default();
        let user = &*memory as *const MemoryCount as *mut c_void;
        // SAFETY: as above, for the boxed memory count; `on_memory` has the
        // signature of `RTCMemoryMonitorFunction`.
        unsafe { sys::rtcSetDeviceMemoryMonitorFunction(raw, Some(on_memory), user) };
        let dev = Device {
            inner: Arc::new(DeviceInner {
                raw,
                errors,
                memory,
            }),
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

    /// Bytes Embree holds for this device now, as its memory monitor
    /// callback reported them (scenes, BVHs, geometry buffers).
    #[must_use]
    pub fn memory(&self) -> usize {
        self.inner.memory.current.load(Ordering::Relaxed).max(0) as usize
    }

    /// The most bytes held at once since the device was made or the last
    /// [`Device::reset_peak`].
    #[must_use]
    pub fn peak_memory(&self) -> usize {
        self.inner.memory.peak.load(Ordering::Relaxed).max(0) as usize
    }

    /// Restarts the peak from the bytes held now.
    pub fn reset_peak(&self) {
        let m = &self.inner.memory;
        m.peak
            .store(m.current.load(Ordering::Relaxed), Ordering::Relaxed);
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

/// A user geometry: the primitives of a [`UserScene`], asked about by
/// Embree's callbacks one primitive at a time (Embree's user-geometry
/// contract, restated: the callbacks skip invalid lanes, accept only hits
/// with `tnear <= t <= tfar`, and update `tfar` together with the hit).
pub trait UserGeometry: Send + Sync + 'static {
    /// What one [`UserScene::intersect`] call carries to the callbacks
    /// (e.g. the window of candidate hits being gathered).
    type Query<'q>;

    /// What one [`UserScene::occluded`] call carries to the callbacks (e.g.
    /// which hits to skip).
    type ShadowQuery<'q>;

    /// How many primitives.
    fn count(&self) -> usize;

    /// The box `(lower, upper)` of primitive `prim`; it must contain every
    /// point [`UserGeometry::intersect`] can accept.
    fn bounds(&self, prim: u32) -> ([f32; 3], [f32; 3]);

    /// Tests primitive `prim` with `tnear <= t <= tfar`. Returns the new
    /// `tfar` (at most the old) when the hit is accepted, `None` otherwise.
    /// Embree culls everything beyond the returned `tfar`.
    fn intersect(
        &self,
        prim: u32,
        ray: &Ray,
        tnear: f32,
        tfar: f32,
        query: &mut Self::Query<'_>,
    ) -> Option<f32>;

    /// True when primitive `prim` is hit with `tnear <= t <= tfar` (a hit
    /// that counts for `query`).
    fn occluded(
        &self,
        prim: u32,
        ray: &Ray,
        tnear: f32,
        tfar: f32,
        query: &Self::ShadowQuery<'_>,
    ) -> bool;
}

/// The per-ray query context: begins with `RTCRayQueryContext` so Embree can
/// hand it back to the callbacks, followed by where the candidates go.
#[repr(C)]
struct QueryContext<'q, G: UserGeometry> {
    base: RayQueryContext,
    query: *mut G::Query<'q>,
}

/// The per-ray context of an occlusion query, laid out like
/// [`QueryContext`]: Embree's context first, then the shadow query.
#[repr(C)]
struct ShadowContext<'q, G: UserGeometry> {
    base: RayQueryContext,
    query: *const G::ShadowQuery<'q>,
}

/// `RTCRayQueryContext` as Embree 4.3 and later lay it out: the
/// `embree4-sys` bindings come from the 4.2 headers, which lack the
/// `instPrimID` stack that a library built with instance arrays (the
/// default, and the PyPI build `scripts/setup.sh` installs) reads after
/// `instID` and copies into every hit. Without this field Embree reads past
/// the context.
#[repr(C)]
struct RayQueryContext {
    base: sys::RTCRayQueryContext,
    inst_prim_id: [c_uint; 1],
}

/// `rtcInitRayQueryContext` (inline in `rtcore_ray.h`), for the layout of
/// [`RayQueryContext`].
fn ray_query_context() -> RayQueryContext {
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
struct RayHitSlot {
    rayhit: sys::RTCRayHit,
    tail: [c_uint; 4],
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

/// `rtcInitOccludedArguments` (inline in `rtcore_scene.h`), with the
/// context set (null: Embree's default).
fn occluded_arguments(ctx: *mut sys::RTCRayQueryContext) -> sys::RTCOccludedArguments {
    sys::RTCOccludedArguments {
        flags: sys::RTCRayQueryFlags::INCOHERENT,
        feature_mask: sys::RTCFeatureFlags::RTC_FEATURE_FLAG_ALL,
        context: ctx,
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

/// A ray with an empty hit record, as `rtcIntersect1` expects it, in a
/// [`RayHitSlot`].
fn embree_rayhit(ray: &Ray, t_min: f32, t_max: f32) -> RayHitSlot {
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

/// The ray of a callback's `RTCRay`.
fn ray_of(r: &sys::RTCRay) -> Ray {
    Ray {
        origin: glam::Vec3::new(r.org_x, r.org_y, r.org_z),
        dir: glam::Vec3::new(r.dir_x, r.dir_y, r.dir_z),
    }
}

/// Bounds callback: the box [`UserGeometry::bounds`] gives.
unsafe extern "C" fn user_bounds<G: UserGeometry>(args: *const sys::RTCBoundsFunctionArguments) {
    // SAFETY: Embree passes valid arguments for the duration of the call;
    // `geometryUserPtr` is the `G` boxed in `UserScene::new`, alive while
    // the scene is.
    let args = unsafe { &*args };
    let geom = unsafe { &*(args.geometryUserPtr as *const G) };
    let (lo, hi) = geom.bounds(args.primID);
    // SAFETY: `bounds_o` points to one writable RTCBounds.
    let out = unsafe { &mut *args.bounds_o };
    [out.lower_x, out.lower_y, out.lower_z] = lo;
    [out.upper_x, out.upper_y, out.upper_z] = hi;
}

/// Intersect callback: [`UserGeometry::intersect`] decides; an accepted hit
/// moves `tfar` and records the primitive in the hit. The same primitive
/// may be offered twice; the query must cope (the candidate window dedupes
/// by id).
unsafe extern "C" fn user_intersect<G: UserGeometry>(
    args: *const sys::RTCIntersectFunctionNArguments,
) {
    // SAFETY: valid for the call; `N == 1` since only `rtcIntersect1` is used
    // (checked), so `rayhit` is an `RTCRayHit` and `valid` has one lane.
    let args = unsafe { &*args };
    if args.N != 1 || unsafe { *args.valid } == 0 {
        return;
    }
    // SAFETY: user pointer as in `user_bounds`; the context is the
    // `QueryContext<G>` passed by `UserScene::intersect` (it begins with
    // `RTCRayQueryContext`, repr(C)), whose `query` is a live `&mut` for
    // this call.
    let geom = unsafe { &*(args.geometryUserPtr as *const G) };
    let ctx = unsafe { &mut *(args.context as *mut QueryContext<'_, G>) };
    let query = unsafe { &mut *ctx.query };
    let rayhit = unsafe { &mut *(args.rayhit as *mut sys::RTCRayHit) };
    let r = &mut rayhit.ray;
    if let Some(tfar) = geom.intersect(args.primID, &ray_of(r), r.tnear, r.tfar, query) {
        r.tfar = tfar;
        rayhit.hit.primID = args.primID;
        rayhit.hit.geomID = args.geomID;
    }
}

/// Occluded callback: any hit in `[tnear, tfar]` ends the query, signalled
/// by setting `tfar = -inf` as Embree requires.
unsafe extern "C" fn user_occluded<G: UserGeometry>(
    args: *const sys::RTCOccludedFunctionNArguments,
) {
    // SAFETY: as in `user_intersect`; `ray` is an `RTCRay` for `N == 1`.
    let args = unsafe { &*args };
    if args.N != 1 || unsafe { *args.valid } == 0 {
        return;
    }
    // SAFETY: user pointer as in `user_bounds`; the context is the
    // `ShadowContext<G>` passed by `UserScene::occluded` (it begins with
    // `RTCRayQueryContext`, repr(C)), whose `query` is a live shared
    // reference for this call.
    let geom = unsafe { &*(args.geometryUserPtr as *const G) };
    let ctx = unsafe { &*(args.context as *const ShadowContext<'_, G>) };
    let query = unsafe { &*ctx.query };
    let r = unsafe { &mut *(args.ray as *mut sys::RTCRay) };
    if geom.occluded(args.primID, &ray_of(r), r.tnear, r.tfar, query) {
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

    /// The nearest hit in `[t_min, t_max]` with Embree's default context
    /// (for scenes without user geometry: triangles, native discs).
    fn intersect1(&self, ray: &Ray, t_min: f32, t_max: f32) -> RayHitSlot {
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
    unsafe fn occluded(
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

/// A committed scene of one user geometry `G`, ready to query from any
/// number of threads.
pub struct UserScene<G: UserGeometry> {
    // Declared first, so dropped (released) before `geometry`.
    scene: SceneHandle,
    // Read by the callbacks through the raw pointer given to Embree; must
    // outlive `scene`.
    geometry: Box<G>,
}

// SAFETY: a committed Embree scene may be queried concurrently; `G` is
// `Send + Sync` and only read through `&G`.
unsafe impl<G: UserGeometry> Send for UserScene<G> {}
// SAFETY: as above.
unsafe impl<G: UserGeometry> Sync for UserScene<G> {}

impl<G: UserGeometry> UserScene<G> {
    /// Registers the primitives of `geometry` as one user geometry and
    /// commits the scene.
    pub fn new(device: &Device, geometry: G) -> Result<UserScene<G>, EmbreeError> {
        let count = c_uint::try_from(geometry.count())
            .map_err(|_| EmbreeError(format!("{} primitives exceed 2^32", geometry.count())))?;
        let raw = device.inner.raw;
        let out = UserScene {
            scene: SceneHandle::new(device)?,
            geometry: Box::new(geometry),
        };
        let scene = out.scene.raw;
        if count > 0 {
            // SAFETY: live device; USER is a valid geometry type.
            let geom = unsafe { sys::rtcNewGeometry(raw, sys::RTCGeometryType::USER) };
            device.check()?;
            let user = &*out.geometry as *const G as *mut c_void;
            // SAFETY: `geom` is a fresh user geometry; the callbacks have the
            // signatures Embree expects and read `user` as a `G`, which stays
            // valid as long as the scene (owned by `out`). Attaching retains
            // the geometry, so our reference is released right after.
            unsafe {
                sys::rtcSetGeometryUserPrimitiveCount(geom, count);
                sys::rtcSetGeometryUserData(geom, user);
                sys::rtcSetGeometryBoundsFunction(
                    geom,
                    Some(user_bounds::<G>),
                    std::ptr::null_mut(),
                );
                sys::rtcSetGeometryIntersectFunction(geom, Some(user_intersect::<G>));
                sys::rtcSetGeometryOccludedFunction(geom, Some(user_occluded::<G>));
                sys::rtcCommitGeometry(geom);
                sys::rtcAttachGeometry(scene, geom);
                sys::rtcReleaseGeometry(geom);
            }
            device.check()?;
        }
        out.scene.commit()?;
        Ok(out)
    }

    /// The geometry the callbacks read.
    #[must_use]
    pub fn geometry(&self) -> &G {
        &self.geometry
    }

    /// Traces `ray` over `[t_min, t_max]`, handing `query` to every
    /// [`UserGeometry::intersect`] call it makes.
    pub fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32, query: &mut G::Query<'_>) {
        let mut ctx = QueryContext::<G> {
            base: ray_query_context(),
            query: query as *mut G::Query<'_>,
        };
        let mut args = intersect_arguments((&mut ctx as *mut QueryContext<'_, G>).cast());
        let mut slot = embree_rayhit(ray, t_min, t_max);
        // SAFETY: committed scene; `slot` and `args` live across the call,
        // the slot with room for the hit Embree writes; `args.context`
        // points at the repr(C) `QueryContext<G>`, which begins with the
        // context Embree reads and whose `query` borrows `query` mutably
        // for the call, matching the type `user_intersect::<G>` reads.
        unsafe {
            sys::rtcIntersect1(
                self.scene.raw,
                (&mut slot as *mut RayHitSlot).cast(),
                &mut args,
            );
        };
    }

    /// True when any primitive is hit in `[t_min, t_max]`, handing `query`
    /// to every [`UserGeometry::occluded`] call it makes.
    #[must_use]
    pub fn occluded(&self, ray: &Ray, t_min: f32, t_max: f32, query: &G::ShadowQuery<'_>) -> bool {
        let mut ctx = ShadowContext::<G> {
            base: ray_query_context(),
            query: query as *const G::ShadowQuery<'_>,
        };
        // SAFETY: the repr(C) `ShadowContext<G>` begins with the context
        // Embree reads, and its `query` borrows `query` for the call,
        // matching the type `user_occluded::<G>` reads.
        unsafe {
            self.scene.occluded(
                ray,
                t_min,
                t_max,
                (&mut ctx as *mut ShadowContext<'_, G>).cast(),
            )
        }
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

/// Embree's built-in oriented discs (`RTC_GEOMETRY_TYPE_ORIENTED_DISC_POINT`)
/// over the bounding circles of [`crate::primitive::Disc`]s, every hit
/// Embree finds confirmed by the shared [`crate::primitive::Primitive::intersect`]
/// on the disc itself in an intersection and an occlusion filter: what a
/// user would pick instead of user geometry, for benchmarks. It returns the
/// closest confirmed hit, not the candidate window of the backend contract,
/// and knows no self-hit rule, so it is not a backend.
pub struct NativeDiscScene {
    scene: SceneHandle,
    /// The discs the filters read (the geometry's user pointer): boxed, so
    /// their address stays put while the scene lives.
    _discs: Box<DiscList>,
    memory_bytes: usize,
}

/// The discs behind a [`NativeDiscScene`]'s user pointer.
struct DiscList(Vec<crate::primitive::Disc>);

// SAFETY: a committed Embree scene may be queried concurrently; the filters
// only read the disc list, which is never written after the build.
unsafe impl Send for NativeDiscScene {}
// SAFETY: as above.
unsafe impl Sync for NativeDiscScene {}

/// The filter of [`NativeDiscScene`]: a hit stands only if the disc itself
/// is hit (at any distance past `tnear`; Embree keeps its own `t`).
unsafe extern "C" fn native_disc_filter(args: *const sys::RTCFilterFunctionNArguments) {
    use crate::primitive::Primitive;
    // SAFETY: Embree passes valid arguments for the duration of the call.
    let args = unsafe { &*args };
    // Only the single-ray queries are used: `N == 1`, so `ray` is an
    // `RTCRay`, `hit` an `RTCHit` and `valid` one lane.
    if args.N != 1 || args.valid.is_null() {
        return;
    }
    // SAFETY: one valid lane (above); the user pointer is the boxed disc
    // list of the `NativeDiscScene`, alive while its scene is; `ray` and
    // `hit` point to one ray and one hit (`N == 1`).
    let (valid, discs, ray, hit) = unsafe {
        (
            &mut *args.valid,
            &(*(args.geometryUserPtr as *const DiscList)).0,
            &*(args.ray as *const sys::RTCRay),
            &*(args.hit as *const sys::RTCHit),
        )
    };
    if *valid == 0 {
        return;
    }
    let confirmed = discs.get(hit.primID as usize).is_some_and(|d| {
        d.intersect(&ray_of(ray), ray.tnear, f32::INFINITY)
            .is_some()
    });
    if !confirmed {
        *valid = 0;
    }
}

impl NativeDiscScene {
    /// Builds one oriented-disc geometry over `discs` (each disc's bounding
    /// circle: centre, normal, larger radius) with the confirming filters,
    /// and commits the scene.
    pub fn new(
        device: &Device,
        discs: &[crate::primitive::Disc],
    ) -> Result<NativeDiscScene, EmbreeError> {
        let raw = device.inner.raw;
        let before = device.memory();
        let boxed = Box::new(DiscList(discs.to_vec()));
        let scene = SceneHandle::new(device)?;
        // SAFETY: live device; ORIENTED_DISC_POINT is a valid type.
        let geom = unsafe { sys::rtcNewGeometry(raw, sys::RTCGeometryType::ORIENTED_DISC_POINT) };
        device.check()?;
        if geom.is_null() {
            return Err(EmbreeError("rtcNewGeometry returned null".into()));
        }
        // SAFETY: `geom` is a fresh disc geometry; Embree allocates each
        // buffer for `len` items of the given stride and returns a pointer
        // valid until the geometry is released; we check it for null and
        // fill exactly `len` items. The user pointer is the boxed disc list,
        // which outlives the scene (dropped after it, field order).
        unsafe {
            let n = discs.len();
            let vb = sys::rtcSetNewGeometryBuffer(
                geom,
                sys::RTCBufferType::VERTEX,
                0,
                sys::RTCFormat::FLOAT4,
                16,
                n,
            ) as *mut f32;
            let nb = sys::rtcSetNewGeometryBuffer(
                geom,
                sys::RTCBufferType::NORMAL,
                0,
                sys::RTCFormat::FLOAT3,
                12,
                n,
            ) as *mut f32;
            if vb.is_null() || nb.is_null() {
                sys::rtcReleaseGeometry(geom);
                device.check()?;
                return Err(EmbreeError("could not allocate disc buffers".into()));
            }
            let vs = std::slice::from_raw_parts_mut(vb, n * 4);
            let ns = std::slice::from_raw_parts_mut(nb, n * 3);
            for ((v, nrm), d) in vs
                .chunks_exact_mut(4)
                .zip(ns.chunks_exact_mut(3))
                .zip(discs)
            {
                let r = (1.0 / d.u_scaled.length()).max(1.0 / d.v_scaled.length());
                v.copy_from_slice(&[d.center.x, d.center.y, d.center.z, r]);
                nrm.copy_from_slice(&d.normal.to_array());
            }
            sys::rtcSetGeometryUserData(geom, (&*boxed as *const DiscList).cast_mut().cast());
            sys::rtcSetGeometryIntersectFilterFunction(geom, Some(native_disc_filter));
            sys::rtcSetGeometryOccludedFilterFunction(geom, Some(native_disc_filter));
            sys::rtcCommitGeometry(geom);
            sys::rtcAttachGeometry(scene.raw, geom);
            sys::rtcReleaseGeometry(geom);
        }
        device.check()?;
        scene.commit()?;
        Ok(NativeDiscScene {
            scene,
            _discs: boxed,
            memory_bytes: device.memory().saturating_sub(before),
        })
    }

    /// The closest confirmed hit in `[t_min, t_max]`: the disc's index and
    /// Embree's distance.
    #[must_use]
    pub fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<(u32, f32)> {
        // The filter reads only the scene's own disc list.
        let slot = self.scene.intersect1(ray, t_min, t_max);
        let h = &slot.rayhit.hit;
        (h.geomID != sys::RTC_INVALID_GEOMETRY_ID).then_some((h.primID, slot.rayhit.ray.tfar))
    }

    /// True when a confirmed hit lies in `[t_min, t_max]`.
    #[must_use]
    pub fn occluded(&self, ray: &Ray, t_min: f32, t_max: f32) -> bool {
        // SAFETY: null context: the filters use only the geometry's user
        // pointer.
        unsafe { self.scene.occluded(ray, t_min, t_max, std::ptr::null_mut()) }
    }

    /// Bytes the device's memory monitor saw Embree keep while building.
    #[must_use]
    pub fn memory_bytes(&self) -> usize {
        self.memory_bytes
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// Native discs answer with the disc the exact test finds nearest:
    /// elliptical discs are registered by their bounding circles, and the
    /// filter rejects hits between the circle and the ellipse.
    #[test]
    fn native_discs_confirm_hits_with_the_exact_test() {
        use crate::primitive::{Disc, Primitive};
        use crate::splat::Splat;
        let device = Device::new().unwrap();
        // An ellipse 2 x 0.5 in the z = 0 plane, and a circle behind it.
        let mut e = Splat::disc(Vec3::ZERO, Vec3::Z, 1.0).unwrap();
        e.u_axis = Vec3::X;
        e.v_axis = Vec3::Y;
        e.radii = glam::Vec2::new(2.0, 0.5);
        let c = Splat::disc(Vec3::new(0.0, 0.0, -1.0), Vec3::Z, 1.5).unwrap();
        let discs: Vec<Disc> = [e, c].iter().map(Splat::disc_geometry).collect();
        let scene = NativeDiscScene::new(&device, &discs).unwrap();
        let down = |x: f32, y: f32| Ray::new(Vec3::new(x, y, 5.0), -Vec3::Z);
        // Inside the ellipse: the ellipse, at distance 5.
        let (id, t) = scene
            .intersect(&down(1.5, 0.1), 0.0, f32::INFINITY)
            .unwrap();
        assert_eq!(id, 0);
        assert!((t - 5.0).abs() < 1e-5);
        // Inside its bounding circle but outside the ellipse: the circle
        // behind it.
        assert_eq!(
            scene
                .intersect(&down(0.0, 1.2), 0.0, f32::INFINITY)
                .map(|h| h.0),
            Some(1)
        );
        // Outside both.
        assert!(
            scene
                .intersect(&down(0.0, 1.9), 0.0, f32::INFINITY)
                .is_none()
        );
        assert!(!scene.occluded(&down(0.0, 1.9), 0.0, f32::INFINITY));
        assert!(scene.occluded(&down(0.0, 1.2), 0.0, f32::INFINITY));
        // Random rays: the same nearest disc as the exact test.
        let mut rng = crate::rng::SplitMix64::new(9);
        for _ in 0..2000 {
            let o = Vec3::new(rng.range(-3.0, 3.0), rng.range(-3.0, 3.0), 5.0);
            let ray = Ray::new(
                o,
                Vec3::new(rng.range(-0.3, 0.3), rng.range(-0.3, 0.3), -1.0),
            );
            let exact = discs
                .iter()
                .enumerate()
                .filter_map(|(i, d)| {
                    d.intersect(&ray, 0.0, f32::INFINITY)
                        .map(|h| (i as u32, h.t))
                })
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map(|h| h.0);
            assert_eq!(
                scene.intersect(&ray, 0.0, f32::INFINITY).map(|h| h.0),
                exact
            );
        }
        assert!(scene.memory_bytes() > 0);
    }

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
