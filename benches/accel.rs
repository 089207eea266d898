//! Build and trace benchmarks of the acceleration backends, side by side on
//! the same splats and rays: the octree (as registered, whose default layout
//! depends on the size; each of its two leaf layouts, copies and shared
//! packs; and the report's bounding-square overlap test, §3.1),
//! Embree 4 user-geometry discs, and (rows for comparison, not backends)
//! Embree's native oriented discs with every hit confirmed by the shared
//! disc test (`embree-native`, no rules: it stops at the first disc met),
//! and the same discs deciding each hit with the backends' rules in
//! Embree's filter (`embree-native-rules`: the exact span, the self-hit and
//! pass-over rules; asserted to find the octree's blocked shadow rays).
//! The brute-force oracle is left out (quadratic).
//!
//! Then the triangle rows (issue 57): the bundled bunny mesh's 69,666
//! triangles on the octree and on Embree's user geometry (both deciding
//! with the one exact test, asserted to find the same hits) against
//! Embree's own triangles (its own test, one ray at a time: the speed the
//! report's first claim is about), `W`x`H` primary rays and the shadow rays
//! of their hits; `SPLATRAY_BENCH_ONLY=triangles,octree` keeps them (with
//! `SPLATRAY_BENCH_SIZES=` alone).
//!
//! Splats lie on the procedural blobby surface of the test suite; primary
//! rays come from a 1024×1024 pinhole camera, traced in parallel with rayon
//! over rows; shadow rays go from each primary hit (resolved with Phong
//! normal fields, as the renderer resolves them) toward a point light with
//! `t_min = eps_self`, leaving the splat they start on (the self-hit rule
//! of `accel::Departure`) and passing the hits beyond the Phong splats'
//! curved silhouettes (`accel::PassOver`): the renderer's Phong shadow rays. Throughput is
//! reported as rays per second. Each backend traces the same rays one at a
//! time and, in the "packets" rows, in packets of `accel::PACKET` (8×1
//! pixel tiles; 8 neighbouring hits' shadow rays) through
//! `Backend::intersect_packet` / `occluded_packet` (Embree:
//! `rtcIntersect8` / `rtcOccluded8`).
//!
//! ```sh
//! cargo bench --bench accel -- --sample-size 10
//! SPLATRAY_BENCH_SIZES=35000,1000000,4000000 cargo bench --bench accel -- --sample-size 10
//! ```
//!
//! Build seconds are what each structure reports (`BuildStats`): Embree's
//! are the scene's build (the discs copied into it, the BVH committed) on a
//! device created beforehand, without the device's creation, which the
//! table prints apart.
//!
//! Before criterion runs, a summary table (build seconds, structure
//! figures, primary and shadow rays/s, the speed ratio to Embree user
//! geometry for each kind of ray) is printed to stderr, all measured in this
//! run: the backends take turns pass by pass, and each ratio is the median
//! over the passes of the two speeds in the same pass.
//! `SPLATRAY_BENCH_PAIRS=k` sets the passes (3 by default) and skips
//! criterion; `SPLATRAY_BENCH_ONLY=octree,embree` keeps only the rows named;
//! `SPLATRAY_BENCH_SPLATS=FILE.ply` takes a splat file's discs instead of
//! the blobby surface's sizes (the camera framing them).
//! "MB" is what each structure holds: everything the octree keeps, and for
//! Embree the bytes its device memory monitor saw it keep for the scene.

#[path = "../tests/common/mod.rs"]
mod common;

use common::{Curved, Query, blobby_splats, camera_queries, diagonal, leaving, phong_hit};
use criterion::{Criterion, SamplingMode, Throughput};
use glam::Vec3;
use rayon::prelude::*;
use splatray::accel::octree::{Octree, OctreeParams};
use splatray::accel::{
    Backend, BuildStats, Candidate, CandidateHits, PACKET, Skip, backends, registry,
};
use splatray::embree::{Device, DiscFilter, NativeDiscScene, QueryFilteredDiscs, TriangleScene};
use splatray::primitive::{Disc, Triangle};
use splatray::scene::SceneScale;
use splatray::splat::Splat;
use std::hint::black_box;
use std::time::{Duration, Instant};

const W: usize = 1024;
const H: usize = 1024;

