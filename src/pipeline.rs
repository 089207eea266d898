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
//! before (the caller's `read` seconds). The held-out check
//! (`validate::holdout`, which grows its own splats through this entry)
//! reads only what stages 1–3 set, so [`generate_beside`] runs it beside
//! stages 4–6 once the splats are grown: its serial parts fill the cores
//! that theirs leave idle.

use crate::freespace::{TrimReport, trim_free_space};
use crate::progress::{Progress, notify};
use crate::splat::color::{ColorField, fit_cloud};
use crate::splat::{Grown, PointCloud, Splat, SplatParams, SplatReport, generate_stages};
use crate::{Error, Result};
use std::sync::Mutex;
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
    run(cloud, params, true, progress, None)
}

/// What [`generate_beside`] ran beside the pipeline.
#[derive(Clone, Debug)]
pub struct Beside<R> {
    /// Its answer (`None`: generation failed before the splats were grown).
    pub value: Option<R>,
    /// The wall seconds the pipeline waited for it after its own last stage.
    pub waited: f64,
}

impl<R> Beside<R> {
    /// Nothing ran beside.
    #[must_use]
    pub fn none() -> Beside<R> {
        Beside {
            value: None,
            waited: 0.0,
        }
    }
}

/// [`generate`], with `beside` run once the splats are grown, on the same
/// threads as the stages after growth, given the report as it will end
/// for everything those stages leave alone (`ϵ`, the noise, the diagonal
/// and the splats' mean radius, in the cloud's units; see
/// [`crate::splat::generate_with_progress`]) and the points it left out as
/// outliers (indices into `cloud`, ascending). The progress names `stage`
/// while the pipeline waits for it.
///
/// # Errors
/// As [`generate`] (the value `beside` made is then dropped).
pub fn generate_beside<R: Send>(
    cloud: &PointCloud,
    params: &SplatParams,
    progress: Option<Progress<'_>>,
    stage: &str,
    beside: impl Fn(&SplatReport, &[u32]) -> R + Sync,
) -> Result<(Generated, Beside<R>)> {
    let value = Mutex::new(None);
    let (generated, done) = rayon::scope(|s| {
        let (beside, value) = (&beside, &value);
        let grown = |whole: &SplatReport, left_out: &[u32]| {
            let (whole, left_out) = (whole.clone(), left_out.to_vec());
            s.spawn(move |_| {
                let r = beside(&whole, &left_out);
                *value.lock().unwrap_or_else(std::sync::PoisonError::into_inner) = Some(r);
            });
        };
        let generated = run(cloud, params, true, progress, Some(&grown as Grown<'_>));
        let pending = value.lock().map_or(true, |v| v.is_none());
        if generated.is_ok() && pending {
            notify(progress, stage, 0.0);
        }
        (generated, Instant::now())
    });
    let waited = done.elapsed().as_secs_f64();
    let value = value.into_inner().unwrap_or_else(std::sync::PoisonError::into_inner);
    Ok((generated?, Beside { value, waited }))
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
    run(cloud, params, false, progress, None)
}

fn run(
    cloud: &PointCloud,
    params: &SplatParams,
    colours: bool,
    progress: Option<Progress<'_>>,
    grown: Option<Grown<'_>>,
) -> Result<Generated> {
    let (mut splats, mut report, outliers) =
        generate_stages(cloud, params, progress, grown).map_err(Error::from)?;
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
