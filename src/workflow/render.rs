//! The `render` workflow: a loaded scene through one backend of the
//! registry to a frame (the image and its AOVs), or one band of its rows,
//! with the render's typed report. The front end loads the scene, writes
//! the image, the AOVs and the report, and prints.

use crate::Result;
use crate::accel::registry;
use crate::progress::Progress;
use crate::render::integrator::{Frame, RayCounts, render, render_rows};
use crate::scene::Scene;

/// The rows of band `i` of `n` in an image `height` rows high.
#[must_use]
pub fn band_rows(height: u32, (i, n): (u32, u32)) -> std::ops::Range<u32> {
    let at = |k: u32| (u64::from(height) * u64::from(k) / u64::from(n)) as u32;
    at(i)..at(i + 1)
}

/// The render report (JSON).
#[derive(Debug, serde::Serialize)]
pub struct RenderReport {
    /// Backend name.
    pub backend: String,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Samples per pixel.
    pub spp: u32,
    /// Splats in the scene.
    pub splats: usize,
    /// Triangles in the scene (left out of the report when none).
    #[serde(skip_serializing_if = "is_zero")]
    pub triangles: usize,
    /// Seconds to read points and generate splats.
    pub splat_seconds: f64,
    /// Seconds to build the acceleration structure.
    pub build_seconds: f64,
    /// Seconds to render.
    pub render_seconds: f64,
    /// Rays by kind.
    pub rays: RayCounts,
    /// Millions of rays (all kinds) per second of render time.
    pub mrays_per_s: f64,
}

impl RenderReport {
    /// The report of one render.
    #[must_use]
    pub fn new(scene: &Scene, backend: &str, build_seconds: f64, frame: &Frame) -> RenderReport {
        RenderReport {
            backend: backend.to_string(),
            width: frame.width,
            height: frame.height,
            spp: scene.camera.spp,
            splats: scene.splats.len(),
            triangles: scene.triangles.tris.len(),
            splat_seconds: scene.load.splat_seconds,
            build_seconds,
            render_seconds: frame.seconds,
            rays: frame.rays,
            mrays_per_s: frame.rays.total() as f64 / frame.seconds.max(1e-9) / 1e6,
        }
    }
}

/// For reports: a count left out when zero.
pub(crate) fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// What [`render_scene`] gives.
#[derive(Debug)]
pub struct Rendered {
    /// The frame: the image and its AOVs (the band's rows only, with a
    /// band).
    pub frame: Frame,
    /// The report.
    pub report: RenderReport,
}

/// Renders `scene` with the registry's `backend`, the whole image or band
/// `band` = (I, N) of it ([`band_rows`]).
///
/// # Errors
/// A backend the registry does not know, or that does not build.
pub fn render_scene(
    scene: &Scene,
    backend: &str,
    band: Option<(u32, u32)>,
    progress: Option<Progress<'_>>,
) -> Result<Rendered> {
    let info = registry::lookup(backend)?;
    let built = info.build_scene(scene)?;
    let build_seconds = built.stats().build_seconds;
    let frame = match band {
        Some(b) => render_rows(
            scene,
            built.as_ref(),
            band_rows(scene.camera.height, b),
            progress,
        ),
        None => render(scene, built.as_ref(), progress),
    };
    let report = RenderReport::new(scene, info.name, build_seconds, &frame);
    Ok(Rendered { frame, report })
}
