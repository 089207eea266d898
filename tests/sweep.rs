//! `splatray sweep` end to end on a small mesh scene (the bundled bunny mesh,
//! few samples, 48×36 pixels, 5 budget steps): the CSV's columns and rows,
//! splat counts growing as epsilon shrinks, Phong normal fields beating flat
//! splats at every budget (§4.4, fig. 16), both plot files, and clean
//! one-line failures on bad input.

mod common;

use common::scratch;

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn mesh() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/data/bunny-mesh.ply")
}

/// A bunny sampled with few points plus a sphere shape (which must stay as
/// it is), one point light.
fn write_scene(dir: &Path) -> PathBuf {
    let scene = format!(
        r#"
[camera]
from = [1.5, 1.1, 4.4]
at = [0.0, -0.1, 0.0]
fov = 34

[[model]]
mesh = "{}"
samples = 6000
seed = 3

[[model]]
shape = {{ kind = "sphere", center = [1.6, -0.6, -1.0], radius = 0.35, splats = 400 }}

[[light]]
kind = "point"
position = [2.0, 4.0, 3.0]
intensity = 20.0
"#,
        mesh().display().to_string().replace('\\', "/")
    );
    let p = dir.join("scene.toml");
    std::fs::write(&p, scene).unwrap();
    p
}

fn sweep(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_splatray"))
        .arg("sweep")
        .args(args)
        .output()
        .unwrap()
}

const COLUMNS: [&str; 26] = [
    "step",
    "epsilon",
    "shading",
    "splats",
    "scene_splats",
    "triangles",
    "splat_seconds",
    "octree_build_s",
    "embree_build_s",
    "octree_render_s",
    "embree_render_s",
    "octree_mrays_per_s",
    "embree_mrays_per_s",
    "octree_memory_bytes",
    "embree_memory_bytes",
    "coverage",
    "false_hits",
    "depth_rel_p50",
    "depth_rel_p99",
    "normal_deg_mean",
    "normal_deg_p99",
    "psnr_db",
    "backends_identical",
    "embree_coverage",
    "embree_normal_deg_mean",
    "embree_psnr_db",
];

