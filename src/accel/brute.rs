//! The brute-force oracle: every ray against every splat.

use super::{Backend, BuildStats, Candidate, CandidateHits, Ray, intersect_disc};
use crate::splat::Disc;

/// Tests every splat for every ray. The reference the other backends are
/// checked against on small inputs.
pub struct Brute {
    discs: Vec<Disc>,
    stats: BuildStats,
}

impl Brute {
    /// Builds (copies) the disc list.
    #[must_use]
    pub fn new(discs: &[Disc]) -> Brute {
        Brute {
            discs: discs.to_vec(),
            stats: BuildStats {
                memory_bytes: std::mem::size_of_val(discs),
                ..BuildStats::default()
            },
        }
    }
}

impl Brute {
    /// Records the build time measured by the caller.
    pub fn set_build_seconds(&mut self, s: f64) {
        self.stats.build_seconds = s;
    }
}

impl Backend for Brute {
    fn name(&self) -> &'static str {
        "brute"
    }

    fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32, hits: &mut CandidateHits) {
        hits.clear();
        for (id, d) in self.discs.iter().enumerate() {
            if let Some((t, u, v)) = intersect_disc(d, ray, t_min, t_max) {
                hits.offer(Candidate {
                    id: id as u32,
                    t,
                    u,
                    v,
                });
            }
        }
    }

    fn occluded(&self, ray: &Ray, t_min: f32, t_max: f32) -> bool {
        self.discs
            .iter()
            .any(|d| intersect_disc(d, ray, t_min, t_max).is_some())
    }

    fn stats(&self) -> &BuildStats {
        &self.stats
    }
}
