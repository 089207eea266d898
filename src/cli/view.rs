//! What `render` and `compare` share: the scene to load and the view
//! overrides applied to it.

use super::progress::ProgressLine;
use splatray::resolve::ShadingMode;
use splatray::scene::{Scene, load_scene};
use std::path::{Path, PathBuf};

/// The scene and its view overrides (flattened into a command's options).
#[derive(Clone, Debug, clap::Args)]
pub struct SceneArgs {
    /// Scene file (TOML). Default: the bundled scenes/bunny.toml.
    pub scene: Option<PathBuf>,
    /// Override the camera's width.
    #[arg(long)]
    pub width: Option<u32>,
    /// Override the camera's height.
    #[arg(long)]
    pub height: Option<u32>,
    /// Override the shading mode: flat, blended or phong.
    #[arg(long)]
    pub shading: Option<ShadingMode>,
}

impl SceneArgs {
    /// The scene file: the one given, else the bundled default.
    #[must_use]
    pub fn path(&self) -> PathBuf {
        self.scene.clone().unwrap_or_else(default_scene)
    }

    /// Loads the scene (progress on `line`), applies the overrides and
    /// `spp`, and prints the loader's warnings.
    ///
    /// # Errors
    /// A scene that does not load or an override out of range, as one line.
    pub fn load(&self, spp: Option<u32>, line: &ProgressLine) -> Result<Scene, String> {
        let progress = |stage: &str, f: f64| line.update(stage, f);
        let mut scene = load_scene(&self.path(), Some(&progress))?;
        line.finish();
        scene.set_view(self.width, self.height, spp, self.shading)?;
        for w in &scene.load.warnings {
            eprintln!("warning: {w}");
        }
        Ok(scene)
    }
}

/// The bundled default scene: `scenes/bunny.toml` under the current folder,
/// else under the source tree this binary was built from.
#[must_use]
pub fn default_scene() -> PathBuf {
    let local = PathBuf::from("scenes/bunny.toml");
    if local.is_file() {
        local
    } else {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/bunny.toml")
    }
}
