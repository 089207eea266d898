//! A point cloud to an image through the library's front door: a scene file
//! whose model is a point cloud is loaded (its points made into splats as
//! the file says), rendered on a chosen backend and written as a PNG — the
//! image `splatray render` writes of the same scene, byte for byte
//! (scripts/test.sh checks it on the scene `render --save-scene` wrote for a
//! cloud given alone).
//!
//! `cargo run --release --example cloud_to_image -- SCENE.toml OUT.png [BACKEND]`

use splatray::{Error, Result, build_backend, load_scene, render, write_image};
use std::path::PathBuf;

fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("cloud_to_image: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (scene_path, out) = match args.as_slice() {
        [s, o] | [s, o, _] => (PathBuf::from(s), PathBuf::from(o)),
        _ => {
            return Err(Error::invalid(
                "usage: cloud_to_image SCENE.toml OUT.png [BACKEND]",
            ));
        }
    };
    let backend = args.get(2).map_or("octree", String::as_str);

    // Points to splats: the scene's models are generated as they load.
    let scene = load_scene(&scene_path, None)?;
    // The acceleration structure, then the image (the Whitted integrator).
    let built = build_backend(backend, &scene)?;
    let frame = render(&scene, &*built, None);
    write_image(&frame, &out)?;
    println!(
        "{}: {} splats, {}x{} on {backend}, {} rays -> {}",
        scene_path.display(),
        scene.splats.len(),
        frame.width,
        frame.height,
        frame.rays.total(),
        out.display()
    );
    Ok(())
}
