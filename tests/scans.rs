//! Real-scan robustness: the synthetic scanner, `scan-check`, outliers.

mod common;

use common::{Rng, data, scratch};
use glam::{DVec3, Vec3};
use splatray::io::{read_mesh, read_points, write_points};
use splatray::scanner::{RangeNoise, ScanParams, ScanPattern, scan_mesh};
use splatray::splat::{Creases, PointCloud, SplatParams, generate};
use splatray::validate::scan_check::{ScanCheckParams, ScanCheckReport, scan_check};

fn bunny_scan(pattern: ScanPattern, columns: u32, rows: u32) -> splatray::scanner::Scan {
    let mesh = read_mesh(&data("bunny-mesh.ply")).unwrap();
    scan_mesh(
        &mesh,
        &ScanParams {
            from: DVec3::new(1.5, 1.0, 3.5),
            columns,
            rows,
            pattern,
            range_noise: RangeNoise::Spacing(0.5),
            outliers: 0.01,
            missing: 0.05,
            seed: 7,
            ..ScanParams::default()
        },
    )
    .unwrap()
}

#[test]
fn scanner_counts_add_up_and_keeps_its_viewpoint_through_pcd() {
    let scan = bunny_scan(ScanPattern::Raster, 200, 150);
    assert_eq!(scan.rays, 200 * 150);
    assert_eq!(scan.returns, scan.cloud.len() + scan.missing);
    let n = scan.returns as f64;
    assert!((scan.missing as f64 / n - 0.05).abs() < 0.02, "{scan:?}");
    assert!((scan.outliers as f64 / n - 0.01).abs() < 0.01);
    assert!(scan.noise_sigma > 0.0 && (scan.noise_sigma - 0.5 * scan.spacing).abs() < 1e-6);
    let path = scratch("scan-roundtrip").join("scan.pcd");
    write_points(&path, &scan.cloud).unwrap();
    let back = read_points(&path).unwrap();
    // Read back re-centred on the cloud's medians: the viewpoint and the
    // positions are offsets from the origin, each within one f32 rounding
    // of an offset of at most a few units.
    let vp = back.origin + back.viewpoint.unwrap().as_dvec3();
    assert!(
        (vp - DVec3::new(1.5, 1.0, 3.5)).abs().max_element() < 1e-6,
        "{vp}"
    );
    assert_eq!(back.len(), scan.cloud.len());
    for i in 0..scan.cloud.len() {
        let d = (back.world(i) - scan.cloud.world(i)).abs().max_element();
        assert!(d <= f64::from(f32::EPSILON), "point {i} moved by {d}");
    }
}

fn check(cloud: &PointCloud, remove_outliers: bool) -> ScanCheckReport {
    scan_check(
        cloud,
        &ScanCheckParams {
            splat: SplatParams {
                remove_outliers,
                ..SplatParams::default()
            },
            ..ScanCheckParams::default()
        },
        None,
    )
    .unwrap()
}

#[test]
fn raster_scan_lines_of_sight_are_free_and_no_splat_is_giant() {
    let scan = bunny_scan(ScanPattern::Raster, 480, 360);
    let r = check(&scan.cloud, true);
    assert!(r.rays > 1500, "{r:?}");
    assert!(r.gross_early_fraction <= 0.002, "{r:?}");
    assert!(r.consistent_fraction >= 0.98, "{r:?}");
    assert!(r.miss_fraction <= 0.005, "{r:?}");
    assert!(r.max_over_median_radius <= 8.0, "{r:?}");
    assert!(r.held_out_outliers > 0, "{r:?}");
    assert!(r.viewpoint_is_scanner, "{:?}", r.generation.facing_away);
    assert!(!r.trim.as_ref().unwrap().skipped, "{r:?}");
    // The same check sees the phantom discs the outliers grow when they are
    // kept: it can fail.
    let kept = check(&scan.cloud, false);
    assert!(kept.gross_early_fraction > 0.05, "{kept:?}");
    assert!(kept.max_over_median_radius > 8.0, "{kept:?}");
}

