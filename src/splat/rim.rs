//! Clip lines at a splat's rim (`docs/DESIGN.md`, "Creases"): where the
//! points of the splat's own face end inside its disc, at a crease or a
//! border, a line of eq. (5)'s clipped disc cuts the rest away. Growth
//! ([`super::grow`]) gathers the face's points and asks [`clip_lines`].

use super::clip::{Clip, ClipLine};
use super::knn::PointTree;
use glam::{Vec2, Vec3};

/// Directions tried for a clip line (evenly spaced over the full turn).
pub const CLIP_DIRECTIONS: usize = 96;

/// A clip line's direction is refined between the coarse directions in
/// this many steps each way, over half a coarse step.
pub const REFINE_STEPS: i32 = 4;

/// A corner's two clip lines are chosen again in turns, each given the
/// other, at most this many times ([`clip_lines`]).
pub const CORNER_ROUNDS: usize = 4;

/// A crease needs at least this many points of the other face past the
/// own face's last points ([`clip_lines`]).
pub const CREASE_MIN_POINTS: usize = 3;

/// ... and a jump of at least this many degrees between the mean normals
/// of the own face's points along the line and of those points.
pub const CREASE_JUMP_DEG: f32 = 30.0;

/// ... and the normals on either side each agree, the length of their
/// mean at least this (a plane each; about 26° of spread): the noise of
/// estimated normals makes no crease.
pub const CREASE_COHERENCE: f32 = 0.9;

/// ... and both run along the line over at least this share of its chord
/// across the disc: a crease crosses the splat, the facet of a fine mesh
/// or a lump of noise does not.
pub const CREASE_LENGTH: f32 = 0.4;

/// ... and only where the face across leaves the splat's plane by more
/// than this many `ϵ` at the disc's rim: a gentler crease, or one near the
/// rim, the whole disc stands close enough to. On the bunny (a scanned
/// mesh whose facets meet at over 30° along 1.4 % of its edges) 1 `ϵ` cost
/// 0.8 dB, 2 `ϵ` 0.03 dB (`docs/notes/README.md`, "Issue 39").
pub const CREASE_RISE_EPS: f32 = 2.0;

/// ... but where both sides are planes, their normals agreeing to this
/// length of their mean (about 2.5° of spread), only by more than
/// [`CREASE_RISE_EPS_PLANES`] `ϵ`: two flat faces meet on a known line, and
/// a disc overhanging it, however close in depth, is shaded as its own
/// face. At 2 `ϵ` the discs along an eave (roof and wall 51° apart)
/// overhung it, seen from below a light seam of roof along the wall
/// (`tests/creases.rs`, the gable block scanned from below: 759 -> 713
/// seam pixels). `compare --truth`, 800×600: solids 36.42 -> 36.97 dB,
/// bunny 37.91 -> 37.90, glass 39.91 (7 more splats), survey 29.44; the
/// rule for every crease (no planes test) took the bunny's clipped splats
/// from 600 to 1,070 and the two-station noisy solids from 35.13 to 34.60
/// dB (`docs/notes/generation.md`, "Issue 54, round 5").
pub const CREASE_PLANES: f32 = 0.999;

/// ... the rise a crease between planes needs (half the span eq. (1)
/// allows a splat's own points either side).
pub const CREASE_RISE_EPS_PLANES: f32 = 0.5;

/// ... and the points across rise from the splat's plane as a face turned
/// by at least this share of that jump: the main axis of their offsets
/// across the line and heights over the plane (total least squares) turns
/// from the plane by at least this share of the angle between the two
/// sides' mean normals. The facets of a scanned mesh (the bunny's) turn
/// their normals by 30–60° while their points stay on the smooth surface,
/// near the plane; a true crease's other face leaves it at its own angle.
/// Measured with `compare --truth` (creases on, 800×600): bunny 37.54 ->
/// 37.77 dB (37.87 creases off), solids 34.20 -> 34.58 dB
/// (`docs/notes/creases.md`, "Issue 39: creases on by default").
pub const CREASE_STEEP: f32 = 0.5;

/// ... and, where the jump is under this many degrees, only where the two
/// sides are not one smooth surface ([`smooth_across`]): the facets of a
/// scanned mesh turn their sampled normals by 32–62° (deciles 1 and 9 of
/// the bunny's crease candidates that passed every other test) over a
/// thin rounded rim (the ears'), whose points across rise steeply; the
/// solids' creases jump by 90° (the median), their roof's by less. With
/// `compare --truth` (creases on, 800×600): glass 39.67 -> 39.96 dB (40.00
/// off), bunny 37.77 -> 37.86 (37.87 off), solids 34.58 -> 34.94; at 50°
/// glass 39.77, bunny 37.76; at 70° glass 39.99, bunny 37.79
/// (`docs/notes/creases.md`, "Issue 39: smooth rims").
pub const CREASE_SMOOTH_JUMP_DEG: f32 = 60.0;

/// [`smooth_across`]: one quadric over both sides may fit this many points
/// (of MSAC's score) worse than a quadric and a plane apart. 0: glass
/// 39.76 dB, solids 34.58 (every roof and cylinder crease kept, too few
/// rims gated); 2: 39.96 / 34.94; 3: 39.97 / 34.96.
pub const CREASE_SMOOTH_SLACK: f32 = 2.0;

/// [`smooth_across`] scores residuals within this many `ϵ` (half the span
/// eq. (1) allows a splat's own points).
pub const CREASE_SMOOTH_TOL: f32 = 0.5;

/// A border (no point past the face's last) needs an empty band at least
/// this many point spacings wide: sampling leaves smaller gaps.
pub const BORDER_SPACINGS: f32 = 2.0;

/// A border's clip line stands at most this many point spacings past the
/// last of the face's points (where the surface ends between them is not
/// known); along a chord of length `L` (in spacings) at `1/L` spacings,
/// the mean distance from a straight border to the last of points spread
/// one per spacing² along it. At a fixed 0.15 spacings the ground of the
/// solids overhung its border by a fraction of a pixel all round: 0.17 %
/// of the image in false hits, against 0.08 % (`docs/notes/creases.md`,
/// "Issue 39, part D").
pub const CLIP_GAP_SPACINGS: f32 = 0.15;

/// ... but on a small splat ([`BORDER_SMALL`]) of a scanned cloud
/// ([`Surface::scanned`]) this many spacings past it (the next scan row)
/// where the face's own points along that rim turn from the splat's
/// normal by at least [`CLIP_GAP_TURN_DEG`]: a rounded edge turns before
/// it ends, and the line at 0.15 cut off `milk.pcd`'s held-out points a
/// little past the training cloud's last (`scan-check`, seeds 1-5, misses
/// with creases 2/3/5/3/3, 16 rays -> 0/1/4/2/3, 10; whole discs
/// 3/1/2/1/1, 8; with the turn gate at 1°: 10, 3°: 10, 5°: 11, 7°: 12,
/// 10°: 15). A box edge's points keep their face's normal: a spacing
/// past them, ungated, the lines overhung the scanned solids' true edges
/// (`tests/creases.rs`, one station 32.09 -> 29.37 dB, two 35.13 ->
/// 33.63, the thin pole failing); with the gate every test there passes.
/// The scanned bunny (`compare scenes/scan.toml --truth`): 34.00 ->
/// 33.99 dB, false hits 0.023 -> 0.033 % (`docs/notes/generation.md`,
/// issue 54, twentieth session).
pub const CLIP_GAP_SCANNED_SPACINGS: f32 = 1.0;

/// ... the turn (degrees) of [`Lines::rim_side`]'s mean normal from the
/// splat's that [`CLIP_GAP_SCANNED_SPACINGS`] asks.
pub const CLIP_GAP_TURN_DEG: f32 = 2.0;

/// ... or, where that band crosses the rim, few points of the face (from
/// the whole cloud, not only the graph's neighbours) in a band
/// [`BORDER_SPACINGS`] deep past the last point, along the line's chord
/// across the disc but at least this many spacings either side of the
/// line's middle: near the rim the chord is short, and random sampling
/// leaves a short band empty by chance (the graph's neighbours just
/// outside the rim, limited to the chord, cost the bunny with creases
/// 0.3 dB; `docs/notes/creases.md`, "Issue 39, part C").
pub const BORDER_HALF_SPACINGS: f32 = 4.0;

/// ... counting the points of the face within this many radii of the
/// splat's plane (the face goes on past the rim, bending as it may).
pub const BORDER_HEIGHT: f32 = 0.5;

/// ... counting fewer of them than this share of the points a face going
/// on past the rim puts in the band (its area outside the disc over
/// spacing²): a straight border's last points, noisy, reach a little past
/// the last one inside the disc; a face going on fills the band.
pub const BORDER_FILL: f32 = 0.1;

/// ... and, on a small splat ([`BORDER_SMALL`]) of a scanned cloud
/// ([`Surface::scanned`]), where the band of
/// [`BORDER_SPACINGS`] past the face's last point (along its chord, at
/// least [`BORDER_HALF_SPACINGS`] either side of its middle) holds no point
/// of any face turned by under [`BORDER_BEND_DEG`] that rises from the
/// plane by at most this many times its offset past that point (plus
/// `ϵ/2`): the graph gathers a face's neighbours, and where a rounded
/// edge's points beyond are turned past [`super::grow::CREASE_DEG`] and
/// none is a neighbour of the face's last points, the face seems to end
/// there. Border lines stood there on `milk.pcd`'s rounded edges, cutting
/// small discs short of held-out points that whole discs reach
/// (`scan-check`, seeds 1-5, misses 3/5/7/6/5 -> 2/3/5/3/3 rays, whole
/// discs 3/1/2/1/1; a rise of 1, band 4 spacings: 2/5/5/3/5;
/// `docs/notes/generation.md`, issue 54, nineteenth session). Only where a
/// scanner saw the cloud: a surface that turns away from it thins out
/// there. The airborne survey's tiles hold no viewpoint, and on them the
/// rule took the lines off the ground's true outer edge: the small survey
/// of `tests/survey.rs` overhung it against the background, false hits
/// 0.367 -> 0.434 % of the image (one point in the band was enough; two:
/// 0.372 %, `milk.pcd` 22 misses; points past 30° only: 0.373 %, 20).
pub const BORDER_RISE: f32 = 3.0;

/// ... counting the points whose normals turn from the seed's by less
/// than this (degrees): a bend, not a wall under an eave. For every splat
/// (no [`BORDER_SMALL`]) and every cloud (no scanner needed) the default
/// survey lost 0.17 dB without it (29.56 -> 29.39) and 0.07 with it; with
/// both 0.01 (29.55).
pub const BORDER_BEND_DEG: f32 = 45.0;

/// ... on a splat whose point spacing is at least this share of its
/// radius (a disc two spacings wide or less, whose band reaches its
/// middle): larger splats have points enough to place a border. For
/// every splat the estimated bunny of `tests/creases.rs` lost 0.19 dB
/// (38.65 -> 38.46, its test failing); at 0.6 `milk.pcd`'s misses went
/// back to 2/4/6/5/6.
pub const BORDER_SMALL: f32 = 0.5;

/// The points past the rim are counted this many at a time, the count
/// stopping once it shows no border ([`Lines::border`]).
const BEYOND_CHUNK: usize = 16;

/// What the clip lines are measured against: the cloud, its normals and
/// kd-tree, `ϵ`, and the cosine at which a neighbour's normal turns onto
/// another face ([`super::grow::CREASE_DEG`]).
pub(super) struct Surface<'a> {
    pub(super) points: &'a [Vec3],
    pub(super) normals: &'a [Vec3],
    pub(super) tree: &'a PointTree,
    pub(super) epsilon: f32,
    pub(super) face_cos: f32,
    /// Seen from a scanner ([`BORDER_RISE`]).
    pub(super) scanned: bool,
}

