//! Issue 39, generation: clip lines at creases, none on a smooth surface,
//! and no disc over a hole; a small solid rendered against its mesh with
//! crease clipping on and off.

mod common;

use common::solids_scan;

use glam::Vec3;
use splatray::scene::{build_scene, parse_scene_str};
use splatray::splat::{Creases, PointCloud, SplatParams, generate};
use std::path::Path;

/// A ring of points round an empty middle (an annulus 0.8..1.0 in the
/// plane z = 0, normals given): no splat may span the middle.
#[test]
fn no_disc_over_a_ring_of_points() {
    let mut rng = 12345u64;
    let mut next = || {
        rng = rng
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (rng >> 40) as f32 / (1u64 << 24) as f32
    };
    let (mut positions, mut normals) = (Vec::new(), Vec::new());
    while positions.len() < 4000 {
        let (x, y) = (2.0 * next() - 1.0, 2.0 * next() - 1.0);
        let r = (x * x + y * y).sqrt();
        if (0.8..=1.0).contains(&r) {
            positions.push(Vec3::new(x, y, 0.0));
            normals.push(Vec3::Z);
        }
    }
    let cloud = PointCloud {
        positions: positions.clone(),
        normals: Some(normals),
        ..PointCloud::default()
    };
    let params = SplatParams {
        epsilon_rel: 0.05,
        ..SplatParams::default()
    };
    let (splats, report) = generate(&cloud, &params).unwrap();
    assert_eq!(report.hollow_large_splats, 0);
    assert_eq!(report.uncovered_large_splats, 0);
    // Every splat's centre lies within half its radius of a point.
    for s in &splats {
        let c = s.center + cloud.origin.as_vec3();
        let near = positions
            .iter()
            .map(|p| p.distance(c))
            .fold(f32::MAX, f32::min);
        assert!(
            near <= 0.5 * s.radii.max_element(),
            "splat at {c} radius {} is {near} from the ring",
            s.radii.max_element()
        );
    }
}

/// A smooth curved sheet gets no clip line inside it: only along its four
/// borders (none with creases off).
#[test]
fn a_smooth_surface_has_no_crease() {
    let positions: Vec<Vec3> = (0..14400)
        .map(|i| {
            let (x, y) = ((i % 120) as f32 / 119.0, (i / 120) as f32 / 119.0);
            Vec3::new(x, y, 0.3 * (x * x + y * y) + 0.05 * (6.0 * x).sin())
        })
        .collect();
    let cloud = PointCloud {
        positions,
        ..PointCloud::default()
    };
    let on = SplatParams {
        creases: Creases::On,
        ..SplatParams::default()
    };
    let (splats, report) = generate(&cloud, &on).unwrap();
    let o = cloud.origin.as_vec3();
    let inner = splats
        .iter()
        .filter(|s| {
            let c = s.center + o;
            let r = s.radii.max_element();
            c.x > r && c.x < 1.0 - r && c.y > r && c.y < 1.0 - r
        })
        .filter(|s| s.is_clipped())
        .count();
    assert_eq!(inner, 0, "{} clipped of {}", report.clipped, splats.len());
    assert!(report.clipped > 0, "the borders are clipped");
    let off = SplatParams {
        creases: Creases::Off,
        ..SplatParams::default()
    };
    assert_eq!(generate(&cloud, &off).unwrap().1.clipped, 0);
}

/// A flat rectangle smaller than the splats its sampling allows (a box's
/// top seen alone: its face ends on all four sides): with creases, no
/// splat overhangs it, though two clip lines can cut only two of a disc's
/// sides. A splat whose face ends on a third side grows again smaller
/// (`grow::SPILL_SHARE`).
#[test]
fn a_face_ending_on_four_sides_is_not_overhung() {
    let (w, h) = (0.8f32, 0.6f32);
    let mut rng = splatray::rng::SplitMix64::new(39);
    let positions: Vec<Vec3> = (0..3000)
        .map(|_| Vec3::new(w * rng.next_f32(), h * rng.next_f32(), 0.0))
        .collect();
    let cloud = PointCloud {
        positions,
        normals: Some(vec![Vec3::Z; 3000]),
        ..PointCloud::default()
    };
    let params = SplatParams {
        creases: Creases::On,
        ..SplatParams::default()
    };
    let (splats, report) = generate(&cloud, &params).unwrap();
    // The area of the splats (as clipped) outside the rectangle, over
    // their whole area: a 64x64 grid over each disc.
    let o = cloud.origin.as_vec3();
    let (mut outside, mut total) = (0f64, 0f64);
    let mut largest = 0f32;
    for s in &splats {
        largest = largest.max(s.radii.max_element());
        let cell = f64::from(s.radii.x * s.radii.y) * 4.0 / (64.0 * 64.0);
        for k in 0..64 * 64 {
            let u = 2.0 * ((k % 64) as f32 + 0.5) / 64.0 - 1.0;
            let v = 2.0 * ((k / 64) as f32 + 0.5) / 64.0 - 1.0;
            if u * u + v * v > 1.0 || !s.clip.keeps(u, v) {
                continue;
            }
            let p = s.center + o + s.u_axis * (u * s.radii.x) + s.v_axis * (v * s.radii.y);
            total += cell;
            if p.x < 0.0 || p.x > w || p.y < 0.0 || p.y > h {
                outside += cell;
            }
        }
    }
    let share = outside / total;
    eprintln!(
        "{} splats ({} clipped), largest radius {largest}, outside {:.4} % of their area",
        splats.len(),
        report.clipped,
        100.0 * share
    );
    // Splats this sampling allows span most of the rectangle.
    assert!(largest > 0.15, "{largest}");
    // Measured: 78 splats, 0.25 % of their area outside (border lines
    // stand up to 0.15 spacings past the last points); 144 splats, 0.68 %
    // before splats grew again smaller at a third side.
    assert!(share < 0.0035, "{share}");
}

/// The solids of scenes/solids.toml (box, gable-roofed block, cylinder on a
/// ground plane), 60k exact samples, 200x150: PSNR and false hits against
/// the mesh with crease clipping on and off.
#[test]
fn a_solid_renders_as_itself_with_creases() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let text = std::fs::read_to_string(root.join("solids.toml"))
        .unwrap()
        .replace("samples = 300000", "samples = 60000")
        .replace("width = 800", "width = 200")
        .replace("height = 600", "height = 150");
    let (psnr_on, false_on) = solids_figures(&text, &root, true);
    let (psnr_off, false_off) = solids_figures(&text, &root, false);
    // Measured: on 29.45 dB, 0.140 % false hits with crease lines moved
    // onto their clip partners' planes (`splat::partners`); 29.38 dB with
    // splats whose face
    // ends on a third side grown again smaller (`grow::SPILL_SHARE`);
    // 27.97 dB, 0.277 % before, with the rise test of
    // `grow::CREASE_STEEP` and the smooth-rim test of `grow::smooth_across`
    // (at these 60k samples a few edge splats have too few points across
    // to show their face's rise, while the scene's 300k gain 34.20 -> 34.94
    // dB); 28.14 dB, 0.21 % before them (27.32 dB, 0.56 % before the
    // border band from the whole cloud, the border's gap by the chord and
    // corners' lines by the area they cut; 26.26 dB, 0.94 % before clip
    // lines turned to the finer direction); off 18.26 dB, 17.3 %.
    assert!(psnr_on > 29.3, "{psnr_on}");
    assert!(false_on < 0.0017, "{false_on}");
    assert!(psnr_off < 19.0, "{psnr_off}");
    assert!(false_off > 0.15, "{false_off}");
}

