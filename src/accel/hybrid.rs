//! Splats and triangles in one backend (issue 57): a splat backend and a
//! triangle backend of the same registry entry, queried in turn, their
//! hits offered to one window. Splat `i` keeps id `i`; triangle `j` gets
//! id `first + j`. The window does not depend on the order hits arrive in
//! (rule 2 of the backend contract, `docs/DESIGN.md`), so the merged
//! window is the one a single structure over both would give, on every
//! backend alike. A scene without triangles never builds one: its
//! backend is the splats' own, as before.

use super::{Backend, BackendInfo, BuildStats, CandidateHits, Departure, PACKET, Query};
use crate::data::Splat;
use crate::error::Result;
use crate::primitive::{Disc, Triangle};

/// A splat backend and a triangle backend as one.
pub struct Hybrid {
    splats: Box<dyn Backend>,
    tris: Box<dyn Backend>,
    first: u32,
    stats: BuildStats,
}

impl Hybrid {
    /// The two backends, triangle ids starting at `first` (the splats'
    /// count).
    #[must_use]
    pub fn new(splats: Box<dyn Backend>, tris: Box<dyn Backend>, first: u32) -> Hybrid {
        let (a, b) = (splats.stats(), tris.stats());
        let stats = BuildStats {
            build_seconds: a.build_seconds + b.build_seconds,
            memory_bytes: a.memory_bytes + b.memory_bytes,
            nodes: a.nodes + b.nodes,
            leaves: a.leaves + b.leaves,
            mean_refs_per_leaf: a.mean_refs_per_leaf,
        };
        Hybrid {
            splats,
            tris,
            first,
            stats,
        }
    }

    /// The query as the splat side sees it: a ray leaving a triangle
    /// skips no splat. The splats' self-hit rule would take a splat
    /// standing on a triangle floor, met from behind by a ray rising off
    /// the floor beside its foot, for the surface the ray leaves (its
    /// "rising" case) and leak light under it
    /// (`tests/triangles.rs`, the contact case); a triangle is an exact
    /// surface, with no noisy neighbours to skip.
    fn splat_query<'a>(&self, q: &Query<'a>) -> Query<'a> {
        Query {
            from: q.from.filter(|d| d.id < self.first),
            ..*q
        }
    }

    /// The query as the triangle side sees it, up to `t_max`: triangle
    /// ids from 0, a departure from a splat leaves no triangle, and no
    /// hit passed over (the pass-over rule is the Phong splats').
    fn tri_query<'a>(&self, q: &Query<'a>, t_max: f32) -> Query<'a> {
        Query {
            t_max,
            from: q.from.map(|d| Departure {
                id: d.id.checked_sub(self.first).unwrap_or(u32::MAX),
                ..d
            }),
            pass: None,
            ..*q
        }
    }
}

impl Backend for Hybrid {
    fn intersect_from(&self, q: &Query, hits: &mut CandidateHits) {
        self.splats.intersect_from(&self.splat_query(q), hits);
        let mut tris = CandidateHits::new(hits.xi());
        // A triangle beyond the splats' window can never be a candidate.
        let t_max = q.t_max.min(hits.far());
        self.tris
            .intersect_from(&self.tri_query(q, t_max), &mut tris);
        hits.merge(&tris, self.first);
    }

    fn occluded_from(&self, q: &Query) -> bool {
        self.splats.occluded_from(&self.splat_query(q))
            || self.tris.occluded_from(&self.tri_query(q, q.t_max))
    }

    fn stats(&self) -> &BuildStats {
        &self.stats
    }

    fn prefers_packets(&self) -> bool {
        self.splats.prefers_packets()
    }

