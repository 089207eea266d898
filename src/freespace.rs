//! Lines of sight are free space: where the scanner's viewpoint is known,
//! every scanned point was seen from it, so no splat may cross the segment
//! from the viewpoint to a point short of that point. Splats at a
//! foreground edge overhang the silhouette by up to their radius and would
//! hide the background the scanner saw just beyond it; they are shrunk
//! away from the lines of sight they block. A line of sight on which no
//! splat stands near its point (within the margin) is not blocked: the
//! splat in front is then the point's own surface, which range noise left
//! in front of it, and shrinking it would open a hole in that surface. Nor
//! is a splat shrunk where that would open a hole among the points the
//! scanner saw all round it (`opened_holes`): the line through it stays
//! blocked instead.

use crate::accel::octree::{Octree, OctreeParams};
use crate::accel::{Backend, Candidate, CandidateHits, Ray};
use crate::data::FACING_AWAY_MAX;
use crate::primitive::Primitive;
use crate::splat::{PointCloud, Splat, SplatParams, SplatReport, Viewpoints};
use crate::{Error, Result};
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::cell::OnceCell;
use std::collections::HashMap;
use std::hash::BuildHasherDefault;

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

/// What trimming did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct TrimReport {
    /// Lines of sight cast per pass.
    pub rays: usize,
    /// Lines blocked in the first pass.
    pub blocked: usize,
    /// Rays that met nothing cast per pass ([`PointCloud::misses`]).
    pub misses: usize,
    /// Of those, rays meeting a splat in the first pass.
    pub misses_blocked: usize,
    /// Splats shrunk (over all passes).
    pub shrunk: usize,
    /// Lines still blocked after the last pass.
    pub still_blocked: usize,
    /// Shrinks undone because they opened a hole in the scanned surface
    /// (each such splat kept whole from then on).
    pub kept_whole: usize,
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

/// What one line of sight met in a pass: the first splat on it (short of
/// its point by more than the margin; [`NO_SPLAT`] for none) and, where
/// that splat blocks it, the blocking hit (see [`blocked`]).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Sight {
    first: u32,
    block: Option<(u32, Vec2)>,
}

/// [`Sight::first`] of a line that meets no splat.
const NO_SPLAT: u32 = u32::MAX;

/// For every point, the first splat blocking its line of sight (more than
/// `margin` in front of it, see [`MARGIN_ALONG`]), with the hit's
/// normalised disc coordinates; only when some splat stands within
/// `margin` of the point on that line (its own surface, which the blocking
/// splat hides). Without one, the splat in front is the point's surface
/// itself, standing in front of it by the noise of a coarse scan, and it
/// is kept: shrinking it would open a hole through that surface along the
/// line, which a camera near the scanner looks through (on
/// `scenes/scan-lines.toml` such holes show the floor through the bunny;
/// `docs/notes/generation.md`, "Issue 23: the specks' causes, and shadow rays
/// that see the surface").
///
/// Then, for every miss of `misses` (a ray from their one viewpoint that
/// met nothing), the first splat it meets, if any. Lines are numbered
/// points first, then misses; with `only`, just those lines are cast, in
/// its order.
fn blocked(
    (splats, lines): (&[Splat], &Lines),
    points: &[Vec3],
    vp: &Viewpoints,
    misses: &Misses,
    margin: f32,
    only: Option<&[u32]>,
) -> Vec<Sight> {
    // In a coloured cloud a ray that met nothing is checked against whole
    // discs: a splat its clip lines let pass stands at the capture's border
    // or hole, and shrinks as a whole disc would. Its lines already cut the
    // overhang, but a splat grown to its full size across a textured
    // capture's edge spreads one linear colour field over it: on the
    // striped organised capture (`scan-check --photo`, creases on) 25.99 dB
    // with the clipped discs, 27.49 with whole ones, 26.92 without creases.
    // Without colours the clipped disc is the surface, and shrinking it
    // costs: the noisy solids scan 31.00 -> 30.78 dB, `scenes/scan.toml`
    // 34.10 -> 34.02 (`docs/notes/creases.md`, "Issue 39: creases on by
    // default").
    let whole =
        (misses.whole_discs && !misses.dirs.is_empty() && splats.iter().any(Splat::is_clipped))
            .then(|| Lines {
                parts: vec![(octree_over(splats, None, false), None)],
                clipped: false,
            });
    let cast = |(hits, part): &mut (CandidateHits, CandidateHits), i: usize| -> Sight {
        let none = Sight {
            first: NO_SPLAT,
            block: None,
        };
        let Some(&p) = points.get(i) else {
            let k = i - points.len();
            let ray = Ray {
                origin: misses.origin(k),
                dir: misses.dirs[k],
            };
            let past = whole.as_ref().unwrap_or(lines);
            return past.nearest(&ray, (0.0, f32::INFINITY), hits, part).map_or(none, |h| Sight {
                first: h.id,
                block: Some((h.id, Vec2::new(h.u, h.v))),
            });
        };
        let Some((ray, d)) = sight_line(vp.at(i), p) else {
            return none;
        };
        let t_max = d - margin;
        if t_max <= 0.0 {
            return none;
        }
        let Some(h) = lines.nearest(&ray, (0.0, t_max), hits, part) else {
            return none;
        };
        let depth = d - h.t;
        let cos = splats[h.id as usize].normal.dot(ray.dir).abs();
        let blocks = depth > margin && (depth * cos > margin || depth > MARGIN_ALONG * margin);
        let (first, q) = (h.id, (h.id, Vec2::new(h.u, h.v)));
        if !blocks {
            return Sight { first, block: None };
        }
        Sight {
            first,
            block: lines.occluded(&ray, (d - margin, d + margin)).then_some(q),
        }
    };
    let init = || (CandidateHits::new(0.0), CandidateHits::new(0.0));
    match only {
        Some(lines) => lines
            .par_iter()
            .with_min_len(512)
            .map_init(init, |hits, &i| cast(hits, i as usize))
            .collect(),
        None => (0..points.len() + misses.dirs.len())
            .into_par_iter()
            .with_min_len(512)
            .map_init(init, cast)
            .collect(),
    }
}