#[test]
fn sweep_measures_budget_against_error() {
    let dir = scratch("run");
    let scene = write_scene(&dir);
    let csv = dir.join("s.csv");
    let png = dir.join("s.png");
    let o = sweep(&[
        scene.to_str().unwrap(),
        "--csv",
        csv.to_str().unwrap(),
        "--plot",
        png.to_str().unwrap(),
        "--width",
        "48",
        "--height",
        "36",
        "--steps",
        "5",
    ]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "sweep failed: {}\n{stdout}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(stdout.contains("exact surface: rendered once"), "{stdout}");
    assert!(stdout.contains("summary:"), "{stdout}");

    // The CSV: every documented column, one row per (step, mode).
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(header, COLUMNS);
    type Rows<'a> = Vec<HashMap<&'a str, &'a str>>;
    let (mesh, rows): (Rows, Rows) = lines
        .map(|l| {
            let cells: Vec<&str> = l.split(',').collect();
            assert_eq!(cells.len(), header.len(), "row {l}");
            header.iter().copied().zip(cells).collect::<HashMap<_, _>>()
        })
        .partition(|r| r["shading"] == "mesh");
    let num = |r: &HashMap<&str, &str>, k: &str| -> f64 {
        r[k].parse::<f64>()
            .unwrap_or_else(|_| panic!("{k} = {}", r[k]))
    };
    let of = |mode: &str| -> Vec<&HashMap<&str, &str>> {
        rows.iter().filter(|r| r["shading"] == mode).collect()
    };
    let (flat, blended, phong) = (of("flat"), of("blended"), of("phong"));
    for m in [&flat, &blended, &phong] {
        assert_eq!(m.len(), 5, "rows per shading mode");
    }
    assert_eq!(rows.len(), 15);

    // Splats grow as epsilon shrinks; the shape's 400 splats are not varied.
    for w in flat.windows(2) {
        assert!(num(w[1], "epsilon") < num(w[0], "epsilon"));
        assert!(
            num(w[1], "splats") > num(w[0], "splats"),
            "splats must grow as epsilon shrinks: {} then {}",
            w[0]["splats"],
            w[1]["splats"]
        );
    }
    for r in &rows {
        assert_eq!(num(r, "scene_splats") - num(r, "splats"), 400.0);
        assert_eq!(r["backends_identical"], "true", "backends differ: {r:?}");
        // Measured 0.98712 at the coarsest row, 1 at most (0.987 when
        // the bound was 0.9): a margin of about 0.007.
        assert!(num(r, "coverage") > 0.98, "coverage {r:?}");
        // Timings: positive and below a sane ceiling (measured well under
        // a second each on these small inputs).
        for k in ["splat_seconds", "octree_build_s", "embree_build_s"] {
            assert!(num(r, k) > 0.0 && num(r, k) < 60.0, "{k}: {}", num(r, k));
        }
    }
    assert_mesh_row(&mesh, &stdout);
    let span = num(flat[4], "splats") / num(flat[0], "splats");
    assert!(span >= 3.0, "splat span only {span:.2}x");

    // Phong normal fields (eq. 4, blended by eq. 5) beat flat splats at every
    // budget against the exact surface's normals (§4.4, fig. 16).
    for (f, p) in flat.iter().zip(&phong) {
        assert_eq!(f["splats"], p["splats"]);
        assert!(
            num(p, "normal_deg_mean") < num(f, "normal_deg_mean"),
            "step {}: phong {} deg not below flat {} deg",
            f["step"],
            p["normal_deg_mean"],
            f["normal_deg_mean"]
        );
    }
    // Flat and blended splats are the same discs: the same coverage. Phong
    // splats are not hit beyond their fields' silhouettes: fewer false hits
    // than the discs at every budget, and a closer image (measured at this
    // size: false hits 3.9 against 5.5 % at 332 splats, PSNR 19.7 against
    // 17.5 dB; holes at the outline, coverage 0.987).
    for ((f, b), p) in flat.iter().zip(&blended).zip(&phong) {
        assert_eq!(f["coverage"], b["coverage"]);
        assert!(
            num(p, "false_hits") < num(f, "false_hits") && num(p, "psnr_db") > num(f, "psnr_db"),
            "step {}: phong false hits {} / PSNR {} against flat {} / {}",
            f["step"],
            p["false_hits"],
            p["psnr_db"],
            f["false_hits"],
            f["psnr_db"]
        );
    }

    // Both plot files, the PNG at its drawn size.
    let img = image::open(&png).unwrap();
    assert_eq!((img.width(), img.height()), (1280, 560));
    let svg = std::fs::read_to_string(dir.join("s.svg")).unwrap();
    assert!(svg.contains("<svg") && svg.contains("normal error"));
    // The mesh's point per backend, labelled, and its legend entry.
    for label in [
        "mesh octree",
        "mesh embree",
        "mesh, 69666 triangles (smooth-shaded)",
    ] {
        assert!(svg.contains(label), "{label} not in the plot");
    }
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains("partial"))
        .collect();
    assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");
}

