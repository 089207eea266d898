//! The brute-force oracle: every ray against every primitive.

use super::{Backend, BuildStats, Candidate, CandidateHits, Query, Skip};
use crate::primitive::Primitive;
use std::time::Instant;

/// Tests every primitive for every ray. The reference the other backends
/// are checked against on small inputs.
pub struct Brute<P> {
    prims: Vec<P>,
    stats: BuildStats,
}

impl<P: Primitive> Brute<P> {
    /// Builds (copies) the primitive list.
    #[must_use]
    pub fn new(prims: &[P]) -> Brute<P> {
        let start = Instant::now();
        let prims = prims.to_vec();
        let stats = BuildStats {
            build_seconds: start.elapsed().as_secs_f64(),
            memory_bytes: std::mem::size_of_val(prims.as_slice()),
            ..BuildStats::default()
        };
        Brute { prims, stats }
    }

    /// Every hit that counts, in primitive order.
    fn hits<'a>(&'a self, q: &'a Query) -> impl Iterator<Item = Candidate> + 'a {
        self.prims.iter().enumerate().filter_map(move |(id, p)| {
            let h = p.intersect(&q.ray, q.t_min, q.t_max)?;
            let id = id as u32;
            (!q.secondary().skips(q.ray.dir, id, p, &h)).then_some(Candidate {
                id,
                t: h.t,
                u: h.u,
                v: h.v,
            })
        })
    }
}

impl<P: Primitive> Backend for Brute<P> {
    fn intersect_from(&self, q: &Query, hits: &mut CandidateHits) {
        hits.clear();
        if q.meets_nothing() {
            return;
        }
        for c in self.hits(q) {
            hits.offer(c);
        }
    }

    fn occluded_from(&self, q: &Query) -> bool {
        !q.meets_nothing() && self.hits(q).next().is_some()
    }

    fn stats(&self) -> &BuildStats {
        &self.stats
    }
}

/// A second brute force, registered only with the `test-backends` feature:
/// it offers the hits in reverse primitive order, so the conformance suite
/// shows that the candidate window does not depend on the order hits
/// arrive in, and that a backend added with one registry line is tested.
#[cfg(feature = "test-backends")]
pub struct BruteReversed<P>(Brute<P>);

#[cfg(feature = "test-backends")]
impl<P: Primitive> BruteReversed<P> {
    /// Builds (copies) the primitive list.
    #[must_use]
    pub fn new(prims: &[P]) -> BruteReversed<P> {
        BruteReversed(Brute::new(prims))
    }
}

#[cfg(feature = "test-backends")]
impl<P: Primitive> Backend for BruteReversed<P> {
    fn intersect_from(&self, q: &Query, hits: &mut CandidateHits) {
        hits.clear();
        if q.meets_nothing() {
            return;
        }
        let all: Vec<Candidate> = self.0.hits(q).collect();
        for c in all.into_iter().rev() {
            hits.offer(c);
        }
    }

    fn occluded_from(&self, q: &Query) -> bool {
        self.0.occluded_from(q)
    }

    fn stats(&self) -> &BuildStats {
        self.0.stats()
    }
}