/// The solids' 60k exact samples with creases found where the cloud shows
/// them (the default, not the scene's `creases = true`): lean growth's gate
/// finds a clean cloud with creases and borders and grows it with clip
/// lines at them (`splat::lean`'s sharp growth), near the stages' figures.
#[test]
fn a_clean_solid_grows_lean_with_clip_lines() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let mesh = splatray::io::read_mesh(&root.join("data/solids.ply")).unwrap();
    let s = splatray::io::sample_mesh(&mesh, 60_000, 0.0, 1);
    let cloud = PointCloud {
        positions: s.positions,
        ..Default::default()
    };
    let (_, rep) =
        splatray::splat::generate(&cloud, &splatray::splat::SplatParams::default()).unwrap();
    let lean = rep.lean.as_ref().expect("a lean report");
    assert!(lean.used && lean.sharp, "{lean:?}");
    // Measured: 1,294 of 3,686 splats clipped (1,119 before the lines
    // where too few points cross a crease, `lean::sharp::stop_line`).
    assert!(rep.clipped > 1200, "{} clipped", rep.clipped);
    let text = std::fs::read_to_string(root.join("solids.toml"))
        .unwrap()
        .replace("samples = 300000", "samples = 60000")
        .replace("width = 800", "width = 200")
        .replace("height = 600", "height = 150");
    let sharp = text.replace("splat = { creases = true }", "splat = { }");
    let scene = build_scene(&parse_scene_str(&sharp).unwrap(), &root, None).unwrap();
    let e = common::errors_against_truth(&scene);
    eprintln!("lean with clip lines: {e:?}");
    let (psnr_stages, _) = solids_figures(&text, &root, true);
    // Measured: 31.00 dB, 0.130 % false hits, against the stages' (creases
    // on) 29.52 dB, 0.12 % (30.36 dB, 0.133 % without `stop_line`; 29.38
    // dB, 0.41 % with border lines where 6 points, not 4, were expected
    // past them: `lean::sharp`'s `BORDER_EXPECTED`); at 300k samples 36.77
    // against 36.36 at this size, 38.44 against 36.47 at 400x300, 37.26
    // against 36.97 at 800x600; whole discs 18.26 dB.
    let psnr = e.image_psnr_db.unwrap();
    assert!(psnr > 30.85, "{psnr}");
    assert!(
        psnr > psnr_stages + 1.3,
        "{psnr} against the stages' {psnr_stages}"
    );
    assert!(e.false_hits < 0.0016, "{}", e.false_hits);
}

/// The solids scanned exactly from the camera's position (no range noise;
/// 1000x750 rays for the splats' facing, 400x300 for the image, about 16k
/// returns): lean growth's gate finds a clean
/// cloud with creases and borders, so a scan grows lean too, its splats
/// turned toward the scanner tree by tree (a tree across a crease by the
/// sides each splat faces the other from) and its curved silhouettes left
/// open (`splat::lean::SCAN_BEND`); free-space trimming still runs, the
/// points facing away measured on the splats. 200x150 against the mesh.
#[test]
fn an_exact_scan_grows_lean_facing_its_scanner() {
    let cloud = solids_scan([1000, 750], 0.0, 0.0);
    let eye = cloud.viewpoint.expect("a scan's viewpoint");
    // The scanner's position, as `splat` and a scene take a cloud's own.
    let params = splatray::splat::SplatParams {
        viewpoint: Some(eye),
        ..Default::default()
    };
    let (splats, rep) = splatray::splat::generate(&cloud, &params).unwrap();
    let lean = rep.lean.as_ref().expect("a lean report");
    assert!(lean.used && lean.sharp, "{lean:?}");
    // Measured: 0.0 % of the points facing away (7.2 % with the sign
    // alone across creases, so that trimming refused the viewpoint).
    let away = rep.facing_away.expect("a scan facing-away share");
    assert!(away < 0.001, "{away}");
    let facing = splats
        .iter()
        .filter(|s| s.normal.dot(eye - s.center) > 0.0)
        .count();
    // Measured: all 2,143 splats face the scanner (the rays are Embree's,
    // so a grazing splat may turn on another machine).
    assert!(
        1000 * facing >= 999 * splats.len(),
        "{facing} of {} face the scanner",
        splats.len()
    );
    let (e, psnr_stages) = lean_and_stages_scanned("rays = [400, 300]");
    let psnr = e.image_psnr_db.unwrap();
    // Measured (the scan traced by the octree, the same on every ISA):
    // 34.09 dB, 0.103 % false hits, against the stages' (creases on)
    // 31.77 dB, 0.127 %. Traced by Embree: 33.58 dB, 0.09 %, normal error
    // 0.53°, against 31.89 dB, 0.10 %, 1.00°. At 1000x750 rays and 400x300
    // pixels 35.52 against 35.03 dB (35.70 with trimming given the
    // outlier seeds' lines of sight too); from two stations (800x600 rays
    // each) 37.75 against 36.58.
    assert!(psnr > 33.9, "{psnr}");
    assert!(
        psnr > psnr_stages + 2.0,
        "{psnr} against the stages' {psnr_stages}"
    );
    assert!(e.false_hits < 0.0011, "{}", e.false_hits);
}

/// A dense scan too noisy for sharp lean growth has its points settled
/// onto their surfaces first (`splat::lean`'s `settle`), then grows sharp
/// and lean, facing its scanner. Against the stages on the solids scanned
/// with 1000x750 rays (200x150 against the mesh): above them at range
/// noise of 0.3 spacings, at most about a decibel under them at 0.5, the
/// noise where the stages' flat faces serve best.
#[test]
fn a_dense_noisy_scan_grows_lean_on_settled_points() {
    let cloud = solids_scan([1000, 750], 0.0, 0.3);
    let (_, rep) = common::grown_from_its_viewpoint(&cloud);
    let lean = rep.lean.as_ref().expect("a lean report");
    assert!(lean.used && lean.sharp && lean.settled, "{lean:?}");
    // Measured: 0.0 % (the trees turned toward the scanner).
    let away = rep.facing_away.expect("a scan facing-away share");
    assert!(away < 0.001, "{away}");
    // A sparse scan with the same noise keeps the stages, saying why.
    let (_, sparse) = common::grown_from_its_viewpoint(&solids_scan([400, 300], 0.0, 0.5));
    let lean = sparse.lean.as_ref().expect("a lean report");
    let why = lean.refused.as_deref().unwrap_or_default();
    assert!(
        !lean.used && why.contains("settling the points"),
        "{lean:?}"
    );
    let (e, stages) = lean_and_stages_scanned("rays = [1000, 750], range_noise_spacing = 0.3");
    let psnr = e.image_psnr_db.unwrap();
    // Measured (the scan traced by the octree): 35.73 dB, 0.023 % false
    // hits, against the stages' 34.71 dB, 0.093 % (traced by Embree at
    // avx512 / avx2 / sse4.2: 35.73 / 35.73 / 35.93 against 34.63 / 34.76
    // / 34.56).
    assert!(
        psnr > 35.5 && psnr > stages + 0.8,
        "{psnr} against the stages' {stages}"
    );
    assert!(e.false_hits < 0.0004, "{}", e.false_hits);
    let (e, stages) = lean_and_stages_scanned("rays = [1000, 750], range_noise_spacing = 0.5");
    let psnr = e.image_psnr_db.unwrap();
    // Measured (traced by the octree): 34.24 against 35.15 dB, 0.040 %
    // false hits against 0.060 % (by Embree at avx512 / avx2 / sse4.2:
    // 34.27 / 34.29 / 34.23 against 35.29 / 35.15 / 35.26).
    assert!(
        psnr > 34.0 && psnr > stages - 1.2,
        "{psnr} against the stages' {stages}"
    );
    assert!(e.false_hits < 0.0006, "{}", e.false_hits);
}