/// The lines whose [`Sight`] may differ once the splats marked `changed`
/// have shrunk: those blocked, and those whose first splat is one of them.
/// Every other line keeps its sight, because a shrink only takes hits
/// away: a line that met no splat meets none, and one whose first splat
/// is unchanged meets it first again, blocks or not as before, and (not
/// blocking) stays unblocked.
fn to_recast(sights: &[Sight], changed: &[bool]) -> Vec<u32> {
    sights
        .iter()
        .enumerate()
        .filter(|(_, s)| s.block.is_some() || (s.first != NO_SPLAT && changed[s.first as usize]))
        .map(|(i, _)| i as u32)
        .collect()
}

/// The splats trimming casts lines of sight through, in one octree or
/// parted in two: those a pass leaves as they were, and the few it shrinks
/// (or restores), so that a pass builds one octree over all the splats,
/// not two (each 2.6-3 ms on the real table scan's 12k splats, in eight
/// passes). Over clipped discs when some splat is clipped (the lines of
/// sight pass the clipped-away parts), else over discs. Hits are offered
/// by splat: the nearest is the one octree over them all would give.
struct Lines {
    parts: Vec<Part>,
    /// Over clipped discs.
    clipped: bool,
}

impl Lines {
    /// One octree over every splat.
    fn of(splats: &[Splat]) -> Lines {
        let clipped = splats.iter().any(Splat::is_clipped);
        Lines {
            parts: vec![(octree_over(splats, None, clipped), None)],
            clipped,
        }
    }

    /// Two octrees over `splats`: one over those not in `few`, one over
    /// those of `few` (ascending), which [`Lines::with_few`] builds again
    /// as they change.
    fn parted(splats: &[Splat], few: &[u32]) -> Lines {
        let clipped = splats.iter().any(Splat::is_clipped);
        let mut rest = Vec::with_capacity(splats.len() - few.len());
        let mut k = 0;
        for i in 0..splats.len() as u32 {
            if few.get(k) == Some(&i) {
                k += 1;
            } else {
                rest.push(i);
            }
        }
        Lines {
            parts: vec![
                (octree_over(splats, Some(&rest), clipped), Some(rest)),
                (octree_over(splats, Some(few), clipped), Some(few.to_vec())),
            ],
            clipped,
        }
    }

    /// The same octree over most of `splats` ([`Lines::parted`]'s first),
    /// only the few changed since; all built again when that changes
    /// whether some splat is clipped.
    fn with_few(mut self, splats: &[Splat]) -> Lines {
        if splats.iter().any(Splat::is_clipped) != self.clipped {
            return Lines::of(splats);
        }
        if let Some((few, Some(ids))) = self.parts.get_mut(1) {
            *few = octree_over(splats, Some(ids), self.clipped);
        }
        self
    }

    /// The nearest hit of `ray` in `t`, its splat's index as its id (`hits`
    /// and `part` are scratch).
    fn nearest(&self, ray: &Ray, t: (f32, f32), hits: &mut CandidateHits, part: &mut CandidateHits) -> Option<Candidate> {
        if let [(octree, None)] = self.parts.as_slice() {
            octree.intersect(ray, t.0, t.1, hits);
            return hits.nearest().copied();
        }
        hits.clear();
        for (octree, ids) in &self.parts {
            octree.intersect(ray, t.0, t.1, part);
            for c in part.as_slice() {
                let id = ids.as_ref().map_or(c.id, |ids| ids[c.id as usize]);
                hits.offer(Candidate { id, ..*c });
            }
        }
        hits.nearest().copied()
    }

    /// True when `ray` meets a splat in `t`.
    fn occluded(&self, ray: &Ray, t: (f32, f32)) -> bool {
        self.parts.iter().any(|(octree, _)| octree.occluded(ray, t.0, t.1))
    }
}

