//! Helpers shared by the backend test suites: a seeded generator, procedural
//! splat models, ray sets, and the one agreement check every backend is run
//! through against the brute-force oracle (after svenstaro/bvh's
//! `testbase.rs`).
#![allow(dead_code)]

use glam::{Vec2, Vec3};
pub use splatray::accel::Query;
use splatray::accel::registry::oracle;
use splatray::accel::{Backend, CandidateHits, Departure, Ray, backends as registry};
use splatray::primitive::{Clip, ClipLine, ClippedDisc, Disc, Hit, Local, Primitive, Single};
use splatray::resolve::{Resolved, ShadingMode, resolve};
use splatray::splat::{NormalField, Splat};
use std::path::{Path, PathBuf};

/// A bundled data file, `scenes/data/NAME`.
pub fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes/data")
        .join(name)
}

/// A fresh, empty scratch folder for one test, `SUITE-NAME` in the
/// build's own temporary folder (`target/tmp`): a run leaves one copy a
/// name there, not a folder a process in the system's temporary folder (a
/// hundred runs had left 15,000 of them). A name is one test's within its
/// suite; two runs of one suite at once (a debug and a release build, say)
/// would share it.
pub fn scratch(name: &str) -> PathBuf {
    let d =
        Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("{}-{name}", env!("CARGO_CRATE_NAME")));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The `splatray` binary built for these tests.
pub fn bin() -> std::process::Command {
    std::process::Command::new(env!("CARGO_BIN_EXE_splatray"))
}

/// Renders `scene` with the registered backend `name` (no progress).
pub fn render_with(
    scene: &splatray::scene::Scene,
    name: &str,
) -> splatray::render::integrator::Frame {
    let info = splatray::accel::registry::find(name).unwrap_or_else(|| panic!("no backend {name}"));
    let b = info
        .build_scene(scene)
        .unwrap_or_else(|e| panic!("building {name}: {e}"));
    splatray::render::integrator::render(scene, b.as_ref(), None)
}

/// `scene` rendered with the default renderer and measured against its
/// exact surfaces (`validate::compare::truth_errors`).
pub fn errors_against_truth(
    scene: &splatray::scene::Scene,
) -> splatray::validate::compare::TruthErrors {
    use splatray::validate::compare::{render_truth, truth_errors};
    let truth = render_truth(
        scene,
        &splatray::validate::truth::Truth::new(scene).unwrap(),
        None,
    );
    let frame = render_with(scene, default_renderer());
    truth_errors(frame, &truth, &scene.camera, scene.options.scale.diagonal)
}

/// The registry's renderers (`accel::registry::renderers`), by name: the
/// backends a scene-level test renders with. Panics when there are fewer
/// than two (every cross-check between renderers would compare nothing).
pub fn renderers() -> Vec<&'static str> {
    let names: Vec<&'static str> = splatray::accel::registry::renderers()
        .iter()
        .map(|b| b.name)
        .collect();
    assert!(names.len() >= 2, "the registry lists renderers {names:?}");
    names
}

/// The default renderer: the registry's first (the reference of `compare`).
pub fn default_renderer() -> &'static str {
    renderers()[0]
}

/// A renderer other than the default (the registry's second): where a test
/// renders with the other backend, or compares against it.
pub fn other_renderer() -> &'static str {
    renderers()[1]
}

/// The default seed; `SPLATRAY_SEED` overrides it so a failure can be
/// replayed.
pub const DEFAULT_SEED: u64 = 0x5eed_2007;

/// The seed of this run: `SPLATRAY_SEED` (decimal or `0x` hex) or
/// [`DEFAULT_SEED`].
pub fn seed() -> u64 {
    env_seed().unwrap_or(DEFAULT_SEED)
}

/// `SPLATRAY_SEED` (decimal or `0x` hex), if set; scripts/test.sh sets a
/// fresh one for its second pass of the conformance suite and the fuzzer.
///
/// # Panics
/// If it is set to something that is not a number.
pub fn env_seed() -> Option<u64> {
    let s = std::env::var("SPLATRAY_SEED").ok()?;
    let s = s.trim();
    let parsed = match s.strip_prefix("0x") {
        Some(h) => u64::from_str_radix(h, 16),
        None => s.parse(),
    };
    Some(parsed.unwrap_or_else(|_| panic!("SPLATRAY_SEED={s} is not a number")))
}

