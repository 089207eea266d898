//! A mutation fuzzer on stable Rust over everything that reads user input:
//! the point readers (PLY, PCD, XYZ), the mesh and splat-file readers, the
//! scene parser and the scene builder (with a small render), and splat
//! generation on what the readers accept. Seeds are `tests/fuzz/corpus/`;
//! every input that ever panicked is kept in `tests/fuzz/crashes/` and
//! replayed here.
//!
//! `cargo test --release --test fuzz` runs it for `FUZZ_SECONDS` (30 by
//! default, split over the targets); a longer run:
//! `FUZZ_SECONDS=3600 cargo test --release --test fuzz -- --nocapture`.
//! A panicking input is written to `target/fuzz-crashes/` and fails the
//! run; copy it to `tests/fuzz/crashes/` once fixed.

mod common;

use splatray::io::{Format, parse_gaussians, parse_mesh, parse_points, parse_splats};
use splatray::scene::{build_scene, parse_scene_str};
use splatray::splat::{LeanMode, SplatParams, generate};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// One thing that reads input.
#[derive(Clone, Copy, Debug)]
enum Target {
    Points(Format),
    Mesh,
    Splats,
    Gaussians,
    Scene,
}

impl Target {
    fn name(self) -> &'static str {
        match self {
            Target::Points(Format::Ply) => "ply",
            Target::Points(Format::Pcd) => "pcd",
            Target::Points(Format::Xyz) => "xyz",
            Target::Points(Format::Las) => "las",
            Target::Points(Format::E57) => "e57",
            Target::Mesh => "mesh",
            Target::Splats => "splats",
            Target::Gaussians => "gaussians",
            Target::Scene => "scene",
        }
    }

    /// The target of a corpus or crash file: its folder and extension.
    fn of(path: &Path) -> Target {
        let folder = path.parent().and_then(Path::file_name).unwrap_or_default();
        let name = path.file_name().unwrap_or_default().to_string_lossy();
        let ext = path.extension().unwrap_or_default().to_string_lossy();
        match (folder.to_string_lossy().as_ref(), ext.as_ref()) {
            ("mesh", _) => Target::Mesh,
            ("splats", _) => Target::Splats,
            ("gaussians", _) => Target::Gaussians,
            ("scene", _) => Target::Scene,
            (_, "pcd") => Target::Points(Format::Pcd),
            (_, "xyz") => Target::Points(Format::Xyz),
            (_, "las" | "laz") => Target::Points(Format::Las),
            (_, "e57") => Target::Points(Format::E57),
            _ if name.starts_with("mesh-") => Target::Mesh,
            _ if name.starts_with("splats-") => Target::Splats,
            _ if name.starts_with("gaussians-") => Target::Gaussians,
            _ if name.starts_with("scene-") => Target::Scene,
            _ if name.starts_with("pcd-") => Target::Points(Format::Pcd),
            _ if name.starts_with("xyz-") => Target::Points(Format::Xyz),
            _ if name.starts_with("las-") => Target::Points(Format::Las),
            _ if name.starts_with("e57-") => Target::Points(Format::E57),
            _ => Target::Points(Format::Ply),
        }
    }

    /// Runs the target on `bytes`: an error is fine, a panic is not.
    fn run(self, bytes: &[u8]) {
        match self {
            Target::Points(f) => {
                if let Ok(cloud) = parse_points(bytes, f) {
                    // Splat generation on what a reader accepts, while small.
                    if cloud.len() <= 400 {
                        let _ = generate(&cloud, &SplatParams::default());
                        // Lean growth without its gate: whatever it is
                        // given, no panic.
                        let lean = SplatParams {
                            lean: LeanMode::Always,
                            ..SplatParams::default()
                        };
                        let _ = generate(&cloud, &lean);
                        // And with its clip lines.
                        let sharp = SplatParams {
                            lean: LeanMode::AlwaysSharp,
                            ..SplatParams::default()
                        };
                        let _ = generate(&cloud, &sharp);
                    }
                }
            }
            Target::Mesh => drop(parse_mesh(bytes)),
            Target::Splats => drop(parse_splats(bytes)),
            Target::Gaussians => drop(parse_gaussians(bytes, 0.5)),
            Target::Scene => scene(bytes),
        }
    }
}

