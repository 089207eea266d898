//! No disc over a hole: how much of a splat's kept (clipped) disc its
//! points cover, and the large splats that cover less than half of it
//! shrunk to the part they cover, the points they then leave bare given
//! small splats of their own.
//!
//! Growth (§2.1, eqs. 1–3) takes the smallest disc over the points it
//! accepted; where those points are two clusters across a gap (a floor's
//! edge and a stray row of points past it, a surface and the spray of a
//! scanner's mixed pixels) the disc spans the gap, a sheet no surface
//! holds. The centre-based rule of growth (`grow::HOLLOW_SHARE`) catches a
//! ring round an empty middle, not a disc whose centre sits on its seed.

use super::knn::{Knn, PointTree};
use crate::data::Splat;
use glam::{Vec2, Vec3};
use kiddo::SquaredEuclidean;
use kiddo::immutable::float::kdtree::ImmutableKdTree;
use rayon::prelude::*;

/// A splat counts as large for [`super::SplatReport::uncovered_large_splats`]
/// (and for [`shrink_uncovered`]) above this many times the median radius.
pub const UNCOVERED_LARGE: f32 = 5.0;

/// A sample of a splat's disc is covered where a point lies within this
/// many local spacings of it. The spacing is the densest the disc
/// touches: a low quantile ([`SPACING_QUANTILE`]), over the points
/// nearest its samples, of the k-th neighbour distance over `sqrt(k / π)`
/// (the side of the square each of `k` points holds), so a disc reaching
/// from a dense floor to a sparse stray row counts the gap between them as
/// uncovered.
pub const COVER_SPACINGS: f32 = 3.0;

/// The spacing a disc is measured in is the `1 / SPACING_QUANTILE`
/// quantile of its samples' nearest points' spacings: the densest it
/// touches over a tenth of it, not one dense cluster's (the least of them
/// made a disc of the bundled dinosaur scan covered or not as its frame
/// turned, 1.0 against 0.29).
const SPACING_QUANTILE: usize = 10;

/// Samples across a disc's diameter, less one ([`cover_samples`]).
const ACROSS: i32 = 20;

/// The samples of `s`'s kept disc (a grid `ACROSS + 1` wide over the
/// disc, in normalised splat coordinates, those its clip lines keep), each
/// with whether a point of `tree` lies within [`COVER_SPACINGS`] local
/// spacings of it (from `knn`). With `scan_lines` (a graph widened to
/// join the lines of a scan), the spacing is the k-th neighbour distance
/// itself: the gap between two lines is the sampling there, not a hole.
fn cover_samples(s: &Splat, tree: &PointTree, knn: &Knn, scan_lines: bool) -> Vec<(Vec2, bool)> {
    let half = ACROSS / 2;
    let per = if scan_lines {
        1.0
    } else {
        (std::f32::consts::PI / knn.k.max(1) as f32).sqrt()
    };
    let mut near: Vec<(Vec2, f32)> = Vec::new();
    let mut spacings: Vec<f32> = Vec::new();
    for y in -half..=half {
        for x in -half..=half {
            let q = Vec2::new(x as f32, y as f32) / half as f32;
            if q.length_squared() > 1.0 || !s.clip.keeps(q.x, q.y) {
                continue;
            }
            let w = s.center + s.u_axis * (q.x * s.radii.x) + s.v_axis * (q.y * s.radii.y);
            let nn = tree.nearest_one::<SquaredEuclidean>(&w.to_array());
            near.push((q, nn.distance));
            spacings.push(per * knn.kth_distance[nn.item as usize]);
        }
    }
    if spacings.is_empty() {
        return Vec::new();
    }
    let low = spacings.len() / SPACING_QUANTILE;
    let spacing = *spacings.select_nth_unstable_by(low, f32::total_cmp).1;
    let reach2 = (COVER_SPACINGS * spacing) * (COVER_SPACINGS * spacing);
    near.into_iter().map(|(q, d)| (q, d <= reach2)).collect()
}

