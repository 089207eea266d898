//! The surface nearest to a point: for each query point, the splat or
//! triangle of a scene closest to it, the closest point on it and their
//! distance. The point-cloud counterpart of Open3D's
//! `RaycastingScene.compute_closest_points` / `compute_distance` (the
//! Python `SplatScene` calls it; issue 55's nearest-distance query).
//!
//! A splat's surface is its flat disc (eq. 2-3: centre, tangent axes and
//! radii) less the parts beyond its clip lines; the Phong normal field of
//! eq. (4) shades it and moves no point of it. A triangle's is the
//! triangle. Each primitive's distance is computed in double precision
//! over the single-precision primitive, the same whatever the order of
//! the visit, so the search's answer is that of visiting every primitive
//! (ties to the lowest id; [`Nearest`]'s unit tests check it).
//!
//! The search is a binary bounding-volume hierarchy of the primitives'
//! boxes, built on the first query (a scene that asks no distance pays
//! nothing), visited nearest box first and pruned by the best distance
//! found. It is its own structure, not a backend's: the backends answer
//! rays, and a point's nearest surface needs boxes ordered by distance,
//! which neither the octree's ray walk nor Embree's ray queries give.

use crate::data::Splat;
use crate::primitive::{Primitive, Triangle};
use glam::{DVec2, DVec3, Vec3};
use rayon::prelude::*;

/// Primitives per leaf at most.
const LEAF: usize = 4;

/// The nearest surface to one query point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Closest {
    /// The primitive's id: a splat's index, or the splats' count plus a
    /// triangle's index (the ids `cast_rays` reports); `u32::MAX` when
    /// the scene has no surface.
    pub id: u32,
    /// The closest point on it, in the scene's frame.
    pub point: DVec3,
    /// Its distance from the query point (infinite with no surface).
    pub distance: f64,
    /// The primitive's unit normal (a splat's `n_i`, a triangle's face
    /// normal): the side a signed distance is positive on.
    pub normal: Vec3,
}

impl Closest {
    const NONE: Closest = Closest {
        id: u32::MAX,
        point: DVec3::splat(f64::NAN),
        distance: f64::INFINITY,
        normal: Vec3::ZERO,
    };

    /// The distance, negative when the query point lies behind the
    /// primitive (against its normal).
    #[must_use]
    pub fn signed(&self, query: DVec3) -> f64 {
        if (query - self.point).dot(self.normal.as_dvec3()) < 0.0 {
            -self.distance
        } else {
            self.distance
        }
    }
}

/// One node: its box, and either its first primitive (in
/// [`Nearest::order`]) and their count (a leaf), or its first child, the
/// second right after it (`count == 0`).
#[derive(Clone, Copy, Debug)]
struct Node {
    lo: [f32; 3],
    hi: [f32; 3],
    first: u32,
    count: u32,
}

/// The nearest-surface search over one scene's splats and triangles
/// (which each query is given again: the search holds boxes and ids
/// only, 21-26 bytes a primitive: a 32-byte node for every 1.6-2.5).
#[derive(Debug)]
pub struct Nearest {
    nodes: Vec<Node>,
    order: Vec<u32>,
    splats: usize,
    triangles: usize,
}

/// A primitive's box: lower and upper corners.
type Box3 = ([f32; 3], [f32; 3]);

impl Nearest {
    /// The search over `splats` and then `tris` (ids in that order). A
    /// primitive that is not finite is left out.
    #[must_use]
    pub fn build(splats: &[Splat], tris: &[Triangle]) -> Nearest {
        let boxes: Vec<Box3> = splats
            .iter()
            .map(|s| prim_box(&s.disc_geometry()))
            .chain(tris.iter().map(prim_box))
            .collect();
        let mut order: Vec<u32> = (0..boxes.len() as u32)
            .filter(|&i| {
                let (lo, hi) = boxes[i as usize];
                lo.iter().chain(&hi).all(|x| x.is_finite())
            })
            .collect();
        let mut nodes = Vec::with_capacity(2 * order.len() / LEAF + 1);
        if !order.is_empty() {
            nodes.push(Node {
                lo: [0.0; 3],
                hi: [0.0; 3],
                first: 0,
                count: 0,
            });
            let len = order.len();
            split(&boxes, &mut order, 0, len, 0, &mut nodes);
        }
        Nearest {
            nodes,
            order,
            splats: splats.len(),
            triangles: tris.len(),
        }
    }