/// Parses a scene; builds it when it is cheap (shapes only, few splats) and
/// renders a few pixels when that is cheap too.
fn scene(bytes: &[u8]) {
    let Ok(text) = std::str::from_utf8(bytes) else {
        return;
    };
    let Ok(mut file) = parse_scene_str(text) else {
        return;
    };
    let cheap = file.models.iter().all(|m| {
        m.shape.as_ref().is_some_and(|s| s.splats <= 5000)
            && m.points.is_none()
            && m.mesh.is_none()
            && m.splats.is_none()
            && m.gaussians.is_none()
    }) && file.models.len() <= 4;
    if !cheap {
        return;
    }
    file.camera.width = file.camera.width.min(8);
    file.camera.height = file.camera.height.min(6);
    file.camera.spp = file.camera.spp.min(2);
    let Ok(scene) = build_scene(&file, Path::new("."), None) else {
        return;
    };
    let e = splatray::render::budget::estimate(&scene, splatray::render::budget::Holds::ONE);
    if e.rays <= 1e5
        && let Ok(backend) = splatray::accel::registry::renderers()[0].build_splats(&scene.splats)
    {
        let _ = splatray::render::integrator::render(&scene, backend.as_ref(), None);
    }
}

/// xorshift64*.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// Values that break parsers and arithmetic.
const TOKENS: &[&str] = &[
    "nan",
    "-nan",
    "inf",
    "-inf",
    "0",
    "-0",
    "-1",
    "1e38",
    "-1e38",
    "3.5e38",
    "1e-45",
    "1e300",
    "4294967295",
    "4294967296",
    "18446744073709551615",
    "-2147483648",
    "65536",
    "1e9",
    "0.0",
    "[]",
    "[1.0]",
    "\"x\"",
    "{}",
    "true",
    "",
    " ",
    "\n",
    "0x10",
];

/// Bytes that break binary readers.
const BYTES: &[u8] = &[0, 1, 0x7f, 0x80, 0xff, b'\n', b' ', b'-', b'.', b'e'];

/// One mutation of `data` (a copy), drawing splices from `pool`.
fn mutate(data: &[u8], pool: &[Vec<u8>], rng: &mut Rng) -> Vec<u8> {
    let mut d = data.to_vec();
    for _ in 0..1 + rng.below(3) {
        let len = d.len();
        match rng.below(9) {
            // Flip a bit.
            0 if len > 0 => {
                let i = rng.below(len);
                d[i] ^= 1 << rng.below(8);
            }
            // An interesting byte, or four (a u32 or f32 field).
            1 if len > 0 => {
                let i = rng.below(len);
                d[i] = BYTES[rng.below(BYTES.len())];
            }
            2 if len >= 4 => {
                let i = rng.below(len - 3);
                let v: [u8; 4] = match rng.below(5) {
                    0 => u32::MAX.to_le_bytes(),
                    1 => f32::NAN.to_le_bytes(),
                    2 => f32::INFINITY.to_le_bytes(),
                    3 => f32::MAX.to_le_bytes(),
                    _ => 0x8000_0000u32.to_le_bytes(),
                };
                d[i..i + 4].copy_from_slice(&v);
            }
            // Replace a token (a run of non-space bytes) by a hostile one.
            3 | 4 if len > 0 => {
                let i = rng.below(len);
                let start = d[..i]
                    .iter()
                    .rposition(|b| b.is_ascii_whitespace() || matches!(b, b',' | b'[' | b'='))
                    .map_or(0, |p| p + 1);
                let end = d[i..]
                    .iter()
                    .position(|b| b.is_ascii_whitespace() || matches!(b, b',' | b']'))
                    .map_or(len, |p| i + p);
                let t = TOKENS[rng.below(TOKENS.len())].as_bytes();
                d.splice(start..end.max(start), t.iter().copied());
            }
            // Delete, duplicate or insert a chunk.
            5 if len > 0 => {
                let i = rng.below(len);
                let n = 1 + rng.below(16.min(len - i));
                d.drain(i..i + n);
            }
            6 if len > 0 => {
                let i = rng.below(len);
                let n = 1 + rng.below(64.min(len - i));
                let chunk = d[i..i + n].to_vec();
                let at = rng.below(len);
                d.splice(at..at, chunk);
            }
            // Duplicate or drop a whole line (a header key, a row).
            7 => {
                let lines: Vec<&[u8]> = d.split_inclusive(|&b| b == b'\n').collect();
                if !lines.is_empty() {
                    let k = rng.below(lines.len());
                    let mut out = Vec::with_capacity(d.len() + 64);
                    for (j, l) in lines.iter().enumerate() {
                        if j == k && rng.below(2) == 0 {
                            continue;
                        }
                        out.extend_from_slice(l);
                        if j == k {
                            out.extend_from_slice(l);
                        }
                    }
                    d = out;
                }
            }
            // Splice in part of another input.
            _ => {
                let other = &pool[rng.below(pool.len())];
                if !other.is_empty() {
                    let i = rng.below(other.len());
                    let n = 1 + rng.below(128.min(other.len() - i));
                    let at = rng.below(len + 1);
                    d.splice(at..at, other[i..i + n].iter().copied());
                }
            }
        }
    }
    d.truncate(1 << 16);
    d
}