fn sizes() -> Vec<usize> {
    std::env::var("SPLATRAY_BENCH_SIZES")
        .ok()
        .map(|s| s.split(',').filter_map(|x| x.trim().parse().ok()).collect())
        .unwrap_or_else(|| vec![35_000, 1_000_000])
}

/// Who is benchmarked: every registered renderer and variant (the
/// registry's fast roles; the oracle and slow ones are quadratic), and
/// Embree's native discs.
type Build = Box<dyn Fn(&[Disc]) -> Box<dyn Backend>>;

fn builders() -> Vec<(&'static str, Build)> {
    let mut out: Vec<(&'static str, Build)> = backends::<Disc>()
        .into_iter()
        .filter(|b| b.role.is_fast())
        .map(|b| {
            let name = b.name;
            let f: Build = Box::new(move |d: &[Disc]| {
                b.build(d)
                    .unwrap_or_else(|e| panic!("building {name}: {e}"))
            });
            (name, f)
        })
        .collect();
    out.push((
        "embree-native",
        Box::new(|d: &[Disc]| Box::new(Native::new(d)) as Box<dyn Backend>),
    ));
    out.push((
        "embree-native-rules",
        Box::new(|d: &[Disc]| Box::new(NativeRules::new(d)) as Box<dyn Backend>),
    ));
    out
}

/// Embree's native oriented discs (`splatray::embree::NativeDiscScene`:
/// each splat's bounding circle, every hit confirmed by the shared disc
/// test in a filter), what a user might pick instead of user geometry:
/// the closest confirmed hit only (no candidate window, no self-hit rule
/// on shadow rays), so a benchmark row, not a backend.
struct Native {
    scene: NativeDiscScene,
    stats: BuildStats,
}

impl Native {
    fn new(discs: &[Disc]) -> Native {
        // The device first, outside the build's time (as for user geometry).
        let device = Device::new().expect("an Embree device");
        let start = Instant::now();
        let scene = NativeDiscScene::new(&device, discs).expect("native discs");
        let stats = BuildStats {
            build_seconds: start.elapsed().as_secs_f64(),
            memory_bytes: scene.memory_bytes(),
            ..BuildStats::default()
        };
        Native { scene, stats }
    }
}

impl Backend for Native {
    fn intersect_from(&self, q: &Query, hits: &mut CandidateHits) {
        hits.clear();
        if let Some((id, t)) = self.scene.intersect(&q.ray, q.t_min, q.t_max) {
            hits.offer(Candidate {
                id,
                t,
                u: 0.0,
                v: 0.0,
            });
        }
    }

    fn occluded_from(&self, q: &Query) -> bool {
        self.scene.occluded(&q.ray, q.t_min, q.t_max)
    }

    fn stats(&self) -> &BuildStats {
        &self.stats
    }
}

/// Embree's native discs with the backends' rules: each query's hits
/// decided in Embree's argument filter (`splatray::embree::QueryFilteredDiscs`)
/// by the shared disc test on the query's exact span, the self-hit rule
/// (`accel::Departure`) and the pass-over rule (`accel::PassOver`), as
/// Embree's user geometry decides them in its callbacks
/// (`accel::embree`): the renderer's query on Embree's own discs. The
/// closest kept hit only, so a benchmark row, not a backend.
struct NativeRules {
    scene: QueryFilteredDiscs,
    stats: BuildStats,
}

impl NativeRules {
    fn new(discs: &[Disc]) -> NativeRules {
        let device = Device::new().expect("an Embree device");
        let start = Instant::now();
        let scene = QueryFilteredDiscs::new(&device, discs).expect("native discs");
        let stats = BuildStats {
            build_seconds: start.elapsed().as_secs_f64(),
            memory_bytes: scene.memory_bytes(),
            ..BuildStats::default()
        };
        NativeRules { scene, stats }
    }
}

/// One query's rules, as the filter asks them: the splat the ray leaves
/// passed by its id, then the shared disc test on the query's exact span,
/// then the self-hit and pass-over rules on the hit (what
/// `accel::embree`'s occluded callback asks).
struct Rules<'a, 'q>(&'a Query<'q>);

impl DiscFilter for Rules<'_, '_> {
    #[inline]
    fn keeps(&self, prim: u32, disc: &Disc, ray: &splatray::accel::Ray) -> bool {
        use splatray::primitive::Primitive;
        let q = self.0;
        if q.from.is_some_and(|d| d.id == prim) {
            return false;
        }
        disc.intersect(ray, q.t_min, q.t_max)
            .is_some_and(|h| !q.secondary().skips(ray.dir, prim, disc, &h))
    }
}

impl Backend for NativeRules {
    fn intersect_from(&self, q: &Query, hits: &mut CandidateHits) {
        hits.clear();
        if q.meets_nothing() {
            return;
        }
        if let Some((id, t)) = self.scene.intersect(&q.ray, q.t_min, q.t_max, &Rules(q)) {
            hits.offer(Candidate {
                id,
                t,
                u: 0.0,
                v: 0.0,
            });
        }
    }

    fn occluded_from(&self, q: &Query) -> bool {
        if q.meets_nothing() {
            return false;
        }
        self.scene.occluded(&q.ray, q.t_min, q.t_max, &Rules(q))
    }

    fn stats(&self) -> &BuildStats {
        &self.stats
    }
}

/// Traces `queries` in parallel, `W` rays per task (a row); returns hits.
fn trace(backend: &dyn Backend, queries: &[Query], xi: f32) -> usize {
    queries
        .par_chunks(W)
        .map(|row| {
            let mut hits = CandidateHits::new(xi);
            row.iter()
                .filter(|q| {
                    backend.intersect(&q.ray, q.t_min, q.t_max, &mut hits);
                    !hits.is_empty()
                })
                .count()
        })
        .sum()
}

/// Shadow rays in parallel; returns how many are occluded.
fn shadow(backend: &dyn Backend, queries: &[Query]) -> usize {
    queries
        .par_chunks(W)
        .map(|row| row.iter().filter(|q| backend.occluded_from(q)).count())
        .sum()
}

/// [`trace`] with the rays of each row handed over in packets of
/// [`PACKET`] (8×1 pixel tiles), through `Backend::intersect_packet`.
fn trace_packets(backend: &dyn Backend, queries: &[Query], xi: f32) -> usize {
    queries
        .par_chunks(W)
        .map(|row| {
            let mut hits = vec![CandidateHits::new(xi); PACKET];
            row.chunks(PACKET)
                .map(|qs| {
                    backend.intersect_packet(qs, &mut hits);
                    hits[..qs.len()].iter().filter(|h| !h.is_empty()).count()
                })
                .sum::<usize>()
        })
        .sum()
}

/// [`shadow`] in packets of [`PACKET`] consecutive shadow rays (the hits
/// of neighbouring pixels toward the one light), through
/// `Backend::occluded_packet`.
fn shadow_packets(backend: &dyn Backend, queries: &[Query]) -> usize {
    queries
        .par_chunks(W)
        .map(|row| {
            let mut out = [false; PACKET];
            row.chunks(PACKET)
                .map(|qs| {
                    backend.occluded_packet(qs, &mut out);
                    out[..qs.len()].iter().filter(|&&o| o).count()
                })
                .sum::<usize>()
        })
        .sum()
}

struct Scene {
    discs: Vec<Disc>,
    scale: SceneScale,
    primary: Vec<Query<'static>>,
    shadow: Vec<Query<'static>>,
    /// Shadow rays the octree finds blocked (the renderer's rules).
    blocked: usize,
}

fn scene(n: usize) -> Scene {
    let splats = blobby_splats(n, 0x5eed_2007);
    scene_of(
        splats,
        (Vec3::new(0.7, 1.1, 4.0), Vec3::ZERO),
        Vec3::new(5.0, 6.0, 3.0),
    )
}

/// The scene of a splat file's splats (`SPLATRAY_BENCH_SPLATS`, their
/// discs; clip lines are not traced): the camera looks at their box's
/// centre from in front, above and to the right, and the light stands
/// higher, as the triangle rows' do for the mesh.
fn file_scene(path: &str) -> (usize, Scene) {
    let set = splatray::io::read_splats(std::path::Path::new(path)).unwrap_or_else(|e| {
        eprintln!("SPLATRAY_BENCH_SPLATS: {e}");
        std::process::exit(2)
    });
    let (lo, hi) = set.splats.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), s| (lo.min(s.center), hi.max(s.center)),
    );
    let (c, size) = ((lo + hi) * 0.5, (hi - lo).max_element());
    let n = set.splats.len();
    let eye = c + Vec3::new(0.3, 0.4, 1.4) * size;
    (
        n,
        scene_of(set.splats, (eye, c), c + Vec3::new(1.5, 2.5, 1.0) * size),
    )
}

