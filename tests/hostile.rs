//! Hostile input, one test per class of the issue: every bad number, size
//! or count fails in one line naming the key (and the line) or the flag,
//! with a non-zero exit, no panic, within a bounded time, and leaves no
//! output behind.

mod common;

use common::scratch;
use std::path::Path;
use std::process::Command;

/// What a run did.
struct Run {
    ok: bool,
    stderr: String,
    stdout: String,
    /// Whether any file named `out.*` is in the folder.
    leftovers: bool,
}

/// Runs `splatray CMD scene.toml -o out.png ARGS` on `scene` in a fresh folder.
fn run(name: &str, cmd: &str, scene: &str, args: &[&str]) -> Run {
    let dir = scratch(&format!("hostile-{name}"));
    let scene_path = dir.join("scene.toml");
    std::fs::write(&scene_path, scene).unwrap();
    let mut c = Command::new(env!("CARGO_BIN_EXE_splatray"));
    c.arg(cmd).arg(&scene_path);
    if cmd == "render" {
        c.arg("-o").arg(dir.join("out.png"));
    }
    let o = c.args(args).output().unwrap();
    Run {
        ok: o.status.success(),
        stderr: String::from_utf8_lossy(&o.stderr).into_owned(),
        stdout: String::from_utf8_lossy(&o.stdout).into_owned(),
        leftovers: leftovers(&dir),
    }
}

fn leftovers(dir: &Path) -> bool {
    std::fs::read_dir(dir)
        .unwrap()
        .filter_map(Result::ok)
        .any(|e| e.file_name().to_string_lossy().starts_with("out"))
}

/// The run failed in one line holding every `expect`, with nothing left.
fn fails_cleanly(name: &str, r: &Run, expect: &[&str]) {
    assert!(!r.ok, "{name}: should fail; stdout {}", r.stdout);
    assert_eq!(
        r.stderr.trim().lines().count(),
        1,
        "{name}: one line, got:\n{}",
        r.stderr
    );
    for e in expect {
        assert!(r.stderr.contains(e), "{name}: '{e}' not in: {}", r.stderr);
    }
    assert!(!r.stderr.contains("panicked"), "{name}: {}", r.stderr);
    assert!(!r.leftovers, "{name}: an output was left behind");
}

const CAMERA: &str =
    "[camera]\nfrom = [0.0, 0.5, 3.0]\nat = [0.0, 0.0, 0.0]\nwidth = 32\nheight = 24\n";
const SPHERE: &str = "[[model]]\nshape = { kind = \"sphere\", radius = 0.5, splats = 200 }\n";

fn scene(extra: &str) -> String {
    format!("{CAMERA}{SPHERE}{extra}\n")
}

/// Two facing mirrors, the camera between them looking at one: every ray
/// bounces to `max_depth`.
fn facing_mirrors(depth: &str) -> String {
    let mirror = |z: f32, nz: f32| {
        format!(
            "[[model]]\nmaterial = {{ kind = \"mirror\", reflectance = 1.0 }}\n\
             shape = {{ kind = \"quad\", size = [200.0, 200.0], splats = 400, normal = [0.0, 0.0, {nz}], center = [0.0, 0.0, {z}] }}\n"
        )
    };
    format!(
        "[camera]\nfrom = [0.0, 0.0, 0.5]\nat = [0.0, 0.0, -1.0]\nwidth = 8\nheight = 6\nfov = 5.0\n{}{}\
         [[light]]\nkind = \"point\"\nposition = [0.0, 0.0, 0.0]\n[render]\nmax_depth = {depth}\n",
        mirror(-1.0, 1.0),
        mirror(1.0, -1.0)
    )
}

/// Class 1: recursion depth cannot overflow a render thread's stack.
#[test]
fn recursion_depth_is_capped_below_a_stack_overflow() {
    for cmd in ["render", "compare"] {
        let r = run("depth", cmd, &facing_mirrors("100000"), &[]);
        fails_cleanly("depth", &r, &["line 17", "`max_depth`", "1..=64", "100000"]);
    }
    // The deepest allowed: every level used, no overflow.
    let dir = scratch("hostile-depth-ok");
    std::fs::write(dir.join("m.toml"), facing_mirrors("64")).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_splatray"))
        .arg("render")
        .arg(dir.join("m.toml"))
        .arg("-o")
        .arg(dir.join("m.png"))
        .arg("--report")
        .arg(dir.join("m.json"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("m.json")).unwrap()).unwrap();
    assert_eq!(report["rays"]["reflection"], 8 * 6 * 63, "{report}");
}

