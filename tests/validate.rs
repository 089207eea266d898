//! `compare`: the report schema, and a deliberately broken octree (§3.1
//! step 3 skipped) caught as holes.

mod common;

use common::render_with;

use splatray::accel::octree::{Octree, OctreeParams};
use splatray::primitive::Disc;
use splatray::render::integrator::render;
use splatray::scene::{Scene, build_scene, parse_scene_str};
use splatray::validate::causes::{Cause, Tolerances, error_budget};
use splatray::validate::compare::{compare_frames, render_truth};
use splatray::validate::truth::Truth;
use std::path::Path;
use std::process::Command;

const SCENE: &str = r#"
background = [0.2, 0.2, 0.3]
[camera]
from = [0.0, 1.0, 4.0]
at = [0.0, 0.0, 0.0]
width = 96
height = 72
[[model]]
shape = { kind = "sphere", center = [0.0, 0.3, 0.0], radius = 0.8, splats = 800 }
material = { kind = "phong" }
[[model]]
shape = { kind = "quad", center = [0.0, -0.5, 0.0], size = [4.0, 4.0], splats = 800 }
[[light]]
kind = "point"
position = [2.0, 3.0, 2.0]
intensity = 20
"#;

fn scene() -> Scene {
    build_scene(&parse_scene_str(SCENE).unwrap(), Path::new("."), None).unwrap()
}

#[test]
fn correct_backends_agree_completely() {
    let sc = scene();
    let o = render_with(&sc, common::default_renderer());
    let e = render_with(&sc, common::other_renderer());
    let a = compare_frames(&o, &e, sc.options.scale.diagonal);
    assert_eq!(a.hit_agreement, 1.0, "{a:?}");
    assert_eq!(a.same_splat, 1.0, "{a:?}");
    assert_eq!(a.dt_rel_max, 0.0, "{a:?}");
    assert_eq!(a.normal_deg_max, 0.0, "{a:?}");
    assert_eq!(a.image_psnr_db, None, "{a:?}");
}

#[test]
fn broken_octree_is_caught_as_holes() {
    let sc = scene();
    let discs: Vec<Disc> = sc.splats.iter().map(|s| s.disc_geometry()).collect();
    let broken = Octree::without_overlap_insertion(&discs, &OctreeParams::default());
    let bad = render(&sc, &broken, None);
    let good = render_with(&sc, common::other_renderer());
    let a = compare_frames(&bad, &good, sc.options.scale.diagonal);
    eprintln!("broken octree vs embree: {a:?}");
    // Holes: rays the broken tree misses that Embree hits; never the reverse.
    assert!(a.only_second > 0, "{a:?}");
    assert_eq!(a.only_first, 0, "{a:?}");
    assert!(a.hit_agreement < 1.0);
    assert!(a.image_psnr_db.is_some());
}

