//! Secondary rays skip the surface they leave and nothing else
//! (`accel::Departure`), identically in every tested backend: a coarse,
//! slightly uneven floor of large overlapping splats with a sphere of splats
//! resting on it. Rays leaving the floor toward the sphere must hit it
//! however close to the contact they start; rays grazing the floor or the
//! sphere must not hit the splats they start among (one in the test's
//! 3,150 may: see its comment).

use crate::common::*;
use glam::Vec3;
use splatray::accel::{CandidateHits, Departure, Ray};
use splatray::resolve::{Resolved, ShadingMode, resolve};
use splatray::scene::SceneScale;
use splatray::scene::shapes;
use splatray::splat::Splat;

const FLOOR_RADIUS: f32 = 0.45;
const SPHERE_RADIUS: f32 = 0.5;

/// The floor's splats first (ids below the returned count), then the
/// sphere's; the sphere touches the floor at `contact`.
struct Set {
    splats: Vec<Splat>,
    floor: usize,
    center: Vec3,
    contact: Vec3,
}

fn floor_and_sphere(seed: u64) -> Set {
    let mut rng = Rng::new(seed);
    let mut splats = Vec::new();
    for i in 0..10 {
        for j in 0..10 {
            let c = Vec3::new(
                -2.25 + 0.5 * i as f32,
                rng.range(-0.004, 0.004),
                -2.25 + 0.5 * j as f32,
            );
            // Tilted by up to ~1.2°: neighbours stand a little above or
            // below each other, as on a scanned floor.
            let n = Vec3::new(rng.range(-0.015, 0.015), 1.0, rng.range(-0.015, 0.015));
            splats.push(Splat::disc(c, n, FLOOR_RADIUS).unwrap());
        }
    }
    let floor = splats.len();
    let center = Vec3::new(0.1, SPHERE_RADIUS, 0.05);
    splats.extend(shapes::sphere(center, SPHERE_RADIUS, 1500));
    Set {
        splats,
        floor,
        center,
        contact: center - Vec3::Y * SPHERE_RADIUS,
    }
}

/// The departure of a ray leaving the surface a camera ray from `eye` meets
/// at `target`: the resolved hit, as the integrator leaves it.
fn depart(b: &Backends, set: &Set, eye: Vec3, target: Vec3, xi: f32) -> (Departure, bool) {
    let ray = Ray::new(eye, target - eye);
    let mut h = CandidateHits::new(xi);
    b.oracle.intersect(&ray, 0.0, f32::INFINITY, &mut h);
    let hit = resolve(&h, &ray, &set.splats, ShadingMode::Phong)
        .and_then(Resolved::hit)
        .unwrap_or_else(|| panic!("set-up: {ray:?} must hit"));
    (
        Departure {
            id: hit.id,
            point: hit.point,
            normal: hit.geometric_normal,
        },
        hit.front,
    )
}

/// The departure of a ray leaving the floor below `target`: on the floor
/// splat whose disc holds `target`'s vertical projection nearest its centre
/// (as the resolver picks), where the vertical through `target` meets it.
fn on_floor(set: &Set, target: Vec3) -> Departure {
    let (id, s) = set.splats[..set.floor]
        .iter()
        .enumerate()
        .min_by(|(_, a), (_, b)| {
            let r = |s: &Splat| (target - s.center).with_y(0.0).length();
            r(a).total_cmp(&r(b))
        })
        .unwrap();
    let t = s.normal.dot(s.center - target) / s.normal.y;
    Departure {
        id: id as u32,
        point: target + Vec3::Y * t,
        normal: s.normal,
    }
}

fn leaving(from: Departure, dir: Vec3, eps_self: f32) -> Query<'static> {
    Query {
        ray: Ray {
            origin: from.point,
            dir: dir.normalize(),
        },
        t_min: eps_self,
        t_max: f32::INFINITY,
        from: Some(from),
        pass: None,
    }
}

fn occluded_everywhere(b: &Backends, q: &Query) -> bool {
    let want = b.oracle.occluded_from(q);
    for backend in &b.tested {
        assert_eq!(
            backend.occluded_from(q),
            want,
            "{} occluded: {q:?}",
            backend.name()
        );
    }
    want
}