/// A splat in the making, as its seed sees it: the seed `p` with normal
/// `n`, the metric frame `(a, b, aspect)`, the centre at metric offset
/// `shift` from the seed, metric radius `r`, the plane at height `hc`
/// along `n`.
#[derive(Clone, Copy)]
pub(super) struct Frame {
    pub(super) p: Vec3,
    pub(super) n: Vec3,
    pub(super) a: Vec3,
    pub(super) b: Vec3,
    pub(super) aspect: f32,
    pub(super) shift: Vec2,
    pub(super) r: f32,
    pub(super) hc: f32,
}

impl Frame {
    /// The ball round the splat's centre holding the face's points round
    /// its rim that a border is counted from ([`Lines`]), for the point
    /// spacing `spacing` in radii.
    pub(super) fn reach(&self, spacing: f32) -> Reach {
        let reach = 1.0 + (BORDER_SPACINGS + BORDER_HALF_SPACINGS) * spacing;
        let centre = self.p
            + self.n * self.hc
            + self.a * (self.shift.x * self.aspect)
            + self.b * self.shift.y;
        let ball = reach * self.r * self.aspect;
        Reach {
            centre,
            ball2: ball * ball,
        }
    }

    /// Point `q` of `points` in the splat's normalised coordinates.
    pub(super) fn near(&self, points: &[Vec3], q: usize) -> Near {
        let d = points[q] - self.p;
        Near {
            q: (Vec2::new(self.a.dot(d) / self.aspect, self.b.dot(d)) - self.shift) / self.r,
            h: (self.n.dot(d) - self.hc) / self.r,
            j: q as u32,
        }
    }

    /// [`Frame::near`] of a point inside the disc (`|q| ≤ 1`) with its
    /// height left at zero, for a quiet splat's own face ([`clip_lines`]'
    /// `quiet`), whose heights are never read: with no other face there is
    /// no crease ([`Lines::crease`]), and a scanned cloud's small splat,
    /// where [`Lines::goes_on`] and [`Lines::rim_side`] would read them, is
    /// never quiet. `Err` with the whole [`Frame::near`] of a point past
    /// the rim. The same `q`, bit for bit.
    pub(super) fn near_inside(&self, points: &[Vec3], q: usize) -> Result<Near, Near> {
        let d = points[q] - self.p;
        self.near_inside_at(points, q, Vec2::new(self.a.dot(d) / self.aspect, self.b.dot(d)))
    }

    /// [`Frame::near_inside`] given the point's metric coordinates
    /// `(a·d / aspect, b·d)` (`d` its offset from the seed), as the growth
    /// took them ([`super::grow`]): the same operations, so the same `q`.
    #[inline(always)]
    pub(super) fn near_inside_at(&self, points: &[Vec3], q: usize, xy: Vec2) -> Result<Near, Near> {
        let m = Near {
            q: (xy - self.shift) / self.r,
            h: 0.0,
            j: q as u32,
        };
        if m.q.length_squared() <= 1.0 {
            return Ok(m);
        }
        let d = points[q] - self.p;
        Err(Near {
            h: (self.n.dot(d) - self.hc) / self.r,
            ..m
        })
    }
}

/// A point met while gathering a splat's own face ([`clip_lines`]):
/// its position in the splat's normalised coordinates, its height over the
/// plane (in radii) and its index.
#[derive(Clone, Copy)]
pub(super) struct Near {
    pub(super) q: Vec2,
    h: f32,
    j: u32,
}

impl Near {
    /// Whether the point lies past the disc's rim and near enough its plane
    /// ([`BORDER_HEIGHT`]) to count for a border ([`Lines::border`]).
    pub(super) fn past_rim(&self) -> bool {
        self.h.abs() <= BORDER_HEIGHT && self.q.length_squared() > 1.0
    }
}

/// [`Frame::reach`]: the ball the kd-tree is asked for the face's points
/// round a splat's rim.
#[derive(Clone, Copy)]
pub(super) struct Reach {
    centre: Vec3,
    ball2: f32,
}

impl Reach {
    /// Whether `x` lies in the ball with room to spare: its squared
    /// distance from the centre, however rounded, is within the tree's
    /// bound by [`REACH_MARGIN`], so the tree's query finds it too.
    pub(super) fn surely_holds(&self, x: Vec3) -> bool {
        (x - self.centre).length_squared() <= self.ball2 * (1.0 - REACH_MARGIN)
    }
}

/// [`Reach::surely_holds`]'s room, a share of the squared radius: the
/// squared distances the kd-tree and [`Reach::surely_holds`] take of one
/// point differ by a few roundings of `f32` (about 1e-7 of it each).
const REACH_MARGIN: f32 = 1e-4;

/// Where along `w` (normalised splat coordinates) the face across a crease
/// meets the splat's plane: the offset `s = w·q` of the points of `across`
/// regressed on their height `h` by least squares, and the offset at
/// `h = 0` taken (the two planes' line of intersection, where Zwicker et
/// al.'s clip lines and the 2012 clipping method put it), kept within
/// `[ext, ext + spacing]` (`ext`: the own face's farthest point along `w`).
fn crease_at(across: &[Near], w: Vec2, ext: f32, spacing: f32) -> (f32, f32) {
    let n = across.len() as f32;
    let (mut sh, mut ss, mut shh, mut ssh) = (0f32, 0f32, 0f32, 0f32);
    for p in across {
        let s = w.dot(p.q);
        sh += p.h;
        ss += s;
        shh += p.h * p.h;
        ssh += s * p.h;
    }
    let (mh, ms) = (sh / n, ss / n);
    let var_h = shh / n - mh * mh;
    let slope = if var_h > 1e-12 {
        (ssh / n - ms * mh) / var_h
    } else {
        0.0
    };
    let c = ms - slope * mh;
    if c.is_finite() {
        (c.clamp(ext, ext + spacing), slope)
    } else {
        (ext + CLIP_GAP_SPACINGS * spacing, 0.0)
    }
}

/// The angle (radians, in `[0, π/2]`) between the splat's plane and the
/// main axis of the points of `across` in the plane of their offset
/// `s = w·q` across the line and their height `h` over the splat's plane
/// (total least squares, so a face rising straight up is as well defined
/// as one going on flat).
fn rise_angle(across: &[Near], w: Vec2) -> f32 {
    let n = across.len().max(1) as f32;
    let ms = across.iter().map(|m| w.dot(m.q)).sum::<f32>() / n;
    let mh = across.iter().map(|m| m.h).sum::<f32>() / n;
    let (mut vs, mut vh, mut cv) = (0f32, 0f32, 0f32);
    for m in across {
        let (ds, dh) = (w.dot(m.q) - ms, m.h - mh);
        vs += ds * ds;
        vh += dh * dh;
        cv += ds * dh;
    }
    (0.5 * (2.0 * cv).atan2(vs - vh)).abs()
}

/// Whether the splat's own points `own` and the points `across` a crease
/// candidate lie on one smooth surface: the quadratic height field over
/// the plane of normal `n` (the two sides' mean normals' bisector) fitted
/// to both together ([`super::fit::height_fit`]) fits them within
/// [`CREASE_SMOOTH_SLACK`] points of MSAC's score as closely as a quadric
/// fitted to `own` alone and a plane fitted to `across` alone (a curved
/// face meeting a flat one: the cylinder's side on the ground), with
/// residuals scored within [`CREASE_SMOOTH_TOL`] `ϵ`. `p` is the seed's
/// position (the offsets' origin).
fn smooth_across(own: &[Near], across: &[Near], n: Vec3, inp: &Surface, p: Vec3) -> bool {
    use super::fit::height_fit;
    let off =
        |v: &[Near]| -> Vec<Vec3> { v.iter().map(|m| inp.points[m.j as usize] - p).collect() };
    let (o, ac) = (off(own), off(across));
    let both: Vec<Vec3> = o.iter().chain(ac.iter()).copied().collect();
    let tol = CREASE_SMOOTH_TOL * inp.epsilon;
    let Some(one) = height_fit(&both, n, tol, 6, 6) else {
        return false;
    };
    // Too few own points for a quadric: their plane.
    let apart = height_fit(&o, n, tol, 6, 6)
        .or_else(|| height_fit(&o, n, tol, 3, 3))
        .unwrap_or(0.0)
        + height_fit(&ac, n, tol, 3, 3).unwrap_or(0.0);
    one + CREASE_SMOOTH_SLACK >= apart
}

/// The unit mean of the normals of `pts`, and their coherence: the length
/// of their mean (1 when they agree, smaller the more they spread).
fn mean_normal(pts: &[Near], normals: &[Vec3]) -> (Vec3, f32) {
    let sum = pts.iter().map(|p| normals[p.j as usize]).sum::<Vec3>();
    (
        sum.normalize_or_zero(),
        sum.length() / pts.len().max(1) as f32,
    )
}

/// The unit disc as a polygon, for the area a clip line cuts away.
fn disc_polygon() -> &'static [Vec2] {
    static POLY: std::sync::OnceLock<Vec<Vec2>> = std::sync::OnceLock::new();
    POLY.get_or_init(|| {
        const N: usize = 128;
        (0..N)
            .map(|k| {
                let t = std::f32::consts::TAU * k as f32 / N as f32;
                Vec2::new(t.cos(), t.sin())
            })
            .collect()
    })
}

/// The convex polygon `poly` (counter-clockwise) cut to the side of `l`
/// it keeps (Sutherland–Hodgman, one edge).
fn clip_polygon(poly: &[Vec2], l: ClipLine) -> Vec<Vec2> {
    let mut out = Vec::with_capacity(poly.len() + 2);
    clip_walk(poly, l, |v, _| out.push(v));
    out
}

/// The index after `k` round a polygon of `n` vertices (`(k + 1) % n`
/// without the division).
fn next_vertex(k: usize, n: usize) -> usize {
    if k + 1 == n { 0 } else { k + 1 }
}

/// The vertices of [`clip_polygon`]'s result, in its order, each handed
/// to `visit` with its index in `poly` (`usize::MAX` for a vertex made
/// where an edge crosses `l`): the one clipping loop behind both the
/// polygon and [`clipped_area`]. Each vertex's side `f(q) = a·x + b·y -
/// d` is taken once and carried to the next edge (the same products in
/// the same order, so the same bits as taken twice).
fn clip_walk(poly: &[Vec2], l: ClipLine, mut visit: impl FnMut(Vec2, usize)) {
    let f = |q: Vec2| l.a * q.x + l.b * q.y - l.d;
    let Some(&first) = poly.first() else {
        return;
    };
    let n = poly.len();
    let mut fp = f(first);
    for (k, &p) in poly.iter().enumerate() {
        let q = poly[next_vertex(k, n)];
        let fq = f(q);
        if fp <= 0.0 {
            visit(p, k);
        }
        if (fp <= 0.0) != (fq <= 0.0) {
            visit(p + (q - p) * (fp / (fp - fq)), usize::MAX);
        }
        fp = fq;
    }
}

/// `polygon_area(&clip_polygon(poly, l))`, bit for bit, without the
/// clipped polygon: [`clip_walk`]'s vertices, the shoelace's terms summed
/// in [`polygon_area`]'s order, a term between two of `poly`'s own
/// vertices, consecutive there, read from `edges` (`edges[k]` is
/// `poly[k]`'s term with the next vertex, the same product). The sum
/// starts from zero of either sign: only a zero's sign can differ from
/// `sum`'s, and the area is its absolute value.
fn clipped_area(poly: &[Vec2], edges: &[f32], l: ClipLine) -> f32 {
    let n = poly.len();
    // The first vertex kept, the last (with its index in `poly`, if one
    // of its own), the sum so far.
    let mut first: Option<Vec2> = None;
    let (mut last, mut last_k) = (Vec2::ZERO, usize::MAX);
    let mut sum = 0f32;
    clip_walk(poly, l, |v, k| {
        if first.is_none() {
            first = Some(v);
        } else if k != usize::MAX && last_k != usize::MAX && next_vertex(last_k, n) == k {
            sum += edges[last_k];
        } else {
            sum += last.perp_dot(v);
        }
        (last, last_k) = (v, k);
    });
    if let Some(v) = first {
        sum += last.perp_dot(v);
    }
    0.5 * sum.abs()
}

