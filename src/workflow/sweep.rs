//! The `sweep` workflow: render time against error over the splat budget
//! and the shading mode (report §4.4, fig. 16), on a scene file whose
//! models are generated from points or meshes (`validate::sweep`). The
//! front end prints each row as it comes and writes the CSV and the plot.

use crate::progress::Progress;
use crate::scene::{SceneFile, parse_scene_file};
use crate::validate::sweep::{SweepPlan, SweepResult, run_sweep};
use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// What [`sweep`] is asked to do.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepRequest {
    /// The scene file (TOML).
    pub scene: PathBuf,
    /// Image width of every render.
    pub width: u32,
    /// Image height of every render.
    pub height: u32,
    /// Budget steps, spaced geometrically in epsilon (5 to 64).
    pub steps: usize,
    /// Coarsest epsilon (fraction of each model's bounding-box diagonal).
    pub eps_coarse: f32,
    /// Finest epsilon.
    pub eps_fine: f32,
}

impl SweepRequest {
    /// The checks made before anything is read: the steps and the
    /// resolution in range.
    ///
    /// # Errors
    /// One line naming the option.
    pub fn check(&self) -> Result<()> {
        if !(5..=64).contains(&self.steps) {
            return Err(Error::invalid(format!(
                "--steps {} must be in 5..=64",
                self.steps
            )));
        }
        if self.width == 0 || self.height == 0 || self.width > 1 << 15 || self.height > 1 << 15 {
            return Err(Error::invalid(format!(
                "resolution {}x{} must be in 1..=32768",
                self.width, self.height
            )));
        }
        Ok(())
    }
}

/// A sweep ready to run: its options checked, its plan made, its scene
/// read.
#[derive(Debug)]
pub struct Sweep {
    scene: PathBuf,
    plan: SweepPlan,
    file: SceneFile,
}

impl SweepRequest {
    /// Checks the options, makes the plan and reads the scene: every
    /// refusal before any work.
    ///
    /// # Errors
    /// An option out of range, an epsilon range that is not one, a scene
    /// that does not read.
    pub fn prepare(&self) -> Result<Sweep> {
        self.check()?;
        let plan = SweepPlan::geometric(
            self.eps_coarse,
            self.eps_fine,
            self.steps,
            self.width,
            self.height,
        )?;
        let file = parse_scene_file(&self.scene)?;
        Ok(Sweep {
            scene: self.scene.clone(),
            plan,
            file,
        })
    }
}

impl Sweep {
    /// Every budget step and shading mode rendered with every backend and
    /// measured against the exact surface, one row each, and the meshes
    /// as triangles on every backend (the mesh row; `log` hears each
    /// row's line as it is measured).
    ///
    /// # Errors
    /// A scene with no generated model, a model that does not build; one
    /// line naming the scene.
    pub fn run(
        &self,
        progress: Option<Progress<'_>>,
        log: &mut dyn FnMut(&str),
    ) -> Result<SweepResult> {
        let base = self.scene.parent().unwrap_or(Path::new("."));
        run_sweep(&self.file, base, &self.plan, progress, log)
            .map_err(|e| e.context(self.scene.display()))
    }
}

/// [`SweepRequest::prepare`], then `Sweep::run`.
///
/// # Errors
/// As those.
pub fn sweep(
    req: &SweepRequest,
    progress: Option<Progress<'_>>,
    log: &mut dyn FnMut(&str),
) -> Result<SweepResult> {
    req.prepare()?.run(progress, log)
}
