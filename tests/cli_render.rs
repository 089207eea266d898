//! `splatray render` on bad scene files: one clear line, non-zero exit, and
//! no output file, partial or whole.

mod common;

use common::scratch;

use std::path::Path;
use std::process::Command;

/// Runs `render` on a scene text; returns (success, stderr, output exists,
/// any file left in the folder besides the scene and its inputs).
fn render(dir: &Path, scene: &str) -> (bool, String, bool) {
    let scene_path = dir.join("scene.toml");
    std::fs::write(&scene_path, scene).unwrap();
    let out = dir.join("out.png");
    let o = Command::new(env!("CARGO_BIN_EXE_splatray"))
        .arg("render")
        .arg(&scene_path)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    let leftovers = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .any(|e| e.file_name().to_string_lossy().contains("out."));
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
        leftovers,
    )
}

const CAMERA: &str =
    "[camera]\nfrom = [0.0, 0.0, 3.0]\nat = [0.0, 0.0, 0.0]\nwidth = 16\nheight = 16\n";

fn assert_clean_failure(name: &str, scene: &str, expect: &[&str]) {
    let dir = scratch(name);
    let (ok, err, leftovers) = render(&dir, scene);
    assert!(!ok, "{name}: render should fail");
    assert_eq!(
        err.trim().lines().count(),
        1,
        "{name}: one line, got:\n{err}"
    );
    for e in expect {
        assert!(err.contains(e), "{name}: '{e}' not in: {err}");
    }
    assert!(!leftovers, "{name}: an output file was left behind");
    assert!(!err.contains("panicked"), "{name}: {err}");
}

#[test]
fn good_scene_renders() {
    let dir = scratch("good");
    let scene = format!(
        "{CAMERA}[[model]]\nshape = {{ kind = \"sphere\", radius = 1.0, splats = 100 }}\n[[light]]\nkind = \"point\"\nposition = [1.0, 1.0, 3.0]\n"
    );
    let (ok, err, made) = render(&dir, &scene);
    assert!(ok, "{err}");
    assert!(made);
    let img = image::open(dir.join("out.png")).unwrap();
    assert_eq!((img.width(), img.height()), (16, 16));
}

#[test]
fn missing_model_file() {
    let scene = format!("{CAMERA}[[model]]\npoints = \"nope/missing.ply\"\n");
    assert_clean_failure("missing", &scene, &["missing.ply"]);
}

#[test]
fn unknown_key_names_key_and_line() {
    let scene = format!(
        "{CAMERA}[[model]]\nshape = {{ kind = \"sphere\", radius = 1.0, splats = 10 }}\ncolour = [1, 0, 0]\n"
    );
    assert_clean_failure("unknown", &scene, &["colour", "line 8"]);
}

#[test]
fn negative_resolution() {
    let scene = "[camera]\nfrom = [0.0, 0.0, 3.0]\nat = [0.0, 0.0, 0.0]\nwidth = -16\n[[model]]\nshape = { kind = \"sphere\", radius = 1.0, splats = 10 }\n";
    assert_clean_failure("negres", scene, &["line 4"]);
}

#[test]
fn zero_resolution() {
    let scene = format!(
        "{}[[model]]\nshape = {{ kind = \"sphere\", radius = 1.0, splats = 10 }}\n",
        CAMERA.replace("width = 16", "width = 0")
    );
    assert_clean_failure("zerores", &scene, &["resolution"]);
}

#[test]
fn non_ply_model() {
    let dir = scratch("nonply");
    std::fs::write(dir.join("model.ply"), "this is not a ply file\n1 2 3\n").unwrap();
    let scene = format!("{CAMERA}[[model]]\npoints = \"model.ply\"\n");
    let (ok, err, leftovers) = render(&dir, &scene);
    assert!(!ok);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("model.ply"), "{err}");
    assert!(!leftovers);
}

#[test]
fn bad_output_extension_fails_before_work() {
    let dir = scratch("ext");
    let scene_path = dir.join("scene.toml");
    std::fs::write(
        &scene_path,
        format!("{CAMERA}[[model]]\nshape = {{ kind = \"sphere\", radius = 1.0, splats = 10 }}\n"),
    )
    .unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_splatray"))
        .args(["render"])
        .arg(&scene_path)
        .arg("-o")
        .arg(dir.join("out.jpg"))
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains(".png or .exr"));
}

