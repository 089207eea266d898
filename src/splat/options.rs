//! Splat generation's options as a user gives them, and the one place
//! they become [`SplatParams`].

use super::generate::{Creases, LeanMode, SplatParams};
use crate::data::PointCloud;
use glam::DVec3;

/// Splat generation's options as given (what `splat`, `scan-check`, a
/// scene's `[model.splat]` table and the Python package take); `None`:
/// the default of `SplatParams`. Every caller builds its parameters
/// here, once.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GenerationOptions {
    /// Error threshold ϵ of §2.1 as a fraction of the bounding-box diagonal.
    pub epsilon_rel: Option<f32>,
    /// Neighbours per point.
    pub k: Option<usize>,
    /// Density factor of §2.2, in (0, 1].
    pub density: Option<f32>,
    /// Elliptical splats along the minimum-curvature direction.
    pub ellipses: bool,
    /// One colour per splat: no linear colour fields.
    pub flat_colors: bool,
    /// Find creases and clip splats at them (`SplatParams::creases`):
    /// `Some(true)` everywhere, `Some(false)` nowhere, `None` the default
    /// (`crate::splat::Creases::Auto`).
    pub creases: Option<bool>,
    /// Where the scanner stood, in the input's coordinates (default: the
    /// cloud's own).
    pub viewpoint: Option<DVec3>,
    /// Ignore the cloud's own viewpoint (or its scanners' positions).
    pub no_viewpoint: bool,
    /// Keep one point per cell this many ϵ wide (default: a cloud far
    /// denser than ϵ needs is thinned unasked; 0 keeps every point).
    pub thin: Option<f64>,
    /// Never grow by lean growth (`SplatParams::lean`; by default it grows
    /// the splats where its gate finds the cloud suits it).
    pub no_lean: bool,
}

impl GenerationOptions {
    /// The generation parameters for `cloud`: the options given, defaults
    /// for the rest, the viewpoint given (made relative to the cloud's
    /// origin, in f64) or else the cloud's own.
    #[must_use]
    pub fn params(&self, cloud: &PointCloud) -> SplatParams {
        let viewpoint = if self.no_viewpoint {
            None
        } else {
            self.viewpoint
                .map(|v| cloud.local_viewpoint(v))
                .or(cloud.viewpoint)
        };
        SplatParams {
            viewpoint,
            ..self.params_without_viewpoint()
        }
    }

    /// The generation parameters before a cloud is read (tiled generation
    /// finds each tile's viewpoints itself).
    #[must_use]
    pub fn params_without_viewpoint(&self) -> SplatParams {
        let defaults = SplatParams::default();
        SplatParams {
            k: self.k.unwrap_or(defaults.k),
            epsilon_rel: self.epsilon_rel.unwrap_or(defaults.epsilon_rel),
            density: self.density.unwrap_or(defaults.density),
            ellipses: self.ellipses,
            color_fields: !self.flat_colors,
            creases: self.creases.map_or(defaults.creases, Creases::from_bool),
            scan_viewpoints: !self.no_viewpoint,
            thin: self.thin.unwrap_or(defaults.thin),
            auto_thin: self.thin.is_none(),
            lean: if self.no_lean { LeanMode::Off } else { LeanMode::Gated },
            ..defaults
        }
    }

    /// Whether an option of point clouds was given (they do not apply to a
    /// Gaussian splat file).
    pub fn point_options_given(&self) -> bool {
        self.epsilon_rel.is_some()
            || self.k.is_some()
            || self.density.is_some()
            || self.ellipses
            || self.creases.is_some()
    }
}