    /// Bytes the search holds.
    #[must_use]
    pub fn memory_bytes(&self) -> usize {
        self.nodes.len() * std::mem::size_of::<Node>() + self.order.len() * 4
    }

    /// The nearest surface to `p` (the scene's frame) among `splats` and
    /// `tris`, the ones the search was built over; on equal distances the
    /// lowest id.
    ///
    /// # Panics
    /// When `splats` or `tris` are not as many as the search was built
    /// over.
    #[must_use]
    pub fn closest(&self, splats: &[Splat], tris: &[Triangle], p: DVec3) -> Closest {
        self.closest_with(splats, tris, p, &mut Vec::new())
    }

    /// [`Nearest::closest`] of every point, in parallel (a stack for each
    /// piece of the work, none for each point).
    #[must_use]
    pub fn closest_all(&self, splats: &[Splat], tris: &[Triangle], points: &[DVec3]) -> Vec<Closest> {
        points
            .par_iter()
            .with_min_len(256)
            .map_init(Vec::new, |stack, &p| self.closest_with(splats, tris, p, stack))
            .collect()
    }

    /// [`Nearest::closest`] with the nodes still to visit kept in `stack`.
    fn closest_with(
        &self,
        splats: &[Splat],
        tris: &[Triangle],
        p: DVec3,
        stack: &mut Vec<(u32, f64)>,
    ) -> Closest {
        assert!(
            splats.len() == self.splats && tris.len() == self.triangles,
            "Nearest::closest: not the primitives it was built over"
        );
        let mut best = Closest::NONE;
        let mut best2 = f64::INFINITY;
        if self.nodes.is_empty() || !p.is_finite() {
            return best;
        }
        stack.clear();
        stack.push((0, 0.0));
        while let Some((at, d2)) = stack.pop() {
            // Equal distances are visited: the lowest id wins a tie.
            if d2 > best2 {
                continue;
            }
            let node = self.nodes[at as usize];
            if node.count > 0 {
                let ids = &self.order[node.first as usize..(node.first + node.count) as usize];
                for &id in ids {
                    let q = match id.checked_sub(self.splats as u32) {
                        None => splat_closest(&splats[id as usize], p),
                        Some(t) => Some(triangle_closest(&tris[t as usize], p)),
                    };
                    // A splat its lines leave nothing of, or a degenerate
                    // triangle, is no surface.
                    let Some(q) = q.filter(|q| q.is_finite()) else {
                        continue;
                    };
                    let e2 = (p - q).length_squared();
                    if e2 < best2 || (e2 == best2 && id < best.id) {
                        best2 = e2;
                        best = Closest {
                            id,
                            point: q,
                            distance: e2.sqrt(),
                            normal: Vec3::ZERO,
                        };
                    }
                }
                continue;
            }
            let (a, b) = (node.first, node.first + 1);
            let da = box_distance2(&self.nodes[a as usize], p);
            let db = box_distance2(&self.nodes[b as usize], p);
            // The nearer child is popped first.
            let (near, far) = if da <= db { ((a, da), (b, db)) } else { ((b, db), (a, da)) };
            if far.1 <= best2 {
                stack.push(far);
            }
            if near.1 <= best2 {
                stack.push(near);
            }
        }
        // The normal of the one primitive kept, not of every one offered.
        if best.id != u32::MAX {
            best.normal = match best.id.checked_sub(self.splats as u32) {
                None => splats[best.id as usize].normal,
                Some(t) => tris[t as usize].unit_normal(),
            };
        }
        best
    }
}