/// The seeded generator of every test: the library's SplitMix64.
pub use splatray::rng::SplitMix64 as Rng;

/// Radius of the blobby surface in direction `d` (unit): a sphere with
/// bumps, "bunny-like" enough to have concave and convex parts.
fn blob_radius(d: [f64; 3]) -> f64 {
    1.0 + 0.22 * (3.0 * d[0]).sin() * (2.0 * d[1] + 0.5).sin() * (4.0 * d[2]).cos()
        + 0.1 * (5.0 * d[1]).cos()
}

fn blob_field(p: [f64; 3]) -> f64 {
    let l = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
    l - blob_radius([p[0] / l, p[1] / l, p[2] / l])
}

/// `n` splats on a blobby closed surface of size ~2.4, with jittered
/// positions and normals, half of them elliptical, random tangent frames,
/// and small Phong normal fields (so every shading mode matters). Splat
/// radii are large enough that neighbours overlap, as in §2.
pub fn blobby_splats(n: usize, seed: u64) -> Vec<Splat> {
    let mut rng = Rng::new(seed);
    let area = 4.0 * std::f32::consts::PI * 1.1 * 1.1;
    let r = 1.8 * (area / (std::f32::consts::PI * n as f32)).sqrt();
    (0..n)
        .map(|_| {
            let d = rng.unit();
            let dd = [f64::from(d.x), f64::from(d.y), f64::from(d.z)];
            let rad = blob_radius(dd);
            let p = [dd[0] * rad, dd[1] * rad, dd[2] * rad];
            let h = 1e-5;
            let mut g = [0.0f64; 3];
            for (k, gk) in g.iter_mut().enumerate() {
                let mut a = p;
                let mut b = p;
                a[k] += h;
                b[k] -= h;
                *gk = (blob_field(a) - blob_field(b)) / (2.0 * h);
            }
            let normal =
                Vec3::new(g[0] as f32, g[1] as f32, g[2] as f32).normalize() + rng.unit() * 0.05;
            let center = Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32) + rng.unit() * (0.05 * r);
            let mut s = Splat::disc(center, normal, r * rng.range(0.8, 1.2)).unwrap();
            // Rotate the tangent frame randomly in the plane.
            let a = rng.range(0.0, std::f32::consts::TAU);
            let (sa, ca) = a.sin_cos();
            let (u, v) = (s.u_axis, s.v_axis);
            s.u_axis = u * ca + v * sa;
            s.v_axis = s.normal.cross(s.u_axis);
            if rng.next_f32() < 0.5 {
                s.radii = Vec2::new(s.radii.x * 1.4, s.radii.y * 0.75);
            }
            s.field = NormalField {
                xc: rng.range(-0.05, 0.05),
                yc: rng.range(-0.05, 0.05),
                alpha: rng.range(-0.2, 0.2),
                beta: rng.range(-0.2, 0.2),
            };
            s
        })
        .collect()
}

/// Seeded random rays around `splats` (bounding box centre `c`, size `s`):
/// most aimed at a jittered splat centre (so they hit), some in random
/// directions, some with a finite `t_max`.
pub fn random_queries(splats: &[Splat], count: usize, seed: u64) -> Vec<Query<'static>> {
    let mut rng = Rng::new(seed ^ 0xa5a5_a5a5);
    let (lo, hi) = bounds(splats);
    let c = (lo + hi) * 0.5;
    let s = (hi - lo).max_element().max(f32::MIN_POSITIVE);
    (0..count)
        .map(|i| {
            let origin = c + Vec3::new(
                rng.range(-1.5, 1.5),
                rng.range(-1.5, 1.5),
                rng.range(-1.5, 1.5),
            ) * s;
            let dir = if i % 5 == 4 || splats.is_empty() {
                rng.unit()
            } else {
                let target = splats[rng.below(splats.len())].center + rng.unit() * (0.02 * s);
                (target - origin).normalize()
            };
            let t_max = if i % 7 == 6 {
                rng.range(0.5, 3.0) * s
            } else {
                f32::INFINITY
            };
            Query::new(Ray { origin, dir }, 0.0, t_max)
        })
        .collect()
}

