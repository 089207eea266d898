//! Issue 39: the synthetic airborne survey (`splatray terrain`) splatted with
//! creases on and rendered against its exact surface, small enough for the
//! test suite: a 60 m survey with three buildings, scanned with the default
//! pattern (two line scanners pitched fore and aft, as a real system flies)
//! and with the old across-only pattern, whose walls facing along the track
//! get no point.

mod common;

use splatray::scene::{build_scene, parse_scene_str};
use splatray::terrain::{ScanPattern, TerrainParams, write_terrain};
use splatray::validate::compare::TruthErrors;

/// The survey `pattern` makes (60 m, one tile, three buildings, the
/// default density, noise and seed), splatted whole with creases on and
/// rendered at 400×300 from the south-east, 40° above, as the scene
/// `render --save-scene` makes for the full survey; its errors against the
/// exact surface.
fn survey_errors(pattern: ScanPattern) -> TruthErrors {
    let dir = common::scratch(&format!("survey-{pattern:?}"));
    let params = TerrainParams {
        size: 60.0,
        tiles: 1,
        buildings: 3,
        pattern,
        ..TerrainParams::default()
    };
    let made = write_terrain(&params, &dir, None).unwrap();
    assert!(made.points > 30_000, "{} points", made.points);
    // The survey's corner is the default origin 500000, 4000000, 100; its
    // centre 30 m east and north of it, the ground within about 12 m of
    // z = 100.
    let view = (
        "500080.0, 3999958.0, 180.0",
        "500030.0, 4000030.0, 105.0",
        3300.0,
    );
    let e = errors_seen_from(&dir, view, "{ creases = true }");
    eprintln!("{pattern:?}: {} points", made.points);
    e
}

/// The errors against its truth of the survey in `dir` (tiles/ and
/// truth.ply) rendered at 400×300 from `from` toward `at`, a point light
/// of `intensity` at the eye, its model's `splat` options `splat`.
fn errors_seen_from(
    dir: &std::path::Path,
    (from, at, intensity): (&str, &str, f64),
    splat: &str,
) -> TruthErrors {
    let scene = format!(
        r#"
background = [0.12, 0.13, 0.16]
[camera]
from = [{from}]
at = [{at}]
up = [0, 0, 1]
fov = 35
width = 400
height = 300
[[model]]
points = "tiles"
truth = "truth.ply"
splat = {splat}
material = {{ kind = "phong", color = [0.78, 0.76, 0.72], specular = 0.15, shininess = 30 }}
[[light]]
kind = "point"
position = [{from}]
intensity = {intensity:?}
[[light]]
kind = "directional"
direction = [0.5477, 0.1431, -0.8244]
intensity = 0.85
[render]
ambient = 0.05
"#
    );
    let scene = build_scene(&parse_scene_str(&scene).unwrap(), dir, None).unwrap();
    let e = common::errors_against_truth(&scene);
    eprintln!("{splat}: {} splats, {e:?}", scene.splats.len());
    e
}