/// A 24-point LAS (or LAZ) file with colours, in memory.
fn las_seed(compressed: bool) -> Vec<u8> {
    let mut b = las::Builder::default();
    b.point_format = las::point::Format::new(2).unwrap();
    b.point_format.is_compressed = compressed;
    let mut w =
        las::Writer::new(std::io::Cursor::new(Vec::new()), b.into_header().unwrap()).unwrap();
    for i in 0..24 {
        let t = f64::from(i) * 0.7;
        w.write_point(las::Point {
            x: t.sin(),
            y: t.cos(),
            z: t * 0.1,
            color: Some(las::Color {
                red: 1000 * i as u16,
                green: 0,
                blue: 65535,
            }),
            ..Default::default()
        })
        .unwrap();
    }
    w.into_inner().unwrap().into_inner()
}

/// A small E57 file of two scans (one with a pose, one Cartesian f32 with
/// colour, one spherical), written by the crate that reads it.
fn e57_seed() -> Vec<u8> {
    use e57::{Quaternion, Record, RecordValue, Transform, Translation};
    // The writer needs a file (it reads back what it wrote).
    let path = common::scratch("e57-seed").join("seed.e57");
    let mut w = e57::E57Writer::from_file(&path, "fuzz-seed").unwrap();
    let mut pc = w
        .add_pointcloud(
            "a",
            vec![
                Record::CARTESIAN_X_F32,
                Record::CARTESIAN_Y_F32,
                Record::CARTESIAN_Z_F32,
                Record::COLOR_RED_U8,
                Record::COLOR_GREEN_U8,
                Record::COLOR_BLUE_U8,
            ],
        )
        .unwrap();
    pc.set_transform(Some(Transform {
        rotation: Quaternion {
            w: 0.8,
            x: 0.6,
            y: 0.0,
            z: 0.0,
        },
        translation: Translation {
            x: 1.0,
            y: 2.0,
            z: 3.0,
        },
    }));
    for i in 0..16 {
        let t = i as f32 * 0.4;
        pc.add_point(vec![
            RecordValue::Single(t.sin()),
            RecordValue::Single(t.cos()),
            RecordValue::Single(t * 0.1),
            RecordValue::Integer(i * 10),
            RecordValue::Integer(0),
            RecordValue::Integer(255),
        ])
        .unwrap();
    }
    pc.finalize().unwrap();
    let mut pc = w
        .add_pointcloud(
            "b",
            vec![
                Record::SPHERICAL_AZIMUTH_F64,
                Record::SPHERICAL_ELEVATION_F64,
                Record::SPHERICAL_RANGE_F64,
            ],
        )
        .unwrap();
    for i in 0..16 {
        let t = f64::from(i) * 0.2;
        pc.add_point(vec![
            RecordValue::Double(t),
            RecordValue::Double(0.1 * t),
            RecordValue::Double(2.0 + t),
        ])
        .unwrap();
    }
    pc.finalize().unwrap();
    w.finalize().unwrap();
    drop(w);
    let bytes = std::fs::read(&path).unwrap();
    let _ = std::fs::remove_file(&path);
    bytes
}