/// Pinhole camera rays, `w × h`, from `eye` looking at `at` with a vertical
/// field of view of 40°.
pub fn camera_queries(eye: Vec3, at: Vec3, w: usize, h: usize) -> Vec<Query<'static>> {
    let fwd = (at - eye).normalize();
    let right = fwd.cross(Vec3::Y).normalize();
    let up = right.cross(fwd);
    let tan = (20f32).to_radians().tan();
    let mut out = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let px = ((x as f32 + 0.5) / w as f32 * 2.0 - 1.0) * tan * w as f32 / h as f32;
            let py = (1.0 - (y as f32 + 0.5) / h as f32 * 2.0) * tan;
            out.push(Query::new(
                Ray {
                    origin: eye,
                    dir: (fwd + right * px + up * py).normalize(),
                },
                0.0,
                f32::INFINITY,
            ));
        }
    }
    out
}

/// Bounding box of the splat centres (`(0, 0)` when empty).
pub fn bounds(splats: &[Splat]) -> (Vec3, Vec3) {
    if splats.is_empty() {
        return (Vec3::ZERO, Vec3::ZERO);
    }
    splats.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), s| {
            let e = s.half_extent();
            (lo.min(s.center - e), hi.max(s.center + e))
        },
    )
}

/// Bounding-box diagonal of the splats.
pub fn diagonal(splats: &[Splat]) -> f32 {
    let (lo, hi) = bounds(splats);
    (hi - lo).length()
}

/// A second primitive, defined outside the library as a user would: a
/// library primitive (the disc by default, or the clipped disc) without
/// its SIMD pack ([`Single`]), every method delegated. Its hits are the
/// wrapped primitive's bit for bit, so backends built over it must agree
/// with the oracle built over that primitive.
#[derive(Clone, Copy, Debug)]
pub struct Unpacked<P = Disc>(pub P);

impl<P: Primitive> Primitive for Unpacked<P> {
    type Pack = Single<Unpacked<P>>;
    fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<Hit> {
        self.0.intersect(ray, t_min, t_max)
    }
    fn center(&self) -> Vec3 {
        self.0.center()
    }
    fn half_extent(&self) -> Vec3 {
        self.0.half_extent()
    }
    fn coarse_half_extent(&self) -> Vec3 {
        self.0.coarse_half_extent()
    }
    fn meets_box(&self, lo: Vec3, hi: Vec3) -> bool {
        self.0.meets_box(lo, hi)
    }
    fn locate(&self, p: Vec3) -> Local {
        self.0.locate(p)
    }
}

/// A built backend under a label that says which registry entry and
/// primitive it is (`octree<unpacked>`), for failure messages.
pub struct Named {
    /// `entry<primitive>`.
    pub name: String,
    backend: Box<dyn Backend>,
    /// False for the registry's oracle and slow entries (brute force, whose
    /// packets are the backend trait's default loop over single rays).
    fast: bool,
}

impl Named {
    /// Wraps a backend built outside the registry (a deliberately broken one,
    /// say).
    pub fn new(name: impl Into<String>, backend: Box<dyn Backend>) -> Named {
        Named {
            name: name.into(),
            backend,
            fast: true,
        }
    }

    /// The label.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The backend.
    pub fn as_ref(&self) -> &dyn Backend {
        self.backend.as_ref()
    }
}

impl std::ops::Deref for Named {
    type Target = dyn Backend;
    fn deref(&self) -> &Self::Target {
        self.backend.as_ref()
    }
}

/// The oracle plus every backend under test.
pub struct Backends {
    /// The registry's oracle, over discs.
    pub oracle: Named,
    /// The backends checked against it: every registered entry (renderers,
    /// their variants, the slow ones, the oracle itself over the other
    /// primitive) over discs and over [`Unpacked`] discs.
    pub tested: Vec<Named>,
}

