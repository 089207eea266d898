//! The Embree 4 backend: splats as user-geometry discs (DESIGN §2). Safe
//! code only; the FFI is in [`crate::embree`].

use super::{Backend, BuildStats, CandidateHits, Ray};
use crate::embree::{Device, DiscScene, EmbreeError};
use crate::splat::Splat;
use std::time::Instant;

/// Embree's BVH over user-geometry discs.
pub struct EmbreeBackend {
    scene: DiscScene,
    stats: BuildStats,
}

impl EmbreeBackend {
    /// Builds the Embree scene over `splats` on `device`.
    pub fn new(device: &Device, splats: &[Splat]) -> Result<EmbreeBackend, EmbreeError> {
        let start = Instant::now();
        let scene = DiscScene::new(device, splats)?;
        let stats = BuildStats {
            build_seconds: start.elapsed().as_secs_f64(),
            memory_bytes: std::mem::size_of_val(splats) / std::mem::size_of::<Splat>().max(1)
                * std::mem::size_of::<crate::splat::Disc>(),
            ..BuildStats::default()
        };
        Ok(EmbreeBackend { scene, stats })
    }

    /// Errors Embree reported since the last check.
    pub fn check(&self) -> Result<(), EmbreeError> {
        self.scene.check()
    }
}

impl Backend for EmbreeBackend {
    fn name(&self) -> &'static str {
        "embree"
    }

    fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32, hits: &mut CandidateHits) {
        self.scene.intersect(ray, t_min, t_max, hits);
    }

    fn occluded(&self, ray: &Ray, t_min: f32, t_max: f32) -> bool {
        self.scene.occluded(ray, t_min, t_max)
    }

    fn stats(&self) -> &BuildStats {
        &self.stats
    }
}