/// Class 2: procedural shapes whose size or count would panic or exhaust
/// memory.
#[test]
fn extreme_shapes_fail_in_one_line() {
    for (name, shape, expect) in [
        (
            "thin-quad",
            "kind = \"quad\", size = [1e30, 1e-30], splats = 100",
            &["span", "1e18"][..],
        ),
        (
            "huge-sphere",
            "kind = \"sphere\", radius = 1e38, splats = 100",
            &["span"][..],
        ),
        (
            "count",
            "kind = \"quad\", size = [1.0, 1.0], splats = 1000000000000",
            &["line 7", "`splats`", "50000000"][..],
        ),
        (
            "count-u64",
            "kind = \"quad\", size = [1.0, 1.0], splats = 18446744073709551615",
            &["line 7"][..],
        ),
        (
            "zero-normal",
            "kind = \"quad\", size = [1.0, 1.0], splats = 10, normal = [0.0, 0.0, 0.0]",
            &["shape.normal"][..],
        ),
    ] {
        let r = run(
            name,
            "render",
            &format!("{CAMERA}[[model]]\nshape = {{ {shape} }}\n"),
            &[],
        );
        fails_cleanly(name, &r, expect);
    }
    // A quad a billion times longer than wide still makes about the splats
    // asked for, quickly.
    let r = run(
        "long-quad",
        "render",
        &scene("[[model]]\nshape = { kind = \"quad\", size = [1e9, 1e-9], splats = 100 }"),
        &[],
    );
    assert!(r.ok, "{}", r.stderr);
}

/// Class 4: the image's memory is bounded by what the machine has (or by
/// --max-memory), not by a per-side limit alone.
#[test]
fn image_memory_is_checked_before_rendering() {
    let r = run(
        "pixels",
        "render",
        &scene(""),
        &["--width", "32768", "--height", "32768"],
    );
    fails_cleanly("pixels", &r, &["GB", "32768x32768", "--max-memory"]);
    let r = run(
        "pixels-limit",
        "render",
        &scene(""),
        &["--width", "4096", "--height", "4096", "--max-memory", "0.5"],
    );
    fails_cleanly(
        "pixels-limit",
        &r,
        &["1.3 GB", "--max-memory limit (0.5 GB)"],
    );
    let r = run(
        "max-memory-nan",
        "render",
        &scene(""),
        &["--max-memory", "nan"],
    );
    assert!(
        !r.ok && r.stderr.contains("finite number above 0"),
        "{}",
        r.stderr
    );
}

/// Class 5: work that would hang (samples, glass depth) is refused with its
/// worst-case cost; --max-rays raises the limit.
#[test]
fn hanging_work_is_refused_with_its_cost() {
    let light = "[[light]]\nkind = \"sphere\"\nposition = [1.0, 2.0, 3.0]\nradius = 0.1\n";
    for (name, extra, expect) in [
        (
            "samples",
            format!("{light}samples = 1000000"),
            &["line 12", "`samples`", "1..=4096"][..],
        ),
        (
            "samples-u32",
            format!("{light}samples = 4294967295"),
            &["`samples`"][..],
        ),
        (
            "samples-zero",
            format!("{light}samples = 0"),
            &["`samples`", "got 0"][..],
        ),
        (
            "glass-depth",
            "material = { kind = \"glass\" }\n[render]\nmax_depth = 30".to_string(),
            &["rays", "1073741823 paths", "glass", "--max-rays"][..],
        ),
    ] {
        let r = run(name, "render", &scene(&extra), &[]);
        fails_cleanly(name, &r, expect);
    }
    let deep = scene("material = { kind = \"glass\" }\n[render]\nmax_depth = 16");
    let r = run("glass-limit", "render", &deep, &["--max-rays", "1e6"]);
    fails_cleanly("glass-limit", &r, &["up to 5.03e7 rays", "limit of 1e6"]);
    let r = run("glass-ok", "render", &deep, &[]);
    assert!(r.ok, "{}", r.stderr);
}

