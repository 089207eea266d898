//! `splatray view`: the thin command over [`crate::viewer`].

use super::progress::ProgressLine;
use super::view::default_scene;
use crate::Result;
use crate::viewer::{Overrides, ServeOptions, Source, serve};
use glam::DVec3;
use std::path::PathBuf;

/// Options of `splatray view`.
#[derive(Clone, Debug, clap::Args)]
pub struct ViewerArgs {
    /// Scene file (TOML) or point cloud, as `render` takes it. Default: the
    /// bundled scenes/bunny.toml.
    pub scene: Option<PathBuf>,
    /// Port to listen on (0: any free port; the URL printed says which).
    #[arg(long, default_value_t = 8737)]
    pub port: u16,
    /// Address to listen on. Default: the loopback address only; give
    /// 0.0.0.0 to let other machines in (there is no authentication).
    #[arg(long, default_value = "127.0.0.1")]
    pub host: String,
    /// Override the full-quality frame's width.
    #[arg(long)]
    pub width: Option<u32>,
    /// Override the full-quality frame's height.
    #[arg(long)]
    pub height: Option<u32>,
    /// A point cloud's up axis (as `render --up`).
    #[arg(long, value_parser = super::view::parse_up, allow_hyphen_values = true)]
    pub up: Option<DVec3>,
    /// Samples per pixel of the refined frame that follows the
    /// full-quality one while the view stands still (none when not above
    /// the scene's).
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub refine_spp: u32,
}

/// Runs `splatray view`.
pub fn run(args: &ViewerArgs) -> Result<()> {
    let path = args.scene.clone().unwrap_or_else(default_scene);
    let line = ProgressLine::new();
    let progress = |stage: &str, f: f64| line.update(stage, f);
    let o = Overrides {
        width: args.width,
        height: args.height,
        up: args.up,
    };
    let loaded = Source::load(&path, o, Some(&progress));
    line.finish();
    let (source, scene) = loaded?;
    for w in &scene.load.warnings {
        eprintln!("warning: {w}");
    }
    eprintln!(
        "{}: {} splats, {}x{} spp {}",
        path.display(),
        scene.splats.len(),
        source.width,
        source.height,
        source.spp()
    );
    let opts = ServeOptions {
        host: args.host.clone(),
        port: args.port,
        refine_spp: args.refine_spp,
    };
    serve(source, scene, &opts)
}