fn build_all<P: Primitive>(prims: &[P], primitive: &str, out: &mut Vec<Named>) {
    for info in registry::<P>() {
        let b = info
            .build(prims)
            .unwrap_or_else(|e| panic!("building backend {}: {e}", info.name));
        let mut named = Named::new(format!("{}<{primitive}>", info.name), b);
        named.fast = info.role.is_fast();
        out.push(named);
    }
}

/// Builds the oracle and every tested backend over the splats: over
/// discs (`<disc>`, `<unpacked>`), or, when some splat is clipped, over
/// clipped discs (`<clipped>`, `<clipped-unpacked>`), as
/// `BackendInfo::build_splats` chooses for a scene.
pub fn backends(splats: &[Splat]) -> Backends {
    if splats.iter().any(Splat::is_clipped) {
        let prims: Vec<ClippedDisc> = splats.iter().map(Splat::clipped_geometry).collect();
        backends_over(&prims, "clipped", "clipped-unpacked")
    } else {
        let discs: Vec<Disc> = splats.iter().map(Splat::disc_geometry).collect();
        backends_over(&discs, "disc", "unpacked")
    }
}

fn backends_over<P: Primitive>(prims: &[P], label: &str, unpacked_label: &str) -> Backends {
    let mut all = Vec::new();
    build_all(prims, label, &mut all);
    let oracle_name = format!("{}<{label}>", oracle::<P>().name);
    let oracle_at = all
        .iter()
        .position(|b| b.name == oracle_name)
        .expect("the oracle was built");
    let oracle = all.remove(oracle_at);
    let unpacked: Vec<Unpacked<P>> = prims.iter().copied().map(Unpacked).collect();
    build_all(&unpacked, unpacked_label, &mut all);
    Backends {
        oracle,
        tested: all,
    }
}

/// The clip line of splat `s` at the line through `p0` in its plane that
/// keeps the side away from `m` (a unit direction in the plane, pointing
/// off the face): `(p - p0) · m <= 0`, in the splat's normalised
/// coordinates (`p = c + r_u u U + r_v v V`).
pub fn clip_at(s: &Splat, p0: Vec3, m: Vec3) -> ClipLine {
    let (a, b) = (s.u_axis.dot(m) * s.radii.x, s.v_axis.dot(m) * s.radii.y);
    let len = a.hypot(b);
    ClipLine {
        a: a / len,
        b: b / len,
        d: -(s.center - p0).dot(m) / len,
    }
}

/// Clips about a third of `splats` with one line and a sixth with two
/// (a corner), each line at a random angle in the splat's plane and a
/// random offset in `[-0.4, 0.6]` of the radii, so rays meet the
/// clipped-away parts, the lines and the kept parts alike. Seeded.
pub fn clip_some(splats: &mut [Splat], seed: u64) {
    let mut rng = Rng::new(seed ^ 0x00c1_1900);
    let line = |rng: &mut Rng| {
        let (s, c) = rng.range(0.0, std::f32::consts::TAU).sin_cos();
        ClipLine {
            a: c,
            b: s,
            d: rng.range(-0.4, 0.6),
        }
    };
    for s in splats.iter_mut() {
        let k = rng.next_f32();
        if k < 1.0 / 6.0 {
            s.clip = Clip::two(line(&mut rng), line(&mut rng));
        } else if k < 0.5 {
            s.clip = Clip::one(line(&mut rng));
        }
    }
}

fn describe(q: &Query, splats: &[Splat], hits: &CandidateHits) -> String {
    let mut s = format!(
        "ray {:?} t_min {:?} t_max {:?} from {:?}\n",
        q.ray, q.t_min, q.t_max, q.from
    );
    for c in hits.as_slice() {
        s += &format!("    {c:?} splat {:?}\n", splats[c.id as usize]);
    }
    s
}

/// Checks `backend` against the oracle on every query: identical candidate
/// windows (ids, `t`, `u`, `v` compared bit for bit: every backend calls the
/// same `Primitive::intersect` on the same `Disc` values and the same
/// self-hit rule, `Departure::skips`, so nothing may differ), identical
/// overflow flags, identical `occluded` answers (closest-hit and any-hit
/// queries skip the same hits), and identical resolved hits in all three
/// shading modes. Returns a replayable description of the first
/// disagreement.
pub fn agree(
    oracle: &Named,
    backend: &Named,
    splats: &[Splat],
    queries: &[Query],
    xi: f32,
) -> Result<(), String> {
    agree_with(
        &Expected::of(oracle, splats, queries, xi),
        backend,
        splats,
        queries,
    )
}

