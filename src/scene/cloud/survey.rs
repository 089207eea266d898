//! Step 1, the survey: the cloud read once ([`crate::io::read_any`]) and
//! what the camera and materials need to know of it — a sample of at most
//! [`SURVEY_SAMPLE`] points (every n-th) without the outliers splat
//! generation leaves out ([`crate::splat::outliers`]), its bounding box, the
//! file's viewpoint, whether it has colours, and an organised cloud's
//! sensor ([`crate::scene::sensor`]).

use crate::io::{CloudRead, Format, SplatSet, read_any};
use crate::scene::model::MAX_EXTENT;
use crate::scene::sensor::{Sensor, recover};
use crate::{Error, Result};
use glam::{DVec3, Vec3};
use std::path::Path;

/// Points of the cloud used for framing, at most.
pub const SURVEY_SAMPLE: usize = 20_000;
/// What the file holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CloudKind {
    /// Points (PLY, PCD, XYZ; a mesh PLY gives its vertices): a `points`
    /// model.
    Points,
    /// A splat PLY written by `splatray splat`: a `splats` model.
    Splats,
    /// A Gaussian splat PLY (2DGS or 3DGS layout): a `gaussians` model.
    Gaussians,
}

impl CloudKind {
    /// The scene file's key for this kind of model.
    #[must_use]
    pub fn key(self) -> &'static str {
        match self {
            CloudKind::Points => "points",
            CloudKind::Splats => "splats",
            CloudKind::Gaussians => "gaussians",
        }
    }
}

/// What the camera and materials need to know of a cloud.
#[derive(Clone, Debug)]
pub struct Survey {
    /// Points or splats.
    pub kind: CloudKind,
    /// Points (or splats) in the file.
    pub points: usize,
    /// Where the scanner stood, when the file says.
    pub viewpoint: Option<DVec3>,
    /// Whether the points carry colour.
    pub colors: bool,
    /// The framing sample without its outliers.
    pub sample: Vec<DVec3>,
    /// Sample points left out as outliers.
    pub outliers: usize,
    /// Bounding box of [`Survey::sample`].
    pub lo: DVec3,
    /// Bounding box of [`Survey::sample`].
    pub hi: DVec3,
    /// The sensor of an organised cloud (a PCD with `HEIGHT` > 1), or why
    /// none could be fitted.
    pub sensor: Option<std::result::Result<Sensor, String>>,
    /// Whether the file's format fixes `+z` as up (LAS and LAZ: z is
    /// elevation), so the up rules of [`super::up`] take it.
    pub z_is_elevation: bool,
}

impl Survey {
    /// Centre of the bounding box.
    #[must_use]
    pub fn center(&self) -> DVec3 {
        0.5 * (self.lo + self.hi)
    }

    /// Half the bounding box's diagonal (never zero).
    #[must_use]
    pub fn radius(&self) -> f64 {
        (0.5 * (self.hi - self.lo).length()).max(1e-30)
    }
}

/// Reads a cloud (points or a splat file) and surveys it.
///
/// # Errors
/// The reader's one-line error (no usable point among them).
pub fn survey_file(path: &Path) -> Result<Survey> {
    read_and_survey(path).map(|(s, _)| s)
}

/// [`survey_file`], and what was read, for the scene built from the survey
/// (`build_scene_read`): the file is read once.
///
/// # Errors
/// As [`survey_file`]; a cloud wider than the renderer's f32 geometry
/// holds ([`MAX_EXTENT`]).
pub fn read_and_survey(path: &Path) -> Result<(Survey, CloudRead)> {
    let (read, grid) = read_any(path)?;
    let s = match &read {
        CloudRead::Points(c) => {
            let colors = c.colors.as_ref().is_some_and(|k| k.len() == c.len());
            survey(
                CloudKind::Points,
                &c.positions,
                c.origin,
                c.viewpoint,
                colors,
            )
        }
        CloudRead::Splats(set) => survey_splats(CloudKind::Splats, set),
        CloudRead::Gaussians(g) => survey_splats(CloudKind::Gaussians, &g.set),
    };
    let mut s = s.map_err(|e| e.context(path.display()))?;
    s.sensor = grid.map(|g| recover(&g));
    s.z_is_elevation = matches!(read, CloudRead::Points(_)) && is_las(path);
    let span = 2.0 * s.radius();
    if span.is_nan() || span > f64::from(MAX_EXTENT) {
        return Err(Error::invalid(format!(
            "{}: the {} span {span:.2e}, beyond the {:e} the renderer's f32 geometry holds",
            path.display(),
            s.kind.key(),
            MAX_EXTENT
        )));
    }
    Ok((s, read))
}