/// A convex polygon (counter-clockwise) with its shoelace terms and its
/// vertices' coordinates in lanes, for the areas [`Lines::best`]'s lines
/// keep of it ([`Base::clipped_area`]).
struct Base {
    poly: Vec<Vec2>,
    /// `edges[k]`: `poly[k]`'s shoelace term with the next vertex.
    edges: Vec<f32>,
    xs: Vec<f32>,
    ys: Vec<f32>,
}

/// [`Base::clipped_area`] takes the sides of at most this many vertices
/// in its masks (a disc polygon cut by two lines has at most 132); a
/// larger polygon is walked ([`clipped_area`]).
const MASKED_VERTICES: usize = 256;

impl Base {
    fn of(poly: Vec<Vec2>) -> Self {
        let n = poly.len();
        let edges = (0..n)
            .map(|k| poly[k].perp_dot(poly[next_vertex(k, n)]))
            .collect();
        // Padded to whole lanes of 8 with vertices on no side (not a
        // number: never kept, and past `n`, never read).
        let pad = n.next_multiple_of(8) - n;
        let (xs, ys) = poly
            .iter()
            .map(|q| (q.x, q.y))
            .chain(std::iter::repeat_n((f32::NAN, f32::NAN), pad))
            .unzip();
        Base {
            poly,
            edges,
            xs,
            ys,
        }
    }

    /// [`clipped_area`] of the polygon, bit for bit: the same vertices
    /// visited in the same order and the same terms summed in it, but each
    /// vertex's side `a·x + b·y - d ≤ 0` taken in lanes into bit masks (the
    /// same products and sums in their order: the same bits), and the
    /// walk taken by runs of vertices kept and not: a run kept adds its
    /// consecutive terms from `edges`, a run not kept adds nothing, and a
    /// crossing is made only where the side changes, from the two
    /// vertices' sides taken again (the same bits).
    fn clipped_area(&self, l: ClipLine) -> f32 {
        let (poly, edges) = (&self.poly, &self.edges);
        let n = poly.len();
        if n > MASKED_VERTICES {
            return clipped_area(poly, edges, l);
        }
        let mut masks = [0u64; MASKED_VERTICES / 64];
        let lanes = self.xs.chunks_exact(8).zip(self.ys.chunks_exact(8));
        for (c, (xs, ys)) in lanes.enumerate() {
            let (Ok(xs), Ok(ys)) = (xs.try_into(), ys.try_into()) else {
                unreachable!("chunks of 8");
            };
            let m = crate::simd::side_mask8(xs, ys, (l.a, l.b, l.d));
            masks[c >> 3] |= u64::from(m) << (8 * (c & 7));
        }
        let kept = |k: usize| (masks[k >> 6] >> (k & 63)) & 1 != 0;
        // The first index from `k` on whose side is `side` (`n` if none).
        let next_side = |k: usize, side: bool| {
            let word = |c: usize| if side { masks[c] } else { !masks[c] };
            let mut c = k >> 6;
            let mut m = word(c) & (!0u64 << (k & 63));
            while m == 0 {
                c += 1;
                if c * 64 >= n {
                    return n;
                }
                m = word(c);
            }
            (c * 64 + m.trailing_zeros() as usize).min(n)
        };
        let f = |q: Vec2| l.a * q.x + l.b * q.y - l.d;
        // The first vertex visited, the last, the sum so far.
        let mut first: Option<Vec2> = None;
        let mut last = Vec2::ZERO;
        let mut sum = 0f32;
        let mut k = 0;
        while k < n {
            let side = kept(k);
            let end = next_side(k, !side);
            if side {
                let p = poly[k];
                if first.is_none() {
                    first = Some(p);
                } else {
                    sum += last.perp_dot(p);
                }
                for &e in &edges[k..end - 1] {
                    sum += e;
                }
                last = poly[end - 1];
            }
            // The crossing on the run's last edge, if the side changes.
            let j = end - 1;
            let next = next_vertex(j, n);
            if next != 0 || kept(0) != side {
                let (p, q) = (poly[j], poly[next]);
                let (fp, fq) = (f(p), f(q));
                let v = p + (q - p) * (fp / (fp - fq));
                if first.is_none() {
                    first = Some(v);
                } else {
                    sum += last.perp_dot(v);
                }
                last = v;
            }
            k = end;
        }
        if let Some(v) = first {
            sum += last.perp_dot(v);
        }
        0.5 * sum.abs()
    }
}

/// The area of a simple polygon (shoelace).
fn polygon_area(poly: &[Vec2]) -> f32 {
    let n = poly.len();
    0.5 * (0..n)
        .map(|k| poly[k].perp_dot(poly[next_vertex(k, n)]))
        .sum::<f32>()
        .abs()
}

/// Points of a grid over the unit disc, for whether a clip line cuts
/// anything away.
fn disc_grid() -> &'static [Vec2] {
    static GRID: std::sync::OnceLock<Vec<Vec2>> = std::sync::OnceLock::new();
    GRID.get_or_init(|| {
        const N: i32 = 10;
        let mut g = Vec::new();
        for y in -N..=N {
            for x in -N..=N {
                let q = Vec2::new(x as f32, y as f32) / N as f32;
                if q.length_squared() <= 1.0 {
                    g.push(q);
                }
            }
        }
        g
    })
}

/// A splat's clip lines and what a third would cut of what they keep
/// (a share of the disc, [`super::grow::SPILL_SHARE`]).
#[derive(Clone, Copy, Debug)]
pub(super) struct Clipped {
    pub(super) lines: Clip,
    pub(super) spill: f32,
}

impl Clipped {
    pub(super) const NONE: Clipped = Clipped {
        lines: Clip::NONE,
        spill: 0.0,
    };
}

/// The clip lines (none, one or two) of the splat `f`, given the points
/// of its own face inside its disc (`own`, the seed first), those of
/// other faces met while gathering them (`other`), those of its own face
/// met past the rim ([`Near::past_rim`]) that lie in the ball of
/// [`Frame::reach`] ([`Reach::surely_holds`]; `ring`), and the point
/// spacing in radii.
///
/// The points of the splat's own face inside its disc (normals within
/// [`super::grow::CREASE_DEG`] of the seed's) are gathered by a traversal of the
/// neighbourhood graph from the seed through that face, with the points
/// of other faces it meets on the way. For each of [`CLIP_DIRECTIONS`]
/// directions `w` in the splat's normalised coordinates, the part of the
/// disc past the own face's farthest point along `w` holds none of the
/// face's points. It is cut away when the face ends there:
/// - at a crease: at least [`CREASE_MIN_POINTS`] points of other faces
///   lie there, and their mean normal turns from the mean normal of the
///   own face's points along that rim by at least [`CREASE_JUMP_DEG`] (a
///   jump, where a smooth surface bending past [`super::grow::CREASE_DEG`] turns by
///   a little from one point to the next), each side's normals agree
///   ([`CREASE_COHERENCE`]), both run along [`CREASE_LENGTH`] of the
///   chord, the points across rise from the plane at an angle of at
///   least [`CREASE_STEEP`] of that jump ([`rise_angle`]), and the face across leaves the plane by over
///   [`CREASE_RISE_EPS`] `ϵ` at the rim ([`CREASE_RISE_EPS_PLANES`]
///   between planes, [`CREASE_PLANES`]), and, under a jump of
///   [`CREASE_SMOOTH_JUMP_DEG`], the two sides are not one smooth
///   surface ([`smooth_across`]); the line is the two faces'
///   line of intersection ([`crease_at`]);
/// - at a border (a free edge, a hole): no point at all lies there, over
///   a band at least [`BORDER_SPACINGS`] point spacings wide; or, where
///   that band crosses the rim, the cloud holds fewer than
///   [`BORDER_FILL`] of the points a face going on would put in it
///   ([`BORDER_HALF_SPACINGS`], [`BORDER_HEIGHT`]); the line stands
///   the mean gap of evenly spread points short of a straight border
///   past the last point, at most [`CLIP_GAP_SPACINGS`] spacings.
///
/// The candidate cutting away the largest share of the disc is the
/// first line, and the one cutting away the most of what the first
/// keeps the second (a corner); then the first is chosen again, as the
/// one cutting the most of what the second keeps.
///
/// `quiet`: the sets are [`super::grow`]'s quiet ones (no other face, not
/// a scanned cloud's small splat, `own`'s heights not taken): the
/// extents are taken with [`fold_reaching`] first ([`coarse_exts`]).
#[must_use]
pub(super) fn clip_lines(
    s: &Surface,
    f: &Frame,
    (own, other, ring): (&[Near], &[Near], &[Near]),
    spacing: f32,
    quiet: bool,
) -> Clipped {
    let mut lines = Lines::new(s, f, own, other, ring, spacing);
    let step = std::f32::consts::TAU / CLIP_DIRECTIONS as f32;
    let candidates: Vec<(f32, ClipLine)> = lines
        .coarse_lines(quiet)
        .filter_map(|(k, l)| l.map(|l| (step * k as f32, l)))
        .collect();
    if candidates.is_empty() {
        // Nearly every search on a smooth surface: `best` finds nothing.
        return Clipped::NONE;
    }
    let Some((first, cut)) = lines.best(&candidates, &[]) else {
        return Clipped::NONE;
    };
    if cut == 0 {
        return Clipped::NONE;
    }
    let one = Clipped {
        lines: Clip::one(first),
        spill: 0.0,
    };
    let Some((mut second, c)) = lines.best(&candidates, &[first]) else {
        return one;
    };
    if c == 0 {
        return one;
    }
    // At a corner a line chosen alone may turn to take some of what the
    // other cuts, pivoting on the corner's last point and overhanging
    // its own edge at its far end: each is chosen again, in turns, as
    // the line cutting the most of what the other keeps, until neither
    // changes (both then follow their own edges).
    let mut first = first;
    for round in 0..CORNER_ROUNDS {
        let kept_by = if round % 2 == 0 { second } else { first };
        let Some((again, c)) = lines.best(&candidates, &[kept_by]) else {
            break;
        };
        let old = if round % 2 == 0 {
            &mut first
        } else {
            &mut second
        };
        if c == 0 || again == *old {
            break;
        }
        *old = again;
    }
    // What a third line would cut of what the two keep: the face ends
    // on a third side.
    let spill = lines
        .best(&candidates, &[first, second])
        .map_or(0.0, |(_, c)| c as f32 / disc_grid().len() as f32);
    Clipped {
        lines: Clip::two(first, second),
        spill,
    }
}

/// The [`CLIP_DIRECTIONS`] coarse directions of [`clip_lines`], `(cos t,
/// sin t)` at `t = k·τ/CLIP_DIRECTIONS` as [`Lines::line_at`] makes them,
/// made once.
fn coarse_dirs() -> &'static ([f32; CLIP_DIRECTIONS], [f32; CLIP_DIRECTIONS]) {
    static DIRS: std::sync::OnceLock<([f32; CLIP_DIRECTIONS], [f32; CLIP_DIRECTIONS])> =
        std::sync::OnceLock::new();
    DIRS.get_or_init(|| {
        let step = std::f32::consts::TAU / CLIP_DIRECTIONS as f32;
        let (mut xs, mut ys) = ([0f32; CLIP_DIRECTIONS], [0f32; CLIP_DIRECTIONS]);
        for k in 0..CLIP_DIRECTIONS {
            let t = step * k as f32;
            (xs[k], ys[k]) = (t.cos(), t.sin());
        }
        (xs, ys)
    })
}

