//! Primitives: the surfaces a backend intersects, each owning everything a
//! backend asks of it — the ray intersection, its bounds, the exact overlap
//! test with an axis-aligned box (the octree's step 3 of §3.1), and an
//! optional SIMD pack. Backends are generic over [`Primitive`], so the hot
//! loop is monomorphised per primitive; see `docs/DESIGN.md`, "The primitive
//! contract", for what an implementation must guarantee.
//!
//! Two today: [`Disc`], the oriented elliptical disc of a splat (circles
//! are the case `r_u = r_v`), and [`ClippedDisc`], a disc cut by one or two
//! clip lines ([`Clip`]), built only for scenes holding clipped splats.

pub mod clip;
mod clipped;
mod disc;
mod triangle;

pub use clip::{Clip, ClipLine};
pub use clipped::{ClipTable, ClippedDisc, ClippedPack};
pub use disc::{Disc, DiscPack};
pub use triangle::{ON_TRIANGLE, Triangle, TrianglePack};

use glam::Vec3;

use crate::geometry::Ray;

/// Where a ray meets a primitive: the ray parameter and the hit's local
/// coordinates, normalised so that the primitive is `u² + v² <= 1`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit.
    pub t: f32,
    /// First local coordinate (along the major axis, divided by its radius).
    pub u: f32,
    /// Second local coordinate.
    pub v: f32,
}

/// Where a point lies relative to a primitive: what the self-hit rule of
/// secondary rays ([`crate::accel::Departure`]) asks of every primitive.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Local {
    /// Squared normalised radial coordinate of the point's projection onto
    /// the primitive (`u² + v²`: 1 on the rim).
    pub radial2: f32,
    /// Signed distance of the point from the primitive's surface, divided
    /// by the primitive's largest radius.
    pub height: f32,
    /// The primitive's unit normal at the projection (its own side).
    pub normal: Vec3,
}

/// A surface primitive as the backends see it.
///
/// The contract (relied on by the cross-validation): [`Primitive::intersect`]
/// is the only routine that decides a hit, in every backend, so two backends
/// that test the same primitives return bit-identical hits; every other
/// method may only be conservative — the box of [`Primitive::half_extent`]
/// and [`Primitive::meets_box`] must never exclude a point that
/// `intersect` can return (padding against rounding is the backends' job),
/// and [`Pack::may_hit`] must pass every lane `intersect` hits.
pub trait Primitive: Copy + Send + Sync + 'static {
    /// How a backend stores several primitives to test them together; use
    /// [`Single`] for a primitive without a SIMD filter of its own.
    type Pack: Pack<Self>;

    /// The hit of `ray` with `t_min <= t <= t_max`, or `None`. NaN anywhere
    /// must give `None`, never a NaN `t`.
    fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<Hit>;

    /// Centre: the point the octree files the primitive under (§3.1).
    fn center(&self) -> Vec3;

    /// Half extents of the tight axis-aligned box around the primitive,
    /// centred at [`Primitive::center`].
    fn half_extent(&self) -> Vec3;

    /// Radius of a ball around [`Primitive::center`] holding every point
    /// `intersect` can return (up to rounding, which the backends pad):
    /// the tight box's circumscribed ball by default.
    fn bounding_radius(&self) -> f32 {
        self.half_extent().length()
    }

    /// Semi-axes `(a, b)` of an ellipse `center + α a + β b`, `α² + β² <=
    /// 1`, holding every point `intersect` can return (up to rounding), for
    /// a bound tighter than the ball's seen edge-on; `None` (the default)
    /// when the primitive is no such ellipse.
    fn semi_axes(&self) -> Option<(Vec3, Vec3)> {
        None
    }

    /// Half extents of a coarser box for a cheaper, looser overlap test (the
    /// report's bounding square of a splat, §3.1); the tight box by default.
    fn coarse_half_extent(&self) -> Vec3 {
        self.half_extent()
    }

    /// Exact test: does the primitive meet the closed box `[lo, hi]`?
    fn meets_box(&self, lo: Vec3, hi: Vec3) -> bool;

    /// Where `p` lies relative to the primitive ([`Local`]): the geometry
    /// the self-hit rule of secondary rays decides on, in every backend
    /// alike (`docs/DESIGN.md`, "The backend contract"). NaN in `p` gives
    /// NaN fields, which the rule treats as "not the same surface".
    fn locate(&self, p: Vec3) -> Local;
}

