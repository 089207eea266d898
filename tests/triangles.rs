//! Triangles on every backend and SIMD path (issue 57): every registered
//! backend built over `Triangle`s (the octree on each SIMD path this CPU
//! runs, Embree's user geometry, the brute-force oracle) gives the
//! oracle's candidates bit for bit, a ray through a shared edge or vertex
//! hits exactly one triangle, grazing and in-plane rays agree, a shadow
//! ray leaving a triangle does not meet it or its neighbours at the
//! departure point but does meet a blocker, and NaN or infinite rays meet
//! nothing.

mod common;

use glam::Vec3;
use splatray::accel::{Backend, CandidateHits, Departure, Query, registry};
use splatray::geometry::Ray;
use splatray::primitive::Triangle;

/// A bumpy `n × n` grid of unit squares, two triangles each, wound so the
/// face normals point up (+z); heights from the vertex indices so that
/// neighbouring faces are not coplanar.
fn terrain(n: usize) -> Vec<Triangle> {
    let h = |i: usize, j: usize| ((i * 7 + j * 3) % 5) as f32 * 0.125;
    let p = |i: usize, j: usize| Vec3::new(i as f32, j as f32, h(i, j));
    let mut out = Vec::new();
    for i in 0..n {
        for j in 0..n {
            out.push(Triangle {
                v: [p(i, j), p(i + 1, j), p(i + 1, j + 1)],
            });
            out.push(Triangle {
                v: [p(i, j), p(i + 1, j + 1), p(i, j + 1)],
            });
        }
    }
    out
}

fn backends(tris: &[Triangle]) -> Vec<(&'static str, Box<dyn Backend>)> {
    registry::backends::<Triangle>()
        .into_iter()
        .map(|b| (b.name, b.build(tris).expect(b.name)))
        .collect()
}