/// Whether `path` is a LAS or LAZ file, by its extension or, for a
/// regular file without one, its first bytes (`LASF`; a pipe, already
/// read, is not opened again: that would wait for a writer).
fn is_las(path: &Path) -> bool {
    match Format::from_extension(path) {
        Some(f) => f == Format::Las,
        None => {
            std::fs::metadata(path).is_ok_and(|m| m.is_file())
                && crate::io::file_head(path).is_some_and(|h| Format::sniff(&h) == Some(Format::Las))
        }
    }
}

/// [`survey`] of a splat file's centres; it has colours when a splat is
/// not white.
fn survey_splats(kind: CloudKind, set: &SplatSet) -> Result<Survey> {
    let centres: Vec<Vec3> = set.splats.iter().map(|s| s.center).collect();
    let colors = set.splats.iter().any(|s| s.color != Vec3::ONE);
    survey(kind, &centres, set.origin, None, colors)
}

/// Surveys positions, offsets from `origin` (as the readers give them; the
/// viewpoint is in the same frame): a sample of at most [`SURVEY_SAMPLE`]
/// (every n-th point), its outliers removed, and its bounding box, all in
/// the file's coordinates.
///
/// # Errors
/// When no position is finite.
pub fn survey(
    kind: CloudKind,
    positions: &[Vec3],
    origin: DVec3,
    viewpoint: Option<Vec3>,
    colors: bool,
) -> Result<Survey> {
    let finite: Vec<Vec3> = positions
        .iter()
        .copied()
        .filter(|p| p.is_finite())
        .collect();
    if finite.is_empty() {
        return Err(Error::invalid("the cloud has no usable point"));
    }
    let stride = finite.len().div_ceil(SURVEY_SAMPLE);
    let sample: Vec<Vec3> = finite.iter().step_by(stride).copied().collect();
    let viewpoint = viewpoint.filter(|v| v.is_finite());
    let keep = inliers(&sample, viewpoint);
    let outliers = keep.iter().filter(|k| !**k).count();
    let sample: Vec<DVec3> = sample
        .iter()
        .zip(&keep)
        .filter(|(_, k)| **k)
        .map(|(p, _)| origin + p.as_dvec3())
        .collect();
    let (lo, hi) = sample.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    Ok(Survey {
        kind,
        points: positions.len(),
        viewpoint: viewpoint.map(|v| origin + v.as_dvec3()),
        colors,
        sample,
        outliers,
        lo,
        hi,
        sensor: None,
        z_is_elevation: false,
    })
}

/// Which sample points are not outliers, by the test splat generation
/// uses before growing splats ([`crate::splat::outliers`], on the sample's
/// 8 nearest neighbours; ranges from `viewpoint` when there is one). Exact
/// duplicates are kept with the point they repeat. Small samples (under 32
/// points) keep everything.
fn inliers(sample: &[Vec3], viewpoint: Option<Vec3>) -> Vec<bool> {
    const K: usize = 8;
    // Distinct points (the neighbour graph needs them), each with the
    // indices of the sample points at its position.
    let mut order: Vec<usize> = (0..sample.len()).collect();
    let key = |i: usize| sample[i].to_array().map(f32::to_bits);
    order.sort_by_key(|&i| key(i));
    let mut distinct: Vec<Vec3> = Vec::new();
    let mut slot = vec![0usize; sample.len()];
    for (j, &i) in order.iter().enumerate() {
        if j == 0 || key(order[j - 1]) != key(i) {
            distinct.push(sample[i]);
        }
        slot[i] = distinct.len() - 1;
    }
    if distinct.len() < 32 {
        return vec![true; sample.len()];
    }
    let out = crate::splat::outliers::find(
        &distinct,
        K,
        viewpoint.map(crate::splat::Viewpoints::One).as_ref(),
    );
    slot.iter().map(|&d| !out[d]).collect()
}
