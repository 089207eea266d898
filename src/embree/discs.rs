//! Embree's built-in oriented discs over the project's discs: what a user
//! would pick instead of user geometry, measured against it by the
//! benchmark (`benches/accel.rs`).

use super::scene::{
    RayHitSlot, RayQueryContext, SceneHandle, embree_ray, embree_rayhit, intersect_arguments,
    new_buffers, new_geometry, occluded_arguments, ray_of, ray_query_context, traversal_span,
};
use super::{Device, EmbreeError};
use crate::geometry::Ray;
use embree4_sys as sys;

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

/// The scene of native discs both kinds share: the disc list the filters
/// read, its scene, and the bytes Embree kept.
type Built = (SceneHandle, Box<DiscList>, usize);

/// Builds one oriented-disc geometry over `discs` (each disc's bounding
/// circle: centre, normal, larger radius) and commits the scene: with the
/// confirming geometry filters ([`NativeDiscScene`]), or with none and the
/// filters of each query's arguments enabled ([`QueryFilteredDiscs`]).
fn build(
    device: &Device,
    discs: &[crate::primitive::Disc],
    per_query: bool,
) -> Result<Built, EmbreeError> {
    let before = device.memory();
    let boxed = Box::new(DiscList(discs.to_vec()));
    let scene = SceneHandle::new(device)?;
    let geom = new_geometry(device, sys::RTCGeometryType::ORIENTED_DISC_POINT)?;
    // SAFETY: `geom` is a fresh disc geometry, written only here; FLOAT4
    // is four f32, FLOAT3 three; the slices are filled before the
    // geometry is released.
    let (vs, ns) = unsafe {
        new_buffers::<f32, 4, f32, 3>(
            device,
            geom,
            (
                sys::RTCBufferType::VERTEX,
                sys::RTCFormat::FLOAT4,
                discs.len(),
            ),
            (
                sys::RTCBufferType::NORMAL,
                sys::RTCFormat::FLOAT3,
                discs.len(),
            ),
            "disc",
        )?
    };
    for ((v, nrm), d) in vs.iter_mut().zip(ns.iter_mut()).zip(discs) {
        let r = (1.0 / d.u_scaled.length()).max(1.0 / d.v_scaled.length());
        *v = [d.center.x, d.center.y, d.center.z, r];
        *nrm = d.normal.to_array();
    }
    // SAFETY: `geom` filled; the user pointer is the boxed disc list,
    // which outlives the scene (the caller keeps both, the scene dropped
    // first); attaching retains the geometry, so our reference is released
    // right after; the scene's flags are set before its commit.
    unsafe {
        sys::rtcSetGeometryUserData(geom, (&*boxed as *const DiscList).cast_mut().cast());
        if per_query {
            sys::rtcSetGeometryEnableFilterFunctionFromArguments(geom, true);
            sys::rtcSetSceneFlags(scene.raw, sys::RTCSceneFlags::FILTER_FUNCTION_IN_ARGUMENTS);
        } else {
            sys::rtcSetGeometryIntersectFilterFunction(geom, Some(native_disc_filter));
            sys::rtcSetGeometryOccludedFilterFunction(geom, Some(native_disc_filter));
        }
        sys::rtcCommitGeometry(geom);
        sys::rtcAttachGeometry(scene.raw, geom);
        sys::rtcReleaseGeometry(geom);
    }
    device.check()?;
    scene.commit()?;
    let memory_bytes = device.memory().saturating_sub(before);
    Ok((scene, boxed, memory_bytes))
}