/// The own face's farthest extent `max w·q` over `own` along each of the
/// [`CLIP_DIRECTIONS`] coarse directions `w` of [`clip_lines`]: the same
/// products, sums and maxima, point by point in the same order, as
/// [`Lines::line_at`] takes along one direction, so bit for bit its `ext`,
/// but all directions at once in lanes.
///
/// The points near the rim (at least [`OUTER_EXT`] from the centre) are
/// folded first. Where every extent is then positive, a point nearer the
/// centre than the least of them (by [`EXT_MARGIN`], against rounding) is
/// below every direction's extent and is passed over; the rest are folded.
/// A maximum of positive values does not depend on the order (equal ones
/// have equal bits); where an extent is not positive (a zero's sign would
/// follow the order), every point is folded again in order.
///
/// With `reaching` the outer points are folded by [`fold_reaching`]
/// first (the same bits where it answers): for [`clip_lines`]' quiet sets, whose
/// faces fill their discs; a face ending inside the disc (at a crease)
/// would fold twice.
fn coarse_exts(own: &[Near], reaching: bool) -> [f32; CLIP_DIRECTIONS] {
    let mut ext = [f32::MIN; CLIP_DIRECTIONS];
    let outer = |m: &&Near| m.q.length_squared() >= OUTER_EXT * OUTER_EXT;
    let mut qs: Vec<Vec2> = own.iter().filter(outer).map(|m| m.q).collect();
    if !(reaching && fold_reaching(&mut ext, &qs)) {
        ext = [f32::MIN; CLIP_DIRECTIONS];
        fold_exts(&mut ext, &qs);
    }
    let least = ext.iter().copied().fold(f32::INFINITY, f32::min);
    if least > 0.0 && least.is_finite() {
        let below = least * least * (1.0 - EXT_MARGIN);
        qs.clear();
        qs.extend(own.iter().map(|m| m.q).filter(|q| {
            let d2 = q.length_squared();
            d2 < OUTER_EXT * OUTER_EXT && d2 >= below
        }));
        fold_exts(&mut ext, &qs);
        return ext;
    }
    ext = [f32::MIN; CLIP_DIRECTIONS];
    qs.clear();
    qs.extend(own.iter().map(|m| m.q));
    fold_exts(&mut ext, &qs);
    ext
}

/// [`fold_reaching`]'s floor: the extents it gives are [`fold_exts`]'
/// wherever every one of them reaches it (a face filling its disc to the
/// rim: on the sphere the least extent is about 0.97).
const REACH_FLOOR: f32 = OUTER_EXT;

/// [`fold_exts`] of the points `qs` into the extents `ext` (all
/// `f32::MIN`), each point folded only into the blocks of [`EXT_LANES`]
/// directions where it can reach [`REACH_FLOOR`]; true where every extent
/// then reaches the floor (else `ext` is not the fold, and the caller
/// folds again in full).
///
/// A point `q` at `r = |q|` reaches `w·q ≥ T` (`T` the floor) only along
/// directions within `α = acos(T/r)` of its own; a block's directions lie
/// within `γ` = 3.5 steps of its centre `c`, so the point can reach one of
/// them only where `c·q ≥ r·cos(γ + α) = T·cos γ − sin γ·√(r² − T²)`.
/// Taking `γ` as 4 steps leaves half a step (3.75°, at least 0.2 % of
/// `w·q`) against the roundings (about 1e-7 each): a point passed over in
/// a block has every product there below `T`. Where every extent is at
/// least `T` those points do not change a maximum of positive values,
/// which does not depend on the order (equal ones have equal bits): the
/// same bits as [`fold_exts`] over every point. On the sphere a point near
/// the rim reaches 2-3 of the 12 blocks: each point is tested against
/// every block's centre and folded into those it can reach, in its order.
fn fold_reaching(ext: &mut [f32; CLIP_DIRECTIONS], qs: &[Vec2]) -> bool {
    const BLOCKS: usize = CLIP_DIRECTIONS / EXT_LANES;
    let step = std::f32::consts::TAU / CLIP_DIRECTIONS as f32;
    let gamma = 4.0 * step;
    let t = REACH_FLOOR;
    let (cg, sg) = (gamma.cos() * t, gamma.sin());
    // Below the floor by more than the roundings: no product reaches it.
    let floor2 = t * t * (1.0 - EXT_MARGIN);
    let (mut cxs, mut cys) = ([0f32; BLOCKS], [0f32; BLOCKS]);
    for b in 0..BLOCKS {
        let mid = step * (b * EXT_LANES) as f32 + 3.5 * step;
        (cxs[b], cys[b]) = (mid.cos(), mid.sin());
    }
    let (xs, ys) = coarse_dirs();
    for &q in qs {
        let r2 = q.length_squared();
        if r2 < floor2 {
            continue;
        }
        let h = cg - sg * (r2 - t * t).max(0.0).sqrt();
        let mut blocks = 0u32;
        for (b, (cx, cy)) in cxs.iter().zip(&cys).enumerate() {
            blocks |= u32::from((cx * q.x) + (cy * q.y) >= h) << b;
        }
        while blocks != 0 {
            let lo = blocks.trailing_zeros() as usize * EXT_LANES;
            blocks &= blocks - 1;
            let lanes = lo..lo + EXT_LANES;
            let e = ext[lanes.clone()].iter_mut();
            for ((a, wx), wy) in e.zip(&xs[lanes.clone()]).zip(&ys[lanes]) {
                *a = at_least((wx * q.x) + (wy * q.y), *a);
            }
        }
    }
    ext.iter().all(|&e| e >= t)
}

/// [`fold_exts`] takes this many directions at once.
const EXT_LANES: usize = 8;
const _: () = assert!(CLIP_DIRECTIONS.is_multiple_of(EXT_LANES));

/// Fold the points `qs`, in their order, into the extents `ext` along
/// [`coarse_dirs`]: `ext[k] = max(ext[k], w_k·q)`, the same products, sum
/// and maximum as one point at a time over every direction, so the same
/// bits; [`EXT_LANES`] directions at a time over all the points, which
/// keeps their extents in registers. The maximum is [`at_least`] with the
/// extent as the floor: an extent is never NaN (it starts at `f32::MIN`
/// and only takes a product above it), so it is `f32::max`'s, of two
/// zeros the extent as `f32::max` keeps it (the test
/// `coarse_exts_are_each_directions_fold` folds signed zeros), without
/// its NaN test and blend (3 of 7 instructions a lane group).
fn fold_exts(ext: &mut [f32; CLIP_DIRECTIONS], qs: &[Vec2]) {
    let (xs, ys) = coarse_dirs();
    let lanes = ext.chunks_exact_mut(EXT_LANES);
    for ((e, wx), wy) in lanes.zip(xs.chunks_exact(EXT_LANES)).zip(ys.chunks_exact(EXT_LANES)) {
        let mut acc = [0f32; EXT_LANES];
        acc.copy_from_slice(e);
        let (mut wxs, mut wys) = ([0f32; EXT_LANES], [0f32; EXT_LANES]);
        wxs.copy_from_slice(wx);
        wys.copy_from_slice(wy);
        for q in qs {
            for ((a, wx), wy) in acc.iter_mut().zip(wxs).zip(wys) {
                *a = at_least((wx * q.x) + (wy * q.y), *a);
            }
        }
        e.copy_from_slice(&acc);
    }
}

/// How many of the points `other` lie [`across`] a candidate line along
/// each of the [`CLIP_DIRECTIONS`] coarse directions of [`clip_lines`],
/// past the own face's extents `exts` ([`coarse_exts`]): the count
/// [`Lines::line_with`] takes along one direction (the same test of the
/// same values, so the same count), for all directions at once in lanes,
/// [`EXT_LANES`] directions over all the points at a time. On the 200k
/// bunny half the splats meet no point of another face (`other` empty:
/// every count zero, nothing counted).
fn coarse_counts(
    other: &Lanes,
    exts: &[f32; CLIP_DIRECTIONS],
    spacing: f32,
) -> [u32; CLIP_DIRECTIONS] {
    let mut counts = [0u32; CLIP_DIRECTIONS];
    if other.xs.is_empty() {
        return counts;
    }
    let (xs, ys) = coarse_dirs();
    let lanes = counts.chunks_exact_mut(EXT_LANES).zip(exts.chunks_exact(EXT_LANES));
    for ((c, e), (wx, wy)) in lanes.zip(xs.chunks_exact(EXT_LANES).zip(ys.chunks_exact(EXT_LANES))) {
        let mut acc = [0u32; EXT_LANES];
        let (mut es, mut wxs, mut wys) = ([0f32; EXT_LANES], [0f32; EXT_LANES], [0f32; EXT_LANES]);
        es.copy_from_slice(e);
        wxs.copy_from_slice(wx);
        wys.copy_from_slice(wy);
        for (&x, &y) in other.xs.iter().zip(&other.ys) {
            let q = Vec2::new(x, y);
            for (((a, &ext), &wx), &wy) in acc.iter_mut().zip(&es).zip(&wxs).zip(&wys) {
                *a += u32::from(across(q, Vec2::new(wx, wy), ext, spacing));
            }
        }
        c.copy_from_slice(&acc);
    }
    counts
}

/// [`coarse_exts`] folds first the points at least this far from the
/// centre (in radii).
const OUTER_EXT: f32 = 0.9;

/// [`coarse_exts`] passes over a point whose squared distance from the
/// centre is below the least extent's square by this share: the products
/// `w·q` along the directions round to within a few `f32` units of `|q|`
/// (about 1e-7 each).
const EXT_MARGIN: f32 = 1e-4;

/// [`Lines::crease`]'s room below the least jump that passes its test:
/// `acos` of the mean normals' dot product, at most the cosine of
/// [`CREASE_JUMP_DEG`], is at least that angle but for a few `f32`
/// roundings (about 1e-7 of it each).
const JUMP_MARGIN: f32 = 1e-3;

/// [`Lines::rim_side`] tests only the own face's points farthest out where
/// the face has at least this many inside the disc (a dense cloud's large
/// splats); a smaller one is passed over whole, cheaper than ordering it.
const RIM_BY_REACH: usize = 128;

/// Points' normalised coordinates in lanes (x's and y's apart), for
/// counts over them that the compiler vectorises.
#[derive(Default)]
struct Lanes {
    xs: Vec<f32>,
    ys: Vec<f32>,
}

impl Lanes {
    fn of(pts: &[Near]) -> Self {
        pts.iter().map(|m| m.q).collect()
    }
}

impl FromIterator<Vec2> for Lanes {
    fn from_iter<I: IntoIterator<Item = Vec2>>(it: I) -> Self {
        let (xs, ys) = it.into_iter().map(|q| (q.x, q.y)).unzip();
        Lanes { xs, ys }
    }
}

/// Points' normalised coordinates in lanes ([`Lanes`]), grouped by the
/// octant of their direction from the centre ([`octant`]): octant `o`'s
/// points are `starts[o]..starts[o + 1]`, in their order within it. The
/// lanes hold the points twice over (`starts[8]` of them, then the same
/// again), so that [`Octants::round_from`] is one slice.
struct Octants {
    lanes: Lanes,
    starts: [usize; 9],
}

impl Octants {
    fn of(pts: &[Near]) -> Self {
        let mut starts = [0usize; 9];
        for m in pts {
            starts[octant(m.q) + 1] += 1;
        }
        for o in 0..8 {
            starts[o + 1] += starts[o];
        }
        let mut at = starts;
        let n = pts.len();
        let (mut xs, mut ys) = (vec![0f32; 2 * n], vec![0f32; 2 * n]);
        for m in pts {
            let o = octant(m.q);
            (xs[at[o]], ys[at[o]]) = (m.q.x, m.q.y);
            at[o] += 1;
        }
        xs.copy_within(..n, n);
        ys.copy_within(..n, n);
        Octants {
            lanes: Lanes { xs, ys },
            starts,
        }
    }