/// A ray as a [`Pack`] test takes it: origin and direction as plain
/// arrays, broadcast to every lane, and the span `[t_min, t_max]` tested
/// (one slot of [`PackRays`]).
#[derive(Clone, Copy, Debug)]
pub struct PackRay {
    /// Origin.
    pub origin: [f32; 3],
    /// Direction.
    pub dir: [f32; 3],
    /// Near end of the span.
    pub t_min: f32,
    /// Far end of the span.
    pub t_max: f32,
}

impl PackRay {
    /// The ray's components, with the span `[t_min, t_max]`.
    #[must_use]
    pub fn new(ray: &Ray, t_min: f32, t_max: f32) -> PackRay {
        PackRay {
            origin: ray.origin.to_array(),
            dir: ray.dir.to_array(),
            t_min,
            t_max,
        }
    }
}

/// Rays of a packet sharing one origin (a shadow batch leaving one hit, the
/// primary rays of one eye), each with its own direction and span, for
/// [`Pack::masks_rays`]; slot `k` is ray `k` of the packet.
#[derive(Clone, Copy, Debug)]
pub struct PackRays {
    /// The origin every ray shares.
    pub origin: [f32; 3],
    /// Each ray's direction.
    pub dir: [[f32; 3]; crate::simd::RAYS],
    /// Each ray's `t_min`.
    pub t_min: [f32; crate::simd::RAYS],
    /// Each ray's `t_max`.
    pub t_max: [f32; crate::simd::RAYS],
    /// A cone from `origin` holding every ray's half-line, when the rays
    /// start at `t_min >= 0`: a pack may drop, for all the rays at once,
    /// the primitives no ray of the cone can hit.
    pub cone: Option<crate::simd::Cone>,
}