/// Builds the node `at` over `order[start..end]` (its box written here)
/// and its subtree: split at the median of the boxes' centres along the
/// widest axis of the centres until [`LEAF`] remain.
fn split(boxes: &[Box3], order: &mut [u32], start: usize, end: usize, at: usize, nodes: &mut Vec<Node>) {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    let mut clo = [f32::INFINITY; 3];
    let mut chi = [f32::NEG_INFINITY; 3];
    for &i in &order[start..end] {
        let (a, b) = boxes[i as usize];
        for k in 0..3 {
            lo[k] = lo[k].min(a[k]);
            hi[k] = hi[k].max(b[k]);
            let c = 0.5 * (a[k] + b[k]);
            clo[k] = clo[k].min(c);
            chi[k] = chi[k].max(c);
        }
    }
    nodes[at].lo = lo;
    nodes[at].hi = hi;
    let n = end - start;
    if n <= LEAF {
        nodes[at].first = start as u32;
        nodes[at].count = n as u32;
        return;
    }
    let axis = (0..3)
        .max_by(|&a, &b| (chi[a] - clo[a]).total_cmp(&(chi[b] - clo[b])))
        .unwrap_or(0);
    let mid = start + n / 2;
    let centre = |i: &u32| {
        let (a, b) = boxes[*i as usize];
        a[axis] + b[axis]
    };
    order[start..end].select_nth_unstable_by(n / 2, |x, y| centre(x).total_cmp(&centre(y)).then(x.cmp(y)));
    let first = nodes.len();
    let empty = Node {
        lo: [0.0; 3],
        hi: [0.0; 3],
        first: 0,
        count: 0,
    };
    nodes.push(empty);
    nodes.push(empty);
    nodes[at].first = first as u32;
    nodes[at].count = 0;
    split(boxes, order, start, mid, first, nodes);
    split(boxes, order, mid, end, first + 1, nodes);
}

/// Squared distance from `p` to the node's box (0 inside).
#[inline]
fn box_distance2(n: &Node, p: DVec3) -> f64 {
    let mut d2 = 0.0;
    for ((x, l), h) in p.to_array().into_iter().zip(n.lo).zip(n.hi) {
        let (l, h) = (f64::from(l), f64::from(h));
        let e = if x < l {
            l - x
        } else if x > h {
            x - h
        } else {
            0.0
        };
        d2 += e * e;
    }
    d2
}

/// A primitive's box: [`Primitive::center`] and
/// [`Primitive::half_extent`] (the octree's tight box), padded by a few
/// ulps of its coordinates so that the f32 box holds the primitive.
fn prim_box<P: Primitive>(p: &P) -> Box3 {
    let (c, h) = (p.center().as_dvec3(), p.half_extent().as_dvec3());
    let pad = 1e-6 * (c.abs() + h);
    (
        (c - h - pad).as_vec3().to_array(),
        (c + h + pad).as_vec3().to_array(),
    )
}

/// The point of splat `s` closest to `p`: `p` projected onto the splat's
/// plane, then onto the kept part of its disc ([`closest_in_kept`]) in
/// the plane's coordinates along `u_i` and `v_i`; `None` when its clip
/// lines keep nothing of its disc.
fn splat_closest(s: &Splat, p: DVec3) -> Option<DVec3> {
    let c = s.center.as_dvec3();
    let (u, v) = (s.u_axis.as_dvec3(), s.v_axis.as_dvec3());
    let d = p - c;
    let q = DVec2::new(d.dot(u), d.dot(v));
    let radii = s.radii.as_dvec2();
    // A line `a u' + b v' <= d` over the radii-normalised coordinates
    // (`primitive::clip`) is `(a / r_u) x + (b / r_v) y <= d` in the plane's.
    let mut lines = [(DVec2::ZERO, 0.0); 2];
    let mut count = 0;
    for l in s.clip.lines() {
        let w = DVec2::new(f64::from(l.a) / radii.x, f64::from(l.b) / radii.y);
        let len = w.length();
        if len > 0.0 && len.is_finite() {
            lines[count] = (w / len, f64::from(l.d) / len);
            count += 1;
        }
    }
    let k = closest_in_kept(q, radii, &lines[..count])?;
    Some(c + u * k.x + v * k.y)
}