/// A dense scan with creases scattering just over
/// `lean::SCAN_SETTLE_SIGMA` (the solids with 1000x750 rays and range
/// noise of 0.18 spacings: scatter 0.062 `ϵ`) is settled before sharp lean
/// growth (grown sharp from its points as they lie it read 0.35 dB less
/// at 400x300, seeds 1-6); at 0.12 spacings (0.041) it is grown sharp
/// unsettled.
#[test]
fn a_dense_scan_just_over_the_settle_bound_is_settled() {
    let (_, rep) = common::grown_from_its_viewpoint(&solids_scan([1000, 750], 0.0, 0.18));
    let lean = rep.lean.as_ref().expect("a lean report");
    assert!(lean.used && lean.sharp && lean.settled, "{lean:?}");
    let sigma = lean.gate.sigma;
    assert!(
        sigma > splatray::splat::lean::SCAN_SETTLE_SIGMA
            && sigma <= splatray::splat::lean::SCAN_SHARP_SIGMA,
        "{sigma}"
    );
    let (_, rep) = common::grown_from_its_viewpoint(&solids_scan([1000, 750], 0.0, 0.12));
    let lean = rep.lean.as_ref().expect("a lean report");
    assert!(lean.used && lean.sharp && !lean.settled, "{lean:?}");
    let (e, stages) = lean_and_stages_scanned("rays = [1000, 750], range_noise_spacing = 0.18");
    let psnr = e.image_psnr_db.unwrap();
    // Measured (the scan traced by the octree): 37.77 dB, 0.033 % false
    // hits, against the stages' 34.49 dB; grown sharp unsettled (the bound
    // at `SCAN_SHARP_SIGMA`), 36.08 dB.
    assert!(
        psnr > 37.5 && psnr > stages + 3.0,
        "{psnr} against the stages' {stages}"
    );
    assert!(e.false_hits < 0.0005, "{}", e.false_hits);
}

/// A scan with stray returns along its rays (0.2 %, at 0.5-1.5 times the
/// range: the farthest widen the bounding box by more than half) grows
/// lean, `ϵ` taken from the box of all but the most extreme points
/// (`generate::lean_scale`), where the box's widening used to send it to
/// the stages: better than theirs, with a warning saying why `ϵ` differs.
#[test]
fn a_scan_with_far_stray_returns_grows_lean() {
    let cloud = solids_scan([400, 300], 0.002, 0.0);
    let (_, rep) = common::grown_from_its_viewpoint(&cloud);
    let lean = rep.lean.as_ref().expect("a lean report");
    assert!(lean.used && lean.sharp, "{lean:?}");
    assert!(
        rep.warnings
            .iter()
            .any(|w| w.contains("widen the bounding box")),
        "{:?}",
        rep.warnings
    );
    // With `ϵ` given (as a tile's is, from the plan's own trimmed box) the
    // box plays no part: lean growth runs, as many splats within a few.
    let (n_whole, eps) = (rep.splats, rep.epsilon);
    let given = SplatParams {
        viewpoint: cloud.viewpoint,
        epsilon_abs: Some(eps),
        ..Default::default()
    };
    let (_, rep) = generate(&cloud, &given).unwrap();
    let lean = rep.lean.as_ref().expect("a lean report");
    assert!(lean.used && lean.sharp, "{lean:?}");
    let ratio = rep.splats as f64 / n_whole as f64;
    assert!(
        (ratio - 1.0).abs() < 0.02,
        "{} against {n_whole}",
        rep.splats
    );
    let (e, psnr_stages) = lean_and_stages_scanned("rays = [400, 300], outliers = 0.002");
    let psnr = e.image_psnr_db.unwrap();
    // Measured (the scan traced by the octree): 33.33 dB against the
    // stages' 32.03, false hits 0.077 % (the stages' 0.127 %). Traced by
    // Embree at avx512 / avx2 / sse4.2 on an AMD EPYC: 32.97 / 33.21 /
    // 32.96 dB against 31.67 / 31.91 / 31.97, false hits 0.087 / 0.080 /
    // 0.087 %; on an Intel Xeon at avx2, 0.117 %. Seeds 2 and 3: 33.05
    // and 32.80 against 31.59 and 32.26.
    assert!(psnr > 33.1, "{psnr}");
    assert!(
        psnr > psnr_stages + 1.0,
        "{psnr} against the stages' {psnr_stages}"
    );
    assert!(e.false_hits < 0.0009, "{}", e.false_hits);
}

/// A scan grown lean faces its scanner at any `ϵ`: the orientation tree
/// crosses creases first where each splat's centre stands clear of the
/// other's plane (`lean::link_weight`). By `|n_a · n_b|` alone the solids
/// scanned with 400×300 rays had 9.2 % of their points facing away after
/// the trees' turns at `ϵ` 0.0035 of the diagonal and 8.9 % at 0.008, so
/// trimming refused the viewpoint; now none at either.
#[test]
fn a_scan_grown_lean_faces_its_scanner_at_coarse_epsilons() {
    let cloud = solids_scan([400, 300], 0.0, 0.0);
    for epsilon_rel in [0.0035, 0.008] {
        let params = SplatParams {
            viewpoint: cloud.viewpoint,
            epsilon_rel,
            ..Default::default()
        };
        let (_, rep) = generate(&cloud, &params).unwrap();
        let lean = rep.lean.as_ref().expect("a lean report");
        assert!(lean.used, "{epsilon_rel}: {lean:?}");
        // Measured: 0.000 at both (0.092 and 0.089 before).
        let away = rep.facing_away.expect("a scan's facing-away share");
        assert!(away < 0.01, "{epsilon_rel}: {away} facing away");
        assert!(
            !rep.warnings.iter().any(|w| w.contains("face away")),
            "{epsilon_rel}: {:?}",
            rep.warnings
        );
    }
}

/// A scan with creases and some range noise grows sharp and lean where
/// its scatter is under `lean::SCAN_SHARP_SIGMA`, above `GATE_SIGMA`: the
/// solids scanned with 400×300 rays and range noise of 0.07 spacings
/// (scatter 0.063 `ϵ`), against the stages, which dip there below their
/// flat-face rules' switch; the bunny scanned with noise of 0.1 spacings
/// (scatter 0.057, no crease, silhouettes for borders) keeps the stages.
#[test]
fn a_noisy_scan_with_creases_grows_lean_under_the_scans_bound() {
    let cloud = solids_scan([400, 300], 0.0, 0.07);
    let (_, rep) = common::grown_from_its_viewpoint(&cloud);
    let lean = rep.lean.as_ref().expect("a lean report");
    let g = lean.gate;
    eprintln!("{lean:?}");
    assert!(
        g.sigma > splatray::splat::lean::GATE_SIGMA && g.scan,
        "{g:?}"
    );
    assert!(lean.used && lean.sharp, "{lean:?}");
    let (e, psnr_stages) = lean_and_stages_scanned("rays = [400, 300], range_noise_spacing = 0.07");
    let psnr = e.image_psnr_db.unwrap();
    // Measured (200x150 against the mesh, the scan traced by the octree):
    // 32.67 dB against the stages' 31.68 (traced by Embree, 32.67 against
    // 31.67; seeds 2 and 3 of the scan: 32.93 / 31.94 against 31.43 /
    // 31.07).
    assert!(psnr > 32.3, "{psnr}");
    assert!(
        psnr > psnr_stages + 0.6,
        "{psnr} against the stages' {psnr_stages}"
    );
    // The bunny: plain lean growth's bound.
    let mesh = splatray::io::read_mesh(&common::data("bunny-mesh.ply")).unwrap();
    let scan = splatray::scanner::ScanParams {
        from: glam::DVec3::new(1.5, 1.0, 3.5),
        columns: 1000,
        rows: 750,
        range_noise: splatray::scanner::RangeNoise::Spacing(0.1),
        seed: 1,
        ..Default::default()
    };
    let bunny = splatray::scanner::scan_mesh(&mesh, &scan).unwrap().cloud;
    let (_, rep) = common::grown_from_its_viewpoint(&bunny);
    let lean = rep.lean.as_ref().expect("a lean report");
    assert!(
        lean.gate.sigma > splatray::splat::lean::GATE_SIGMA && lean.gate.scan,
        "{lean:?}"
    );
    let why = lean.refused.as_deref().unwrap_or_default();
    assert!(!lean.used && why.contains("at most 0.046"), "{lean:?}");
}

