//! Clip partners: the splats on the two sides of a crease cut where their
//! planes meet, so the two faces close along the edge.
//!
//! Growth places a crease line from the points (`grow::crease_at`): where
//! the points across the crease meet the splat's plane. Under range noise
//! that line is only as good as the few points in a band a few spacings
//! wide, and the splat across places its own line from other points: the
//! two lines miss each other by a fraction of a spacing. Where both stand
//! inside the edge a ray passes between them (a pinhole, and light leaking
//! into a shadow); where both stand outside, one overhangs the other face.
//! The 2012 method for clipping splats on sharp edges and corners (The
//! Visual Computer) pairs each clipped splat with a *clip partner* across
//! the edge and cuts it by the partner's plane: both then end on the one
//! line where the two planes meet, the line the rendered surfaces share.
//!
//! A partner of a line is a splat turned by at least
//! [`super::grow::CREASE_DEG`] from the splat, whose plane passes within
//! `ϵ` of the line's midpoint and whose disc holds that midpoint's
//! projection. The line moves onto the planes' intersection where that
//! keeps its direction within [`TURN_DEG`] and its midpoint within `ϵ` of
//! where it was; of several partners, the one moving it farthest out (a
//! splat along an edge meets several across it, and the farthest leaves
//! none of them a gap to show through). A border (no splat across) keeps
//! its line.
//!
//! With `whole_discs` (generation asks for it under strong range noise,
//! `normals::FlatFaces::Strong`, where the points' normals at an edge are
//! too noisy for growth to find every crease and a whole disc on the edge
//! overhangs it, a flap casting a false shadow on the face below), a whole
//! disc that a clipped neighbour's crease line runs across, the neighbour
//! turned as above, is cut by the neighbour's plane: the side under it at a
//! convex edge (the neighbour's centre below the disc's plane), over it at
//! a concave one, where the cut keeps at least a fifth of the disc
//! ([`CUT_MIN_D`]). A cut that leaves one of the points as read (before
//! denoising moved them) within the coverage tolerance of no splat is
//! undone. At weaker noise growth finds the creases and these cuts only
//! add false ones: the bunny's ears (docs/notes/real-scans.md, "the noisy scan,
//! round 4").

use super::clip::{Clip, ClipLine};
use super::knn::PointTree;
use crate::data::Splat;
use glam::{Vec2, Vec3};
use kiddo::SquaredEuclidean;
use kiddo::immutable::float::kdtree::ImmutableKdTree;
use rayon::prelude::*;

/// The most a line may turn to meet its partner's plane (degrees).
pub const TURN_DEG: f32 = 15.0;

/// The lowest offset `d` (normalised) of a line cutting a whole disc: the
/// cut keeps the part `a u + b v <= d`, about a fifth of the disc at -0.6.
pub const CUT_MIN_D: f32 = -0.6;

/// What [`meet_partners`] changed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Met {
    /// Crease lines moved onto a partner's plane.
    pub moved: usize,
    /// Whole discs cut by a clipped neighbour's plane.
    pub cut: usize,
}

type CentreTree = ImmutableKdTree<f32, u64, 3, 32>;

