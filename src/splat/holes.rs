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

use super::knn::{Knn, PointTree, dist_sq};
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
/// Where `points` (the tree's) are given, each sample's nearest point is
/// found among the disc's neighbourhood first ([`Nearby`]): the same point
/// and distance as the tree's `nearest_one`, which answers the rest.
fn cover_samples(
    s: &Splat,
    tree: &PointTree,
    knn: &Knn,
    scan_lines: bool,
    points: Option<&[Vec3]>,
) -> Vec<(Vec2, bool)> {
    let half = ACROSS / 2;
    let per = if scan_lines {
        1.0
    } else {
        (std::f32::consts::PI / knn.k.max(1) as f32).sqrt()
    };
    let nearby = points.and_then(|p| Nearby::of(s, tree, p, half));
    let mut near: Vec<(Vec2, f32)> = Vec::new();
    let mut spacings: Vec<f32> = Vec::new();
    // The nearest point of the sample before (`prev`), and of the first
    // sample of the row before (`head`): each bounds the next sample's.
    let mut head: Option<u32> = None;
    for y in -half..=half {
        let mut prev = head;
        let mut first: Option<u32> = None;
        for x in -half..=half {
            let q = Vec2::new(x as f32, y as f32) / half as f32;
            if q.length_squared() > 1.0 || !s.clip.keeps(q.x, q.y) {
                continue;
            }
            let w = s.center + s.u_axis * (q.x * s.radii.x) + s.v_axis * (q.y * s.radii.y);
            let (distance, item) = nearby
                .as_ref()
                .and_then(|n| n.nearest(w, prev))
                .unwrap_or_else(|| {
                    let nn = tree.nearest_one::<SquaredEuclidean>(&w.to_array());
                    (nn.distance, nn.item)
                });
            first.get_or_insert(item);
            prev = Some(item);
            near.push((q, distance));
            spacings.push(per * knn.kth_distance[item as usize]);
        }
        head = first.or(head);
    }
    if spacings.is_empty() {
        return Vec::new();
    }
    let low = spacings.len() / SPACING_QUANTILE;
    let spacing = *spacings.select_nth_unstable_by(low, f32::total_cmp).1;
    let reach2 = (COVER_SPACINGS * spacing) * (COVER_SPACINGS * spacing);
    near.into_iter().map(|(q, d)| (q, d <= reach2)).collect()
}

/// A large splat's neighbourhood, for its samples' nearest points
/// ([`cover_samples`]): the points of the tree within [`NEARBY_REACH`]
/// times the disc's larger radius of its centre, bucketed in a square grid
/// of cells a sample step wide over the disc's plane. A sample's nearest
/// point is within the distance `b` of the point nearest the sample before
/// it; where the ball of that radius round the sample lies inside the
/// neighbourhood's, the nearest point is one of the neighbourhood's within
/// `b` of the sample in the plane (a projection shortens no distance), in
/// the cells that reach: scanned there with the tree's squared distance
/// (`SquaredEuclidean`'s sum, in its order), it is the tree's answer
/// where one point alone is nearest. Elsewhere (a tie, a ball reaching
/// out) the tree answers.
struct Nearby<'a> {
    points: &'a [Vec3],
    centre: Vec3,
    /// The plane's axes (orthonormal, from the splat's).
    u: Vec3,
    v: Vec3,
    /// The neighbourhood's radius.
    reach: f32,
    /// A cell's width, and the cells along a side.
    cell: f32,
    side: usize,
    /// Cell `c`'s points are `items[starts[c]..starts[c + 1]]`.
    starts: Vec<u32>,
    items: Vec<u32>,
}

/// [`Nearby`]'s radius, in the disc's larger radius: the samples lie
/// within one, so a sample's nearest point is looked up here where it lies
/// within half a radius (else the tree is asked).
const NEARBY_REACH: f32 = 1.5;

/// [`Nearby`]'s relative margin on distances, far above the rounding of
/// the squared distances and projections in `f32`.
const NEARBY_MARGIN: f32 = 1e-4;