    /// Each side's packet call in turn (a coherent batch stays one on
    /// both), then each query's windows merged as in
    /// [`Backend::intersect_from`]: the same candidates.
    fn intersect_packet(&self, qs: &[Query], hits: &mut [CandidateHits]) {
        assert!(hits.len() >= qs.len(), "a window per query");
        for (qs, hits) in qs.chunks(PACKET).zip(hits.chunks_mut(PACKET)) {
            let n = qs.len();
            let sq: [Query; PACKET] = std::array::from_fn(|k| self.splat_query(&qs[k.min(n - 1)]));
            self.splats.intersect_packet(&sq[..n], hits);
            let tq: [Query; PACKET] = std::array::from_fn(|k| {
                let i = k.min(n - 1);
                self.tri_query(&qs[i], qs[i].t_max.min(hits[i].far()))
            });
            let mut tris: [CandidateHits; PACKET] =
                std::array::from_fn(|k| CandidateHits::new(hits[k.min(n - 1)].xi()));
            self.tris.intersect_packet(&tq[..n], &mut tris[..n]);
            for (h, t) in hits.iter_mut().zip(&tris[..n]) {
                h.merge(t, self.first);
            }
        }
    }

    /// Each side's packet call, the answers or-ed.
    fn occluded_packet(&self, qs: &[Query], out: &mut [bool]) {
        assert!(out.len() >= qs.len(), "an answer per query");
        for (qs, out) in qs.chunks(PACKET).zip(out.chunks_mut(PACKET)) {
            let n = qs.len();
            let sq: [Query; PACKET] = std::array::from_fn(|k| self.splat_query(&qs[k.min(n - 1)]));
            self.splats.occluded_packet(&sq[..n], out);
            let tq: [Query; PACKET] = std::array::from_fn(|k| {
                let q = &qs[k.min(n - 1)];
                self.tri_query(q, q.t_max)
            });
            let mut blocked = [false; PACKET];
            self.tris.occluded_packet(&tq[..n], &mut blocked[..n]);
            for (o, b) in out.iter_mut().zip(blocked) {
                *o |= b;
            }
        }
    }

    /// Each side's call for scattered rays, the triangles asked only of
    /// the queries the splats leave open.
    fn occluded_each(&self, qs: &[Query], out: &mut [bool]) {
        assert!(out.len() >= qs.len(), "an answer per query");
        let sq: Vec<Query> = qs.iter().map(|q| self.splat_query(q)).collect();
        self.splats.occluded_each(&sq, out);
        let open: Vec<usize> = (0..qs.len()).filter(|&i| !out[i]).collect();
        let tq: Vec<Query> = open.iter().map(|&i| self.tri_query(&qs[i], qs[i].t_max)).collect();
        let mut blocked = vec![false; open.len()];
        self.tris.occluded_each(&tq, &mut blocked);
        for (&i, b) in open.iter().zip(blocked) {
            out[i] = b;
        }
    }
}

impl BackendInfo<Disc> {
    /// This backend over `splats` and `tris` together: the splats' own
    /// ([`BackendInfo::build_splats`]) when there are no triangles, else a
    /// [`Hybrid`] of it and the same-named entry's backend over the
    /// triangles (ids after the splats').
    pub fn build_hybrid(&self, splats: &[Splat], tris: &[Triangle]) -> Result<Box<dyn Backend>> {
        let s = self.build_splats(splats)?;
        if tris.is_empty() {
            return Ok(s);
        }
        let first = u32::try_from(splats.len())
            .ok()
            .filter(|f| u32::try_from(tris.len()).is_ok_and(|n| f.checked_add(n).is_some()))
            .ok_or_else(|| crate::Error::invalid("too many splats and triangles for 32-bit ids"))?;
        let t = super::registry::lookup::<Triangle>(self.name)?.build(tris)?;
        Ok(Box::new(Hybrid::new(s, t, first)))
    }
}

impl BackendInfo<Disc> {
    /// This backend over a loaded scene's splats and triangles
    /// ([`BackendInfo::build_hybrid`]): what the renderer, `compare`, the
    /// sweep and the viewer trace.
    pub fn build_scene(&self, scene: &crate::scene::Scene) -> Result<Box<dyn Backend>> {
        self.build_hybrid(&scene.splats, &scene.triangles.tris)
    }
}