/// The oracle's answers to a set of queries, found once and held for every
/// backend checked against them ([`assert_all_agree`]): its candidate
/// window (with the window width `xi`), the window resolved in each
/// shading mode, and its `occluded` answer, query by query. The oracle is
/// pure, so each backend is compared with exactly what asking the oracle
/// again would give (asked again per backend, the brute-force oracle was
/// most of the conformance suite's time).
pub struct Expected {
    name: String,
    xi: f32,
    answers: Vec<(CandidateHits, [Option<Resolved>; 3], bool)>,
}

/// The shading modes [`agree`] resolves each window in.
const MODES: [ShadingMode; 3] = [ShadingMode::Flat, ShadingMode::Blended, ShadingMode::Phong];

impl Expected {
    /// Asks `oracle` every query of `queries`.
    pub fn of(oracle: &Named, splats: &[Splat], queries: &[Query], xi: f32) -> Expected {
        let answers = queries
            .iter()
            .map(|q| {
                let mut want = CandidateHits::new(xi);
                oracle.intersect_from(q, &mut want);
                let resolved = MODES.map(|mode| resolve(&want, &q.ray, splats, mode));
                let occluded = oracle.occluded_from(q);
                (want, resolved, occluded)
            })
            .collect();
        Expected {
            name: oracle.name().to_string(),
            xi,
            answers,
        }
    }
}

/// [`agree`] against the oracle's answers found once (`expected`, for
/// the same `queries`).
pub fn agree_with(
    expected: &Expected,
    backend: &Named,
    splats: &[Splat],
    queries: &[Query],
) -> Result<(), String> {
    assert_eq!(
        expected.answers.len(),
        queries.len(),
        "the oracle's answers are for other queries"
    );
    let (xi, want_name) = (expected.xi, &expected.name);
    let mut got = CandidateHits::new(xi);
    for (i, (q, (want, resolved, occ_want))) in queries.iter().zip(&expected.answers).enumerate() {
        backend.intersect_from(q, &mut got);
        let bits = |h: &CandidateHits| {
            h.as_slice()
                .iter()
                .map(|c| (c.id, c.t.to_bits(), c.u.to_bits(), c.v.to_bits()))
                .collect::<Vec<_>>()
        };
        let head = || format!("{} vs {}, query {i}, xi {xi:?}", backend.name(), want_name);
        if bits(want) != bits(&got) || want.overflowed() != got.overflowed() {
            return Err(format!(
                "{}: candidate windows differ\n  {} (overflowed {}): {}  {} (overflowed {}): {}",
                head(),
                want_name,
                want.overflowed(),
                describe(q, splats, want),
                backend.name(),
                got.overflowed(),
                describe(q, splats, &got)
            ));
        }
        for (mode, a) in MODES.iter().zip(resolved) {
            let b = resolve(&got, &q.ray, splats, *mode);
            if *a != b {
                return Err(format!(
                    "{}: resolved hits differ in {mode:?}: {a:?} vs {b:?}\n  {}",
                    head(),
                    describe(q, splats, want)
                ));
            }
        }
        let occ_got = backend.occluded_from(q);
        if *occ_want != occ_got || *occ_want == want.is_empty() {
            return Err(format!(
                "{}: occluded {} ({}) vs {} ({}), window empty: {}\n  {}",
                head(),
                occ_want,
                want_name,
                occ_got,
                backend.name(),
                want.is_empty(),
                describe(q, splats, want)
            ));
        }
    }
    Ok(())
}