/// Issue 57: the CSV's mesh row, the bunny mesh's 69,666 triangles
/// rendered once on every backend beside the sphere's 400 splats, shaded
/// smooth as the exact surface is: near zero error against it (measured),
/// a measured speed and memory per backend, the backends' renders
/// identical; and its log line.
fn assert_mesh_row(mesh: &[HashMap<&str, &str>], stdout: &str) {
    assert_eq!(mesh.len(), 1, "one mesh row");
    let m = &mesh[0];
    let num = |k: &str| -> f64 {
        m[k].parse::<f64>()
            .unwrap_or_else(|_| panic!("{k} = {}", m[k]))
    };
    assert_eq!((num("triangles"), num("splats")), (69666.0, 0.0));
    assert_eq!(num("scene_splats"), 400.0);
    for b in ["octree", "embree"] {
        let (build, render) = (num(&format!("{b}_build_s")), num(&format!("{b}_render_s")));
        assert!(build > 0.0 && build < 60.0, "{b} build {build}");
        assert!(render > 0.0 && render < 60.0, "{b} render {render}");
        // Rays over seconds: the render's own figure, consistent with it.
        let mrays = num(&format!("{b}_mrays_per_s"));
        assert!(mrays > 0.0 && mrays.is_finite(), "{b} {mrays} Mrays/s");
        // 69,666 triangles hold at least their 36 bytes of vertices each.
        let bytes = num(&format!("{b}_memory_bytes"));
        assert!(bytes > 69666.0 * 36.0, "{b} {bytes} bytes");
    }
    // Measured: the same surface and normals, traced by the backends'
    // triangle test where the exact surface is traced by Embree's, so only
    // a few silhouette pixels differ. Measured at 48x36 (each Embree ISA):
    // normal error 0.0276 deg, false hits 0.00058 (1 pixel of 1,728),
    // coverage 1, PSNR 60.2 dB; shaded flat it would be about 1.2 deg and
    // 35 dB.
    for k in ["normal_deg_mean", "embree_normal_deg_mean"] {
        assert!(num(k) < 0.05, "{k} {}", num(k));
    }
    assert!(
        num("false_hits") < 0.002 && num("coverage") > 0.999,
        "{m:?}"
    );
    for k in ["psnr_db", "embree_psnr_db"] {
        assert!(m[k] == "inf" || num(k) > 55.0, "{k} {}", m[k]);
    }
    assert_eq!(m["backends_identical"], "true");
    assert!(
        stdout.contains("mesh as triangles: 69666 triangles (400 splats beside them)")
            && stdout.contains("backends identical; against the exact surface's render"),
        "{stdout}"
    );
}

