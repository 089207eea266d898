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
pub mod embree;
pub mod octree;
pub mod registry;
mod window;

pub use crate::geometry::Ray;
pub use registry::{BackendInfo, backends};
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

/// One acceleration backend (`docs/DESIGN.md`, "The backend contract"). Implemented by the brute-force
/// oracle, the octree and Embree.
pub trait Backend: Send + Sync {
    /// Short name: `brute`, `octree`, `embree`.
    fn name(&self) -> &'static str;

    /// Fills `hits` (cleared first) with the candidate hits of `ray` in
    /// `[t_min, t_max]`: the nearest and all within `hits.xi()` of it.
    fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32, hits: &mut CandidateHits);

    /// True when any splat is hit with `t` in `[t_min, t_max]`.
    fn occluded(&self, ray: &Ray, t_min: f32, t_max: f32) -> bool;

    /// Build figures.
    fn stats(&self) -> &BuildStats;
}