#[test]
fn rays_leaving_the_floor_hit_the_sphere_up_to_the_contact() {
    let set = floor_and_sphere(seed());
    let scale = SceneScale::from_diagonal(diagonal(&set.splats));
    let b = backends(&set.splats);
    let mut closer_than_a_floor_splat = 0;
    let mut queries = Vec::new();
    for k in 0..24 {
        let phi = k as f32 * std::f32::consts::TAU / 24.0 + 0.1;
        let out = Vec3::new(phi.cos(), 0.0, phi.sin());
        for rho in [0.03f32, 0.06, 0.1, 0.2, 0.35] {
            let from = on_floor(&set, set.contact + out * rho);
            // Toward the sphere's centre: through its underside.
            let query = leaving(from, set.center - from.point, scale.eps_self);
            let h = windows(&b, &set.splats, &query, scale.xi, "floor to sphere");
            let nearest = h
                .nearest()
                .unwrap_or_else(|| panic!("{query:?} must hit the sphere"));
            assert!(
                nearest.id as usize >= set.floor,
                "{query:?} must hit the sphere first, got floor splat {nearest:?}"
            );
            assert!(occluded_everywhere(&b, &query), "{query:?} not occluded");
            closer_than_a_floor_splat += usize::from(nearest.t < FLOOR_RADIUS);
            queries.push(query);
        }
    }
    // The old guard skipped every hit within the radius of the splat a ray
    // leaves: most of these hits lie within it.
    assert!(
        closer_than_a_floor_splat > queries.len() / 2,
        "set-up: only {closer_than_a_floor_splat} of {} hits lie within a floor splat's radius",
        queries.len()
    );
    assert_all_agree(&b, &set.splats, &queries, scale.xi, "floor to sphere");
}

#[test]
fn grazing_rays_do_not_hit_the_surface_they_leave() {
    let set = floor_and_sphere(seed() ^ 3);
    let scale = SceneScale::from_diagonal(diagonal(&set.splats));
    let b = backends(&set.splats);
    let mut rng = Rng::new(seed());
    let mut queries = Vec::new();
    let mut self_hits_without_rule = 0;
    let mut h = CandidateHits::new(scale.xi);
    let own = |id: u32, floor: bool| (id as usize >= set.floor) != floor;
    // Off the floor, away from the sphere, 4° to 8° above the departure
    // splat's plane: beyond the floor's own unevenness (tilts up to 1.2°,
    // heights ±0.004), so only the splats around the departure point stand
    // in the way.
    for _ in 0..150 {
        let phi = rng.range(0.0, std::f32::consts::TAU);
        let out = Vec3::new(phi.cos(), 0.0, phi.sin());
        let from = on_floor(&set, set.contact + out * rng.range(0.8, 1.8));
        let along = (out - from.normal * out.dot(from.normal)).normalize();
        let lift = rng.range(4.0, 8.0).to_radians();
        let q = leaving(
            from,
            along * lift.cos() + from.normal * lift.sin(),
            scale.eps_self,
        );
        queries.push((q, true));
    }
    // Off the sphere's lit side, nearly tangent: 0.5°–3° outward, and
    // 0.5°–3° inward (the chord out of the sphere is the same surface).
    for i in 0..3000 {
        let d = rng.unit();
        let d = Vec3::new(d.x, d.y.abs() * 0.8 + 0.2, d.z).normalize();
        let target = set.center + d * SPHERE_RADIUS;
        let (from, front) = depart(&b, &set, set.center + d * 3.0, target, scale.xi);
        assert!(front && from.id as usize >= set.floor);
        let t = from.normal.cross(rng.unit()).normalize();
        let angle = rng.range(0.5, 3.0).to_radians() * if i % 2 == 0 { 1.0 } else { -1.0 };
        let q = leaving(
            from,
            t * angle.cos() + from.normal * angle.sin(),
            scale.eps_self,
        );
        queries.push((q, false));
    }
    let mut self_hits = Vec::new();
    for (q, floor) in &queries {
        let w = windows(&b, &set.splats, q, scale.xi, "grazing ray");
        if w.as_slice().iter().any(|c| own(c.id, *floor)) {
            self_hits.push(format!(
                "{q:?} hit the surface it leaves: {:?}",
                w.as_slice()
            ));
        }
        b.oracle.intersect(&q.ray, q.t_min, q.t_max, &mut h);
        self_hits_without_rule += usize::from(h.as_slice().iter().any(|c| own(c.id, *floor)));
    }
    // The rule reaches the overhang of neighbours up to
    // `SAME_SURFACE_RIM` (2.5) radii from the departure point's projection;
    // rarely one lies farther. Measured: 1 self-hit in about 351,000 rays
    // leaving this sphere 0.5°–3° from tangent (201 runs of this test at
    // 1,150 rays, and 120,000 more over 40 seeds, farthest otherwise 2.45
    // radii); the one met a neighbour at 2.52 radii. Three radii for
    // rising neighbours would close it, at 170 pixels made worse for 11
    // better on `scenes/bunny.toml` (`compare --truth`, 800 px, -0.04 dB;
    // `scenes/glass.toml` -0.04). So the rule keeps 2.5 and this test
    // allows one self-hit in its 3,150 rays: two come once in about
    // 25,000 runs. With 2 radii, 15 of 6,000 rays hit themselves: 9 of
    // these 3,150 on the seed that met the 2.52 (`0x00ad4344910859cd`).
    assert!(
        self_hits.len() <= 1,
        "{} of {} grazing rays hit the surface they leave:\n{}",
        self_hits.len(),
        queries.len(),
        self_hits.join("\n")
    );
    // Without the rule, eps_self alone lets many of them hit their own
    // surface: the rule is what keeps them clean.
    assert!(
        self_hits_without_rule > queries.len() / 4,
        "set-up: only {self_hits_without_rule} of {} grazing rays hit their own surface without the rule",
        queries.len()
    );
    let queries: Vec<Query> = queries.into_iter().map(|(q, _)| q).collect();
    assert_all_agree(&b, &set.splats, &queries, scale.xi, "grazing rays");
}

