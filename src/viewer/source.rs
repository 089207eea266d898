//! What the viewer shows and how a view becomes scene text: the scene or
//! cloud given on the command line, loaded once, and the scene-file text of
//! any camera the page asks for — written by the writer `render
//! --save-scene` uses ([`crate::scene::cloud::scene_text`], and its
//! [`camera_text`] for a scene file's camera), so that the text the page
//! saves renders the page's full-quality frame byte for byte.

use crate::names::Named;
use crate::progress::Progress;
use crate::resolve::ShadingMode;
use crate::scene::cloud::{
    CloudRequest, CloudSceneOptions, Survey, View, camera_text, decimals, is_cloud_path,
    make_scene, path_from, scene_text,
};
use crate::scene::model::Intrinsics;
use crate::scene::{Scene, load_scene, parse_scene_str};
use crate::{Error, Result};
use glam::DVec3;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// A camera as the page holds it, in the scene file's coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ViewCamera {
    /// Eye.
    pub from: [f64; 3],
    /// Point looked at.
    pub at: [f64; 3],
    /// Up hint.
    pub up: [f64; 3],
    /// Vertical field of view, degrees (with `sensor`, the sensor's, for
    /// the page's orbit arithmetic only).
    pub fov: f64,
    /// The sensor's (or the scene file's) intrinsics instead of `fov`:
    /// true only for the sensor view itself, unmoved.
    #[serde(default)]
    pub sensor: bool,
}

impl ViewCamera {
    /// The camera checked: finite numbers, `from` apart from `at`, `up` not
    /// along the view, the field of view in `(0, 180)`.
    ///
    /// # Errors
    /// One line naming what is wrong.
    pub fn check(&self) -> Result<()> {
        let all = self.from.iter().chain(&self.at).chain(&self.up);
        if !all.copied().chain([self.fov]).all(f64::is_finite) {
            return Err(Error::invalid("camera: every number must be finite"));
        }
        let f = DVec3::from(self.at) - DVec3::from(self.from);
        if f.length() <= 0.0 {
            return Err(Error::invalid("camera: `from` and `at` coincide"));
        }
        if f.normalize().cross(DVec3::from(self.up)).length() < 1e-9 {
            return Err(Error::invalid(
                "camera: `up` is zero or parallel to the view direction",
            ));
        }
        if !(self.fov > 0.0 && self.fov < 180.0) {
            return Err(Error::invalid(format!(
                "camera: fov {} must be in (0, 180) degrees",
                self.fov
            )));
        }
        Ok(())
    }
}

/// The input's kind and what writing its scene text needs.
#[derive(Debug)]
enum Kind {
    /// A point cloud given alone: its scene made as `render CLOUD` makes it.
    Cloud {
        /// The cloud, absolute.
        path: PathBuf,
        survey: Box<Survey>,
        /// The view chosen for it (with an organised cloud's sensor).
        view: View,
        options: CloudSceneOptions,
    },
    /// A scene file: its tables, the camera's left out, model paths made
    /// absolute.
    File {
        table: toml::Table,
        /// The file's intrinsics and image size, if its camera has them.
        intrinsics: Option<(Intrinsics, u32, u32)>,
        width: u32,
        height: u32,
        spp: u32,
    },
}

/// The scene the viewer shows, loaded once, and how to write its text.
#[derive(Debug)]
pub struct Source {
    /// The path given (for titles).
    pub path: PathBuf,
    /// The splats' bounding box in the file's coordinates.
    pub bounds: Option<(DVec3, DVec3)>,
    /// How many splats.
    pub splats: usize,
    /// The full-quality frame's size.
    pub width: u32,
    /// The full-quality frame's size.
    pub height: u32,
    /// The scene's own shading mode and each model's.
    pub shading: (ShadingMode, Vec<Option<ShadingMode>>),
    /// The input's own view.
    pub initial: ViewCamera,
    /// An organised cloud's sensor view (or a scene file's intrinsics
    /// camera), one key away.
    pub sensor: Option<ViewCamera>,
    /// Decimals of the camera's coordinates in the text.
    digits: usize,
    kind: Kind,
}

/// The command line's overrides of the input's view.
#[derive(Clone, Copy, Debug, Default)]
pub struct Overrides {
    /// Image width.
    pub width: Option<u32>,
    /// Image height.
    pub height: Option<u32>,
    /// A point cloud's up axis.
    pub up: Option<DVec3>,
}

/// The model keys that hold paths, relative to the scene file's folder.
const PATH_KEYS: [&str; 6] = ["points", "splats", "gaussians", "mesh", "triangles", "truth"];