/// The point nearest to `q` of the ellipse `(x / r_x)² + (y / r_y)² <= 1`
/// cut by the half-planes `w · x <= d` (`w` unit); `None` when they leave
/// nothing of it. Inside, `q` itself; else the nearest of: the ellipse's
/// nearest point (when the lines keep it), and each line's nearest point
/// on its chord within the other line. A convex set's nearest point to an
/// outside `q` lies on its boundary, on an arc only when `q` is outside
/// the ellipse (else it is on a chord or a corner, which the chords'
/// ends hold).
fn closest_in_kept(q: DVec2, radii: DVec2, lines: &[(DVec2, f64)]) -> Option<DVec2> {
    let in_ellipse = (q / radii).length_squared() <= 1.0;
    let kept = |x: DVec2| lines.iter().all(|&(w, d)| w.dot(x) <= d);
    if in_ellipse && kept(q) {
        return Some(q);
    }
    let mut best: Option<(f64, DVec2)> = None;
    let mut offer = |x: DVec2| {
        let e = (x - q).length_squared();
        if best.is_none_or(|(b, _)| e < b) {
            best = Some((e, x));
        }
    };
    if !in_ellipse {
        let e = ellipse_closest(q, radii);
        // The arc point counts where the lines keep it, up to rounding.
        if lines.iter().all(|&(w, d)| w.dot(e) <= d + 1e-12 * radii.max_element()) {
            offer(e);
        }
    }
    for (i, &(w, d)) in lines.iter().enumerate() {
        // The line's points `foot + s t`, within the ellipse: a s² + b s + c <= 0.
        let t = w.perp();
        let foot = w * d;
        let (ti, fi) = (t / radii, foot / radii);
        let (a, b, c) = (ti.length_squared(), 2.0 * ti.dot(fi), fi.length_squared() - 1.0);
        let disc = b * b - 4.0 * a * c;
        if !(disc >= 0.0 && a > 0.0) {
            continue;
        }
        let root = disc.sqrt();
        let (mut s0, mut s1) = ((-b - root) / (2.0 * a), (-b + root) / (2.0 * a));
        for (j, &(w2, d2)) in lines.iter().enumerate() {
            if j == i {
                continue;
            }
            // w2 · (foot + s t) <= d2.
            let (k, m) = (w2.dot(t), d2 - w2.dot(foot));
            if k > 0.0 {
                s1 = s1.min(m / k);
            } else if k < 0.0 {
                s0 = s0.max(m / k);
            } else if m < 0.0 {
                s1 = f64::NEG_INFINITY;
            }
        }
        if s0 <= s1 {
            offer(foot + t * (q - foot).dot(t).clamp(s0, s1));
        }
    }
    best.map(|(_, x)| x)
}

