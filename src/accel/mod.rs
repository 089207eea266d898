//! Acceleration backends and the contract they share (`docs/DESIGN.md`,
//! "The backend contract").
//!
//! Every backend answers the same two questions about a ray — the candidate
//! hits within the blending window `xi` of the nearest hit (§4.3), and
//! whether anything is hit at all (shadow rays) — using the one ray–splat
//! routine, [`crate::primitive::Primitive::intersect`]. Nothing above
//! [`Backend`] knows which ran; every backend is listed once, in
//! [`registry`].

pub mod brute;
mod departure;
pub mod embree;
pub mod hybrid;
pub mod octree;
mod pass;
pub mod registry;
mod window;

pub use crate::geometry::{Ray, RaySet};
pub use departure::{
    Departure, NoSkip, SAME_SURFACE_COS, SAME_SURFACE_HEIGHT, SAME_SURFACE_RIM, Skip, WAY_OUT_COS,
};
pub use pass::{PassOver, Secondary};
pub use registry::{BackendInfo, Role, backends};
pub use window::{Candidate, CandidateHits, MAX_CANDIDATES};

/// Figures about one built acceleration structure.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BuildStats {
    /// Wall seconds to build.
    pub build_seconds: f64,
    /// Bytes held by the structure (excluding the splats themselves).
    pub memory_bytes: usize,
    /// Octree: interior plus leaf nodes.
    pub nodes: usize,
    /// Octree: leaves.
    pub leaves: usize,
    /// Octree: mean splat references per non-empty leaf.
    pub mean_refs_per_leaf: f64,
}

/// One ray query of the backend contract: the ray, its interval
/// `[t_min, t_max]`, for a secondary ray the splat it leaves (whose
/// surface every backend skips alike, [`Departure::skips`]), and the hits
/// the ray passes ([`PassOver`]: a shadow ray sees Phong splats as the
/// curved surfaces the resolver shows).
#[derive(Clone, Copy)]
pub struct Query<'a> {
    /// The ray.
    pub ray: Ray,
    /// Lower end of the interval (0, or `eps_self` for a secondary ray).
    pub t_min: f32,
    /// Upper end of the interval.
    pub t_max: f32,
    /// The splat a secondary ray leaves, `None` for a primary ray.
    pub from: Option<Departure>,
    /// The hits the ray passes, left out as if absent (`None`: every hit
    /// counts). The integrator gives it to shadow rays.
    pub pass: Option<&'a dyn PassOver>,
}

impl std::fmt::Debug for Query<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Query")
            .field("ray", &self.ray)
            .field("t_min", &self.t_min)
            .field("t_max", &self.t_max)
            .field("from", &self.from)
            .field("pass", &self.pass.is_some())
            .finish()
    }
}

impl<'a> Query<'a> {
    /// True when the interval is empty or undefined (a NaN end, or
    /// `t_min > t_max`): the query meets nothing, on every backend
    /// (tests/conformance/hostile_rays.rs).
    #[inline]
    #[must_use]
    pub fn meets_nothing(&self) -> bool {
        self.t_min.is_nan() || self.t_max.is_nan() || self.t_min > self.t_max
    }

    /// A primary-ray query: nothing skipped.
    #[must_use]
    pub fn new(ray: Ray, t_min: f32, t_max: f32) -> Query<'a> {
        Query {
            ray,
            t_min,
            t_max,
            from: None,
            pass: None,
        }
    }

    /// What the query skips as one type for every secondary query: its
    /// departure's self-hit rule and its pass-over rule ([`Secondary`]).
    #[must_use]
    pub fn secondary(&self) -> Secondary<'_> {
        Secondary {
            from: self.from.as_ref(),
            pass: self.pass,
        }
    }
}

/// One acceleration backend (`docs/DESIGN.md`, "The backend contract"). Implemented by the brute-force
/// oracle, the octree and Embree; its name is its `registry` entry's.
pub trait Backend: Send + Sync {
    /// Fills `hits` (cleared first) with the candidate hits of `q.ray` in
    /// `[q.t_min, q.t_max]`: the nearest and all within the window of it.
    /// With `q.from`, a secondary ray leaving that splat: every hit
    /// `Departure::skips` is left out before it counts (as if absent).
    /// An interval with a NaN end, or with `t_min > t_max`, meets nothing
    /// (`Query::meets_nothing`): the same miss on every backend.
    fn intersect_from(&self, q: &Query, hits: &mut CandidateHits);