/// Scan lines 4x farther apart than the samples along them, with range
/// noise of half the spacing between lines (twice the samples' spacing): a
/// neighbourhood from one line fits the plane of that line's fan of rays
/// (edge-on to the scanner), and splats grown at the seeds' noisy heights
/// overlap at scattered depths. Both are caught here: the held-out lines of
/// sight meet the splats where the scanner met the surface.
#[test]
fn scan_line_lines_of_sight_are_free() {
    let scan = bunny_scan(ScanPattern::Lines, 1600, 200);
    let r = check(&scan.cloud, true);
    assert!(r.rays > 1500, "{r:?}");
    assert!(r.gross_early_fraction <= 0.002, "{r:?}");
    assert!(r.consistent_fraction >= 0.98, "{r:?}");
    assert!(r.miss_fraction <= 0.005, "{r:?}");
    assert!(r.max_over_median_radius <= 8.0, "{r:?}");
    assert!(r.generation.moved_onto_surfaces(), "{:?}", r.generation);
}

/// The coarse scan-line case (800×100: lines 8× farther apart than the
/// samples, range noise 1.9 `ϵ`): the nearest splat stands in front of
/// the held-out points (the nearest of several overlapping planes the noise
/// scattered), the surface a render shows does not (measured with seed 7
/// here: nearest 95.13 % consistent, the resolved surface 95.79 %, 2.10 %
/// early, 1.98 % late; `sample`'s seed 1 gives 95.97 % and 96.51 %). Before
/// splats covered only the requested `k` neighbours rather than the
/// widened graph's, and before the normals were fitted again to the
/// projected points (issue 23, `docs/notes/README.md`): 88.88 % and 94.95 %.
#[test]
fn coarse_scan_lines_meet_the_rendered_surface() {
    let scan = bunny_scan(ScanPattern::Lines, 800, 100);
    let r = check(&scan.cloud, true);
    let s = &r.surface;
    eprintln!(
        "nearest splat {:.4}, rendered surface {s:?}",
        r.consistent_fraction
    );
    assert!(r.rays > 1500, "{r:?}");
    assert!(s.consistent_fraction >= 0.957, "{s:?}");
    assert!(r.consistent_fraction >= 0.95, "{r:?}");
    assert!(s.early_fraction <= 0.04 && s.late_fraction <= 0.03, "{s:?}");
    // The nearest splat is the stricter figure: it is what shadow rays meet.
    assert!(r.consistent_fraction < s.consistent_fraction, "{r:?}");
    assert!(s.window > 0.0, "{s:?}");
}

#[test]
fn scan_check_needs_a_viewpoint() {
    let mut cloud = bunny_scan(ScanPattern::Raster, 64, 48).cloud;
    cloud.viewpoint = None;
    let e = scan_check(&cloud, &ScanCheckParams::default(), None).unwrap_err();
    assert!(e.to_string().contains("viewpoint"), "{e}");
}

/// A viewpoint that is not the scanner's (a cloud scanned from all sides, a
/// default `VIEWPOINT`): half a closed sphere faces away from it, which no
/// scanner sees. Trimming against it would cut the near side for hiding the
/// far side; nothing is trimmed, and scan-check says its lines of sight
/// check nothing.
#[test]
fn a_viewpoint_seeing_backs_of_surfaces_is_not_the_scanners() {
    let cloud = PointCloud {
        positions: sphere(6000, 1.0, 5),
        viewpoint: Some(Vec3::new(6.0, 0.0, 0.0)),
        ..PointCloud::default()
    };
    let r = check(&cloud, true);
    let away = r.generation.facing_away.unwrap();
    assert!((0.3..0.6).contains(&away), "{away}");
    assert!(!r.viewpoint_is_scanner);
    let t = r.trim.as_ref().unwrap();
    assert!(t.skipped && t.shrunk == 0, "{t:?}");
    assert!(
        r.generation
            .warnings
            .iter()
            .any(|w| w.contains("face away")),
        "{:?}",
        r.generation.warnings
    );
    // The bundled lamppost: points on every side of a pole, few on the side
    // facing its default VIEWPOINT.
    let lamp = check(&read_points(&data("lamppost-ascii.pcd")).unwrap(), true);
    assert!(
        !lamp.viewpoint_is_scanner,
        "{:?}",
        lamp.generation.facing_away
    );
}