/// The batches [`packets_agree`] traces: the queries in order in packets
/// of 8 (coherent where the queries are, e.g. a camera's rows), in
/// batches of uneven lengths (packets with lanes left empty, and single
/// rays), and interleaved from the two halves (divergent packets).
fn packet_orders(n: usize) -> Vec<(&'static str, Vec<usize>, Vec<usize>)> {
    let in_order: Vec<usize> = (0..n).collect();
    let eights: Vec<usize> = (0..n).step_by(8).map(|i| 8.min(n - i)).collect();
    let mut uneven = Vec::new();
    let mut left = n;
    for &len in [8usize, 3, 5, 1, 7, 2, 6, 4].iter().cycle() {
        if left == 0 {
            break;
        }
        uneven.push(len.min(left));
        left -= len.min(left);
    }
    let half = n.div_ceil(2);
    let mut mixed: Vec<usize> = (0..half)
        .flat_map(|i| [i, i + half])
        .filter(|&i| i < n)
        .collect();
    mixed.reverse();
    vec![
        ("packets of 8", in_order.clone(), eights.clone()),
        ("uneven batches", in_order, uneven),
        ("divergent packets", mixed, eights),
    ]
}

/// Checks `backend`'s packet queries (`Backend::intersect_packet`,
/// `Backend::occluded_packet`) and its scattered batches
/// (`Backend::occluded_each`, each batch and then every query at once)
/// against its own single-ray answers on every query, in every order of
/// [`packet_orders`]: identical candidate windows bit for bit, overflow
/// flags and any-hit answers (the backend contract: a ray's candidates do
/// not depend on the batch it is traced in).
pub fn packets_agree(backend: &Named, queries: &[Query], xi: f32) -> Result<(), String> {
    let bits = |h: &CandidateHits| {
        let c: Vec<_> = h
            .as_slice()
            .iter()
            .map(|c| (c.id, c.t.to_bits(), c.u.to_bits(), c.v.to_bits()))
            .collect();
        (c, h.overflowed())
    };
    let mut one = CandidateHits::new(xi);
    let single: Vec<_> = queries
        .iter()
        .map(|q| {
            backend.intersect_from(q, &mut one);
            (bits(&one), backend.occluded_from(q))
        })
        .collect();
    for (what, order, lens) in packet_orders(queries.len()) {
        let mut at = 0;
        for len in lens {
            let idx = &order[at..at + len];
            at += len;
            let qs: Vec<Query> = idx.iter().map(|&i| queries[i]).collect();
            // Stale windows and answers: the packet calls must clear them.
            let mut hits = vec![CandidateHits::new(xi); len + 1];
            for h in &mut hits {
                h.offer(splatray::accel::Candidate {
                    id: 7,
                    t: 0.5,
                    u: 0.0,
                    v: 0.0,
                });
            }
            let mut occ = vec![true; len + 1];
            let mut each = vec![true; len + 1];
            backend.intersect_packet(&qs, &mut hits);
            backend.occluded_packet(&qs, &mut occ);
            backend.occluded_each(&qs, &mut each);
            for (j, &i) in idx.iter().enumerate() {
                if each[j] != single[i].1 {
                    return Err(format!(
                        "{}: {what}: query {i} (ray {j} of {len}) asked as one of scattered rays \
                         (occluded_each) gives {} against {} alone\n  {:?}",
                        backend.name(),
                        each[j],
                        single[i].1,
                        queries[i]
                    ));
                }
                if bits(&hits[j]) != single[i].0 || occ[j] != single[i].1 {
                    return Err(format!(
                        "{}: {what}: query {i} (lane {j} of {len}) traced in a packet differs from                          the same query alone: {:?} / {} vs {:?} / {}\n  {:?}",
                        backend.name(),
                        bits(&hits[j]),
                        occ[j],
                        single[i].0,
                        single[i].1,
                        queries[i]
                    ));
                }
            }
        }
        let qs: Vec<Query> = order.iter().map(|&i| queries[i]).collect();
        let mut each = vec![true; qs.len() + 1];
        backend.occluded_each(&qs, &mut each);
        if let Some(j) = (0..qs.len()).find(|&j| each[j] != single[order[j]].1) {
            let i = order[j];
            return Err(format!(
                "{}: {what}: query {i} asked among all {} at once (occluded_each) gives {} \
                 against {} alone\n  {:?}",
                backend.name(),
                qs.len(),
                each[j],
                single[i].1,
                queries[i]
            ));
        }
    }
    Ok(())
}

/// Queries whose packets [`assert_all_agree`] checks on a brute-force
/// backend.
const SLOW_PACKETS: usize = 256;

