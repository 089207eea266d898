//! User geometry: a scene of one `RTC_GEOMETRY_TYPE_USER` geometry whose
//! callbacks ask a [`UserGeometry`] written in safe code.

use super::scene::{
    RayHitSlot, RayQueryContext, SceneHandle, embree_rayhit, intersect_arguments, new_geometry,
    ray_of, ray_query_context,
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