/// An octree of [`Lines`] and the splats of its primitives (`None`: all, in
/// order).
type Part = (Box<dyn Backend>, Option<Vec<u32>>);

/// An octree over `splats` (those of `ids`, their primitives numbered in
/// that order), over clipped discs when `clipped`.
fn octree_over(splats: &[Splat], ids: Option<&[u32]>, clipped: bool) -> Box<dyn Backend> {
    fn over<P>(splats: &[Splat], ids: Option<&[u32]>, f: impl Fn(&Splat) -> P) -> Vec<P> {
        match ids {
            Some(ids) => ids.iter().map(|&i| f(&splats[i as usize])).collect(),
            None => splats.iter().map(f).collect(),
        }
    }
    if clipped {
        return Box::new(Octree::new(&over(splats, ids, Splat::clipped_geometry), &OctreeParams::default()));
    }
    Box::new(Octree::new(&over(splats, ids, Splat::disc_geometry), &OctreeParams::default()))
}

/// The scanners' rays that met nothing: [`PointCloud::misses`] from its
/// one viewpoint, or [`crate::splat::Scans::misses`] from each scan's.
#[derive(Clone, Debug, Default)]
pub struct Misses {
    /// The scanners' positions.
    pub from: Vec<Vec3>,
    /// Unit directions.
    pub dirs: Vec<Vec3>,
    /// Per direction, its scanner's index in `from`; empty when every ray
    /// is `from[0]`'s.
    pub of: Vec<u16>,
    /// Test the rays against whole discs, clipped or not (a coloured
    /// cloud's splats, whose colour fields span what their clip lines
    /// cut): see [`blocked`].
    pub whole_discs: bool,
}

impl Misses {
    /// Where miss `k` was cast from.
    ///
    /// # Panics
    /// When `from` has no entry for it (misses built without scanners).
    #[must_use]
    pub fn origin(&self, k: usize) -> Vec3 {
        self.from[self.of.get(k).map_or(0, |&s| usize::from(s))]
    }
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
    // The clip lines stay where they are on the surface.
    s.clip = s.clip.reframed([shift.x, shift.y], [1.0 - a, 1.0 - a]);
    // The same field over the smaller disc: old (u, v) = shift + (1-a)(u', v')
    // in eq. (4)'s normalised coordinates.
    let f = &mut s.field;
    f.xc += f.alpha * shift.x;
    f.yc += f.beta * shift.y;
    f.alpha *= 1.0 - a;
    f.beta *= 1.0 - a;
}

/// Sample rings of a shrunk splat's removed crescent, in its old disc's
/// normalised radius.
const HOLE_RINGS: [f32; 6] = [0.2, 0.35, 0.5, 0.65, 0.8, 0.95];

/// Samples per ring.
const HOLE_SPOKES: usize = 32;

/// A sample is a hole when its line of sight meets no splat up to this many
/// margins beyond it: nearer, the line meets the same surface further along
/// (a curved or grazing one). On the coarse scan-line case 3 margins kept
/// 11 splats whole and cost 0.3 % of its consistent lines of sight; 10 and
/// 30 margins none, and the same holes closed on `scenes/scan-lines.toml`.
const HOLE_DEPTH: f32 = 30.0;

