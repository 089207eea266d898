//! The extension module finds Embree 4 where the splatray crate's build
//! script found it (`EMBREE_DIR`, `pkg-config embree4`, the clone's
//! `.embree/lib` from `scripts/setup.sh`) and records that folder as its
//! rpath, so `import splatray` needs no `LD_LIBRARY_PATH` (the library's
//! link search path reaches this crate; its rpath does not).

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
    if let Some(dir) = from_env.or_else(from_pkg).or_else(local) {
        let dir = dir.canonicalize().unwrap_or(dir);
        println!("cargo:rustc-link-arg=-Wl,-rpath,{}", dir.display());
    }
}
