//! Hostile input, one test per class of the issue: every bad number, size
//! or count fails in one line naming the key (and the line) or the flag,
//! with a non-zero exit, no panic, within a bounded time, and leaves no
//! output behind.

mod common;

use common::scratch;
use std::io::Read;
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// The time any one run below may take: each fails (or, for the few that
/// must succeed, renders a tiny image) in well under a second (measured:
/// 0.01-0.4 s each, release build, 2 busy cores); one still running after
/// this is killed and fails its test, so "bounded time" is checked.
const RUN_LIMIT: Duration = Duration::from_secs(30);

/// Runs a command to its end, killed and failing the test when it takes
/// longer than [`RUN_LIMIT`].
trait BoundedOutput {
    fn bounded_output(&mut self) -> Output;
}

impl BoundedOutput for Command {
    fn bounded_output(&mut self) -> Output {
        let started = Instant::now();
        let mut child = self
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // Drained meanwhile so that a chatty child never blocks on a pipe.
        let mut out = child.stdout.take().unwrap();
        let mut err = child.stderr.take().unwrap();
        let out = std::thread::spawn(move || {
            let mut b = Vec::new();
            out.read_to_end(&mut b).map(|_| b)
        });
        let err = std::thread::spawn(move || {
            let mut b = Vec::new();
            err.read_to_end(&mut b).map(|_| b)
        });
        let status = loop {
            if let Some(status) = child.try_wait().unwrap() {
                break status;
            }
            if started.elapsed() > RUN_LIMIT {
                let _ = child.kill();
                let _ = child.wait();
                panic!("{self:?} still running after {RUN_LIMIT:?}: killed");
            }
            std::thread::sleep(Duration::from_millis(5));
        };
        Output {
            status,
            stdout: out.join().unwrap().unwrap(),
            stderr: err.join().unwrap().unwrap(),
        }
    }
}

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
    let o = c.args(args).bounded_output();
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
        .bounded_output();
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

/// Bad triangle input (issue 57): a `triangles` model's degenerate,
/// non-finite or out-of-range face, a non-finite normal, a mesh without
/// faces, a face placed beyond f32: one line naming the file and the
/// face, a non-zero exit, nothing written, in `render` and `compare`.
#[test]
fn bad_triangle_meshes_fail_naming_the_file_and_the_face() {
    let ply = |verts: &str, faces: &str, nf: usize| {
        format!(
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
             property float z\nelement face {nf}\nproperty list uchar int vertex_indices\n\
             end_header\n{verts}{faces}"
        )
    };
    let tri = "0 0 0\n1 0 0\n0 1 0\n";
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
    let cases: [(&str, &str, String, &[&str]); 11] = [
        ("degenerate-ply", "m.ply", ply(tri, "3 0 1 2\n3 1 1 2\n", 2), &["m.ply", "face 1 is degenerate"]),
        ("collinear-obj", "m.obj", format!("{obj}v 2 0 0\nf 1 2 3\nf 1 2 4\n"), &["m.obj", "face 1 (line 6) is degenerate"]),
        ("nan-ply", "m.ply", ply("0 0 0\n1 nan 0\n0 1 0\n", "3 0 1 2\n", 1), &["m.ply", "face 0 uses vertex 1", "non-finite"]),
        ("inf-obj", "m.obj", format!("{obj}v 1 inf 0\nf 1 2 4\n"), &["m.obj", "face 0 uses vertex 4", "non-finite"]),
        ("index-ply", "m.ply", ply(tri, "3 0 1 7\n", 1), &["m.ply", "face 0 uses vertex 7", "only 3 vertices"]),
        ("negative-ply", "m.ply", ply(tri, "3 0 -1 2\n", 1), &["m.ply", "face 0", "negative"]),
        ("index-obj", "m.obj", format!("{obj}f 1 2 3\nf 1 -5 3\n"), &["m.obj", "line 5: face 1", "out of range"]),
        ("no-faces-ply", "m.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n".to_string(), &["m.ply", "not a mesh"]),
        ("no-faces-obj", "m.obj", obj.to_string(), &["m.obj", "no triangles"]),
        ("normal-obj", "m.obj", format!("{obj}vn 0 0 nan\nf 1//1 2//1 3//1\n"), &["m.obj", "normal 1 is not finite"]),
        ("placed", "m.obj", format!("{obj}f 1 2 3\n"), &["model 2", "triangle 0", "once placed"]),
    ];
    for (name, file, text, expect) in cases {
        for cmd in ["render", "compare"] {
            let dir = scratch(&format!("hostile-tri-{name}-{cmd}"));
            std::fs::write(dir.join(file), &text).unwrap();
            let transform = if name == "placed" {
                "transform = { scale = 1e-30, translate = [1e20, 0.0, 0.0] }\n"
            } else {
                ""
            };
            std::fs::write(
                dir.join("scene.toml"),
                scene(&format!("[[model]]\ntriangles = \"{file}\"\n{transform}")),
            )
            .unwrap();
            let mut c = Command::new(env!("CARGO_BIN_EXE_splatray"));
            c.arg(cmd).arg(dir.join("scene.toml"));
            if cmd == "render" {
                c.arg("-o").arg(dir.join("out.png"));
            } else {
                c.arg("--report").arg(dir.join("out.json"));
            }
            let o = c.bounded_output();
            let r = Run {
                ok: o.status.success(),
                stderr: String::from_utf8_lossy(&o.stderr).into_owned(),
                stdout: String::from_utf8_lossy(&o.stdout).into_owned(),
                leftovers: leftovers(&dir),
            };
            fails_cleanly(&format!("{name} ({cmd})"), &r, expect);
        }
    }
}

