//! Lines of sight are free space: where the scanner's viewpoint is known,
//! every scanned point was seen from it, so no splat may cross the segment
//! from the viewpoint to a point short of that point. Splats at a
//! foreground edge overhang the silhouette by up to their radius and would
//! hide the background the scanner saw just beyond it; they are shrunk
//! away from the lines of sight they block. A line of sight on which no
//! splat stands near its point (within the margin) is not blocked: the
//! splat in front is then the point's own surface, which range noise left
//! in front of it, and shrinking it would open a hole in that surface.

use crate::accel::octree::{Octree, OctreeParams};
use crate::accel::{Backend, CandidateHits, Ray};
use crate::splat::{
    PointCloud, Splat, SplatParams, SplatReport, Viewpoints, generate_with_progress, outliers,
};
use crate::{Error, Result};
use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// Most passes of trimming (they stop when no line is blocked): a shrunk
/// splat can uncover a splat behind it that blocks the same line of sight,
/// and each pass shrinks a splat once. On `lamppost-ascii.pcd` 3 passes left
/// 115 of 305 blocked lines blocked, 8 leave 12.
pub const PASSES: usize = 8;

/// A hit counts as blocking when it lies more than this many `ϵ` (the
/// growth threshold of eq. 1) in front of the point: closer hits are the
/// point's own surface, within the noise the splats were grown to.
pub const MARGIN_EPS: f32 = 2.0;

/// A hit also counts as the point's own surface within this many times the
/// cloud's noise (the points' scatter about their local planes,
/// [`SplatReport::noise`]): a point pushed behind its surface by range noise
/// is seen through that surface's splats.
pub const MARGIN_NOISE: f32 = 3.0;

/// The margin is measured across the blocking splat (the point's depth
/// behind its plane): seen at a grazing angle, the point's own surface
/// meets the line of sight far in front of a point pushed behind it by
/// noise. Along the line of sight, a hit more than this many margins in
/// front of the point blocks at any angle (a foreground edge overhanging the
/// background is seen at a grazing angle too).
pub const MARGIN_ALONG: f32 = 2.0;

/// If more than this fraction of the lines of sight are blocked, the
/// viewpoint is not the scanner's (a cloud registered from several scans,
/// or a default `VIEWPOINT`): nothing is trimmed and a warning says so.
pub const IMPLAUSIBLE: f64 = 0.2;

/// If more than this share of the points face away from the viewpoint
/// ([`SplatReport::facing_away`]), the viewpoint is not the scanner's:
/// nothing is trimmed and a warning says so. Single scans measure under
/// 0.01 % (the synthetic bunny scans, milk.pcd); the bundled lamppost,
/// points on every side of a pole and few on the side facing its
/// default `VIEWPOINT`, 14 %.
pub const FACING_AWAY_MAX: f64 = 0.05;

/// What trimming did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct TrimReport {
    /// Lines of sight cast per pass.
    pub rays: usize,
    /// Lines blocked in the first pass.
    pub blocked: usize,
    /// Splats shrunk (over all passes).
    pub shrunk: usize,
    /// Lines still blocked after the last pass.
    pub still_blocked: usize,
    /// True when the viewpoint looked implausible and nothing was trimmed.
    pub skipped: bool,
}

/// The line of sight from `viewpoint` to `point`: the ray and the point's
/// distance along it; `None` when they coincide.
#[must_use]
pub fn sight_line(viewpoint: Vec3, point: Vec3) -> Option<(Ray, f32)> {
    let dir = (point - viewpoint).try_normalize()?;
    Some((
        Ray {
            origin: viewpoint,
            dir,
        },
        (point - viewpoint).length(),
    ))
}

/// For every point, the first splat blocking its line of sight (more than
/// `margin` in front of it, see [`MARGIN_ALONG`]), with the hit's
/// normalised disc coordinates; only when some splat stands within
/// `margin` of the point on that line (its own surface, which the blocking
/// splat hides). Without one, the splat in front is the point's surface
/// itself, standing in front of it by the noise of a coarse scan, and it
/// is kept: shrinking it would open a hole through that surface along the
/// line, which a camera near the scanner looks through (on
/// `scenes/scan-lines.toml` such holes show the floor through the bunny;
/// `docs/development.md`, "Issue 23: the specks' causes, and shadow rays
/// that see the surface").
fn blocked(
    splats: &[Splat],
    points: &[Vec3],
    vp: &Viewpoints,
    margin: f32,
) -> Vec<Option<(u32, Vec2)>> {
    let discs: Vec<_> = splats.iter().map(Splat::disc_geometry).collect();
    let octree = Octree::new(&discs, &OctreeParams::default());
    points
        .par_iter()
        .enumerate()
        .with_min_len(512)
        .map_init(
            || CandidateHits::new(0.0),
            |hits, (i, &p)| {
                let (ray, d) = sight_line(vp.at(i), p)?;
                let t_max = d - margin;
                if t_max <= 0.0 {
                    return None;
                }
                octree.intersect(&ray, 0.0, t_max, hits);
                let h = hits.nearest()?;
                let depth = d - h.t;
                let cos = splats[h.id as usize].normal.dot(ray.dir).abs();
                let blocks =
                    depth > margin && (depth * cos > margin || depth > MARGIN_ALONG * margin);
                if !blocks {
                    return None;
                }
                let q = (h.id, Vec2::new(h.u, h.v));
                octree.intersect(&ray, d - margin, d + margin, hits);
                (!hits.is_empty()).then_some(q)
            },
        )
        .collect()
}