/// The point of the ellipse's rim `(x / r_x)² + (y / r_y)² = 1` nearest
/// to `q`: on a circle along `q`'s direction; on an ellipse by bisection
/// of Eberly's root function ("Distance from a Point to an Ellipse, an
/// Ellipsoid, or a Hyperellipsoid", 2013) in the first quadrant, with
/// `q`'s signs restored.
fn ellipse_closest(q: DVec2, radii: DVec2) -> DVec2 {
    if radii.x == radii.y {
        let len = q.length();
        return if len > 0.0 { q * (radii.x / len) } else { DVec2::new(radii.x, 0.0) };
    }
    // Eberly's order: the major radius first.
    let swap = radii.y > radii.x;
    let (e0, e1) = if swap { (radii.y, radii.x) } else { (radii.x, radii.y) };
    let (y0, y1) = if swap { (q.y.abs(), q.x.abs()) } else { (q.x.abs(), q.y.abs()) };
    let (x0, x1) = if y1 > 0.0 {
        if y0 > 0.0 {
            let (z0, z1) = (y0 / e0, y1 / e1);
            let g = z0 * z0 + z1 * z1 - 1.0;
            if g == 0.0 {
                (y0, y1)
            } else {
                let r0 = (e0 / e1) * (e0 / e1);
                let s = eberly_root(r0, z0, z1, g);
                (r0 * y0 / (s + r0), y1 / (s + 1.0))
            }
        } else {
            (0.0, e1)
        }
    } else {
        let (numer, denom) = (e0 * y0, e0 * e0 - e1 * e1);
        if numer < denom {
            let x = numer / denom;
            (e0 * x, e1 * (1.0 - x * x).max(0.0).sqrt())
        } else {
            (e0, 0.0)
        }
    };
    let (x, y) = if swap { (x1, x0) } else { (x0, x1) };
    DVec2::new(x.copysign(q.x), y.copysign(q.y))
}

/// The root `s` of `(r0 z0 / (s + r0))² + (z1 / (s + 1))² = 1` by
/// bisection (Eberly's `GetRoot`; `g` the function's value at 0).
fn eberly_root(r0: f64, z0: f64, z1: f64, g: f64) -> f64 {
    let n0 = r0 * z0;
    let mut s0 = z1 - 1.0;
    let mut s1 = if g < 0.0 { 0.0 } else { n0.hypot(z1) - 1.0 };
    let mut s = 0.0;
    for _ in 0..1100 {
        s = 0.5 * (s0 + s1);
        if s == s0 || s == s1 {
            break;
        }
        let (a, b) = (n0 / (s + r0), z1 / (s + 1.0));
        let f = a * a + b * b - 1.0;
        if f > 0.0 {
            s0 = s;
        } else if f < 0.0 {
            s1 = s;
        } else {
            break;
        }
    }
    s
}