/// A huge mesh (issue 57) is refused before anything is rendered or
/// written, its triangles counted at their own bytes
/// (`BYTES_PER_TRIANGLE`, 320: half a splat's 640). A PLY header declaring
/// 10^12 faces is refused from its header alone (320,000 GB), whatever
/// follows it. A binary PLY grid of 1,002,528 triangles (19 MB) with
/// `--max-memory 0.25` is refused from its header in one line naming the
/// file and its faces (0.3 GB), nothing written; the same grid as OBJ
/// while it is read; with `--max-memory 0.5` both render (at 640 B a
/// triangle, 0.64 GB, they were refused).
#[test]
fn a_huge_mesh_is_refused_up_front() {
    let dir = scratch("hostile-huge-mesh");
    // From its header alone: the body is not there.
    let fake = "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n\
                property float y\nproperty float z\nelement face 1000000000000\n\
                property list uchar int vertex_indices\nend_header\n";
    std::fs::write(dir.join("huge.ply"), fake).unwrap();
    let r = run(
        "huge-header",
        "render",
        &scene(&format!(
            "[[model]]\ntriangles = \"{}\"",
            dir.join("huge.ply").display()
        )),
        &[],
    );
    fails_cleanly(
        "huge-header",
        &r,
        &["huge.ply", "1000000000000 faces", "GB"],
    );
    // A grid of n x n squares, two triangles each.
    let n: u32 = 708;
    let mut ply = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\n\
         property float y\nproperty float z\nelement face {}\n\
         property list uchar int vertex_indices\nend_header\n",
        (n + 1) * (n + 1),
        2 * n * n
    )
    .into_bytes();
    for j in 0..=n {
        for i in 0..=n {
            for x in [i as f32 / n as f32 - 0.5, j as f32 / n as f32 - 0.5, 0.0] {
                ply.extend_from_slice(&x.to_le_bytes());
            }
        }
    }
    let v = |i: u32, j: u32| (j * (n + 1) + i) as i32;
    for j in 0..n {
        for i in 0..n {
            for t in [
                [v(i, j), v(i + 1, j), v(i + 1, j + 1)],
                [v(i, j), v(i + 1, j + 1), v(i, j + 1)],
            ] {
                ply.push(3);
                for k in t {
                    ply.extend_from_slice(&k.to_le_bytes());
                }
            }
        }
    }
    std::fs::write(dir.join("grid.ply"), &ply).unwrap();
    // The grid in `file` is refused under 0.25 GB, the reason `expect`
    // named, and renders whole under 0.5 GB.
    let refused_then_fits = |file: &str, expect: &str| {
        let grid = scene(&format!(
            "[[model]]\ntriangles = \"{}\"",
            dir.join(file).display()
        ));
        let name = format!("{file}-limit");
        let r = run(&name, "render", &grid, &["--max-memory", "0.25"]);
        fails_cleanly(&name, &r, &[file, expect, "the --max-memory limit"]);
        let r = run(
            &format!("{file}-fits"),
            "render",
            &grid,
            &["--max-memory", "0.5"],
        );
        assert!(r.ok, "{file} fits: {}", r.stderr);
        assert!(r.stdout.contains("1002528 triangles"), "{}", r.stdout);
    };
    // Refused by the reader from the header's count (the budget reaches
    // the reader), not by the render's budget after reading.
    refused_then_fits("grid.ply", "1002528 faces as triangles needs about 0.3 GB");
    // The same grid as OBJ text (44 MB): refused while it is read, at the
    // first count of 65,536 faces whose triangles pass 0.25 GB (786,432
    // x 320 B = 0.252 GB), before its last 216,096 faces are held.
    let mut obj = String::new();
    for j in 0..=n {
        for i in 0..=n {
            obj += &format!(
                "v {} {} 0\n",
                i as f32 / n as f32 - 0.5,
                j as f32 / n as f32 - 0.5
            );
        }
    }
    for j in 0..n {
        for i in 0..n {
            let (a, b, c, d) = (
                v(i, j) + 1,
                v(i + 1, j) + 1,
                v(i + 1, j + 1) + 1,
                v(i, j + 1) + 1,
            );
            obj += &format!("f {a} {b} {c}\nf {a} {c} {d}\n");
        }
    }
    std::fs::write(dir.join("grid.obj"), obj).unwrap();
    refused_then_fits("grid.obj", "its first 786432 faces as 786432 triangles");
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