/// Where a ray from `o` along unit `d`, inside the exact sphere the splats
/// sample, leaves it (`t` of the far root).
fn exact_exit(set: &Set, o: Vec3, d: Vec3) -> f32 {
    let oc = o - set.center;
    let b = d.dot(oc);
    let c = oc.length_squared() - SPHERE_RADIUS * SPHERE_RADIUS;
    -b + (b * b - c).max(0.0).sqrt()
}

/// The highest point any floor splat reaches.
fn floor_top(set: &Set) -> f32 {
    set.splats[..set.floor]
        .iter()
        .map(|s| s.center.y + s.radii.max_element() * (1.0 - s.normal.y * s.normal.y).sqrt())
        .fold(f32::NEG_INFINITY, f32::max)
}

/// How far a window's nearest hit may lie beyond the exact sphere's exit
/// along the ray. Every splat plane is tangent to the sphere, so outside
/// it: the hit is never nearer than the exit, and farther by the planes'
/// standoff over the sphere (`R (1 - cos θ)`, θ up to a splat radius over
/// R, 0.07) over the exit's obliquity (the sine of at least 27°): 0.0027
/// at most. Measured over 100 fresh seeds (`SPLATRAY_SEED`, with the
/// regression seeds below 400 runs, 80,000 rays): at most 0.00196. A
/// far-side splat skipped by the way-out rule puts the hit at least a
/// splat farther (0.03); with rays 20°-25° into the surface it passes
/// the whole far side and hits the floor (6 seeds of 6).
const EXIT_SLACK: f32 = 0.003;

