//! What `render` and `compare` share: the scene to load — a scene file, or
//! a point cloud given alone, for which a scene is made — and the view
//! overrides applied to it.

use super::progress::ProgressLine;
use crate::resolve::ShadingMode;
use crate::scene::cloud::{CloudRequest, is_cloud_path, make_scene};
use crate::scene::{Scene, load_scene_within};
use crate::{Error, Result};
use glam::DVec3;
use std::path::{Path, PathBuf};

/// The scene and its view overrides (flattened into a command's options).
#[derive(Clone, Debug, clap::Args)]
pub struct SceneArgs {
    /// Scene file (TOML), or a point cloud (.ply, .pcd, .xyz, .txt, or
    /// recognised by its first bytes; a splat PLY from `splatray splat` too)
    /// rendered with a camera, lights and material made for it. Default: the
    /// bundled scenes/bunny.toml.
    pub scene: Option<PathBuf>,
    /// Override the camera's width.
    #[arg(long)]
    pub width: Option<u32>,
    /// Override the camera's height.
    #[arg(long)]
    pub height: Option<u32>,
    /// Override the shading mode: flat, blended or phong.
    #[arg(long, value_parser = crate::names::parse::<ShadingMode>)]
    pub shading: Option<ShadingMode>,
    /// A point cloud's up axis: x, y, z, -x, -y, -z or X,Y,Z. Default: a
    /// flat cloud's thinnest side; +z when the cloud's viewpoint looks down
    /// along +z; else +y (docs/DESIGN.md, "A point cloud without a scene").
    #[arg(long, value_parser = parse_up, allow_hyphen_values = true)]
    pub up: Option<DVec3>,
    /// Write the scene made for a point cloud here (TOML, the cloud's path
    /// relative to it), to edit and render again: it renders the same image.
    #[arg(long, value_name = "SCENE.toml")]
    pub save_scene: Option<PathBuf>,
    /// The most rays the render may trace, worst case (every glass hit
    /// reflecting and refracting to max_depth, every light sample).
    #[arg(long, default_value_t = crate::render::budget::DEFAULT_MAX_RAYS, value_parser = positive)]
    pub max_rays: f64,
    /// The most memory the render may take, GB (default: what the machine
    /// has available).
    #[arg(long, value_name = "GB", value_parser = positive)]
    pub max_memory: Option<f64>,
}

/// A finite number above zero.
fn positive(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(x) if x.is_finite() && x > 0.0 => Ok(x),
        _ => Err(format!("'{s}' must be a finite number above 0")),
    }
}

/// `--up`: an axis name or three numbers.
pub fn parse_up(s: &str) -> Result<DVec3, String> {
    let axis = match s.trim() {
        "x" | "+x" => Some(DVec3::X),
        "y" | "+y" => Some(DVec3::Y),
        "z" | "+z" => Some(DVec3::Z),
        "-x" => Some(DVec3::NEG_X),
        "-y" => Some(DVec3::NEG_Y),
        "-z" => Some(DVec3::NEG_Z),
        _ => None,
    };
    if let Some(a) = axis {
        return Ok(a);
    }
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("'{s}' is not an axis (x, y, z, -x, -y, -z) or X,Y,Z"))?;
    match v.as_slice() {
        [x, y, z] => DVec3::new(*x, *y, *z)
            .try_normalize()
            .ok_or_else(|| format!("'{s}' must be a non-zero, finite vector")),
        _ => Err(format!(
            "'{s}' is not an axis (x, y, z, -x, -y, -z) or X,Y,Z"
        )),
    }
}

impl SceneArgs {
    /// `--max-memory` in bytes (given in GB, 10^9 bytes).
    fn max_bytes(&self) -> Option<u64> {
        self.max_memory.map(|gb| (gb * 1e9) as u64)
    }

    /// Checks the worst-case rays and the memory of rendering `scene`
    /// while holding `holds` against `--max-rays` and `--max-memory` (or the
    /// memory available).
    ///
    /// # Errors
    /// Over a limit: one line with the cost and the flag.
    pub fn check_budget(&self, scene: &Scene, holds: crate::render::budget::Holds) -> Result<()> {
        let limits = crate::render::budget::Limits {
            max_rays: self.max_rays,
            max_bytes: self.max_bytes(),
        };
        crate::render::budget::check(scene, holds, &limits)
            .map(|_| ())
            .map_err(|e| e.context(self.path().display()))
    }

    /// The scene file or cloud: the one given, else the bundled default.
    #[must_use]
    pub fn path(&self) -> PathBuf {
        self.scene.clone().unwrap_or_else(default_scene)
    }

    /// Whether the input is a point cloud rather than a scene file.
    #[must_use]
    pub fn is_cloud(&self) -> bool {
        is_cloud_path(&self.path())
    }

    /// Loads the scene (progress on `line`), applies the overrides and
    /// `spp`, and prints the loader's warnings. A point cloud gets a scene
    /// made for it (saved with `--save-scene`).
    ///
    /// # Errors
    /// A scene that does not load or an override out of range, as one line.
    pub fn load(&self, spp: Option<u32>, line: &ProgressLine) -> Result<Scene> {
        let path = self.path();
        let scene = if is_cloud_path(&path) {
            self.load_cloud(&path, spp, line)?
        } else {
            if self.up.is_some() || self.save_scene.is_some() {
                return Err(Error::invalid(format!(
                    "{}: --up and --save-scene apply to a point cloud, not to a scene file",
                    path.display()
                )));
            }
            let progress = |stage: &str, f: f64| line.update(stage, f);
            let mut scene = load_scene_within(&path, Some(&progress), self.max_bytes())?;
            line.finish();
            scene.set_view(self.width, self.height, spp, self.shading)?;
            scene
        };
        for w in &scene.load.warnings {
            eprintln!("warning: {w}");
        }
        Ok(scene)
    }

    /// A point cloud's scene (`scene::cloud::make_scene`: surveyed, a
    /// camera chosen, written as scene text with the overrides in it and
    /// built from that text), and with `--save-scene` that text saved, so
    /// that the scene saved renders the same image.
    fn load_cloud(&self, path: &Path, spp: Option<u32>, line: &ProgressLine) -> Result<Scene> {
        let request = CloudRequest {
            width: self.width,
            height: self.height,
            spp,
            shading: self.shading,
            up: self.up,
            save: self.save_scene.clone(),
        };
        let progress = |stage: &str, f: f64| line.update(stage, f);
        let made = make_scene(path, &request, Some(&progress))?;
        line.finish();
        eprintln!("{}: {}", path.display(), made.note());
        if let Some(s) = &self.save_scene {
            let text = made.saved_text(path, s)?;
            crate::io::write_text(s, &text)?;
        }
        Ok(made.scene)
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
