//! The `scan-check` workflow: a scan as its own ground truth. Some points
//! are held out, splats grown from the rest, and a line of sight cast from
//! the scanner to every held-out point (`validate::scan_check`); or, for an
//! organised colour capture, the photo check (`validate::photo`): held-out
//! pixels seen from the sensor against the captured colours. The library
//! reads the scan (and its organised grid) itself; the front end prints.

use super::splat::GenerationOptions;
use crate::io::{IoError, IoErrorKind, read_organised, read_points};
use crate::progress::Progress;
use crate::validate::photo::{PhotoReport, photo_check};
use crate::validate::scan_check::{ScanCheckParams, ScanCheckReport, scan_check as check_lines};
use crate::{Error, Result};
use serde::Serialize;
use std::path::PathBuf;

/// What [`scan_check`] is asked to do.
#[derive(Clone, Debug, PartialEq)]
pub struct ScanCheckRequest {
    /// The scan (a PCD with its VIEWPOINT, or any point file with
    /// `generation.viewpoint`).
    pub input: PathBuf,
    /// Splat generation options; the viewpoint is also where the lines of
    /// sight start.
    pub generation: GenerationOptions,
    /// A hit within this fraction of the point's distance is consistent.
    pub tolerance: f32,
    /// Fraction of the points held out and checked.
    pub holdout: f32,
    /// Seed of the hold-out choice.
    pub seed: u64,
    /// The photo check of an organised colour capture instead.
    pub photo: bool,
    /// The backend the photo check renders with.
    pub backend: String,
}

/// What [`scan_check`] measured.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(untagged)]
pub enum ScanCheckOutcome {
    /// The lines of sight.
    Lines(Box<ScanCheckReport>),
    /// The photo check.
    Photo(PhotoReport),
}

/// Runs the check `req` asks for, reporting progress.
///
/// # Errors
/// An unreadable scan, no viewpoint, a cloud that is not organised for
/// the photo check, bad options; each one line naming the scan.
pub fn scan_check(
    req: &ScanCheckRequest,
    progress: Option<Progress<'_>>,
) -> Result<ScanCheckOutcome> {
    let cloud = read_points(&req.input)?;
    let splat = req.generation.params(&cloud);
    let name = req.input.display();
    if req.photo {
        let bytes =
            std::fs::read(&req.input).map_err(|e| IoError::new(&req.input, IoErrorKind::Io(e)))?;
        let grid = read_organised(&bytes)
            .map_err(|k| IoError::new(&req.input, k))?
            .ok_or_else(|| {
                Error::invalid(format!(
                    "{name}: --photo needs an organised cloud (a PCD with HEIGHT > 1 and colours)"
                ))
            })?;
        let r = photo_check(&grid, &splat, req.holdout, req.seed, &req.backend)
            .map_err(|e| e.context(&name))?;
        return Ok(ScanCheckOutcome::Photo(r));
    }
    if req.generation.no_viewpoint {
        return Err("scan-check needs the scanner's viewpoint: drop --no-viewpoint".into());
    }
    let params = ScanCheckParams {
        viewpoint: splat.viewpoint,
        splat,
        tolerance: req.tolerance,
        holdout: req.holdout,
        seed: req.seed,
    };
    let r = check_lines(&cloud, &params, progress).map_err(|e| e.context(&name))?;
    Ok(ScanCheckOutcome::Lines(Box::new(r)))
}
