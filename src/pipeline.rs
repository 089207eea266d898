//! Points in, finished splats out: the one entry to splat generation,
//! [`generate`]. Every caller goes through it: the command line
//! (`workflow::splat`), scene loading, each tile of tiled generation, the
//! photo and scan checks, the held-out check, Python and Dask. Its stages
//! run in order, each timed in the report's `seconds` and named in the
//! progress line:
//!
//! 1. cleaning, thinning and the neighbourhood graph of §2, statistical
//!    outliers left out (`knn`);
//! 2. normals, faces and creases (`normals`);
//! 3. seeds and growth with density control (§2.1–2.2, eqs. 1–3), clip
//!    lines where a face ends, crease partners and no disc over a hole
//!    (`grow`);
//! 4. normal fields (§4.1, eq. 4) and the coverage check (`fit`);
//! 5. free-space trimming along the scanner's lines of sight, where the
//!    cloud has a viewpoint (`trim`, [`crate::freespace`]);
//! 6. colour fields, where the cloud has colours and the parameters ask
//!    for them (`colors`, [`crate::splat::color`]).
//!
//! Stages 1–4 are [`crate::splat::generate_with_progress`]; trimming leaves
//! out the lines of sight of the points stage 1 left out as outliers. Reading comes
//! before (the caller's `read` seconds) and the held-out check after
//! (`validate::holdout`, which grows its own splats through this entry).

use crate::freespace::{TrimReport, trim_free_space};
use crate::progress::{Progress, notify};
use crate::splat::color::{ColorField, fit_cloud};
use crate::splat::{PointCloud, Splat, SplatParams, SplatReport, generate_stages};
use crate::{Error, Result};
use std::time::Instant;

/// What `generate` made.
#[derive(Clone, Debug)]
pub struct Generated {
    /// The splats, positions relative to the cloud's origin.
    pub splats: Vec<Splat>,
    /// What generation found and what each stage took.
    pub report: SplatReport,
    /// What free-space trimming did (`None`: the cloud has no viewpoint).
    pub trim: Option<TrimReport>,
    /// One colour field per splat, or none (no colours, one colour, or
    /// `SplatParams::color_fields` off).
    pub color_fields: Vec<ColorField>,
    /// How many of those are zero (a constant colour).
    pub constant_color_fields: usize,
}

/// The splats of `cloud` with `params`, through every stage of the
/// pipeline (see the module's documentation).
///
/// # Errors
/// As [`generate_with_progress`], and a viewpoint that is not finite.
pub fn generate(
    cloud: &PointCloud,
    params: &SplatParams,
    progress: Option<Progress<'_>>,
) -> Result<Generated> {
    run(cloud, params, true, progress)
}

/// [`generate`] without its last stage, the colour fields: for checks that
/// look at the surface alone (the held-out check). Everything else, the
/// trimming's treatment of a coloured cloud included, is as [`generate`].
///
/// # Errors
/// As [`generate`].
pub fn generate_uncoloured(
    cloud: &PointCloud,
    params: &SplatParams,
    progress: Option<Progress<'_>>,
) -> Result<Generated> {
    run(cloud, params, false, progress)
}

fn run(
    cloud: &PointCloud,
    params: &SplatParams,
    colours: bool,
    progress: Option<Progress<'_>>,
) -> Result<Generated> {
    let (mut splats, mut report, outliers) =
        generate_stages(cloud, params, progress).map_err(Error::from)?;
    let t0 = Instant::now();
    let trim = trim_free_space(cloud, params, &mut splats, &mut report, &outliers, progress)?;
    let t1 = Instant::now();
    let (color_fields, constant_color_fields) =
        if colours && params.color_fields && cloud.colors.is_some() {
            notify(progress, "colour fields", 0.0);
            fit_cloud(&mut splats, cloud, params)
        } else {
            (Vec::new(), 0)
        };
    let t2 = Instant::now();
    report.seconds.trim = (t1 - t0).as_secs_f64();
    report.seconds.colors = (t2 - t1).as_secs_f64();
    report.seconds.total += (t2 - t0).as_secs_f64();
    Ok(Generated {
        splats,
        report,
        trim,
        color_fields,
        constant_color_fields,
    })
}