/// The scene of `splats`: `W`x`H` camera rays from `eye` towards `at`, and
/// the shadow rays of their Phong hits towards a point `light`.
fn scene_of(splats: Vec<Splat>, (eye, at): (Vec3, Vec3), light: Vec3) -> Scene {
    // The splats live as long as the run: the shadow queries' pass-over
    // rule refers to them.
    let splats: &'static [Splat] = Box::leak(splats.into_boxed_slice());
    let curved: &'static Curved<'static> = Box::leak(Box::new(Curved(splats)));
    let scale = SceneScale::from_diagonal(diagonal(splats));
    let primary = camera_queries(eye, at, W, H);
    // Shadow rays from the Phong hits of the primary rays (found by the
    // octree; the agreement suite shows every backend finds the same), as
    // the renderer traces them: leaving the hit's splat and passing hits
    // beyond Phong splats' curved silhouettes.
    let discs: Vec<Disc> = splats.iter().map(Splat::disc_geometry).collect();
    let probe = Octree::new(&discs, &OctreeParams::default());
    let shadow: Vec<Query<'static>> = primary
        .par_iter()
        .filter_map(|q| {
            let mut h = CandidateHits::new(scale.xi);
            let hit = phong_hit(&probe, splats, q, &mut h)?;
            let to_light = light - hit.point;
            Some(Query {
                ray: splatray::accel::Ray {
                    origin: hit.point,
                    dir: to_light.normalize(),
                },
                t_min: scale.eps_self,
                t_max: to_light.length(),
                from: Some(leaving(&hit)),
                pass: Some(curved as &dyn splatray::accel::PassOver),
            })
        })
        .collect();
    let blocked = shadow.par_iter().filter(|q| probe.occluded_from(q)).count();
    Scene {
        discs,
        scale,
        primary,
        shadow,
        blocked,
    }
}