/// [`Pack::LANES`] primitives stored together (SoA for a SIMD filter).
pub trait Pack<P>: Copy + Send + Sync + 'static {
    /// Primitives per pack.
    const LANES: usize;
    /// A pack whose every lane is padding that no ray can hit.
    const EMPTY: Self;
    /// What the lanes leave out of their primitives, kept once beside a
    /// structure's packs and looked up by primitive id: `()` for a pack
    /// whose lanes hold their primitives whole ([`DiscPack`]); for
    /// [`ClippedPack`] the clip lines of the clipped splats alone
    /// ([`ClipTable`]), so a lane costs what a disc's does and a scene
    /// pays for the clip lines it has, once each, not once per reference.
    type Side: Send + Sync + 'static;
    /// The side table of `prims` (primitive `i` has id `i`).
    fn side(prims: &[P]) -> Self::Side;
    /// Bytes the side table holds.
    fn side_bytes(side: &Self::Side) -> usize;
    /// Stores in `lane` what the lanes hold of `p` (the rest is `side`'s),
    /// bit for bit.
    fn set(&mut self, lane: usize, p: &P);
    /// The primitive of `lane`, whose id is `id`, with what `side` (made
    /// by [`Pack::side`] over the primitives the ids index) holds of it:
    /// bit for bit the primitive stored.
    fn get(&self, lane: usize, id: u32, side: &Self::Side) -> P;
    /// The pack whose lane `l` holds `lane(l)` (padding where `None`).
    fn from_fn(lane: impl Fn(usize) -> Option<P>) -> Self {
        let mut pack = Self::EMPTY;
        for l in 0..Self::LANES {
            if let Some(p) = lane(l) {
                pack.set(l, &p);
            }
        }
        pack
    }
    /// What the filter derives from a ray's origin and direction alone,
    /// made once per ray ([`Pack::prep`]) for every leaf the ray visits:
    /// the triangles' shear; `()` where a pack needs nothing.
    type Prep: Copy + Send + Sync;
    /// The [`Pack::Prep`] of `ray` (its span is not used).
    fn prep(ray: &PackRay) -> Self::Prep;
    /// Bit `l` set when lane `l` may be hit in the ray's span: a filter
    /// that must pass every lane [`Primitive::intersect`] hits and no padding
    /// lane; each lane passed is then decided by `intersect` itself.
    fn may_hit(&self, ray: &PackRay) -> u32;
    /// [`Pack::may_hit`] of each of `packs` into `out` (at least as long),
    /// computed on the SIMD path `isa` where the pack has one: every path
    /// passes the same lanes.
    #[inline]
    fn masks(packs: &[Self], ray: &PackRay, isa: crate::simd::Isa, out: &mut [u32]) {
        let _ = isa;
        for (p, m) in packs.iter().zip(out.iter_mut()) {
            *m = p.may_hit(ray);
        }
    }

    /// [`Pack::masks`] given `prep`, made by [`Pack::prep`] from this
    /// ray's origin and direction: the same masks.
    #[inline]
    fn masks_prepped(
        packs: &[Self],
        ray: &PackRay,
        prep: &Self::Prep,
        isa: crate::simd::Isa,
        out: &mut [u32],
    ) {
        let _ = prep;
        Self::masks(packs, ray, isa, out);
    }

    /// [`Pack::masks_prepped`] of the packs `packs[j]` for each bit `j` set
    /// in `met` into `out[j]` (the other slots left as they are): the same
    /// masks. Here: one call per run of consecutive bits; a pack with a
    /// SIMD filter takes them all in one call.
    #[inline]
    fn masks_met(
        packs: &[Self],
        met: u32,
        ray: &PackRay,
        prep: &Self::Prep,
        isa: crate::simd::Isa,
        out: &mut [u32],
    ) {
        let mut m = met;
        while m != 0 {
            let j = m.trailing_zeros() as usize;
            let n = (m >> j).trailing_ones() as usize;
            Self::masks_prepped(&packs[j..j + n], ray, prep, isa, &mut out[j..j + n]);
            m &= !(((1u64 << (j + n)) - 1) as u32);
        }
    }

    /// True when [`Pack::hits_met`] keeps the lanes' answers (a pack with
    /// the disc filter); else `hits_met` is never called.
    const LANE_HITS: bool = false;

    /// [`Pack::masks_met`] (the same masks into `out`) with each met pack
    /// `j`'s lanes' `(t, u, v)` into `hits` slot `j`, from which
    /// [`Pack::lane_hit`] decides a lane as [`Primitive::intersect`] does;
    /// only where [`Pack::LANE_HITS`] (here: the masks alone).
    #[inline]
    fn hits_met(
        packs: &[Self],
        met: u32,
        ray: &PackRay,
        prep: &Self::Prep,
        isa: crate::simd::Isa,
        out: &mut [u32],
        hits: &mut crate::simd::LaneHits<'_>,
    ) {
        let _ = hits;
        Self::masks_met(packs, met, ray, prep, isa, out);
    }

    /// The hit [`Primitive::intersect`] finds on lane `lane` (id `id`,
    /// `side` as in [`Pack::get`]) within `[t_min, cut]`, given that
    /// [`Pack::hits_met`] passed the lane with `(t, u, v)` for a span
    /// `[t_min, t_max]` with `t_max >= cut`: bit for bit `intersect`'s
    /// answer. Only where [`Pack::LANE_HITS`] (here: `intersect` itself).
    #[inline]
    fn lane_hit(
        &self,
        lane: usize,
        id: u32,
        side: &Self::Side,
        ray: &Ray,
        (t_min, cut): (f32, f32),
        tuv: (f32, f32, f32),
    ) -> Option<Hit>
    where
        P: Primitive,
    {
        let _ = tuv;
        self.get(lane, id, side).intersect(ray, t_min, cut)
    }

    /// [`Pack::may_hit`] of each of `packs` for each ray `k` set in
    /// `active` into `out[j][k]` (0 for the other rays), and the rays whose
    /// mask is not zero into `rays[j]` (bit `k`; `out` and `rays` at least
    /// as long as `packs`), on the SIMD path `isa` where the pack has one:
    /// every ray's lanes exactly those [`Pack::masks`] gives it alone.
    #[inline]
    fn masks_rays(
        packs: &[Self],
        rays: &PackRays,
        active: u32,
        isa: crate::simd::Isa,
        out: &mut [[u32; crate::simd::RAYS]],
        any: &mut [u32],
    ) {
        // Each active ray's masks by [`Pack::masks`] (the pack's SIMD path
        // where it has one).
        masks_per_ray(packs, rays, active, out, any, |c, r, _, m| {
            Self::masks(c, r, isa, m);
        });
    }

    /// [`Pack::masks_rays`] given each active ray's [`Pack::Prep`]
    /// (`preps[k]`, made by [`Pack::prep`] from ray `k`; `None` for a ray
    /// not active): the same masks.
    #[inline]
    fn masks_rays_prepped(
        packs: &[Self],
        rays: &PackRays,
        preps: &[Option<Self::Prep>; crate::simd::RAYS],
        active: u32,
        isa: crate::simd::Isa,
        out: &mut [[u32; crate::simd::RAYS]],
        any: &mut [u32],
    ) {
        let _ = preps;
        Self::masks_rays(packs, rays, active, isa, out, any);
    }

    /// [`Pack::masks`] of the packs `packs[at[j]]` into `out[j]` (the
    /// packs a leaf of the octree's shared layout lists, not all
    /// consecutive). Here: one [`Pack::masks`] call per run of consecutive
    /// indices; a pack with a SIMD filter takes them all in one call.
    #[inline]
    fn masks_at(packs: &[Self], at: &[u32], ray: &PackRay, isa: crate::simd::Isa, out: &mut [u32]) {
        let mut j = 0;
        while j < at.len() {
            let p = at[j] as usize;
            let n = runs_from(&at[j..]);
            Self::masks(&packs[p..p + n], ray, isa, &mut out[j..j + n]);
            j += n;
        }
    }

    /// [`Pack::masks_rays`] of the packs `packs[at[j]]` into `out[j]` and
    /// `any[j]`, as [`Pack::masks_at`].
    #[inline]
    fn masks_rays_at(
        packs: &[Self],
        at: &[u32],
        rays: &PackRays,
        active: u32,
        isa: crate::simd::Isa,
        out: &mut [[u32; crate::simd::RAYS]],
        any: &mut [u32],
    ) {
        let mut j = 0;
        while j < at.len() {
            let p = at[j] as usize;
            let n = runs_from(&at[j..]);
            let (o, a) = (&mut out[j..j + n], &mut any[j..j + n]);
            Self::masks_rays(&packs[p..p + n], rays, active, isa, o, a);
            j += n;
        }
    }
}

