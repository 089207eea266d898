//! The `sample` and `splat` subcommands end to end, and their errors.

mod common;

use common::{bin, data, scratch};

use std::path::Path;

#[test]
fn sample_then_splat_with_report() {
    let dir = scratch("ok");
    let pts = dir.join("pts.ply");
    let out = bin()
        .args(["sample"])
        .arg(data("bunny-mesh.ply"))
        .args(["-n", "5000", "--seed", "4", "--noise", "0.0005", "-o"])
        .arg(&pts)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let cloud = splatray::io::read_points(&pts).unwrap();
    assert_eq!(cloud.len(), 5000);
    let splats = dir.join("s.ply");
    let report = dir.join("r.json");
    let out = bin()
        .arg("splat")
        .arg(&pts)
        .arg("-o")
        .arg(&splats)
        .args(["--k", "10", "--ellipses", "--report"])
        .arg(&report)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let read = splatray::io::read_splats(&splats).unwrap();
    // The splats carry the cloud's origin (the centre of its bounding box).
    assert_eq!(read.origin, cloud.origin);
    assert_ne!(read.origin, glam::DVec3::ZERO);
    let read = read.splats;
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(json["splats"].as_u64().unwrap() as usize, read.len());
    assert_eq!(json["origin"][1].as_f64(), Some(cloud.origin.y));
    assert!(read.len() < 5000);
    // (The grown-from `coverage` is 1 by construction: the held-out one is
    // checked.)
    assert!(json["coverage"].is_number());
    // The held-out coverage (10 % by default), printed and in the report,
    // measured in windows holding at most 8 % of the cloud (400 points):
    // a few dozen points tested, so it carries its 95 % interval. Not 1 by
    // construction: 5,000 points on the bunny leave some held-out points
    // off the splats grown without them (the whole cloud's regrowth,
    // `--holdout-full`: 0.9522 of 502); measured 0.9286 of 14, interval
    // 0.685-0.987, which holds it.
    let h = &json["heldout_coverage"];
    let hc = h["coverage"].as_f64().unwrap();
    let tested = h["tested"].as_u64().unwrap();
    assert!((8..60).contains(&tested), "{h}");
    assert!(
        json["heldout_windows"]["points"].as_u64().unwrap() <= 400,
        "{json}"
    );
    let (lo, hi) = (
        h["interval"][0].as_f64().unwrap(),
        h["interval"][1].as_f64().unwrap(),
    );
    assert!(lo <= hc && hc <= hi && lo <= 0.9522 && 0.9522 <= hi, "{h}");
    assert!(hi - lo > 0.1 && hc < 1.0, "{h}");
    assert!(String::from_utf8_lossy(&out.stderr).contains("95 % interval"));
    assert!(String::from_utf8_lossy(&out.stderr).contains("held-out coverage"));
    assert_eq!(json["k"].as_u64(), Some(10));
    for key in ["read", "knn", "normals", "grow", "fit", "total"] {
        // A timing, positive and below a sane ceiling (measured: 0.5 s in
        // all on 2 busy cores).
        let t = json["seconds"][key].as_f64().unwrap_or(f64::NAN);
        assert!(t > 0.0 && t < 60.0, "{key}: {t} s");
    }
}

/// Run `splat` on `input` and expect a one-line `splatray: ...` failure.
fn expect_failure(input: &Path, dir: &Path) -> String {
    let out_path = dir.join("never.ply");
    let out = bin()
        .arg("splat")
        .arg(input)
        .arg("-o")
        .arg(&out_path)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(err.starts_with("splatray: "), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(!out_path.exists(), "no output on failure");
    err
}

#[test]
fn bad_inputs_fail_with_one_line() {
    let dir = scratch("bad");
    let w = |name: &str, bytes: &[u8]| {
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    };
    let err = expect_failure(&w("empty.ply", b""), &dir);
    assert!(err.contains("empty"), "{err}");
    expect_failure(&w("x.dat", b"\x7fELF\x00\x00"), &dir);
    let full = std::fs::read(data("bunny-mesh.ply")).unwrap();
    let err = expect_failure(&w("cut.ply", &full[..200_000]), &dir);
    assert!(err.contains("truncated"), "{err}");
    let err = expect_failure(&w("line.xyz", b"0 0 0\n1 1 1\n2 2 2\n3 3 3\n"), &dir);
    assert!(err.contains("line"), "{err}");
    expect_failure(&w("nan.xyz", b"nan nan nan\n"), &dir);
    expect_failure(&dir.join("missing.pcd"), &dir);
}

#[test]
fn warnings_do_not_fail_the_run() {
    let dir = scratch("warn");
    let p = dir.join("dup.xyz");
    let mut text = String::new();
    for i in 0..30 {
        for j in 0..30 {
            text.push_str(&format!("{i} {j} {}\n", (i * j) as f32 * 0.001));
        }
    }
    text.push_str("0 0 0\nnan 1 1\n");
    std::fs::write(&p, text).unwrap();
    let out = bin()
        .arg("splat")
        .arg(&p)
        .arg("-o")
        .arg(dir.join("o.ply"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("duplicate point") && err.contains("non-finite"),
        "{err}"
    );
}

/// A report that cannot be written fails the run before any work, in one
/// line, and leaves no splat file (nor a temporary) behind.
#[test]
fn an_unwritable_report_leaves_no_output() {
    let dir = scratch("report-fails");
    let report_dir = dir.join("a-folder");
    std::fs::create_dir_all(&report_dir).unwrap();
    for report in [dir.join("missing").join("r.json"), report_dir.clone()] {
        let out_path = dir.join("out.ply");
        let out = bin()
            .arg("splat")
            .arg(data("milk.pcd"))
            .arg("-o")
            .arg(&out_path)
            .arg("--report")
            .arg(&report)
            .output()
            .unwrap();
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr).to_string();
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        assert!(err.contains("folder"), "{err}");
        let left: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .filter(|n| n != "a-folder")
            .collect();
        assert!(left.is_empty(), "left behind: {left:?}");
    }
}