/// Median of `runs` timings of `f`, in seconds.
fn median_seconds(runs: usize, mut f: impl FnMut()) -> f64 {
    median((0..runs).map(|_| seconds(&mut f)).collect())
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn seconds(f: &mut dyn FnMut()) -> f64 {
    let s = Instant::now();
    f();
    s.elapsed().as_secs_f64()
}

/// The one-pass table: per backend, the median of 3 builds, then `rounds`
/// passes of the primary and the shadow rays, one ray at a time and in
/// packets (`Backend::intersect_packet`, `occluded_packet`: [`PACKET`]
/// rays, 8×1 pixel tiles and the shadow rays of neighbouring hits), the
/// backends taking turns pass by pass so that all see the same load on a
/// shared machine. Rays/s are medians over the passes; "vs embree" is the
/// median over the passes of the row's speed / Embree user geometry's in
/// the same pass and the same mode (a packet row against Embree's packet
/// row, `rtcIntersect8` / `rtcOccluded8`); "vs 1 ray" of a packet row is
/// its speed over the same backend's one ray at a time, in the same pass.
/// With `only` set, just the backends of those names (Embree's native
/// discs have no packet row).
fn summary(scenes: &[(usize, Scene)], rounds: usize, only: Option<&[String]>) {
    eprintln!(
        "\n{:>9} {:>19} {:>8} {:>9} {:>8} {:>10} {:>9} {:>11} {:>11} {:>8} {:>8} {:>8} {:>8}",
        "splats",
        "backend",
        "build s",
        "nodes",
        "leaves",
        "refs/leaf",
        "MB",
        "primary/s",
        "shadow/s",
        "vs embree",
        "(shadow)",
        "vs 1 ray",
        "(shadow)"
    );
    for (n, sc) in scenes {
        let built: Vec<Built> = builders()
            .into_iter()
            .filter(|(name, _)| only.is_none_or(|o| o.iter().any(|x| x == name)))
            .map(|(name, build)| {
                // The build's own time (`BuildStats`): Embree's without
                // creating its device.
                let build_s = median(
                    (0..3)
                        .map(|_| black_box(build(&sc.discs)).stats().build_seconds)
                        .collect(),
                );
                let b = build(&sc.discs);
                trace(b.as_ref(), &sc.primary, sc.scale.xi);
                (name, build_s, b)
            })
            .collect();
        // Shadow rays blocked, per row: every row under the renderer's
        // rules finds the octree's count; the plain native discs (no
        // rules) stop on more.
        let blocked: Vec<(&str, usize)> = built
            .iter()
            .map(|(name, _, b)| (*name, shadow(b.as_ref(), &sc.shadow)))
            .collect();
        eprintln!(
            "{n} splats: {} shadow rays, blocked under the rules (the octree's count) {}; per row: {blocked:?}",
            sc.shadow.len(),
            sc.blocked
        );
        assert!(
            blocked
                .iter()
                .all(|&(name, k)| name == "embree-native" || k == sc.blocked),
            "a row under the rules disagrees with the octree: {blocked:?} against {}",
            sc.blocked
        );
        let rays = Rays {
            primary: &sc.primary,
            shadow: &sc.shadow,
            xi: sc.scale.xi,
        };
        rows(&n.to_string(), &built, &rays, "embree", rounds);
    }
    if only.is_none_or(|o| o.iter().any(|x| x == "triangles")) {
        triangle_rows(rounds, only);
    }
    eprintln!(
        "(build s: median of 3, as each structure reports it: Embree's without creating its device ({:.1} ms \
         apart, median of 3) and with the discs copied in; rays/s: median of {rounds} passes of {W}x{H} primary rays and of the shadow rays of \
         their hits, the backends taking turns pass by pass, one ray at a time, then in packets of {PACKET} \
         (8x1 pixel tiles; the shadow rays of 8 neighbouring hits); 'vs embree': median over the passes of the \
         row's speed / Embree user geometry's in the same pass and mode, primary and (shadow) rays (the \
         bunny mesh's rows: / Embree's own triangles', one ray at a time); 'vs 1 ray': \
         a packet row's speed / the same backend's one ray at a time in the same pass; {} threads)\n",
        1e3 * median_seconds(3, || drop(black_box(
            Device::new().expect("an Embree device")
        ))),
        rayon::current_num_threads()
    );
}

/// A benchmarked backend: its name, build seconds and the built structure.
type Built<'a> = (&'a str, f64, Box<dyn Backend>);