/// The share of `s`'s kept (clipped) disc that points cover: of a grid of
/// samples over the disc (21 across) that its clip lines keep, those with
/// a point of `tree` within [`COVER_SPACINGS`] local spacings (from `knn`;
/// `scan_lines` as in a cloud whose graph was widened for scan lines,
/// where the k-th neighbour distance itself is the spacing).
#[must_use]
pub fn covered_share(s: &Splat, tree: &PointTree, knn: &Knn, scan_lines: bool) -> f32 {
    share(&cover_samples(s, tree, knn, scan_lines))
}

/// The covered share of `samples` (1 for none).
fn share(samples: &[(Vec2, bool)]) -> f32 {
    if samples.is_empty() {
        return 1.0;
    }
    samples.iter().filter(|c| c.1).count() as f32 / samples.len() as f32
}

/// The median of the splats' larger radii (0 for none).
pub(crate) fn median_radius(splats: &[Splat]) -> f32 {
    let mut radii: Vec<f32> = splats.iter().map(|s| s.radii.max_element()).collect();
    if radii.is_empty() {
        return 0.0;
    }
    let mid = radii.len() / 2;
    *radii.select_nth_unstable_by(mid, f32::total_cmp).1
}

/// How many splats wider than [`UNCOVERED_LARGE`] times the median radius
/// have less than half their kept disc covered by points
/// ([`covered_share`]; `scan_lines` as there).
#[must_use]
pub fn uncovered_large(splats: &[Splat], tree: &PointTree, knn: &Knn, scan_lines: bool) -> usize {
    uncovered_large_measured(splats, &Measured::default(), tree, knn, scan_lines)
}

/// [`uncovered_large`], taking a splat's share from `measured` where it was
/// measured on the same disc (centre, axes, radii and clip lines; its
/// normal field may have been fitted since).
pub(crate) fn uncovered_large_measured(
    splats: &[Splat],
    measured: &Measured,
    tree: &PointTree,
    knn: &Knn,
    scan_lines: bool,
) -> usize {
    let median = median_radius(splats);
    splats
        .par_iter()
        .enumerate()
        .filter(|(i, s)| {
            s.radii.max_element() > UNCOVERED_LARGE * median
                && measured
                    .share_of(*i, s)
                    .unwrap_or_else(|| covered_share(s, tree, knn, scan_lines))
                    < 0.5
        })
        .count()
}

/// The covered shares [`shrink_uncovered`] measured of the splats it left
/// as they were, by splat index (ascending), each with the splat it
/// measured.
#[derive(Clone, Debug, Default)]
pub(crate) struct Measured(Vec<(u32, Splat, f32)>);

impl Measured {
    /// The share measured of splat `i`, if `s` has the disc it was
    /// measured on.
    fn share_of(&self, i: usize, s: &Splat) -> Option<f32> {
        let k = self.0.binary_search_by_key(&i, |m| m.0 as usize).ok()?;
        let (_, was, share) = &self.0[k];
        let same = was.center == s.center
            && was.u_axis == s.u_axis
            && was.v_axis == s.v_axis
            && was.radii == s.radii
            && was.clip == s.clip;
        same.then_some(*share)
    }
}

/// Does `p` lie on `s`: within `epsilon` of its plane, inside its disc and
/// on the kept side of its clip lines?
#[must_use]
pub fn on_splat(s: &Splat, p: Vec3, epsilon: f32) -> bool {
    let d = p - s.center;
    if d.dot(s.normal).abs() > epsilon {
        return false;
    }
    let (u, v) = (d.dot(s.u_axis) / s.radii.x, d.dot(s.v_axis) / s.radii.y);
    u * u + v * v <= 1.0 && s.clip.keeps(u, v)
}

/// What [`shrink_uncovered`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Shrunk {
    /// Splats shrunk to the part of their disc their points cover.
    pub shrunk: usize,
    /// Small splats added for the points a shrunk splat left on none.
    pub added: usize,
}

/// A shrunk splat is shrunk further, around its new centre, while its
/// points cover less than this share of it: it stands over what they
/// cover, not half over the gap it spanned.
pub const SHRUNK_COVERS: f32 = 0.9;

/// At most this many times, each to this share of the radius before
/// ([`SHRINK`]).
const SHRINK_STEPS: usize = 8;
/// See [`SHRINK_STEPS`].
const SHRINK: f32 = 0.7;