impl NativeDiscScene {
    /// Builds one oriented-disc geometry over `discs` (each disc's bounding
    /// circle: centre, normal, larger radius) with the confirming filters,
    /// and commits the scene.
    pub fn new(
        device: &Device,
        discs: &[crate::primitive::Disc],
    ) -> Result<NativeDiscScene, EmbreeError> {
        let (scene, boxed, memory_bytes) = build(device, discs, false)?;
        Ok(NativeDiscScene {
            scene,
            _discs: boxed,
            memory_bytes,
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

/// Which hits a [`QueryFilteredDiscs`] query keeps: asked by Embree's filter
/// about each hit it finds on a disc's bounding circle, with the state of
/// the one query it belongs to (handed to the filter through the query
/// context, as [`super::UserScene`] hands its queries to its callbacks).
pub trait DiscFilter {
    /// True when the hit of `ray` on disc `prim` (`disc`, the scene's
    /// disc of that index) counts; a hit not kept is passed, and Embree
    /// goes on looking.
    fn keeps(&self, prim: u32, disc: &crate::primitive::Disc, ray: &Ray) -> bool;
}

/// Embree's built-in oriented discs, as [`NativeDiscScene`], whose hits are
/// decided by each query's own [`DiscFilter`] instead of one filter fixed
/// at the build: Embree's argument filter (`RTCIntersectArguments::filter`,
/// `RTCOccludedArguments::filter`), the geometry enabled for it, the scene
/// built with `RTC_SCENE_FLAG_FILTER_FUNCTION_IN_ARGUMENTS`. What a user of
/// Embree's discs would write to give them the self-hit and pass-over
/// rules of the backends; for benchmarks, not a backend.
pub struct QueryFilteredDiscs {
    scene: SceneHandle,
    /// The discs the filter reads (through the query context): boxed, so
    /// their address stays put while the scene lives.
    discs: Box<DiscList>,
    memory_bytes: usize,
}

// SAFETY: as for `NativeDiscScene`: a committed scene may be queried
// concurrently, and the disc list is never written after the build; each
// query's filter state lives on its caller's stack.
unsafe impl Send for QueryFilteredDiscs {}
// SAFETY: as above.
unsafe impl Sync for QueryFilteredDiscs {}

/// The context of a [`QueryFilteredDiscs`] query: Embree's context first
/// (`repr(C)`, so Embree can hand it back to the filter), then the discs
/// and the query's filter.
#[repr(C)]
struct FilterContext<F> {
    base: RayQueryContext,
    discs: *const DiscList,
    filter: *const F,
}

/// The argument filter of [`QueryFilteredDiscs`]: a hit stands only if the
/// query's [`DiscFilter`] keeps it (Embree keeps its own `t`).
unsafe extern "C" fn query_filter<F: DiscFilter>(args: *const sys::RTCFilterFunctionNArguments) {
    // SAFETY: Embree passes valid arguments for the duration of the call.
    let args = unsafe { &*args };
    // Only the single-ray queries are used: `N == 1`, so `ray` is an
    // `RTCRay`, `hit` an `RTCHit` and `valid` one lane.
    if args.N != 1 || args.valid.is_null() {
        return;
    }
    // SAFETY: one valid lane (above); the context is the `FilterContext<F>`
    // that `QueryFilteredDiscs::intersect` or `occluded` passed with this
    // very filter (Embree hands the query's context pointer to its
    // callbacks unchanged), whose disc list and filter are live for the
    // call; `ray` and `hit` point to one ray and one hit (`N == 1`).
    let (valid, ctx, ray, hit) = unsafe {
        (
            &mut *args.valid,
            &*(args.context as *const FilterContext<F>),
            &*(args.ray as *const sys::RTCRay),
            &*(args.hit as *const sys::RTCHit),
        )
    };
    if *valid == 0 {
        return;
    }
    // SAFETY: as above: both pointers are live shared borrows for the call.
    let (discs, filter) = unsafe { (&(*ctx.discs).0, &*ctx.filter) };
    let kept = discs
        .get(hit.primID as usize)
        .is_some_and(|d| filter.keeps(hit.primID, d, &ray_of(ray)));
    if !kept {
        *valid = 0;
    }
}

impl QueryFilteredDiscs {
    /// Builds one oriented-disc geometry over `discs` (each disc's bounding
    /// circle, as [`NativeDiscScene::new`]) with no filter of its own, the
    /// filters of the queries' arguments enabled, and commits the scene.
    pub fn new(
        device: &Device,
        discs: &[crate::primitive::Disc],
    ) -> Result<QueryFilteredDiscs, EmbreeError> {
        let (scene, discs, memory_bytes) = build(device, discs, true)?;
        Ok(QueryFilteredDiscs {
            scene,
            discs,
            memory_bytes,
        })
    }

    fn context<F: DiscFilter>(&self, filter: &F) -> FilterContext<F> {
        FilterContext {
            base: ray_query_context(),
            discs: &*self.discs,
            filter,
        }
    }

    /// The closest hit in `[t_min, t_max]` that `filter` keeps: the disc's
    /// index and Embree's distance. The span is the query's exact one:
    /// Embree traverses it widened as the user-geometry backend does
    /// (`accel::embree`'s span slack), and `filter` tests the exact span.
    #[must_use]
    pub fn intersect<F: DiscFilter>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        filter: &F,
    ) -> Option<(u32, f32)> {
        let mut ctx = self.context(filter);
        let mut args = intersect_arguments((&mut ctx as *mut FilterContext<F>).cast());
        args.filter = Some(query_filter::<F>);
        let (lo, hi) = traversal_span(ray, t_min, t_max);
        let mut slot = embree_rayhit(ray, lo, hi);
        // SAFETY: committed scene; `ctx`, `slot` and `args` live across the
        // call, the context and the slot with the layout and room Embree
        // 4.3+ uses; `args.context` points at the repr(C) `FilterContext<F>`
        // (Embree's context first) that `query_filter::<F>`, the argument
        // filter set with it, reads.
        unsafe {
            sys::rtcIntersect1(
                self.scene.raw,
                (&mut slot as *mut RayHitSlot).cast(),
                &mut args,
            );
        };
        let h = &slot.rayhit.hit;
        (h.geomID != sys::RTC_INVALID_GEOMETRY_ID).then_some((h.primID, slot.rayhit.ray.tfar))
    }

    /// True when a hit in `[t_min, t_max]` that `filter` keeps exists (the
    /// span widened for traversal as in [`QueryFilteredDiscs::intersect`]).
    #[must_use]
    pub fn occluded<F: DiscFilter>(&self, ray: &Ray, t_min: f32, t_max: f32, filter: &F) -> bool {
        let mut ctx = self.context(filter);
        let mut args = occluded_arguments((&mut ctx as *mut FilterContext<F>).cast());
        args.filter = Some(query_filter::<F>);
        let (lo, hi) = traversal_span(ray, t_min, t_max);
        let mut r = embree_ray(ray, lo, hi);
        // SAFETY: committed scene; `ctx`, `r` and `args` live across the
        // call; `args.context` points at the repr(C) `FilterContext<F>`
        // that `query_filter::<F>`, the argument filter set with it, reads.
        unsafe { sys::rtcOccluded1(self.scene.raw, &mut r, &mut args) };
        r.tfar == f32::NEG_INFINITY
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

    /// A query's own filter decides which hits count: the exact test on
    /// every disc but one passed by index, as the self-hit rule passes the
    /// splat a ray leaves.
    #[test]
    fn query_filters_decide_per_query() {
        use crate::primitive::{Disc, Primitive};
        use crate::splat::Splat;
        struct Exact(Option<u32>);
        impl DiscFilter for Exact {
            fn keeps(&self, prim: u32, disc: &Disc, ray: &Ray) -> bool {
                self.0 != Some(prim) && disc.intersect(ray, 0.0, f32::INFINITY).is_some()
            }
        }
        let device = Device::new().unwrap();
        // Two discs on the z axis, the nearer one first.
        let discs: Vec<Disc> = [0.0, -1.0]
            .iter()
            .map(|&z| {
                Splat::disc(Vec3::new(0.0, 0.0, z), Vec3::Z, 1.0)
                    .unwrap()
                    .disc_geometry()
            })
            .collect();
        let scene = QueryFilteredDiscs::new(&device, &discs).unwrap();
        let down = Ray::new(Vec3::new(0.2, 0.1, 5.0), -Vec3::Z);
        let near = scene.intersect(&down, 0.0, f32::INFINITY, &Exact(None));
        assert_eq!(near.map(|h| h.0), Some(0));
        let past = scene.intersect(&down, 0.0, f32::INFINITY, &Exact(Some(0)));
        assert_eq!(past.map(|h| h.0), Some(1));
        assert!((past.unwrap().1 - 6.0).abs() < 1e-5);
        // Only the nearer disc in the span: occluded unless it is passed.
        assert!(scene.occluded(&down, 0.0, 5.5, &Exact(None)));
        assert!(!scene.occluded(&down, 0.0, 5.5, &Exact(Some(0))));
        assert!(scene.occluded(&down, 0.0, 6.5, &Exact(Some(0))));
        // Outside both discs: nothing, whatever the filter.
        let beside = Ray::new(Vec3::new(1.5, 0.0, 5.0), -Vec3::Z);
        assert!(!scene.occluded(&beside, 0.0, f32::INFINITY, &Exact(None)));
        assert!(scene.memory_bytes() > 0);
    }
}