/// The error budget by cause on real renders against the exact sphere and
/// floor: flat shading (only the normals change) moves error into the
/// normal-related causes and leaves the coverage ones pixel for pixel as
/// they were; the broken octree's holes are all found as holes.
#[test]
fn error_budget_puts_each_error_where_it_belongs() {
    let with = |shading: &str| {
        let text = SCENE.replace(
            "[camera]",
            &format!("[render]\nshading = \"{shading}\"\n[camera]"),
        );
        build_scene(&parse_scene_str(&text).unwrap(), Path::new("."), None).unwrap()
    };
    let (phong, flat) = (with("phong"), with("flat"));
    let truth = render_truth(&phong, &Truth::new(&phong).unwrap(), None);
    let diagonal = phong.options.scale.diagonal;
    let tol = Tolerances::default();
    let budget = |f: &splatray::render::integrator::Frame| {
        error_budget(f, &truth, diagonal, &tol, &phong.material_of).0
    };
    let (fp, ff) = (
        render_with(&phong, common::other_renderer()),
        render_with(&flat, common::other_renderer()),
    );
    let (p, f) = (budget(&fp), budget(&ff));
    eprintln!("phong {p:#?}\nflat {f:#?}");
    let by = |b: &splatray::validate::causes::ErrorBudget, c: Cause| b.causes[c as usize].clone();
    for b in [&p, &f] {
        let shares: f64 = b.causes.iter().map(|c| c.share).sum();
        assert!((shares - 1.0).abs() < 1e-9, "{b:?}");
        assert_eq!(b.causes.iter().map(|c| c.pixels).sum::<usize>(), 96 * 72);
        for c in &b.causes {
            // Making any cause's pixels exact never lowers the PSNR.
            assert!(c.psnr_if_exact_db.unwrap_or(f64::INFINITY) >= b.psnr_db.unwrap() - 1e-9);
        }
    }
    // The same discs: the same coverage and the same silhouettes.
    for c in [
        Cause::Background,
        Cause::Hole,
        Cause::FalseHit,
        Cause::Silhouette,
        Cause::Depth,
    ] {
        assert_eq!(by(&p, c).pixels, by(&f, c).pixels, "{c:?}");
    }
    // Flat normals: the shading error grows and leads among the
    // normal-related causes.
    let normal_se =
        |b| [Cause::Terminator, Cause::Shadow, Cause::Shading].map(|c| by(b, c).squared_error);
    let (np, nf) = (normal_se(&p), normal_se(&f));
    assert!(nf[2] > 2.0 * np[2], "shading {np:?} -> {nf:?}");
    assert!(nf[2] > nf[0] && nf[2] > nf[1], "{nf:?}");
    // The broken octree (§3.1 step 3 skipped) against the truth: its
    // extra misses are holes, and the holes cost it PSNR.
    let discs: Vec<Disc> = phong.splats.iter().map(|s| s.disc_geometry()).collect();
    let broken = Octree::without_overlap_insertion(&discs, &OctreeParams::default());
    let bad = render(&phong, &broken, None);
    let bad = budget(&bad);
    let gap = by(&bad, Cause::Hole).pixels - by(&p, Cause::Hole).pixels;
    assert!(gap > 0, "{bad:?}");
    assert!(by(&bad, Cause::Hole).psnr_if_exact_db.unwrap() > bad.psnr_db.unwrap() + 0.1);
}

/// A scratch folder for test `name` holding [`SCENE`] as `s.toml`: the
/// folder and the scene's path.
fn scene_in_scratch(name: &str) -> (std::path::PathBuf, std::path::PathBuf) {
    let dir = common::scratch(name);
    let scene = dir.join("s.toml");
    std::fs::write(&scene, SCENE).unwrap();
    (dir, scene)
}