/// The rays of a table's rows.
struct Rays<'a> {
    primary: &'a [Query<'static>],
    shadow: &'a [Query<'static>],
    xi: f32,
}

/// The rows of one scene: `rounds` passes of the primary and the shadow
/// rays, one ray at a time and in packets, the backends taking turns pass
/// by pass; the speed ratios against the row named `reference` (one ray at
/// a time when that row has no packets).
fn rows(label: &str, built: &[Built], rays: &Rays, reference: &str, rounds: usize) {
    let packets = |name: &str| !name.starts_with("embree-native");
    // Per backend and mode (0: one ray at a time, 1: packets), the
    // seconds of each pass.
    let mut prim = vec![[Vec::new(), Vec::new()]; built.len()];
    let mut shad = vec![[Vec::new(), Vec::new()]; built.len()];
    for _ in 0..rounds {
        for (i, (name, _, b)) in built.iter().enumerate() {
            prim[i][0].push(seconds(&mut || {
                black_box(trace(b.as_ref(), rays.primary, rays.xi));
            }));
            shad[i][0].push(seconds(&mut || {
                black_box(shadow(b.as_ref(), rays.shadow));
            }));
            if packets(name) {
                prim[i][1].push(seconds(&mut || {
                    black_box(trace_packets(b.as_ref(), rays.primary, rays.xi));
                }));
                shad[i][1].push(seconds(&mut || {
                    black_box(shadow_packets(b.as_ref(), rays.shadow));
                }));
            }
        }
    }
    let refer = built.iter().position(|b| b.0 == reference);
    // Median over the passes of `a`'s seconds over `b`'s.
    let ratio = |a: &[f64], b: &[f64]| median((0..rounds).map(|r| a[r] / b[r]).collect());
    let vs = |times: &[[Vec<f64>; 2]], i: usize, m: usize| {
        refer.map_or(f64::NAN, |e| {
            let me = if packets(reference) { m } else { 0 };
            ratio(&times[e][me], &times[i][m])
        })
    };
    for m in 0..2 {
        for (i, (name, build_s, b)) in built.iter().enumerate() {
            if m == 1 && !packets(name) {
                continue;
            }
            let s = b.stats();
            let (one, one_s) = if m == 1 {
                (
                    ratio(&prim[i][0], &prim[i][1]),
                    ratio(&shad[i][0], &shad[i][1]),
                )
            } else {
                (f64::NAN, f64::NAN)
            };
            let label_b = if m == 1 {
                format!("{name} packets")
            } else {
                (*name).to_string()
            };
            eprintln!(
                "{:>9} {:>19} {:>8.3} {:>9} {:>8} {:>10.2} {:>9.1} {:>11.3e} {:>11.3e} {:>8.3} {:>8.3} {:>8.3} {:>8.3}",
                label,
                label_b,
                build_s,
                s.nodes,
                s.leaves,
                s.mean_refs_per_leaf,
                s.memory_bytes as f64 / 1e6,
                rays.primary.len() as f64 / median(prim[i][m].clone()),
                rays.shadow.len() as f64 / median(shad[i][m].clone()),
                vs(&prim, i, m),
                vs(&shad, i, m),
                one,
                one_s,
            );
        }
    }
}