    /// Every point once, from octant `o`'s first round the turn to the
    /// point before it.
    fn round_from(&self, o: usize) -> (&[f32], &[f32]) {
        let (from, n) = (self.starts[o], self.starts[8]);
        let (xs, ys) = (&self.lanes.xs, &self.lanes.ys);
        (&xs[from..from + n], &ys[from..from + n])
    }
}

/// The points of the cloud in the ball of `f`'s [`Frame::reach`], asked
/// of the tree the first time (`ball` keeps them), in the tree's order.
fn ball_of<'b>(
    ball: &'b mut Option<Vec<u32>>,
    s: &Surface<'_>,
    f: &Frame,
    spacing: f32,
) -> &'b [u32] {
    ball.get_or_insert_with(|| {
        let reach = f.reach(spacing);
        s.tree
            .within_unsorted::<kiddo::SquaredEuclidean>(&reach.centre.to_array(), reach.ball2)
            .into_iter()
            .map(|q| q.item)
            .collect()
    })
}

/// The octant (0 to 7, counter-clockwise from `+x`, 45° each) of the
/// direction of `q` from the centre; any octant for NaN.
fn octant(q: Vec2) -> usize {
    let (x, y) = (q.x, q.y);
    match (y >= 0.0, x > 0.0) {
        (true, true) => usize::from(y >= x),
        (true, false) => 2 + usize::from(-x >= y),
        (false, false) => 4 + usize::from(-y >= -x),
        (false, true) => 6 + usize::from(x >= -y),
    }
}

/// [`Lines::border`]'s chord across the disc at the own face's last point
/// `ext`, the gap its line stands past that point, and whether the line is
/// then inside the disc (`spacing` in radii).
///
/// The maximum and minimum are [`at_least`] and [`at_most`]: `f32::max`'s
/// and `f32::min`'s values here (`1 − ext²` is never `−0`; a NaN
/// `spacing` makes the gap NaN either way), without their NaN handling.
#[inline(always)]
fn border_gap(ext: f32, spacing: f32) -> (f32, f32, bool) {
    let chord = 2.0 * at_least(1.0 - ext * ext, 0.0).sqrt();
    let gap = at_most(spacing * spacing / at_least(chord, spacing), CLIP_GAP_SPACINGS * spacing);
    (chord, gap, ext + gap < 1.0)
}

/// `x.max(floor)` for a `floor` that is not NaN, as one `maxss`: `x` where
/// it is above `floor`, else `floor` (a NaN `x` gives `floor`, as
/// `f32::max` does); of two zeros, `floor`. `f32::max` adds a test and a
/// blend for a NaN `floor`.
#[inline(always)]
fn at_least(x: f32, floor: f32) -> f32 {
    if x > floor { x } else { floor }
}

/// `x.min(cap)` for a `cap` that is not NaN, as one `minss`: `x` where it
/// is below `cap`, else `cap` (a NaN `x` gives `cap`, as `f32::min` does);
/// of two zeros, `cap`.
#[inline(always)]
fn at_most(x: f32, cap: f32) -> f32 {
    if x < cap { x } else { cap }
}

/// An extent `from` near the rim and [`border_gap`]'s gap there, at most
/// its gap at any `ext ≥ from` (`spacing` in radii): from `from ≥ 0` on,
/// the chord shrinks as `ext` grows and each operation rounds
/// monotonically, so the gap does not shrink. `ext ≥ from` and
/// `ext + gap ≥ 1` then say the line is not inside the disc with one sum
/// (NaN says nothing: the full test is taken). `from` stands the largest
/// gap short of the rim, where the gap mostly is that largest one.
fn far_gap(spacing: f32) -> (f32, f32) {
    let from = at_least(1.0 - CLIP_GAP_SPACINGS * spacing, 0.0);
    (from, border_gap(from, spacing).1)
}

/// Whether the point at `q` (normalised splat coordinates) lies across a
/// candidate line along `w` past the own face's last point at `ext`
/// ([`Lines::line_with`]): from a spacing short of it to two past it, within
/// the disc's chord. Every test taken (no branch), so that a count over
/// lanes vectorises.
///
/// Taken component by component (`w·q`, then `q - w s` and its squared
/// length), the products and sums glam's `dot`, `*`, `-` and
/// `length_squared` take, in their order: the same bits, and a loop the
/// compiler vectorises (over `Vec2`s it did not).
fn across(q: Vec2, w: Vec2, ext: f32, spacing: f32) -> bool {
    let s = (w.x * q.x) + (w.y * q.y);
    let (x, y) = (q.x - w.x * s, q.y - w.y * s);
    (s >= ext - spacing) & (s <= ext + 2.0 * spacing) & ((x * x) + (y * y) <= 1.0)
}

/// The candidate lines of one splat ([`clip_lines`]), direction by
/// direction.
struct Lines<'a> {
    s: &'a Surface<'a>,
    /// The seed.
    p: Vec3,
    /// The metric radius.
    r: f32,
    own: &'a [Near],
    other: &'a [Near],
    /// The face's points just past the rim that the neighbourhood graph
    /// met while gathering `own`, each in the tree's ball ([`Frame::reach`]):
    /// some of `beyond`, known without asking the tree; in lanes, by
    /// octant.
    ring: Octants,
    /// The face's points (from the whole cloud) just past the rim, asked of
    /// the tree the first time a border's count needs more than `ring`; in
    /// lanes.
    beyond: Option<Lanes>,
    /// The points of the cloud in the ball of [`Frame::reach`] whose
    /// normals turn by under [`BORDER_BEND_DEG`], from `ball`, the first
    /// time a border is found ([`Lines::goes_on`]).
    all: Option<Vec<Near>>,
    /// Every point of the cloud in the ball of [`Frame::reach`], asked of
    /// the tree once, the first time `beyond` or `all` needs it.
    ball: Option<Vec<u32>>,
    /// `other` in lanes.
    other_lanes: Lanes,
    frame: Frame,
    /// The point spacing, in radii.
    spacing: f32,
    jump_cos: f32,
    /// The least jump (radians) between the sides' mean normals that
    /// passes the test against `jump_cos`, less [`JUMP_MARGIN`] of it for
    /// `acos`' rounding ([`Lines::crease`]).
    least_jump: f32,
    /// The normals of `own`, in its order, taken the first time a crease
    /// needs them.
    own_normals: Vec<Vec3>,
    /// The squared distances of `own`'s points from the centre, each with
    /// its place in `own`, farthest first; taken with `own_normals`
    /// ([`Lines::rim_side`]).
    by_reach: Vec<(f32, u32)>,
    /// Scratch: the places in `own` of a crease's rim points.
    rim: Vec<u32>,
    /// Scratch: the points across a crease.
    across: Vec<Near>,
    /// [`Lines::line_at`]'s lines so far, by the angle's bits.
    at: Vec<(u32, Option<ClipLine>)>,
}

impl<'a> Lines<'a> {
    fn new(
        s: &'a Surface<'a>,
        f: &Frame,
        own: &'a [Near],
        other: &'a [Near],
        ring: &'a [Near],
        spacing: f32,
    ) -> Self {
        Lines {
            s,
            p: f.p,
            r: f.r,
            own,
            other,
            ring: Octants::of(ring),
            beyond: None,
            all: None,
            ball: None,
            other_lanes: Lanes::of(other),
            frame: *f,
            spacing,
            jump_cos: CREASE_JUMP_DEG.to_radians().cos(),
            least_jump: CREASE_JUMP_DEG.to_radians().cos().acos() * (1.0 - JUMP_MARGIN),
            own_normals: Vec::new(),
            by_reach: Vec::new(),
            rim: Vec::new(),
            across: Vec::new(),
            at: Vec::new(),
        }
    }

    /// The face's points round the rim, from the whole cloud (the graph
    /// holds only a ring one neighbour deep): where one lies just past the
    /// last inside point along a direction, the face goes on there. Asked
    /// of the tree once, when first needed.
    fn beyond(&mut self) -> &Lanes {
        let (s, f, spacing) = (self.s, self.frame, self.spacing);
        let ball = &mut self.ball;
        self.beyond.get_or_insert_with(|| {
            ball_of(ball, s, &f, spacing)
                .iter()
                .filter(|&&j| s.normals[j as usize].dot(f.n) > s.face_cos)
                .map(|&j| f.near(s.points, j as usize))
                .filter(Near::past_rim)
                .map(|m| m.q)
                .collect()
        })
    }

    /// The line cutting the disc in direction `t` (radians), if the face
    /// ends there. A function of `t` alone for one splat (what
    /// [`Lines::line_with`] takes once and keeps is the same whenever
    /// taken): kept by `t`'s bits, for [`Lines::best`]'s later calls,
    /// which mostly refine round the same coarse direction again.
    fn line_at(&mut self, t: f32) -> Option<ClipLine> {
        if let Some(&(_, l)) = self.at.iter().find(|(bits, _)| *bits == t.to_bits()) {
            return l;
        }
        let w = Vec2::new(t.cos(), t.sin());
        let ext = self.own.iter().map(|m| w.dot(m.q)).fold(f32::MIN, f32::max);
        let l = self.line_with(w, ext);
        self.at.push((t.to_bits(), l));
        l
    }

    /// [`Lines::line_at`] along the unit `w`, the own face's farthest
    /// point along it at `ext`.
    fn line_with(&mut self, w: Vec2, ext: f32) -> Option<ClipLine> {
        let spacing = self.spacing;
        // How many lie across, counted in lanes; gathered only for a
        // crease.
        let (xs, ys) = (&self.other_lanes.xs, &self.other_lanes.ys);
        let count: u32 = xs
            .iter()
            .zip(ys)
            .map(|(&x, &y)| u32::from(across(Vec2::new(x, y), w, ext, spacing)))
            .sum();
        self.line_counted(w, ext, count)
    }