/// Class 7: non-finite or out-of-range numbers in a scene fail where they
/// enter, naming the key and the line.
#[test]
fn unchecked_numbers_fail_naming_key_and_line() {
    for (extra, key) in [
        (
            "material = { kind = \"phong\", shininess = nan }",
            "`shininess`",
        ),
        (
            "material = { kind = \"phong\", shininess = -2.0 }",
            "`shininess`",
        ),
        (
            "material = { kind = \"phong\", specular = inf }",
            "`specular`",
        ),
        (
            "material = { kind = \"mirror\", reflectance = nan }",
            "`reflectance`",
        ),
        ("material = { kind = \"glass\", ior = -1.5 }", "`ior`"),
        ("transform = { rotate = [nan, 0.0, 0.0] }", "`rotate`"),
        ("transform = { rotate = [0.0, inf, 0.0] }", "`rotate`"),
        ("transform = { translate = [nan, 0.0, 0.0] }", "`translate`"),
        ("transform = { scale = 0.0 }", "`scale`"),
        ("splat = { viewpoint = [nan, 0.0, 0.0] }", "`viewpoint`"),
        ("[render]\nambient = nan", "`ambient`"),
        ("[render]\nxi = -1.0", "`xi`"),
    ] {
        let r = run("numbers", "render", &scene(extra), &[]);
        fails_cleanly(extra, &r, &[key, "line "]);
    }
    let fov = CAMERA.replace("height = 24", "height = 24\nfov = 1e-30");
    let r = run("fov", "render", &format!("{fov}{SPHERE}"), &[]);
    fails_cleanly("fov", &r, &["line 6", "`fov`", "1e-30"]);
}

/// Class 10: a model placed beyond what f32 holds is named as such, not as
/// a camera whose `from` and `at` coincide.
#[test]
fn far_or_huge_models_are_named_not_blamed_on_the_camera() {
    for (name, extra, expect) in [
        (
            "translate",
            "[[model]]\nshape = { kind = \"sphere\", radius = 1.0, splats = 100 }\ntransform = { translate = [1e300, 0.0, 0.0] }",
            &["model 2", "not finite once placed"][..],
        ),
        (
            "scale",
            "[[model]]\nshape = { kind = \"sphere\", radius = 1.0, splats = 100 }\ntransform = { scale = 1e38 }",
            &["span"][..],
        ),
        (
            "far",
            "[[model]]\nshape = { kind = \"sphere\", radius = 1.0, splats = 100 }\ntransform = { translate = [1e30, 0.0, 0.0] }",
            &["span"][..],
        ),
    ] {
        let r = run(name, "render", &scene(extra), &[]);
        fails_cleanly(name, &r, expect);
        assert!(!r.stderr.contains("coincide"), "{}", r.stderr);
    }
}

/// Class 11: negative radiance, a light without samples, a NaN normal.
#[test]
fn loose_numbers_are_checked() {
    for (extra, key) in [
        (
            "[[light]]\nkind = \"point\"\nposition = [1.0, 1.0, 1.0]\nintensity = -1.0",
            "`intensity`",
        ),
        (
            "[[light]]\nkind = \"point\"\nposition = [1.0, 1.0, 1.0]\ncolor = [1.0, -1.0, 1.0]",
            "`color`",
        ),
        ("material = { color = [-0.5, 0.5, 0.5] }", "`color`"),
        ("[render]\nambient = -0.1", "`ambient`"),
        (
            "[[model]]\nshape = { kind = \"quad\", size = [1.0, 1.0], splats = 10, normal = [nan, 0.0, 1.0] }",
            "`normal`",
        ),
    ] {
        let r = run("loose", "render", &scene(extra), &[]);
        fails_cleanly(extra, &r, &[key, "line "]);
    }
    let bg = format!("{CAMERA}background = [-1.0, 0.0, 0.0]\n{SPHERE}");
    let r = run("background", "render", &bg, &[]);
    fails_cleanly("background", &r, &["`background`", "line 6"]);
}