/// Stray returns near a scanned surface (a point on a scan ray at 0.5-1.5
/// times its range, inside the box, as mixed pixels at silhouettes are)
/// grow no splat standing off the surface: lean growth leaves a seed lying
/// off its nearest's plane out as an outlier (`lean::SEED_OFF_SPACINGS`),
/// so no disc hangs in the air and trimming does not cut the surface
/// behind it for the stray point's line of sight.
#[test]
fn stray_returns_inside_a_scan_grow_no_splat_off_the_surface() {
    use rayon::prelude::*;
    let clean = solids_scan([1000, 750], 0.0, 0.0);
    let scan = solids_scan([1000, 750], 0.002, 0.0);
    assert_eq!(scan.origin, clean.origin);
    // A return the clean scan has is the surface's (no range noise: the
    // same ray, the same point); the rest are strays, kept inside the
    // clean scan's box (the farther ones would widen the box and keep lean
    // growth off the cloud).
    let surface: std::collections::HashSet<[u32; 3]> = clean
        .positions
        .iter()
        .map(|p| p.to_array().map(f32::to_bits))
        .collect();
    let (lo, hi) = clean
        .positions
        .iter()
        .fold((glam::Vec3::MAX, glam::Vec3::MIN), |(a, b), p| {
            (a.min(*p), b.max(*p))
        });
    let stray: Vec<bool> = scan
        .positions
        .iter()
        .map(|p| !surface.contains(&p.to_array().map(f32::to_bits)))
        .collect();
    let drop: Vec<bool> = scan
        .positions
        .iter()
        .zip(&stray)
        .map(|(p, &s)| s && !(p.cmpge(lo).all() && p.cmple(hi).all()))
        .collect();
    let cloud = scan.subset(&drop.iter().map(|d| !d).collect::<Vec<_>>());
    let inside = stray.iter().zip(&drop).filter(|(s, d)| **s && !**d).count();
    // Measured: 87 strays inside the box (218 in all).
    assert!(inside >= 80, "{inside} strays inside the box");
    let (splats, rep) = common::grown_from_its_viewpoint(&cloud);
    let lean = rep.lean.as_ref().expect("a lean report");
    assert!(lean.used && lean.sharp, "{lean:?}");
    // A splat standing off the surface: its centre farther than two `ϵ`
    // from every return of the clean scan (a centre on a face lies within
    // about a spacing of one, 0.6-1.2 `ϵ` here).
    let eps = rep.epsilon as f32;
    let off: Vec<f32> = splats
        .par_iter()
        .map(|s| {
            let c = s.center;
            clean
                .positions
                .iter()
                .map(|p| p.distance_squared(c))
                .fold(f32::INFINITY, f32::min)
                .sqrt()
                / eps
        })
        .filter(|&d| d > 2.0)
        .collect();
    eprintln!(
        "{} of {} splats off the surface: {off:?}",
        off.len(),
        splats.len()
    );
    // Measured: none of 2,162, against 10 of 2,173 (4.1-6.6 `ϵ` off) with
    // every seed kept (the rule's bound raised out of reach).
    assert!(off.len() <= 1, "{off:?}");
}

/// The same solids scanned from the camera's position by a range scanner
/// with noise (`scan = { ..., range_noise_spacing = 0.5 }`, 400x300 rays,
/// about 16k returns), 200x150 against the mesh: crease clipping still
/// finds the edges through the noise (issue 39: noise must not hide real
/// creases).
#[test]
fn a_noisy_scan_of_a_solid_renders_with_creases() {
    let (root, text) = solids_scanned(
        "seed = 1\nscan = { from = [1.9, 1.5, 2.4], at = [0.0, 0.2, 0.0], \
             rays = [400, 300], range_noise_spacing = 0.5 }",
    );
    let (psnr_on, false_on) = solids_figures(&text, &root, true);
    let (psnr_off, false_off) = solids_figures(&text, &root, false);
    // Measured: on 32.09 dB, 0.123 % false hits (Embree forced to sse4.2:
    // 32.16 dB, 0.133 %) with flat faces fitted whole and their points
    // moved onto them along their lines of sight (`splat::planes`); 32.02
    // dB, 0.153 % with face splats as large as elsewhere
    // (`grow::FACE_RADIUS_FACTOR`); 31.74 dB, 0.123 % (sse4.2: 31.66 dB,
    // 0.130 %) before, with crease lines moved onto their clip partners'
    // planes and whole discs on an edge cut by them (`splat::partners`);
    // 31.63 dB with the lines moved only; 31.36 dB, 0.130 % (sse4.2: 31.26
    // dB) before, with a point whose
    // k-nearest plane the noise tilted off its flat face taking the
    // face's wide plane too, and edge points their face's plane however
    // little it turns (`normals::FLAT_EDGE_DEG`); 31.00 dB, 0.137 % before
    // (avx2: 30.94 dB, sse4.2: 30.98 dB) with flat faces' normals
    // from their wide planes (2 rounds of smoothing over the face) and
    // constant fields where no gradient stands out of the noise
    // (`normals::FLAT_F`, `field::GRADIENT_F`); 30.48 dB, 0.123 % before,
    // with splats whose face
    // ends on a third side grown again smaller (`grow::SPILL_SHARE`);
    // 30.39 dB, 0.130 % before, with the quadric gate of
    // `normals::face_normals` (a neighbourhood one quadric fits as closely
    // as two planes keeps its normal: the noisy bunny scans with creases
    // gain 0.9-1.1 dB, a few of this scan's noisy edge points keep their
    // blended normals), the rise test of `grow::CREASE_STEEP` and the
    // smooth-rim test of `grow::smooth_across`; 30.80 dB, 0.133 % before
    // them (a point at an edge takes
    // the nearer of the two faces' planes, `normals::face_normals`; 29.81
    // dB, 0.13 % with the plane through the point holding the most; 27.60
    // dB, 0.12 % without face normals; 27.53 dB, 0.12 % before the border
    // band from the whole cloud; 27.31 dB, 0.30 % before the deep border
    // band of part C); off 26.91 dB, 0.45 % (a scan's splats are small
    // where it is noisy, so whole discs overhang less than on exact
    // samples).
    assert!(psnr_on > 31.9, "{psnr_on}");
    // 0.0014 exactly with Embree forced to its AVX2 kernels on an AVX-512
    // machine (the thirty-fourth session's CI, main and merge alike): the
    // bound holds that figure on every ISA the suite reruns.
    assert!(false_on <= 0.0014, "{false_on}");
    assert!(psnr_on > psnr_off + 0.2, "on {psnr_on} off {psnr_off}");
    assert!(false_on < false_off, "on {false_on} off {false_off}");
}