/// Writes `bytes` to `name` in a fresh folder; returns its path.
fn file(name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let dir = scratch(&format!("hostile-file-{name}"));
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

/// The error of reading points from `bytes` saved as `name`.
fn points_error(name: &str, bytes: &[u8]) -> String {
    let e = splatray::io::read_points(&file(name, bytes))
        .unwrap_err()
        .to_string();
    assert_eq!(e.lines().count(), 1, "{e}");
    e
}

const PLY_XYZ: &str = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n";

/// Class 3: a compressed PCD body that claims more than LZF can expand to
/// fails before anything is allocated for it.
#[test]
fn decompression_bombs_fail_before_decompressing() {
    let n: u32 = 300_000_000;
    let mut bytes = format!(
        "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\nPOINTS {n}\nDATA binary_compressed\n"
    )
    .into_bytes();
    let raw = n.wrapping_mul(12);
    bytes.extend_from_slice(&1000u32.to_le_bytes());
    bytes.extend_from_slice(&raw.to_le_bytes());
    bytes.extend(std::iter::repeat_n(0u8, 1000));
    let e = points_error("bomb.pcd", &bytes);
    assert!(
        e.contains("bomb.pcd") && e.contains("more than LZF can expand to"),
        "{e}"
    );
}

/// Class 9: a header that names a property twice, or rows with more values
/// than the header declares, fail instead of being read shifted.
#[test]
fn ply_columns_are_never_read_shifted() {
    let dup = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float x\nproperty float z\nend_header\n0 0 0 0\n1 0 0 0\n0 1 0 0\n";
    let e = points_error("dup.ply", dup.as_bytes());
    assert!(
        e.contains("line 6") && e.contains("\"x\" is declared twice"),
        "{e}"
    );
    let extra = format!("{PLY_XYZ}end_header\n0 0 0\n1 0 0 9\n0 1 0\n");
    let e = points_error("extra.ply", extra.as_bytes());
    assert!(
        e.contains("line 9") && e.contains("past its properties"),
        "{e}"
    );
    let short = format!("{PLY_XYZ}end_header\n0 0 0\n1 0\n0 1 0\n");
    let e = points_error("short.ply", short.as_bytes());
    assert!(
        e.contains("line 9") && e.contains("\"z\"") && e.contains("ends early"),
        "{e}"
    );
}

/// Class 10: messages say what is wrong where it is.
#[test]
fn reader_messages_name_the_real_fault() {
    // A list-typed coordinate is not "non-finite coordinates".
    let list = "ply\nformat ascii 1.0\nelement vertex 3\nproperty list uchar float x\nproperty float y\nproperty float z\nend_header\n1 0 0 0\n1 1 0 0\n1 0 1 0\n";
    let e = points_error("list.ply", list.as_bytes());
    assert!(e.contains("\"x\" is a list"), "{e}");
    // Float face indices are not "negative vertex index".
    let faces = format!(
        "{PLY_XYZ}element face 1\nproperty list uchar float vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    );
    let e = splatray::io::read_mesh(&file("faces.ply", faces.as_bytes()))
        .unwrap_err()
        .to_string();
    assert!(e.contains("must be a list of integers"), "{e}");
    // 8-byte integer PCD fields are read, not turned into NaN.
    let mut pcd = b"VERSION 0.7\nFIELDS x y z\nSIZE 8 8 8\nTYPE U U I\nCOUNT 1 1 1\nWIDTH 3\nHEIGHT 1\nPOINTS 3\nDATA binary\n".to_vec();
    for p in [[1u64, 2, 3], [4, 5, 6], [7, 9, 8]] {
        pcd.extend_from_slice(&p[0].to_le_bytes());
        pcd.extend_from_slice(&p[1].to_le_bytes());
        pcd.extend_from_slice(&(-(p[2] as i64)).to_le_bytes());
    }
    let c = splatray::io::read_points(&file("u8.pcd", &pcd)).unwrap();
    assert_eq!(c.len(), 3);
    assert_eq!(c.world(2), glam::DVec3::new(7.0, 9.0, -8.0));
    // `nan` in an ascii PLY is a point to skip, as everywhere else.
    let nan = format!("{PLY_XYZ}end_header\n0 0 0\nnan 0 0\n0 1 0\n");
    let nan_path = file("nan.ply", nan.as_bytes());
    let c = splatray::io::read_points(&nan_path).unwrap();
    assert_eq!((c.len(), c.skipped_total()), (2, 1), "{c:?}");
    // A negative number for a flag reaches its check.
    let o = Command::new(env!("CARGO_BIN_EXE_splatray"))
        .arg("splat")
        .arg(&nan_path)
        .args(["--epsilon", "-0.1", "-o"])
        .arg(nan_path.with_file_name("out.ply"))
        .bounded_output();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("epsilon = -0.1"),
        "{err}"
    );
}

/// An ascii splat file of `rows` (21 values each), in the earlier layout
/// (linear float `red green blue`), which the reader still takes.
fn splat_file(name: &str, rows: &[&str]) -> std::path::PathBuf {
    let props = [
        "x",
        "y",
        "z",
        "nx",
        "ny",
        "nz",
        "radius",
        "ux",
        "uy",
        "uz",
        "vx",
        "vy",
        "vz",
        "radius_v",
        "field_xc",
        "field_yc",
        "field_alpha",
        "field_beta",
        "red",
        "green",
        "blue",
    ];
    let mut text = format!("ply\nformat ascii 1.0\nelement vertex {}\n", rows.len());
    for p in props {
        text += &format!("property float {p}\n");
    }
    text += "end_header\n";
    for r in rows {
        text += r;
        text += "\n";
    }
    file(name, text.as_bytes())
}

const GOOD_SPLAT: &str = "0 0 0 0 0 1 0.1 1 0 0 0 1 0 0.1 0 0 0 0 0.5 0.5 0.5";

/// Class 7 (splat files) and 11 (an empty one): every splat value is
/// checked as it is read.
#[test]
fn splat_file_values_are_checked() {
    for (name, row, expect) in [
        (
            "zero-u",
            "0 0 0 0 0 1 0.1 0 0 0 0 1 0 0.1 0 0 0 0 0.5 0.5 0.5",
            "u axis",
        ),
        (
            "u-along-n",
            "0 0 0 0 0 1 0.1 0 0 2 0 1 0 0.1 0 0 0 0 0.5 0.5 0.5",
            "u axis",
        ),
        (
            "slope",
            "0 0 0 0 0 1 0.1 1 0 0 0 1 0 0.1 0 0 1e30 0 0.5 0.5 0.5",
            "normal field",
        ),
        (
            "colour",
            "0 0 0 0 0 1 0.1 1 0 0 0 1 0 0.1 0 0 0 0 -1 0.5 0.5",
            "negative colour",
        ),
    ] {
        let e = splatray::io::read_splats(&splat_file(&format!("{name}.ply"), &[GOOD_SPLAT, row]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("splat 1") && e.contains(expect), "{name}: {e}");
    }
    // A normal of length 1e30 is a direction: normalised without overflow.
    let long = "0 0 0 0 0 1e30 0.1 1 0 0 0 1 0 0.1 0 0 0 0 0.5 0.5 0.5";
    let s = splatray::io::read_splats(&splat_file("long-normal.ply", &[long])).unwrap();
    assert_eq!(s.splats[0].normal, glam::Vec3::Z);
    // A splat at 1e38 is read (a transform may bring it in) but not
    // rendered as it is.
    let far = "1e38 0 0 0 0 1 0.1 1 0 0 0 1 0 0.1 0 0 0 0 0.5 0.5 0.5";
    let path = splat_file("far.ply", &[GOOD_SPLAT, far]);
    let o = Command::new(env!("CARGO_BIN_EXE_splatray"))
        .arg("render")
        .arg(&path)
        .arg("-o")
        .arg(path.with_file_name("out.png"))
        .bounded_output();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("span"), "{err}");
    assert!(!leftovers(path.parent().unwrap()));
    let e = splatray::io::read_splats(&splat_file("empty.ply", &[]))
        .unwrap_err()
        .to_string();
    assert!(e.contains("no splats"), "{e}");
}

/// Class 11: outputs under the wrong extension, and a PCD whose organised
/// size disagrees with its point count.
#[test]
fn loose_file_checks() {
    let cloud = file(
        "c.ply",
        format!("{PLY_XYZ}end_header\n0 0 0\n1 0 0\n0 1 0\n").as_bytes(),
    );
    let dir = cloud.parent().unwrap();
    for (cmd, args, expect) in [
        ("splat", vec!["-o", "out.png"], "must end in .ply"),
        (
            "sample",
            vec!["-n", "10", "-o", "out.png"],
            "must end in .ply or .pcd",
        ),
    ] {
        let o = Command::new(env!("CARGO_BIN_EXE_splatray"))
            .current_dir(dir)
            .arg(cmd)
            .arg(&cloud)
            .args(args)
            .bounded_output();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains(expect), "{cmd}: {err}");
        assert!(!leftovers(dir), "{cmd} left an output");
    }
    let pcd = b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 2\nPOINTS 3\nDATA ascii\n0 0 0\n1 0 0\n0 1 0\n";
    let e = points_error("wh.pcd", pcd);
    assert!(e.contains("WIDTH 2 x HEIGHT 2 is not POINTS 3"), "{e}");
}

/// Class 8: a comparison or a sweep whose report or CSV cannot be written
/// fails before any work and leaves none of its other outputs.
#[test]
fn compare_and_sweep_outputs_are_one_batch() {
    let dir = scratch("hostile-batch");
    let scene_path = dir.join("scene.toml");
    std::fs::write(&scene_path, scene("")).unwrap();
    std::fs::create_dir_all(dir.join("out-report.json")).unwrap();
    std::fs::create_dir_all(dir.join("out.csv")).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_splatray"))
        .arg("compare")
        .arg(&scene_path)
        .arg("--diff")
        .arg(dir.join("out-diff.png"))
        .arg("--report")
        .arg(dir.join("out-report.json"))
        .bounded_output();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("is a folder"), "{err}");
    assert!(!dir.join("out-diff.png").exists());
    let o = Command::new(env!("CARGO_BIN_EXE_splatray"))
        .arg("sweep")
        .arg(&scene_path)
        .arg("--csv")
        .arg(dir.join("out.csv"))
        .arg("--plot")
        .arg(dir.join("out-plot.png"))
        .bounded_output();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("is a folder"), "{err}");
    assert!(!dir.join("out-plot.png").exists() && !dir.join("out-plot.svg").exists());
}