/// The largest 4-connected cluster of covered samples of `samples` (the
/// grid of [`cover_samples`]): its centre (mean) and the radius, from
/// that centre, that holds every one of its samples with half a grid step
/// to spare; `None` with no covered sample.
fn covered_part(samples: &[(Vec2, bool)]) -> Option<(Vec2, f32)> {
    let half = ACROSS / 2;
    let w = (ACROSS + 1) as usize;
    let cell = |q: Vec2| {
        let x = (q.x * half as f32).round() as i32 + half;
        let y = (q.y * half as f32).round() as i32 + half;
        (y as usize) * w + x as usize
    };
    let mut at = vec![usize::MAX; w * w];
    for (k, &(q, c)) in samples.iter().enumerate() {
        if c {
            at[cell(q)] = k;
        }
    }
    let mut seen = vec![false; w * w];
    let mut best: Vec<usize> = Vec::new();
    for start in 0..w * w {
        if at[start] == usize::MAX || seen[start] {
            continue;
        }
        let mut part = Vec::new();
        let mut stack = vec![start];
        seen[start] = true;
        while let Some(c) = stack.pop() {
            part.push(at[c]);
            let (x, y) = (c % w, c / w);
            let mut push = |nx: usize, ny: usize| {
                let n = ny * w + nx;
                if at[n] != usize::MAX && !seen[n] {
                    seen[n] = true;
                    stack.push(n);
                }
            };
            if x > 0 {
                push(x - 1, y);
            }
            if x + 1 < w {
                push(x + 1, y);
            }
            if y > 0 {
                push(x, y - 1);
            }
            if y + 1 < w {
                push(x, y + 1);
            }
        }
        if part.len() > best.len() {
            best = part;
        }
    }
    if best.is_empty() {
        return None;
    }
    let centre = best.iter().map(|&k| samples[k].0).sum::<Vec2>() / best.len() as f32;
    let reach = best
        .iter()
        .map(|&k| samples[k].0.distance(centre))
        .fold(0f32, f32::max)
        + 0.5 / half as f32;
    Some((centre, reach.min(1.0)))
}

/// `s` moved within its plane to the normalised offset `shift` and its
/// radii scaled by `scale`: its clip lines stay where they are on the
/// surface ([`super::Clip::reframed`]).
fn reframed(s: &Splat, shift: Vec2, scale: f32) -> Splat {
    let mut out = *s;
    out.center = s.center + s.u_axis * (shift.x * s.radii.x) + s.v_axis * (shift.y * s.radii.y);
    out.radii = s.radii * scale;
    out.clip = s.clip.reframed(shift.to_array(), [scale, scale]);
    out
}

/// Shrinks every splat wider than [`UNCOVERED_LARGE`] times the median
/// radius that covers less than half its kept disc ([`covered_share`]) to
/// the largest connected part of its disc that points do cover (then,
/// while they cover less than [`SHRUNK_COVERS`] of it, by [`SHRINK`], at
/// most [`SHRINK_STEPS`] times); the points it covered that no splat
/// covers now each seed a small splat (a disc of its k-th neighbour
/// distance or the median radius, the less, with its own normal and
/// colour, taking the points it covers) so that no point is lost. `covered` (growth's) is cleared for the
/// points the shrunk splats no longer hold.
#[allow(clippy::too_many_arguments)]
pub fn shrink_uncovered(
    splats: &mut Vec<Splat>,
    covered: &mut [bool],
    (points, normals, colors): (&[Vec3], &[Vec3], Option<&[Vec3]>),
    tree: &PointTree,
    knn: &Knn,
    scan_lines: bool,
    epsilon: f32,
) -> Shrunk {
    shrink_uncovered_measured(splats, covered, (points, normals, colors), tree, knn, scan_lines, epsilon).0
}