/// For each shrunk splat of `cut` (its index, the splat before the shrink,
/// the point whose line of sight it blocked), whether the shrink opened a
/// hole in the surface the scanner saw: a point of its removed crescent,
/// seen from that line's viewpoint, through which the line of sight now
/// meets no splat up to [`HOLE_DEPTH`] margins beyond it, while the cloud's points lie
/// around it on every side (its four quadrants within the old radius, on
/// the splat's plane within `margin`). A crescent that overhung an edge
/// (the case trimming is for) has points on one side only; one inside
/// the scanned surface has them all round, and shrinking it shows what lies
/// behind the surface (on `scenes/scan-lines.toml`, the floor through the
/// bunny).
fn opened_holes(
    (splats, lines): (&[Splat], &Lines),
    cut: &[(usize, Splat, usize)],
    points: &[Vec3],
    vp: &Viewpoints,
    misses: &Misses,
    (margin, cells): (f32, &OnceCell<PointCells>),
) -> Vec<bool> {
    if cut.is_empty() {
        return Vec::new();
    }
    // The points within twice the old disc's reach of its centre.
    let around: Vec<(Vec3, f32)> = cut
        .iter()
        .map(|(_, old, _)| {
            let reach = old.radii.max_element();
            (old.center, 4.0 * reach * reach)
        })
        .collect();
    let around = cells.get_or_init(|| PointCells::new(points, &around)).within(points, &around);
    cut.par_iter()
        .zip(&around)
        .map_init(Vec::new, |near, (&(id, old, i), around)| {
                // A miss (past the points) is checked for holes like any
                // line: a cluster of dropped returns inside the surface
                // looks like one.
                let eye = if let Some(&p) = points.get(i) {
                    let eye = vp.at(i);
                    // The line it blocked: through to a point far behind,
                    // the scanner saw a real gap, and opening it is the
                    // point.
                    let Some((line, d)) = sight_line(eye, p) else {
                        return false;
                    };
                    let behind = d - old.normal.dot(old.center - eye) / old.normal.dot(line.dir);
                    if behind.is_nan() || behind > HOLE_DEPTH * margin {
                        return false;
                    }
                    eye
                } else {
                    misses.origin(i - points.len())
                };
                let new = splats[id].clipped_geometry();
                let reach = old.radii.max_element();
                let (c, n, u, v) = (old.center, old.normal, old.u_axis, old.v_axis);
                // The points on the old disc's plane within its reach of
                // any sample, in its tangent coordinates.
                near.clear();
                for &k in around {
                    let d = points[k as usize] - c;
                    if n.dot(d).abs() <= margin {
                        near.push(Vec2::new(u.dot(d), v.dot(d)));
                    }
                }
                HOLE_RINGS.iter().any(|&ring| {
                    (0..HOLE_SPOKES).any(|k| {
                        let a = std::f32::consts::TAU * k as f32 / HOLE_SPOKES as f32;
                        let xy = Vec2::new(a.cos() * old.radii.x, a.sin() * old.radii.y) * ring;
                        let x = c + u * xy.x + v * xy.y;
                        if new.locate(x).radial2 <= 1.0 {
                            return false;
                        }
                        let mut quadrants = 0u8;
                        for &p in near.iter() {
                            let d = p - xy;
                            if d.length_squared() <= reach * reach {
                                quadrants |=
                                    1 << (usize::from(d.x >= 0.0) + 2 * usize::from(d.y >= 0.0));
                            }
                        }
                        if quadrants != 0b1111 {
                            return false;
                        }
                        let Some((ray, t)) = sight_line(eye, x) else {
                            return false;
                        };
                        !lines.occluded(&ray, (0.0, t + HOLE_DEPTH * margin))
                    })
                })
            },
        )
        .collect()
}

/// The points of a trimming, bucketed once into cells for the balls of
/// every pass's shrinks ([`opened_holes`]): a pass asks about a few
/// splats, and each asking looks only at the points of its balls' cells.
/// Looking every point up among a pass's balls' cells instead cost 4 to 12
/// ms a pass however few its shrinks: the real table scan's trimming took
/// 0.19-0.20 s, with the cells 0.17 (`docs/notes/generation.md`, "Issue 54,
/// seventieth session").
struct PointCells {
    /// The cells' width.
    h: f32,
    /// The points' indices, cell by cell.
    order: Vec<u32>,
    /// A cell's key ([`PointCells::key`]) to its run of `order`.
    runs: HashMap<u64, (u32, u32), BuildHasherDefault<CellHash>>,
}

impl PointCells {
    /// The cells of `points`, two and a half times as wide as the median
    /// radius of `balls` (the first pass's; a wider ball of a later pass
    /// covers more cells, and one over more cells than there are points
    /// tests every point).
    fn new(points: &[Vec3], balls: &[(Vec3, f32)]) -> PointCells {
        let mut radii: Vec<f32> = balls.iter().filter(|b| usable(b)).map(|b| b.1.sqrt()).collect();
        let mid = radii.len() / 2;
        let median = if radii.is_empty() { 0.0 } else { *radii.select_nth_unstable_by(mid, f32::total_cmp).1 };
        let h = (2.5 * median).max(f32::MIN_POSITIVE);
        let mut keyed: Vec<(u64, u32)> = points
            .par_iter()
            .enumerate()
            .with_min_len(4096)
            .map(|(i, &p)| (Self::key(Self::cell(h, p)), i as u32))
            .collect();
        keyed.par_sort_unstable();
        let mut runs: HashMap<u64, (u32, u32), BuildHasherDefault<CellHash>> = HashMap::default();
        let mut start = 0;
        for (i, w) in keyed.windows(2).enumerate() {
            if w[0].0 != w[1].0 {
                runs.insert(w[0].0, (start, i as u32 + 1));
                start = i as u32 + 1;
            }
        }
        if let Some(last) = keyed.last() {
            runs.insert(last.0, (start, keyed.len() as u32));
        }
        PointCells {
            h,
            order: keyed.into_iter().map(|k| k.1).collect(),
            runs,
        }
    }

    fn cell(h: f32, p: Vec3) -> [i64; 3] {
        ((p / h).floor()).to_array().map(|x| x as i64)
    }

    /// A cell's key, its coordinates' low 21 bits: cells that share a key
    /// share a run, and cost only distance tests.
    fn key(c: [i64; 3]) -> u64 {
        let bits = |x: i64| (x as u64) & ((1 << 21) - 1);
        bits(c[0]) | bits(c[1]) << 21 | bits(c[2]) << 42
    }

