//! `compare`: the report schema, and a deliberately broken octree (§3.1
//! step 3 skipped) caught as holes.

use splatray::accel::BackendKind;
use splatray::accel::octree::{Octree, OctreeParams};
use splatray::primitive::Disc;
use splatray::render::integrator::render;
use splatray::scene::{Scene, build_scene, parse_scene_str};
use splatray::validate::compare::compare_frames;
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
shape = { kind = "quad", center = [0.0, -0.5, 0.0], size = [4.0, 4.0], splats = 900 }
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
    let o = KindFrame::new(&sc, BackendKind::Octree);
    let e = KindFrame::new(&sc, BackendKind::Embree);
    let a = compare_frames(&o.0, &e.0, sc.options.scale.diagonal);
    assert_eq!(a.hit_agreement, 1.0, "{a:?}");
    assert_eq!(a.same_splat, 1.0, "{a:?}");
    assert_eq!(a.dt_rel_max, 0.0, "{a:?}");
    assert_eq!(a.normal_deg_max, 0.0, "{a:?}");
    assert_eq!(a.image_psnr_db, None, "{a:?}");
}

struct KindFrame(splatray::render::integrator::Frame);
impl KindFrame {
    fn new(sc: &Scene, kind: BackendKind) -> KindFrame {
        let b = kind.build(&sc.splats).unwrap();
        KindFrame(render(sc, b.as_ref(), None))
    }
}

#[test]
fn broken_octree_is_caught_as_holes() {
    let sc = scene();
    let discs: Vec<Disc> = sc.splats.iter().map(|s| s.disc_geometry()).collect();
    let broken = Octree::without_overlap_insertion(&discs, &OctreeParams::default());
    let bad = render(&sc, &broken, None);
    let good = KindFrame::new(&sc, BackendKind::Embree).0;
    let a = compare_frames(&bad, &good, sc.options.scale.diagonal);
    eprintln!("broken octree vs embree: {a:?}");
    // Holes: rays the broken tree misses that Embree hits; never the reverse.
    assert!(a.only_second > 0, "{a:?}");
    assert_eq!(a.only_first, 0, "{a:?}");
    assert!(a.hit_agreement < 1.0);
    assert!(a.image_psnr_db.is_some());
}

#[test]
fn compare_report_has_the_documented_keys() {
    let dir = std::env::temp_dir().join(format!("splatray-validate-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scene = dir.join("s.toml");
    std::fs::write(&scene, SCENE).unwrap();
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
        assert!(v[k].is_number(), "{k} missing or not a number in {v}");
    }
    assert!(v.get("image_psnr_db").is_some(), "image_psnr_db missing");
    assert_eq!(v["rays"], 96 * 72);
    for b in ["octree", "embree"] {
        for k in ["build_seconds", "mrays_per_s"] {
            assert!(v[b][k].as_f64().is_some_and(|x| x >= 0.0), "{b}.{k} in {v}");
        }
    }
    let img = image::open(&diff).unwrap();
    assert_eq!((img.width(), img.height()), (3 * 96, 72));
}