/// The same solids scanned with range noise from two stations (the
/// camera's and one to its left, `scan = { from = [[...], [...]] }`, 800x600
/// rays each): the second station sees the faces the sphere light lights
/// and the first does not, so shadows are cast by scanned geometry; 200x150
/// against the mesh, creases on.
#[test]
fn a_solid_scanned_from_two_stations_renders_near_its_mesh() {
    let (root, text) = solids_scanned(
        "seed = 1\nscan = { from = [[1.9, 1.5, 2.4], [-2.4, 1.5, 1.9]], \
             at = [0.0, 0.2, 0.0], rays = [800, 600], range_noise_spacing = 0.5 }",
    );
    let (psnr, false_hits) = solids_figures(&text, &root, true);
    // Measured: 35.13 dB, 0.053 % false hits (Embree forced to sse4.2:
    // 35.16 dB, 0.053 %) with flat faces fitted whole (`splat::planes`);
    // 33.71 dB, 0.100 % (sse4.2: 33.76 dB, 0.097 %) before, with crease
    // lines moved onto their clip
    // partners' planes and whole discs on an edge cut by them
    // (`splat::partners`; 33.52 dB with the lines moved only); 33.32 dB,
    // 0.103 % (sse4.2: 33.25 dB) before, with the tilted-plane
    // and edge rules of `normals::face_normals` (33.35 dB, 0.100 % before;
    // 33.03 dB, 0.093 % without
    // the flat faces' wide-plane normals and constant fields; the camera's
    // station alone 32.65 dB, 0.077 %). At 800x600 (docs/notes/real-scans.md,
    // "the noisy scan, round 5"): 34.41 dB, 2.01 dB under the exact
    // samples' 36.42 (issue 39 asks for 3; 33.69 dB before the faces).
    assert!(psnr > 34.95, "{psnr}");
    assert!(false_hits < 0.0008, "{false_hits}");
}

/// The solids' scene scanned from its camera (`scan`: the scan's keys
/// after its position, e.g. `rays = [400, 300]`) at 200x150: lean
/// growth's errors against the mesh (the default `splat`), and the
/// stages' PSNR (creases on). The scan is traced by the octree's exact
/// triangles (`tracer = "octree"`), so its points are the same on every
/// machine and Embree ISA: traced by Embree forced to avx2, the exact
/// 400x300 scan read 0.137 % false hits on an Intel Xeon against 0.090 %
/// at its avx512, past the bound its other machines had measured.
fn lean_and_stages_scanned(scan: &str) -> (splatray::validate::compare::TruthErrors, f64) {
    let (root, text) = solids_scanned(&format!(
        "seed = 1\nscan = {{ from = [1.9, 1.5, 2.4], at = [0.0, 0.2, 0.0], tracer = \"octree\", {scan} }}"
    ));
    let lean_text = text.replace("splat = { creases = true }", "splat = { }");
    let scene = build_scene(&parse_scene_str(&lean_text).unwrap(), &root, None).unwrap();
    let e = common::errors_against_truth(&scene);
    eprintln!("lean, scan {scan}: {e:?}");
    let (psnr_stages, _) = solids_figures(&text, &root, true);
    (e, psnr_stages)
}

/// The scenes folder and scenes/solids.toml with its exact samples
/// replaced by `scan` (a model's `seed` and `scan` lines), at 200x150.
fn solids_scanned(scan: &str) -> (std::path::PathBuf, String) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let samples = "samples = 300000\nseed = 1";
    let text = std::fs::read_to_string(root.join("solids.toml")).unwrap();
    assert!(
        text.contains(samples),
        "scenes/solids.toml no longer says `{samples}`"
    );
    let text = text
        .replace(samples, scan)
        .replace("width = 800", "width = 200")
        .replace("height = 600", "height = 150");
    (root, text)
}

/// PSNR (dB) and false-hit share of the solids scene `text` (scenes/solids.toml
/// edited), rendered against its mesh with crease clipping `creases`.
fn solids_figures(text: &str, root: &Path, creases: bool) -> (f64, f64) {
    // The scene turns creases on; each run says on or off.
    let key = "splat = { creases = true }";
    assert!(
        text.contains(key),
        "scenes/solids.toml no longer says `{key}`"
    );
    let t = text.replace(key, &format!("splat = {{ creases = {creases} }}"));
    let scene = build_scene(&parse_scene_str(&t).unwrap(), root, None).unwrap();
    let e = common::errors_against_truth(&scene);
    eprintln!("creases {creases}: {e:?}");
    (e.image_psnr_db.unwrap(), e.false_hits)
}

/// The bunny of scenes/glass.toml (120k samples of the scanned mesh,
/// scaled 0.9): its facets turn their sampled normals by 32–62° over the
/// ears' thin rounded rims, where the points across rise steeply from a
/// small splat's plane as a true crease's other face would; one quadric
/// fits both sides there (`grow::CREASE_SMOOTH_JUMP_DEG`), and few splats
/// are clipped (the mesh's holes at the base are true borders).
#[test]
fn the_glass_bunny_rims_get_no_false_creases() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let model = "samples = 120000\nseed = 2";
    let text = std::fs::read_to_string(root.join("glass.toml")).unwrap();
    assert!(
        text.contains(model),
        "scenes/glass.toml no longer says `{model}`"
    );
    let t = text.replace(model, &format!("{model}\nsplat = {{ creases = true }}"));
    let scene = build_scene(&parse_scene_str(&t).unwrap(), &root, None).unwrap();
    let clipped = scene.splats.iter().filter(|s| s.is_clipped()).count();
    eprintln!("{clipped} of {} splats clipped", scene.splats.len());
    // Measured: 523 of 28,491 clipped; without the rule 1,467 of 28,594.
    assert!(clipped < 600, "{clipped}");
}

/// `scenes/bunny.toml` (under `root`) at 400x300, checked to say `model`
/// (the text the caller replaces).
fn bunny_at_400x300(root: &Path, model: &str) -> String {
    let text = std::fs::read_to_string(root.join("bunny.toml")).unwrap();
    assert!(
        text.contains(model),
        "scenes/bunny.toml no longer says `{model}`"
    );
    text.replace("width = 800", "width = 400")
        .replace("height = 600", "height = 300")
}

/// The bundled bunny (scenes/bunny.toml: 200k samples of a scanned mesh
/// whose facets turn their normals by 30–60° along 1.4 % of its edges),
/// rendered at 400x300 against its mesh, grown by the stages (lean growth
/// finds no creases at all): crease clipping takes the facets
/// for no crease, so the smooth surface loses next to nothing, and few of
/// its splats are clipped (the mesh's holes at the base are true borders).
#[test]
fn the_smooth_bunny_gets_no_false_creases() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let model = "samples = 200000\nseed = 1";
    let text = bunny_at_400x300(&root, model);
    let figures = |creases: bool| {
        let t = text.replace(
            model,
            &format!("{model}\nsplat = {{ creases = {creases}, lean = false }}"),
        );
        let scene = build_scene(&parse_scene_str(&t).unwrap(), &root, None).unwrap();
        let e = common::errors_against_truth(&scene);
        let clipped = scene.splats.iter().filter(|s| s.is_clipped()).count();
        eprintln!(
            "creases {creases}: {clipped} of {} clipped, {e:?}",
            scene.splats.len()
        );
        (
            e.image_psnr_db.unwrap(),
            clipped as f64 / scene.splats.len() as f64,
        )
    };
    let (psnr_on, clipped_on) = figures(true);
    let (psnr_off, clipped_off) = figures(false);
    // Measured: on 38.05 dB, 600 of 23,776 splats clipped (2.5 %, the
    // floor's 8,000 included); off 37.87 dB. Without the smooth-rim test
    // of `grow::CREASE_SMOOTH_JUMP_DEG`: on 37.99 dB, 1,670 of 23,860
    // (7.0 %); before the rise test of `grow::CREASE_STEEP` too: on 37.82
    // dB, about 2,700 clipped (11 %), the facets taken for creases along
    // the ears' rims and the flanks.
    assert_eq!(clipped_off, 0.0);
    assert!(clipped_on < 0.03, "{clipped_on}");
    assert!(psnr_on > psnr_off, "on {psnr_on} off {psnr_off}");
}