impl Source {
    /// Loads `path`: a scene file, or a point cloud with the scene
    /// `render CLOUD` makes for it; the scene built, its camera the input's.
    ///
    /// # Errors
    /// One line: the input does not load, or an override is out of range.
    pub fn load(
        path: &Path,
        o: Overrides,
        progress: Option<Progress<'_>>,
    ) -> Result<(Source, Scene)> {
        if is_cloud_path(path) {
            Self::load_cloud(path, o, progress)
        } else {
            if o.up.is_some() {
                return Err(Error::invalid(format!(
                    "{}: --up applies to a point cloud, not to a scene file",
                    path.display()
                )));
            }
            Self::load_file(path, o, progress)
        }
    }

    fn load_cloud(
        path: &Path,
        o: Overrides,
        progress: Option<Progress<'_>>,
    ) -> Result<(Source, Scene)> {
        let request = CloudRequest {
            width: o.width,
            height: o.height,
            up: o.up,
            ..CloudRequest::default()
        };
        let made = make_scene(path, &request, progress)?;
        let abs = std::fs::canonicalize(path).map_err(|e| {
            Error::other(e).context(format_args!("{}: cannot resolve", path.display()))
        })?;
        let v = &made.view;
        let fov = match v.sensor {
            Some((k, _, h)) => 2.0 * (0.5 * f64::from(h) / k.fy).atan().to_degrees(),
            None => v.fov,
        };
        let cam = ViewCamera {
            from: v.from.to_array(),
            at: v.at.to_array(),
            up: v.up.to_array(),
            fov,
            sensor: v.sensor.is_some(),
        };
        let scene = made.scene;
        let source = Source {
            path: path.to_path_buf(),
            digits: decimals(made.survey.radius()),
            initial: cam,
            sensor: v.sensor.is_some().then_some(cam),
            bounds: scene.world_bounds(),
            splats: scene.splats.len(),
            width: scene.camera.width,
            height: scene.camera.height,
            shading: (scene.options.shading, scene.shading_of.clone()),
            kind: Kind::Cloud {
                path: abs,
                survey: Box::new(made.survey),
                view: made.view,
                options: made.options,
            },
        };
        Ok((source, scene))
    }

    fn load_file(
        path: &Path,
        o: Overrides,
        progress: Option<Progress<'_>>,
    ) -> Result<(Source, Scene)> {
        let text = std::fs::read_to_string(path).map_err(|e| {
            Error::other(e).context(format_args!("{}: cannot read scene", path.display()))
        })?;
        let file = parse_scene_str(&text).map_err(|e| e.context(path.display()))?;
        let mut scene = load_scene(path, progress)?;
        scene.set_view(o.width, o.height, None, None)?;
        let mut table: toml::Table = text
            .parse()
            .map_err(|e: toml::de::Error| Error::invalid(format!("{}: {e}", path.display())))?;
        table.remove("camera");
        let base = std::fs::canonicalize(path.parent().unwrap_or(Path::new("")))
            .or_else(|_| std::env::current_dir())
            .map_err(Error::other)?;
        if let Some(toml::Value::Array(models)) = table.get_mut("model") {
            for m in models.iter_mut().filter_map(toml::Value::as_table_mut) {
                for key in PATH_KEYS {
                    if let Some(toml::Value::String(p)) = m.get_mut(key) {
                        let abs = path_from(Path::new("/"), &base.join(&*p));
                        *p = abs.to_str().map(str::to_string).ok_or_else(|| {
                            Error::invalid(format!("{}: a path is not UTF-8", abs.display()))
                        })?;
                    }
                }
            }
        }
        let c = &file.camera;
        let intrinsics = c
            .intrinsics
            .map(|k| (Intrinsics::from(k), c.width, c.height));
        let fov = match c.intrinsics {
            Some(k) => 2.0 * (0.5 * f64::from(c.height) / k.fy).atan().to_degrees(),
            None => f64::from(c.fov),
        };
        let cam = ViewCamera {
            from: c.from,
            at: c.at,
            up: c.up.map(f64::from),
            fov,
            sensor: intrinsics.is_some(),
        };
        let radius = scene
            .world_bounds()
            .map_or(1.0, |(lo, hi)| 0.5 * (hi - lo).length());
        let source = Source {
            path: path.to_path_buf(),
            digits: decimals(radius),
            bounds: scene.world_bounds(),
            splats: scene.splats.len(),
            width: scene.camera.width,
            height: scene.camera.height,
            shading: (scene.options.shading, scene.shading_of.clone()),
            initial: cam,
            sensor: intrinsics.is_some().then_some(cam),
            kind: Kind::File {
                table,
                intrinsics,
                width: scene.camera.width,
                height: scene.camera.height,
                spp: scene.camera.spp,
            },
        };
        Ok((source, scene))
    }

    /// Samples per pixel of the full-quality frame (the input's).
    #[must_use]
    pub fn spp(&self) -> u32 {
        match &self.kind {
            Kind::Cloud { options, .. } => options.spp,
            Kind::File { spp, .. } => *spp,
        }
    }

