//! Work bounded before it starts: a render's worst-case ray count and its
//! memory, estimated from the scene and checked against limits (the
//! machine's available memory unless told otherwise), so a scene or a flag
//! that asks for days of work or more memory than the machine has fails at
//! once, with the cost in the message and the flag that overrides it.

use crate::scene::{Light, Material, Scene};
use crate::{Error, Result};

/// Peak bytes per pixel of one rendered frame and its outputs: 64.5
/// measured (`render scenes/bunny.toml` at 1024² and 4096², PNG or EXR
/// with every AOV: 92.8 MB and 1,083.8 MB peak resident), and 8 more for
/// the two light-share AOVs (`Frame::light_lit`), rounded up.
pub const BYTES_PER_PIXEL: u64 = 80;

/// Peak bytes per splat of a loaded scene with one accelerator built: 550
/// measured for the octree, 300 for Embree (a 287,390-splat file rendered
/// at 64², 164 MB and 95 MB peak resident), rounded up. A triangle counts
/// its own [`BYTES_PER_TRIANGLE`].
pub const BYTES_PER_SPLAT: u64 = 640;

pub use crate::io::BYTES_PER_TRIANGLE;

/// The default cap on the worst-case rays of one render: about half an
/// hour at the 5 Mrays/s two cores trace on the bundled bunny.
pub const DEFAULT_MAX_RAYS: f64 = 1e10;

/// What a render may cost.
#[derive(Clone, Debug, PartialEq)]
pub struct Estimate {
    /// Upper bound on the rays traced (primary, secondary and shadow).
    pub rays: f64,
    /// Recursion paths per primary ray, at most: `2^max_depth - 1` with
    /// glass (each hit may both reflect and refract), `max_depth` with
    /// mirrors, else 1.
    pub paths: f64,
    /// Rays per path node, at most: the node's own ray and one shadow ray
    /// per light sample.
    pub rays_per_node: f64,
    /// Peak memory, bytes.
    pub bytes: u64,
}

/// The limits a render is checked against.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limits {
    /// Most rays (worst case).
    pub max_rays: f64,
    /// Most bytes; `None`: the machine's available memory.
    pub max_bytes: Option<u64>,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_rays: DEFAULT_MAX_RAYS,
            max_bytes: None,
        }
    }
}

/// What a run holds in memory at once while it renders.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Holds {
    /// Frames of the camera's size (a comparison keeps one per backend and
    /// the truth's).
    pub frames: u32,
    /// Accelerators built over the splats (a sweep builds every backend's
    /// before it renders).
    pub accelerators: u32,
}

impl Holds {
    /// One frame, one accelerator: a render.
    pub const ONE: Holds = Holds {
        frames: 1,
        accelerators: 1,
    };
}

/// The worst-case cost of rendering `scene` while holding `holds`.
#[must_use]
pub fn estimate(scene: &Scene, holds: Holds) -> Estimate {
    let cam = &scene.camera;
    let pixels = u64::from(cam.width) * u64::from(cam.height);
    let depth = f64::from(scene.options.max_depth.max(1));
    let glass = scene
        .materials
        .iter()
        .any(|m| matches!(m, Material::Glass { .. }));
    let mirror = scene
        .materials
        .iter()
        .any(|m| matches!(m, Material::Mirror { .. }));
    let paths = if glass {
        depth.exp2() - 1.0
    } else if mirror {
        depth
    } else {
        1.0
    };
    let shadow: f64 = scene
        .lights
        .iter()
        .map(|l| match l {
            Light::Sphere { samples, .. } => {
                let k = f64::from(*samples).sqrt().ceil();
                k * k
            }
            _ => 1.0,
        })
        .sum();
    let rays_per_node = 1.0 + shadow;
    let rays = pixels as f64 * f64::from(cam.spp) * paths * rays_per_node;
    let bytes = pixels
        .saturating_mul(BYTES_PER_PIXEL)
        .saturating_mul(u64::from(holds.frames.max(1)))
        .saturating_add(
            (scene.splats.len() as u64)
                .saturating_mul(BYTES_PER_SPLAT)
                .saturating_add(
                    (scene.triangles.tris.len() as u64).saturating_mul(BYTES_PER_TRIANGLE),
                )
                .saturating_mul(u64::from(holds.accelerators.max(1))),
        );
    Estimate {
        rays,
        paths,
        rays_per_node,
        bytes,
    }
}

/// Checks [`estimate`] against `limits`.
///
/// # Errors
/// More rays than `limits.max_rays`, or more memory than `limits.max_bytes`
/// (or than is available): one line with the cost, what makes it, and the
/// flag that raises the limit.
pub fn check(scene: &Scene, holds: Holds, limits: &Limits) -> Result<Estimate> {
    let e = estimate(scene, holds);
    let cam = &scene.camera;
    if e.rays > limits.max_rays {
        let why = if e.paths > 1.0 {
            format!(
                " x {:.0} paths (max_depth {}{})",
                e.paths,
                scene.options.max_depth,
                if e.paths > f64::from(scene.options.max_depth) {
                    ", glass: each hit may reflect and refract"
                } else {
                    ", mirrors"
                }
            )
        } else {
            String::new()
        };
        return Err(Error::invalid(format!(
            "the render may trace up to {:.2e} rays ({}x{} pixels x {} spp{why} x {:.0} rays per \
             hit with the lights' shadow samples), over the limit of {:.0e}: lower what makes \
             it, or raise the limit with --max-rays",
            e.rays, cam.width, cam.height, cam.spp, e.rays_per_node, limits.max_rays
        )));
    }
    let (limit, whose) = match limits.max_bytes {
        Some(b) => (Some(b), "the --max-memory limit"),
        None => match crate::memory::limit() {
            Some(b) => (Some(b.bytes), b.source),
            None => (None, ""),
        },
    };
    if let Some(limit) = limit
        && e.bytes > limit
    {
        let gb = |b: u64| b as f64 / 1e9;
        let tris = match scene.triangles.tris.len() {
            0 => String::new(),
            n => format!(" and {n} triangles x {BYTES_PER_TRIANGLE} B"),
        };
        return Err(Error::invalid(format!(
            "the render needs about {:.1} GB ({}x{} pixels x {BYTES_PER_PIXEL} B x {} \
             frame(s), {} splats x {BYTES_PER_SPLAT} B{tris} x {} accelerator(s)), over {whose} \
             ({:.1} GB): lower --width/--height, or pass --max-memory GB",
            gb(e.bytes),
            cam.width,
            cam.height,
            holds.frames,
            scene.splats.len(),
            holds.accelerators,
            gb(limit)
        )));
    }
    Ok(e)
}