/// Every clipped splat's lines moved onto the planes of their partners,
/// and, with `whole_discs`, whole discs a clipped neighbour's crease line
/// runs across cut by its plane (module doc). `epsilon`: the generation's
/// ϵ in the splats' units. `cloud`: the points and their tree; a cut that
/// leaves one of the disc's points on no splat is undone.
pub fn meet_partners(
    splats: &mut [Splat],
    epsilon: f32,
    whole_discs: bool,
    cloud: (&[Vec3], &PointTree, f32),
) -> Met {
    if splats.iter().all(|s| s.clip.is_none()) {
        return Met::default();
    }
    let coords: Vec<[f32; 3]> = splats.iter().map(|s| s.center.to_array()).collect();
    let tree: CentreTree = ImmutableKdTree::new_from_slice(&coords);
    let near = Near {
        splats,
        tree: &tree,
        r_max: splats
            .iter()
            .map(|s| s.radii.max_element())
            .fold(0.0, f32::max),
        crease_cos: super::grow::CREASE_DEG.to_radians().cos(),
        epsilon,
    };
    let new: Vec<Option<(Clip, bool)>> = (0..splats.len())
        .into_par_iter()
        .map(|i| {
            if !splats[i].clip.is_none() {
                near.moved_lines(i).map(|c| (c, false))
            } else if whole_discs {
                near.cut(i).map(|l| (Clip::one(l), true))
            } else {
                None
            }
        })
        .collect();
    let mut new = new;
    // A cut that leaves one of the disc's points on no splat is undone (it
    // must not open a hole in the cloud's coverage; a moved line's points
    // past the partner's plane are the noise the move is for).
    if new.iter().flatten().any(|&(_, cut)| cut) {
        let mut after = splats.to_vec();
        for (s, n) in after.iter_mut().zip(&new) {
            if let Some((clip, _)) = n {
                s.clip = *clip;
            }
        }
        let now = Near {
            splats: &after,
            ..near
        };
        let undo: Vec<bool> = (0..splats.len())
            .into_par_iter()
            .map(|i| new[i].is_some_and(|(_, cut)| cut) && now.uncovers(i, &splats[i].clip, cloud))
            .collect();
        for (n, u) in new.iter_mut().zip(undo) {
            if u {
                *n = None;
            }
        }
    }
    let mut met = Met::default();
    for (s, n) in splats.iter_mut().zip(new) {
        if let Some((clip, cut)) = n {
            if cut {
                met.cut += 1;
            } else {
                met.moved += clip
                    .lines()
                    .iter()
                    .zip(s.clip.lines())
                    .filter(|(a, b)| a != b)
                    .count();
            }
            s.clip = clip;
        }
    }
    met
}

/// The splats and a tree of their centres.
struct Near<'a> {
    splats: &'a [Splat],
    tree: &'a CentreTree,
    r_max: f32,
    crease_cos: f32,
    epsilon: f32,
}

/// A point of splat `s`'s plane from its normalised coordinates.
fn at(s: &Splat, q: Vec2) -> Vec3 {
    s.center + s.u_axis * (q.x * s.radii.x) + s.v_axis * (q.y * s.radii.y)
}

/// `x`'s normalised coordinates in `s`'s plane, and its height over it.
fn local(s: &Splat, x: Vec3) -> (Vec2, f32) {
    let off = x - s.center;
    (
        Vec2::new(s.u_axis.dot(off) / s.radii.x, s.v_axis.dot(off) / s.radii.y),
        s.normal.dot(off),
    )
}

/// Where `p`'s plane meets `s`'s, as a unit line `a u + b v = d` in `s`'s
/// normalised coordinates keeping the side under `p`'s plane (`None` for
/// parallel planes).
fn meeting(s: &Splat, p: &Splat) -> Option<ClipLine> {
    let a = s.radii.x * p.normal.dot(s.u_axis);
    let b = s.radii.y * p.normal.dot(s.v_axis);
    let d = -p.normal.dot(s.center - p.center);
    let len = a.hypot(b);
    (len > 0.0 && len.is_finite() && d.is_finite()).then(|| ClipLine {
        a: a / len,
        b: b / len,
        d: d / len,
    })
}