/// The bundled bunny's 200k samples with their normals dropped (positions
/// only, as a scan gives them; the normals estimated), rendered at 400x300
/// against its mesh: the scanned mesh's rough facets (its base's rim, the
/// ears) hold two planes nearly as well as one smooth surface, and a
/// normal turned onto one of them is worse than the smooth one, so the face
/// search turns a normal only where its two planes hold its neighbourhood
/// closely (`splat::normals::TWO_FACES_HOLD`), and creases cost the smooth
/// bunny nothing against the same stages without them. Lean growth, which
/// looks for no crease, is held to its own figure.
#[test]
fn the_estimated_bunny_keeps_its_smooth_normals() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let dir = common::scratch("bunny-estimated");
    let mesh = splatray::io::read_mesh(&root.join("data/bunny-mesh.ply")).unwrap();
    let mut cloud = splatray::io::sample_mesh(&mesh, 200_000, 0.0, 1);
    cloud.normals = None;
    let points = dir.join("bunny-points.ply");
    splatray::io::write_points(&points, &cloud).unwrap();
    let model = "mesh = \"data/bunny-mesh.ply\"\nsamples = 200000\nseed = 1";
    let text = bunny_at_400x300(&root, model);
    let psnr = |splat: &str| {
        let t = text.replace(
            model,
            &format!(
                "points = {:?}\ntruth = \"data/bunny-mesh.ply\"\nsplat = {{ {splat} }}",
                points.display().to_string()
            ),
        );
        let scene = build_scene(&parse_scene_str(&t).unwrap(), &root, None).unwrap();
        let e = common::errors_against_truth(&scene);
        eprintln!("{splat}: {} splats, {e:?}", scene.splats.len());
        e.image_psnr_db.unwrap()
    };
    let on = psnr("creases = true");
    let (off, lean) = (
        psnr("creases = false, lean = false"),
        psnr("creases = false"),
    );
    let _ = std::fs::remove_dir_all(&dir);
    // Measured: on 38.67 dB, the same stages without creases 38.46, lean
    // growth (no creases looked for) 39.18 (21,323, 21,277 and 21,492
    // splats; without `lean::gaps` closing its pinholes, lean fails the
    // bound); with every normal the search turned kept (before `TWO_FACES_HOLD`)
    // on 38.03.
    assert!(on > off, "on {on} off {off}");
    assert!(on > 38.57 && lean > 39.08, "on {on} lean {lean}");
}

/// A pole 1.6 scan spacings in radius with a thin sign (a plate 0.5
/// spacings thick) on a ground plane, y up: the mesh written as PLY.
fn write_pole(path: &Path) {
    let mut verts: Vec<[f32; 3]> = Vec::new();
    let mut faces: Vec<[usize; 3]> = Vec::new();
    let mut quad = |q: [[f32; 3]; 4]| {
        let i = verts.len();
        verts.extend(q);
        faces.push([i, i + 1, i + 2]);
        faces.push([i, i + 2, i + 3]);
    };
    let g = 1.0;
    quad([[-g, 0.0, -g], [-g, 0.0, g], [g, 0.0, g], [g, 0.0, -g]]);
    let (r, h, n) = (0.03f32, 1.6f32, 48);
    let at = |k: usize| {
        let a = std::f32::consts::TAU * k as f32 / n as f32;
        (r * a.cos(), r * a.sin())
    };
    for k in 0..n {
        let ((ax, az), (bx, bz)) = (at(k), at(k + 1));
        quad([[bx, 0.0, bz], [ax, 0.0, az], [ax, h, az], [bx, h, bz]]);
        // The cap as a thin quad to the axis.
        quad([[0.0, h, 0.0], [bx, h, bz], [ax, h, az], [0.0, h, 0.0]]);
    }
    let (x0, x1, y0, y1, z0, z1) = (0.03, 0.33, 0.9, 1.1, -0.005, 0.005);
    quad([[x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]]);
    quad([[x1, y0, z0], [x0, y0, z0], [x0, y1, z0], [x1, y1, z0]]);
    quad([[x1, y0, z1], [x1, y0, z0], [x1, y1, z0], [x1, y1, z1]]);
    quad([[x0, y1, z1], [x1, y1, z1], [x1, y1, z0], [x0, y1, z0]]);
    quad([[x0, y0, z0], [x1, y0, z0], [x1, y0, z1], [x0, y0, z1]]);
    let mesh = splatray::io::Mesh {
        positions: verts.iter().map(|v| Vec3::from(*v)).collect(),
        triangles: faces.iter().map(|f| f.map(|k| k as u32)).collect(),
        origin: glam::DVec3::ZERO,
    };
    splatray::terrain::write_mesh_ply(&mesh, path).unwrap();
}

/// A thin pole with a sign, scanned from one side with range noise (half
/// a spacing), against its mesh: whole discs, wider than the pole, make it
/// and the sign fat blobs; clipped at the points' borders they are nearer
/// the mesh. (The bundled lamppost scan, which has no mesh, draws on fewer
/// pixels with creases: 1.3 % of a 160×120 render against 1.97 %.)
#[test]
fn a_thin_pole_scan_is_nearer_its_mesh_with_creases() {
    let dir = common::scratch("thin-pole");
    write_pole(&dir.join("pole.ply"));
    let scene = |creases: bool| {
        format!(
            "background = [0.60, 0.70, 0.85]\n\
             [camera]\nfrom = [1.2, 1.0, 2.0]\nat = [0.0, 0.8, 0.0]\nfov = 40\n\
             width = 400\nheight = 300\n\
             [[model]]\nmesh = \"pole.ply\"\nseed = 1\n\
             scan = {{ from = [1.2, 1.0, 2.0], at = [0.0, 0.8, 0.0], rays = [320, 240], \
             range_noise_spacing = 0.5 }}\n\
             splat = {{ creases = {creases} }}\n\
             material = {{ kind = \"phong\", color = [0.80, 0.76, 0.70], specular = 0.15, \
             shininess = 30 }}\n\
             [[light]]\nkind = \"sphere\"\nposition = [2.0, 4.0, 3.0]\nradius = 0.3\nintensity = 28.0\n\
             [[light]]\nkind = \"directional\"\ndirection = [0.3, -0.5, -1.0]\nintensity = 0.25\n"
        )
    };
    let figures = |creases: bool| {
        let s = build_scene(&parse_scene_str(&scene(creases)).unwrap(), &dir, None).unwrap();
        let e = common::errors_against_truth(&s);
        eprintln!("creases {creases}: {} splats, {e:?}", s.splats.len());
        e
    };
    let (on, off) = (figures(true), figures(false));
    let (p_on, p_off) = (on.image_psnr_db.unwrap(), off.image_psnr_db.unwrap());
    // Measured: on 29.35 dB, 0.44 % false hits, coverage 0.979; off 28.37
    // dB, 0.90 %, 0.991 (400x300, 1,468 and 1,461 splats).
    assert!(p_on > p_off + 0.7, "on {p_on} off {p_off}");
    assert!(
        on.false_hits < 0.6 * off.false_hits,
        "on {on:?} off {off:?}"
    );
}

