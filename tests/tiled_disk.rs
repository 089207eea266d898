//! A disk that fills during a tiled run: while the tiles are spilled, and
//! while the output is written. The run stops with one line naming the
//! file it could not write, as an I/O error (not bad data of the input),
//! leaves nothing half-written, and `--resume` then finishes with the bytes
//! of a run that was never interrupted.
//!
//! The full disk is a file-size limit (`prlimit --fsize`, util-linux, which
//! `scripts/setup.sh` installs): a write past it fails with EFBIG, as one
//! past a full disk fails with ENOSPC (the binary catches SIGXFSZ, so the
//! write returns the error rather than the signal killing the process).
//! A third test fills a real disk: a small tmpfs in a user namespace
//! (`unshare`). Without `prlimit` or `unshare` (or user namespaces) these
//! tests fail; they do not skip.

mod common;

use common::{bin, data, scratch};
use splatray::io::{read_mesh, sample_mesh, write_points};
use std::path::{Path, PathBuf};
use std::process::Output;

/// 60,000 bunny points without normals (the tiles orient their own, so
/// halo files are written too), as a binary PLY.
fn cloud(dir: &Path) -> PathBuf {
    let mesh = read_mesh(&data("bunny-mesh.ply")).unwrap();
    let mut c = sample_mesh(&mesh, 60_000, 2e-4, 5);
    c.normals = None;
    let p = dir.join("points.ply");
    write_points(&p, &c).unwrap();
    p
}

/// `splatray splat INPUT -o OUT --tile-points 15000 EXTRA` (8 tiles),
/// under a file-size limit of `fsize` bytes when given.
fn run(input: &Path, out: &Path, fsize: Option<u64>, extra: &[&str]) -> Output {
    let mut cmd = match fsize {
        Some(n) => {
            let mut c = std::process::Command::new("prlimit");
            c.arg(format!("--fsize={n}"))
                .arg("--")
                .arg(env!("CARGO_BIN_EXE_splatray"));
            c
        }
        None => bin(),
    };
    cmd.arg("splat")
        .arg(input)
        .arg("-o")
        .arg(out)
        .args(["--tile-points", "15000"])
        .args(extra)
        .output()
        .unwrap_or_else(|e| {
            panic!("cannot run the tiled splat (prlimit from util-linux, which scripts/setup.sh installs, must be on PATH): {e}")
        })
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The stderr of a run that must have failed in one line.
fn failed_in_one_line(o: &Output, why: &str) -> String {
    let err = stderr(o);
    assert!(!o.status.success(), "{why}: {err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    err
}

/// Every file under `dir`, recursively.
fn files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(files(&p));
        } else {
            out.push(p);
        }
    }
    out
}

fn names_with(dir: &Path, part: &str) -> Vec<String> {
    files(dir)
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .filter(|n| n.contains(part))
        .collect()
}