fn assert_clean_failure(args: &[&str], expect: &str) {
    let o = sweep(args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{args:?} should fail");
    assert_eq!(err.trim().lines().count(), 1, "one line, got:\n{err}");
    assert!(err.contains(expect), "'{expect}' not in: {err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn bad_input_fails_in_one_line() {
    let dir = scratch("bad");
    let scene = write_scene(&dir);
    let s = scene.to_str().unwrap();
    assert_clean_failure(&[s, "--steps", "3"], "--steps 3");
    assert_clean_failure(
        &[s, "--eps-coarse", "0.001", "--eps-fine", "0.01"],
        "coarse > fine",
    );
    assert_clean_failure(&[s, "--csv", "out.txt"], "must end in .csv");
    assert_clean_failure(&[s, "--plot", "/no/such/dir/p.png"], "does not exist");
    assert_clean_failure(&[s, "--width", "0"], "resolution");
    assert_clean_failure(&[dir.join("none.toml").to_str().unwrap()], "cannot read");
    // Only shapes: nothing to vary.
    let shapes = dir.join("shapes.toml");
    std::fs::write(
        &shapes,
        "[camera]\nfrom = [0.0, 0.0, 3.0]\nat = [0.0, 0.0, 0.0]\n\n[[model]]\n\
         shape = { kind = \"sphere\", radius = 1.0, splats = 50 }\n",
    )
    .unwrap();
    assert_clean_failure(&[shapes.to_str().unwrap()], "nothing to vary");
}

/// Issue 24: the normal fields had fallen behind flat splats at coarse
/// budgets (the bunny at 507 splats: Phong 10.6° against flat 9.1°) and
/// nothing noticed. A small sweep of the bundled bunny (50,000 samples,
/// 160×120, ϵ 0.05 … 0.0032, about 450 … 7,100 splats) must keep, at every
/// budget, Phong below blended below flat in mean normal error against the
/// mesh, Phong at most 0.7× flat, and fewer false hits (rays hitting
/// splats where the mesh is missed) with Phong splats than with flat ones,
/// which are not hit beyond their fields' silhouettes
/// (`resolve::resolve_models`); the holes that rule leaves at the outline
/// stay below 0.1 % of the rays. Measured: phong/flat 0.661, 0.587, 0.504,
/// 0.486, 0.494 (0.787 … 0.575 before the silhouettes; 0.79 … 0.57 with
/// discs at mid-span), Phong 5.78° and flat 8.74° at 454 splats (held at
/// 6.0° and 8.9°: the planes' placement and the silhouettes), false hits
/// Phong / flat 2.08 / 2.70 % … 0.052 / 0.156 %, Phong coverage at least
/// 0.99941.
#[test]
fn phong_beats_blended_beats_flat_at_every_budget() {
    let dir = scratch("phong-order");
    let scene =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/bunny.toml"))
            .unwrap()
            .replace(
                "\"data/bunny-mesh.ply\"",
                &format!("\"{}\"", mesh().display().to_string().replace('\\', "/")),
            )
            .replace("samples = 200000", "samples = 50000");
    assert!(scene.contains("samples = 50000"), "bunny.toml changed");
    let path = dir.join("bunny.toml");
    std::fs::write(&path, scene).unwrap();
    let csv = dir.join("s.csv");
    let o = sweep(&[
        path.to_str().unwrap(),
        "--csv",
        csv.to_str().unwrap(),
        "--width",
        "160",
        "--height",
        "120",
        "--steps",
        "5",
        "--eps-fine",
        "0.0032",
    ]);
    assert!(
        o.status.success(),
        "sweep failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |k: &str| header.iter().position(|h| *h == k).unwrap();
    let (shading, splats, err) = (col("shading"), col("splats"), col("normal_deg_mean"));
    let (coverage, false_hits) = (col("coverage"), col("false_hits"));
    // Per mode, per step: splats, normal error, coverage, false hits.
    let mut by_mode: HashMap<String, Vec<(f64, f64, f64, f64)>> = HashMap::new();
    for l in lines {
        let c: Vec<&str> = l.split(',').collect();
        let num = |k: usize| -> f64 { c[k].parse().unwrap() };
        by_mode.entry(c[shading].to_string()).or_default().push((
            num(splats),
            num(err),
            num(coverage),
            num(false_hits),
        ));
    }
    let (flat, blended, phong) = (&by_mode["flat"], &by_mode["blended"], &by_mode["phong"]);
    assert_eq!((flat.len(), blended.len(), phong.len()), (5, 5, 5));
    for ((f, b), p) in flat.iter().zip(blended).zip(phong) {
        let (n, ratio) = (f.0, p.1 / f.1);
        assert!(
            p.1 < b.1 && b.1 < f.1,
            "{n} splats: phong {:.3} deg, blended {:.3}, flat {:.3}: not in that order",
            p.1,
            b.1,
            f.1
        );
        if n < 900.0 {
            assert!(
                p.1 <= 6.0 && f.1 <= 8.9,
                "{n} splats: phong {:.3} deg above 6.0 or flat {:.3} above 8.9: \
                 the planes' placement or the fields' silhouettes regressed",
                p.1,
                f.1
            );
        }
        assert!(
            ratio <= 0.7,
            "{n} splats: phong/flat {ratio:.3} above 0.7 ({:.3} / {:.3} deg)",
            p.1,
            f.1
        );
        assert!(
            p.3 < f.3 && p.2 >= 0.999,
            "{n} splats: phong false hits {:.5} not below flat's {:.5}, or coverage {:.5} \
             below 0.999: the fields' silhouettes regressed",
            p.3,
            f.3,
            p.2
        );
    }
}