/// The point of triangle `t` nearest to `p` (Ericson, "Real-Time
/// Collision Detection", 5.1.5: the Voronoi regions of its vertices,
/// edges and face), in double precision.
fn triangle_closest(t: &Triangle, p: DVec3) -> DVec3 {
    let [a, b, c] = t.v.map(Vec3::as_dvec3);
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::primitive::clip::{Clip, ClipLine};
    use crate::rng::SplitMix64;
    use glam::Vec2;

    /// Splats of every shape: circles, ellipses, one and two clip lines,
    /// in a box of side 4 around `at`.
    fn splats(rng: &mut SplitMix64, n: usize, at: Vec3) -> Vec<Splat> {
        (0..n)
            .map(|i| {
                let c = at + Vec3::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), rng.range(-2.0, 2.0));
                let r = rng.range(0.05, 0.4);
                let mut s = Splat::disc(c, rng.unit(), r).expect("a unit normal");
                if i % 3 == 1 {
                    s.radii = Vec2::new(r, r * rng.range(0.2, 0.9));
                }
                let line = |rng: &mut SplitMix64| {
                    let a = rng.range(0.0, std::f32::consts::TAU);
                    ClipLine {
                        a: a.cos(),
                        b: a.sin(),
                        d: rng.range(-0.6, 0.9),
                    }
                };
                s.clip = match i % 5 {
                    2 => Clip::one(line(rng)),
                    3 => Clip::two(line(rng), line(rng)),
                    _ => Clip::NONE,
                };
                s
            })
            .collect()
    }

    fn triangles(rng: &mut SplitMix64, n: usize, at: Vec3) -> Vec<Triangle> {
        (0..n)
            .map(|_| {
                let c = at + Vec3::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), rng.range(-2.0, 2.0));
                Triangle {
                    v: [0, 1, 2].map(|_| c + rng.unit() * rng.range(0.05, 0.5)),
                }
            })
            .collect()
    }

    /// Every primitive visited, lowest id on equal distances.
    fn brute(splats: &[Splat], tris: &[Triangle], p: DVec3) -> (u32, f64) {
        let mut best = (u32::MAX, f64::INFINITY);
        for (i, s) in splats.iter().enumerate() {
            if let Some(q) = splat_closest(s, p) {
                let e = (p - q).length_squared();
                if e < best.1 {
                    best = (i as u32, e);
                }
            }
        }
        for (i, t) in tris.iter().enumerate() {
            let e = (p - triangle_closest(t, p)).length_squared();
            if e < best.1 {
                best = ((splats.len() + i) as u32, e);
            }
        }
        (best.0, best.1.sqrt())
    }

    #[test]
    fn the_search_answers_as_visiting_every_primitive() {
        let mut rng = SplitMix64::new(5);
        // Far from the origin, as a scan's frame can be after its offset.
        let at = Vec3::new(300.0, -40.0, 12.0);
        let s = splats(&mut rng, 700, at);
        let t = triangles(&mut rng, 120, at);
        let near = Nearest::build(&s, &t);
        // 23.9 bytes a primitive here (511 nodes); 21-26 at any count.
        let per = near.memory_bytes() as f64 / 820.0;
        assert!((16.0..=30.0).contains(&per), "{per} bytes a primitive");
        let mut on_triangles = 0;
        let mut inside = 0;
        for k in 0..3000 {
            let spread = [0.5f32, 3.0, 40.0][k % 3];
            let mut p = (at + rng.unit() * rng.range(0.0, spread)).as_dvec3();
            if k % 7 == 0 {
                // On a splat's centre: distance 0 unless a line cut it off.
                p = s[rng.below(s.len())].center.as_dvec3();
            }
            let got = near.closest(&s, &t, p);
            let (id, d) = brute(&s, &t, p);
            assert_eq!((got.id, got.distance), (id, d), "point {p}");
            assert!(((p - got.point).length() - d).abs() <= 1e-12 * (1.0 + d));
            on_triangles += usize::from(id as usize >= s.len());
            inside += usize::from(d == 0.0);
        }
        // Both kinds of primitive and exact zeros were met (seed 5: 247
        // nearest triangles, 352 points on a splat).
        assert!(on_triangles > 200 && inside > 300, "{on_triangles} {inside}");
        let all: Vec<DVec3> = (0..500).map(|_| (at + rng.unit() * 3.0).as_dvec3()).collect();
        let par = near.closest_all(&s, &t, &all);
        for (p, c) in all.iter().zip(&par) {
            assert_eq!(*c, near.closest(&s, &t, *p));
        }
    }

    /// The closest point of a primitive against a fine sampling of it: it
    /// lies on the kept part (within rounding), and no sample is nearer
    /// than it by more than the sampling's step.
    #[test]
    fn a_primitives_closest_point_is_nearer_than_every_sample_of_it() {
        let mut rng = SplitMix64::new(11);
        let s = splats(&mut rng, 60, Vec3::ZERO);
        let steps = 160;
        for (i, sp) in s.iter().enumerate() {
            let (ru, rv) = (sp.radii.x, sp.radii.y);
            // A grid over the disc, its rim and its lines' chords.
            let grid = (0..=steps * steps).map(|k| {
                let (a, b) = ((k % (steps + 1)) as f32, (k / (steps + 1)) as f32);
                (2.0 * a / steps as f32 - 1.0, 2.0 * b / steps as f32 - 1.0)
            });
            let rim = (0..4000).map(|k| {
                let a = k as f32 * std::f32::consts::TAU / 4000.0;
                (a.cos(), a.sin())
            });
            let chords = sp.clip.lines().iter().flat_map(|l| {
                (0..=2000).map(move |k| {
                    let s = k as f32 / 1000.0 - 1.0;
                    (l.a * l.d - l.b * s, l.b * l.d + l.a * s)
                })
            });
            let samples: Vec<DVec3> = grid
                .chain(rim)
                .chain(chords)
                .filter(|&(x, y)| x * x + y * y <= 1.0 + 1e-6 && sp.clip.lines().iter().all(|l| l.a * x + l.b * y <= l.d + 1e-6))
                .map(|(x, y)| (sp.center + sp.u_axis * (x * ru) + sp.v_axis * (y * rv)).as_dvec3())
                .collect();
            let step = 2.0 * f64::from(ru.max(rv)) / steps as f64;
            for _ in 0..20 {
                let p = (sp.center + rng.unit() * rng.range(0.0, 1.0)).as_dvec3();
                let got = splat_closest(sp, p);
                if samples.is_empty() {
                    continue;
                }
                let q = got.unwrap_or_else(|| panic!("splat {i}: samples but no closest point"));
                let d = (p - q).length();
                let sampled = samples.iter().map(|x| (p - *x).length()).fold(f64::INFINITY, f64::min);
                // The samples are f32 points (a few 1e-8 off their place).
                assert!(d <= sampled + 1e-6, "splat {i}: {d} beyond a sample at {sampled}");
                let r0 = q - sp.center.as_dvec3();
                assert!(sampled - d <= 1.5 * step, "splat {i}: {d} against samples {sampled}, step {step}, at {:?} clip {:?}, radii {ru} {rv}", (r0.dot(sp.u_axis.as_dvec3()) / f64::from(ru), r0.dot(sp.v_axis.as_dvec3()) / f64::from(rv), r0.dot(sp.normal.as_dvec3())), sp.clip);
                // On the kept part.
                let r = q - sp.center.as_dvec3();
                let (x, y) = (r.dot(sp.u_axis.as_dvec3()) / f64::from(ru), r.dot(sp.v_axis.as_dvec3()) / f64::from(rv));
                // (The tangent frame is unit to f32 rounding, about 1e-7.)
                assert!(x * x + y * y <= 1.0 + 1e-6, "splat {i} off its rim: {x} {y}");
                for l in sp.clip.lines() {
                    assert!(f64::from(l.a) * x + f64::from(l.b) * y <= f64::from(l.d) + 1e-6, "splat {i} past a line");
                }
            }
        }
        for t in triangles(&mut rng, 40, Vec3::ZERO) {
            let samples: Vec<DVec3> = (0..=steps)
                .flat_map(|a| (0..=steps - a).map(move |b| (a, b)))
                .map(|(a, b)| {
                    let (x, y) = (a as f32 / steps as f32, b as f32 / steps as f32);
                    (t.v[0] + (t.v[1] - t.v[0]) * x + (t.v[2] - t.v[0]) * y).as_dvec3()
                })
                .collect();
            let edge = f64::from((t.v[1] - t.v[0]).length().max((t.v[2] - t.v[0]).length()));
            for _ in 0..20 {
                let p = (t.v[0] + rng.unit() * rng.range(0.0, 1.0)).as_dvec3();
                let d = (p - triangle_closest(&t, p)).length();
                let sampled = samples.iter().map(|x| (p - *x).length()).fold(f64::INFINITY, f64::min);
                assert!(d <= sampled + 1e-6 && sampled - d <= 1.5 * edge / steps as f64, "{d} {sampled}");
            }
        }
    }

    #[test]
    fn no_surface_answers_no_id_and_an_infinite_distance() {
        let near = Nearest::build(&[], &[]);
        let c = near.closest(&[], &[], DVec3::ONE);
        assert_eq!((c.id, c.distance), (u32::MAX, f64::INFINITY));
        // A splat its two lines leave nothing of is no surface either.
        let mut s = Splat::disc(Vec3::ZERO, Vec3::Z, 1.0).expect("a unit normal");
        s.clip = Clip::two(ClipLine { a: 1.0, b: 0.0, d: -0.5 }, ClipLine { a: -1.0, b: 0.0, d: -0.5 });
        let near = Nearest::build(&[s], &[]);
        assert_eq!(near.closest(&[s], &[], DVec3::ONE).id, u32::MAX);
    }
}