/// The bundled `milk.pcd` (a carton with rounded edges, scanned from its
/// `VIEWPOINT`) held out at seeds 1-5, creases found and whole discs: the
/// lines of sight with creases miss at most two more held-out points than
/// whole discs, and meet as many within a few. Measured (creases / whole
/// discs, rays of about 1,280 a seed): misses 0/1/4/2/3 (10) against
/// 3/1/2/1/1 (8), consistent 1272/1275/1250/1229/1250 against
/// 1271/1275/1251/1232/1251 (on - off: +1/0/-1/-3/-1). With every border's
/// line at most 0.15 spacings past the last point (no
/// `splat::rim::CLIP_GAP_SCANNED_SPACINGS`), creases missed 2/3/5/3/3
/// (16) and met 1270/1273/1253/1228/1250 (-1/-2/+2/-4/-1); before a
/// scanned small splat's border needed its band free of a bending surface
/// (`splat::rim::BORDER_RISE`), 3/5/7/6/5 (26) and 1269/1271/1250/1224/1250
/// (seed 4: 8 fewer); `docs/notes/generation.md`, issue 54, nineteenth and
/// twentieth sessions. Over seeds 1-30: misses 48 against 31, consistent
/// 37,940 against 37,961, the misses held-out points of the carton's
/// silhouette a row past a training border (sixty-seventh session).
#[test]
fn milk_lines_of_sight_with_creases_nearly_as_whole_discs() {
    let cloud = read_points(&data("milk.pcd")).unwrap();
    let run = |seed: u64, creases: Creases| {
        scan_check(
            &cloud,
            &ScanCheckParams {
                splat: SplatParams {
                    creases,
                    ..SplatParams::default()
                },
                seed,
                ..ScanCheckParams::default()
            },
            None,
        )
        .unwrap()
    };
    let mut misses = 0;
    for seed in 1..=5 {
        let (on, off) = (run(seed, Creases::Auto), run(seed, Creases::Off));
        assert!(on.generation.clipped > 0, "{seed}: {:?}", on.generation);
        assert!(
            on.consistent + 3 >= off.consistent,
            "seed {seed}: consistent {} against {}",
            on.consistent,
            off.consistent
        );
        misses += on.miss;
    }
    assert!(misses <= 10, "{misses} misses");
}