impl<'a> Nearby<'a> {
    /// The neighbourhood of `s` with cells `1 / half` of its larger radius
    /// wide; `None` where the disc is degenerate or `points` are not the
    /// tree's (a found point's squared distance not the tree's, bit for
    /// bit).
    fn of(s: &Splat, tree: &PointTree, points: &'a [Vec3], half: i32) -> Option<Nearby<'a>> {
        let r = s.radii.max_element();
        let u = s.u_axis.try_normalize()?;
        let v = s.v_axis.reject_from_normalized(u).try_normalize()?;
        let reach = NEARBY_REACH * r;
        let cell = r / half as f32;
        if !(cell > 0.0 && reach.is_finite()) {
            return None;
        }
        let side = ((2.0 * reach / cell).ceil() as usize).clamp(1, 64);
        let c = s.center.to_array();
        let found = tree.within_unsorted::<SquaredEuclidean>(&c, reach * reach);
        let mut near = Nearby {
            points,
            centre: s.center,
            u,
            v,
            reach,
            cell,
            side,
            starts: vec![0; side * side + 1],
            items: vec![0; found.len()],
        };
        let mut cells = Vec::with_capacity(found.len());
        for f in &found {
            let p = points.get(f.item as usize)?;
            if dist_sq(p.to_array(), c).to_bits() != f.distance.to_bits() {
                return None;
            }
            let at = near.cell_of(*p);
            near.starts[at + 1] += 1;
            cells.push(at as u32);
        }
        for k in 1..near.starts.len() {
            near.starts[k] += near.starts[k - 1];
        }
        let mut next = near.starts.clone();
        for (f, &at) in found.iter().zip(&cells) {
            let at = at as usize;
            near.items[next[at] as usize] = f.item;
            next[at] += 1;
        }
        Some(near)
    }

    /// The cell coordinates of a place `a` along an axis (clamped: the
    /// cast saturates, below 0 and not a number to 0, and rounds toward
    /// zero, so it floors what it keeps).
    fn index(&self, a: f32) -> usize {
        (((a + self.reach) / self.cell) as usize).min(self.side - 1)
    }

    /// The cell of point `p`.
    fn cell_of(&self, p: Vec3) -> usize {
        let d = p - self.centre;
        self.index(self.u.dot(d)) * self.side + self.index(self.v.dot(d))
    }

    /// The tree's nearest point to `w` (squared distance, index), from the
    /// neighbourhood where the point `hint` bounds it inside (see
    /// [`Nearby`]); `None` for the tree to answer.
    fn nearest(&self, w: Vec3, hint: Option<u32>) -> Option<(f32, u32)> {
        let q = w.to_array();
        let bound = dist_sq(q, self.points[hint? as usize].to_array());
        let r = bound.sqrt();
        let d = w - self.centre;
        if (d.length() + r) * (1.0 + NEARBY_MARGIN) >= self.reach {
            return None;
        }
        let pad = r * (1.0 + NEARBY_MARGIN) + NEARBY_MARGIN * self.reach;
        let (a, b) = (self.u.dot(d), self.v.dot(d));
        let (i0, i1) = (self.index(a - pad), self.index(a + pad));
        let (j0, j1) = (self.index(b - pad), self.index(b + pad));
        let (mut best, mut item, mut tie) = (f32::INFINITY, u32::MAX, false);
        for i in i0..=i1 {
            let row = i * self.side;
            let (lo, hi) = (self.starts[row + j0] as usize, self.starts[row + j1 + 1] as usize);
            for &k in &self.items[lo..hi] {
                let e = dist_sq(q, self.points[k as usize].to_array());
                if e < best {
                    (best, item, tie) = (e, k, false);
                } else if e == best {
                    tie = true;
                }
            }
        }
        (best <= bound && !tie).then_some((best, item))
    }
}

/// The share of `s`'s kept (clipped) disc that points cover: of a grid of
/// samples over the disc (21 across) that its clip lines keep, those with
/// a point of `tree` within [`COVER_SPACINGS`] local spacings (from `knn`;
/// `scan_lines` as in a cloud whose graph was widened for scan lines,
/// where the k-th neighbour distance itself is the spacing).
#[must_use]
pub fn covered_share(s: &Splat, tree: &PointTree, knn: &Knn, scan_lines: bool) -> f32 {
    share(&cover_samples(s, tree, knn, scan_lines, None))
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
    (points, tree): (&[Vec3], &PointTree),
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
            let samples = cover_samples(s, tree, knn, scan_lines, Some(points));
            let covers = share(&samples);
            let to = (covers < 0.5)
                .then(|| covered_part(&samples))
                .flatten()
                .map(|(shift, scale)| {
                    let mut t = reframed(s, shift, scale);
                    for _ in 0..SHRINK_STEPS {
                        if share(&cover_samples(&t, tree, knn, scan_lines, Some(points))) >= SHRUNK_COVERS {
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
    let (found, measured) = measure_large(splats, median, (points, tree), knn, scan_lines);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use crate::splat::knn::build_tree;

    /// A floor of 100×100 points (spacing 0.01) with a square hole and a
    /// row of stray points past its edge: jittered (`jitter`, no two points
    /// as near as any other) or on an exact lattice (ties everywhere).
    fn floor(jitter: f32, seed: u64) -> Vec<Vec3> {
        let mut rng = SplitMix64::new(seed);
        let mut pts = Vec::new();
        for i in 0..100 {
            for j in 0..100 {
                let (x, y) = (i as f32 * 0.01 - 0.5, j as f32 * 0.01 - 0.5);
                if (0.05..0.25).contains(&x) && (-0.1..0.1).contains(&y) {
                    continue;
                }
                let d = (rng.unit() * jitter).with_z(rng.unit().z * jitter * 0.3);
                pts.push(Vec3::new(x, y, 0.0) + d);
            }
        }
        for j in 0..40 {
            pts.push(Vec3::new(0.8, j as f32 * 0.01 - 0.2, 0.02));
        }
        pts
    }

    /// Every sample [`Nearby`] answers is the tree's own answer (squared
    /// distance bit for bit, and point), on jittered and lattice floors,
    /// for discs over the points, over the hole, reaching past the cloud
    /// and tilted; the rest the tree answers, and the covered samples are
    /// the same with it and without it.
    #[test]
    fn nearby_answers_as_the_tree_does() {
        let (mut asked, mut answered) = ([0usize; 2], [0usize; 2]);
        for (case, jitter) in [0.003f32, 0.0].into_iter().enumerate() {
            let pts = floor(jitter, 7 + case as u64);
            let tree = build_tree(&pts);
            let knn = Knn::build(&tree, &pts, 12);
            let mut rng = SplitMix64::new(11);
            for k in 0..40 {
                let c = Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, 0.0);
                let n = (Vec3::Z + rng.unit() * (0.1 * (k % 4) as f32)).normalize();
                let r = 0.03 + 0.3 * rng.next_f32();
                let s = Splat::disc(c, n, r).unwrap();
                let near = Nearby::of(&s, &tree, &pts, ACROSS / 2).unwrap();
                let mut hint = None;
                for y in -10..=10 {
                    for x in -10..=10 {
                        let q = Vec2::new(x as f32, y as f32) / 10.0;
                        if q.length_squared() > 1.0 {
                            continue;
                        }
                        let w = s.center + s.u_axis * (q.x * r) + s.v_axis * (q.y * r);
                        let nn = tree.nearest_one::<SquaredEuclidean>(&w.to_array());
                        asked[case] += 1;
                        if let Some((d, item)) = near.nearest(w, hint) {
                            answered[case] += 1;
                            assert_eq!((d.to_bits(), item), (nn.distance.to_bits(), nn.item));
                        }
                        hint = Some(nn.item);
                    }
                }
                let fast = cover_samples(&s, &tree, &knn, false, Some(&pts));
                assert_eq!(fast, cover_samples(&s, &tree, &knn, false, None));
            }
        }
        // Measured: 11,574 and 11,565 of 12,680 samples answered (the
        // rest the first of each disc, or a ball reaching out of the
        // neighbourhood over the hole and past the cloud's edge).
        for (a, n) in answered.iter().zip(asked) {
            assert!(a * 100 >= 90 * n, "{answered:?} of {asked:?}");
        }
    }

    /// Points that are not the tree's give no neighbourhood.
    #[test]
    fn nearby_needs_the_trees_points() {
        let pts = floor(0.003, 3);
        let tree = build_tree(&pts);
        let s = Splat::disc(Vec3::ZERO, Vec3::Z, 0.1).unwrap();
        assert!(Nearby::of(&s, &tree, &pts, 10).is_some());
        let moved: Vec<Vec3> = pts.iter().map(|p| *p + Vec3::X * 1e-3).collect();
        assert!(Nearby::of(&s, &tree, &moved, 10).is_none());
    }
}