#[test]
fn report_and_aovs_are_written() {
    let dir = scratch("aov");
    let scene_path = dir.join("scene.toml");
    std::fs::write(
        &scene_path,
        format!("{CAMERA}[[model]]\nshape = {{ kind = \"sphere\", radius = 1.0, splats = 200 }}\n[[light]]\nkind = \"directional\"\ndirection = [0.0, 0.0, -1.0]\n"),
    )
    .unwrap();
    let out = dir.join("img.png");
    let report = dir.join("r.json");
    let o = Command::new(env!("CARGO_BIN_EXE_splatray"))
        .arg("render")
        .arg(&scene_path)
        .arg("-o")
        .arg(&out)
        .args([
            "--backend",
            common::other_renderer(),
            "--aov",
            "depth,normal,splat,albedo",
            "--report",
        ])
        .arg(&report)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(v["backend"], common::other_renderer());
    assert_eq!(v["width"], 16);
    assert_eq!(v["rays"]["primary"], 256);
    assert!(v["rays"]["shadow"].as_u64().unwrap() > 0);
    assert_eq!(v["rays"]["refraction"], 0, "no glass, no refraction rays");
    for k in [
        "splats",
        "build_seconds",
        "render_seconds",
        "mrays_per_s",
        "spp",
        "height",
    ] {
        assert!(v[k].is_number(), "{k} in {v}");
    }
    // The depth AOV: the centre pixel sees the sphere at distance ~2.
    let depth = image::open(dir.join("img.depth.exr")).unwrap().to_rgb32f();
    let d = depth.get_pixel(8, 8)[0];
    assert!((d - 2.0).abs() < 0.05, "centre depth {d}");
    assert!(depth.get_pixel(0, 0)[0].is_infinite(), "corner should miss");
    let ids = image::open(dir.join("img.splat.exr")).unwrap().to_rgb32f();
    assert!(ids.get_pixel(8, 8)[0] >= 0.0);
    assert_eq!(ids.get_pixel(0, 0)[0], -1.0);
    let n = image::open(dir.join("img.normal.exr")).unwrap().to_rgb32f();
    assert!(n.get_pixel(8, 8)[2] > 0.9, "centre normal faces the camera");
    // The albedo AOV: the unlit colour where a ray hits, zero where none
    // does, and the same bytes from the octree.
    let albedo = image::open(dir.join("img.albedo.exr")).unwrap().to_rgb32f();
    assert!(
        albedo.get_pixel(8, 8).0.iter().all(|&c| c > 0.1),
        "centre albedo"
    );
    assert_eq!(albedo.get_pixel(0, 0).0, [0.0; 3]);
    let out2 = dir.join("img2.png");
    let o = Command::new(env!("CARGO_BIN_EXE_splatray"))
        .arg("render")
        .arg(&scene_path)
        .arg("-o")
        .arg(&out2)
        .args(["--backend", common::default_renderer(), "--aov", "albedo"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        std::fs::read(dir.join("img.albedo.exr")).unwrap()
            == std::fs::read(dir.join("img2.albedo.exr")).unwrap(),
        "the backends' albedo AOVs differ"
    );
}

#[test]
fn camera_that_sees_nothing_gets_a_warning_naming_where_the_splats_are() {
    let dir = scratch("nothing");
    // The camera looks away from the sphere at (0, 0, 0).
    let scene = "[camera]\nfrom = [0.0, 0.0, 3.0]\nat = [0.0, 0.0, 6.0]\nwidth = 8\nheight = 8\n[[model]]\nshape = { kind = \"sphere\", center = [10.0, 0.0, 0.0], radius = 1.0, splats = 50 }\n";
    let (ok, err, made) = render(&dir, scene);
    assert!(ok, "{err}");
    assert!(made);
    assert!(err.contains("no primary ray hit a splat"), "{err}");
    // Splat centres lie on the sphere around x = 10, in the file's
    // coordinates (not the re-centred ones).
    let x_after = |key: &str| -> f32 {
        let rest = &err[err.find(key).unwrap() + key.len()..];
        rest[..rest.find(',').unwrap()].parse().unwrap()
    };
    let (lo, hi) = (x_after("span ["), x_after("to ["));
    assert!(
        (8.9..9.2).contains(&lo) && (10.8..11.1).contains(&hi),
        "{lo} {hi}: {err}"
    );
}

/// An output that cannot be written (a report or an AOV path that is a
/// folder) fails the run before any work, in one line, and leaves none of
/// its outputs: the image, AOVs and report are committed together.
#[test]
fn an_unwritable_report_or_aov_leaves_no_output() {
    let dir = scratch("outputs");
    let scene = format!(
        "{CAMERA}[[model]]\nshape = {{ kind = \"sphere\", radius = 1.0, splats = 100 }}\n[[light]]\nkind = \"point\"\nposition = [1.0, 1.0, 3.0]\n"
    );
    let scene_path = dir.join("scene.toml");
    std::fs::write(&scene_path, scene).unwrap();
    std::fs::create_dir_all(dir.join("r-folder")).unwrap();
    std::fs::create_dir_all(dir.join("out.depth.exr")).unwrap();
    for extra in [
        vec!["--report", "r-folder"],
        vec!["--aov", "normal,depth", "--report", "r.json"],
    ] {
        let o = Command::new(env!("CARGO_BIN_EXE_splatray"))
            .current_dir(&dir)
            .arg("render")
            .arg(&scene_path)
            .args(["-o", "out.png"])
            .args(&extra)
            .output()
            .unwrap();
        assert!(!o.status.success(), "{extra:?}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        assert!(err.contains("is a folder"), "{err}");
        let mut left: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        assert_eq!(
            left,
            ["out.depth.exr", "r-folder", "scene.toml"],
            "{extra:?}"
        );
    }
}

/// Bands rendered apart (`--band I/N`, uneven: 37 rows in 3 bands, one of
/// them in another backend) and stitched are the whole render's bytes, PNG
/// and EXR; a wrong band or a mixed stitch is one line.
#[test]
fn bands_stitch_into_the_whole_render() {
    let dir = scratch("render-bands");
    let scene_path = dir.join("scene.toml");
    let scene = format!(
        "{}[[model]]\nshape = {{ kind = \"sphere\", center = [0.0, 0.0, 0.0], radius = 1.0, splats = 3000 }}\n\
         [[light]]\nkind = \"sphere\"\nposition = [2.0, 3.0, 3.0]\nradius = 0.5\nintensity = 20.0\nsamples = 4\n",
        CAMERA
            .replace("height = 16", "height = 37")
            .replace("width = 16", "width = 29")
    );
    std::fs::write(&scene_path, scene).unwrap();
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_splatray"))
            .args(args)
            .output()
            .unwrap()
    };
    let s = scene_path.to_str().unwrap();
    for ext in ["png", "exr"] {
        let whole = dir.join(format!("whole.{ext}"));
        let o = run(&["render", s, "--spp", "4", "-o", whole.to_str().unwrap()]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let mut parts = Vec::new();
        for i in 0..3 {
            let p = dir.join(format!("band{i}.{ext}"));
            let backend = common::renderers()[usize::from(i == 1)];
            let band = format!("{i}/3");
            let o = run(&[
                "render",
                s,
                "--spp",
                "4",
                "--backend",
                backend,
                "--band",
                &band,
                "-o",
                p.to_str().unwrap(),
            ]);
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
            parts.push(p.to_str().unwrap().to_string());
        }
        let stitched = dir.join(format!("stitched.{ext}"));
        let mut args = vec!["stitch".to_string()];
        args.extend(parts.iter().cloned());
        args.extend(["-o".into(), stitched.to_str().unwrap().into()]);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = run(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert!(
            std::fs::read(&stitched).unwrap() == std::fs::read(&whole).unwrap(),
            "stitched {ext} differs from the whole render"
        );
    }
    let bad = run(&["render", s, "--band", "3/3", "-o", "x.png"]);
    assert!(!bad.status.success());
    let mixed = dir.join("mixed.png");
    let o = run(&[
        "stitch",
        dir.join("band0.png").to_str().unwrap(),
        dir.join("band1.exr").to_str().unwrap(),
        "-o",
        mixed.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("band1.exr"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(!mixed.exists());
}

#[test]
fn every_registry_entry_renders_under_its_own_name() {
    // The octree's layouts and overlap tests are registry entries that
    // differ from `octree` only in their parameters (one entry each, no type
    // of their own): each must report its own name, and all of them, being
    // one contract, the octree's image byte for byte.
    let dir = scratch("entries");
    let scene_path = dir.join("scene.toml");
    std::fs::write(
        &scene_path,
        format!("{CAMERA}[[model]]\nshape = {{ kind = \"sphere\", radius = 1.0, splats = 300 }}\n[[light]]\nkind = \"point\"\nposition = [2.0, 2.0, 3.0]\n"),
    )
    .unwrap();
    let mut images = Vec::new();
    for info in splatray::accel::registry::backends::<splatray::primitive::Disc>() {
        let out = dir.join(format!("{}.png", info.name));
        let report = dir.join(format!("{}.json", info.name));
        let o = Command::new(env!("CARGO_BIN_EXE_splatray"))
            .arg("render")
            .arg(&scene_path)
            .arg("-o")
            .arg(&out)
            .args(["--backend", info.name, "--report"])
            .arg(&report)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
        assert_eq!(v["backend"], info.name);
        let stdout = String::from_utf8_lossy(&o.stdout);
        assert!(
            stdout.contains(info.name),
            "{} not named in: {stdout}",
            info.name
        );
        images.push((info.name, std::fs::read(&out).unwrap()));
    }
    assert!(
        images.len() >= 5,
        "{:?}",
        images.iter().map(|i| i.0).collect::<Vec<_>>()
    );
    for (name, bytes) in &images[1..] {
        assert!(
            *bytes == images[0].1,
            "{name}'s image differs from {}'s",
            images[0].0
        );
    }
}

/// CI (`.ci/run`) runs README's test command as README writes it: README
/// gives it alone in its own code block (the one running
/// `scripts/test.sh`), and that block's one line is `.ci/run`'s last.
#[test]
fn ci_runs_readmes_test_command() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let blocks: Vec<&str> = readme.split("```").skip(1).step_by(2).collect();
    let block = blocks
        .iter()
        .find(|b| b.contains("scripts/test.sh"))
        .expect("README names the test suite's command");
    let lines: Vec<&str> = block
        .lines()
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .collect();
    assert_eq!(
        lines.len(),
        1,
        "README's test command stands alone: {block}"
    );
    let ci = std::fs::read_to_string(root.join(".ci/run")).unwrap();
    let last = ci.lines().rev().find(|l| !l.trim().is_empty()).unwrap();
    assert_eq!(last, lines[0], "README's test command and .ci/run's differ");
}
