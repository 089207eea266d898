//! Hostile rays at the backend contract, given to the backends directly:
//! NaN and infinite origins and directions, NaN and reversed intervals, and
//! a model at UTM-scale coordinates (about 4e6, where the readers would
//! have re-centred it). The defined answer is a miss (no candidate, not
//! occluded), identical on every tested backend and the oracle.

use crate::common::*;
use glam::Vec3;
use splatray::accel::{CandidateHits, Ray};
use splatray::scene::SceneScale;
use splatray::splat::Splat;

/// Every hostile variant of a ray that hits, and what it is.
fn hostile(origin: Vec3, dir: Vec3) -> Vec<(String, Query<'static>)> {
    let (nan, inf) = (f32::NAN, f32::INFINITY);
    let ray = |o: Vec3, d: Vec3| Ray { origin: o, dir: d };
    let mut out = Vec::new();
    for (what, o) in [
        ("NaN origin x", Vec3::new(nan, origin.y, origin.z)),
        ("NaN origin", Vec3::splat(nan)),
        ("+inf origin z", Vec3::new(origin.x, origin.y, inf)),
        ("-inf origin x", Vec3::new(-inf, origin.y, origin.z)),
        ("infinite origin", Vec3::new(inf, -inf, inf)),
    ] {
        out.push((what.to_string(), Query::new(ray(o, dir), 0.0, inf)));
    }
    for (what, d) in [
        ("NaN direction x", Vec3::new(nan, dir.y, dir.z)),
        ("NaN direction", Vec3::splat(nan)),
        ("+inf direction z", Vec3::new(dir.x, dir.y, inf)),
        ("-inf direction x", Vec3::new(-inf, dir.y, dir.z)),
        ("infinite direction", Vec3::new(inf, inf, -inf)),
        ("zero direction", Vec3::ZERO),
    ] {
        out.push((what.to_string(), Query::new(ray(origin, d), 0.0, inf)));
    }
    for (what, t_min, t_max) in [
        ("NaN t_min", nan, inf),
        ("NaN t_max", 0.0, nan),
        ("NaN interval", nan, nan),
        ("reversed interval", 100.0, 0.0),
        ("reversed to -inf", 0.0, -inf),
        ("interval from +inf", inf, inf),
    ] {
        out.push((what.to_string(), Query::new(ray(origin, dir), t_min, t_max)));
    }
    out
}

/// Rays aimed at splat centres (each hits as given), then made hostile:
/// every one must miss on every backend, with the oracle's (empty) window
/// and no occlusion.
fn hostile_rays_miss(splats: &[Splat], what: &str) {
    let b = backends(splats);
    let xi = SceneScale::from_diagonal(diagonal(splats)).xi;
    let (lo, hi) = bounds(splats);
    let eye = hi + (hi - lo) * 0.7;
    let mut cases = 0;
    for s in splats.iter().step_by(splats.len() / 8) {
        let dir = (s.center - eye).normalize();
        let good = Query::new(Ray { origin: eye, dir }, 0.0, f32::INFINITY);
        assert!(
            !windows(&b, splats, &good, xi, what).is_empty(),
            "{what}: the ray before it is made hostile must hit: {good:?}"
        );
        for (how, query) in hostile(eye, dir) {
            let label = format!("{what}: {how}");
            let h = windows(&b, splats, &query, xi, &label);
            assert!(h.is_empty(), "{label}: {query:?} hit {:?}", h.as_slice());
            for backend in b.tested.iter().chain(std::iter::once(&b.oracle)) {
                let mut got = CandidateHits::new(xi);
                backend.intersect(&query.ray, query.t_min, query.t_max, &mut got);
                assert!(got.is_empty(), "{label}: {} hit", backend.name());
                assert!(
                    !backend.occluded(&query.ray, query.t_min, query.t_max),
                    "{label}: {} occluded",
                    backend.name()
                );
            }
            cases += 1;
        }
    }
    assert!(cases >= 8 * 17, "{what}: only {cases} cases");
}

#[test]
fn non_finite_rays_and_bad_intervals_miss_on_every_backend() {
    hostile_rays_miss(&blobby_splats(400, seed()), "unit model");
}

/// A model about 100 units across at UTM-scale coordinates (x 4e5,
/// y 4e6: f32 steps of 0.03 and 0.25 there), given to the backends as it
/// is: hostile rays miss, and ordinary ones agree with the oracle.
#[test]
fn a_model_at_utm_coordinates_agrees_and_hostile_rays_miss() {
    let at = Vec3::new(4.0e5, 4.0e6, 120.0);
    let splats: Vec<Splat> = blobby_splats(400, seed())
        .iter()
        .map(|s| Splat {
            center: s.center * 100.0 + at,
            radii: s.radii * 100.0,
            ..*s
        })
        .collect();
    hostile_rays_miss(&splats, "model at 4e6");
    let b = backends(&splats);
    let xi = SceneScale::from_diagonal(diagonal(&splats)).xi;
    let queries = random_queries(&splats, 600, seed());
    let hits = count_hits(b.oracle.as_ref(), &queries, xi);
    eprintln!("model at 4e6: {hits} of {} rays hit", queries.len());
    assert!(hits > queries.len() / 3, "model at 4e6: only {hits} hits");
    assert_all_agree(&b, &splats, &queries, xi, "model at 4e6");
    let (lo, hi) = bounds(&splats);
    let c = (lo + hi) * 0.5;
    let camera = camera_queries(c + (hi - lo) * Vec3::new(0.3, 0.5, 1.8), c, 24, 24);
    assert_all_agree(&b, &splats, &camera, xi, "model at 4e6, camera");
}