    /// True when any splat is hit with `t` in `[q.t_min, q.t_max]`, leaving
    /// out the hits `q.from` skips (as [`Backend::intersect_from`]).
    fn occluded_from(&self, q: &Query) -> bool;

    /// Build figures.
    fn stats(&self) -> &BuildStats;

    /// [`Backend::intersect_from`] for a primary ray: nothing skipped.
    fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32, hits: &mut CandidateHits) {
        self.intersect_from(&Query::new(*ray, t_min, t_max), hits);
    }

    /// [`Backend::occluded_from`] with nothing skipped.
    fn occluded(&self, ray: &Ray, t_min: f32, t_max: f32) -> bool {
        self.occluded_from(&Query::new(*ray, t_min, t_max))
    }

    /// True when [`Backend::intersect_packet`] and
    /// [`Backend::occluded_packet`] trace a coherent batch faster than one
    /// query at a time, so the integrator hands this backend batches (the
    /// answers are the same either way). False by default.
    fn prefers_packets(&self) -> bool {
        false
    }

    /// A batch of queries traced together (a packet: e.g. the primary rays
    /// of a small screen tile, or the shadow rays of one hit): `hits[i]`
    /// gets exactly what [`Backend::intersect_from`] gives `qs[i]`, the
    /// same candidates bit for bit, whatever else the batch holds. Backends
    /// that trace coherent rays together (the octree, Embree's
    /// `rtcIntersect8`) override it; this default traces one at a time.
    ///
    /// # Panics
    /// If `hits` is shorter than `qs`.
    fn intersect_packet(&self, qs: &[Query], hits: &mut [CandidateHits]) {
        assert!(hits.len() >= qs.len(), "a window per query");
        for (q, h) in qs.iter().zip(hits.iter_mut()) {
            self.intersect_from(q, h);
        }
    }

    /// What the backend knows once about many primary rays leaving one
    /// origin: `rays`, a run of a batch sharing their first ray's origin
    /// bit for bit (a camera's rays), and the directions in which they
    /// certainly hit nothing ([`Fan`]; the octree's, `octree`'s module
    /// doc). `None` (the default, and when the run would not pay): every
    /// ray is traced.
    fn fan(&self, rays: &dyn RaySet) -> Option<Box<dyn Fan + '_>> {
        let _ = rays;
        None
    }

    /// Whether [`Backend::fan`] may pay for a run of `rays` rays: false
    /// (the default) where it certainly gives `None`, so a caller need not
    /// make the run's rays to ask.
    fn fan_pays(&self, rays: usize) -> bool {
        let _ = rays;
        false
    }

    /// A backend answering every query exactly as this one does, bit for
    /// bit, that knows once the rays along `dir` (its bits: the shadow
    /// rays of a directional light, about `rays` of them) and answers
    /// their occlusion from that (the octree's: each cell of a grid across
    /// `dir` with its list of primitives); `None` (the default, and where
    /// it would not pay): this one.
    fn parallel(&self, dir: glam::Vec3, rays: usize) -> Option<Box<dyn Backend + '_>> {
        let _ = (dir, rays);
        None
    }

    /// [`Backend::occluded_from`] for a batch: `out[i]` is its answer for
    /// `qs[i]`. The default asks one query at a time.
    ///
    /// # Panics
    /// If `out` is shorter than `qs`.
    fn occluded_packet(&self, qs: &[Query], out: &mut [bool]) {
        assert!(out.len() >= qs.len(), "an answer per query");
        for (q, o) in qs.iter().zip(out.iter_mut()) {
            *o = self.occluded_from(q);
        }
    }

    /// [`Backend::occluded_from`] for a batch of scattered rays (no shared
    /// origin): `out[i]` is its answer for `qs[i]`. The default asks one
    /// query at a time.
    ///
    /// # Panics
    /// If `out` is shorter than `qs`.
    fn occluded_each(&self, qs: &[Query], out: &mut [bool]) {
        assert!(out.len() >= qs.len(), "an answer per query");
        for (q, o) in qs.iter().zip(out.iter_mut()) {
            *o = self.occluded_from(q);
        }
    }
}