/// The brute-force oracle among the built backends.
fn oracle<'a>(all: &'a [(&'static str, Box<dyn Backend>)]) -> &'a dyn Backend {
    let name = registry::oracle::<Triangle>().name;
    all.iter().find(|(n, _)| *n == name).unwrap().1.as_ref()
}

fn window(b: &dyn Backend, ray: &Ray) -> Vec<(u32, f32, f32, f32)> {
    let mut hits = CandidateHits::new(0.0);
    b.intersect(ray, 0.0, f32::INFINITY, &mut hits);
    hits.as_slice()
        .iter()
        .map(|c| (c.id, c.t, c.u, c.v))
        .collect()
}

#[test]
fn rays_through_shared_edges_and_vertices_hit_exactly_one_triangle_on_every_backend() {
    let tris = terrain(6);
    let all = backends(&tris);
    assert!(
        all.len() >= 4,
        "octree, embree, variants, brute: {}",
        all.len()
    );
    let mut rays = 0;
    for i in 1..12 {
        for j in 1..12 {
            let (x, y) = (i as f32 * 0.5, j as f32 * 0.5);
            // The point of the surface over (x, y) on the grid lines: a
            // vertex, an edge's midpoint or a diagonal's.
            let z = tris
                .iter()
                .find_map(|t| t.intersect_down(x, y))
                .expect("over the grid");
            let p = Vec3::new(x, y, z);
            for d in [
                Vec3::new(0.0, 0.0, -1.0),
                Vec3::new(0.2, -0.1, -1.0),
                Vec3::new(-0.4, 0.3, -1.0),
                Vec3::new(0.0, 0.0, 1.0),
            ] {
                let ray = Ray::new(p - d.normalize() * 5.0, d);
                let want = window(oracle(&all), &ray);
                assert_eq!(want.len(), 1, "brute, through {p} along {d}: {want:?}");
                for (name, b) in &all {
                    assert_eq!(
                        window(b.as_ref(), &ray),
                        want,
                        "{name}: through {p} along {d}"
                    );
                }
                rays += 1;
            }
        }
    }
    assert_eq!(rays, 484);
}

/// The height of the triangle under `(x, y)` straight down, if it is
/// over the triangle (a helper on the test's side, from the exact test).
trait Down {
    fn intersect_down(&self, x: f32, y: f32) -> Option<f32>;
}

impl Down for Triangle {
    fn intersect_down(&self, x: f32, y: f32) -> Option<f32> {
        use splatray::primitive::Primitive;
        let ray = Ray::new(Vec3::new(x, y, 10.0), -Vec3::Z);
        self.intersect(&ray, 0.0, f32::INFINITY)
            .map(|h| ray.at(h.t).z)
    }
}

#[test]
fn grazing_in_plane_and_random_rays_agree_with_the_oracle() {
    let tris = terrain(5);
    let all = backends(&tris);
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut r = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut hit = 0;
    for k in 0..600 {
        let ray = match k % 3 {
            // Grazing: nearly horizontal, just over the surface.
            0 => Ray::new(
                Vec3::new(-1.0, r() * 5.0, 0.3 + r() * 0.3),
                Vec3::new(1.0, r() - 0.5, -0.05 * r()),
            ),
            // In the plane of a flat stretch (z = 0 plane through vertices
            // of height 0) and along a grid line.
            1 => Ray::new(Vec3::new(-1.0, (k % 6) as f32, 0.0), Vec3::X),
            _ => Ray::new(
                Vec3::new(r() * 5.0, r() * 5.0, 3.0),
                Vec3::new(r() - 0.5, r() - 0.5, -1.0),
            ),
        };
        let want = window(oracle(&all), &ray);
        hit += usize::from(!want.is_empty());
        for (name, b) in &all {
            assert_eq!(window(b.as_ref(), &ray), want, "{name}: ray {k} {ray:?}");
            let occluded = b.occluded(&ray, 0.0, f32::INFINITY);
            assert_eq!(occluded, !want.is_empty(), "{name}: ray {k}");
        }
    }
    assert!(hit > 300, "too few rays hit: {hit}");
}

#[test]
fn a_shadow_ray_leaving_a_triangle_skips_only_the_surface_it_leaves() {
    // The terrain, and one blocker triangle high over its middle.
    let mut tris = terrain(4);
    let blocker = tris.len() as u32;
    tris.push(Triangle {
        v: [
            Vec3::new(1.5, 1.5, 3.0),
            Vec3::new(2.5, 1.5, 3.0),
            Vec3::new(2.0, 2.5, 3.0),
        ],
    });
    let all = backends(&tris);
    let (mut left, mut blocked) = (0, 0);
    for i in 1..8 {
        for j in 1..8 {
            let (x, y) = (i as f32 * 0.5, j as f32 * 0.5);
            // Where a camera ray from above meets the terrain (a vertex or
            // an edge: the departure point lies on several triangles).
            let cam = Ray::new(Vec3::new(x, y, 10.0), -Vec3::Z);
            let (id, t) = tris[..blocker as usize]
                .iter()
                .enumerate()
                .filter_map(|(i, tri)| {
                    splatray::primitive::Primitive::intersect(tri, &cam, 0.0, 20.0)
                        .map(|h| (i as u32, h.t))
                })
                .min_by(|a, b| (a.1, a.0).partial_cmp(&(b.1, b.0)).unwrap())
                .unwrap();
            let c = splatray::accel::Candidate {
                id,
                t,
                u: 0.0,
                v: 0.0,
            };
            let point = cam.at(c.t);
            let from = Departure {
                id: c.id,
                point,
                normal: tris[c.id as usize].unit_normal(),
            };
            for (up, name_dir) in [(Vec3::Z, "up"), (Vec3::new(0.3, -0.2, 1.0), "tilted")] {
                let ray = Ray::new(point, up);
                let q = Query {
                    ray,
                    t_min: 0.0,
                    t_max: 100.0,
                    from: Some(from),
                    pass: None,
                };
                // Blocked exactly when the ray meets the blocker.
                let want = splatray::primitive::Primitive::intersect(
                    &tris[blocker as usize],
                    &ray,
                    0.0,
                    100.0,
                )
                .is_some();
                for (name, b) in &all {
                    assert_eq!(
                        b.occluded_from(&q),
                        want,
                        "{name}: leaving {point} {name_dir} from triangle {}",
                        c.id
                    );
                }
                left += 1;
                blocked += usize::from(want);
            }
        }
    }
    // 49 points, two rays each; those meeting the blocker are blocked (3
    // measured: most points under it lie on its rim).
    assert_eq!(left, 98);
    assert!((3..=20).contains(&blocked), "{blocked} of {left} blocked");
}

#[test]
fn nan_and_infinite_rays_meet_nothing_on_every_backend() {
    let tris = terrain(3);
    let all = backends(&tris);
    let o = Vec3::new(1.2, 1.3, 3.0);
    for ray in [
        Ray {
            origin: o,
            dir: Vec3::new(f32::NAN, 0.0, -1.0),
        },
        Ray {
            origin: Vec3::NAN,
            dir: -Vec3::Z,
        },
        Ray {
            origin: Vec3::new(f32::INFINITY, 1.0, 3.0),
            dir: -Vec3::Z,
        },
        Ray {
            origin: o,
            dir: Vec3::new(0.0, 0.0, f32::NEG_INFINITY),
        },
        Ray {
            origin: o,
            dir: Vec3::ZERO,
        },
    ] {
        for (name, b) in &all {
            assert!(window(b.as_ref(), &ray).is_empty(), "{name}: {ray:?}");
            assert!(!b.occluded(&ray, 0.0, f32::INFINITY), "{name}: {ray:?}");
        }
    }
    // The same rays' finite twin hits on every backend.
    let ray = Ray::new(o, -Vec3::Z);
    for (name, b) in &all {
        assert_eq!(window(b.as_ref(), &ray).len(), 1, "{name}");
    }
}

/// A splat standing on a triangle floor (`accel::hybrid`): a disc of
/// radius 0.5 at `(0, 0, 0.5)` facing +x, its rim touching the floor
/// `z = 0` (two triangles) at the origin; a light up and toward +x.
#[test]
fn a_splat_touching_a_triangle_floor_has_no_gap_and_no_self_shadow() {
    use splatray::splat::Splat;
    let splats = vec![Splat::disc(Vec3::new(0.0, 0.0, 0.5), Vec3::X, 0.5).unwrap()];
    let c = |x: f32, y: f32| Vec3::new(x, y, 0.0);
    let floor = vec![
        Triangle {
            v: [c(-2.0, -2.0), c(2.0, -2.0), c(2.0, 2.0)],
        },
        Triangle {
            v: [c(-2.0, -2.0), c(2.0, 2.0), c(-2.0, 2.0)],
        },
    ];
    let light = Vec3::new(3.0, 0.2, 3.0);
    for info in registry::renderers() {
        let b = info.build_hybrid(&splats, &floor).unwrap();
        // No gap: rays at the contact from the lit side meet the splat or
        // the floor, the splat (id 0) when aimed above the floor.
        for k in 0..=40 {
            let aim = Vec3::new(0.0, (k as f32 - 20.0) * 0.0001, k as f32 * 0.0005);
            let ray = Ray::new(Vec3::new(1.0, 0.1, 0.6), aim - Vec3::new(1.0, 0.1, 0.6));
            let mut hits = CandidateHits::new(0.0);
            b.intersect(&ray, 0.0, f32::INFINITY, &mut hits);
            let n = hits
                .nearest()
                .unwrap_or_else(|| panic!("{}: gap at {aim}", info.name));
            assert!(
                k == 0 || n.id == 0,
                "{}: aimed at the splat {aim}, met {n:?}",
                info.name
            );
        }
        // No self-shadow: shadow rays leaving the floor in front of the
        // splat, and the splat's front near its foot, reach the light;
        // leaving the floor behind the splat they are blocked by it.
        for k in 1..=20 {
            let s = k as f32 * 0.005;
            for (id, point, normal, blocked) in [
                (1u32, Vec3::new(s, 0.0, 0.0), Vec3::Z, false),
                (0, Vec3::new(0.0, 0.0, s), Vec3::X, false),
                (1, Vec3::new(-s, 0.0, 0.0), Vec3::Z, true),
            ] {
                let dir = light - point;
                let q = Query {
                    ray: Ray::new(point, dir),
                    t_min: 0.0,
                    t_max: dir.length(),
                    from: Some(Departure { id, point, normal }),
                    pass: None,
                };
                assert_eq!(
                    b.occluded_from(&q),
                    blocked,
                    "{}: leaving {point} of primitive {id}",
                    info.name
                );
            }
        }
    }
}

/// `scenes/hybrid.toml`, loaded, at `w × h`.
fn hybrid(w: u32, h: u32) -> splatray::scene::Scene {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/hybrid.toml");
    let mut s = splatray::scene::load_scene(&path, None).unwrap();
    s.set_view(Some(w), Some(h), None, None).unwrap();
    s
}

/// A triangle hit is a window of one: a splat just behind a triangle,
/// within the blending window, is not blended into it, and a splat just in
/// front of it is the surface, not blended with the triangle either.
#[test]
fn the_resolver_treats_a_triangle_hit_as_a_window_of_one() {
    use splatray::accel::Candidate;
    use splatray::resolve::{Resolved, ShadingMode, resolve_with_triangles};
    use splatray::splat::Splat;
    let splats = vec![Splat::disc(Vec3::ZERO, Vec3::Z, 1.0).unwrap()];
    let ray = Ray::new(Vec3::new(0.0, 0.0, 5.0), -Vec3::Z);
    let tri_hit = |c: &Candidate| splatray::resolve::SurfaceHit {
        id: c.id,
        t: c.t,
        point: ray.at(c.t),
        normal: Vec3::X,
        geometric_normal: Vec3::X,
        front: true,
        blended: 1,
        shadow_origin: ray.at(c.t),
    };
    let model = |_| (ShadingMode::Blended, 0.1);
    let window = |hits: &[(u32, f32)]| {
        let mut w = CandidateHits::new(0.1);
        for &(id, t) in hits {
            w.offer(Candidate {
                id,
                t,
                u: 0.0,
                v: 0.0,
            });
        }
        w
    };
    // Triangle (id 1) nearest, the splat 0.05 behind it.
    let r = resolve_with_triangles(
        &window(&[(1, 4.95), (0, 5.0)]),
        &ray,
        &splats,
        model,
        tri_hit,
    );
    assert!(
        matches!(r, Some(Resolved::Hit(h)) if h.id == 1 && h.normal == Vec3::X),
        "{r:?}"
    );
    // The splat nearest, the triangle 0.05 behind: the splat alone.
    let r = resolve_with_triangles(
        &window(&[(0, 5.0), (1, 5.05)]),
        &ray,
        &splats,
        model,
        tri_hit,
    );
    assert!(
        matches!(r, Some(Resolved::Hit(h)) if h.id == 0 && h.blended == 1 && h.normal == Vec3::Z),
        "{r:?}"
    );
}

/// `scenes/hybrid.toml` (the bunny's splats on a triangle table, under a
/// triangle lamp shade with vertex normals, a triangle mirror, a glass
/// sphere of splats): octree and Embree give the same hits, ids and image,
/// both kinds are seen, shadows fall across both kinds, and the shade
/// shades with its interpolated normals while the table's are its faces'.
#[test]
fn the_hybrid_scene_renders_the_same_on_octree_and_embree() {
    use splatray::validate::compare::compare_frames;
    let scene = hybrid(160, 120);
    let first = scene.first_triangle();
    // The table's 60 triangles, the shade's 96, the mirror's 2.
    assert_eq!(scene.triangles.tris.len(), 158);
    let frames: Vec<_> = ["octree", "embree"]
        .iter()
        .map(|&name| {
            let b = registry::find(name).unwrap().build_scene(&scene).unwrap();
            splatray::render::integrator::render(&scene, b.as_ref(), None)
        })
        .collect();
    let a = compare_frames(&frames[0], &frames[1], scene.options.scale.diagonal);
    assert_eq!((a.hit_agreement, a.same_splat), (1.0, 1.0), "{a:?}");
    assert_eq!(frames[0].rgb, frames[1].rgb, "the images, bit for bit");
    let f = &frames[0];
    let n = f.splat.len();
    let tri = |id: u32| id != u32::MAX && id >= first;
    let splat = |id: u32| id < first;
    let material = |id: u32| scene.material_for(id);
    // Shadowed: facing a light, not all of it reaching the point.
    let shadowed = |i: usize| f.light_facing[i] > 0.0 && f.light_lit[i] < 0.5 * f.light_facing[i];
    let count = |p: &dyn Fn(usize) -> bool| (0..n).filter(|&i| p(i)).count();
    let tris_seen = count(&|i| tri(f.splat[i]));
    let splats_seen = count(&|i| splat(f.splat[i]));
    // Table (material 1) in shadow, and floor splats (material 5) in
    // the table's shadow.
    let table_shadowed = count(&|i| tri(f.splat[i]) && material(f.splat[i]) == 1 && shadowed(i));
    let floor_shadowed = count(&|i| splat(f.splat[i]) && material(f.splat[i]) == 5 && shadowed(i));
    // The shade (material 2): normals interpolated, off its faces'.
    let shade = |i: usize| tri(f.splat[i]) && material(f.splat[i]) == 2;
    let face = |i: usize| scene.triangles.face[(f.splat[i] - first) as usize];
    let shade_smooth = count(&|i| shade(i) && f.normal[i].dot(face(i)) < 0.9999);
    let table_flat =
        count(&|i| tri(f.splat[i]) && material(f.splat[i]) == 1 && f.normal[i] != face(i));
    eprintln!(
        "{n} pixels: {tris_seen} triangles, {splats_seen} splats; shadowed: {table_shadowed} \
         table, {floor_shadowed} floor; shade {} pixels, {shade_smooth} off their faces' normals",
        count(&shade)
    );
    // Measured at 160 × 120 (19,200 pixels): 4,726 triangle and 7,509
    // splat pixels; 798 table pixels and 4,121 floor pixels shadowed; 608
    // of the shade's 801 pixels off their faces' normals (the rest near
    // the middle of a face, where the interpolated normal is the face's).
    assert!(
        tris_seen > 4500 && splats_seen > 7000,
        "{tris_seen} {splats_seen}"
    );
    assert!(table_shadowed > 700 && floor_shadowed > 3900);
    assert!(shade_smooth * 10 > count(&shade) * 7 && table_flat == 0);
}

/// The command line: `render scenes/hybrid.toml` gives the same bytes on
/// `--backend octree` and `--backend embree`, and `compare` reports full
/// agreement and the triangles.
#[test]
fn hybrid_render_and_compare_on_the_command_line() {
    let dir = common::scratch("hybrid");
    std::fs::create_dir_all(&dir).unwrap();
    let scene = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/hybrid.toml");
    let run = |args: &[&str]| {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_splatray"))
            .args(args)
            .arg(&scene)
            .args(["--width", "96", "--height", "72"])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    let png = |b: &str| dir.join(format!("{b}.png"));
    for b in ["octree", "embree"] {
        run(&["render", "--backend", b, "-o", png(b).to_str().unwrap()]);
    }
    let (o, e) = (
        std::fs::read(png("octree")).unwrap(),
        std::fs::read(png("embree")).unwrap(),
    );
    assert!(o == e, "the two renders differ");
    let report = dir.join("compare.json");
    run(&["compare", "--report", report.to_str().unwrap()]);
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(r["triangles"], 158, "{r}");
    let a = &r["backends"][1]["agreement"];
    assert_eq!(
        (a["hit_agreement"].as_f64(), a["same_splat"].as_f64()),
        (Some(1.0), Some(1.0)),
        "{a}"
    );
    assert!(a["image_psnr_db"].is_null(), "identical images: {a}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `compare --as-triangles`: the bunny's mesh model rendered again as its
/// 69,666 triangles on every backend in the same run (the floor, a shape,
/// stays splats), the backends agreeing on the triangles bit for bit, and
/// the splats' image measured against the triangles'; a scene without a
/// mesh is refused in one line.
#[test]
fn compare_as_triangles_renders_the_meshes_beside_the_splats() {
    let dir = common::scratch("as-tri");
    std::fs::create_dir_all(&dir).unwrap();
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let report = dir.join("r.json");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_splatray"))
        .args([
            "compare",
            "--as-triangles",
            "--width",
            "80",
            "--height",
            "60",
            "--report",
        ])
        .arg(&report)
        .arg(root.join("scenes/bunny.toml"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let t = &r["as_triangles"];
    assert_eq!(
        (t["models"].as_u64(), t["triangles"].as_u64()),
        (Some(1), Some(69_666)),
        "{t}"
    );
    assert_eq!(t["splats"], 7921, "the floor's splats stay: {t}");
    let a = &t["backends"][1]["agreement"];
    assert_eq!(
        (a["hit_agreement"].as_f64(), a["same_splat"].as_f64()),
        (Some(1.0), Some(1.0)),
        "{a}"
    );
    // The splats against the exact triangles: measured 35.26 dB at
    // 80 × 60, the same on every backend (the stages' splats, before
    // lean growth grew the bunny's by default: 34.36).
    let psnr: Vec<f64> = t["splats_psnr_db"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p.as_f64().unwrap())
        .collect();
    assert!(
        psnr.iter().all(|&p| p == psnr[0] && p > 35.0 && p < 35.5),
        "{psnr:?}"
    );
    // No mesh to turn into triangles: refused before rendering, one line.
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_splatray"))
        .args(["compare", "--as-triangles", "--report"])
        .arg(dir.join("none.json"))
        .arg(root.join("scenes/contact.toml"))
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && e.trim().lines().count() == 1, "{e}");
    assert!(
        e.contains("no model has a mesh") && !dir.join("none.json").exists(),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The hybrid backend's packet calls give each query what its single
/// calls give (`Backend::intersect_packet`'s contract), on both backends:
/// the camera rays of `scenes/hybrid.toml` in packets of 8, and shadow
/// rays from their hits toward the lamp, some leaving splats and some
/// triangles, in packets and as one batch (`Backend::occluded_each`).
#[test]
fn the_hybrid_backends_packets_answer_as_single_queries() {
    let scene = hybrid(64, 48);
    let cam = &scene.camera;
    let lamp = Vec3::new(0.1, 1.4, 0.1) - scene.offset;
    let bits = |h: &CandidateHits| {
        h.as_slice()
            .iter()
            .map(|c| (c.id, c.t.to_bits(), c.u.to_bits(), c.v.to_bits()))
            .collect::<Vec<_>>()
    };
    for name in ["octree", "embree"] {
        let b = registry::find(name).unwrap().build_scene(&scene).unwrap();
        let xi = scene.options.scale.xi;
        let rays: Vec<Ray> = (0..cam.height)
            .flat_map(|y| (0..cam.width).map(move |x| (x, y)))
            .map(|(x, y)| cam.ray(x as f32 + 0.5, y as f32 + 0.5))
            .collect();
        let (mut from_tri, mut from_splat) = (0, 0);
        for chunk in rays.chunks(8) {
            let qs: Vec<Query> = chunk
                .iter()
                .map(|r| Query::new(*r, 0.0, f32::INFINITY))
                .collect();
            let mut packed: Vec<CandidateHits> =
                qs.iter().map(|_| CandidateHits::new(xi)).collect();
            b.intersect_packet(&qs, &mut packed);
            let mut shadows = Vec::new();
            for (q, p) in qs.iter().zip(&packed) {
                let mut one = CandidateHits::new(xi);
                b.intersect_from(q, &mut one);
                assert_eq!(bits(p), bits(&one), "{name}");
                if let Some(c) = one.nearest() {
                    let origin = q.ray.at(c.t);
                    let to = lamp - origin;
                    let normal = if c.id >= scene.first_triangle() {
                        from_tri += 1;
                        scene.triangles.face[(c.id - scene.first_triangle()) as usize]
                    } else {
                        from_splat += 1;
                        scene.splats[c.id as usize].normal
                    };
                    shadows.push(Query {
                        ray: Ray::new(origin, to),
                        t_min: scene.options.scale.eps_self,
                        t_max: to.length(),
                        from: Some(Departure {
                            id: c.id,
                            point: origin,
                            normal,
                        }),
                        pass: None,
                    });
                }
            }
            let mut out = vec![false; shadows.len()];
            b.occluded_packet(&shadows, &mut out);
            // And as one batch of scattered rays (stale answers first).
            let mut each = vec![true; shadows.len()];
            b.occluded_each(&shadows, &mut each);
            for ((q, o), e) in shadows.iter().zip(&out).zip(&each) {
                let alone = b.occluded_from(q);
                assert_eq!(*o, alone, "{name}");
                assert_eq!(*e, alone, "{name}: occluded_each");
            }
        }
        // Measured at 64 × 48 (3,072 rays): 760 end on triangles, 1,200
        // on splats.
        assert!(
            from_tri > 700 && from_splat > 1100,
            "{from_tri} {from_splat}"
        );
    }
}

/// `smooth = true` on a `triangles` model whose file has no normals: each
/// corner shades with the area-weighted vertex normal (a tent of two
/// faces: the ridge's corners get the two faces' mean, the others their
/// own face's); without it every corner is zero (face normals). `smooth`
/// on any other model is refused in one line.
#[test]
fn smooth_triangles_shade_with_area_weighted_vertex_normals() {
    let dir = common::scratch("smooth");
    std::fs::create_dir_all(&dir).unwrap();
    // Two unit right triangles meeting at the ridge x = 0, tilted 45° each way.
    std::fs::write(
        dir.join("tent.obj"),
        "v 0 1 0\nv 0 1 1\nv -1 0 0\nv 1 0 0\nf 1 3 2\nf 1 2 4\n",
    )
    .unwrap();
    let load = |extra: &str| {
        let text = format!(
            "[camera]\nfrom = [0, 3, 3]\nat = [0, 0.5, 0.5]\n\
             [[model]]\ntriangles = \"tent.obj\"\n{extra}\n\
             [[light]]\nkind = \"point\"\nposition = [0, 4, 0]\nintensity = 5\n"
        );
        let file = splatray::scene::parse_scene_str(&text).unwrap();
        splatray::scene::build_scene(&file, &dir, None)
    };
    let flat = load("").unwrap();
    assert!(
        flat.triangles
            .normals
            .iter()
            .flatten()
            .all(|n| *n == Vec3::ZERO)
    );
    let smooth = load("smooth = true").unwrap();
    let s = 0.5f32.sqrt();
    let (left, right) = (Vec3::new(-s, s, 0.0), Vec3::new(s, s, 0.0));
    for (k, corners) in smooth.triangles.normals.iter().enumerate() {
        let face = smooth.triangles.face[k];
        for n in corners {
            // Ridge corners: the faces' mean, straight up; the rest: the face's.
            let want = if n.x.abs() < 1e-6 { Vec3::Y } else { face };
            assert!((*n - want).length() < 1e-6, "face {k}: {n} against {want}");
            assert!(
                want == Vec3::Y || (want - left).length() < 1e-6 || (want - right).length() < 1e-6
            );
        }
    }
    let text = "[camera]\nfrom = [0, 3, 3]\nat = [0, 0, 0]\n[[model]]\n\
                shape = { kind = \"sphere\", center = [0, 0, 0], radius = 1, splats = 50 }\n\
                smooth = true\n";
    let file = splatray::scene::parse_scene_str(text).unwrap();
    let Err(err) = splatray::scene::build_scene(&file, &dir, None) else {
        panic!("smooth on a shape is refused");
    };
    let err = err.to_string();
    assert!(
        err.contains("`smooth` applies to `triangles` models only") && !err.contains('\n'),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