/// A floor that ends at a table leg, with a sparse stray row of points
/// beyond its edge (a scan's spray past the floor, seen in a real scan of
/// a table): no splat wider than five times the median radius may cover
/// less than half of its disc with points (the splat grown from the
/// floor's edge out to the row spans the gap).
#[test]
fn no_disc_over_the_gap_to_a_stray_row() {
    let jit = |i: usize| ((i.wrapping_mul(2_654_435_761) >> 7) % 1001) as f32 / 1000.0 - 0.5;
    let mut positions = Vec::new();
    for i in 0..50 {
        for j in 0..50 {
            let q = positions.len();
            positions.push(Vec3::new(
                0.02 * i as f32 + 0.004 * jit(q),
                0.02 * j as f32 + 0.004 * jit(q + 1),
                0.0005 * jit(q + 2),
            ));
        }
    }
    // The leg: a cylinder of radius 0.03 standing at the floor's edge.
    for k in 0..35 {
        for t in 0..10 {
            let a = std::f32::consts::TAU * t as f32 / 10.0;
            positions.push(Vec3::new(
                1.0 + 0.03 * a.cos(),
                0.5 + 0.03 * a.sin(),
                0.02 * (k + 1) as f32,
            ));
        }
    }
    // The stray row, 0.3 past the edge, a point every 0.1.
    for j in 0..11 {
        positions.push(Vec3::new(1.3, 0.1 * j as f32, 0.0));
    }
    let cloud = PointCloud {
        positions,
        ..PointCloud::default()
    };
    let (splats, report) = generate(&cloud, &SplatParams::default()).unwrap();
    let mut radii: Vec<f32> = splats.iter().map(|s| s.radii.max_element()).collect();
    radii.sort_by(f32::total_cmp);
    eprintln!(
        "{} splats, median radius {}, largest {:?}, uncovered large {}",
        splats.len(),
        radii[radii.len() / 2],
        &radii[radii.len() - 5..],
        report.uncovered_large_splats
    );
    // Measured: 230 splats, median radius 0.040, the largest 0.55 (the
    // flat floor's, clipped at its corners and covered), none uncovered.
    assert_eq!(report.uncovered_large_splats, 0, "{report:?}");
    assert_eq!(report.hollow_large_splats, 0, "{report:?}");
}

/// The measure behind `uncovered_large_splats` (`covered_share`): a disc
/// over a dense grid is covered, a disc over a ring of points round an
/// empty middle is not, and neither is a disc reaching from a dense patch
/// across a gap to a sparse stray row (the spacing it counts in is the
/// densest the disc touches); a clip line leaves out what it cuts away.
#[test]
fn covered_share_tells_a_disc_over_a_hole() {
    use splatray::splat::covered_share;
    use splatray::splat::knn::{Knn, build_tree};
    use splatray::splat::{Clip, ClipLine, Splat};
    let share = |pts: &[Vec3], s: &Splat| {
        let tree = build_tree(pts);
        covered_share(s, &tree, &Knn::build(&tree, pts, 12), false)
    };
    let disc = |c: Vec3, r: f32| Splat::disc(c, Vec3::Z, r).unwrap();
    let grid: Vec<Vec3> = (0..40 * 40)
        .map(|i| Vec3::new(0.025 * (i % 40) as f32, 0.025 * (i / 40) as f32, 0.0))
        .collect();
    let full = share(&grid, &disc(Vec3::new(0.5, 0.5, 0.0), 0.4));
    assert!(full > 0.99, "{full}");
    // A ring 0.8..1 round an empty middle.
    let ring: Vec<Vec3> = (0..3000)
        .map(|i| {
            let t = i as f32 * 0.618_034 * std::f32::consts::TAU;
            let r = 0.8 + 0.2 * ((i * 37) % 100) as f32 / 100.0;
            Vec3::new(r * t.cos(), r * t.sin(), 0.0)
        })
        .collect();
    let hollow = share(&ring, &disc(Vec3::ZERO, 1.0));
    // Measured 0.44: the ring's band and three spacings inside it.
    assert!(hollow < 0.5, "{hollow}");
    // The dense patch x < 0.4 and a stray row at x = 1.3, a point every
    // 0.1: a disc from the patch's edge over the row.
    let mut stray: Vec<Vec3> = grid.iter().copied().filter(|p| p.x < 0.4).collect();
    stray.extend((0..11).map(|j| Vec3::new(1.3, 0.1 * j as f32, 0.0)));
    let gap = share(&stray, &disc(Vec3::new(0.85, 0.5, 0.0), 0.5));
    // Measured 0.15.
    assert!(gap < 0.5, "{gap}");
    // The same disc clipped at the patch's edge keeps only covered ground.
    let mut clipped = disc(Vec3::new(0.85, 0.5, 0.0), 0.5);
    // Keeps x <= 0.4: (x - 0.85) = 0.5 (u u_axis.x + v v_axis.x).
    clipped.clip = Clip::one(ClipLine {
        a: clipped.u_axis.x,
        b: clipped.v_axis.x,
        d: -0.9,
    });
    let kept = share(&stray, &clipped);
    eprintln!("covered: grid {full}, ring {hollow}, gap {gap}, clipped {kept}");
    assert!(kept > 0.99, "{kept}");
}

/// The action on a disc over a hole (`holes::shrink_uncovered`): a large
/// splat reaching from a dense patch across a gap to a sparse stray row
/// (as growth from the patch's edge makes where the graph joins them) is
/// shrunk to the patch's part of it; the row's points it leaves on no
/// splat get small splats of their own, so every point still lies on a
/// splat; small splats and a covered large one are left as they are.
#[test]
fn a_disc_over_a_gap_shrinks_to_what_its_points_cover() {
    use splatray::splat::holes::{covered_share, shrink_uncovered};
    use splatray::splat::knn::{Knn, build_tree};
    use splatray::splat::{Splat, on_splat};
    let mut pts: Vec<Vec3> = (0..40 * 40)
        .map(|i| Vec3::new(0.025 * (i % 40) as f32, 0.025 * (i / 40) as f32, 0.0))
        .filter(|p| p.x < 0.4)
        .collect();
    let row = pts.len();
    pts.extend((0..11).map(|j| Vec3::new(1.3, 0.1 * j as f32, 0.0)));
    let normals = vec![Vec3::Z; pts.len()];
    let tree = build_tree(&pts);
    let knn = Knn::build(&tree, &pts, 12);
    let eps = 0.001;
    // Small splats over the patch (radius 0.03, every other grid point),
    // a large covered one inside it, and the one over the gap.
    let mut splats: Vec<Splat> = pts[..row]
        .iter()
        .step_by(2)
        .map(|&p| Splat::disc(p, Vec3::Z, 0.03).unwrap())
        .collect();
    splats.push(Splat::disc(Vec3::new(0.2, 0.5, 0.0), Vec3::Z, 0.18).unwrap());
    let gap = Splat::disc(Vec3::new(0.85, 0.5, 0.0), Vec3::Z, 0.5).unwrap();
    splats.push(gap);
    let before = splats.len();
    assert!(covered_share(&gap, &tree, &knn, false) < 0.5);
    let held: Vec<bool> = pts
        .iter()
        .map(|p| splats.iter().any(|s| on_splat(s, *p, eps)))
        .collect();
    let mut covered = vec![false; pts.len()];
    let done = shrink_uncovered(
        &mut splats,
        &mut covered,
        (&pts, &normals, None),
        &tree,
        &knn,
        false,
        eps,
    );
    eprintln!(
        "{done:?}, the gap's splat now {:?} at {}",
        splats[before - 1].radii,
        splats[before - 1].center
    );
    assert_eq!(done.shrunk, 1, "{done:?}");
    let shrunk = splats[before - 1];
    // Measured: radius 0.038 at x = 0.43, the patch's edge (0.375) and
    // the three spacings it covers past it.
    assert!(shrunk.radii.x < 0.1, "{shrunk:?}");
    assert!(covered_share(&shrunk, &tree, &knn, false) >= 0.5);
    // The covered large splat and the small ones are as they were.
    assert_eq!(splats[before - 2].radii.x, 0.18);
    // Every point a splat held still lies on one: the row's got their own
    // (measured: 5 added, for the row's points the gap's disc held).
    assert!(done.added >= 1, "{done:?}");
    for (j, p) in pts.iter().enumerate().filter(|(j, _)| held[*j]) {
        assert!(
            splats.iter().any(|s| on_splat(s, *p, eps)),
            "point {j} at {p} is on no splat"
        );
    }
}