/// Runs [`agree`] for every tested backend; panics with the seed and the
/// replayable description of the first disagreement.
pub fn assert_all_agree(b: &Backends, splats: &[Splat], queries: &[Query], xi: f32, what: &str) {
    let want = Expected::of(&b.oracle, splats, queries, xi);
    for backend in &b.tested {
        // Brute force traces a packet as the backend trait's default loop
        // over single rays, the same code for every query: its packets are
        // checked on the first SLOW_PACKETS queries, in every order (with
        // all of them checked, the floor case took 26.3 s, 9.1 s now;
        // `docs/notes/testing.md`, forty-first session).
        let packets = if backend.fast {
            queries
        } else {
            &queries[..queries.len().min(SLOW_PACKETS)]
        };
        if let Err(e) = agree_with(&want, backend, splats, queries)
            .and_then(|()| packets_agree(backend, packets, xi))
        {
            panic!("{what}: {e}\n(replay with SPLATRAY_SEED={:#x})", seed());
        }
    }
}

/// Every tested backend's window for `query`, checked equal to the oracle's;
/// returns the oracle's.
pub fn windows(
    b: &Backends,
    splats: &[Splat],
    query: &Query,
    xi: f32,
    what: &str,
) -> CandidateHits {
    assert_all_agree(b, splats, std::slice::from_ref(query), xi, what);
    let mut h = CandidateHits::new(xi);
    b.oracle.intersect_from(query, &mut h);
    h
}

/// How many queries of `queries` hit something in the oracle.
pub fn count_hits(oracle: &dyn Backend, queries: &[Query], xi: f32) -> usize {
    let mut h = CandidateHits::new(xi);
    queries
        .iter()
        .filter(|q| {
            oracle.intersect_from(q, &mut h);
            !h.is_empty()
        })
        .count()
}

/// How many queries of `queries` the self-hit rule changes in the oracle:
/// the window or the any-hit answer differs from the same ray's with
/// nothing skipped.
pub fn count_skipping(oracle: &dyn Backend, queries: &[Query], xi: f32) -> usize {
    let mut with = CandidateHits::new(xi);
    let mut without = CandidateHits::new(xi);
    queries
        .iter()
        .filter(|q| {
            oracle.intersect_from(q, &mut with);
            oracle.intersect(&q.ray, q.t_min, q.t_max, &mut without);
            with.as_slice() != without.as_slice()
        })
        .count()
}

/// The surface `q`'s ray meets with Phong splats, as the integrator finds
/// it: the window gathered (into `h`) and resolved, and gathered again past
/// candidates beyond their fields' silhouettes.
pub fn phong_hit(
    oracle: &dyn Backend,
    splats: &[Splat],
    q: &Query,
    h: &mut CandidateHits,
) -> Option<splatray::resolve::SurfaceHit> {
    let mut t_min = q.t_min;
    loop {
        oracle.intersect(&q.ray, t_min, q.t_max, h);
        match resolve(h, &q.ray, splats, ShadingMode::Phong)? {
            Resolved::Beyond(t) => t_min = t,
            Resolved::Hit(hit) => return Some(hit),
        }
    }
}

/// What a secondary ray from `hit` leaves: its winning splat, as the
/// integrator's queries say.
pub fn leaving(hit: &splatray::resolve::SurfaceHit) -> Departure {
    Departure {
        id: hit.id,
        point: hit.point,
        normal: hit.geometric_normal,
    }
}

/// The splats as Phong splats, for shadow queries: a hit on a disc beyond
/// its field's curved silhouette is passed (`resolve::beyond_silhouette_at`),
/// as the integrator's shadow rays pass it.
pub struct Curved<'a>(pub &'a [Splat]);

impl splatray::accel::PassOver for Curved<'_> {
    fn passes(&self, id: u32, hit: &splatray::primitive::Hit, dir: Vec3) -> bool {
        splatray::resolve::beyond_silhouette_at(&self.0[id as usize], hit.u, hit.v, dir)
    }
}

