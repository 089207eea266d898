//! What several subcommands share: the splat generation options (`splat`,
//! `scan-check`), the default backend, writing a JSON report.

use crate::accel::registry;
use crate::workflow::splat::GenerationOptions;
use crate::{Error, Result};
use glam::DVec3;
use std::path::Path;

/// The splat generation options `splat` and `scan-check` share.
#[derive(Clone, Debug, clap::Args)]
pub struct SplatOptions {
    /// Error threshold ϵ of §2.1 as a fraction of the bounding-box diagonal
    /// (`SplatParams::epsilon_rel`; the report gives it in the cloud's units).
    #[arg(long = "epsilon")]
    pub epsilon_rel: Option<f32>,
    /// Neighbours per point.
    #[arg(long)]
    pub k: Option<usize>,
    /// Density factor of §2.2, in (0, 1].
    #[arg(long)]
    pub density: Option<f32>,
    /// Grow elliptical splats along the minimum-curvature direction.
    #[arg(long)]
    pub ellipses: bool,
    /// One colour per splat: no linear colour field fitted to a coloured
    /// cloud's points (`splat::color`; the fields are on by default).
    #[arg(long)]
    pub flat_colors: bool,
    /// Find creases, corners and borders and clip splats at them
    /// everywhere, also in a cloud sampled along scan lines (by default
    /// they are found but there; docs/usage.md, "Sharp edges").
    #[arg(long)]
    pub creases: bool,
    /// Whole discs: find no creases, corners or borders.
    #[arg(long, conflicts_with = "creases")]
    pub no_creases: bool,
    /// Where the scanner stood, as X,Y,Z in the input's coordinates:
    /// normals are oriented toward it. Default: the cloud's own (a PCD's
    /// VIEWPOINT).
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    pub viewpoint: Option<Vec<f64>>,
    /// Ignore the cloud's own viewpoint (or its scanners' positions).
    #[arg(long, conflicts_with = "viewpoint")]
    pub no_viewpoint: bool,
    /// Where the cloud is denser than ϵ needs, keep one point per cell this
    /// many ϵ wide (default: the widest of 0.25, 0.5 and 1 whose typical
    /// point's cell holds 8 or more points, 5 or more at 1, 0.5 only at
    /// `--epsilon` 0.008 or finer and 1 at 0.002 or finer, else every point;
    /// 0: every point).
    #[arg(long)]
    pub thin: Option<f64>,
    /// No lean growth: the stages (normals, creases, growth) on any cloud.
    /// By default lean growth (one plane fit a splat, no normal a point,
    /// several times faster) grows the splats of a clean, closed, densely
    /// sampled surface without creases, where its gate finds one, and of
    /// such a cloud with creases and borders (a solid's samples, an
    /// airborne survey, a clean scan), its splats clipped there
    /// (docs/usage.md, "Lean growth").
    #[arg(long)]
    pub no_lean: bool,
}

impl SplatOptions {
    /// The viewpoint given on the command line, checked.
    ///
    /// # Errors
    /// Not three finite numbers.
    pub fn viewpoint(&self) -> Result<Option<DVec3>> {
        match self.viewpoint.as_deref() {
            None => Ok(None),
            Some([x, y, z]) if [x, y, z].iter().all(|v| v.is_finite()) => {
                Ok(Some(DVec3::new(*x, *y, *z)))
            }
            Some(v) => Err(Error::invalid(format!(
                "--viewpoint needs three finite numbers, got {v:?}"
            ))),
        }
    }

    /// The library's generation options: these, the viewpoint checked.
    ///
    /// # Errors
    /// A malformed viewpoint.
    pub fn generation(&self) -> Result<GenerationOptions> {
        Ok(GenerationOptions {
            epsilon_rel: self.epsilon_rel,
            k: self.k,
            density: self.density,
            ellipses: self.ellipses,
            flat_colors: self.flat_colors,
            creases: (self.creases || self.no_creases).then_some(self.creases),
            viewpoint: self.viewpoint()?,
            no_viewpoint: self.no_viewpoint,
            thin: self.thin,
            no_lean: self.no_lean,
        })
    }
}

/// The default backend: the registry's first.
pub fn default_backend() -> String {
    registry::names()[0].to_string()
}

/// Writes `value` as pretty JSON to `path`, atomically.
pub fn write_json<T: serde::Serialize>(path: &Path, value: &T) -> Result<()> {
    crate::io::write_text(path, &(super::json_text(value)? + "\n"))?;
    Ok(())
}