/// A gable-roofed block on a ground plane, y up: walls 1 × 1.6 and 0.5
/// high, the ridge 0.9 high along z, so each roof meets its wall at an
/// eave of 128.7° (the normals 51.3° apart). The mesh written as PLY.
fn write_gable(path: &Path) {
    let mut verts: Vec<[f32; 3]> = Vec::new();
    let mut faces: Vec<[usize; 3]> = Vec::new();
    let mut poly = |q: &[[f32; 3]]| {
        let i = verts.len();
        verts.extend(q);
        for k in 1..q.len() - 1 {
            faces.push([i, i + k, i + k + 1]);
        }
    };
    let g = 1.6;
    poly(&[[-g, 0.0, -g], [-g, 0.0, g], [g, 0.0, g], [g, 0.0, -g]]);
    let (x0, x1, z0, z1, h, r) = (-0.5f32, 0.5f32, -0.8f32, 0.8f32, 0.5f32, 0.9f32);
    poly(&[[x1, 0.0, z1], [x1, 0.0, z0], [x1, h, z0], [x1, h, z1]]);
    poly(&[[x0, 0.0, z0], [x0, 0.0, z1], [x0, h, z1], [x0, h, z0]]);
    poly(&[
        [x0, 0.0, z1],
        [x1, 0.0, z1],
        [x1, h, z1],
        [0.0, r, z1],
        [x0, h, z1],
    ]);
    poly(&[
        [x1, 0.0, z0],
        [x0, 0.0, z0],
        [x0, h, z0],
        [0.0, r, z0],
        [x1, h, z0],
    ]);
    poly(&[[x1, h, z1], [x1, h, z0], [0.0, r, z0], [0.0, r, z1]]);
    poly(&[[x0, h, z0], [x0, h, z1], [0.0, r, z1], [0.0, r, z0]]);
    let mesh = splatray::io::Mesh {
        positions: verts.iter().map(|v| Vec3::from(*v)).collect(),
        triangles: faces.iter().map(|f| f.map(|k| k as u32)).collect(),
        origin: glam::DVec3::ZERO,
    };
    splatray::terrain::write_mesh_ply(&mesh, path).unwrap();
}

/// The gable block scanned from below its eave (a scanner on a tripod
/// beside the wall, `scan` of the scene, looking up at the eave) and
/// rendered from there, 400×300, creases `on` or off: the pixels where
/// one face of the eave shows the other's shading (the exact surface
/// shows the wall, within 5° of its normal, and the splats the roof's,
/// within 15°, or the other way round), and the pixels of each face.
fn eave_seam(dir: &Path, scan: &str, creases: bool) -> (usize, usize) {
    use splatray::validate::compare::render_truth;
    let scene = format!(
        "background = [0.60, 0.70, 0.85]\n\
         [camera]\nfrom = [1.8, 0.2, 0.4]\nat = [0.5, 0.5, 0.0]\nfov = 30\n\
         width = 400\nheight = 300\n\
         [[model]]\nmesh = \"gable.ply\"\nseed = 1\n{scan}\n\
         splat = {{ creases = {creases} }}\n\
         material = {{ kind = \"phong\", color = [0.80, 0.76, 0.70], specular = 0.15, \
         shininess = 30 }}\n\
         [[light]]\nkind = \"sphere\"\nposition = [2.0, 4.0, 3.0]\nradius = 0.3\nintensity = 28.0\n\
         [[light]]\nkind = \"directional\"\ndirection = [0.3, -0.5, -1.0]\nintensity = 0.25\n"
    );
    let s = build_scene(&parse_scene_str(&scene).unwrap(), dir, None).unwrap();
    let truth = render_truth(
        &s,
        &splatray::validate::truth::Truth::new(&s).unwrap(),
        None,
    );
    let mut frame = common::render_with(&s, common::default_renderer());
    splatray::validate::compare::orient_to_camera(&mut frame, &s.camera);
    let wall = Vec3::X;
    let roof = Vec3::new(0.4, 0.5, 0.0).normalize();
    let within = |n: Vec3, m: Vec3, deg: f32| n.dot(m) >= deg.to_radians().cos();
    let (mut seam, mut faces) = (0, 0);
    for (t, n) in truth.normal.iter().zip(&frame.normal) {
        for (a, b) in [(wall, roof), (roof, wall)] {
            if within(*t, a, 5.0) {
                faces += 1;
                seam += usize::from(within(*n, b, 15.0));
            }
        }
    }
    eprintln!(
        "creases {creases}: {} splats, {seam} seam pixels of {faces}",
        s.splats.len()
    );
    (seam, faces)
}

/// Issue 54: a gable block seen from below its eaves has no seam. The
/// roof's and the wall's splats along the eave end where the two faces
/// meet (`rim::CREASE_RISE_EPS`): few show their face's shading across the
/// eave on the other. Scanned without noise and with range noise of half a
/// spacing.
#[test]
fn a_gable_block_seen_from_below_its_eave_has_no_seam() {
    let dir = common::scratch("gable-eave");
    write_gable(&dir.join("gable.ply"));
    let scan = "scan = { from = [1.8, 0.2, 0.4], at = [0.5, 0.5, 0.0], rays = [600, 450], \
                tracer = \"octree\" }";
    let (seam, faces) = eave_seam(&dir, scan, true);
    let (seam_off, _) = eave_seam(&dir, scan, false);
    let noisy = "scan = { from = [1.8, 0.2, 0.4], at = [0.5, 0.5, 0.0], rays = [600, 450], \
                 range_noise_spacing = 0.5, tracer = \"octree\" }";
    let (seam_noisy, _) = eave_seam(&dir, noisy, true);
    // The scans are traced by the octree's exact triangles (`tracer =
    // "octree"`), so the points and the figures are the same on every
    // Embree ISA and SIMD path: measured 608 seam pixels of 90,738 on the
    // two faces (the eave runs across the whole 400-pixel image: about 1.5
    // pixels wide), whole discs 1,096, range noise 226, the same with Embree
    // forced to sse4.2, avx2 and avx512 and with SPLATRAY_SIMD=portable.
    // (Scanned by Embree the seam moved 711-791 pixels and whole discs
    // 1,128-2,026 with the ISA: docs/notes/generation.md, "Issue 54, round
    // 5".) Not yet "no seam": what is left are splats of the wall whose own
    // face's points (the roof's first rows, their estimated normals blended
    // to within 30° of the wall's) reach their rim, so no line is found, and
    // under range noise sides too scattered to count as planes.
    assert!(faces > 80_000, "{faces}");
    assert!(seam < 640, "{seam}");
    assert!(seam_noisy < 240, "{seam_noisy}");
    // 608 against 1,096: 0.55 of whole discs.
    assert!(5 * seam < 3 * seam_off, "{seam} {seam_off}");
}