#[test]
fn compare_report_has_the_documented_keys() {
    let (dir, scene) = scene_in_scratch("validate");
    let report = dir.join("r.json");
    let diff = dir.join("d.png");
    let o = Command::new(env!("CARGO_BIN_EXE_splatray"))
        .arg("compare")
        .arg(&scene)
        .arg("--report")
        .arg(&report)
        .arg("--diff")
        .arg(&diff)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    // One entry per rendering backend of the registry, the reference first;
    // every other one carries its agreement with the reference.
    let by_name = |name: &str| {
        v["backends"]
            .as_array()
            .and_then(|a| a.iter().find(|b| b["name"] == name))
            .unwrap_or_else(|| panic!("backend {name} missing in {v}"))
            .clone()
    };
    assert_eq!(v["backends"][0]["name"], common::default_renderer(), "{v}");
    let agreement = &by_name(common::other_renderer())["agreement"];
    for k in [
        "rays",
        "hit_agreement",
        "same_splat",
        "dt_rel_p50",
        "dt_rel_p99",
        "dt_rel_max",
        "normal_deg_p99",
        "image_max_abs",
    ] {
        assert!(
            agreement[k].is_number(),
            "{k} missing or not a number in {v}"
        );
    }
    assert!(
        agreement.get("image_psnr_db").is_some(),
        "image_psnr_db missing"
    );
    assert_eq!(v["rays"], 96 * 72);
    assert_eq!(agreement["rays"], 96 * 72);
    for b in common::renderers() {
        for k in ["build_seconds", "mrays_per_s"] {
            let x = &by_name(b)[k];
            // Positive and below a sane ceiling (a 96 x 72 render of a
            // small scene: milliseconds to build, 1-20 Mrays/s measured).
            assert!(
                x.as_f64().is_some_and(|x| x > 0.0 && x < 1e4),
                "{b}.{k} in {v}"
            );
        }
        assert!(
            by_name(b)["memory_bytes"].as_u64().is_some_and(|m| m > 0),
            "{b} memory in {v}"
        );
    }
    let img = image::open(&diff).unwrap();
    assert_eq!((img.width(), img.height()), (3 * 96, 72));
    // No truth asked: no truth panel.
    assert!(!dir.join("d-truth.png").exists());
    // With --truth: the reference against the exact surfaces beside it.
    let o = Command::new(env!("CARGO_BIN_EXE_splatray"))
        .arg("compare")
        .arg(&scene)
        .arg("--truth")
        .arg("--diff")
        .arg(&diff)
        .arg("--report")
        .arg(&report)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let img = image::open(dir.join("d-truth.png")).unwrap();
    assert_eq!((img.width(), img.height()), (3 * 96, 72));
    // The causes of error beside their cost, and the split in the report.
    let img = image::open(dir.join("d-causes.png")).unwrap();
    assert_eq!((img.width(), img.height()), (2 * 96, 72));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let causes = v["truth"]["backends"][0]["by_cause"]["causes"]
        .as_array()
        .unwrap_or_else(|| panic!("by_cause missing in {v}"));
    let names: Vec<&str> = causes
        .iter()
        .map(|c| c["cause"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        [
            "background",
            "hole",
            "false_hit",
            "silhouette",
            "depth",
            "terminator",
            "shadow",
            "shading"
        ]
    );
    let shares: f64 = causes.iter().map(|c| c["share"].as_f64().unwrap()).sum();
    assert!((shares - 1.0).abs() < 1e-9, "{v}");
}

/// `compare --rounds 3`: every backend renders three times in turns; the
/// report gives the rounds, each backend's median speed, and the median of
/// the rounds' ratios inside their range; the images are the same as with
/// one round (renders repeat bit for bit). `--rounds 0` is refused.
#[test]
fn compare_rounds_take_turns() {
    let (dir, scene) = scene_in_scratch("rounds");
    let run = |rounds: &str, tag: &str| {
        let report = dir.join(format!("r{tag}.json"));
        let diff = dir.join(format!("d{tag}.png"));
        let o = common::bin()
            .args(["compare", scene.to_str().unwrap(), "--rounds", rounds])
            .arg("--report")
            .arg(&report)
            .arg("--diff")
            .arg(&diff)
            .output()
            .unwrap();
        let v: Option<serde_json::Value> = o
            .status
            .success()
            .then(|| serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap());
        (o, v, diff)
    };
    let (o, v, diff3) = run("3", "3");
    let v = v.unwrap_or_else(|| panic!("{}", String::from_utf8_lossy(&o.stderr)));
    assert_eq!(v["rounds"], 3, "{v}");
    let embree = &v["backends"][1];
    let ratio = embree["reference_over_this"].as_f64().unwrap();
    let range = embree["reference_over_this_range"].as_array().unwrap();
    let (lo, hi) = (range[0].as_f64().unwrap(), range[1].as_f64().unwrap());
    assert!(lo > 0.0 && lo <= ratio && ratio <= hi, "{v}");
    assert!(
        v["backends"][0].get("reference_over_this_range").is_none(),
        "{v}"
    );
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("median of 3 rounds taken in turns"), "{out}");
    let (o, v, diff1) = run("1", "1");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(v.unwrap()["rounds"], 1);
    assert_eq!(
        std::fs::read(&diff1).unwrap(),
        std::fs::read(&diff3).unwrap()
    );
    let (o, _, _) = run("0", "0");
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("--rounds"), "{err}");
}

