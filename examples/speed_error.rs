//! A cloud's render speed against its error, in a small sweep: a scene of
//! points sampled from the bundled bunny mesh (the mesh is the exact
//! surface the errors are measured against) is made into splats at five
//! budgets, from coarse to fine, and rendered flat, blended and with Phong
//! normal fields on every backend (report §4.4, fig. 16). Prints one line
//! per budget and shading mode; exits 1 when the backends' images differ
//! in a row or when the finest Phong splats are not closer to the surface
//! than the coarsest (the error must fall as the budget grows).
//!
//! `cargo run --release --example speed_error -- [SAMPLES]` (default 20000)

use splatray::{Error, Result, ShadingMode, SweepRequest, sweep};
use std::path::Path;

fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("speed_error: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run() -> Result<()> {
    let samples = match std::env::args().nth(1) {
        None => 20_000,
        Some(s) => s
            .parse::<u32>()
            .ok()
            .filter(|n| (100..=1_000_000).contains(n))
            .ok_or_else(|| Error::invalid(format!("SAMPLES '{s}' must be in 100..=1000000")))?,
    };
    // The scene: the mesh sampled into a cloud (its `truth`), one light.
    let mesh = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/data/bunny-mesh.ply");
    let dir = std::env::temp_dir().join(format!("splatray-speed-error-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(Error::other)?;
    let scene = dir.join("scene.toml");
    let text = format!(
        "[camera]\nfrom = [1.5, 1.1, 4.4]\nat = [0.0, -0.1, 0.0]\nfov = 34\n\n\
         [[model]]\nmesh = {:?}\nsamples = {samples}\nseed = 3\n\n\
         [[light]]\nkind = \"point\"\nposition = [2.0, 4.0, 3.0]\nintensity = 20.0\n",
        mesh.display().to_string()
    );
    std::fs::write(&scene, text).map_err(Error::other)?;

    let request = SweepRequest {
        scene: scene.clone(),
        width: 96,
        height: 72,
        steps: 5,
        eps_coarse: 0.02,
        eps_fine: 0.002,
    };
    let rows = sweep(&request, None, &mut |_| {});
    std::fs::remove_dir_all(&dir).map_err(Error::other)?;
    let result = rows?;
    let rows = result.rows;

    println!("step epsilon  splats shading  backend: render s, PSNR dB, normal error mean deg");
    for r in &rows {
        let per_backend: Vec<String> = r
            .backends
            .iter()
            .map(|b| {
                let psnr = b
                    .errors
                    .image_psnr_db
                    .map_or("-".into(), |p| format!("{p:.2}"));
                format!(
                    "{}: {:.4}, {psnr}, {:.3}",
                    b.name, b.render_s, b.errors.normal_deg_mean
                )
            })
            .collect();
        println!(
            "{:>4} {:.5} {:>6} {:<8} {}",
            r.step,
            r.epsilon_rel,
            r.splats,
            format!("{:?}", r.shading).to_lowercase(),
            per_backend.join("; ")
        );
        if !r.backends_identical {
            return Err(Error::invalid(format!(
                "step {} ({:?}): the backends' images differ",
                r.step, r.shading
            )));
        }
    }
    let phong: Vec<_> = rows
        .iter()
        .filter(|r| r.shading == ShadingMode::Phong)
        .collect();
    let (coarse, fine) = match (phong.first(), phong.last()) {
        (Some(c), Some(f)) if phong.len() == request.steps => (c, f),
        _ => {
            return Err(Error::invalid(format!(
                "{} Phong rows, expected {}",
                phong.len(),
                request.steps
            )));
        }
    };
    let (e0, e1) = (
        coarse.reference().errors.normal_deg_mean,
        fine.reference().errors.normal_deg_mean,
    );
    if e1.partial_cmp(&e0) != Some(std::cmp::Ordering::Less) {
        return Err(Error::invalid(format!(
            "Phong normal error {e1:.3}° at {} splats is not below {e0:.3}° at {}",
            fine.splats, coarse.splats
        )));
    }
    if let Some(m) = &result.mesh {
        let speeds: Vec<String> = m
            .backends
            .iter()
            .map(|b| format!("{}: {:.4} s", b.name, b.render_s))
            .collect();
        println!("mesh ({} triangles): {}", m.triangles, speeds.join("; "));
    }
    println!(
        "{} rows, backends identical in each; Phong normal error {e0:.3}° at {} splats -> {e1:.3}° at {}",
        rows.len(),
        coarse.splats,
        fine.splats
    );
    Ok(())
}
