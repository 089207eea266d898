//! User geometry: a scene of one `RTC_GEOMETRY_TYPE_USER` geometry whose
//! callbacks ask a [`UserGeometry`] written in safe code.

use super::scene::{
    LANES8, RayHit8Slot, RayHitSlot, RayQueryContext, SceneHandle, embree_ray8, embree_rayhit,
    embree_rayhit8, intersect_arguments, new_geometry, occluded_arguments, ray_query_context,
};
use super::{Device, EmbreeError};
use crate::geometry::Ray;
use embree4_sys as sys;
use std::ffi::{c_uint, c_void};

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

/// The query context: begins with `RTCRayQueryContext` so Embree can hand
/// it back to the callbacks, followed by where each ray's candidates go:
/// the query of the ray whose `id` is `k` at `query[k]` (one ray: `id` 0;
/// a packet: lane `k` has `id` `k`).
#[repr(C)]
struct QueryContext<'q, G: UserGeometry> {
    base: RayQueryContext,
    query: [*mut G::Query<'q>; LANES8],
}

/// The context of an occlusion query, laid out like [`QueryContext`]:
/// Embree's context first, then each ray's shadow query by its `id`.
#[repr(C)]
struct ShadowContext<'q, G: UserGeometry> {
    base: RayQueryContext,
    query: [*const G::ShadowQuery<'q>; LANES8],
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

/// Field `f` of lane `i` of an `RTCRayN` / `RTCRayHitN` of `n` lanes, as
/// `rtcore_ray.h`'s `RTCRayN_*` and `RTCHitN_*` accessors lay them out
/// (ray fields 0–11: origin, `tnear`, direction, time, `tfar`, mask, `id`,
/// flags; then the hit's from 12: normal, `u`, `v`, `primID` at 17,
/// `geomID` at 18).
///
/// # Safety
/// `base` points to a live ray (and hit, for `f >= 12`) record of `n`
/// lanes, `i < n`.
#[inline(always)]
unsafe fn lane(base: *mut u32, n: usize, f: usize, i: usize) -> *mut u32 {
    // SAFETY: within the record, as the caller guarantees.
    unsafe { base.add(f * n + i) }
}

/// The ray, `tnear`, `tfar` and `id` of lane `i` of a record of `n` lanes.
///
/// # Safety
/// As [`lane`].
#[inline(always)]
unsafe fn read_lane(base: *mut u32, n: usize, i: usize) -> (Ray, f32, f32, usize) {
    // SAFETY: as the caller guarantees; every field is 4 bytes.
    let f = |field: usize| f32::from_bits(unsafe { *lane(base, n, field, i) });
    let ray = Ray {
        origin: glam::Vec3::new(f(0), f(1), f(2)),
        dir: glam::Vec3::new(f(4), f(5), f(6)),
    };
    // SAFETY: as above.
    let id = unsafe { *lane(base, n, 10, i) } as usize;
    (ray, f(3), f(8), id)
}

/// Calls `f(i, ray, tnear, tfar, query)` for each valid lane `i` of a
/// callback's record of `n` lanes, with the query of its ray (`queries`
/// indexed by the ray's `id`; a lane whose id names none is left alone).
///
/// # Safety
/// `valid` has `n` lanes and `base` points to a live ray record of `n`
/// lanes.
#[inline(always)]
unsafe fn each_lane<Q: Copy>(
    valid: *const i32,
    base: *mut u32,
    n: usize,
    queries: &[Q; LANES8],
    mut f: impl FnMut(usize, Ray, f32, f32, Q),
) {
    for i in 0..n {
        // SAFETY: `i < n`, a lane of `valid` and of the record.
        if unsafe { *valid.add(i) } == 0 {
            continue;
        }
        // SAFETY: as above.
        let (ray, tnear, tfar, id) = unsafe { read_lane(base, n, i) };
        if let Some(&q) = queries.get(id) {
            f(i, ray, tnear, tfar, q);
        }
    }
}

/// Intersect callback: for each valid lane, [`UserGeometry::intersect`]
/// decides with that ray's query; an accepted hit moves the lane's `tfar`
/// and records the primitive in its hit. The same primitive may be offered
/// twice; the query must cope (the candidate window dedupes by id).
unsafe extern "C" fn user_intersect<G: UserGeometry>(
    args: *const sys::RTCIntersectFunctionNArguments,
) {
    // SAFETY: valid for the call: `valid` has `N` lanes and `rayhit` is an
    // `RTCRayHitN` of `N` lanes (`rtcIntersect1`: one, `rtcIntersect8`:
    // eight, or one ray of the packet on its own).
    let args = unsafe { &*args };
    let n = args.N as usize;
    // SAFETY: user pointer as in `user_bounds`; the context is the
    // `QueryContext<G>` passed by `UserScene::intersect` or
    // `UserScene::intersect8` (it begins with `RTCRayQueryContext`,
    // repr(C)), whose `query` entries for the ids of the rays traced are
    // live `&mut` for this call, one per ray.
    let geom = unsafe { &*(args.geometryUserPtr as *const G) };
    let ctx = unsafe { &*(args.context as *const QueryContext<'_, G>) };
    let base = args.rayhit.cast::<u32>();
    let visit = |i: usize, ray: Ray, tnear: f32, tfar: f32, q: *mut G::Query<'_>| {
        // SAFETY: the query of this ray, live and not otherwise
        // borrowed during the call (each ray has its own).
        let query = unsafe { &mut *q };
        if let Some(t) = geom.intersect(args.primID, &ray, tnear, tfar, query) {
            // SAFETY: lane `i` of the ray's `tfar` and of the hit's
            // `primID`, `geomID`.
            unsafe {
                *lane(base, n, 8, i) = t.to_bits();
                *lane(base, n, 17, i) = args.primID;
                *lane(base, n, 18, i) = args.geomID;
            }
        }
    };
    // SAFETY: `valid` and the record have `N` lanes (the call's
    // arguments).
    unsafe { each_lane(args.valid, base, n, &ctx.query, visit) };
}

/// Occluded callback: any hit in `[tnear, tfar]` ends the lane's query,
/// signalled by setting its `tfar = -inf` as Embree requires.
unsafe extern "C" fn user_occluded<G: UserGeometry>(
    args: *const sys::RTCOccludedFunctionNArguments,
) {
    // SAFETY: as in `user_intersect`; `ray` is an `RTCRayN` of `N` lanes.
    let args = unsafe { &*args };
    let n = args.N as usize;
    // SAFETY: user pointer as in `user_bounds`; the context is the
    // `ShadowContext<G>` passed by `UserScene::occluded` or
    // `UserScene::occluded8` (it begins with `RTCRayQueryContext`,
    // repr(C)), whose `query` entries for the ids of the rays traced are
    // live shared references for this call.
    let geom = unsafe { &*(args.geometryUserPtr as *const G) };
    let ctx = unsafe { &*(args.context as *const ShadowContext<'_, G>) };
    let base = args.ray.cast::<u32>();
    let visit = |i: usize, ray: Ray, tnear: f32, tfar: f32, q: *const G::ShadowQuery<'_>| {
        // SAFETY: a live shared reference for the call.
        let query = unsafe { &*q };
        if geom.occluded(args.primID, &ray, tnear, tfar, query) {
            // SAFETY: lane `i` of the ray's `tfar`.
            unsafe { *lane(base, n, 8, i) = f32::NEG_INFINITY.to_bits() };
        }
    };
    // SAFETY: `valid` and the record have `N` lanes (the call's
    // arguments).
    unsafe { each_lane(args.valid, base, n, &ctx.query, visit) };
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
        let out = UserScene {
            scene: SceneHandle::new(device)?,
            geometry: Box::new(geometry),
        };
        let scene = out.scene.raw;
        if count > 0 {
            let geom = new_geometry(device, sys::RTCGeometryType::USER)?;
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
            query: [query as *mut G::Query<'_>; LANES8],
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
            query: [query as *const G::ShadowQuery<'_>; LANES8],
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

    /// Traces up to eight rays `(ray, t_min, t_max)` as one packet
    /// (`rtcIntersect8`), handing the query in `queries[k]` to every
    /// [`UserGeometry::intersect`] call about ray `k`; rays past the eighth
    /// are not traced.
    ///
    /// # Panics
    /// If a ray has no query (`queries[k]` missing or `None`).
    pub fn intersect8(&self, rays: &[(Ray, f32, f32)], queries: &mut [Option<G::Query<'_>>]) {
        let mut ptrs = [std::ptr::null_mut(); LANES8];
        for (k, p) in ptrs.iter_mut().enumerate().take(rays.len()) {
            let q = queries.get_mut(k).and_then(Option::as_mut);
            *p = q.expect("a query per ray") as *mut G::Query<'_>;
        }
        let mut ctx = QueryContext::<G> {
            base: ray_query_context(),
            query: ptrs,
        };
        let mut args = intersect_arguments((&mut ctx as *mut QueryContext<'_, G>).cast());
        args.flags = sys::RTCRayQueryFlags::COHERENT;
        let (mut slot, valid) = embree_rayhit8(rays);
        // SAFETY: committed scene; `valid`, `slot` and `args` live across
        // the call, the mask and the slot aligned to 32 bytes, the slot
        // with room for the hits Embree 4.3+ writes; `args.context` points
        // at the repr(C) `QueryContext<G>` whose `query[k]` borrows
        // `queries[k]` mutably for the call for each valid lane `k` (ray
        // id `k`; the other entries are null and no valid ray has their
        // id), matching the type `user_intersect::<G>` reads.
        unsafe {
            sys::rtcIntersect8(
                valid.0.as_ptr(),
                self.scene.raw,
                (&mut slot as *mut RayHit8Slot).cast(),
                &mut args,
            );
        };
    }

    /// For up to eight rays `(ray, t_min, t_max)` traced as one packet
    /// (`rtcOccluded8`): `out[k]` true when any primitive is hit in ray
    /// `k`'s interval, handing `queries[k]` to every
    /// [`UserGeometry::occluded`] call about it.
    ///
    /// # Panics
    /// If `queries` or `out` is shorter than `rays`.
    pub fn occluded8(
        &self,
        rays: &[(Ray, f32, f32)],
        queries: &[G::ShadowQuery<'_>],
        out: &mut [bool],
    ) {
        assert!(
            queries.len() >= rays.len() && out.len() >= rays.len(),
            "a query and an answer per ray"
        );
        let mut ptrs = [std::ptr::null(); LANES8];
        for (p, q) in ptrs.iter_mut().zip(queries.iter()) {
            *p = q as *const G::ShadowQuery<'_>;
        }
        let mut ctx = ShadowContext::<G> {
            base: ray_query_context(),
            query: ptrs,
        };
        let mut args = occluded_arguments((&mut ctx as *mut ShadowContext<'_, G>).cast());
        args.flags = sys::RTCRayQueryFlags::COHERENT;
        let (mut r, valid) = embree_ray8(rays);
        // SAFETY: committed scene; `valid`, `r` and `args` live across the
        // call, the mask and the rays aligned to 32 bytes; `args.context`
        // points at the repr(C) `ShadowContext<G>` whose `query[k]`
        // borrows `queries[k]` for the call for each valid lane `k` (ray id
        // `k`), matching the type `user_occluded::<G>` reads.
        unsafe { sys::rtcOccluded8(valid.0.as_ptr(), self.scene.raw, &mut r, &mut args) };
        for (k, o) in out.iter_mut().take(rays.len().min(LANES8)).enumerate() {
            *o = r.tfar[k] == f32::NEG_INFINITY;
        }
    }

    /// Errors reported by Embree since the last check (queries do not report
    /// errors per call: check after a batch).
    pub fn check(&self) -> Result<(), EmbreeError> {
        self.scene.device.check()
    }
}
