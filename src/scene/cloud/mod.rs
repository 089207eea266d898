//! A scene for a point cloud given alone (`splatray render CLOUD.pcd`): one
//! model from the cloud, a camera that shows all of it, a headlight and a key
//! light, a material and a background — written as scene-file text, so the
//! scene rendered and the scene saved for editing are the same text.
//!
//! [`make_scene`] takes the steps in order, each from what the one before
//! gave (`docs/DESIGN.md`, "A point cloud without a scene"):
//!
//! 1. [`mod@survey`]: the file read once; a sample of its points, their box,
//!    the viewpoint, colours, an organised cloud's sensor;
//! 2. [`view`]: the camera, its up vector by the rules of [`up`];
//! 3. [`text`]: the scene as TOML;
//! 4. the scene: that text parsed and built like any scene file
//!    ([`crate::scene::load::build_scene_read`]), the model taking the cloud
//!    the survey read.

pub mod survey;
pub mod text;
pub mod up;
pub mod view;

#[cfg(test)]
mod tests;

pub use crate::io::is_splat_ply;
pub use survey::{CloudKind, SURVEY_SAMPLE, Survey, read_and_survey, survey, survey_file};
pub use text::{
    BACKGROUND, CloudSceneOptions, DEFAULT_SIZE, camera_text, decimals, path_from, scene_text,
};
pub use up::UPRIGHT_RATIO;
pub use view::{View, choose_view};

use crate::io::Format;
use crate::progress::{Progress, notify};
use crate::resolve::ShadingMode;
use crate::scene::file::parse_scene_str;
use crate::scene::load::build_scene_read;
use crate::scene::model::Scene;
use crate::{Error, Result};
use glam::DVec3;
use std::path::{Path, PathBuf};

/// Whether `path` names a point cloud rather than a scene file: a `.ply`,
/// `.pcd`, `.xyz` or `.txt` extension, or (any extension but `.toml`) a file
/// whose first bytes are PLY, PCD or XYZ; or a folder (of point files, read
/// as one cloud: `crate::io::read_folder`); or a pipe.
#[must_use]
pub fn is_cloud_path(path: &Path) -> bool {
    if path.is_dir() {
        return true;
    }
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    if ext.as_deref() == Some("toml") {
        return false;
    }
    if Format::from_extension(path).is_some() {
        return true;
    }
    // A pipe (`<(cat scan.pcd)`, a FIFO) gives its bytes once: sniffing
    // its head would use them up and leave the reader waiting for a
    // writer, so it is read as a cloud (a scene file through a pipe is
    // then one clear error, not a wait).
    if std::fs::metadata(path).is_ok_and(|m| !m.is_file()) {
        return true;
    }
    crate::io::file_head(path).is_some_and(|h| Format::sniff(&h).is_some())
}

/// What is asked of a cloud's scene beyond the cloud: the command line's
/// view overrides.
#[derive(Clone, Debug, Default)]
pub struct CloudRequest {
    /// Image width (default: an organised cloud's grid, else
    /// [`DEFAULT_SIZE`]).
    pub width: Option<u32>,
    /// Image height (as `width`).
    pub height: Option<u32>,
    /// Samples per pixel (default 1).
    pub spp: Option<u32>,
    /// Shading mode (default: the scene file's, phong).
    pub shading: Option<ShadingMode>,
    /// The up vector, instead of the rules of [`up`] (and of an organised
    /// cloud's sensor).
    pub up: Option<DVec3>,
    /// Where the scene will be saved: its folder is checked before the
    /// scene is built ([`CloudScene::saved_text`] gives the text).
    pub save: Option<PathBuf>,
}

/// A cloud's scene as made, with what made it.
#[derive(Debug)]
pub struct CloudScene {
    /// The scene, set up as a scene file's is.
    pub scene: Scene,
    /// Step 1.
    pub survey: Survey,
    /// Step 2.
    pub view: View,
    /// The image and render settings the text holds.
    pub options: CloudSceneOptions,
}

/// Makes the scene for the cloud at `path` (the steps of the module
/// documentation); splat generation reports to `progress`, reading the
/// cloud as the stage "reading the cloud".
///
/// # Errors
/// One line: the cloud does not read or is too wide, a resolution out of
/// `1..=32768`, the folder of `request.save` missing, or the scene does not
/// build (naming the cloud).
pub fn make_scene(
    path: &Path,
    request: &CloudRequest,
    progress: Option<Progress<'_>>,
) -> Result<CloudScene> {
    notify(progress, "reading the cloud", 0.0);
    let (survey, read) = read_and_survey(path)?;
    // An organised cloud renders at its grid's size, registered with the
    // capture.
    let size = match &survey.sensor {
        Some(Ok(s)) if request.up.is_none() => (s.width, s.height),
        _ => DEFAULT_SIZE,
    };
    let options = CloudSceneOptions {
        width: request.width.unwrap_or(size.0),
        height: request.height.unwrap_or(size.1),
        spp: request.spp.unwrap_or(1),
        shading: request.shading,
    };
    let (w, h) = (options.width, options.height);
    if w == 0 || h == 0 || w > 1 << 15 || h > 1 << 15 {
        return Err(Error::invalid(format!(
            "resolution {w}x{h} must be in 1..=32768"
        )));
    }
    if let Some(s) = &request.save {
        check_folder(s)?;
    }
    let view = choose_view(&survey, request.up, f64::from(w) / f64::from(h));
    let text = scene_text(path, &survey, &view, &options)?;
    let file = parse_scene_str(&text).map_err(|e| e.context(path.display()))?;
    // The scene names the cloud by `path`: it takes what was read.
    let mut scene = build_scene_read(&file, Path::new(""), Some((path, read)), progress)
        .map_err(|e| e.context(path.display()))?;
    // As a scene file is set up (`load_scene`'s callers), so that the scene
    // saved renders these bytes wherever the cloud lies.
    scene.set_view(None, None, None, None)?;
    Ok(CloudScene {
        scene,
        survey,
        view,
        options,
    })
}

impl CloudScene {
    /// One line: what the file holds and the camera chosen, and why (the
    /// outliers left out of the framing; an organised grid whose sensor
    /// could not be fitted).
    #[must_use]
    pub fn note(&self) -> String {
        let s = &self.survey;
        let outliers = if s.outliers > 0 {
            format!(
                " ({} outliers of a {}-point sample left out of the framing)",
                s.outliers,
                s.sample.len() + s.outliers
            )
        } else {
            String::new()
        };
        let unfitted = match &s.sensor {
            Some(Err(why)) => format!(" (an organised grid, but {why})"),
            _ => String::new(),
        };
        format!(
            "{} {} without a scene: {}{outliers}{unfitted}",
            s.points,
            s.kind.key(),
            self.view.note
        )
    }

    /// The scene text to save at `save` for the cloud at `path`: the
    /// cloud's path relative to `save`'s folder ([`path_from`]), so that
    /// the saved scene renders the same image.
    ///
    /// # Errors
    /// As [`scene_text`].
    pub fn saved_text(&self, path: &Path, save: &Path) -> Result<String> {
        let folder = save.parent().unwrap_or(Path::new(""));
        scene_text(
            &path_from(folder, path),
            &self.survey,
            &self.view,
            &self.options,
        )
    }
}

/// The folder of an output file exists.
fn check_folder(path: &Path) -> Result<()> {
    match path.parent().filter(|p| !p.as_os_str().is_empty()) {
        Some(d) if !d.is_dir() => Err(Error::invalid(format!(
            "{}: folder does not exist",
            d.display()
        ))),
        _ => Ok(()),
    }
}