impl Near<'_> {
    /// Whether splat `i`, its lines `old` before, now leaves a point that
    /// lay on it on no splat.
    fn uncovers(
        &self,
        i: usize,
        old: &Clip,
        (points, tree, tol): (&[Vec3], &PointTree, f32),
    ) -> bool {
        let s = &self.splats[i];
        let was = Splat { clip: *old, ..*s };
        let r = s.radii.max_element();
        tree.within_unsorted::<SquaredEuclidean>(&s.center.to_array(), r * r)
            .into_iter()
            .map(|nb| points[nb.item as usize])
            .filter(|&x| super::holes::on_splat(&was, x, tol) && !super::holes::on_splat(s, x, tol))
            .any(|x| {
                !self
                    .tree
                    .within_unsorted::<SquaredEuclidean>(&x.to_array(), self.r_max * self.r_max)
                    .into_iter()
                    .any(|nb| super::holes::on_splat(&self.splats[nb.item as usize], x, tol))
            })
    }

    /// The splats within reach of `x` for a splat of radius `r`, turned by
    /// at least the crease angle from `n` (and less than its supplement:
    /// not the other side of a thin sheet).
    fn turned(&self, x: Vec3, r: f32, n: Vec3, skip: usize) -> impl Iterator<Item = &Splat> {
        let reach = r + self.r_max;
        self.tree
            .within_unsorted::<SquaredEuclidean>(&x.to_array(), reach * reach)
            .into_iter()
            .map(|nb| nb.item as usize)
            .filter(move |&j| j != skip)
            .map(|j| &self.splats[j])
            .filter(move |p| p.normal.dot(n).abs() <= self.crease_cos)
    }

    /// Splat `i`'s lines moved onto their partners' planes, or `None` when
    /// none moved.
    fn moved_lines(&self, i: usize) -> Option<Clip> {
        let s = &self.splats[i];
        let turn_cos = TURN_DEG.to_radians().cos();
        let r_min = s.radii.min_element();
        let mut lines: Vec<ClipLine> = s.clip.lines().to_vec();
        let mut moved = false;
        for l in &mut lines {
            let mid = at(s, Vec2::new(l.a, l.b) * l.d);
            // (how far the old midpoint lies past the new line, the line)
            let mut best: Option<(f32, ClipLine)> = None;
            for p in self.turned(mid, s.radii.max_element(), s.normal, i) {
                let (q, h) = local(p, mid);
                if h.abs() > self.epsilon || q.length_squared() > 1.0 {
                    continue;
                }
                let Some(mut m) = meeting(s, p) else {
                    continue;
                };
                let turn = m.a * l.a + m.b * l.b;
                if turn < 0.0 {
                    m = ClipLine {
                        a: -m.a,
                        b: -m.b,
                        d: -m.d,
                    };
                }
                let past = (m.a * l.a * l.d + m.b * l.b * l.d - m.d) * r_min;
                if turn.abs() < turn_cos || past.abs() > self.epsilon || m.d <= -1.0 {
                    continue;
                }
                if best.is_none_or(|(b, _)| past < b) {
                    best = Some((past, m));
                }
            }
            if let Some((_, m)) = best {
                *l = m;
                moved = true;
            }
        }
        moved.then(|| match lines[..] {
            [one] => Clip::one(one),
            [first, second] => Clip::two(first, second),
            _ => s.clip,
        })
    }

    /// The line cutting whole disc `i` where a clipped neighbour's crease
    /// line runs across it: the neighbour's plane, the side under it at a
    /// convex edge and over it at a concave one; of several, the one
    /// cutting the most.
    fn cut(&self, i: usize) -> Option<ClipLine> {
        let s = &self.splats[i];
        let mut best: Option<ClipLine> = None;
        for p in self.turned(s.center, s.radii.max_element(), s.normal, i) {
            let along = p.clip.lines().iter().any(|l| {
                let (q, h) = local(s, at(p, Vec2::new(l.a, l.b) * l.d));
                h.abs() <= self.epsilon && q.length_squared() <= 1.0
            });
            let Some(mut m) = meeting(s, p) else {
                continue;
            };
            if s.normal.dot(p.center - s.center) > 0.0 {
                m = ClipLine {
                    a: -m.a,
                    b: -m.b,
                    d: -m.d,
                };
            }
            if !along || m.d >= 1.0 || m.d < CUT_MIN_D || best.is_some_and(|b| b.d <= m.d) {
                continue;
            }
            // The neighbour's disc holds the cut's point nearest the centre.
            let (q, _) = local(p, at(s, Vec2::new(m.a, m.b) * m.d));
            if q.length_squared() <= 1.0 {
                best = Some(m);
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::splat::NormalField;

    /// A splat at `c` with normal `n`, radius `r`, frame from `u`.
    fn splat(c: Vec3, n: Vec3, u: Vec3, r: f32, clip: Clip) -> Splat {
        Splat {
            center: c,
            normal: n,
            u_axis: u,
            v_axis: n.cross(u),
            radii: Vec2::splat(r),
            color: Vec3::ONE,
            field: NormalField::FLAT,
            clip,
        }
    }

    /// [`meet_partners`] with ϵ = 0.01 and no point near the splats.
    fn meet(s: &mut [Splat], whole: bool) -> Met {
        let far = [Vec3::splat(100.0)];
        let tree = crate::splat::knn::build_tree(&far);
        meet_partners(s, 0.01, whole, (&far, &tree, 0.01))
    }

    fn line(a: f32, b: f32, d: f32) -> ClipLine {
        ClipLine { a, b, d }
    }

    /// The top and the side of a box edge along z at x = 0, y = 0 (top
    /// y = 0 facing +y over x < 0; side x = 0 facing +x under y < 0): each
    /// splat's crease line stands a little inside the edge, as noisy points
    /// put it, so a gap runs between them.
    fn edge(top_d: f32, side_d: f32) -> Vec<Splat> {
        vec![
            // Top: centre at x = -0.05, u = +x, so the edge is u = 0.5.
            splat(
                Vec3::new(-0.05, 0.0, 0.0),
                Vec3::Y,
                Vec3::X,
                0.1,
                Clip::one(line(1.0, 0.0, top_d)),
            ),
            // Side: centre at y = -0.05, u = +y, so the edge is u = 0.5.
            splat(
                Vec3::new(0.0, -0.05, 0.0),
                Vec3::X,
                Vec3::Y,
                0.1,
                Clip::one(line(1.0, 0.0, side_d)),
            ),
        ]
    }

    #[test]
    fn lines_inside_an_edge_move_onto_the_planes_meeting() {
        let mut s = edge(0.45, 0.42);
        let met = meet(&mut s, false);
        assert_eq!(met, Met { moved: 2, cut: 0 });
        for sp in &s {
            let l = sp.clip.lines()[0];
            // The other plane passes through the edge, u = 0.5.
            assert!((l.a - 1.0).abs() < 1e-6 && l.b.abs() < 1e-6, "{l:?}");
            assert!((l.d - 0.5).abs() < 1e-5, "{l:?}");
        }
    }

    #[test]
    fn a_line_farther_than_epsilon_or_without_a_partner_stays() {
        // 0.2 r = 0.02 inside the edge: past ϵ = 0.01.
        let mut s = edge(0.3, 0.3);
        assert_eq!(meet(&mut s, false), Met::default());
        assert_eq!(s[0].clip.lines()[0], line(1.0, 0.0, 0.3));
        // A border: the top alone.
        let mut top = vec![edge(0.45, 0.45)[0]];
        assert_eq!(meet(&mut top, false), Met::default());
        // A smooth bend of 20°: no partner.
        let mut s = edge(0.45, 0.45);
        let n = Vec3::new(20f32.to_radians().sin(), 20f32.to_radians().cos(), 0.0);
        s[1] = splat(
            Vec3::new(0.05, -0.005, 0.0),
            n,
            n.cross(Vec3::Z),
            0.1,
            Clip::NONE,
        );
        let before = s.clone();
        assert_eq!(meet(&mut s, true), Met::default());
        assert_eq!(s, before);
    }

    #[test]
    fn a_whole_disc_over_a_clipped_neighbours_edge_is_cut_only_when_asked() {
        // The top overhangs the edge, whole; the side carries its line.
        let mut s = edge(0.5, 0.5);
        s[0].clip = Clip::NONE;
        let mut kept = s.clone();
        assert_eq!(meet(&mut kept, false).cut, 0);
        assert!(kept[0].clip.is_none());
        let met = meet(&mut s, true);
        assert_eq!(met.cut, 1);
        let l = s[0].clip.lines()[0];
        // Convex: the top keeps x <= 0, u <= 0.5 in its coordinates.
        assert!(
            (l.a - 1.0).abs() < 1e-6 && (l.d - 0.5).abs() < 1e-5,
            "{l:?}"
        );
        // Concave: a floor (y = 0, whole, overhanging x > 0) and a wall
        // rising from it at x = 0, facing -x; the floor keeps x <= 0.
        let mut c = vec![
            splat(
                Vec3::new(-0.05, 0.0, 0.0),
                Vec3::Y,
                Vec3::X,
                0.1,
                Clip::NONE,
            ),
            splat(
                Vec3::new(0.0, 0.05, 0.0),
                -Vec3::X,
                -Vec3::Y,
                0.1,
                Clip::one(line(1.0, 0.0, 0.5)),
            ),
        ];
        assert_eq!(meet(&mut c, true).cut, 1);
        let l = c[0].clip.lines()[0];
        assert!(
            (l.a - 1.0).abs() < 1e-6 && (l.d - 0.5).abs() < 1e-5,
            "{l:?}"
        );
    }

    #[test]
    fn a_cut_that_would_leave_a_point_on_no_splat_is_undone() {
        // The whole top overhangs the edge; a point of it lies past the
        // side's plane (x = 0.02, on the top only): the cut is undone.
        let mut s = edge(0.5, 0.5);
        s[0].clip = Clip::NONE;
        let pts = [Vec3::new(0.02, 0.0, 0.0), Vec3::new(-0.05, 0.0, 0.0)];
        let tree = crate::splat::knn::build_tree(&pts);
        let met = meet_partners(&mut s, 0.01, true, (&pts, &tree, 0.01));
        assert_eq!(met.cut, 0);
        assert!(s[0].clip.is_none());
    }
}
