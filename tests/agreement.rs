//! The generic agreement suite (DESIGN §2): written once, run on every
//! backend (octree with either overlap test, Embree) against the brute-force
//! oracle. Candidate windows must be bit-identical, `occluded` answers equal,
//! and the shared resolver must give the same surface hit in every shading
//! mode. Seeded; `SPLATRAY_SEED` overrides the seed, printed on failure.

mod common;

use common::*;
use glam::Vec3;
use splatray::accel::octree::{Octree, OctreeParams};
use splatray::accel::{Backend, SceneScale};

const SPLATS: usize = 3000;

#[test]
fn random_rays_agree_on_every_backend() {
    let seed = seed();
    let splats = blobby_splats(SPLATS, seed);
    let scale = SceneScale::from_diagonal(diagonal(&splats));
    let b = backends(&splats);
    let queries = random_queries(&splats, 3000, seed);
    let hits = count_hits(&b.oracle, &queries, scale.xi);
    assert!(
        hits > queries.len() / 2,
        "the ray set should mostly hit: {hits} of {}",
        queries.len()
    );
    assert_all_agree(&b, &splats, &queries, scale.xi, "random rays");
}

#[test]
fn camera_and_secondary_rays_agree_on_every_backend() {
    let seed = seed();
    let splats = blobby_splats(SPLATS, seed);
    let scale = SceneScale::from_diagonal(diagonal(&splats));
    let b = backends(&splats);
    let camera = camera_queries(Vec3::new(0.7, 1.1, 4.0), Vec3::ZERO, 48, 40);
    let hits = count_hits(&b.oracle, &camera, scale.xi);
    assert!(hits > camera.len() / 4, "camera sees the model: {hits}");
    assert_all_agree(&b, &splats, &camera, scale.xi, "camera rays");
    let secondary = secondary_queries(
        &b.oracle,
        &splats,
        &camera,
        scale.xi,
        scale.eps_self,
        Vec3::new(5.0, 6.0, 3.0),
    );
    assert!(secondary.len() >= 2 * hits);
    assert_all_agree(
        &b,
        &splats,
        &secondary,
        scale.xi,
        "reflection and shadow rays",
    );
}

#[test]
fn wider_window_agrees_on_every_backend() {
    // A window 20 times wider gathers many candidates per ray (and some
    // overflows): the early exit of each backend must still agree.
    let seed = seed();
    let splats = blobby_splats(SPLATS, seed ^ 1);
    let xi = 20.0 * SceneScale::from_diagonal(diagonal(&splats)).xi;
    let b = backends(&splats);
    let queries = random_queries(&splats, 1000, seed ^ 2);
    assert_all_agree(&b, &splats, &queries, xi, "wide window");
}

#[test]
fn octree_reports_its_structure() {
    let splats = blobby_splats(SPLATS, seed());
    let t = Octree::new(&splats, &OctreeParams::default());
    let s = t.stats();
    assert_eq!(t.name(), "octree");
    assert!(s.nodes > s.leaves && s.leaves > SPLATS / 8, "{s:?}");
    // Each splat is referenced at least once (its centre's leaf), and
    // overlapping splats span more than one leaf.
    assert!(t.references() > SPLATS, "{} refs", t.references());
    assert!(s.mean_refs_per_leaf > 1.0, "{s:?}");
    assert!(s.memory_bytes >= t.references() * 52, "{s:?}");
    assert!(s.build_seconds > 0.0);
}

#[test]
fn comparison_catches_the_holes_of_a_broken_octree() {
    // The test-only octree that skips step 3 of §3.1 (splats only in their
    // centre's leaf) has holes; the agreement check must see them.
    let seed = seed();
    let splats = blobby_splats(SPLATS, seed);
    let xi = SceneScale::from_diagonal(diagonal(&splats)).xi;
    let broken = Octree::new(
        &splats,
        &OctreeParams {
            skip_overlap_insertion: true,
            ..OctreeParams::default()
        },
    );
    let b = backends(&splats);
    let queries = random_queries(&splats, 2000, seed);
    let err = agree(&b.oracle, &broken, &splats, &queries, xi)
        .expect_err("a broken octree must disagree with the oracle");
    assert!(err.contains("differ") || err.contains("occluded"), "{err}");
    assert_eq!(
        broken.references(),
        SPLATS,
        "broken tree holds each splat once"
    );
}
