//! `splatray render CLOUD` without a scene file: every bundled scan and a
//! synthetic one render to a picture that shows the whole cloud, the scene
//! saved with `--save-scene` renders the same image, and bad clouds fail
//! with one line.

mod common;

use common::{bin, data, scratch};
use std::path::{Path, PathBuf};
use std::process::Output;

/// Runs the binary with `args` (in `cwd` when given).
fn run(args: &[&str], cwd: Option<&Path>) -> Output {
    let mut c = bin();
    c.args(args);
    if let Some(d) = cwd {
        c.current_dir(d);
    }
    c.output().unwrap()
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The splat-id AOV written beside `image`, as ids (`-1`: no splat).
fn splat_ids(image: &Path) -> (u32, u32, Vec<f32>) {
    let aov = image.with_file_name(format!(
        "{}.splat.exr",
        image.file_stem().unwrap().to_string_lossy()
    ));
    let img = image::open(&aov).unwrap().to_rgb32f();
    let (w, h) = img.dimensions();
    (w, h, img.pixels().map(|p| p.0[0]).collect())
}

/// Fraction of pixels that hit a splat, and of the one-pixel border ring
/// that does (a cloud cut off by the frame hits the border).
fn coverage(image: &Path) -> (f64, f64) {
    let (w, h, ids) = splat_ids(image);
    let hit = ids.iter().filter(|&&v| v >= 0.0).count();
    let mut border = 0usize;
    let mut border_hit = 0usize;
    for y in 0..h {
        for x in 0..w {
            if x == 0 || y == 0 || x == w - 1 || y == h - 1 {
                border += 1;
                border_hit += usize::from(ids[(y * w + x) as usize] >= 0.0);
            }
        }
    }
    (
        hit as f64 / ids.len() as f64,
        border_hit as f64 / border as f64,
    )
}

/// Renders `cloud` at 160x120 with the splat AOV; returns stderr (the
/// camera note) after checking the run and the image.
fn render_cloud(cloud: &Path, dir: &Path, name: &str, min_cover: f64) -> String {
    let out = dir.join(format!("{name}.png"));
    let o = run(
        &[
            "render",
            s(cloud),
            "-o",
            s(&out),
            "--width",
            "160",
            "--height",
            "120",
            "--aov",
            "splat",
        ],
        None,
    );
    let err = text(&o.stderr);
    assert!(o.status.success(), "{name}: {err}");
    let img = image::open(&out).unwrap();
    assert_eq!((img.width(), img.height()), (160, 120), "{name}");
    let (cover, border) = coverage(&out);
    assert!(
        cover >= min_cover,
        "{name}: only {:.1} % of the pixels show the cloud\n{err}",
        100.0 * cover
    );
    assert!(
        border <= 0.01,
        "{name}: the cloud is cut off by the frame ({:.1} % of the border hits it)\n{err}",
        100.0 * border
    );
    assert!(err.contains("without a scene"), "{name}: {err}");
    err
}

#[test]
fn bundled_scans_render_without_a_scene() {
    let dir = scratch("cloud-bundled");
    // (file, least fraction of the image it covers, camera note expected)
    for (file, min_cover, note) in [
        ("bunny-scan.ply", 0.25, "framing the cloud"),
        ("parasaurolophus_6700.ply", 0.12, "up -y"),
        ("milk.pcd", 0.25, "at the cloud's viewpoint"),
        // A thin pole seen from its scanner: z is up.
        ("lamppost-ascii.pcd", 0.015, "up +z"),
    ] {
        let err = render_cloud(&data(file), &dir, file, min_cover);
        assert!(err.contains(note), "{file}: '{note}' not in: {err}");
    }
}

#[test]
fn synthetic_scans_render_from_their_viewpoint() {
    let dir = scratch("cloud-synthetic");
    for (pattern, rays) in [("raster", "200,150"), ("lines", "400,60")] {
        let scan = dir.join(format!("scan-{pattern}.pcd"));
        let o = run(
            &[
                "sample",
                s(&data("bunny-mesh.ply")),
                "--scan-from",
                "1.5,1.0,3.5",
                "-o",
                s(&scan),
                "--range-noise-spacing",
                "0.5",
                "--outliers",
                "0.01",
                "--missing",
                "0.05",
                "--pattern",
                pattern,
                "--rays",
                rays,
            ],
            None,
        );
        assert!(o.status.success(), "{}", text(&o.stderr));
        let err = render_cloud(&scan, &dir, pattern, 0.25);
        assert!(err.contains("at the cloud's viewpoint"), "{err}");
        assert!(err.contains("up +y"), "{err}");
    }
}

#[test]
fn a_far_cloud_renders() {
    // A georeferenced-looking sphere of points millions of units from zero.
    let dir = scratch("cloud-far");
    let far = dir.join("far.xyz");
    let mut text = String::new();
    let n = 3000;
    for i in 0..n {
        // A Fibonacci sphere of radius 2.
        let y = 1.0 - 2.0 * (f64::from(i) + 0.5) / f64::from(n);
        let r = (1.0 - y * y).sqrt();
        let a = f64::from(i) * 2.399_963_229_728_653;
        let (x, z) = (r * a.cos(), r * a.sin());
        text += &format!(
            "{:.4} {:.4} {:.4}\n",
            4_500_000.0 + 2.0 * x,
            5_300_000.0 + 2.0 * y,
            250.0 + 2.0 * z
        );
    }
    std::fs::write(&far, text).unwrap();
    render_cloud(&far, &dir, "far", 0.25);
}

#[test]
fn a_splat_file_renders_as_splats() {
    let dir = scratch("cloud-splats");
    let splats = dir.join("bunny.splats.ply");
    let o = run(
        &["splat", s(&data("bunny-scan.ply")), "-o", s(&splats)],
        None,
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    let err = render_cloud(&splats, &dir, "splats", 0.25);
    assert!(err.contains(" splats without a scene"), "{err}");
}

/// Renders `args` and returns the decoded image.
fn pixels(args: &[&str], cwd: Option<&Path>) -> Vec<u8> {
    let o = run(args, cwd);
    assert!(o.status.success(), "{args:?}: {}", text(&o.stderr));
    let out = args
        .iter()
        .position(|a| *a == "-o")
        .map(|i| PathBuf::from(args[i + 1]))
        .unwrap();
    image::open(out).unwrap().to_rgb8().into_raw()
}

#[test]
fn saved_scene_renders_the_same_image() {
    let dir = scratch("cloud-roundtrip");
    std::fs::create_dir_all(dir.join("data")).unwrap();
    std::fs::create_dir_all(dir.join("scenes")).unwrap();
    let cloud = dir.join("data/milk.pcd");
    std::fs::copy(data("milk.pcd"), &cloud).unwrap();
    let scene = dir.join("scenes/milk.toml");
    let direct = dir.join("direct.png");
    let overrides = [
        "--width",
        "120",
        "--height",
        "96",
        "--shading",
        "blended",
        "--spp",
        "2",
    ];
    let mut args = vec!["render", s(&cloud), "-o", s(&direct)];
    args.extend(overrides);
    args.extend(["--save-scene", s(&scene)]);
    let a = pixels(&args, None);
    let saved = std::fs::read_to_string(&scene).unwrap();
    // The cloud's path is relative to the scene's folder; the overrides
    // are in the file.
    assert!(saved.contains("points = \"../data/milk.pcd\""), "{saved}");
    assert!(
        saved.contains("width = 120") && saved.contains("spp = 2"),
        "{saved}"
    );
    assert!(saved.contains("shading = \"blended\""), "{saved}");
    // Rendered from another folder, with no override: the same pixels.
    let again = dir.join("again.png");
    let b = pixels(&["render", "scenes/milk.toml", "-o", s(&again)], Some(&dir));
    assert_eq!(a.len(), 120 * 96 * 3);
    assert!(a == b, "the saved scene renders a different image");
    // And not trivially: the image is not all background.
    assert!(a.chunks(3).any(|p| p != &a[..3]));
    // A cloud elsewhere (no folder in common but the root) is written
    // absolute, and renders the same too.
    let far = dir.join("far.toml");
    let c = pixels(
        &[
            "render",
            s(&data("lamppost-ascii.pcd")),
            "-o",
            s(&dir.join("l1.png")),
            "--width",
            "64",
            "--height",
            "48",
            "--save-scene",
            s(&far),
        ],
        None,
    );
    let d = pixels(&["render", s(&far), "-o", s(&dir.join("l2.png"))], None);
    assert!(c == d);
}

/// Runs a command expected to fail; returns its one-line error.
fn fails(args: &[&str], dir: &Path) -> String {
    let o = run(args, None);
    let err = text(&o.stderr);
    assert!(!o.status.success(), "{args:?} should fail");
    assert_eq!(err.trim().lines().count(), 1, "{args:?}: {err}");
    assert!(!err.contains("panicked"), "{err}");
    let left: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("out"))
        .collect();
    assert!(left.is_empty(), "{args:?} left {left:?}");
    err
}

#[test]
fn bad_clouds_fail_with_one_line() {
    let dir = scratch("cloud-bad");
    let out = dir.join("out.png");
    let nan = dir.join("nan.xyz");
    std::fs::write(&nan, "nan 0 0\n1 inf 2\n").unwrap();
    let e = fails(&["render", s(&nan), "-o", s(&out)], &dir);
    assert!(
        e.contains("nan.xyz") && e.contains("no usable point"),
        "{e}"
    );
    let two = dir.join("two.xyz");
    std::fs::write(&two, "0 0 0\n1 0 0\n").unwrap();
    let e = fails(&["render", s(&two), "-o", s(&out)], &dir);
    assert!(e.contains("two.xyz"), "{e}");
    // Recognised by content, whatever the extension.
    let junk = dir.join("cloud.dat");
    std::fs::write(
        &junk,
        "ply\nformat ascii 1.0\nelement vertex 3\nend_header\n",
    )
    .unwrap();
    let e = fails(&["render", s(&junk), "-o", s(&out)], &dir);
    assert!(e.contains("cloud.dat"), "{e}");
    let milk = data("milk.pcd");
    let e = fails(&["compare", s(&milk), "--truth"], &dir);
    assert!(e.contains("--truth") && e.contains("point cloud"), "{e}");
    let e = fails(
        &[
            "render",
            s(&milk),
            "-o",
            s(&out),
            "--save-scene",
            s(&dir.join("no/s.toml")),
        ],
        &dir,
    );
    assert!(e.contains("does not exist"), "{e}");
    // A usage error (clap's own format).
    let o = run(&["render", s(&milk), "-o", s(&out), "--up", "0,0,0"], None);
    assert!(!o.status.success());
    assert!(text(&o.stderr).contains("'0,0,0' must be a non-zero"));
    let bunny = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/bunny.toml");
    let e = fails(&["render", s(&bunny), "-o", s(&out), "--up", "z"], &dir);
    assert!(e.contains("point cloud"), "{e}");
}

#[test]
fn compare_takes_a_cloud() {
    let dir = scratch("cloud-compare");
    let report = dir.join("r.json");
    let o = run(
        &[
            "compare",
            s(&data("lamppost-ascii.pcd")),
            "--width",
            "48",
            "--height",
            "36",
            "--report",
            s(&report),
        ],
        None,
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(r["rays"], 48 * 36);
    assert!(r["splats"].as_u64().unwrap() > 100);
}

#[test]
fn given_up_axis_turns_the_camera() {
    let dir = scratch("cloud-up");
    let out = dir.join("z.png");
    let o = run(
        &[
            "render",
            s(&data("bunny-scan.ply")),
            "-o",
            s(&out),
            "--width",
            "64",
            "--height",
            "48",
            "--up",
            "-x",
            "--save-scene",
            s(&dir.join("z.toml")),
        ],
        None,
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(text(&o.stderr).contains("up -x (given)"));
    let saved = std::fs::read_to_string(dir.join("z.toml")).unwrap();
    assert!(saved.contains("up = [-1, 0, 0]"), "{saved}");
}

/// A cloud through a pipe without an extension (`render <(cat scan.pcd)`,
/// a FIFO) renders: its bytes are read once, not sniffed first (which
/// used them up and left the reader waiting for a writer, forever).
#[test]
fn a_cloud_through_a_pipe_renders() {
    let dir = scratch("cloud-pipe");
    let fifo = dir.join("scan");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    assert!(
        made.is_ok_and(|s| s.success()),
        "mkfifo {} failed",
        fifo.display()
    );
    let bytes = std::fs::read(data("lamppost-ascii.pcd")).unwrap();
    let path = fifo.clone();
    // The writer blocks until the reader opens the pipe, and ends when
    // the reader closes it (a second open would wait for it forever).
    let writer = std::thread::spawn(move || std::fs::write(&path, bytes));
    let out = dir.join("pipe.png");
    let mut child = bin()
        .args([
            "render",
            s(&fifo),
            "-o",
            s(&out),
            "--width",
            "80",
            "--height",
            "60",
        ])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let started = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if started.elapsed() > std::time::Duration::from_secs(60) {
            child.kill().ok();
            // Free the writer, should it still wait for a reader (a
            // non-blocking open for reading does not wait for a writer).
            use std::os::unix::fs::OpenOptionsExt;
            let nonblock = rustix::fs::OFlags::NONBLOCK.bits() as i32;
            drop(
                std::fs::OpenOptions::new()
                    .read(true)
                    .custom_flags(nonblock)
                    .open(&fifo),
            );
            panic!("render of a pipe still running after 60 s: it waits on the pipe");
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let o = child.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(writer.join().unwrap().is_ok());
    assert!(out.exists());
}