fn files_in(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let Ok(rd) = std::fs::read_dir(dir) else {
        return out;
    };
    for e in rd.filter_map(Result::ok) {
        let p = e.path();
        if p.is_dir() {
            out.extend(files_in(&p));
        } else if p.file_name().is_some_and(|n| n != "README.md") {
            out.push(p);
        }
    }
    out.sort();
    out
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz")
}

/// Runs `target` on `bytes`; the panic message if it panicked.
fn panics(target: Target, bytes: &[u8]) -> Option<String> {
    catch_unwind(AssertUnwindSafe(|| target.run(bytes)))
        .err()
        .map(|e| {
            e.downcast_ref::<String>()
                .cloned()
                .or_else(|| e.downcast_ref::<&str>().map(|s| (*s).to_string()))
                .unwrap_or_default()
        })
}

/// Every seed and every input that ever panicked runs without a panic.
#[test]
fn corpus_and_past_crashes_replay_without_panics() {
    let files = files_in(&root());
    assert!(files.len() >= 10, "{files:?}");
    for f in files {
        let bytes = std::fs::read(&f).unwrap();
        let t = Target::of(&f);
        assert!(
            panics(t, &bytes).is_none(),
            "{} ({})",
            f.display(),
            t.name()
        );
    }
}

/// Mutated seeds never panic; the run's executions and findings are
/// printed.
#[test]
fn mutated_inputs_never_panic() {
    let seconds: f64 = std::env::var("FUZZ_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(30.0);
    let mut seeds: Vec<(Target, Vec<u8>)> = files_in(&root().join("corpus"))
        .into_iter()
        .map(|f| (Target::of(&f), std::fs::read(&f).unwrap()))
        .collect();
    // LAS and LAZ seeds, written here by the crate that reads them.
    for compressed in [false, true] {
        seeds.push((Target::Points(Format::Las), las_seed(compressed)));
    }
    seeds.push((Target::Points(Format::E57), e57_seed()));
    let pool: Vec<Vec<u8>> = seeds.iter().map(|(_, b)| b.clone()).collect();
    // Quiet: panics are collected, not printed.
    std::panic::set_hook(Box::new(|_| {}));
    // The mutation stream's seed: SPLATRAY_SEED when set (scripts/test.sh's
    // second pass sets a fresh one), printed below so a run can be replayed.
    let seed = common::env_seed().unwrap_or(0x5eed_1234_abcd_ef01);
    let mut rng = Rng(seed);
    let deadline = Instant::now() + Duration::from_secs_f64(seconds);
    let (mut execs, mut slowest) = (0u64, (Duration::ZERO, String::new()));
    let mut found: Vec<(String, PathBuf)> = Vec::new();
    let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/fuzz-crashes");
    while Instant::now() < deadline && found.len() < 20 {
        let (target, seed) = &seeds[rng.below(seeds.len())];
        let input = mutate(seed, &pool, &mut rng);
        let t0 = Instant::now();
        let p = panics(*target, &input);
        let dt = t0.elapsed();
        if dt > slowest.0 {
            slowest = (dt, target.name().to_string());
        }
        execs += 1;
        if let Some(msg) = p {
            let hash = input.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
                (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3)
            });
            std::fs::create_dir_all(&out).unwrap();
            let path = out.join(format!("{}-{hash:016x}", target.name()));
            std::fs::write(&path, &input).unwrap();
            found.push((msg, path));
        }
    }
    let _ = std::panic::take_hook();
    println!(
        "fuzz: SPLATRAY_SEED={seed:#x}: {execs} executions in {seconds} s over {} seeds, {} panics; slowest input {:.3} s ({})",
        seeds.len(),
        found.len(),
        slowest.0.as_secs_f64(),
        slowest.1
    );
    assert!(execs > 100, "only {execs} executions");
    assert!(
        found.is_empty(),
        "inputs that panicked (mutation stream SPLATRAY_SEED={seed:#x}):\n{}",
        found
            .iter()
            .map(|(m, p)| format!("{}: {m}", p.display()))
            .collect::<Vec<_>>()
            .join("\n")
    );
}