    /// Each coarse direction's candidate line ([`clip_lines`]), in the
    /// directions' order `k` (`t = k·τ/CLIP_DIRECTIONS`): the own face's
    /// extents ([`coarse_exts`]) and the counts across ([`coarse_counts`])
    /// taken once for all of them, each line found as it is asked for
    /// (`reaching`: see [`coarse_exts`]).
    fn coarse_lines(
        &mut self,
        reaching: bool,
    ) -> impl Iterator<Item = (usize, Option<ClipLine>)> + '_ {
        let exts = coarse_exts(self.own, reaching);
        let counts = coarse_counts(&self.other_lanes, &exts, self.spacing);
        let (from, least) = far_gap(self.spacing);
        let (xs, ys) = coarse_dirs();
        (0..CLIP_DIRECTIONS).map(move |k| {
            // No point across and a border's gap, at least `least` past
            // `from`, not inside the disc: no line ([`Lines::border`]'s
            // first test, the same verdict), and no call (most directions
            // of a face reaching its rim).
            if counts[k] == 0 && exts[k] >= from && exts[k] + least >= 1.0 {
                return (k, None);
            }
            let w = Vec2::new(xs[k], ys[k]);
            (k, self.line_counted(w, exts[k], counts[k]))
        })
    }

    /// [`Lines::line_with`] with the count of `other`'s points across
    /// (its own, or [`coarse_counts`]' along a coarse direction).
    fn line_counted(&mut self, w: Vec2, ext: f32, count: u32) -> Option<ClipLine> {
        let spacing = self.spacing;
        let d = if count == 0 {
            self.border(w, ext)?
        } else if count as usize >= CREASE_MIN_POINTS {
            self.across.clear();
            self.across
                .extend(self.other.iter().filter(|m| across(m.q, w, ext, spacing)));
            self.crease(w, ext)?
        } else {
            return None;
        };
        (d > -1.0 && d < 1.0).then_some(ClipLine { a: w.x, b: w.y, d })
    }

    /// A border along `w` past the own face's last point at `ext`: a band
    /// wide enough inside the disc; or, where it crosses the rim, none of
    /// the face's points past the rim in it. The line's offset.
    fn border(&mut self, w: Vec2, ext: f32) -> Option<f32> {
        let spacing = self.spacing;
        // Points spread evenly (one per spacing²) along a chord
        // of length L lie a mean spacing²/L short of a straight
        // border: the line stands there, never farther than
        // CLIP_GAP_SPACINGS. Where that is not inside the disc (the face
        // reaches the rim along `w`) no line is drawn whether the band is
        // open or not: taken first, it spares the band's count (the tree
        // asked for `beyond` is the same whenever it is asked).
        let (chord, gap, inside) = border_gap(ext, spacing);
        if !inside {
            return None;
        }
        // The band's half-width along the chord (both counts below).
        let half = at_least(0.5 * chord, BORDER_HALF_SPACINGS * spacing);
        let band = ext + BORDER_SPACINGS * spacing;
        let open = band < 1.0 || {
            // What a face going on puts in the whole band (over
            // spacing²): `expected` below with the outside's share 1, the
            // same products in the same order, so never less than it (each
            // rounding is monotonic): a count reaching its share of the
            // whole is no border whatever the outside's share. The count
            // stops there (inside a surface, after a tenth of the band's
            // points).
            //
            // The decision rests on the whole count alone, whatever the
            // order the points are counted in: the graph's `ring`, part of
            // `beyond`, is counted first, and where its count reaches that
            // share (inside a surface, nearly always) the tree is not asked.
            // The ring is counted in one pass from the octant before `w`'s
            // round the turn ([`Octants::round_from`]), where the band's
            // points lie.
            let whole = (band - ext) * 2.0 * half / (spacing * spacing);
            //
            // Each chunk's test is taken component by component (glam's
            // `dot` and `perp_dot`, the same products and sums in their
            // order: the same bits) over slices of one length, which the
            // compiler vectorises (the chunks zipped over `Vec2`s it did
            // not).
            let reaches = |mut count: u32, xs: &[f32], ys: &[f32]| {
                let n = xs.len().min(ys.len());
                let mut k = 0;
                while k < n {
                    let e = (k + BEYOND_CHUNK).min(n);
                    let in_band = xs[k..e].iter().zip(&ys[k..e]).map(|(&x, &y)| {
                        let s = (w.x * x) + (w.y * y);
                        let p = (w.x * y) - (w.y * x);
                        u32::from((s > ext) & (s <= band) & (p.abs() <= half))
                    });
                    count += in_band.sum::<u32>();
                    if count as f32 >= BORDER_FILL * whole {
                        return Err(());
                    }
                    k = e;
                }
                Ok(count)
            };
            let (xs, ys) = self.ring.round_from((octant(w) + 7) % 8);
            reaches(0, xs, ys).ok()?;
            let beyond = self.beyond();
            let count = reaches(0, &beyond.xs, &beyond.ys).ok()?;
            // The band's area outside the disc (a grid's share of
            // it), over spacing²: what a face going on puts there.
            // Cell `k`'s `s` is a function of its column `k % N` alone
            // and `t` of its row `k / N`: each taken once, by the same
            // operations (the same bits).
            const N: usize = 8;
            let ss: [f32; N] =
                std::array::from_fn(|i| ext + (band - ext) * (i as f32 + 0.5) / N as f32);
            let ts: [f32; N] =
                std::array::from_fn(|j| half * (2.0 * (j as f32 + 0.5) / N as f32 - 1.0));
            let outside = ts
                .iter()
                .map(|t| ss.iter().filter(|&&s| s * s + t * t > 1.0).count())
                .sum::<usize>() as f32
                / (N * N) as f32;
            let expected = outside * (band - ext) * 2.0 * half / (spacing * spacing);
            (count as f32) < BORDER_FILL * expected
        };
        if !open || self.goes_on(w, ext, half) {
            return None;
        }
        // A scanned small splat's rounded edge ends short of the next
        // row: the line stands there (CLIP_GAP_SCANNED_SPACINGS, never
        // short of `gap`: where that line is not inside, neither is this).
        if self.scanned_small() {
            let (rim_n, _, _) = self.rim_side(w, ext);
            if rim_n.dot(self.frame.n) <= CLIP_GAP_TURN_DEG.to_radians().cos() {
                let wide = ext + CLIP_GAP_SCANNED_SPACINGS * spacing;
                return (wide < 1.0).then_some(wide);
            }
        }
        Some(ext + gap)
    }

    /// A small splat ([`BORDER_SMALL`]) of a scanned cloud
    /// ([`Surface::scanned`]): where the border rules for scans apply.
    fn scanned_small(&self) -> bool {
        self.s.scanned && self.spacing >= BORDER_SMALL
    }

    /// Whether, on a small splat ([`BORDER_SMALL`]), a point of any face
    /// turned by under [`BORDER_BEND_DEG`] lies in a border's band along
    /// `w` past the own face's last point at `ext` (`half` either side of
    /// the chord's middle), rising from the plane no steeper than
    /// [`BORDER_RISE`]: the surface goes on past it, bending. The whole
    /// cloud round the rim, asked of the tree once, when first needed.
    fn goes_on(&mut self, w: Vec2, ext: f32, half: f32) -> bool {
        if !self.scanned_small() {
            return false;
        }
        let (s, f, spacing) = (self.s, self.frame, self.spacing);
        let ball = &mut self.ball;
        let all = self.all.get_or_insert_with(|| {
            let bend_cos = BORDER_BEND_DEG.to_radians().cos();
            ball_of(ball, s, &f, spacing)
                .iter()
                .filter(|&&j| s.normals[j as usize].dot(f.n) >= bend_cos)
                .map(|&j| f.near(s.points, j as usize))
                .collect()
        });
        let band = BORDER_SPACINGS * spacing;
        let flat = 0.5 * s.epsilon / f.r;
        all.iter().any(|m| {
            let past = w.dot(m.q) - ext;
            past > 0.0
                && past <= band
                && w.perp_dot(m.q).abs() <= half
                && m.h.abs() <= BORDER_RISE * past + flat
        })
    }

    /// The own face's side of a crease along `w` past its last point at
    /// `ext`: of its points along the rim (from 1.5 spacings short of it),
    /// the unit mean normal, the coherence ([`mean_normal`]'s, the same sum
    /// in the same order) and their extent along the line. The points not
    /// gathered.
    ///
    /// Where the rim starts past the centre (`from > 0`), a point nearer
    /// the centre than `from` (by [`EXT_MARGIN`], against rounding: `w·q`
    /// rounds to within a few `f32` units of `|w||q|`) cannot reach it
    /// along any direction: only the points of `own` farthest out, found
    /// in `by_reach` (where `own` holds at least [`RIM_BY_REACH`]), are
    /// tested, and those kept are summed in `own`'s
    /// order, so the sums are those of a pass over the whole of `own`.
    fn rim_side(&mut self, w: Vec2, ext: f32) -> (Vec3, f32, f32) {
        if self.own_normals.len() != self.own.len() {
            let normals = self.s.normals;
            self.own_normals = self.own.iter().map(|m| normals[m.j as usize]).collect();
            self.by_reach.clear();
            if self.own.len() >= RIM_BY_REACH {
                self.by_reach
                    .extend((0u32..).zip(self.own).map(|(k, m)| (m.q.length_squared(), k)));
            }
            if self.by_reach.iter().all(|(d2, _)| d2.is_finite()) {
                self.by_reach.sort_unstable_by(|x, y| y.0.total_cmp(&x.0));
            } else {
                self.by_reach.clear();
            }
        }
        let from = ext - 1.5 * self.spacing;
        let (mut sum, mut count) = (Vec3::ZERO, 0usize);
        let (mut lo, mut hi) = (f32::MAX, f32::MIN);
        let mut take = |q: Vec2, n: Vec3| {
            sum += n;
            count += 1;
            let x = w.perp_dot(q);
            (lo, hi) = (lo.min(x), hi.max(x));
        };
        if from > 0.0 && !self.by_reach.is_empty() {
            let bound = from * from * (1.0 - EXT_MARGIN);
            let far = self.by_reach.partition_point(|&(d2, _)| d2 >= bound);
            let own = self.own;
            self.rim.clear();
            self.rim.extend(
                self.by_reach[..far]
                    .iter()
                    .filter(|&&(_, k)| w.dot(own[k as usize].q) >= from)
                    .map(|&(_, k)| k),
            );
            self.rim.sort_unstable();
            for &k in &self.rim {
                take(own[k as usize].q, self.own_normals[k as usize]);
            }
        } else {
            for (m, &n) in self.own.iter().zip(&self.own_normals) {
                if w.dot(m.q) >= from {
                    take(m.q, n);
                }
            }
        }
        (
            sum.normalize_or_zero(),
            sum.length() / count.max(1) as f32,
            hi - lo,
        )
    }

    /// A crease along `w` past the own face's last point at `ext`, between
    /// the own face's points along the rim and those `across`: the line's
    /// offset.
    fn crease(&mut self, w: Vec2, ext: f32) -> Option<f32> {
        let (inp, spacing) = (self.s, self.spacing);
        // Both sides run along the line over most of its chord.
        let chord = 2.0 * (1.0 - ext * ext).max(0.0).sqrt();
        let along = |pts: &[Near]| {
            let (lo, hi) = pts
                .iter()
                .map(|m| w.perp_dot(m.q))
                .fold((f32::MAX, f32::MIN), |(lo, hi), x| (lo.min(x), hi.max(x)));
            hi - lo
        };
        // Where the two faces meet, first: a line there not inside the
        // disc is no line ([`Lines::line_with`]), whatever the tests below
        // say (a function of the points across alone, taken before the
        // normals are read).
        let (c, slope) = crease_at(&self.across, w, ext, spacing);
        let inside = c > -1.0 && c < 1.0;
        if !inside {
            return None;
        }
        // The side across first (a few points): where it fails, the own
        // face's side along the rim is not gathered.
        let (m_across, c_across) = mean_normal(&self.across, inp.normals);
        if c_across < CREASE_COHERENCE || along(&self.across) < CREASE_LENGTH * chord {
            return None;
        }
        // Two of the tests below, taken first where they need only the side
        // across (the own side's rim is a pass over the whole face; on a
        // smooth cloud's facets nine in ten candidates end here, before
        // it): a rise no steeper than the least jump the rim's test lets
        // through allows ([`CREASE_STEEP`]), and a rise that fails however
        // the sides' coherence sets the rise it needs. Each implies the
        // later test's verdict (the same values), so nothing else changes.
        let steep = rise_angle(&self.across, w);
        if steep < CREASE_STEEP * self.least_jump {
            return None;
        }
        let r = self.r;
        let falls = |rise: f32| ((1.0 - c) * r).abs() < slope.abs() * rise * inp.epsilon;
        let least_rise = if c_across >= CREASE_PLANES {
            CREASE_RISE_EPS_PLANES.min(CREASE_RISE_EPS)
        } else {
            CREASE_RISE_EPS
        };
        if falls(least_rise) {
            return None;
        }
        let (m_rim, c_rim, along_rim) = self.rim_side(w, ext);
        let across = &self.across;
        if m_rim.dot(m_across) > self.jump_cos
            || c_rim < CREASE_COHERENCE
            || along_rim < CREASE_LENGTH * chord
        {
            return None;
        }
        // Only where the face across leaves the disc's plane
        // by more than ϵ at its rim: a gentler crease, or one
        // near the rim, the whole disc stands within ϵ of.
        // A face across, not facets of one surface: its points
        // rise from the plane at an angle that goes with the jump.
        let jump = m_rim.dot(m_across).clamp(-1.0, 1.0).acos();
        if steep < CREASE_STEEP * jump {
            return None;
        }
        let rise = if c_rim.min(c_across) >= CREASE_PLANES {
            CREASE_RISE_EPS_PLANES
        } else {
            CREASE_RISE_EPS
        };
        if falls(rise) {
            return None;
        }
        // Facets of one smooth surface, not two faces: below
        // CREASE_SMOOTH_JUMP_DEG, where one quadric fits both sides
        // about as closely as a quadric and a plane apart.
        if jump < CREASE_SMOOTH_JUMP_DEG.to_radians()
            && smooth_across(self.own, across, m_rim + m_across, inp, self.p)
        {
            return None;
        }
        Some(c)
    }

    /// Of the lines found in `lines` (direction, line), the one cutting the
    /// most of what `kept` keeps, with how many of [`disc_grid`]'s points it
    /// cuts of it.
    ///
    /// The best of the coarse directions, then turned by up to half a
    /// step either way to the line cutting the most: a straight border
    /// or crease between two coarse directions is met along its length,
    /// not touched at one end and overhung at the other. "Most" is the
    /// area cut away of what `kept` keeps (the disc as a polygon): a
    /// grid's count cannot tell a line along a border from one turned a
    /// few degrees to pivot on the last point at its end, and overhang
    /// the border at the other.
    fn best(&mut self, lines: &[(f32, ClipLine)], kept: &[ClipLine]) -> Option<(ClipLine, usize)> {
        let step = std::f32::consts::TAU / CLIP_DIRECTIONS as f32;
        let cut = cut_of_kept(kept);
        let (t, coarse) = most_cut(lines, &cut)?;
        // A turned line whose bound ([`segment_bound`]) is below the coarse
        // line's cut cuts strictly less than it: it is never chosen (were
        // the most of the turned ones above the coarse, it would be above
        // this one too), and its cut is not taken.
        let fine = (-REFINE_STEPS..=REFINE_STEPS)
            .filter(|&j| j != 0)
            .filter_map(|j| {
                let l = self.line_at(t + step * j as f32 / (2 * REFINE_STEPS) as f32)?;
                (segment_bound(l.d) >= f64::from(coarse.1)).then(|| (l, cut(&l)))
            })
            .max_by(more);
        let (l, _) = match fine {
            Some(f) if more(&f, &coarse).is_gt() => f,
            _ => coarse,
        };
        let keeps = |q: Vec2| kept.iter().all(|k| k.keeps(q.x, q.y));
        let cuts = disc_grid()
            .iter()
            .filter(|q| keeps(**q) && !l.keeps(q.x, q.y))
            .count();
        Some((l, cuts))
    }
}

