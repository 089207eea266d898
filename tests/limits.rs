//! Memory a process may really use: under an address-space limit (as a
//! batch system or container sets, here with `prlimit --as`), work that
//! would not fit ends with a one-line error naming the limit, a non-zero
//! exit and no file, instead of an allocation abort; and sampling to PLY
//! streams, so its size is no longer bounded by memory at all.

mod common;

use common::{bin, data, scratch};
use splatray::io::{MeshSampler, read_mesh, sample_mesh, write_points, write_sample_ply};
use std::path::Path;
use std::process::{Command, Output};

/// The address-space limit of these runs: 2 GB, well above what the
/// binary maps to start (Embree, rayon's threads) and well below what the
/// work below asks.
const AS_LIMIT: &str = "2000000000";

/// `splatray ARGS` under `prlimit --as`. Without `prlimit` (util-linux,
/// which scripts/setup.sh installs) the test cannot run: it fails and says
/// so, rather than pass having checked nothing.
fn limited(args: &[&std::ffi::OsStr]) -> Output {
    let probe = Command::new("prlimit").arg("--version").output();
    assert!(
        probe.as_ref().is_ok_and(|o| o.status.success()),
        "cannot run: no working `prlimit` (util-linux; scripts/setup.sh installs it): {probe:?}"
    );
    let exe = bin().get_program().to_owned();
    Command::new("prlimit")
        .arg(format!("--as={AS_LIMIT}"))
        .arg(exe)
        .args(args)
        .output()
        .unwrap()
}

fn assert_refused(o: &Output, out: &Path) {
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{err}");
    assert_eq!(
        o.status.code(),
        Some(1),
        "an error exit, not an abort: {err}"
    );
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("address-space limit"), "{err}");
    let dir = out.parent().unwrap();
    let left: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains("out"))
        .collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}

/// A compressed PCD whose header claims 2.4 GB of points within what LZF
/// can expand to: refused before the buffer is allocated.
#[test]
fn a_pcd_claiming_more_than_the_limit_is_refused() {
    let dir = scratch("limits-pcd");
    let n: u64 = 200_000_000;
    let raw = n * 12;
    let comp = raw / 88 + 64;
    let mut bytes = format!(
        "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\nPOINTS {n}\nDATA binary_compressed\n"
    )
    .into_bytes();
    bytes.extend_from_slice(&(comp as u32).to_le_bytes());
    bytes.extend_from_slice(&(raw as u32).to_le_bytes());
    bytes.resize(bytes.len() + comp as usize, 0);
    let input = dir.join("claims.pcd");
    std::fs::write(&input, bytes).unwrap();
    let out = dir.join("out.ply");
    let o = limited(&[
        "splat".as_ref(),
        input.as_ref(),
        "-o".as_ref(),
        out.as_ref(),
    ]);
    assert_refused(&o, &out);
}

#[test]
fn a_render_larger_than_the_limit_is_refused() {
    let dir = scratch("limits-render");
    let out = dir.join("out.png");
    let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/bunny.toml");
    let args: Vec<&std::ffi::OsStr> = vec![
        "render".as_ref(),
        scene.as_ref(),
        "--width".as_ref(),
        "8192".as_ref(),
        "--height".as_ref(),
        "8192".as_ref(),
        "-o".as_ref(),
        out.as_ref(),
    ];
    let o = limited(&args);
    assert_refused(&o, &out);
}

/// A PCD sample is made in memory: 100M points are refused under the
/// limit. (A PLY sample of the same size streams and succeeds.)
#[test]
fn a_pcd_sample_larger_than_the_limit_is_refused() {
    let dir = scratch("limits-sample");
    let out = dir.join("out.pcd");
    let mesh = data("bunny-mesh.ply");
    let args: Vec<&std::ffi::OsStr> = vec![
        "sample".as_ref(),
        mesh.as_ref(),
        "-n".as_ref(),
        "100000000".as_ref(),
        "-o".as_ref(),
        out.as_ref(),
    ];
    let o = limited(&args);
    assert_refused(&o, &out);
}

/// The streamed PLY sample is byte for byte what the in-memory writer
/// makes of the same points, across more than one batch of chunks.
#[test]
fn streamed_samples_equal_the_in_memory_ones() {
    let dir = scratch("limits-stream");
    let mesh = read_mesh(&data("bunny-mesh.ply")).unwrap();
    let n = 1_100_000;
    let (a, b) = (dir.join("memory.ply"), dir.join("stream.ply"));
    write_points(&a, &sample_mesh(&mesh, n, 1e-4, 7)).unwrap();
    write_sample_ply(&b, &MeshSampler::new(&mesh, n, 1e-4, 7), None).unwrap();
    assert!(
        std::fs::read(&a).unwrap() == std::fs::read(&b).unwrap(),
        "the two files differ"
    );
}

/// `info` names the tightest memory bound, and under `prlimit --as` that
/// is the address-space limit.
#[test]
fn info_names_the_address_space_limit() {
    let o = limited(&["info".as_ref()]);
    let text = String::from_utf8_lossy(&o.stdout);
    let line = text
        .lines()
        .find(|l| l.starts_with("memory"))
        .unwrap_or_else(|| panic!("no memory line: {text}"));
    assert!(line.contains("address-space limit"), "{line}");
}
