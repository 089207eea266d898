//! The figures README.md and docs/results.md show for the bundled scenes,
//! held by the code: `splatray compare SCENE --truth` (README's command,
//! without `--rounds`, which only times) must give README's splat count,
//! hit agreement 1 (the backends identical: same hit, same splat, same
//! image), and its errors against the exact surfaces within a stated
//! margin of the figures the two files print. A change that moves a figure
//! beyond its margin fails here until README and docs/results.md say the
//! new figure (or the regression is found).
//!
//! Margins: the files print PSNR and the mean normal error to 0.01 and the
//! truth coverage to 1e-5; the margins are a few of those steps, enough
//! for Embree's ISAs (the exact surfaces are Embree triangles, whose floats
//! differ in the last bits) and small enough that a 0.1 dB drop fails.

mod common;

use common::{bin, scratch};

/// README's table of the bundled scenes (the one under its
/// `compare scenes/bunny.toml --truth --rounds 9` command).
const README: &str = include_str!("../README.md");
/// docs/results.md's table of the same runs (with the truth coverage and
/// the 99th percentile of the normal error).
const RESULTS: &str = include_str!("../docs/results.md");

/// PSNR against the truth, dB: README prints 0.01 dB steps.
const PSNR_MARGIN_DB: f64 = 0.03;
/// Mean normal error, degrees: README prints 0.01 degree steps.
const NORMAL_MEAN_MARGIN_DEG: f64 = 0.01;
/// 99th percentile of the normal error, degrees: results.md prints 0.1.
const NORMAL_P99_MARGIN_DEG: f64 = 0.1;
/// Truth coverage: results.md prints 1e-5 steps (a step is 5 pixels of the
/// 800 x 600 image).
const COVERAGE_MARGIN: f64 = 3e-5;

/// The cells of the table row (README or results.md) of `scene`, trimmed.
fn row<'a>(file: &'a str, which: &str, scene: &str) -> (usize, Vec<&'a str>) {
    let key = format!("| `{scene}` |");
    let (n, line) = file
        .lines()
        .enumerate()
        .find(|(_, l)| l.starts_with(&key))
        .unwrap_or_else(|| panic!("{which} has no table row for `{scene}`"));
    let cells = line.trim_matches('|').split('|').map(str::trim).collect();
    (n + 1, cells)
}

/// The leading number of a cell ("37.92 dB", "0.63°", "23,772",
/// "0.63 / 5.7" -> the first).
fn number(cell: &str) -> f64 {
    let s: String = cell
        .trim()
        .chars()
        .take_while(|c| c.is_ascii_digit() || *c == '.' || *c == ',')
        .filter(|c| *c != ',')
        .collect();
    s.parse()
        .unwrap_or_else(|_| panic!("no number at the start of '{cell}'"))
}

