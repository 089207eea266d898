//! The Embree 4 backend: primitives as one user geometry, whose callbacks
//! (below, in safe code) gather the candidate window of §4.3 into the query
//! of each ray; the FFI is in [`crate::embree`].

use super::{Backend, BuildStats, Candidate, CandidateHits, PACKET, Query, Secondary, Skip};
use crate::embree::{
    Device, EmbreeError, UserGeometry, UserScene, traversal_end, traversal_span,
};
use crate::geometry::Ray;
use crate::primitive::Primitive;
use std::time::Instant;

/// The primitives as Embree sees them, addressed by primitive id.
struct Primitives<P>(Vec<P>);

/// What one ray's query carries to the intersect callback.
struct Gather<'q> {
    hits: &'q mut CandidateHits,
    /// The query's exact span ([`traversal_span`] is what Embree sees).
    t_min: f32,
    t_max: f32,
    /// What a secondary ray skips (the splat it leaves, hits it passes):
    /// such hits are not offered.
    skip: Secondary<'q>,
}

/// What one shadow ray's query carries to the occluded callback.
struct Shadow<'q> {
    /// The query's exact span ([`traversal_span`] is what Embree sees).
    t_min: f32,
    t_max: f32,
    skip: Secondary<'q>,
}

impl Shadow<'_> {
    fn of<'a>(q: &'a Query<'_>) -> Shadow<'a> {
        Shadow {
            t_min: q.t_min,
            t_max: q.t_max,
            skip: q.secondary(),
        }
    }
}

impl<P: Primitive> UserGeometry for Primitives<P> {
    type Query<'q> = Gather<'q>;
    type ShadowQuery<'q> = Shadow<'q>;

    fn count(&self) -> usize {
        self.0.len()
    }

    /// The tight box of the primitive, padded by a few ulps of its
    /// coordinates so that rounding can never cull a real hit.
    fn bounds(&self, prim: u32) -> ([f32; 3], [f32; 3]) {
        let p = &self.0[prim as usize];
        let (c, h) = (p.center(), p.half_extent());
        let pad = (c.abs() + h) * 4.0 * f32::EPSILON;
        ((c - h - pad).to_array(), (c + h + pad).to_array())
    }

    /// Instead of keeping only the closest hit, records every hit into the
    /// window and moves `tfar` to `min(t_max, nearest + xi)` (widened as
    /// [`traversal_end`]), so Embree culls everything beyond the window
    /// (§4.3). The hit is tested against the query's exact span, not
    /// Embree's widened `tnear`.
    #[inline]
    fn intersect(
        &self,
        prim: u32,
        ray: &Ray,
        _tnear: f32,
        tfar: f32,
        q: &mut Gather<'_>,
    ) -> Option<f32> {
        // The splat the ray leaves is skipped whatever the test says:
        // Embree offers it to most secondary rays (its box holds their
        // origin), so its id is checked before the disc test.
        if q.skip.from.is_some_and(|d| d.id == prim) {
            return None;
        }
        let p = &self.0[prim as usize];
        let h = p.intersect(ray, q.t_min, tfar.min(q.t_max))?;
        if q.skip.skips(ray.dir, prim, p, &h) {
            return None;
        }
        let far = q.hits.offer(Candidate {
            id: prim,
            t: h.t,
            u: h.u,
            v: h.v,
        });
        Some(traversal_end(ray, far.min(q.t_max)))
    }

    #[inline]
    fn occluded(&self, prim: u32, ray: &Ray, _tnear: f32, _tfar: f32, s: &Shadow<'_>) -> bool {
        // As in `intersect`: the splat left first, by id; the exact span.
        if s.skip.from.is_some_and(|d| d.id == prim) {
            return false;
        }
        let p = &self.0[prim as usize];
        p.intersect(ray, s.t_min, s.t_max)
            .is_some_and(|h| !s.skip.skips(ray.dir, prim, p, &h))
    }
}

/// The rays `(ray, t_min, t_max)` of up to [`PACKET`] queries (lanes past
/// them repeat the first ray; the packet calls leave them out).
fn packet_rays(qs: &[Query]) -> [(Ray, f32, f32); PACKET] {
    std::array::from_fn(|k| {
        qs.get(k).map_or((qs[0].ray, 0.0, 0.0), |q| {
            let (lo, hi) = traversal_span(&q.ray, q.t_min, q.t_max);
            (q.ray, lo, hi)
        })
    })
}