/// Refraction-like rays into the sphere of `floor_and_sphere(seed)`: the
/// nearest hit must be the sphere's far side, where the exact sphere says
/// the ray leaves it. Returns the largest `t - exit` seen, the smallest
/// angle (degrees) between a departure splat's normal and the far-side
/// splat's, and how many drawn rays were set aside because they leave the
/// sphere at the floor.
fn far_side(seed: u64) -> (f32, f32, usize) {
    let set = floor_and_sphere(seed ^ 5);
    let scale = SceneScale::from_diagonal(diagonal(&set.splats));
    let b = backends(&set.splats);
    let top = floor_top(&set);
    let mut rng = Rng::new(seed ^ 9);
    let mut queries = Vec::new();
    let (mut slack, mut least_turn, mut at_floor) = (0f32, 180f32, 0);
    while queries.len() < 200 {
        assert!(
            at_floor < 200,
            "set-up: {at_floor} rays drawn leave at the floor"
        );
        let d = rng.unit();
        let d = Vec3::new(d.x, d.y.abs() * 0.8 + 0.2, d.z).normalize();
        let target = set.center + d * SPHERE_RADIUS;
        let (from, _) = depart(&b, &set, set.center + d * 3.0, target, scale.xi);
        let t = from.normal.cross(rng.unit()).normalize();
        let angle = rng.range(30.0, 60.0).to_radians();
        let q = leaving(
            from,
            t * angle.cos() - from.normal * angle.sin(),
            scale.eps_self,
        );
        // A ray leaving the sphere within the floor's reach meets the floor
        // splats where they overlap the sphere's underside (tilted up to
        // 1.2° and raised up to 0.004, they reach about 0.013 above the
        // contact): which comes first there is not the rule's to say. Such
        // rays are drawn again (0-10 of 200 per seed over 100 seeds; the
        // former set-up failed for 20 of 30 fresh seeds, here on the floor
        // or, with 0x0badc0ffee, on the chord below).
        let exit = exact_exit(&set, q.ray.origin, q.ray.dir);
        if q.ray.at(exit).y < top + 0.01 {
            at_floor += 1;
            continue;
        }
        let w = windows(&b, &set.splats, &q, scale.xi, "ray into the sphere");
        let far = w
            .nearest()
            .unwrap_or_else(|| panic!("{q:?} must reach the far side"));
        let n = set.splats[far.id as usize].normal;
        // The far side's distance from the exact sphere, not from the
        // departure splat's normal: that normal is a few degrees off the
        // sphere's, and at 25° a chord of `2 R sin(angle)` is up to 12 %
        // off (0.430 for 0.384 with 0x0badc0ffee).
        assert!(
            far.id as usize >= set.floor
                && n.dot(q.ray.dir) > 0.0
                && far.t >= exit - 1e-5
                && far.t <= exit + EXIT_SLACK,
            "{q:?} must leave the sphere through its far side ({exit} away) first, got {far:?}\n(replay with SPLATRAY_SEED={seed:#x})"
        );
        slack = slack.max(far.t - exit);
        least_turn = least_turn.min(n.angle_between(from.normal).to_degrees());
        assert!(occluded_everywhere(&b, &q));
        queries.push(q);
    }
    assert_all_agree(&b, &set.splats, &queries, scale.xi, "rays into the sphere");
    (slack, least_turn, at_floor)
}

#[test]
fn rays_into_the_sphere_reach_its_far_side() {
    // Refraction-like rays, 30° to 60° into the surface: they leave the
    // sphere where its normal has turned by twice that, beyond the 45° of
    // `WAY_OUT_COS`, so the far side is never skipped (refraction from air
    // into an index of 1.5 enters at least 48° in, of 1.33 at least 41°).
    // The departure and far-side splats' normals are each up to about 3°
    // off the sphere's, so the turn the rule sees is `2 α ± 6°`: with 25°
    // (as this test had) the least turn measured was 46.1° over 60 seeds,
    // at the rule's edge, and with 20°-25° the far side is skipped; with
    // 30°, 54.9° over 100 seeds. The run's seed,
    // then seeds the former set-up failed with (kept as regression cases).
    for s in [
        seed(),
        0x0bad_c0ffee,
        0x5607_f1e8_fdac_f125,
        0x15c1_58e7_b6ad_9d5e,
    ] {
        let (slack, turn, at_floor) = far_side(s);
        eprintln!(
            "rays into the sphere, seed {s:#x}: far side at most {slack} beyond the exact exit, normals turned at least {turn:.1}°, {at_floor} rays drawn again (they leave at the floor)"
        );
    }
}