    /// The scene text of `cam` rendered with `spp` samples, `shading`
    /// (`None`: the input's own) and the key light (the first directional
    /// light) travelling along `key` (`None`: as the input has it): the
    /// text "save scene" gives, and the one the viewer reads its camera and
    /// lights from.
    ///
    /// # Errors
    /// A camera that fails [`ViewCamera::check`]; a `key` that is not a
    /// finite non-zero vector, or a scene without a directional light; a
    /// path not UTF-8.
    pub fn text(
        &self,
        cam: &ViewCamera,
        spp: u32,
        shading: Option<ShadingMode>,
        key: Option<[f64; 3]>,
    ) -> Result<String> {
        let text = self.view_text(cam, spp, shading)?;
        let Some(dir) = key else {
            return Ok(text);
        };
        let d = DVec3::from(dir);
        if !d.is_finite() || d.length() == 0.0 {
            return Err(Error::invalid(
                "light: the direction must be a finite, non-zero vector",
            ));
        }
        // The text's leading comments kept, its tables re-written with the
        // key light aimed.
        let head: String = text
            .lines()
            .take_while(|l| l.starts_with('#') || l.is_empty())
            .map(|l| format!("{l}\n"))
            .collect();
        let mut t: toml::Table = text.parse().map_err(|e: toml::de::Error| Error::other(e))?;
        let light = t
            .get_mut("light")
            .and_then(toml::Value::as_array_mut)
            .and_then(|ls| {
                ls.iter_mut()
                    .filter_map(toml::Value::as_table_mut)
                    .find(|l| l.get("kind").and_then(toml::Value::as_str) == Some("directional"))
            })
            .ok_or_else(|| Error::invalid("light: the scene has no directional light to aim"))?;
        let round = |x: f64| (x * 1e4).round() / 1e4;
        let d = d.normalize();
        light.insert(
            "direction".into(),
            toml::Value::Array([d.x, d.y, d.z].map(|x| round(x).into()).to_vec()),
        );
        Ok(head + &toml::to_string(&t).map_err(Error::other)?)
    }

    fn view_text(
        &self,
        cam: &ViewCamera,
        spp: u32,
        shading: Option<ShadingMode>,
    ) -> Result<String> {
        cam.check()?;
        match &self.kind {
            Kind::Cloud {
                path,
                survey,
                view,
                options,
            } => {
                let v = if cam.sensor && view.sensor.is_some() {
                    view.clone()
                } else {
                    View {
                        from: DVec3::from(cam.from),
                        at: DVec3::from(cam.at),
                        up: unit(cam.up),
                        fov: cam.fov,
                        sensor: None,
                        note: "the view chosen in `splatray view`".into(),
                    }
                };
                let o = CloudSceneOptions {
                    spp,
                    shading: shading.or(options.shading),
                    ..*options
                };
                scene_text(path, survey, &v, &o)
            }
            Kind::File {
                table,
                intrinsics,
                width,
                height,
                ..
            } => {
                let mut t = table.clone();
                if let Some(m) = shading {
                    set_shading(&mut t, m);
                }
                let v = View {
                    from: DVec3::from(cam.from),
                    at: DVec3::from(cam.at),
                    up: unit(cam.up),
                    fov: cam.fov,
                    sensor: if cam.sensor { *intrinsics } else { None },
                    note: String::new(),
                };
                let o = CloudSceneOptions {
                    width: *width,
                    height: *height,
                    spp,
                    shading: None,
                };
                let mut text = format!(
                    "# {}, its camera the view chosen in `splatray view` (model paths absolute):\n\
                     # render it with `splatray render THIS.toml`.\n\n",
                    self.path.display()
                );
                text += &toml::to_string(&t).map_err(Error::other)?;
                text += "\n";
                camera_text(&mut text, &v, &o, self.digits);
                Ok(text)
            }
        }
    }
}

/// `v` made unit (a zero `v` is left to [`ViewCamera::check`]).
fn unit(v: [f64; 3]) -> DVec3 {
    DVec3::from(v).try_normalize().unwrap_or(DVec3::Y)
}

/// The whole scene shaded `m`: `[render] shading`, every material's own
/// left out.
fn set_shading(t: &mut toml::Table, m: ShadingMode) {
    let render = t
        .entry("render")
        .or_insert_with(|| toml::Value::Table(toml::Table::new()));
    if let Some(r) = render.as_table_mut() {
        r.insert("shading".into(), m.name().into());
    }
    if let Some(toml::Value::Array(models)) = t.get_mut("model") {
        for model in models.iter_mut().filter_map(toml::Value::as_table_mut) {
            if let Some(mat) = model
                .get_mut("material")
                .and_then(toml::Value::as_table_mut)
            {
                mat.remove("shading");
            }
        }
    }
}