/// A backend's knowledge of the rays leaving one origin
/// ([`Backend::fan`]).
pub trait Fan: Send + Sync {
    /// True only when `ray` (leaving the fan's origin) hits nothing at
    /// `t >= 0` in its backend: a query of it from `t_min >= 0` with
    /// nothing skipped gets an empty window, and its occlusion is false,
    /// whatever its span. False when it may hit, or is not known.
    fn misses(&self, ray: &Ray) -> bool;

    /// Each of `rays`' key into `keys` (one per ray): [`FAN_MISS`] where
    /// [`Fan::misses`] holds, [`FAN_ELSEWHERE`] for a ray whose direction
    /// the fan holds no place for, else a key that rays of neighbouring
    /// directions share, neighbouring keys for neighbouring places (the
    /// default: 0 for every ray that may hit). Rays taken key by key make
    /// packets of neighbouring directions whatever the run's order (issue
    /// 55). One call for many rays, so a backend's test runs in a loop of
    /// its own.
    fn keys_each(&self, rays: &[Ray], keys: &mut [u32]) {
        for (k, r) in keys.iter_mut().zip(rays) {
            *k = if self.misses(r) { FAN_MISS } else { 0 };
        }
    }

    /// [`Fan::keys_each`] of rows not yet made rays (a window of a
    /// caller's rows converted only where the fan does not know them to
    /// miss): `rows` holds, as [`Ray`]s in layout only, each row's origin
    /// as given and its direction before normalising; a row whose
    /// origin's bits are `origin` converts to a ray leaving the fan's
    /// origin. A row gets [`FAN_MISS`] only where the ray it converts to
    /// would (a row that is not a ray may get any key: the caller tells
    /// such rows). False (the default) where the fan cannot key rows:
    /// `keys` then holds nothing.
    fn keys_of_rows(&self, rows: &[Ray], origin: [u32; 3], keys: &mut [u32]) -> bool {
        let _ = (rows, origin, keys);
        false
    }

    /// The window of `q` into `hits` (cleared first), as the backend that
    /// made the fan gathers it, bit for bit (true); false, `hits` left
    /// as it was, where the fan cannot answer it (the default): the caller
    /// asks the backend. `q` is a query of a ray of this fan's run (its
    /// origin the run's, bit for bit) with nothing skipped, whose key
    /// ([`Fan::keys_each`], or [`Fan::keys_of_rows`] of the row it was
    /// converted from) is `key`: the octree's fan answers from the list of
    /// the key's block without finding the block again.
    fn gather_keyed(&self, key: u32, q: &Query, hits: &mut CandidateHits) -> bool {
        let _ = (key, q, hits);
        false
    }

    /// A backend answering every query exactly as the backend that made
    /// the fan does, bit for bit, those of this fan's run (and the octree's
    /// shadow rays toward its origin) from what the fan knows of its
    /// directions (the octree's: each block of directions' own list of
    /// primitives); `None` (the default): that backend.
    fn backend(&self) -> Option<&dyn Backend> {
        None
    }
}

/// [`Fan::keys_each`]'s key of a ray its fan knows to miss.
pub const FAN_MISS: u32 = crate::simd::KEY_MISS;

/// [`Fan::keys_each`]'s key of a ray whose direction its fan holds no
/// place for (outside the octree's grid).
pub const FAN_ELSEWHERE: u32 = crate::simd::KEY_ELSEWHERE;

pub use crate::config::PACKETS_VAR;

/// Whether the integrator hands `backend` coherent batches: [`PACKETS_VAR`]
/// when set (`crate::config::current`; an unusable value is refused by
/// the command line before any work), else [`Backend::prefers_packets`].
#[must_use]
pub fn use_packets(backend: &dyn Backend) -> bool {
    crate::config::current()
        .packets
        .unwrap_or_else(|| backend.prefers_packets())
}

/// Most queries a backend traces together in one packet (the octree's
/// active mask, Embree's `rtcIntersect8`); longer batches are split.
pub const PACKET: usize = 8;