    /// For each ball of `balls` (a centre and a squared radius), the points
    /// of `points` (those the cells were built of) within it, the boundary
    /// included, in ascending order; none for a ball not finite. The
    /// squared distance sums the axes' squares in order, as a k-d tree's
    /// query does.
    fn within(&self, points: &[Vec3], balls: &[(Vec3, f32)]) -> Vec<Vec<u32>> {
        balls
            .par_iter()
            .map_init(Vec::new, |keys, &(c, r2)| {
                let mut found = Vec::new();
                if !usable(&(c, r2)) {
                    return found;
                }
                // Padded: a point within the ball in f32 may lie a rounding
                // outside.
                let r = Vec3::splat(r2.sqrt() * 1.001);
                let (lo, hi) = (Self::cell(self.h, c - r), Self::cell(self.h, c + r));
                let inside = |i: &u32| {
                    let d = points[*i as usize] - c;
                    d.x * d.x + d.y * d.y + d.z * d.z <= r2
                };
                // A ball over more cells than there are points (far wider
                // than the first pass's): every point tested.
                let span = |a: usize| (hi[a].saturating_sub(lo[a]) as u128).saturating_add(1);
                if span(0).saturating_mul(span(1)).saturating_mul(span(2)) > self.order.len() as u128 {
                    found.extend((0..points.len() as u32).filter(inside));
                    return found;
                }
                keys.clear();
                for x in lo[0]..=hi[0] {
                    for y in lo[1]..=hi[1] {
                        for z in lo[2]..=hi[2] {
                            keys.push(Self::key([x, y, z]));
                        }
                    }
                }
                keys.sort_unstable();
                keys.dedup();
                for k in keys.iter() {
                    let Some(&(a, b)) = self.runs.get(k) else { continue };
                    found.extend(self.order[a as usize..b as usize].iter().copied().filter(inside));
                }
                found.sort_unstable();
                found
            })
            .collect()
    }
}

/// A ball with a finite centre and a finite squared radius, not negative.
fn usable(&(c, r2): &(Vec3, f32)) -> bool {
    c.is_finite() && r2.is_finite() && r2 >= 0.0
}

/// A hash of a cell key for [`PointCells`]' table: a multiply, its high
/// half folded into the low bits the table indexes by.
#[derive(Default)]
struct CellHash(u64);

impl std::hash::Hasher for CellHash {
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(self.0 ^ u64::from(b));
        }
    }

    fn write_u64(&mut self, k: u64) {
        let h = (self.0 ^ k).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        self.0 = h ^ (h >> 29);
    }

    fn finish(&self) -> u64 {
        self.0
    }
}