/// Shrinks splat `s` so the normalised disc point `q` (|q| ≤ 1) falls just
/// outside it: the new disc lies inside the old one, touching it on the
/// side away from `q`, so the splat keeps as much of its surface as it can.
fn shrink_away(s: &mut Splat, q: Vec2) {
    let len = q.length();
    let dir = if len > 1e-6 { q / len } else { Vec2::X };
    // New centre at -a·dir, radius 1 - a (normalised); q at distance
    // len + a must exceed it: a > (1 - len) / 2.
    let a = ((1.0 - len) * 0.5 + 0.01).min(0.95);
    let shift = -a * dir;
    s.center += s.u_axis * (shift.x * s.radii.x) + s.v_axis * (shift.y * s.radii.y);
    s.radii *= 1.0 - a;
    // The same field over the smaller disc: old (u, v) = shift + (1-a)(u', v')
    // in eq. (4)'s normalised coordinates.
    let f = &mut s.field;
    f.xc += f.alpha * shift.x;
    f.yc += f.beta * shift.y;
    f.alpha *= 1.0 - a;
    f.beta *= 1.0 - a;
}

/// Trims `splats` so that no line of sight from its viewpoint to one of
/// `points` is blocked more than `margin` in front of its point.
#[must_use]
pub fn trim(
    splats: &mut [Splat],
    points: &[Vec3],
    viewpoint: &Viewpoints,
    margin: f32,
) -> TrimReport {
    let mut report = TrimReport {
        rays: points.len(),
        ..TrimReport::default()
    };
    if splats.is_empty() || points.is_empty() {
        return report;
    }
    for pass in 0..PASSES {
        let b = blocked(splats, points, viewpoint, margin);
        let count = b.iter().flatten().count();
        if pass == 0 {
            report.blocked = count;
            if count as f64 > IMPLAUSIBLE * points.len() as f64 {
                report.skipped = true;
                report.still_blocked = count;
                return report;
            }
        }
        if count == 0 {
            report.still_blocked = 0;
            return report;
        }
        // One shrink per splat per pass, away from its most central
        // violation (the one that needs the largest cut).
        let mut worst: Vec<Option<Vec2>> = vec![None; splats.len()];
        for (id, q) in b.into_iter().flatten() {
            let w = &mut worst[id as usize];
            if w.is_none_or(|o| q.length() < o.length()) {
                *w = Some(q);
            }
        }
        for (s, w) in splats.iter_mut().zip(worst) {
            if let Some(q) = w {
                shrink_away(s, q);
                report.shrunk += 1;
            }
        }
    }
    report.still_blocked = blocked(splats, points, viewpoint, margin)
        .iter()
        .flatten()
        .count();
    report
}

/// Splat generation ([`generate_with_progress`]) followed, when the
/// parameters carry a viewpoint, by free-space trimming against the
/// cloud's points (its outliers left out, as generation leaves them out).
///
/// # Errors
/// As [`generate_with_progress`].
pub fn generate_trimmed(
    cloud: &PointCloud,
    params: &SplatParams,
    progress: Option<crate::progress::Progress<'_>>,
) -> Result<(Vec<Splat>, SplatReport, Option<TrimReport>)> {
    let (mut splats, mut report) = generate_with_progress(cloud, params, progress)?;
    let Some(vp) = crate::splat::viewpoints_of(cloud, params) else {
        return Ok((splats, report, None));
    };
    if !vp.is_finite() {
        return Err(Error::invalid("the viewpoint must be finite"));
    }
    if let Some(away) = report.facing_away.filter(|&a| a > FACING_AWAY_MAX) {
        report.warnings.push(format!(
            "{:.1} % of the points face away from the viewpoint, which a scanner cannot see: it \
             is not the scanner's position (a cloud registered from several scans, or a default \
             VIEWPOINT), so no splat was trimmed (give --viewpoint, or --no-viewpoint)",
            100.0 * away
        ));
        return Ok((
            splats,
            report,
            Some(TrimReport {
                skipped: true,
                ..TrimReport::default()
            }),
        ));
    }
    crate::progress::notify(progress, "free space", 0.0);
    let flags = if params.remove_outliers {
        outliers::find(&cloud.positions, report.k.max(1), Some(&vp))
    } else {
        vec![false; cloud.len()]
    };
    let drop: Vec<bool> = cloud
        .positions
        .iter()
        .zip(&flags)
        .map(|(p, o)| *o || !p.is_finite())
        .collect();
    let points: Vec<Vec3> = cloud
        .positions
        .iter()
        .zip(&drop)
        .filter(|(_, d)| !**d)
        .map(|(p, _)| *p)
        .collect();
    let mut vp = vp;
    vp.retain(&drop);
    let margin = (MARGIN_EPS * report.epsilon as f32).max(MARGIN_NOISE * report.noise as f32);
    let t = trim(&mut splats, &points, &vp, margin);
    if t.skipped {
        report.warnings.push(format!(
            "{:.1} % of the lines of sight from the viewpoint are blocked: it does not look like \
             the scanner's position, so no splat was trimmed (give --viewpoint, or --no-viewpoint)",
            100.0 * t.blocked as f64 / t.rays.max(1) as f64
        ));
    }
    Ok((splats, report, Some(t)))
}
