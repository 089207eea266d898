//! Finds Embree 4 and tells the linker (and the binary's rpath) where it is.
//!
//! Search order: `EMBREE_DIR` (its `lib`, `lib64`, or the folder itself),
//! `pkg-config embree4`, then the project's own git-ignored `.embree/lib`
//! filled by `scripts/setup.sh`. `embree4-sys` itself only says
//! `-lembree4`; this script adds the search path and an rpath so binaries,
//! tests and benches run without `LD_LIBRARY_PATH`.

use std::path::{Path, PathBuf};
use std::process::Command;

fn has_embree(dir: &Path) -> bool {
    dir.join("libembree4.so").exists()
        || dir.join("libembree4.dylib").exists()
        || dir.join("embree4.lib").exists()
}

fn from_embree_dir() -> Option<(PathBuf, String)> {
    let root = PathBuf::from(std::env::var_os("EMBREE_DIR")?);
    ["lib", "lib64", "."]
        .iter()
        .map(|sub| root.join(sub))
        .find(|d| has_embree(d))
        .map(|d| (d, "EMBREE_DIR".to_string()))
}

fn from_pkg_config() -> Option<(PathBuf, String)> {
    let out = Command::new("pkg-config")
        .args(["--libs-only-L", "embree4"])
        .output()
        .ok()?;
    if !out.status.success() {
        return None;
    }
    let text = String::from_utf8_lossy(&out.stdout).to_string();
    let mut dirs: Vec<PathBuf> = text
        .split_whitespace()
        .filter_map(|f| f.strip_prefix("-L"))
        .map(PathBuf::from)
        .collect();
    if dirs.is_empty() {
        // Installed in a default linker path: ask for libdir for the rpath.
        let out = Command::new("pkg-config")
            .args(["--variable=libdir", "embree4"])
            .output()
            .ok()?;
        dirs.push(PathBuf::from(
            String::from_utf8_lossy(&out.stdout).trim().to_string(),
        ));
    }
    dirs.into_iter()
        .find(|d| has_embree(d))
        .map(|d| (d, "pkg-config".to_string()))
}

fn from_local() -> Option<(PathBuf, String)> {
    let dir = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").ok()?).join(".embree/lib");
    has_embree(&dir).then(|| (dir, ".embree".to_string()))
}

fn main() {
    let found = from_embree_dir()
        .or_else(from_pkg_config)
        .or_else(from_local);
    // Nothing printed to stdout before this point: a failed search shows
    // one sentence, not a list of cargo directives.
    let Some((dir, how)) = found else {
        eprintln!(
            "error: Embree 4 not found (looked in EMBREE_DIR, `pkg-config embree4`, .embree/lib); \
             run scripts/setup.sh to install it"
        );
        std::process::exit(1);
    };
    println!("cargo:rerun-if-env-changed=EMBREE_DIR");
    println!("cargo:rerun-if-env-changed=PKG_CONFIG_PATH");
    println!("cargo:rerun-if-changed=.embree/lib");
    println!("cargo:rerun-if-changed=build.rs");
    let dir = dir.canonicalize().unwrap_or(dir);
    println!("cargo:rustc-link-search=native={}", dir.display());
    println!("cargo:rustc-link-arg=-Wl,-rpath,{}", dir.display());
    println!("cargo:rustc-env=SPLATRAY_EMBREE_FOUND_BY={how}");
    println!("cargo:rustc-env=SPLATRAY_EMBREE_LIB_DIR={}", dir.display());
}