/// A splat file with `truth = "mesh.ply"` is measured against that mesh
/// by `compare --truth`, as a sampled mesh model is, and moves with the
/// model's transform; `truth` on a mesh model is refused in one line.
#[test]
fn a_models_truth_mesh_is_its_exact_surface() {
    let dir = common::scratch("validate-truth");
    let mesh = common::data("bunny-mesh.ply");
    let points = dir.join("points.ply");
    let splats = dir.join("splats.ply");
    let run = |args: &[&std::ffi::OsStr]| {
        let o = Command::new(env!("CARGO_BIN_EXE_splatray"))
            .args(args)
            .output()
            .unwrap();
        (
            o.status.success(),
            String::from_utf8_lossy(&o.stderr).into_owned(),
        )
    };
    let os = |s: &str| std::ffi::OsString::from(s);
    let (ok, err) = run(&[
        &os("sample"),
        mesh.as_os_str(),
        &os("-n"),
        &os("60000"),
        &os("-o"),
        points.as_os_str(),
    ]);
    assert!(ok, "{err}");
    let (ok, err) = run(&[
        &os("splat"),
        points.as_os_str(),
        &os("-o"),
        splats.as_os_str(),
        &os("--holdout"),
        &os("0"),
    ]);
    assert!(ok, "{err}");
    let measure = |translate: &str| {
        let scene = dir.join(format!("s{translate}.toml"));
        std::fs::write(
            &scene,
            format!(
                "[camera]\nfrom = [1.5, 1.1, 4.4]\nat = [0.0, -0.1, 0.0]\nfov = 38\nwidth = 120\nheight = 90\n\
                 [[model]]\nsplats = {:?}\ntruth = {:?}\ntransform = {{ translate = [0.0, {translate}, 0.0] }}\n\
                 [[light]]\nkind = \"point\"\nposition = [2.5, 4.0, 3.0]\nintensity = 28.0\n",
                splats.to_str().unwrap(),
                mesh.to_str().unwrap()
            ),
        )
        .unwrap();
        let report = dir.join(format!("r{translate}.json"));
        let (ok, err) = run(&[
            &os("compare"),
            scene.as_os_str(),
            &os("--truth"),
            &os("--report"),
            report.as_os_str(),
        ]);
        assert!(ok, "{err}");
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
        v["truth"]["backends"][0].clone()
    };
    let on = measure("0.0");
    // Holes only at the outline, where Phong splats are not hit beyond
    // their fields' silhouettes (measured: 3 pixels, coverage 0.99853; the
    // bound was 0.999 until Phong splats became the curved surfaces their
    // fields describe, b0b7697, and is 0.998 since: a few outline pixels).
    assert!(on["coverage"].as_f64().unwrap() >= 0.998, "{on}");
    let holes = &on["by_cause"]["holes"];
    assert_eq!(
        (holes["at_2_3px"].as_u64(), holes["farther"].as_u64()),
        (Some(0), Some(0)),
        "{on}"
    );
    assert!(on["false_hits"].as_f64().unwrap() <= 0.01, "{on}");
    // Measured 2.65 degrees (p99 12.5; false hits 0.00065): within 0.5.
    assert!(on["normal_deg_mean"].as_f64().unwrap() < 3.15, "{on}");
    // The truth stays in the model's coordinates and moves with it: the
    // model translated (seen a little from above) is covered as well
    // (measured 0.99952; a truth left behind would cover a fraction).
    let moved = measure("0.25");
    assert!(moved["coverage"].as_f64().unwrap() >= 0.998, "{moved}");
    let scene = dir.join("bad.toml");
    std::fs::write(
        &scene,
        format!(
            "[camera]\nfrom = [0.0, 0.0, 3.0]\nat = [0.0, 0.0, 0.0]\nwidth = 8\nheight = 8\n\
             [[model]]\nmesh = {:?}\nsamples = 1000\ntruth = {:?}\n",
            mesh.to_str().unwrap(),
            mesh.to_str().unwrap()
        ),
    )
    .unwrap();
    let (ok, err) = run(&[
        &os("render"),
        scene.as_os_str(),
        &os("-o"),
        dir.join("x.png").as_os_str(),
    ]);
    assert!(!ok && err.contains("`truth` applies to"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
}