/// Each active ray `k`'s masks of `packs` by `masks(chunk, ray k, k, out)`,
/// a chunk of packs at a time, into `out[j][k]` (0 for the other rays),
/// and the rays with a lane passed into `any[j]`: [`Pack::masks_rays`]
/// one ray after another.
#[inline]
pub(crate) fn masks_per_ray<T>(
    packs: &[T],
    rays: &PackRays,
    active: u32,
    out: &mut [[u32; crate::simd::RAYS]],
    any: &mut [u32],
    mut masks: impl FnMut(&[T], &PackRay, usize, &mut [u32]),
) {
    const CHUNK: usize = 64;
    let mut buf = [0u32; CHUNK];
    for (c, chunk) in packs.chunks(CHUNK).enumerate() {
        let out = &mut out[c * CHUNK..c * CHUNK + chunk.len()];
        let any = &mut any[c * CHUNK..c * CHUNK + chunk.len()];
        out.fill([0; crate::simd::RAYS]);
        any.fill(0);
        let mut left = active & ((1 << crate::simd::RAYS) - 1);
        while left != 0 {
            let k = left.trailing_zeros() as usize;
            left &= left - 1;
            let ray = PackRay {
                origin: rays.origin,
                dir: rays.dir[k],
                t_min: rays.t_min[k],
                t_max: rays.t_max[k],
            };
            let m = &mut buf[..chunk.len()];
            masks(chunk, &ray, k, m);
            for ((o, a), &m) in out.iter_mut().zip(any.iter_mut()).zip(m.iter()) {
                o[k] = m;
                *a |= u32::from(m != 0) << k;
            }
        }
    }

}

/// How many indices at the start of `at` (not empty) are consecutive.
#[inline]
fn runs_from(at: &[u32]) -> usize {
    1 + at[1..]
        .iter()
        .zip(1..)
        .take_while(|&(&a, d)| a == at[0] + d)
        .count()
}

/// Packs filtered per call by [`Pack::masks_at`] on a SIMD path (the
/// longest list of indices taken at once; longer ones are cut).
pub(crate) const AT_CHUNK: usize = 16;

/// The pack of a primitive with no SIMD filter: one primitive, tested by
/// [`Primitive::intersect`] itself (`None` is padding).
#[derive(Clone, Copy, Debug)]
pub struct Single<P>(Option<P>);

impl<P: Primitive> Pack<P> for Single<P> {
    const LANES: usize = 1;
    const EMPTY: Self = Single(None);
    type Side = ();

    fn side(_prims: &[P]) {}

    fn side_bytes((): &()) -> usize {
        0
    }

    type Prep = ();

    fn prep(_ray: &PackRay) {}

    fn set(&mut self, _lane: usize, p: &P) {
        self.0 = Some(*p);
    }

    fn get(&self, _lane: usize, _id: u32, (): &()) -> P {
        match self.0 {
            Some(p) => p,
            None => unreachable!("padding lanes are never passed by may_hit"),
        }
    }

    fn may_hit(&self, lanes: &PackRay) -> u32 {
        let ray = Ray {
            origin: lanes.origin.into(),
            dir: lanes.dir.into(),
        };
        let (t_min, t_max) = (lanes.t_min, lanes.t_max);
        u32::from(
            self.0
                .is_some_and(|p| p.intersect(&ray, t_min, t_max).is_some()),
        )
    }
}