/// The area a line cuts away of what the lines `kept` keep of the disc
/// (as a polygon): [`Lines::best`]'s measure, the kept part clipped once.
fn cut_of_kept(kept: &[ClipLine]) -> impl Fn(&ClipLine) -> f32 {
    let base = Base::of(
        kept.iter()
            .fold(disc_polygon().to_vec(), |poly, k| clip_polygon(&poly, *k)),
    );
    let whole = polygon_area(&base.poly);
    move |l: &ClipLine| whole - base.clipped_area(*l)
}

/// Of the lines found in `lines` (direction, line), the one `cut` says
/// cuts the most ([`more`]; of equal ones the last, as `max_by` takes),
/// with its cut: `lines.iter().map(..).max_by(more)`, without the cuts of
/// lines that cannot be the most.
///
/// A line `w·q = d` cuts of any part of the disc's polygon at most the
/// unit disc's segment past it, `acos d − d·√(1 − d²)` ([`segment_bound`]):
/// the lines are taken by `d`, least first (the bound greatest first), and
/// once a line's bound is below the most cut so far, it and every line
/// after it cut less than that (strictly, the bound's room [`CUT_ROOM`]
/// over `cut`'s roundings), and are passed over. On a splat cut by a
/// straight border the first line or two are cut, of a few dozen found.
fn most_cut(
    lines: &[(f32, ClipLine)],
    cut: impl Fn(&ClipLine) -> f32,
) -> Option<(f32, (ClipLine, f32))> {
    let mut order: Vec<(f32, usize)> = lines.iter().map(|(_, l)| l.d).zip(0..).collect();
    order.sort_unstable_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
    let mut most: Option<(usize, (ClipLine, f32))> = None;
    for (d, k) in order {
        if let Some((_, (_, c))) = most
            && segment_bound(d) < f64::from(c)
        {
            break;
        }
        let l = lines[k].1;
        let x = (l, cut(&l));
        let gt = most
            .as_ref()
            .is_none_or(|(j, m)| more(&x, m).then(k.cmp(j)).is_gt());
        if gt {
            most = Some((k, x));
        }
    }
    most.map(|(k, x)| (lines[k].0, x))
}

/// The area of the unit disc past the line `w·q = d` (`w` a unit vector),
/// and [`CUT_ROOM`] over it: more than [`Lines::best`]'s `cut` of any
/// line at `d` on any part of the disc's polygon (inscribed in the unit
/// circle), however rounded.
fn segment_bound(d: f32) -> f64 {
    let d = f64::from(d).clamp(-1.0, 1.0);
    d.acos() - d * (1.0 - d * d).sqrt() + CUT_ROOM
}

/// [`segment_bound`]'s room over the true segment: `cut` is the disc
/// polygon's area (about π) less a clipped area, each a sum of up to 130
/// shoelace terms in `f32` (each rounding within 2.4e-7 of the sums, under
/// 2π): under 1e-4 off in all, however rounded.
const CUT_ROOM: f64 = 2e-4;