/// Shadow rays from each resolved primary hit toward 8 random points of a
/// sphere light (centre `light`, radius `radius`), leaving the winning
/// splat with `t_min = eps_self` and passing what `pass` passes, 8 in a
/// row from one hit: the batches the integrator hands a backend (sharing
/// an origin, so the octree's packets test each leaf's packs once for all
/// of them).
pub fn light_batches<'a>(
    oracle: &dyn Backend,
    splats: &[Splat],
    primaries: &[Query],
    xi: f32,
    eps_self: f32,
    (light, radius): (Vec3, f32),
    pass: &'a dyn splatray::accel::PassOver,
) -> Vec<Query<'a>> {
    let mut rng = Rng::new(seed() ^ 0x5eed);
    let mut h = CandidateHits::new(xi);
    let mut out = Vec::new();
    for q in primaries {
        if let Some(hit) = phong_hit(oracle, splats, q, &mut h) {
            let from = Some(leaving(&hit));
            for _ in 0..8 {
                let to = light + rng.unit() * radius - hit.point;
                out.push(Query {
                    ray: Ray {
                        origin: hit.point,
                        dir: to / to.length(),
                    },
                    t_min: eps_self,
                    t_max: to.length() - eps_self,
                    from,
                    pass: Some(pass),
                });
            }
        }
    }
    out
}

/// Secondary rays from each resolved primary hit: the mirror reflection and
/// a shadow ray toward `light`, both starting at the hit with
/// `t_min = eps_self` (§3.2, fig. 9 right) and leaving the winning splat
/// (`from`), the shadow ray passing what `pass` passes, as the integrator
/// traces them.
pub fn secondary_queries<'a>(
    oracle: &dyn Backend,
    splats: &[Splat],
    primaries: &[Query],
    xi: f32,
    eps_self: f32,
    light: Vec3,
    pass: &'a dyn splatray::accel::PassOver,
) -> Vec<Query<'a>> {
    let mut h = CandidateHits::new(xi);
    let mut out = Vec::new();
    for q in primaries {
        if let Some(hit) = phong_hit(oracle, splats, q, &mut h) {
            let from = Some(leaving(&hit));
            let n = if hit.front { hit.normal } else { -hit.normal };
            let d = q.ray.dir - 2.0 * q.ray.dir.dot(n) * n;
            out.push(Query {
                ray: Ray {
                    origin: hit.point,
                    dir: d.normalize(),
                },
                t_min: eps_self,
                t_max: f32::INFINITY,
                from,
                pass: None,
            });
            let to_light = light - hit.point;
            out.push(Query {
                ray: Ray {
                    origin: hit.point,
                    dir: to_light.normalize(),
                },
                t_min: eps_self,
                t_max: to_light.length(),
                from,
                pass: Some(pass),
            });
        }
    }
    out
}

/// The solids (scenes/data/solids.ply) scanned from the camera of
/// scenes/solids.toml (1.9, 1.5, 2.4, looking at 0, 0.2, 0) with
/// `columns`×`rows` rays, seed 1: `outliers` of the returns replaced by
/// strays on their rays (0.5-1.5 times the range), range noise of `noise`
/// spacings.
pub fn solids_scan(
    [columns, rows]: [u32; 2],
    outliers: f32,
    noise: f32,
) -> splatray::splat::PointCloud {
    let mesh = splatray::io::read_mesh(&data("solids.ply")).unwrap();
    let params = splatray::scanner::ScanParams {
        from: glam::DVec3::new(1.9, 1.5, 2.4),
        at: Some(glam::DVec3::new(0.0, 0.2, 0.0)),
        columns,
        rows,
        outliers,
        range_noise: splatray::scanner::RangeNoise::Spacing(noise),
        seed: 1,
        ..Default::default()
    };
    splatray::scanner::scan_mesh(&mesh, &params).unwrap().cloud
}

/// `cloud` grown at the defaults from its own viewpoint (a scan's
/// scanner), as `splat` and a scene grow a file's.
pub fn grown_from_its_viewpoint(
    cloud: &splatray::splat::PointCloud,
) -> (Vec<splatray::data::Splat>, splatray::splat::SplatReport) {
    let params = splatray::splat::SplatParams {
        viewpoint: cloud.viewpoint,
        ..Default::default()
    };
    splatray::splat::generate(cloud, &params).unwrap()
}
