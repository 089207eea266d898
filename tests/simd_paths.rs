//! The octree's SIMD paths chosen by `SPLATRAY_SIMD` (`src/simd/`): every
//! path this CPU runs renders the bundled bunny to the same bytes and `info`
//! names it; a path that is not one, or that this CPU cannot run, is a
//! one-line error before any work. (The conformance suite checks each
//! path's candidates through the registry's `octree-<path>` entries.)

mod common;

use common::{bin, scratch};
use splatray::accel::PACKETS_VAR;
use splatray::simd::{Isa, SIMD_VAR, available};
use std::path::Path;

/// Renders the bundled bunny at `size` with `backend` and the environment
/// variable `env` set, to `out`; the image's bytes (the run must succeed).
fn render_bunny(env: (&str, &str), size: (&str, &str), backend: &str, out: &Path) -> Vec<u8> {
    render_scene("scenes/bunny.toml", env, size, backend, out)
}

/// [`render_bunny`] of the bundled scene `scene`.
fn render_scene(
    scene: &str,
    env: (&str, &str),
    size: (&str, &str),
    backend: &str,
    out: &Path,
) -> Vec<u8> {
    let o = bin()
        .env(env.0, env.1)
        .args(["render", scene, "--width", size.0])
        .args(["--height", size.1, "--backend", backend, "-o"])
        .arg(out)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "{}={} {backend}: {}",
        env.0,
        env.1,
        String::from_utf8_lossy(&o.stderr)
    );
    std::fs::read(out).unwrap()
}

#[test]
fn every_path_renders_the_bunny_to_the_same_bytes() {
    let dir = scratch("simd-paths");
    let mut images = Vec::new();
    for isa in available() {
        let info = bin()
            .env(SIMD_VAR, isa.name())
            .arg("info")
            .output()
            .unwrap();
        assert!(info.status.success());
        let text = String::from_utf8_lossy(&info.stdout);
        assert!(
            text.lines()
                .any(|l| l.starts_with(&format!("simd     {isa} "))),
            "info does not name {isa}: {text}"
        );
        let out = dir.join(format!("bunny-{isa}.png"));
        let octree = common::default_renderer();
        let bytes = render_bunny((SIMD_VAR, isa.name()), ("160", "120"), octree, &out);
        images.push((isa, bytes));
    }
    assert!(!images.is_empty(), "no SIMD path at all");
    // Every path against the other renderer (identical by the backend
    // contract), so a CPU with one path still compares something.
    let other = common::other_renderer();
    let reference = render_bunny(
        (SIMD_VAR, "portable"),
        ("160", "120"),
        other,
        &dir.join(format!("bunny-{other}.png")),
    );
    for (isa, bytes) in &images {
        assert!(
            bytes == &reference,
            "{isa} renders other bytes than {other}"
        );
    }
    let untested: Vec<Isa> = Isa::ALL.into_iter().filter(|i| !i.supported()).collect();
    eprintln!(
        "simd paths compared: {:?}; not tested (this CPU lacks them): {untested:?}",
        images.iter().map(|(i, _)| *i).collect::<Vec<_>>()
    );
}

#[test]
fn a_path_that_cannot_run_is_a_one_line_error() {
    let mut names = vec!["sse9".to_string(), "AVX2".to_string()];
    names.extend(
        Isa::ALL
            .into_iter()
            .filter(|i| !i.supported())
            .map(|i| i.name().to_string()),
    );
    let dir = scratch("refused-path");
    for name in names {
        let err = refused((SIMD_VAR, &name), &dir.join("never.png"));
        assert!(err.contains(&format!("{SIMD_VAR}={name}")), "{name}: {err}");
    }
}

/// The integrator's batches (`SPLATRAY_PACKETS`, `accel::use_packets`):
/// the bundled bunny (a sphere light: the shadow rays of each hit go as
/// one batch; a directional light: those of a screen tile's hits) and the
/// glass scene (a point light's shadow rays from a tile's hits, and from
/// the hits that mirrors and glass lead to, which go one at a time) render
/// to the same bytes with packets forced on and off, on both renderers;
/// any other value is a one-line error before any work.
#[test]
fn packets_on_and_off_render_the_bunny_to_the_same_bytes() {
    let dir = scratch("packets");
    for backend in common::renderers() {
        for scene in ["bunny", "glass"] {
            let mut images = Vec::new();
            for mode in ["on", "off"] {
                let out = dir.join(format!("{scene}-{backend}-{mode}.png"));
                images.push(render_scene(
                    &format!("scenes/{scene}.toml"),
                    (PACKETS_VAR, mode),
                    ("96", "72"),
                    backend,
                    &out,
                ));
            }
            assert!(
                images[0] == images[1],
                "{scene}, {backend}: packets change the image"
            );
        }
    }
    let err = refused((PACKETS_VAR, "maybe"), &dir.join("never.png"));
    assert!(err.contains(PACKETS_VAR), "{err}");
}

/// Renders a small bunny to `out` with `var` set to a value the program
/// refuses: it must fail with one line (returned) and write nothing.
fn refused((var, value): (&str, &str), out: &Path) -> String {
    let o = bin()
        .env(var, value)
        .args([
            "render",
            "scenes/bunny.toml",
            "--width",
            "16",
            "--height",
            "12",
        ])
        .arg("-o")
        .arg(out)
        .output()
        .unwrap();
    assert!(!o.status.success(), "{var}={value}");
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(err.trim_end().lines().count(), 1, "{var}={value}: {err}");
    assert!(!out.exists(), "{var}={value}: {} written", out.display());
    err
}