/// The splats of a run never interrupted.
fn reference(dir: &Path, input: &Path) -> Vec<u8> {
    let out = dir.join("reference.ply");
    let o = run(input, &out, None, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    std::fs::read(&out).unwrap()
}

/// The disk fills while spilling (a limit of 100,000 bytes: the spill
/// files hold 117,024 to 126,084 bytes each, measured with `--plan-only`
/// on this cloud): the error names a spill file, every spill file is removed,
/// and `--resume` reuses the plan, spills again and finishes. A resume
/// after the input changed is refused in one line.
#[test]
fn a_full_disk_while_spilling_names_the_spill_file_and_resumes() {
    let dir = scratch("tiled-disk-spill");
    let input = cloud(&dir);
    let whole = reference(&dir, &input);
    let out = dir.join("out.ply");
    let work = dir.join(".out.ply.tiles");
    let o = run(&input, &out, Some(100_000), &[]);
    let err = failed_in_one_line(&o, "the limit did not stop the run");
    assert!(
        err.contains(&*work.to_string_lossy())
            && err.contains("spill-")
            && err.contains(".bin: writing tile")
            && err.contains("File too large"),
        "{err}"
    );
    assert!(!err.contains("bad data"), "{err}");
    assert!(!out.exists(), "an output after a failed spill");
    assert!(names_with(&dir, "spill-").is_empty(), "{:?}", files(&dir));
    assert!(names_with(&dir, ".partial").is_empty(), "{:?}", files(&dir));
    assert!(
        work.join("plan.json").exists(),
        "the plan is kept to resume"
    );

    // The input changed since the plan: refused in one line, nothing done.
    let stamp = std::fs::metadata(&input).unwrap().modified().unwrap();
    let touch = |t: std::time::SystemTime| {
        std::fs::File::options()
            .write(true)
            .open(&input)
            .unwrap()
            .set_modified(t)
            .unwrap();
    };
    touch(stamp + std::time::Duration::from_secs(60));
    let o = run(&input, &out, None, &["--resume"]);
    let err = failed_in_one_line(&o, "refused");
    assert!(
        err.contains("cannot resume") && err.contains("changed since the plan"),
        "{err}"
    );
    assert!(!out.exists());
    touch(stamp);

    let o = run(&input, &out, None, &["--resume"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        std::fs::read(&out).unwrap() == whole,
        "resumed bytes differ"
    );
    assert!(!work.exists(), "the work folder stays after the merge");
    // Nothing left to resume.
    let o = run(&input, &dir.join("other.ply"), None, &["--resume"]);
    let err = stderr(&o);
    assert!(
        !o.status.success() && err.contains("nothing to resume"),
        "{err}"
    );
}

/// The disk fills while the output is written (a limit of 400,000 bytes:
/// the largest file in the work folder is a spill file of 126,084 bytes,
/// then a tile's splat file of 112,019; the output is 792,881 bytes,
/// measured): the error names
/// the output, no temporary is left, the finished tiles stay, and
/// `--resume` merges them without generating any again.
#[test]
fn a_full_disk_while_writing_the_output_names_it_and_resumes() {
    let dir = scratch("tiled-disk-output");
    let input = cloud(&dir);
    let whole = reference(&dir, &input);
    let out = dir.join("out.ply");
    let work = dir.join(".out.ply.tiles");
    let o = run(&input, &out, Some(400_000), &[]);
    let err = failed_in_one_line(&o, "the limit did not stop the run");
    assert!(
        err.contains(&format!("{}: File too large", out.display())),
        "{err}"
    );
    assert!(!out.exists(), "a half-written output");
    assert!(names_with(&dir, ".partial").is_empty(), "{:?}", files(&dir));
    let tiles = names_with(&work, "tile-")
        .iter()
        .filter(|n| n.ends_with(".ply"))
        .count();
    assert_eq!(tiles, 8, "{:?}", files(&work));

    // Other options than the plan's: refused in one line.
    let o = run(&input, &out, None, &["--resume", "--epsilon", "0.02"]);
    let err = failed_in_one_line(&o, "refused");
    assert!(
        err.contains("cannot resume: the splat options differ"),
        "{err}"
    );

    let o = run(&input, &out, None, &["--resume"]);
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("8 resumed"), "{err}");
    assert!(
        std::fs::read(&out).unwrap() == whole,
        "resumed bytes differ"
    );
}

/// A real full disk: a tmpfs of 1.8 MB, mounted in a user and mount
/// namespace of its own (`unshare -rm`, util-linux; no root needed where
/// the kernel allows user namespaces, as Debian's does), holding the
/// output and so the work folder. The spill (80,691 points of 12 bytes,
/// 968.3 kB foreseen, measured) fits, and so do the tiles; the output
/// (1,034,294 bytes with the clip lines of the default creases, measured;
/// 792,881 without; 1.7 and 1.9 MB pass too) does not fit beside the
/// finished tiles: "No space left on device" on
/// the output, nothing half-written. The tmpfs is then grown to 4 MB (space
/// freed) and `--resume` finishes with the bytes of an uninterrupted run.
/// A tmpfs of 200 kB is refused before anything is written, in a sane
/// figure. All of it runs in one shell in the namespace, whose tmpfs ends
/// with it; what the test checks is copied out.
#[test]
fn a_full_tmpfs_names_the_output_and_resumes_once_space_is_freed() {
    let dir = scratch("tiled-disk-tmpfs");
    let input = cloud(&dir);
    let whole = reference(&dir, &input);
    let mnt = dir.join("mnt");
    std::fs::create_dir_all(&mnt).unwrap();
    let script = r#"
        set -u
        bin="$1"; input="$2"; mnt="$3"; dir="$4"
        splat() { "$bin" splat "$input" -o "$mnt/out.ply" --tile-points 15000 "$@"; }
        mount -t tmpfs -o size=200k tmpfs "$mnt" || exit 90
        splat 2> "$dir/small.err"; echo $? > "$dir/small.rc"
        ls -A "$mnt" > "$dir/small.ls"
        mount -o remount,size=1800k "$mnt" || exit 91
        splat 2> "$dir/full.err"; echo $? > "$dir/full.rc"
        ls -A "$mnt" "$mnt/.out.ply.tiles" > "$dir/full.ls"
        mount -o remount,size=4m "$mnt" || exit 92
        splat --resume 2> "$dir/resume.err"; echo $? > "$dir/resume.rc"
        cp "$mnt/out.ply" "$dir/resumed.ply"
        exit 0
    "#;
    let o = std::process::Command::new("unshare")
        .args([
            "--user",
            "--map-root-user",
            "--mount",
            "sh",
            "-c",
            script,
            "sh",
        ])
        .arg(env!("CARGO_BIN_EXE_splatray"))
        .arg(&input)
        .arg(&mnt)
        .arg(&dir)
        .output()
        .expect("unshare (util-linux, which scripts/setup.sh installs) must be on PATH");
    assert!(
        o.status.success(),
        "cannot set up the tmpfs in a user namespace (unshare -rm, mount -t tmpfs): status {:?}, {}",
        o.status.code(),
        String::from_utf8_lossy(&o.stderr)
    );
    let read = |name: &str| std::fs::read_to_string(dir.join(name)).unwrap();
    // Refused up front: one line on the work folder, in kB.
    let err = read("small.err");
    assert_eq!(read("small.rc").trim(), "1", "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(
        err.contains(".out.ply.tiles: the spill needs about ")
            && err.contains(" kB (")
            && err.contains("kB free"),
        "{err}"
    );
    assert!(
        !err.contains("bad data") && !err.contains("0.0 GB"),
        "{err}"
    );
    assert_eq!(
        read("small.ls").trim(),
        ".out.ply.tiles",
        "{}",
        read("small.ls")
    );
    // The disk fills while the output is written.
    let err = read("full.err");
    assert_eq!(read("full.rc").trim(), "1", "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("out.ply: No space left on device"), "{err}");
    let listing = read("full.ls");
    assert!(!listing.contains("partial"), "{listing}");
    assert!(!listing.lines().any(|l| l == "out.ply"), "{listing}");
    assert!(listing.contains("tile-00007.ply"), "{listing}");
    // Space freed: resumed, the same bytes.
    let err = read("resume.err");
    assert_eq!(read("resume.rc").trim(), "0", "{err}");
    assert!(err.contains("8 resumed"), "{err}");
    assert!(
        std::fs::read(dir.join("resumed.ply")).unwrap() == whole,
        "resumed bytes differ"
    );
}