/// Embree's BVH over user-geometry primitives.
pub struct EmbreeBackend<P: Primitive> {
    scene: UserScene<Primitives<P>>,
    stats: BuildStats,
}

impl<P: Primitive> EmbreeBackend<P> {
    /// Builds the Embree scene over `prims` on `device`. Its memory is what
    /// the device's memory monitor saw Embree keep for it.
    pub fn new(device: &Device, prims: &[P]) -> Result<EmbreeBackend<P>, EmbreeError> {
        let before = device.memory();
        let start = Instant::now();
        let scene = UserScene::new(device, Primitives(prims.to_vec()))?;
        let stats = BuildStats {
            build_seconds: start.elapsed().as_secs_f64(),
            memory_bytes: device.memory().saturating_sub(before),
            ..BuildStats::default()
        };
        Ok(EmbreeBackend { scene, stats })
    }

    /// Errors Embree reported since the last check.
    pub fn check(&self) -> Result<(), EmbreeError> {
        self.scene.check()
    }
}

impl<P: Primitive> Backend for EmbreeBackend<P> {
    fn intersect_from(&self, q: &Query, hits: &mut CandidateHits) {
        hits.clear();
        if q.meets_nothing() {
            return;
        }
        let (lo, hi) = traversal_span(&q.ray, q.t_min, q.t_max);
        let mut g = Gather {
            hits,
            t_min: q.t_min,
            t_max: q.t_max,
            skip: q.secondary(),
        };
        self.scene.intersect(&q.ray, lo, hi, &mut g);
    }

    fn occluded_from(&self, q: &Query) -> bool {
        if q.meets_nothing() {
            return false;
        }
        let (lo, hi) = traversal_span(&q.ray, q.t_min, q.t_max);
        self.scene.occluded(&q.ray, lo, hi, &Shadow::of(q))
    }

    /// True: `rtcIntersect8` traces the primary rays of 8×1 pixel tiles
    /// 1.69 times and the shadow rays of neighbouring hits 1.58 times as
    /// fast as `rtcIntersect1` at 35k splats (1.02 / 0.75 at 1M), and
    /// renders the bunny in 0.89 of the time (`docs/notes/backends.md`,
    /// "Issue 25: ray packets", with the commands).
    fn prefers_packets(&self) -> bool {
        true
    }

    /// Packets of up to eight rays through `rtcIntersect8`, each lane with
    /// its own window (the same callbacks: the same candidates as one ray
    /// at a time).
    fn intersect_packet(&self, qs: &[Query], hits: &mut [CandidateHits]) {
        assert!(hits.len() >= qs.len(), "a window per query");
        for (qs, hits) in qs.chunks(PACKET).zip(hits.chunks_mut(PACKET)) {
            let rays = packet_rays(qs);
            let mut it = qs.iter().zip(hits.iter_mut());
            let mut gathers: [Option<Gather<'_>>; PACKET] = std::array::from_fn(|_| {
                it.next().map(|(q, hits)| {
                    hits.clear();
                    Gather {
                        hits,
                        t_min: q.t_min,
                        t_max: q.t_max,
                        skip: q.secondary(),
                    }
                })
            });
            self.scene.intersect8(&rays[..qs.len()], &mut gathers);
            for (q, g) in qs.iter().zip(gathers.iter_mut()) {
                if q.meets_nothing()
                    && let Some(g) = g
                {
                    g.hits.clear();
                }
            }
        }
    }

    /// Packets of up to eight rays through `rtcOccluded8`.
    fn occluded_packet(&self, qs: &[Query], out: &mut [bool]) {
        assert!(out.len() >= qs.len(), "an answer per query");
        for (qs, out) in qs.chunks(PACKET).zip(out.chunks_mut(PACKET)) {
            let rays = packet_rays(qs);
            let skip: [Shadow<'_>; PACKET] = std::array::from_fn(|k| {
                qs.get(k).map_or(
                    Shadow {
                        t_min: 0.0,
                        t_max: 0.0,
                        skip: Secondary {
                            from: None,
                            pass: None,
                        },
                    },
                    Shadow::of,
                )
            });
            self.scene.occluded8(&rays[..qs.len()], &skip, out);
            // An empty or undefined interval meets nothing, as one ray at a
            // time (Embree marks an occluded lane by tfar = -inf, so a
            // t_max of -inf alone would read as occluded).
            for (q, o) in qs.iter().zip(out.iter_mut()) {
                *o &= !q.meets_nothing();
            }
        }
    }

    fn stats(&self) -> &BuildStats {
        &self.stats
    }
}
