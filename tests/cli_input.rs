//! Inputs whose name says nothing: standard input (`-`), a named pipe, a
//! shell's `<(...)`, `--format`; and a folder of point files given to
//! `render` as `splat` takes it. A pipe is read once: every run here has a
//! time limit, and a run that waits on a pipe fails the test.

mod common;

use common::{bin, scratch};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// A run that has not finished in this long is taken to hang on a pipe
/// (each finishes in well under a second on 2 cores).
const LIMIT: Duration = Duration::from_secs(60);

/// 1,500 points on a sphere of radius 2 about (10, 20, 30), as text.
fn sphere_text() -> String {
    let n = 1500;
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let mut s = String::new();
    for i in 0..n {
        let y = 1.0 - 2.0 * (f64::from(i) + 0.5) / f64::from(n);
        let r = (1.0 - y * y).sqrt();
        let a = golden * f64::from(i);
        let p = [
            10.0 + 2.0 * r * a.cos(),
            20.0 + 2.0 * y,
            30.0 + 2.0 * r * a.sin(),
        ];
        s.push_str(&format!("{:.6} {:.6} {:.6}\n", p[0], p[1], p[2]));
    }
    s
}

/// Runs `cmd` (stdin from `input` when given) to its end within [`LIMIT`];
/// panics, having killed it, when it takes longer.
fn run_limited(mut cmd: Command, input: Option<&[u8]>, what: &str) -> Output {
    cmd.stdin(if input.is_some() {
        Stdio::piped()
    } else {
        Stdio::null()
    })
    .stdout(Stdio::piped())
    .stderr(Stdio::piped());
    let mut child = cmd.spawn().unwrap();
    if let Some(bytes) = input {
        let mut stdin = child.stdin.take().unwrap();
        let bytes = bytes.to_vec();
        std::thread::spawn(move || {
            let _ = stdin.write_all(&bytes);
        });
    }
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > LIMIT {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{what}: still running after {LIMIT:?} (waiting on a pipe?)");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

fn ok(out: &Output, what: &str) {
    assert!(
        out.status.success(),
        "{what}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `splat IN -o OUT --holdout 0` plus `extra`.
fn splat(input: &Path, out: &Path, extra: &[&str]) -> Command {
    let mut c = bin();
    c.arg("splat")
        .arg(input)
        .arg("-o")
        .arg(out)
        .args(["--holdout", "0"])
        .args(extra);
    c
}

fn same(a: &Path, b: &Path, what: &str) {
    assert!(
        std::fs::read(a).unwrap() == std::fs::read(b).unwrap(),
        "{what}: {} and {} differ",
        a.display(),
        b.display()
    );
}

#[test]
fn a_piped_cloud_is_read_once() {
    let dir = scratch("input-pipes");
    let text = sphere_text();
    let file = dir.join("pts.xyz");
    std::fs::write(&file, &text).unwrap();
    let reference = dir.join("ref.ply");
    ok(
        &run_limited(splat(&file, &reference, &[]), None, "file"),
        "file",
    );

    // Standard input, with and without --format.
    for (name, extra) in [
        ("stdin-format.ply", &["--format", "xyz"][..]),
        ("stdin.ply", &[]),
    ] {
        let out = dir.join(name);
        let o = run_limited(
            splat(Path::new("-"), &out, extra),
            Some(text.as_bytes()),
            name,
        );
        ok(&o, name);
        same(&reference, &out, name);
    }

    // A file whose name says nothing, with --format.
    let dat = dir.join("pts.dat");
    std::fs::write(&dat, &text).unwrap();
    let out = dir.join("dat.ply");
    ok(
        &run_limited(splat(&dat, &out, &["--format", "xyz"]), None, "--format"),
        "--format",
    );
    same(&reference, &out, "--format xyz");

    // A named pipe called *.xyz: a writer that writes once and goes.
    let fifo = dir.join("pipe.xyz");
    let made = Command::new("mkfifo").arg(&fifo).status().unwrap();
    assert!(made.success(), "mkfifo {}", fifo.display());
    let writer = {
        let (fifo, text) = (fifo.clone(), text.clone());
        std::thread::spawn(move || {
            // Blocks until the command opens the pipe to read.
            std::fs::write(&fifo, text).unwrap();
        })
    };
    let out = dir.join("fifo.ply");
    ok(
        &run_limited(splat(&fifo, &out, &[]), None, "named pipe"),
        "named pipe",
    );
    writer.join().unwrap();
    same(&reference, &out, "named pipe");

    // The shell's process substitution, /dev/fd/N.
    let out = dir.join("subst.ply");
    let mut sh = Command::new("bash");
    sh.arg("-c")
        .arg(format!(
            "exec \"$0\" splat <(cat '{}') -o '{}' --holdout 0",
            file.display(),
            out.display()
        ))
        .arg(env!("CARGO_BIN_EXE_splatray"));
    ok(&run_limited(sh, None, "<(cat)"), "<(cat)");
    same(&reference, &out, "<(cat pts.xyz)");

    // Tiled generation reads its inputs twice: a pipe is refused in one
    // line, and nothing is written.
    let out = dir.join("tiled.ply");
    let o = run_limited(
        splat(Path::new("-"), &out, &["--tile-points", "500"]),
        Some(text.as_bytes()),
        "tiled stdin",
    );
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.starts_with("splatray: -: standard input or a pipe"),
        "{err}"
    );
    assert!(!out.exists());

    // An unknown --format name is refused by the argument parser.
    let o = run_limited(splat(&dat, &out, &["--format", "obj"]), None, "bad format");
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("expected one of ply, pcd, xyz, las, e57"));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `render DIR` reads the folder's point files as one cloud, as `splat DIR`
/// does: the image is the one of a single file holding the same points in
/// the same order.
#[test]
fn render_renders_a_folder_of_tiles() {
    let dir = scratch("input-folder");
    let text = sphere_text();
    let lines: Vec<&str> = text.lines().collect();
    let tiles = dir.join("tiles");
    std::fs::create_dir_all(&tiles).unwrap();
    let (a, b) = lines.split_at(lines.len() / 2);
    std::fs::write(tiles.join("a.xyz"), a.join("\n") + "\n").unwrap();
    std::fs::write(tiles.join("b.xyz"), b.join("\n") + "\n").unwrap();
    std::fs::write(tiles.join("notes.md"), "not a cloud\n").unwrap();
    let whole = dir.join("whole.xyz");
    std::fs::write(&whole, &text).unwrap();
    let render = |input: &PathBuf, out: &Path| {
        let mut c = bin();
        c.arg("render")
            .arg(input)
            .args(["--width", "64", "--height", "48", "-o"])
            .arg(out);
        c
    };
    let (from_dir, from_file) = (dir.join("dir.png"), dir.join("file.png"));
    ok(
        &run_limited(render(&tiles, &from_dir), None, "render DIR"),
        "render DIR",
    );
    ok(
        &run_limited(render(&whole, &from_file), None, "render file"),
        "render file",
    );
    same(&from_file, &from_dir, "render DIR");

    // A folder without point files: one line naming it.
    let empty = dir.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let o = run_limited(render(&empty, &dir.join("e.png")), None, "empty DIR");
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("no point cloud files in the folder"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}