/// The real laser scan of a table scene (460,400 points, the scanner at
/// the origin; `scenes/data/README.md`), checked from its scanner at the
/// defaults (settled, then grown sharp and lean) and with whole discs (the
/// stages), seeds 1-3. Measured: consistent 44,915 / 44,721 / 45,160
/// (134,796) against whole discs' 44,812 / 44,693 / 45,144 (134,649),
/// misses 179 / 208 / 244 (631) against 265 / 197 / 233 (695), of 45,678 /
/// 45,488 / 45,995 rays; gross early 73 / 71 / 60; no large splat over a
/// hole (issue 54 counted 6 on this scan before clipped splats). Before
/// noisy seeds' planes leaning toward their sight lines were widened
/// (`splat::lean::NOISY_NEAREST`), seed 1 read 44,415 consistent and 677
/// misses, 619 of them in the band of five times the density where the
/// scanner turned, whose nearest lie in planes along their sight lines.
#[test]
fn a_real_table_scan_meets_its_scanners_lines_of_sight_as_whole_discs_do() {
    let cloud = read_points(&data("table_scene_lms400.pcd")).unwrap();
    assert_eq!(cloud.len(), 460_400);
    let run = |seed: u64, creases: Creases| {
        let params = ScanCheckParams {
            splat: SplatParams {
                creases,
                ..SplatParams::default()
            },
            seed,
            ..ScanCheckParams::default()
        };
        scan_check(&cloud, &params, None).unwrap()
    };
    let [
        mut rays,
        mut met,
        mut met_whole,
        mut missed,
        mut missed_whole,
        mut gross,
    ] = [0; 6];
    for seed in 1..=3 {
        let (on, off) = (run(seed, Creases::Auto), run(seed, Creases::Off));
        let lean = on.generation.lean.as_ref().unwrap();
        assert!(lean.used && lean.settled, "{seed}: {lean:?}");
        assert!(
            on.viewpoint_is_scanner,
            "{seed}: {:?}",
            on.generation.facing_away
        );
        let g = &on.generation;
        assert_eq!(
            (g.hollow_large_splats, g.uncovered_large_splats),
            (0, 0),
            "{seed}: {g:?}"
        );
        assert_eq!(on.rays, off.rays);
        rays += on.rays;
        (met, met_whole) = (met + on.consistent, met_whole + off.consistent);
        (missed, missed_whole) = (missed + on.miss, missed_whole + off.miss);
        gross += on.gross_early;
    }
    assert!(rays > 130_000, "{rays} rays");
    assert!(
        met >= met_whole + 100,
        "consistent {met} against whole discs' {met_whole}"
    );
    assert!(
        missed + 40 <= missed_whole,
        "{missed} misses against whole discs' {missed_whole}"
    );
    assert!(
        met as f64 >= 0.9825 * rays as f64,
        "consistent {met} of {rays}"
    );
    assert!(
        missed as f64 <= 0.005 * rays as f64,
        "{missed} misses of {rays}"
    );
    assert!(
        gross as f64 <= 0.002 * rays as f64,
        "{gross} gross early of {rays}"
    );
}

fn sphere(n: usize, r: f32, seed: u64) -> Vec<Vec3> {
    let mut rng = Rng::new(seed);
    (0..n).map(|_| rng.unit() * r).collect()
}

#[test]
fn one_far_outlier_grows_no_giant_splat() {
    let pts = sphere(20_000, 1.0, 3);
    let clean = PointCloud {
        positions: pts.clone(),
        ..PointCloud::default()
    };
    let (base, _) = generate(&clean, &SplatParams::default()).unwrap();
    let mut with = pts;
    with.push(Vec3::new(300.0, 200.0, -100.0));
    let dirty = PointCloud {
        positions: with,
        ..PointCloud::default()
    };
    let (splats, rep) = generate(&dirty, &SplatParams::default()).unwrap();
    assert!(
        rep.skipped_points
            .iter()
            .any(|s| s.reason.contains("outlier") && s.count >= 1),
        "{rep:?}"
    );
    let max = splats.iter().map(|s| s.radii.x).fold(0f32, f32::max);
    assert!(max < 0.5, "largest radius {max}");
    let ratio = splats.len() as f64 / base.len() as f64;
    assert!(
        (0.9..1.1).contains(&ratio),
        "{} vs {}",
        splats.len(),
        base.len()
    );
}