/// Samples the disc of each splat wider than [`UNCOVERED_LARGE`] times
/// `median` once: the splats that cover less than half of it, each with the
/// splat it shrinks to ([`covered_part`], then by [`SHRINK`] while under
/// [`SHRUNK_COVERS`]), and the shares of the others.
fn measure_large(
    splats: &[Splat],
    median: f32,
    tree: &PointTree,
    knn: &Knn,
    scan_lines: bool,
) -> (Vec<(usize, Splat)>, Measured) {
    // Each large splat's disc sampled once: its share, and the splat it is
    // shrunk to where it covers less than half.
    let large: Vec<(u32, f32, Option<Splat>)> = splats
        .par_iter()
        .enumerate()
        .filter(|(_, s)| s.radii.max_element() > UNCOVERED_LARGE * median)
        .map(|(i, s)| {
            let samples = cover_samples(s, tree, knn, scan_lines);
            let covers = share(&samples);
            let to = (covers < 0.5)
                .then(|| covered_part(&samples))
                .flatten()
                .map(|(shift, scale)| {
                    let mut t = reframed(s, shift, scale);
                    for _ in 0..SHRINK_STEPS {
                        if covered_share(&t, tree, knn, scan_lines) >= SHRUNK_COVERS {
                            break;
                        }
                        t = reframed(&t, Vec2::ZERO, SHRINK);
                    }
                    t
                });
            (i as u32, covers, to)
        })
        .collect();
    let mut measured = Vec::new();
    let mut found: Vec<(usize, Splat)> = Vec::new();
    for (i, covers, to) in large {
        match to {
            Some(t) => found.push((i as usize, t)),
            None => measured.push((i, splats[i as usize], covers)),
        }
    }
    (found, Measured(measured))
}

/// [`shrink_uncovered`], and the covered shares it measured of the large
/// splats it left as they were ([`uncovered_large_measured`] takes them).
#[allow(clippy::too_many_arguments)]
pub(crate) fn shrink_uncovered_measured(
    splats: &mut Vec<Splat>,
    covered: &mut [bool],
    (points, normals, colors): (&[Vec3], &[Vec3], Option<&[Vec3]>),
    tree: &PointTree,
    knn: &Knn,
    scan_lines: bool,
    epsilon: f32,
) -> (Shrunk, Measured) {
    let median = median_radius(splats);
    let (found, measured) = measure_large(splats, median, tree, knn, scan_lines);
    if found.is_empty() {
        return (Shrunk::default(), measured);
    }
    // The points the old discs held: growth's marks cleared, to be tested
    // against the splats as they are now.
    let mut bare: Vec<u32> = Vec::new();
    for &(i, t) in &found {
        let old = splats[i];
        let r = old.radii.max_element();
        for nb in tree.within_unsorted::<SquaredEuclidean>(&old.center.to_array(), r * r) {
            let j = nb.item as usize;
            if on_splat(&old, points[j], epsilon) && !on_splat(&t, points[j], epsilon) {
                covered[j] = false;
                bare.push(nb.item);
            }
        }
        splats[i] = t;
    }
    bare.sort_unstable();
    bare.dedup();
    let shrunk = found.len();
    // Of those, the ones no splat holds now get splats of their own.
    let centres: Vec<[f32; 3]> = splats.iter().map(|s| s.center.to_array()).collect();
    let by_centre: ImmutableKdTree<f32, u32, 3, 32> = ImmutableKdTree::new_from_slice(&centres);
    let reach = splats
        .iter()
        .map(|s| s.radii.max_element())
        .fold(0f32, f32::max)
        + epsilon;
    let held = |p: Vec3| {
        by_centre
            .within_unsorted::<SquaredEuclidean>(&p.to_array(), reach * reach)
            .iter()
            .any(|nb| on_splat(&splats[nb.item as usize], p, epsilon))
    };
    let lost: Vec<u32> = bare
        .into_iter()
        .filter(|&j| !held(points[j as usize]))
        .collect();
    let mut taken = vec![false; points.len()];
    let mut added = Vec::new();
    for &j in &lost {
        let j = j as usize;
        if taken[j] {
            continue;
        }
        let r = knn.kth_distance[j].min(median).max(f32::MIN_POSITIVE);
        let Some(mut s) = Splat::disc(points[j], normals[j], r) else {
            continue;
        };
        if let Some(c) = colors {
            s.color = c[j];
        }
        for nb in tree.within_unsorted::<SquaredEuclidean>(&points[j].to_array(), r * r) {
            let q = nb.item as usize;
            if on_splat(&s, points[q], epsilon) {
                taken[q] = true;
                covered[q] = true;
            }
        }
        taken[j] = true;
        covered[j] = true;
        added.push(s);
    }
    let out = Shrunk {
        shrunk,
        added: added.len(),
    };
    splats.extend(added);
    (out, measured)
}