/// Embree's own triangles (`splatray::embree::TriangleScene`, its own
/// watertight test, no filter): the speed the report's first claim is
/// about. A benchmark row, not a backend: the nearest hit only.
struct NativeTriangles {
    scene: TriangleScene,
    stats: BuildStats,
}

impl NativeTriangles {
    fn new(positions: &[Vec3], faces: &[[u32; 3]]) -> NativeTriangles {
        let device = Device::new().expect("an Embree device");
        let before = device.memory();
        let start = Instant::now();
        let scene = TriangleScene::new(&device, &[(positions, faces)]).expect("Embree triangles");
        let stats = BuildStats {
            build_seconds: start.elapsed().as_secs_f64(),
            memory_bytes: device.memory().saturating_sub(before),
            ..BuildStats::default()
        };
        NativeTriangles { scene, stats }
    }
}

impl Backend for NativeTriangles {
    fn intersect_from(&self, q: &Query, hits: &mut CandidateHits) {
        hits.clear();
        if let Some(h) = self.scene.intersect(&q.ray, q.t_min, q.t_max) {
            hits.offer(Candidate {
                id: h.triangle,
                t: h.t,
                u: h.u,
                v: h.v,
            });
        }
    }

    fn occluded_from(&self, q: &Query) -> bool {
        self.scene.occluded(&q.ray, q.t_min, q.t_max)
    }

    fn stats(&self) -> &BuildStats {
        &self.stats
    }
}