/// Trims `splats` so that no line of sight from its viewpoint to one of
/// `points` is blocked more than `margin` in front of its point.
#[must_use]
pub fn trim(
    splats: &mut [Splat],
    points: &[Vec3],
    viewpoint: &Viewpoints,
    misses: &Misses,
    margin: f32,
) -> TrimReport {
    let mut report = TrimReport {
        rays: points.len(),
        misses: misses.dirs.len(),
        ..TrimReport::default()
    };
    if splats.is_empty() || points.is_empty() {
        return report;
    }
    // Splats a shrink would have holed (see [`opened_holes`]): kept whole,
    // never shrunk again.
    let mut kept = vec![false; splats.len()];
    // The points in cells, once a pass has shrunk a splat.
    let cells = OnceCell::new();
    // Each pass casts only the lines a shrink of the pass before can have
    // changed ([`to_recast`]); the first casts them all.
    let mut lines = Lines::of(splats);
    let mut sights = blocked((splats, &lines), points, viewpoint, misses, margin, None);
    for pass in 0..PASSES {
        let count = sights.iter().filter(|s| s.block.is_some()).count();
        if pass == 0 {
            report.misses_blocked = sights[points.len()..]
                .iter()
                .filter(|s| s.block.is_some())
                .count();
            report.blocked = count - report.misses_blocked;
            if report.blocked as f64 > IMPLAUSIBLE * points.len() as f64 {
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
        let mut worst: Vec<Option<(Vec2, usize)>> = vec![None; splats.len()];
        for (i, s) in sights.iter().enumerate() {
            let Some((id, q)) = s.block else { continue };
            let w = &mut worst[id as usize];
            if !kept[id as usize] && w.is_none_or(|(o, _)| q.length() < o.length()) {
                *w = Some((q, i));
            }
        }
        let mut cut = Vec::new();
        for (id, (s, w)) in splats.iter_mut().zip(worst).enumerate() {
            if let Some((q, i)) = w {
                cut.push((id, *s, i));
                shrink_away(s, q);
            }
        }
        if cut.is_empty() {
            // Every line left is blocked by a splat kept whole.
            report.still_blocked = count;
            return report;
        }
        // The octree over the splats this pass leaves, built once for the
        // shrinks and for the lines cast again after them.
        let few: Vec<u32> = cut.iter().map(|c| c.0 as u32).collect();
        lines = Lines::parted(splats, &few);
        let holes = opened_holes((splats, &lines), &cut, points, viewpoint, misses, (margin, &cells));
        let mut changed = vec![false; splats.len()];
        let kept_before = report.kept_whole;
        for (&(id, before, _), hole) in cut.iter().zip(holes) {
            if hole {
                splats[id] = before;
                kept[id] = true;
                report.kept_whole += 1;
            } else {
                changed[id] = true;
                report.shrunk += 1;
            }
        }
        let again = to_recast(&sights, &changed);
        if report.kept_whole > kept_before {
            lines = lines.with_few(splats);
        }
        let recast = blocked((splats, &lines), points, viewpoint, misses, margin, Some(&again));
        for (&i, s) in again.iter().zip(recast) {
            sights[i as usize] = s;
        }
    }
    report.still_blocked = sights.iter().filter(|s| s.block.is_some()).count();
    report
}

/// Free-space trimming, the pipeline's stage after growth
/// ([`crate::pipeline::generate`]): when the parameters carry a viewpoint,
/// `splats` (generated from `cloud` with `params`, `report` their report)
/// are trimmed against the cloud's lines of sight, those of `outliers`
/// (indices into `cloud`: the points generation left out as statistical
/// outliers) left out. `None` without a viewpoint.
///
/// # Errors
/// A viewpoint that is not finite.
pub(crate) fn trim_free_space(
    cloud: &PointCloud,
    params: &SplatParams,
    splats: &mut [Splat],
    report: &mut SplatReport,
    outliers: &[u32],
    progress: Option<crate::progress::Progress<'_>>,
) -> Result<Option<TrimReport>> {
    let Some(vp) = crate::splat::viewpoints_of(cloud, params) else {
        return Ok(None);
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
        return Ok(Some(TrimReport {
            skipped: true,
            ..TrimReport::default()
        }));
    }
    crate::progress::notify(progress, "free space", 0.0);
    let mut flags = vec![false; cloud.len()];
    for &i in outliers {
        flags[i as usize] = true;
    }
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
    // Misses are the cloud's own scanner's, usable when trimming looks from
    // it alone.
    let misses = match (&vp, &cloud.misses, cloud.viewpoint, &cloud.scans) {
        (Viewpoints::One(v), Some(dirs), Some(own), _) if *v == own => Misses {
            from: vec![own],
            dirs: dirs.clone(),
            of: Vec::new(),
            whole_discs: false,
        },
        // Per-point viewpoints are the scans' own (`viewpoints_of`).
        (Viewpoints::PerPoint(_), _, _, Some(s))
            if s.misses_of.len() == s.misses.len()
                && s.misses_of
                    .iter()
                    .all(|&k| usize::from(k) < s.positions.len()) =>
        {
            Misses {
                from: s.positions.clone(),
                dirs: s.misses.clone(),
                of: s.misses_of.clone(),
                whole_discs: false,
            }
        }
        _ => Misses::default(),
    };
    let misses = Misses {
        whole_discs: cloud.colors.is_some() && params.color_fields,
        ..misses
    };
    let t = trim(splats, &points, &vp, &misses, margin);
    if t.skipped {
        report.warnings.push(format!(
            "{:.1} % of the lines of sight from the viewpoint are blocked: it does not look like \
             the scanner's position, so no splat was trimmed (give --viewpoint, or --no-viewpoint)",
            100.0 * t.blocked as f64 / t.rays.max(1) as f64
        ));
    }
    Ok(Some(t))
}

#[cfg(test)]
mod tests {
    use super::*;

    const MARGIN: f32 = 0.005;
    const EYE: Vec3 = Vec3::new(0.0, 0.0, 5.0);

    /// For each ball of `balls` (a centre and a squared radius), the points
    /// of `points` within it, the boundary included: [`PointCells`] built
    /// for them and asked once.
    fn points_within(points: &[Vec3], balls: &[(Vec3, f32)]) -> Vec<Vec<u32>> {
        PointCells::new(points, balls).within(points, balls)
    }

    /// One octree over every splat, as trimming casts through.
    fn octree_of(splats: &[Splat]) -> Box<dyn Backend> {
        octree_over(splats, None, splats.iter().any(Splat::is_clipped))
    }

    /// The points of each ball are those a k-d tree finds within it, the
    /// boundary included: balls of mixed radii far from the origin, points
    /// on a lattice (some exactly on a boundary), and one not finite; the
    /// same from cells built for the narrowest balls.
    #[test]
    fn points_within_balls_are_a_trees_points_within_them() {
        use crate::rng::SplitMix64;
        let mut rng = SplitMix64::new(5);
        let base = Vec3::new(4.0e5, -2.5e5, 120.0);
        let mut points: Vec<Vec3> = (0..6000)
            .map(|_| base + Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32() * 0.1) * 40.0)
            .collect();
        // A lattice a quarter apart: balls centred on it with radius 1 have
        // points exactly on their boundary.
        for i in 0..40 {
            for j in 0..40 {
                points.push(base + Vec3::new(i as f32, j as f32, 0.0) * 0.25);
            }
        }
        points.push(Vec3::NAN);
        let mut balls: Vec<(Vec3, f32)> = (0..300)
            .map(|k| {
                let c = points[(k * 37) % 6000];
                let r = 0.05 + 3.0 * rng.next_f32().powi(3);
                (c, r * r)
            })
            .collect();
        balls.push((base + Vec3::new(2.5, 2.5, 0.0), 1.0));
        balls.push((Vec3::NAN, 1.0));
        let found = points_within(&points, &balls);
        // Cells built for a first pass's smallest balls answer wider ones.
        let mut small = balls.clone();
        small.sort_by(|a, b| a.1.total_cmp(&b.1));
        let narrow = PointCells::new(&points, &small[..20]);
        assert!(narrow.h < 0.1 * PointCells::new(&points, &balls).h, "{}", narrow.h);
        assert_eq!(narrow.within(&points, &balls), found);
        // Some over more of those cells than there are points: every point
        // tested for them.
        let wide = balls.iter().filter(|b| (2.0 * b.1.sqrt() / narrow.h).powi(3) > points.len() as f32).count();
        assert!(wide >= 10, "{wide}");
        let tree = crate::splat::knn::build_tree(&points);
        let mut on_boundary = 0;
        for (b, &(c, r2)) in balls.iter().enumerate() {
            let mut got = found[b].clone();
            got.sort_unstable();
            let mut want: Vec<u32> = if c.is_finite() {
                tree.within_unsorted::<kiddo::SquaredEuclidean>(&c.to_array(), r2).iter().map(|nb| nb.item).collect()
            } else {
                Vec::new()
            };
            want.sort_unstable();
            assert_eq!(got, want, "ball {b} at {c} radius² {r2}");
            on_boundary += got.iter().filter(|&&i| (points[i as usize] - c).length_squared() == r2).count();
        }
        // Measured: 4 lattice points at exactly the radius of the last ball.
        assert!(on_boundary >= 4, "{on_boundary} points on a boundary");
        assert!(found.iter().map(Vec::len).sum::<usize>() > 3000);
    }

    /// A square of overlapping discs on the plane `z = 0` (spacing 0.25,
    /// radius 0.2: every point of the square is covered) and its scanned
    /// points (spacing 0.05), plus one point `p` under it with a small disc
    /// of its own (the point's surface, which its line of sight reaches).
    fn scene(p: Vec3) -> (Vec<Splat>, Vec<Vec3>) {
        let mut splats = Vec::new();
        let mut points = Vec::new();
        for i in -4..=4 {
            for j in -4..=4 {
                let c = Vec3::new(i as f32 * 0.25, j as f32 * 0.25, 0.0);
                splats.extend(Splat::disc(c, Vec3::Z, 0.2));
            }
        }
        for i in -20..=20 {
            for j in -20..=20 {
                points.push(Vec3::new(i as f32 * 0.05, j as f32 * 0.05, 0.0));
            }
        }
        splats.extend(Splat::disc(p, Vec3::Z, 0.02));
        points.push(p);
        (splats, points)
    }

    /// Lines of sight to the square's inner points (spacing 0.02) that meet
    /// no splat within `MARGIN` of the plane.
    fn holes(splats: &[Splat]) -> usize {
        let octree = octree_of(splats);
        let mut hits = CandidateHits::new(0.0);
        let mut n = 0;
        for i in -40..=40 {
            for j in -40..=40 {
                let x = Vec3::new(i as f32 * 0.02, j as f32 * 0.02, 0.0);
                let (ray, d) = sight_line(EYE, x).unwrap();
                octree.intersect(&ray, 0.0, d + MARGIN, &mut hits);
                if hits.nearest().is_none_or(|h| h.t < d - MARGIN) {
                    n += 1;
                }
            }
        }
        n
    }

    /// [`trim`] of `points`' lines from [`EYE`], without misses.
    fn trim_lines(splats: &mut [Splat], points: &[Vec3]) -> TrimReport {
        trim(
            splats,
            points,
            &Viewpoints::One(EYE),
            &Misses::default(),
            MARGIN,
        )
    }

    /// A point a few margins under the surface (range noise) is seen
    /// through it: shrinking the surface's discs off its line of sight
    /// would open a hole with points all round it, so the last disc
    /// covering the line is kept whole and the line stays blocked.
    #[test]
    fn noise_under_a_surface_opens_no_hole() {
        let (mut splats, points) = scene(Vec3::new(0.03, 0.02, -0.03));
        assert_eq!(holes(&splats), 0);
        let r = trim_lines(&mut splats, &points);
        assert!(r.blocked == 1 && r.kept_whole >= 1, "{r:?}");
        assert_eq!(r.still_blocked, 1, "{r:?}");
        assert_eq!(holes(&splats), 0, "{r:?}");
    }

    /// Rays that met nothing: one just past the square's edge meets the
    /// overhang of its last discs, which are shrunk off it; one through
    /// the square's inside (dropped returns side by side) would open a
    /// hole there, and the disc is kept whole.
    #[test]
    fn misses_trim_overhangs_but_open_no_hole() {
        let (mut splats, points) = scene(Vec3::new(0.0, 0.0, -0.03));
        let past = Vec3::new(1.1, 0.02, 0.0);
        let inside = Vec3::new(0.31, -0.27, 0.0);
        let misses = Misses {
            from: vec![EYE],
            dirs: vec![(past - EYE).normalize(), (inside - EYE).normalize()],
            of: Vec::new(),
            whole_discs: false,
        };
        let r = trim(&mut splats, &points, &Viewpoints::One(EYE), &misses, MARGIN);
        assert_eq!((r.misses, r.misses_blocked), (2, 2), "{r:?}");
        assert!(r.shrunk >= 1 && r.kept_whole >= 1, "{r:?}");
        // The miss inside, and the point just under the centre (as in
        // `noise_under_a_surface_opens_no_hole`).
        assert_eq!(r.still_blocked, 2, "{r:?}");
        assert_eq!(holes(&splats), 0, "{r:?}");
        let octree = octree_of(&splats);
        let mut hits = CandidateHits::new(0.0);
        let ray = Ray {
            origin: EYE,
            dir: misses.dirs[0],
        };
        octree.intersect(&ray, 0.0, f32::INFINITY, &mut hits);
        assert!(hits.is_empty());
    }

    /// The same line to a point far under the surface: the scanner saw
    /// through a gap there, and the discs are shrunk off it.
    #[test]
    fn a_line_far_through_a_surface_is_freed() {
        let (mut splats, points) = scene(Vec3::new(0.03, 0.02, -0.5));
        let r = trim_lines(&mut splats, &points);
        assert!(
            r.blocked == 1 && r.kept_whole == 0 && r.shrunk >= 1,
            "{r:?}"
        );
        assert_eq!(r.still_blocked, 0, "{r:?}");
        assert!(holes(&splats) > 0);
    }

    /// Recasting only the lines [`to_recast`] names after shrinks gives
    /// every line the sight casting them all again gives: the blocked
    /// lines, and one whose first splat, at a grazing angle and not
    /// blocking, was shrunk off it, uncovering a blocking one behind.
    #[test]
    fn recasting_the_lines_a_shrink_touched_is_casting_them_all() {
        let (mut splats, mut points) = scene(Vec3::new(0.03, 0.02, -0.5));
        // Outside the square: its line passes beside it.
        let p = Vec3::new(2.0, 0.0, -1.0);
        let (ray, d) = sight_line(EYE, p).unwrap();
        splats.extend(Splat::disc(p, Vec3::Z, 0.02));
        let grazing = splats.len();
        let tilted = Vec3::new(1.0, 0.0, 0.1);
        splats.extend(Splat::disc(ray.at(d - 0.009), tilted, 0.05));
        splats.extend(Splat::disc(ray.at(d - 0.007), Vec3::Z, 0.05));
        points.push(p);
        let line = points.len() - 1;
        let (vp, misses) = (Viewpoints::One(EYE), Misses::default());
        let before = blocked((&splats, &Lines::of(&splats)), &points, &vp, &misses, MARGIN, None);
        assert_eq!(before[line].first, grazing as u32);
        assert_eq!(before[line].block, None);
        let blocked_before = before.iter().filter(|s| s.block.is_some()).count();
        assert_eq!(blocked_before, 1);
        let mut changed = vec![false; splats.len()];
        let unshrunk = splats[grazing];
        shrink_away(&mut splats[grazing], Vec2::ZERO);
        changed[grazing] = true;
        for s in &before {
            if let Some((id, q)) = s.block {
                shrink_away(&mut splats[id as usize], q);
                changed[id as usize] = true;
            }
        }
        let all = blocked((&splats, &Lines::of(&splats)), &points, &vp, &misses, MARGIN, None);
        let again = to_recast(&before, &changed);
        let mut partial = before.clone();
        let recast = blocked((&splats, &Lines::of(&splats)), &points, &vp, &misses, MARGIN, Some(&again));
        for (&i, s) in again.iter().zip(recast) {
            partial[i as usize] = s;
        }
        assert_eq!(partial, all);
        // Parted, the shrunk splats in an octree of their own: the same.
        let few: Vec<u32> = (0..splats.len() as u32).filter(|&i| changed[i as usize]).collect();
        let parted = Lines::parted(&splats, &few);
        assert_eq!(parted.parts.len(), 2);
        assert_eq!(blocked((&splats, &parted), &points, &vp, &misses, MARGIN, None), all);
        // One of them restored (a shrink that opened a hole): the few
        // built again, the rest kept.
        splats[grazing] = unshrunk;
        let restored = blocked((&splats, &parted.with_few(&splats)), &points, &vp, &misses, MARGIN, None);
        assert_eq!(restored, blocked((&splats, &Lines::of(&splats)), &points, &vp, &misses, MARGIN, None));
        assert_eq!(restored[line].first, grazing as u32);
        assert_eq!(all[line].first, grazing as u32 + 1);
        assert!(all[line].block.is_some());
        // The blocked line and the grazing splat's, of 1,682.
        assert_eq!(again.len(), 2, "{} lines", points.len());
    }
}
