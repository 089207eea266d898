//! The one module that speaks to Embree 4. All of the project's `unsafe` and
//! FFI lives here, behind a small safe API, a file for each thing it wraps:
//!
//! * [`Device`] (this file): an Embree device whose errors (reported
//!   through the error callback) become [`EmbreeError`]s, never silent
//!   zeros; its memory monitor counts the bytes Embree allocates
//!   ([`Device::memory`]); the configuration and the ISAs of this CPU;
//! * `scene`: what every scene shares (the owned `RTCScene`, rays and query
//!   contexts as Embree 4.3 and later lay them out);
//! * [`UserScene`] (`user`): a scene of one `RTC_GEOMETRY_TYPE_USER`
//!   geometry whose bounds, intersect and occluded callbacks call a
//!   [`UserGeometry`] implemented in safe code (the splat backend
//!   implements it beside the backend, in `accel::embree`): this module
//!   knows nothing of splats;
//! * [`TriangleScene`] (`triangles`): triangle meshes in Embree's own BVH
//!   (ground truth);
//! * `NativeDiscScene` (`discs`): Embree's built-in discs, for the
//!   benchmark that sets them against user geometry, and
//!   `QueryFilteredDiscs`, the same discs with each query's own filter
//!   (Embree's argument filter); compiled with the `native-discs` feature
//!   (the benchmarks and tests turn it on).
//!
//! Raw Embree types never leave this module.

#[cfg(any(test, feature = "native-discs"))]
mod discs;
mod scene;
mod triangles;
mod user;

#[cfg(any(test, feature = "native-discs"))]
pub use discs::{DiscFilter, NativeDiscScene, QueryFilteredDiscs};
pub(crate) use scene::{traversal_end, traversal_span};
pub use triangles::{TriangleHit, TriangleScene};
pub use user::{UserGeometry, UserScene};

use embree4_sys as sys;
use std::ffi::{CStr, CString, c_char, c_void};
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
/// [`Device::new`] hands to `rtcNewDevice` (`crate::config::EMBREE_VAR`).
pub use crate::config::EMBREE_VAR as CONFIG_VAR;

/// The configuration [`Device::new`] uses: that of
/// `crate::config::current` (the value of [`CONFIG_VAR`], read once), or
/// the empty string (Embree's defaults) when it is unset.
#[must_use]
pub fn config_in_force() -> String {
    crate::config::current().embree.clone()
}

/// Embree's main kernel sets, the ones the test suite forces one by one
/// through `isa=` in [`CONFIG_VAR`] where the CPU runs them (`splatray
/// info` prints those as its `embree-isas:` line).
pub const FORCIBLE_ISAS: [&str; 3] = ["sse4.2", "avx2", "avx512"];

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