/// Which of two (line, area cut) cuts more; of equal cuts, the line
/// standing nearer the centre.
fn more(x: &(ClipLine, f32), y: &(ClipLine, f32)) -> std::cmp::Ordering {
    x.1.total_cmp(&y.1).then(y.0.d.total_cmp(&x.0.d))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`clip_polygon`] and [`clipped_area`] against the one-pass forms
    /// they replace (each side taken twice, `%` for the next vertex, the
    /// clipped polygon built and its area summed by `Iterator::sum`), bit
    /// for bit: the disc's polygon and the polygons one and two lines keep
    /// of it, cut by lines through it, past it, through its vertices and
    /// along its edges.
    #[test]
    fn clipped_areas_are_the_clipped_polygons_areas() {
        let old_clip = |poly: &[Vec2], l: ClipLine| {
            let f = |q: Vec2| l.a * q.x + l.b * q.y - l.d;
            let mut out = Vec::new();
            for (k, &p) in poly.iter().enumerate() {
                let q = poly[(k + 1) % poly.len()];
                let (fp, fq) = (f(p), f(q));
                if fp <= 0.0 {
                    out.push(p);
                }
                if (fp <= 0.0) != (fq <= 0.0) {
                    out.push(p + (q - p) * (fp / (fp - fq)));
                }
            }
            out
        };
        let old_area = |poly: &[Vec2]| {
            let n = poly.len();
            0.5 * (0..n)
                .map(|k| poly[k].perp_dot(poly[(k + 1) % n]))
                .sum::<f32>()
                .abs()
        };
        let mut rng = crate::rng::SplitMix64::new(54);
        let mut unit = || (rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
        let mut lines = Vec::new();
        for k in 0..400 {
            let t = std::f32::consts::TAU * unit();
            let d = match k % 4 {
                0 => 2.4 * unit() - 1.2,
                1 => 1.0,
                2 => (std::f32::consts::PI / 128.0).cos(),
                _ => 0.0,
            };
            let t = if k % 8 == 5 { std::f32::consts::TAU * (k / 8) as f32 / 128.0 } else { t };
            lines.push(ClipLine { a: t.cos(), b: t.sin(), d });
        }
        let mut bases = vec![disc_polygon().to_vec(), Vec::new()];
        for k in 0..20 {
            let once = old_clip(disc_polygon(), lines[k]);
            bases.push(old_clip(&once, lines[k + 20]));
            bases.push(once);
        }
        let mut compared = 0usize;
        for base in &bases {
            let edges: Vec<f32> = (0..base.len())
                .map(|k| base[k].perp_dot(base[next_vertex(k, base.len())]))
                .collect();
            assert_eq!(old_area(base).to_bits(), polygon_area(base).to_bits());
            let masked = Base::of(base.clone());
            for &l in &lines {
                let old = old_clip(base, l);
                let new = clip_polygon(base, l);
                assert_eq!(old.len(), new.len());
                for (a, b) in old.iter().zip(&new) {
                    assert_eq!((a.x.to_bits(), a.y.to_bits()), (b.x.to_bits(), b.y.to_bits()));
                }
                assert_eq!(
                    old_area(&old).to_bits(),
                    clipped_area(base, &edges, l).to_bits(),
                    "{l:?} on a base of {} vertices",
                    base.len()
                );
                assert_eq!(
                    old_area(&old).to_bits(),
                    masked.clipped_area(l).to_bits(),
                    "masked: {l:?} on a base of {} vertices",
                    base.len()
                );
                compared += 1;
            }
        }
        assert_eq!(compared, 42 * 400);
    }

    /// [`border_gap`] with [`at_least`] and [`at_most`] against its
    /// form with `f32::max` and `f32::min`, bit for bit: extents over the
    /// disc and past it, at and near `±1`, `±0`, NaN and infinities, and
    /// spacings from tiny to past the radius (the sides of a NaN `spacing`
    /// are NaN either way: the gap's bits are not compared, only that it
    /// is NaN, and the line is never inside); and the two helpers against
    /// `f32::max` and `f32::min` over pairs of such values.
    #[test]
    fn border_gap_is_its_max_min_form() {
        let old = |ext: f32, spacing: f32| {
            let chord = 2.0 * (1.0 - ext * ext).max(0.0).sqrt();
            let gap = (spacing * spacing / chord.max(spacing)).min(CLIP_GAP_SPACINGS * spacing);
            (chord, gap, ext + gap < 1.0)
        };
        let mut exts: Vec<f32> = (0..=4000).map(|j| -1.2 + 0.0006 * j as f32).collect();
        exts.extend([0.0, -0.0, 1.0, -1.0, f32::NAN, f32::INFINITY, f32::NEG_INFINITY]);
        exts.extend([1.0f32, -1.0].map(|x| f32::from_bits(x.to_bits() - 1)));
        let mut spacings: Vec<f32> = (0..200).map(|i| 1e-6 * 1.1f32.powi(i)).collect();
        spacings.extend([0.0, f32::MIN_POSITIVE, f32::INFINITY, f32::NAN]);
        let mut compared = 0;
        for &spacing in &spacings {
            for &ext in &exts {
                let (got, want) = (border_gap(ext, spacing), old(ext, spacing));
                assert_eq!(got.0.to_bits(), want.0.to_bits(), "{ext} {spacing}");
                assert_eq!(got.2, want.2, "{ext} {spacing}");
                if want.1.is_nan() {
                    assert!(got.1.is_nan(), "{ext} {spacing}");
                } else {
                    assert_eq!(got.1.to_bits(), want.1.to_bits(), "{ext} {spacing}");
                }
                compared += 1;
            }
            let (from, least) = far_gap(spacing);
            let want = (1.0 - CLIP_GAP_SPACINGS * spacing).max(0.0);
            assert_eq!(from.to_bits(), want.to_bits(), "{spacing}");
            let want = old(want, spacing).1;
            assert!(least.to_bits() == want.to_bits() || (least.is_nan() && want.is_nan()));
        }
        assert_eq!(compared, 204 * 4010);
        // The helpers: equal to `f32::max`/`f32::min` wherever the floor
        // (cap) is not NaN, but for two zeros of unlike signs.
        let values: Vec<f32> = exts.iter().chain(&spacings).copied().collect();
        for &x in &values {
            for &y in values.iter().filter(|y| !y.is_nan()) {
                if x == 0.0 && y == 0.0 && x.to_bits() != y.to_bits() {
                    continue;
                }
                assert_eq!(at_least(x, y).to_bits(), x.max(y).to_bits(), "{x} {y}");
                assert_eq!(at_most(x, y).to_bits(), x.min(y).to_bits(), "{x} {y}");
            }
        }
    }

    /// [`Octants::round_from`]: every point once, from the octant's first
    /// round the turn, for rings of 0 to 60 points (some on the axes and
    /// diagonals) and every octant.
    #[test]
    fn octants_round_from_holds_every_point_once() {
        let mut rng = crate::rng::SplitMix64::new(5428);
        let mut uniform = || (rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
        for n in 0..=60 {
            let pts: Vec<Near> = (0..n)
                .map(|j| {
                    let t = std::f32::consts::TAU * uniform();
                    let mut q = Vec2::new(t.cos(), t.sin()) * (1.0 + uniform());
                    if j % 5 == 0 {
                        q = (q * 2.0).round() / 2.0;
                    }
                    Near { q, h: 0.0, j }
                })
                .collect();
            let ring = Octants::of(&pts);
            let mut want: Vec<(u32, u32)> = pts.iter().map(|m| (m.q.x.to_bits(), m.q.y.to_bits())).collect();
            want.sort_unstable();
            for o in 0..8 {
                let (xs, ys) = ring.round_from(o);
                assert_eq!((xs.len(), ys.len()), (pts.len(), pts.len()));
                let mut got: Vec<(u32, u32)> = xs.iter().zip(ys).map(|(x, y)| (x.to_bits(), y.to_bits())).collect();
                if ring.starts[o] < ring.starts[o + 1] {
                    assert_eq!(octant(Vec2::new(xs[0], ys[0])), o, "{n} {o}");
                }
                got.sort_unstable();
                assert_eq!(got, want, "{n} {o}");
            }
        }
    }

    /// [`far_gap`]'s one-sum test says "not inside" only where
    /// [`border_gap`] does, over extents and spacings round the rim.
    #[test]
    fn far_gap_is_borders_verdict() {
        let (mut spared, mut taken) = (0, 0);
        for i in 0..400 {
            let spacing = 0.002 + 0.004 * i as f32;
            let (from, least) = far_gap(spacing);
            for j in 0..=4000 {
                let ext = 0.9 + 0.000_025 * j as f32;
                if ext >= from && ext + least >= 1.0 {
                    assert!(!border_gap(ext, spacing).2, "{ext} {spacing}");
                    spared += 1;
                } else if !border_gap(ext, spacing).2 {
                    taken += 1;
                }
            }
        }
        // Measured: 1,266,898 spared (of 1,600,400), 35 not inside left
        // to the full test.
        assert!(spared > 1_250_000 && taken < 50, "{spared} {taken}");
    }

    /// [`coarse_exts`] gives, bit for bit, the farthest extent
    /// [`Lines::line_at`] folds along each coarse direction: points spread
    /// over the disc, on its rim, snapped to a coarse grid (ties between
    /// points, zeros of both signs), on one side of a line through the
    /// centre (extents of zero and below) and a single point at the centre.
    #[test]
    fn coarse_exts_are_each_directions_fold() {
        let mut rng = crate::rng::SplitMix64::new(54);
        let mut uniform = || (rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
        let step = std::f32::consts::TAU / CLIP_DIRECTIONS as f32;
        let mut compared = 0;
        for case in 0..200 {
            let count = [1, 2, 7, 40, 300][case % 5];
            let own: Vec<Near> = (0..count)
                .map(|j| {
                    let (t, r) = (std::f32::consts::TAU * uniform(), uniform().sqrt());
                    let mut q = Vec2::new(t.cos(), t.sin()) * if case % 7 == 3 { 1.0 } else { r };
                    if case % 3 == 0 {
                        q = (q * 4.0).round() / 4.0;
                    }
                    if count == 1 && case % 2 == 0 {
                        q = Vec2::new(-0.0, 0.0);
                    }
                    if case % 11 == 5 {
                        // One-sided: a face ending through the centre.
                        q.x = q.x.abs();
                    }
                    Near { q, h: 0.0, j }
                })
                .collect();
            for reaching in [false, true] {
                let exts = coarse_exts(&own, reaching);
                for (k, got) in exts.iter().enumerate() {
                    let t = step * k as f32;
                    let w = Vec2::new(t.cos(), t.sin());
                    let want = own.iter().map(|m| w.dot(m.q)).fold(f32::MIN, f32::max);
                    assert_eq!(got.to_bits(), want.to_bits(), "case {case}, direction {k}");
                    compared += 1;
                }
            }
        }
        assert_eq!(compared, 2 * 200 * CLIP_DIRECTIONS);
    }

    /// [`most_cut`] against `max_by(more)` over every line's cut, as
    /// [`Lines::best`] took it: the line and its cut bit for bit, and the
    /// same one of equal lines (the last). Lines along random and coarse
    /// directions at offsets from 0.2 to the rim (many near it, as at a
    /// border; some repeated), cutting the disc's polygon and what one or
    /// two lines keep of it.
    #[test]
    fn most_cut_is_the_max_of_every_cut() {
        let mut rng = crate::rng::SplitMix64::new(5425);
        let mut uniform = || (rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
        let step = std::f32::consts::TAU / CLIP_DIRECTIONS as f32;
        let (mut passed, mut cut_in_all, mut total) = (0usize, 0usize, 0usize);
        for case in 0..600 {
            let line = |t: f32, d: f32| ClipLine {
                a: t.cos(),
                b: t.sin(),
                d,
            };
            let count = 1 + case % 40;
            let mut lines: Vec<(f32, ClipLine)> = (0..count)
                .map(|_| {
                    let t = if case % 2 == 0 {
                        step * (uniform() * CLIP_DIRECTIONS as f32).floor()
                    } else {
                        std::f32::consts::TAU * uniform()
                    };
                    let d = if case % 3 == 0 {
                        0.2 + 0.79 * uniform()
                    } else {
                        0.95 + 0.0499 * uniform()
                    };
                    (t, line(t, d))
                })
                .collect();
            if case % 5 == 0 {
                let again = lines[0];
                lines.push(again);
                lines.insert(0, again);
            }
            let kept: Vec<ClipLine> = (0..case % 3)
                .map(|_| line(std::f32::consts::TAU * uniform(), 0.5 + 0.5 * uniform()))
                .collect();
            let area = cut_of_kept(&kept);
            let calls = std::cell::Cell::new(0usize);
            let cut = |l: &ClipLine| {
                calls.set(calls.get() + 1);
                area(l)
            };
            let want = lines
                .iter()
                .enumerate()
                .map(|(k, (t, l))| (k, *t, (*l, cut(l))))
                .max_by(|x, y| more(&x.2, &y.2));
            calls.set(0);
            let got = most_cut(&lines, cut);
            let (Some((_, t, (l, c))), Some((gt, (gl, gc)))) = (want, got) else {
                panic!("case {case}: none");
            };
            let bits = |l: ClipLine| (l.a.to_bits(), l.b.to_bits(), l.d.to_bits());
            assert_eq!(t.to_bits(), gt.to_bits(), "case {case}");
            assert_eq!(bits(l), bits(gl), "case {case}");
            assert_eq!(c.to_bits(), gc.to_bits(), "case {case}");
            passed += 1;
            cut_in_all += calls.get();
            total += lines.len();
        }
        assert_eq!(passed, 600);
        // Measured: 1,012 of the 12,540 lines cut.
        assert_eq!(total, 12_540);
        assert!(cut_in_all <= 1_100, "{cut_in_all}");
    }

    /// [`fold_reaching`] against [`fold_exts`] over every point, bit for
    /// bit wherever it answers: the outer points (past [`OUTER_EXT`]) of
    /// full discs of 100 to 2,000 points, some on the rim, on the floor's
    /// circle or just inside it, or snapped to a fine grid (ties), and
    /// faces ending inside the disc (where it must decline).
    #[test]
    fn fold_reaching_is_fold_exts() {
        let mut rng = crate::rng::SplitMix64::new(5424);
        let mut uniform = || (rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
        let (mut answered, mut declined) = (0, 0);
        for case in 0..400 {
            let count = [100, 300, 670, 2000][case % 4];
            let qs: Vec<Vec2> = (0..count)
                .map(|_| {
                    let t = std::f32::consts::TAU * uniform();
                    let r = match case % 5 {
                        1 => 1.0,
                        2 => REACH_FLOOR * [1.0, 1.0 - 3e-5, 1.0 + 3e-5][(t * 10.0) as usize % 3],
                        _ => uniform().sqrt(),
                    };
                    let mut q = Vec2::new(t.cos(), t.sin()) * r;
                    if case % 3 == 0 {
                        q = (q * 64.0).round() / 64.0;
                    }
                    if case % 11 == 7 {
                        q.x = q.x.min(0.7);
                    }
                    q
                })
                .filter(|q| q.length_squared() >= OUTER_EXT * OUTER_EXT)
                .collect();
            let mut want = [f32::MIN; CLIP_DIRECTIONS];
            fold_exts(&mut want, &qs);
            let mut got = [f32::MIN; CLIP_DIRECTIONS];
            if !fold_reaching(&mut got, &qs) {
                declined += 1;
                assert!(want.iter().any(|&e| e < REACH_FLOOR), "case {case}");
                continue;
            }
            answered += 1;
            for k in 0..CLIP_DIRECTIONS {
                assert_eq!(got[k].to_bits(), want[k].to_bits(), "case {case}, direction {k}");
            }
        }
        // Measured: 246 answered, 154 declined (of 400).
        assert!(answered >= 240 && declined >= 150, "{answered} {declined}");
    }

    /// [`coarse_counts`] against the count [`Lines::line_with`] takes
    /// along each coarse direction, one point at a time: points of another
    /// face round the rim of a face that ends on one side (as at a crease),
    /// or scattered over the whole disc (a smooth surface's facets), some
    /// on the band's edges (snapped to a coarse grid).
    #[test]
    fn coarse_counts_are_each_directions_count() {
        let mut rng = crate::rng::SplitMix64::new(5423);
        let mut uniform = || (rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
        let step = std::f32::consts::TAU / CLIP_DIRECTIONS as f32;
        let (mut nonzero, mut three) = (0, 0);
        for case in 0..120 {
            let mut disc = |n: usize, lo: f32, hi: f32, snap: bool| -> Vec<Near> {
                (0..n)
                    .map(|j| {
                        let t = std::f32::consts::TAU * uniform();
                        let r = lo + (hi - lo) * uniform().sqrt();
                        let mut q = Vec2::new(t.cos(), t.sin()) * r;
                        if snap {
                            q = (q * 8.0).round() / 8.0;
                        }
                        Near { q, h: 0.0, j: j as u32 }
                    })
                    .collect()
            };
            let snap = case % 3 == 0;
            let mut own = disc(60, 0.0, 0.95, snap);
            let other = if case % 2 == 0 {
                // The face ends at x = 0.5; another face goes on past it.
                own.retain(|m| m.q.x <= 0.5);
                let mut o = disc(40, 0.0, 1.2, snap);
                o.retain(|m| m.q.x > 0.45);
                o
            } else {
                disc(case % 9, 0.0, 1.1, snap)
            };
            let spacing = [0.05, 0.1, 0.125, 0.3][case % 4];
            let exts = coarse_exts(&own, false);
            let counts = coarse_counts(&Lanes::of(&other), &exts, spacing);
            for (k, &got) in counts.iter().enumerate() {
                let t = step * k as f32;
                let w = Vec2::new(t.cos(), t.sin());
                let want = other
                    .iter()
                    .filter(|m| across(m.q, w, exts[k], spacing))
                    .count() as u32;
                assert_eq!(got, want, "case {case}, direction {k}");
                nonzero += usize::from(got > 0);
                three += usize::from(got as usize >= CREASE_MIN_POINTS);
            }
        }
        // Both kinds of count occur: measured 4,841 directions with a point
        // across and 1,270 with three or more (of 11,520).
        assert!(nonzero >= 4500 && three >= 1200, "{nonzero} {three}");
    }
}