#[test]
fn cli_sample_scan_and_scan_check_write_what_they_say() {
    let dir = scratch("cli-scan");
    let pcd = dir.join("scan.pcd");
    let out = common::bin()
        .args(["sample"])
        .arg(data("bunny-mesh.ply"))
        .args(["--scan-from", "1.5,1.0,3.5", "--rays", "160,120", "-o"])
        .arg(&pcd)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report = dir.join("check.json");
    let out = common::bin()
        .arg("scan-check")
        .arg(&pcd)
        .arg("--report")
        .arg(&report)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert!(json["rays"].as_u64().unwrap() > 0);
    assert!(String::from_utf8_lossy(&out.stdout).contains("consistent"));
    // -n and --scan-from exclude each other: one line, exit 1.
    let out = common::bin()
        .args(["sample"])
        .arg(data("bunny-mesh.ply"))
        .args(["-n", "10", "--scan-from", "1,1,1", "-o"])
        .arg(dir.join("never.pcd"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(!dir.join("never.pcd").exists());
}

/// The scan settings of the station tests: 120x90 rays, range noise of
/// half a spacing, seed 7 (station k's seed 7 + k).
fn two_station_params() -> ScanParams {
    ScanParams {
        columns: 120,
        rows: 90,
        range_noise: RangeNoise::Spacing(0.5),
        seed: 7,
        ..ScanParams::default()
    }
}

/// Several stations make one cloud of several scans: each station's
/// points with its scanner (the first station's exactly `scan_mesh`'s),
/// each scan's misses kept from its own scanner; one station gives
/// `scan_mesh`'s cloud; no station is an error.
#[test]
fn stations_make_one_cloud_of_several_scans() {
    use splatray::scanner::scan_stations;
    let mesh = read_mesh(&data("bunny-mesh.ply")).unwrap();
    let params = two_station_params();
    let stations = [DVec3::new(1.5, 1.0, 3.5), DVec3::new(-2.0, 1.2, -2.5)];
    let each: Vec<_> = stations
        .iter()
        .enumerate()
        .map(|(k, &from)| {
            let p = ScanParams {
                from,
                seed: 7 + k as u64,
                ..params.clone()
            };
            scan_mesh(&mesh, &p).unwrap().cloud
        })
        .collect();
    let one = scan_stations(&mesh, &params, &stations[..1]).unwrap();
    assert_eq!(one, each[0]);
    let both = scan_stations(&mesh, &params, &stations).unwrap();
    let s = both.scans.as_ref().unwrap();
    assert_eq!(both.viewpoint, None);
    assert_eq!(both.misses, None);
    assert_eq!(both.origin, each[0].origin);
    let n0 = each[0].len();
    assert_eq!(both.len(), n0 + each[1].len());
    assert_eq!(both.positions[..n0], each[0].positions[..]);
    assert_eq!(both.positions[n0..], each[1].positions[..]);
    assert_eq!(s.of.iter().filter(|&&k| k == 0).count(), n0);
    assert!(s.of[..n0].iter().all(|&k| k == 0) && s.of[n0..].iter().all(|&k| k == 1));
    for (k, c) in each.iter().enumerate() {
        assert_eq!(Some(s.positions[k]), c.viewpoint);
        let m: Vec<Vec3> = (0..s.misses.len())
            .filter(|&i| usize::from(s.misses_of[i]) == k)
            .map(|i| s.misses[i])
            .collect();
        assert!(!m.is_empty(), "station {k} missed nothing");
        assert_eq!(Some(m), c.misses);
    }
    // Every point seen from its own station.
    let vp = both.viewpoints().unwrap();
    assert_eq!(vp.at(0), s.positions[0]);
    assert_eq!(vp.at(both.len() - 1), s.positions[1]);
    let e = scan_stations(&mesh, &params, &[]).unwrap_err().to_string();
    assert_eq!(e, "a scan needs at least one station");
    let far = [stations[0], DVec3::new(f64::NAN, 0.0, 0.0)];
    let e = scan_stations(&mesh, &params, &far).unwrap_err().to_string();
    assert!(e.starts_with("station 2 of 2 at [NaN, 0.0, 0.0]: "), "{e}");
    assert_eq!(e.lines().count(), 1, "{e}");
}

/// `sample --scan-from A --scan-from B -o scans.e57` writes the scans
/// `scan_stations` makes: read back, every point in place (f64 in the
/// file), each with its own station, each station's misses kept with it;
/// one station's E57 keeps its viewpoint and misses as its PCD keeps the
/// viewpoint. Several stations to a PCD: a one-line error, nothing written.
#[test]
fn cli_sample_from_stations_writes_an_e57_of_scans() {
    use splatray::scanner::scan_stations;
    let dir = scratch("cli-stations");
    let stations = [DVec3::new(1.5, 1.0, 3.5), DVec3::new(-2.0, 1.2, -2.5)];
    let run = |from: &[DVec3], out: &std::path::Path| {
        let mut cmd = common::bin();
        cmd.arg("sample").arg(data("bunny-mesh.ply"));
        for s in from {
            cmd.arg("--scan-from")
                .arg(format!("{},{},{}", s.x, s.y, s.z));
        }
        cmd.args([
            "--rays",
            "120,90",
            "--range-noise-spacing",
            "0.5",
            "--seed",
            "7",
            "-o",
        ])
        .arg(out)
        .output()
        .unwrap()
    };
    let mesh = read_mesh(&data("bunny-mesh.ply")).unwrap();
    let params = two_station_params();
    let close = |a: DVec3, b: DVec3| (a - b).length() < 1e-6;
    for from in [&stations[..], &stations[..1]] {
        let path = dir.join(format!("scans{}.e57", from.len()));
        let out = run(from, &path);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let made = scan_stations(&mesh, &params, from).unwrap();
        let read = read_points(&path).unwrap();
        assert_eq!(read.len(), made.len());
        assert!((0..made.len()).all(|i| close(read.world(i), made.world(i))));
        let world = |c: &PointCloud, v: Vec3| c.origin + v.as_dvec3();
        let dirs_close = |a: &[Vec3], b: &[Vec3]| {
            a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (*x - *y).length() < 1e-6)
        };
        if from.len() == 1 {
            assert!(read.scans.is_none());
            assert!(close(world(&read, read.viewpoint.unwrap()), from[0]));
            let (r, m) = (read.misses.unwrap(), made.misses.unwrap());
            assert!(!m.is_empty() && dirs_close(&r, &m));
            continue;
        }
        let (r, m) = (read.scans.as_ref().unwrap(), made.scans.as_ref().unwrap());
        assert_eq!(r.of, m.of);
        for (k, at) in from.iter().enumerate() {
            assert!(close(world(&read, r.positions[k]), *at), "station {k}");
        }
        assert_eq!(r.misses_of, m.misses_of);
        assert!(m.misses_of.contains(&1) && dirs_close(&r.misses, &m.misses));
    }
    let pcd = dir.join("never.pcd");
    let out = run(&stations, &pcd);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("write them to an E57 file"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(!pcd.exists());
}

/// Creases by default, but not along scan lines (`Creases::Auto`): the
/// coarse scan-line bunny is grown without clip lines and says so, as it
/// was before creases were the default (byte for byte: `docs/notes/creases.md`,
/// "Issue 39: creases on by default"); `Creases::On` still clips it.
#[test]
fn scan_lines_get_no_creases_unless_asked() {
    let scan = bunny_scan(ScanPattern::Lines, 800, 100);
    let run = |creases| {
        generate(
            &scan.cloud,
            &SplatParams {
                creases,
                ..SplatParams::default()
            },
        )
        .unwrap()
    };
    let (auto, report) = run(Creases::Auto);
    assert_eq!(report.clipped, 0, "{:?}", report.warnings);
    assert!(auto.iter().all(|s| !s.is_clipped()));
    assert!(
        report
            .warnings
            .iter()
            .any(|w| w.starts_with("creases not searched")),
        "{:?}",
        report.warnings
    );
    let (off, _) = run(Creases::Off);
    assert_eq!(auto.len(), off.len());
    let (_, on) = run(Creases::On);
    // Measured: 520 of 2,787 splats clipped with creases forced on.
    assert!(on.clipped > 400, "{} of {}", on.clipped, on.splats);
}