/// The default survey renders as its surface: walls on every side hold
/// points, so clipped splats close the buildings.
#[test]
fn the_default_survey_renders_as_its_surface_with_creases() {
    assert_eq!(TerrainParams::default().pattern, ScanPattern::Oblique);
    let e = survey_errors(ScanPattern::Oblique);
    let psnr = e.image_psnr_db.unwrap();
    // Measured: 24.71 dB, false hits 0.364 % of the image, mean normal
    // error 7.82° (avx2: 24.70 dB, 0.364 %, 7.82°; sse4.2: 24.71 dB,
    // 0.364 %, 7.82°) with noisy flat faces' normals from their wide planes
    // and constant fields (`normals::FLAT_F`, `field::GRADIENT_F`: the
    // small survey's noise sets `face_normals`' tolerance, and its steep
    // hills hold flat patches; the default 200 m survey is unchanged,
    // 29.36 dB); before them 24.93 dB, 0.353 %, 7.82° with Embree's avx512
    // kernels tracing the truth (avx2:
    // 24.92 dB, 0.356 %, 7.82°; sse4.2: 24.90 dB, 0.359 %, 7.83°: edge
    // pixels of the mesh move with the kernel); 24.92 dB, 0.355 %, 7.89°
    // before a turned normal took its side from the edge
    // (`normals::FACE_SIDE_COS`); before splats whose face
    // ends on a third side grew again smaller (`grow::SPILL_SHARE`):
    // 24.96 dB, 0.343 % (avx2 0.358 %, sse4.2 0.353 %), 7.90° (the small survey's hills
    // are steep: 4 m waves over 60 m;
    // most of the normal error is shading on the ground); 24.74 dB,
    // 0.327 %, 8.13° before the rise test of `grow::CREASE_STEEP`, the
    // quadric gate of `normals::face_normals` and `grow::smooth_across`.
    // With the plane
    // through the point in `normals::face_normals` (before the nearer of
    // two faces' planes): 24.28 dB, 0.311 %, 8.66°; before the border band
    // counted from the whole cloud: 24.06 dB, 0.253 %, 8.65°; before both:
    // 24.70 dB, 0.132 %, 9.33°. (The default 200 m survey moved the other
    // way with the border band: 0.097 % -> 0.062 % false hits.)
    // On an Intel Xeon with AVX-512 (thirty-fifth session; the code of
    // the thirty-fourth session's start the same to the pixel): 24.75 dB,
    // 0.3675 % false hits, 7.75° under Embree's default and avx512
    // kernels, 24.70 dB, 0.3817 %, 7.75° under avx2 and 24.74 dB, 0.3683 %,
    // 7.74° under sse4.2: the truth mesh's silhouette pixels move with the
    // kernel tracing it (17 of the 120,000 pixels here).
    assert!(psnr > 24.5, "{psnr}");
    assert!(e.false_hits < 0.0039, "{}", e.false_hits);
    assert!(e.normal_deg_mean < 8.4, "{}", e.normal_deg_mean);
    // The across-only scanner leaves the walls facing north and south
    // open: the camera sees through the south walls.
    let across = survey_errors(ScanPattern::Across);
    let psnr_across = across.image_psnr_db.unwrap();
    // Measured: across 23.36 dB, 14.75° (23.17 dB, 14.97° before the
    // rise test and the quadric gate; 23.04 dB, 15.33° before the
    // nearer of two faces' planes; coverage 0.909 against 0.992).
    assert!(
        psnr > psnr_across + 0.8,
        "oblique {psnr} across {psnr_across}"
    );
    assert!(
        e.normal_deg_mean < across.normal_deg_mean - 3.0,
        "oblique {} across {}",
        e.normal_deg_mean,
        across.normal_deg_mean
    );
}

/// The default survey's points scatter little enough about their planes
/// (0.041 `ϵ`) for lean growth with clip lines at its buildings' edges and
/// its borders, in a quarter of the stages' time: `splat` grows it so, and
/// it renders against its surface as well as the stages' splats.
#[test]
fn the_default_survey_grows_lean_with_clip_lines() {
    let dir = common::scratch("survey-default-lean");
    let made = write_terrain(&TerrainParams::default(), &dir, None).unwrap();
    assert!(made.points > 390_000, "{} points", made.points);
    let report = dir.join("report.json");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_splatray"))
        .arg("splat")
        .arg(dir.join("tiles"))
        .arg("-o")
        .arg(dir.join("splats.ply"))
        .arg("--report")
        .arg(&report)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    let tiles = r["tiles"].as_array().unwrap();
    assert!(
        !tiles.is_empty() && tiles.iter().all(|t| t["lean"] == true),
        "{r}"
    );
    // The scene `render --save-scene` makes for it.
    let view = (
        "500274.5925, 3999839.5469, 326.9095",
        "500107.5328, 4000078.1328, 82.5136",
        36140.37851,
    );
    let lean = errors_seen_from(&dir, view, "{ }");
    let stages = errors_seen_from(&dir, view, "{ creases = true }");
    let (p_lean, p_stages) = (lean.image_psnr_db.unwrap(), stages.image_psnr_db.unwrap());
    // Measured: lean with clip lines 29.83 dB, 0.078 % false hits, mean
    // normal error 1.47° (9,929 splats; 29.79 dB before
    // `lean::sharp::stop_line`); the stages 29.54 dB, 0.062 %, 1.69°
    // (10,578). At 800×600 29.63 and 29.56 dB.
    assert!(p_lean > 29.7, "{p_lean}");
    assert!(p_lean > p_stages, "lean {p_lean} stages {p_stages}");
    assert!(lean.false_hits < 0.0009, "{}", lean.false_hits);
    assert!(lean.normal_deg_mean < 1.6, "{}", lean.normal_deg_mean);
}
