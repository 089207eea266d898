//! The extension module links Embree 4 where the splatray crate's build
//! script found it (`EMBREE_DIR`, `pkg-config embree4`, the clone's
//! `.embree/lib` from `scripts/setup.sh`) and records that folder as its
//! rpath (the library's link search path reaches this crate; its rpath
//! does not). That rpath is what `auditwheel repair`
//! (scripts/python-package.sh) follows to find Embree and TBB; it copies
//! them into the wheel's `splatray.libs/` and replaces the rpath with
//! `$ORIGIN/../splatray.libs`, so the installed module uses those copies.
//! `splatray info` (the command line compiled into the module) says so.

use std::path::{Path, PathBuf};
use std::process::Command;

fn has_embree(dir: &Path) -> bool {
    dir.join("libembree4.so").exists() || dir.join("libembree4.dylib").exists()
}

fn main() {
    println!("cargo:rerun-if-env-changed=EMBREE_DIR");
    println!("cargo:rerun-if-env-changed=PKG_CONFIG_PATH");
    println!("cargo:rerun-if-changed=build.rs");
    let from_env = std::env::var_os("EMBREE_DIR")
        .map(PathBuf::from)
        .and_then(|r| {
            ["lib", "lib64", "."]
                .iter()
                .map(|s| r.join(s))
                .find(|d| has_embree(d))
        });
    let from_pkg = || {
        let out = Command::new("pkg-config")
            .args(["--variable=libdir", "embree4"])
            .output()
            .ok()?;
        let d = PathBuf::from(String::from_utf8_lossy(&out.stdout).trim());
        (out.status.success() && has_embree(&d)).then_some(d)
    };
    let local = || {
        let d = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").ok()?).join("../../.embree/lib");
        has_embree(&d).then_some(d)
    };
    let found = from_env
        .or_else(from_pkg)
        .or_else(local)
        .map(|d| d.canonicalize().unwrap_or(d));
    if let Some(dir) = &found {
        println!("cargo:rustc-link-arg=-Wl,-rpath,{}", dir.display());
    }
    // `splatray info`'s "found by" line: where the wheel's copy comes from.
    println!(
        "cargo:rustc-env=SPLATRAY_EMBREE_FOUND_BY=the wheel (splatray.libs, bundled by auditwheel repair)"
    );
    println!(
        "cargo:rustc-env=SPLATRAY_EMBREE_LIB_DIR=copied at build time from {}",
        found.map_or("the linker's default path".into(), |d| d
            .display()
            .to_string())
    );
}