/// The figures the two files show for `scene`, and the measured ones.
fn check(scene: &str) {
    // README: scene | splats | hit agreement | Mrays/s | normal mean | PSNR.
    let (line, r) = row(README, "README.md", scene);
    assert_eq!(r.len(), 6, "README.md line {line}: {r:?}");
    let at = format!("README.md line {line} (`{scene}`)");
    let (splats, agreement, normal_mean, psnr) = (
        number(r[1]) as u64,
        number(r[2]),
        number(r[4]),
        number(r[5]),
    );
    // results.md: ... | truth coverage | normal mean / p99 | PSNR vs truth.
    let (rline, q) = row(RESULTS, "docs/results.md", scene);
    assert_eq!(q.len(), 9, "docs/results.md line {rline}: {q:?}");
    let rat = format!("docs/results.md line {rline} (`{scene}`)");
    let coverage = number(q[6]);
    let p99 = number(
        q[7].split('/')
            .nth(1)
            .unwrap_or_else(|| panic!("{rat}: {q:?}")),
    );
    assert_eq!(number(q[7]), normal_mean, "{at} and {rat} differ");
    assert_eq!(number(q[8]), psnr, "{at} and {rat} differ");

    let dir = scratch(&format!("readme-{scene}"));
    let report = dir.join("report.json");
    let o = bin()
        .args(["compare", &format!("scenes/{scene}"), "--truth", "--report"])
        .arg(&report)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    eprintln!("{}", String::from_utf8_lossy(&o.stdout));

    assert_eq!(
        v["splats"].as_u64(),
        Some(splats),
        "splats: {at} shows {splats}"
    );
    // The backends must be identical (README: "agree bit for bit"): every
    // one after the reference agrees on every ray, splat and pixel.
    let backends = v["backends"].as_array().unwrap();
    assert_eq!(backends.len(), common::renderers().len(), "{v}");
    assert_eq!(agreement, 1.0, "{at}");
    for b in &backends[1..] {
        let a = &b["agreement"];
        for (k, want) in [
            ("hit_agreement", 1.0),
            ("same_splat", 1.0),
            ("image_max_abs", 0.0),
        ] {
            assert_eq!(
                a[k].as_f64(),
                Some(want),
                "{}: {k} ({at} shows hit agreement 1): {a}",
                b["name"]
            );
        }
        assert_eq!(a["only_first"], 0, "{a}");
        assert_eq!(a["only_second"], 0, "{a}");
    }
    // Against the exact surfaces, every backend (identical above, so the
    // same figures).
    let truth = v["truth"]["backends"].as_array().unwrap();
    assert_eq!(truth.len(), backends.len(), "{v}");
    for t in truth {
        let name = t["name"].as_str().unwrap();
        let f = |k: &str| {
            t[k].as_f64()
                .unwrap_or_else(|| panic!("{name}: no {k} in {t}"))
        };
        eprintln!(
            "{scene} {name}: PSNR {:.3} dB ({at}: {psnr}), normal mean {:.4} deg ({normal_mean}), \
             p99 {:.3} ({rat}: {p99}), coverage {:.6} ({coverage}), false hits {:.6}",
            f("image_psnr_db"),
            f("normal_deg_mean"),
            f("normal_deg_p99"),
            f("coverage"),
            f("false_hits"),
        );
        let near = |k: &str, shown: f64, margin: f64, whose: &str| {
            let got = f(k);
            assert!(
                (got - shown).abs() <= margin,
                "{scene} {name}: {k} {got} is more than {margin} from the {shown} that {whose} shows: \
                 update README.md's table and docs/results.md (with the commands above them) or find \
                 the regression"
            );
        };
        near("image_psnr_db", psnr, PSNR_MARGIN_DB, &at);
        near("normal_deg_mean", normal_mean, NORMAL_MEAN_MARGIN_DEG, &at);
        near("normal_deg_p99", p99, NORMAL_P99_MARGIN_DEG, &rat);
        near("coverage", coverage, COVERAGE_MARGIN, &rat);
        // False hits (neither file prints them; the report does): a pixel
        // the splats hit where the exact surface is missed. Measured 56 of
        // 480,000 pixels on the bunny (0.000117), 47 on the glass
        // (0.000098; both grown by lean growth, whose rims reach a tenth
        // past their points: the stages' 64 and 34); held within 1.5
        // times those, a handful of pixels.
        let false_hits_max = match scene {
            "bunny.toml" => 1.5 * 56.0 / 480_000.0,
            "glass.toml" => 1.5 * 47.0 / 480_000.0,
            _ => unreachable!(),
        };
        assert!(
            f("false_hits") <= false_hits_max,
            "{scene} {name}: false hits {} above {false_hits_max}",
            f("false_hits")
        );
    }
}

#[test]
fn the_bunny_gives_the_figures_readme_shows() {
    check("bunny.toml");
}

#[test]
fn the_glass_gives_the_figures_readme_shows() {
    check("glass.toml");
}