/// The triangle rows (issue 57): the bundled bunny mesh
/// (`scenes/data/bunny-mesh.ply`, 69,666 faces) as `Triangle`s on the
/// octree and on Embree's user geometry (both confirming with the one
/// exact test), against Embree's own triangles. Primary rays of a
/// `W`x`H` view filled by the bunny, shadow rays from their hits toward a
/// point light (`t_min` 1e-4 of the mesh's size). The octree and Embree's
/// user geometry must find the same hits, Embree's own test the same but
/// for a few rays along edges.
fn triangle_rows(rounds: usize, only: Option<&[String]>) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/data/bunny-mesh.ply");
    let mesh = splatray::io::read_mesh(&path).expect("the bundled bunny mesh");
    let tri = |t: &[u32; 3]| Triangle {
        v: t.map(|i| mesh.positions[i as usize]),
    };
    let faces: Vec<[u32; 3]> = (mesh.triangles.iter().copied())
        .filter(|t| tri(t).is_proper())
        .collect();
    let tris: Vec<Triangle> = faces.iter().map(tri).collect();
    let (lo, hi) = mesh.positions.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let (c, size) = ((lo + hi) * 0.5, (hi - lo).max_element());
    let primary = camera_queries(c + Vec3::new(0.3, 0.4, 1.4) * size, c, W, H);
    let probe = registry::lookup::<Triangle>("octree")
        .and_then(|b| b.build(&tris))
        .expect("the octree over triangles");
    let light = c + Vec3::new(1.5, 2.5, 1.0) * size;
    let shadows: Vec<Query<'static>> = primary
        .par_iter()
        .filter_map(|q| {
            let mut h = CandidateHits::new(0.0);
            probe.intersect_from(q, &mut h);
            let p = q.ray.origin + q.ray.dir * h.nearest()?.t;
            let to_light = light - p;
            Some(Query::new(
                splatray::accel::Ray {
                    origin: p,
                    dir: to_light.normalize(),
                },
                1e-4 * size,
                to_light.length(),
            ))
        })
        .collect();
    let mut built: Vec<Built> = backends::<Triangle>()
        .into_iter()
        .filter(|b| b.name == "octree" || b.name == "embree")
        .filter(|b| only.is_none_or(|o| o.iter().any(|x| x == b.name)))
        .map(|b| {
            let build_s = median(
                (0..3)
                    .map(|_| black_box(b.build(&tris).unwrap()).stats().build_seconds)
                    .collect(),
            );
            (b.name, build_s, b.build(&tris).unwrap())
        })
        .collect();
    let native = "embree-native-tri";
    if only.is_none_or(|o| o.iter().any(|x| x == native)) {
        let build_s = median(
            (0..3)
                .map(|_| {
                    black_box(NativeTriangles::new(&mesh.positions, &faces))
                        .stats()
                        .build_seconds
                })
                .collect(),
        );
        let b = NativeTriangles::new(&mesh.positions, &faces);
        built.push((native, build_s, Box::new(b)));
    }
    // Per backend: primary rays that hit, shadow rays blocked.
    let hits: Vec<(&str, usize, usize)> = built
        .iter()
        .map(|(name, _, b)| {
            let p = trace(b.as_ref(), &primary, 0.0);
            (*name, p, shadow(b.as_ref(), &shadows))
        })
        .collect();
    let exact: Vec<_> = hits.iter().filter(|h| h.0 != native).collect();
    assert!(
        exact
            .windows(2)
            .all(|w| w[0].1 == w[1].1 && w[0].2 == w[1].2),
        "the exact test's backends disagree: {hits:?}"
    );
    eprintln!(
        "bunny mesh: {} triangles, {} primary rays, {} shadow rays; (hits, blocked): {hits:?}",
        tris.len(),
        primary.len(),
        shadows.len(),
    );
    let rays = Rays {
        primary: &primary,
        shadow: &shadows,
        xi: 0.0,
    };
    rows("bunny tri", &built, &rays, "embree-native-tri", rounds);
}

fn main() {
    let scenes: Vec<(usize, Scene)> = match std::env::var("SPLATRAY_BENCH_SPLATS") {
        Ok(path) => vec![file_scene(&path)],
        Err(_) => sizes().into_iter().map(|n| (n, scene(n))).collect(),
    };
    let only: Option<Vec<String>> = std::env::var("SPLATRAY_BENCH_ONLY")
        .ok()
        .map(|v| v.split(',').map(|x| x.trim().to_string()).collect());
    let passes: Option<usize> = std::env::var("SPLATRAY_BENCH_PAIRS")
        .ok()
        .and_then(|v| v.parse().ok());
    summary(&scenes, passes.unwrap_or(3), only.as_deref());
    if passes.is_some() {
        return;
    }

    let mut c = Criterion::default()
        .sample_size(10)
        .warm_up_time(std::time::Duration::from_secs(1))
        .measurement_time(std::time::Duration::from_secs(3))
        .configure_from_args();
    for (n, sc) in &scenes {
        let mut g = c.benchmark_group(format!("build/{n}"));
        g.sampling_mode(SamplingMode::Flat);
        g.throughput(Throughput::Elements(*n as u64));
        for (name, build) in builders() {
            g.bench_function(name, |bch| {
                // The build's own time (`BuildStats`: Embree's without
                // creating its device).
                bch.iter_custom(|iters| {
                    (0..iters)
                        .map(|_| Duration::from_secs_f64(build(&sc.discs).stats().build_seconds))
                        .sum()
                })
            });
        }
        g.finish();
        for (name, build) in builders() {
            let b = build(&sc.discs);
            let mut g = c.benchmark_group(format!("trace/{n}"));
            g.sampling_mode(SamplingMode::Flat);
            g.throughput(Throughput::Elements(sc.primary.len() as u64));
            g.bench_function(format!("{name}/primary"), |bch| {
                bch.iter(|| trace(b.as_ref(), &sc.primary, sc.scale.xi))
            });
            g.throughput(Throughput::Elements(sc.shadow.len() as u64));
            g.bench_function(format!("{name}/shadow"), |bch| {
                bch.iter(|| shadow(b.as_ref(), &sc.shadow))
            });
            g.finish();
        }
    }
    c.final_summary();
}
