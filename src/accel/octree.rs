//! The octree of report §3.1, traversed front to back as in §3.2.
//!
//! Build (§3.1):
//! 1. the root is the bounding cube of every splat disc;
//! 2. each splat is inserted by its *centre* into the leaf containing it, and a
//!    leaf holding more than [`OctreeParams::max_leaf`] centres is split into
//!    eight octants, down to [`OctreeParams::max_depth`] (a cell whose centres
//!    all fall in one finest cell, e.g. coincident splats, stays a leaf);
//! 3. once the tree stands, each splat is added to *every* leaf its disc
//!    overlaps ([`OverlapTest`]), so a ray finds a splat in whichever cell it
//!    meets it (fig. 8).
//!
//! Steps 1–2 are done as one parallel sort of the centres' Morton codes
//! followed by a recursive split of the sorted range — the same tree as
//! inserting one splat at a time, since a cell is split exactly when it holds
//! more than `max_leaf` centres. Step 3 descends the tree once per splat, in
//! parallel over chunks of splats in Morton order; a stable counting sort by
//! leaf then groups the references (no sort of 64-bit pairs).
//!
//! The built tree is flattened into 8-byte [`Node`]s (children of a node stored
//! contiguously, empty children left out) and the leaves' references, stored
//! as [`DiscPack`]s: copies of [`LANES`] discs component by component (SoA),
//! so a leaf's discs are read contiguously and tested four at a time.
//!
//! Traversal (§3.2) computes the entry and exit of a cell's eight children at
//! once, then visits the non-empty ones in the order given by the ray
//! direction's signs (`i ^ sign_mask`, a front-to-back order for octants),
//! skipping every cell whose entry lies beyond the far end of the candidate
//! window (`hits.far()`, nearest + `xi`, §4.3): no hit there can still be a
//! candidate. In a leaf, [`DiscPack::may_hit`] repeats the operations of the
//! shared [`intersect_disc`] on four lanes as a filter; every lane it lets
//! through is decided by [`intersect_disc`] itself and offered to
//! [`CandidateHits::offer`], so the candidates are bit-identical to those of
//! the other backends.
//!
//! Robustness: cells are padded by a few ulps of the scene's coordinates both
//! when splats are inserted and when rays are clipped, so that rounding in the
//! slab test or in a hit's position can never make a ray skip a cell holding a
//! splat it hits. Zero direction components give infinite inverse directions;
//! the NaN of `0 * inf` (origin exactly on a padded plane) is resolved to "miss
//! this cell", which is safe because the padded neighbour then contains the
//! whole ray. A NaN ray visits cells but never hits a splat.

use super::{Backend, BuildStats, Candidate, CandidateHits, Ray, intersect_disc};
use crate::splat::{Disc, Splat};
use glam::Vec3;
use rayon::prelude::*;
use std::time::Instant;

/// Bits of a Morton code per axis: the deepest level the build can reach.
const MORTON_BITS: u32 = 21;

/// How a splat is tested against a leaf cell in step 3 of §3.1.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OverlapTest {
    /// The exact test: the elliptical disc meets the (padded) box. The box's
    /// section by the splat plane is a convex polygon; mapped to the splat's
    /// normalised coordinates (where the disc is the unit circle), the disc
    /// meets it iff the centre lies in the box or some edge of the polygon
    /// passes within distance 1 of the origin.
    Exact,
    /// The report's approximation (§3.1): the splat is replaced by its
    /// bounding square `c ± r_u u ± r_v v`, and it is included unless all four
    /// corners lie beyond the same face of the cell. Conservative (never
    /// misses an overlap), but adds references to cells the disc misses.
    BoundingSquare,
}

/// Build parameters of the [`Octree`].
#[derive(Clone, Debug, PartialEq)]
pub struct OctreeParams {
    /// A leaf holding more splat centres than this is split (§3.1).
    pub max_leaf: usize,
    /// Deepest level (root = 0), at most 21. Guarantees termination when many
    /// splats share a centre.
    pub max_depth: u32,
    /// The splat/cell test of step 3 (§3.1).
    pub overlap: OverlapTest,
    /// **Test only: builds a deliberately broken octree.** When true, step 3
    /// is skipped and each splat sits only in the leaf holding its centre, so
    /// rays miss the parts of splats that reach into neighbouring cells —
    /// exactly the holes fig. 8 warns about. It exists so the validation tools
    /// can show they catch such holes; never render with it.
    pub skip_overlap_insertion: bool,
}

impl Default for OctreeParams {
    /// `max_leaf = 8`, `max_depth = 16`, exact overlap test (measured better
    /// than the bounding square: see README, "Acceleration benchmarks").
    fn default() -> Self {
        OctreeParams {
            max_leaf: 8,
            max_depth: 16,
            overlap: OverlapTest::Exact,
            skip_overlap_insertion: false,
        }
    }
}

/// Flag in [`Node::meta`] marking an interior node.
const INTERIOR: u32 = 1 << 31;
/// A [`Node::meta`] value no real node has: marks a slot not yet emitted.
const UNEMITTED: u32 = u32::MAX;

/// One node of the flattened octree: 8 bytes, no bounds (a cell's box is
/// derived from its parent's during traversal).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(C)]
struct Node {
    /// Interior: index in `nodes` of its first stored child. Leaf: index in
    /// `packs` of its first [`DiscPack`].
    first: u32,
    /// Interior: [`INTERIOR`] | 8-bit mask of the stored (non-empty)
    /// children, bit `o` for octant `o = x | y << 1 | z << 2` (1 = upper
    /// half); child `o` sits at `first + popcount(mask & ((1 << o) - 1))`.
    /// Leaf: the number of packs (bit 31 clear).
    meta: u32,
}

/// The octree of §3.1 over a set of splats.
pub struct Octree {
    nodes: Vec<Node>,
    /// The discs of each leaf's references, [`LANES`] to a pack (copies in
    /// reference order, so a leaf's discs are contiguous in memory; the last
    /// pack of a leaf padded with [`DiscPack::EMPTY`] lanes).
    packs: Vec<DiscPack>,
    /// Splat id of each lane of `packs` ([`NO_SPLAT`] on padding lanes).
    pack_ids: Vec<u32>,
    /// Splat references (lanes holding a splat).
    references: usize,
    /// Lower corner of the root cube.
    root_lo: Vec3,
    /// Edge length of the root cube.
    root_size: f32,
    /// Padding added to every cell, in world units.
    pad: f32,
    stats: BuildStats,
}

/// The pointer tree of the build, flattened afterwards.
enum BuildNode {
    Leaf {
        /// Range of the cell's centres in Morton order.
        begin: u32,
        end: u32,
        /// Leaf number (depth-first order), set after the split.
        id: u32,
    },
    Interior {
        begin: u32,
        end: u32,
        children: Box<[BuildNode; 8]>,
        /// References in the subtree, set after step 3.
        refs: u64,
    },
}

impl BuildNode {
    fn range(&self) -> (u32, u32) {
        match self {
            BuildNode::Leaf { begin, end, .. } | BuildNode::Interior { begin, end, .. } => {
                (*begin, *end)
            }
        }
    }
}

/// Lower corner of child octant `oct` of the cell `(lo, 2 * half)`. Build
/// and traversal derive boxes with this same arithmetic, so they agree to
/// the bit.
#[inline]
fn child_lo(lo: Vec3, half: f32, oct: usize) -> Vec3 {
    Vec3::new(
        if oct & 1 != 0 { lo.x + half } else { lo.x },
        if oct & 2 != 0 { lo.y + half } else { lo.y },
        if oct & 4 != 0 { lo.z + half } else { lo.z },
    )
}

/// Spreads the low 21 bits of `x` to every third bit.
fn spread3(x: u64) -> u64 {
    let mut x = x & 0x1f_ffff;
    x = (x | (x << 32)) & 0x1f_0000_0000_ffff;
    x = (x | (x << 16)) & 0x1f_0000_ff00_00ff;
    x = (x | (x << 8)) & 0x100f_00f0_0f00_f00f;
    x = (x | (x << 4)) & 0x10c3_0c30_c30c_30c3;
    x = (x | (x << 2)) & 0x1249_2492_4924_9249;
    x
}

/// Octant of `code` at `depth` (0 = the root's children).
#[inline]
fn octant_at(code: u64, depth: u32) -> usize {
    ((code >> (3 * (MORTON_BITS - 1 - depth))) & 7) as usize
}

struct Splitter<'a> {
    codes: &'a [u64],
    max_leaf: usize,
    max_depth: u32,
}

impl Splitter<'_> {
    /// Splits the Morton-sorted range `[begin, end)` of a cell at `depth`.
    fn split(&self, begin: usize, end: usize, depth: u32) -> BuildNode {
        let leaf = BuildNode::Leaf {
            begin: begin as u32,
            end: end as u32,
            id: 0,
        };
        if end - begin <= self.max_leaf
            || depth >= self.max_depth
            || self.codes[begin] == self.codes[end - 1]
        {
            return leaf;
        }
        // Child boundaries: the sorted codes are grouped by octant at `depth`.
        let mut bounds = [end; 9];
        bounds[0] = begin;
        for (oct, b) in bounds.iter_mut().enumerate().take(8).skip(1) {
            *b = begin + self.codes[begin..end].partition_point(|&c| octant_at(c, depth) < oct);
        }
        let make = |oct: usize| self.split(bounds[oct], bounds[oct + 1], depth + 1);
        let children: Vec<BuildNode> = if end - begin > 20_000 {
            (0..8).into_par_iter().map(make).collect()
        } else {
            (0..8).map(make).collect()
        };
        let children: Box<[BuildNode; 8]> = match children.into_boxed_slice().try_into() {
            Ok(c) => c,
            Err(_) => unreachable!("eight children"),
        };
        BuildNode::Interior {
            begin: begin as u32,
            end: end as u32,
            children,
            refs: 0,
        }
    }
}

/// Numbers the leaves depth first; returns the leaf count.
fn number_leaves(node: &mut BuildNode, next: &mut u32) {
    match node {
        BuildNode::Leaf { id, .. } => {
            *id = *next;
            *next += 1;
        }
        BuildNode::Interior { children, .. } => {
            for c in children.iter_mut() {
                number_leaves(c, next);
            }
        }
    }
}

/// What step 3 tests a splat with.
struct Footprint {
    /// Padded bounds of the tested shape (disc or bounding square).
    lo: Vec3,
    hi: Vec3,
    disc: Disc,
    exact: bool,
}

/// Exact test: does the elliptical `disc` meet the box `[lo, hi]`?
///
/// The box's section by the splat plane is the convex hull of the points
/// where the plane crosses box edges (plus corners lying on it). In the
/// disc's normalised coordinates the disc is the unit circle, so the two meet
/// iff the disc centre lies in the box (then it lies in the section) or the
/// hull comes within distance 1 of the origin; the latter is checked over all
/// segments between section points, which include the hull's edges and
/// otherwise lie inside it.
#[must_use]
fn disc_meets_box(d: &Disc, lo: Vec3, hi: Vec3) -> bool {
    if d.center.cmpge(lo).all() && d.center.cmple(hi).all() {
        return true;
    }
    let half = (hi - lo) * 0.5;
    let rel_mid = (lo + half) - d.center;
    if d.normal.dot(rel_mid).abs() > d.normal.abs().dot(half) {
        return false;
    }
    let mut s = [0.0f32; 8];
    let mut uv = [[0.0f32; 2]; 8];
    for k in 0..8 {
        let rel = lo - d.center
            + Vec3::new(
                if k & 1 != 0 { hi.x - lo.x } else { 0.0 },
                if k & 2 != 0 { hi.y - lo.y } else { 0.0 },
                if k & 4 != 0 { hi.z - lo.z } else { 0.0 },
            );
        s[k] = d.normal.dot(rel);
        uv[k] = [rel.dot(d.u_scaled), rel.dot(d.v_scaled)];
    }
    let mut pts = [[0.0f32; 2]; 12];
    let mut n = 0;
    for k in 0..8 {
        if s[k] == 0.0 {
            pts[n] = uv[k];
            n += 1;
        }
    }
    for a in 0..8 {
        for bit in [1usize, 2, 4] {
            if a & bit != 0 {
                continue;
            }
            let b = a | bit;
            if (s[a] < 0.0 && s[b] > 0.0) || (s[a] > 0.0 && s[b] < 0.0) {
                let t = s[a] / (s[a] - s[b]);
                pts[n] = [
                    uv[a][0] + (uv[b][0] - uv[a][0]) * t,
                    uv[a][1] + (uv[b][1] - uv[a][1]) * t,
                ];
                n += 1;
            }
        }
    }
    let pts = &pts[..n.min(12)];
    for (i, p) in pts.iter().enumerate() {
        if p[0] * p[0] + p[1] * p[1] <= 1.0 {
            return true;
        }
        for q in &pts[i + 1..] {
            if segment_within_unit(*p, *q) {
                return true;
            }
        }
    }
    false
}

/// Does the segment `pq` pass within distance 1 of the origin?
fn segment_within_unit(p: [f32; 2], q: [f32; 2]) -> bool {
    let e = [q[0] - p[0], q[1] - p[1]];
    let ee = e[0] * e[0] + e[1] * e[1];
    if ee <= 0.0 {
        return false;
    }
    let t = (-(p[0] * e[0] + p[1] * e[1]) / ee).clamp(0.0, 1.0);
    let x = p[0] + e[0] * t;
    let y = p[1] + e[1] * t;
    x * x + y * y <= 1.0
}

/// Step 3 for one splat: pushes `(leaf << 32) | key` for every leaf whose
/// padded cell the splat overlaps, plus the leaf holding its centre.
#[allow(clippy::too_many_arguments)]
fn insert_overlaps(
    node: &BuildNode,
    lo: Vec3,
    size: f32,
    pad: f32,
    key: u32,
    fp: &Footprint,
    out: &mut Vec<u64>,
) {
    let (begin, end) = node.range();
    let holds_centre = begin <= key && key < end;
    let cell_lo = lo - Vec3::splat(pad);
    let cell_hi = lo + Vec3::splat(size + pad);
    let boxes_meet = fp.lo.cmple(cell_hi).all() && fp.hi.cmpge(cell_lo).all();
    if !holds_centre && !boxes_meet {
        return;
    }
    match node {
        BuildNode::Leaf { id, .. } => {
            if holds_centre || !fp.exact || disc_meets_box(&fp.disc, cell_lo, cell_hi) {
                out.push((u64::from(*id) << 32) | u64::from(key));
            }
        }
        BuildNode::Interior { children, .. } => {
            let half = size * 0.5;
            for (oct, c) in children.iter().enumerate() {
                insert_overlaps(c, child_lo(lo, half, oct), half, pad, key, fp, out);
            }
        }
    }
}

/// Step 3 for one splat, started below the root: descends along the cells
/// holding the splat's centre while the child cell contains the whole
/// (padded) footprint with a margin of two more paddings, then runs
/// [`insert_overlaps`] from there. Every cell left out lies outside that
/// child, so its padded box cannot meet the footprint and holds no centre:
/// the references are exactly those of [`insert_overlaps`] from the root.
fn insert_splat(
    root: &BuildNode,
    lo: Vec3,
    size: f32,
    pad: f32,
    key: u32,
    fp: &Footprint,
    out: &mut Vec<u64>,
) {
    let (mut node, mut lo, mut size) = (root, lo, size);
    while let BuildNode::Interior { children, .. } = node {
        let Some(oct) = children.iter().position(|c| {
            let (b, e) = c.range();
            b <= key && key < e
        }) else {
            break;
        };
        let half = size * 0.5;
        let clo = child_lo(lo, half, oct);
        let margin = Vec3::splat(3.0 * pad);
        let inside =
            fp.lo.cmpge(clo + margin).all() && fp.hi.cmple(clo + Vec3::splat(half) - margin).all();
        if !inside {
            break;
        }
        node = &children[oct];
        lo = clo;
        size = half;
    }
    insert_overlaps(node, lo, size, pad, key, fp, out);
}

/// Fills the subtree reference counts; returns this subtree's.
fn count_refs(node: &mut BuildNode, leaf_count: &[u32]) -> u64 {
    match node {
        BuildNode::Leaf { id, .. } => u64::from(leaf_count[*id as usize]),
        BuildNode::Interior { children, refs, .. } => {
            *refs = children.iter_mut().map(|c| count_refs(c, leaf_count)).sum();
            *refs
        }
    }
}

fn subtree_refs(node: &BuildNode, leaf_count: &[u32]) -> u64 {
    match node {
        BuildNode::Leaf { id, .. } => u64::from(leaf_count[*id as usize]),
        BuildNode::Interior { refs, .. } => *refs,
    }
}

/// Writes `node` into `nodes[slot]`, appending its non-empty children
/// contiguously (pbrt's flattening, depth first).
fn emit(
    node: &BuildNode,
    slot: usize,
    nodes: &mut Vec<Node>,
    leaf_start: &[u32],
    leaf_count: &[u32],
    emitted: &mut usize,
) {
    *emitted += 1;
    match node {
        BuildNode::Leaf { id, .. } => {
            nodes[slot] = Node {
                first: leaf_start[*id as usize],
                meta: leaf_count[*id as usize],
            };
        }
        BuildNode::Interior { children, .. } => {
            let mut mask = 0u32;
            for (oct, c) in children.iter().enumerate() {
                if subtree_refs(c, leaf_count) > 0 {
                    mask |= 1 << oct;
                }
            }
            let first = nodes.len();
            nodes.resize(
                first + mask.count_ones() as usize,
                Node {
                    first: 0,
                    meta: UNEMITTED,
                },
            );
            nodes[slot] = Node {
                first: first as u32,
                meta: INTERIOR | mask,
            };
            let mut j = first;
            for (oct, c) in children.iter().enumerate() {
                if mask & (1 << oct) != 0 {
                    emit(c, j, nodes, leaf_start, leaf_count, emitted);
                    j += 1;
                }
            }
        }
    }
}

impl Octree {
    /// Builds the octree of §3.1 over `splats` (splat `i` gets id `i`).
    ///
    /// Panics if there are 2^31 or more references or 2^32 splats.
    #[must_use]
    pub fn new(splats: &[Splat], params: &OctreeParams) -> Octree {
        let start = Instant::now();
        let n = splats.len();
        assert!(u32::try_from(n).is_ok(), "at most 2^32 - 1 splats");
        let discs: Vec<Disc> = splats.par_iter().map(Splat::disc_geometry).collect();
        let extents: Vec<Vec3> = splats
            .par_iter()
            .map(|s| match params.overlap {
                OverlapTest::Exact => s.half_extent(),
                OverlapTest::BoundingSquare => {
                    s.u_axis.abs() * s.radii.x + s.v_axis.abs() * s.radii.y
                }
            })
            .collect();

        // 1. The root cube around every (tested shape of a) splat.
        let (lo, hi) = splats
            .par_iter()
            .zip(&extents)
            .map(|(s, e)| (s.center - *e, s.center + *e))
            .reduce(
                || (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
                |a, b| (a.0.min(b.0), a.1.max(b.1)),
            );
        let (root_lo, root_size) = if n == 0 || !lo.is_finite() || !hi.is_finite() {
            (Vec3::ZERO, 1.0)
        } else {
            let size = (hi - lo).max_element();
            let size = (size * (1.0 + 1e-5)).max(f32::MIN_POSITIVE * 1e10);
            (lo - Vec3::splat(size * 1e-6), size * (1.0 + 2e-6))
        };
        // Padding: a few ulps of the largest coordinate of the root, which
        // bounds the rounding of slab distances and hit positions for rays
        // starting within a few scene sizes (module doc).
        let magnitude = root_lo
            .abs()
            .max(root_lo + Vec3::splat(root_size))
            .max_element();
        let pad = 16.0 * f32::EPSILON * (magnitude.abs() + root_size);

        // 2. Insert by centre: sort Morton codes, split ranges.
        let scale = (1u64 << MORTON_BITS) as f32 / root_size;
        let max_q = ((1u64 << MORTON_BITS) - 1) as f32;
        let mut keyed: Vec<(u64, u32)> = splats
            .par_iter()
            .enumerate()
            .map(|(i, s)| {
                let q = ((s.center - root_lo) * scale).clamp(Vec3::ZERO, Vec3::splat(max_q));
                let code =
                    spread3(q.x as u64) | (spread3(q.y as u64) << 1) | (spread3(q.z as u64) << 2);
                (code, i as u32)
            })
            .collect();
        keyed.par_sort_unstable();
        let codes: Vec<u64> = keyed.iter().map(|k| k.0).collect();
        let order: Vec<u32> = keyed.iter().map(|k| k.1).collect();
        drop(keyed);
        let splitter = Splitter {
            codes: &codes,
            max_leaf: params.max_leaf.max(1),
            max_depth: params.max_depth.min(MORTON_BITS),
        };
        let mut root = if n == 0 {
            BuildNode::Leaf {
                begin: 0,
                end: 0,
                id: 0,
            }
        } else {
            splitter.split(0, n, 0)
        };
        let mut leaves = 0u32;
        number_leaves(&mut root, &mut leaves);

        // 3. Every leaf each splat overlaps. Splats are read in Morton order
        // (one parallel gather first, so the descent reads memory in order),
        // in chunks of consecutive keys; each chunk lists `(leaf << 32) | key`
        // in key order, so the chunks concatenated are sorted by key and a
        // stable counting sort by leaf yields every leaf's keys in order.
        let sorted: Vec<(Disc, Vec3)> = order
            .par_iter()
            .map(|&i| (discs[i as usize], extents[i as usize]))
            .collect();
        drop(discs);
        drop(extents);
        const CHUNK: usize = 2048;
        let chunks: Vec<Vec<u64>> = sorted
            .par_chunks(CHUNK)
            .enumerate()
            .map(|(c, chunk)| {
                let mut out = Vec::with_capacity(chunk.len() * 8);
                for (j, (disc, extent)) in chunk.iter().enumerate() {
                    let key = (c * CHUNK + j) as u32;
                    let e = *extent + Vec3::splat(pad);
                    // The broken test-only tree: an empty footprint meets no
                    // cell, so only the leaf holding the centre gets the splat.
                    let (lo, hi) = if params.skip_overlap_insertion {
                        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY))
                    } else {
                        (disc.center - e, disc.center + e)
                    };
                    let fp = Footprint {
                        lo,
                        hi,
                        disc: *disc,
                        exact: params.overlap == OverlapTest::Exact,
                    };
                    insert_splat(&root, root_lo, root_size, pad, key, &fp, &mut out);
                }
                out
            })
            .collect();
        let references: usize = chunks.iter().map(Vec::len).sum();
        assert!(references < INTERIOR as usize, "too many splat references");

        let mut leaf_count = vec![0u32; leaves as usize];
        for p in chunks.iter().flatten() {
            leaf_count[(p >> 32) as usize] += 1;
        }
        // Packs per leaf, and each leaf's first pack.
        let leaf_packs: Vec<u32> = leaf_count
            .iter()
            .map(|&c| c.div_ceil(LANES as u32))
            .collect();
        let mut leaf_start = vec![0u32; leaves as usize];
        let mut acc = 0u32;
        for (s, c) in leaf_start.iter_mut().zip(&leaf_packs) {
            *s = acc;
            acc += c;
        }
        // Counting sort: each leaf's keys, in key order, padded to whole packs.
        let mut pack_keys = vec![NO_SPLAT; acc as usize * LANES];
        let mut cursor: Vec<u32> = leaf_start.iter().map(|&s| s * LANES as u32).collect();
        for p in chunks.iter().flatten() {
            let c = &mut cursor[(p >> 32) as usize];
            pack_keys[*c as usize] = (p & 0xffff_ffff) as u32;
            *c += 1;
        }
        drop(chunks);
        drop(cursor);
        let packs: Vec<DiscPack> = pack_keys
            .par_chunks(LANES)
            .map(|keys| {
                let mut p = DiscPack::EMPTY;
                for (lane, &k) in keys.iter().enumerate() {
                    if k != NO_SPLAT {
                        p.set(lane, &sorted[k as usize].0);
                    }
                }
                p
            })
            .collect();
        let pack_ids: Vec<u32> = pack_keys
            .par_iter()
            .map(|&k| {
                if k == NO_SPLAT {
                    NO_SPLAT
                } else {
                    order[k as usize]
                }
            })
            .collect();
        drop(pack_keys);

        // Flatten.
        count_refs(&mut root, &leaf_packs);
        let mut nodes = vec![Node { first: 0, meta: 0 }];
        let mut emitted = 0;
        emit(&root, 0, &mut nodes, &leaf_start, &leaf_packs, &mut emitted);
        debug_assert_eq!(emitted, nodes.len(), "every node slot emitted once");
        debug_assert!(
            nodes.iter().all(|nd| nd.meta != UNEMITTED),
            "a node slot was never emitted"
        );
        let leaf_nodes = nodes.iter().filter(|nd| nd.meta & INTERIOR == 0).count();
        let nonempty = nodes
            .iter()
            .filter(|nd| nd.meta & INTERIOR == 0 && nd.meta > 0)
            .count();
        // Build-time structures (the pointer tree, codes) are dropped here.
        drop(root);
        let stats = BuildStats {
            build_seconds: start.elapsed().as_secs_f64(),
            memory_bytes: std::mem::size_of_val(nodes.as_slice())
                + std::mem::size_of_val(packs.as_slice())
                + std::mem::size_of_val(pack_ids.as_slice()),
            nodes: nodes.len(),
            leaves: leaf_nodes,
            mean_refs_per_leaf: if nonempty == 0 {
                0.0
            } else {
                references as f64 / nonempty as f64
            },
        };
        Octree {
            nodes,
            packs,
            pack_ids,
            references,
            root_lo,
            root_size,
            pad,
            stats,
        }
    }

    /// Total splat references (a splat counts once per leaf holding it).
    #[must_use]
    pub fn references(&self) -> usize {
        self.references
    }

    /// Front-to-back traversal from the root; `visitor` sees the leaves.
    /// Returns true when the visitor stopped it.
    #[inline]
    fn traverse<V: Visitor>(&self, ray: &Ray, t_min: f32, visitor: &mut V) -> bool {
        if self.references == 0 {
            return false;
        }
        let ctx = RayCtx {
            origin: ray.origin,
            inv_dir: Vec3::ONE / ray.dir,
            sign_mask: usize::from(ray.dir.x.is_sign_negative())
                | usize::from(ray.dir.y.is_sign_negative()) << 1
                | usize::from(ray.dir.z.is_sign_negative()) << 2,
            t_min,
        };
        let pad = Vec3::splat(self.pad);
        let lo = self.root_lo;
        let a = (lo - pad - ctx.origin) * ctx.inv_dir;
        let b = (lo + Vec3::splat(self.root_size) + pad - ctx.origin) * ctx.inv_dir;
        let (near, far) = slab(a, b);
        let entry = max4(t_min, near);
        let exit = min4(visitor.cutoff(), far);
        // NaN compares false: a NaN entry or exit misses the root.
        entry <= exit && self.visit(0, lo, self.root_size, &ctx, visitor)
    }

    fn visit<V: Visitor>(
        &self,
        index: usize,
        lo: Vec3,
        size: f32,
        ctx: &RayCtx,
        visitor: &mut V,
    ) -> bool {
        let node = self.nodes[index];
        if node.meta & INTERIOR == 0 {
            let range = node.first as usize..(node.first + node.meta) as usize;
            return visitor.leaf(
                &self.packs[range.clone()],
                &self.pack_ids[range.start * LANES..range.end * LANES],
            );
        }
        let mask = node.meta & 0xff;
        let half = size * 0.5;
        let pad = Vec3::splat(self.pad);
        let mid = lo + Vec3::splat(half);
        let hi = lo + Vec3::splat(size);
        let o = ctx.origin;
        let inv = ctx.inv_dir;
        // Slab parameters of the padded lower and upper halves on each axis.
        let (lower_near, lower_far) = slab((lo - pad - o) * inv, (mid + pad - o) * inv);
        let (upper_near, upper_far) = slab((mid - pad - o) * inv, (hi + pad - o) * inv);
        // Entry and exit of all eight children at once, branch free; only
        // the children whose interval is non-empty are visited.
        let cut = visitor.cutoff();
        let near = [lower_near.to_array(), upper_near.to_array()];
        let far = [lower_far.to_array(), upper_far.to_array()];
        let corner = |oct: usize, v: &[[f32; 3]; 2]| {
            Vec3::new(v[oct & 1][0], v[(oct >> 1) & 1][1], v[oct >> 2][2])
        };
        let entry: [f32; 8] = std::array::from_fn(|oct| max4(ctx.t_min, corner(oct, &near)));
        let exit: [f32; 8] = std::array::from_fn(|oct| min4(cut, corner(oct, &far)));
        let mut open = 0u32;
        for oct in 0..8 {
            open |= u32::from(entry[oct] <= exit[oct]) << oct;
        }
        let open = open & mask;
        if open == 0 {
            return false;
        }
        for i in 0..8 {
            let oct = i ^ ctx.sign_mask;
            // The window may have shrunk since `exit` was computed.
            if open & (1 << oct) == 0 || entry[oct] > visitor.cutoff() {
                continue;
            }
            let child = node.first as usize + (mask & ((1 << oct) - 1)).count_ones() as usize;
            if self.visit(child, child_lo(lo, half, oct), half, ctx, visitor) {
                return true;
            }
        }
        false
    }
}

/// Discs per [`DiscPack`].
const LANES: usize = 4;

/// Splat id of a padding lane.
const NO_SPLAT: u32 = u32::MAX;

/// [`LANES`] discs of one leaf stored component by component (SoA), so that
/// [`DiscPack::may_hit`] tests them together in a loop LLVM vectorises.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct DiscPack {
    center: [[f32; LANES]; 3],
    normal: [[f32; LANES]; 3],
    u_scaled: [[f32; LANES]; 3],
    v_scaled: [[f32; LANES]; 3],
}

/// A ray's origin and direction broadcast for [`DiscPack::may_hit`].
struct RayLanes {
    origin: [f32; 3],
    dir: [f32; 3],
}

impl RayLanes {
    fn new(ray: &Ray) -> RayLanes {
        RayLanes {
            origin: ray.origin.to_array(),
            dir: ray.dir.to_array(),
        }
    }
}

impl DiscPack {
    /// All lanes padding: a zero normal, so no ray can hit them (`n·d` is
    /// 0 or NaN, hence `t` is never finite).
    const EMPTY: DiscPack = DiscPack {
        center: [[0.0; LANES]; 3],
        normal: [[0.0; LANES]; 3],
        u_scaled: [[0.0; LANES]; 3],
        v_scaled: [[0.0; LANES]; 3],
    };

    fn set(&mut self, lane: usize, d: &Disc) {
        for k in 0..3 {
            self.center[k][lane] = d.center[k];
            self.normal[k][lane] = d.normal[k];
            self.u_scaled[k][lane] = d.u_scaled[k];
            self.v_scaled[k][lane] = d.v_scaled[k];
        }
    }

    /// The disc of `lane`, bit for bit as stored.
    #[inline]
    fn disc(&self, lane: usize) -> Disc {
        let get = |a: &[[f32; LANES]; 3]| Vec3::new(a[0][lane], a[1][lane], a[2][lane]);
        Disc {
            center: get(&self.center),
            normal: get(&self.normal),
            u_scaled: get(&self.u_scaled),
            v_scaled: get(&self.v_scaled),
        }
    }

    /// Bit `l` set when lane `l` may be hit in `[t_min, t_max]`: the
    /// operations of [`intersect_disc`] in the same order per lane (glam's
    /// `dot` is `x*x' + y*y' + z*z'`, left to right; no fused operations), so
    /// the mask equals "`intersect_disc` hits" except that the rim test is
    /// relaxed by `1e-4` — a conservative filter in any case, since each
    /// set lane is then decided by `intersect_disc` itself.
    #[inline(always)]
    fn may_hit(&self, ray: &RayLanes, t_min: f32, t_max: f32) -> u32 {
        let [ox, oy, oz] = ray.origin;
        let [dx, dy, dz] = ray.dir;
        let [nx, ny, nz] = &self.normal;
        let [cx, cy, cz] = &self.center;
        let [ux, uy, uz] = &self.u_scaled;
        let [vx, vy, vz] = &self.v_scaled;
        // One element-wise operation per line, so each is one vector op.
        let denom = lanes(|l| (nx[l] * dx) + (ny[l] * dy) + (nz[l] * dz));
        let ocx = lanes(|l| ox - cx[l]);
        let ocy = lanes(|l| oy - cy[l]);
        let ocz = lanes(|l| oz - cz[l]);
        let num = lanes(|l| (nx[l] * ocx[l]) + (ny[l] * ocy[l]) + (nz[l] * ocz[l]));
        let t = lanes(|l| -num[l] / denom[l]);
        // Once the window is narrow most planes are crossed outside it.
        let mut in_range = 0;
        for (l, t) in t.iter().enumerate() {
            in_range |= u32::from((*t >= t_min) & (*t <= t_max) & (t.abs() < f32::INFINITY)) << l;
        }
        if in_range == 0 {
            return 0;
        }
        let px = lanes(|l| ocx[l] + dx * t[l]);
        let py = lanes(|l| ocy[l] + dy * t[l]);
        let pz = lanes(|l| ocz[l] + dz * t[l]);
        let u = lanes(|l| (px[l] * ux[l]) + (py[l] * uy[l]) + (pz[l] * uz[l]));
        let v = lanes(|l| (px[l] * vx[l]) + (py[l] * vy[l]) + (pz[l] * vz[l]));
        let r2 = lanes(|l| u[l] * u[l] + v[l] * v[l]);
        let mut mask = 0;
        for (l, r2) in r2.iter().enumerate() {
            mask |= u32::from(*r2 <= 1.0001) << l;
        }
        mask & in_range
    }
}

/// `[f(0), .., f(LANES - 1)]`.
#[inline(always)]
fn lanes(f: impl Fn(usize) -> f32) -> [f32; LANES] {
    std::array::from_fn(f)
}

/// Per-ray constants of the traversal.
struct RayCtx {
    origin: Vec3,
    /// `1 / dir`, `±inf` on zero components.
    inv_dir: Vec3,
    /// Bit `k` set when `dir[k]` is negative (sign bit, so `-0.0` counts).
    sign_mask: usize,
    t_min: f32,
}

/// Per-axis (near, far) of a slab from the parameters of its two planes.
/// `a < b` is false for NaN, which then yields NaN or the other value; the
/// callers' comparisons treat that as a miss of the cell (module doc).
#[inline]
fn slab(a: Vec3, b: Vec3) -> (Vec3, Vec3) {
    let near = Vec3::new(
        if a.x < b.x { a.x } else { b.x },
        if a.y < b.y { a.y } else { b.y },
        if a.z < b.z { a.z } else { b.z },
    );
    let far = Vec3::new(
        if a.x > b.x { a.x } else { b.x },
        if a.y > b.y { a.y } else { b.y },
        if a.z > b.z { a.z } else { b.z },
    );
    (near, far)
}

#[inline]
fn max4(t: f32, v: Vec3) -> f32 {
    let m = if v.x > v.y { v.x } else { v.y };
    let m = if m > v.z { m } else { v.z };
    if m > t { m } else { t }
}

#[inline]
fn min4(t: f32, v: Vec3) -> f32 {
    let m = if v.x < v.y { v.x } else { v.y };
    let m = if m < v.z { m } else { v.z };
    if m < t { m } else { t }
}

/// What a traversal does in the leaves.
trait Visitor {
    /// Cells entered beyond this are skipped.
    fn cutoff(&self) -> f32;
    /// Tests a leaf's disc packs (with their lanes' splat ids); true stops
    /// the traversal.
    fn leaf(&mut self, packs: &[DiscPack], ids: &[u32]) -> bool;
}

/// `intersect`: gathers the candidate window.
struct Gather<'a> {
    ray: &'a Ray,
    lanes: RayLanes,
    t_min: f32,
    t_max: f32,
    hits: &'a mut CandidateHits,
}

impl Visitor for Gather<'_> {
    #[inline]
    fn cutoff(&self) -> f32 {
        self.t_max.min(self.hits.far())
    }

    #[inline]
    fn leaf(&mut self, packs: &[DiscPack], ids: &[u32]) -> bool {
        let mut cut = self.cutoff();
        for (pack, ids) in packs.iter().zip(ids.chunks_exact(LANES)) {
            let mut mask = pack.may_hit(&self.lanes, self.t_min, cut);
            while mask != 0 {
                let lane = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                // The shared routine decides, with the window's current end.
                if let Some((t, u, v)) = intersect_disc(&pack.disc(lane), self.ray, self.t_min, cut)
                {
                    let id = ids[lane];
                    cut = self.hits.offer(Candidate { id, t, u, v }).min(self.t_max);
                }
            }
        }
        false
    }
}

/// `occluded`: stops at the first hit.
struct AnyHit<'a> {
    ray: &'a Ray,
    lanes: RayLanes,
    t_min: f32,
    t_max: f32,
}

impl Visitor for AnyHit<'_> {
    #[inline]
    fn cutoff(&self) -> f32 {
        self.t_max
    }

    #[inline]
    fn leaf(&mut self, packs: &[DiscPack], _ids: &[u32]) -> bool {
        packs.iter().any(|pack| {
            let mut mask = pack.may_hit(&self.lanes, self.t_min, self.t_max);
            while mask != 0 {
                let lane = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                if intersect_disc(&pack.disc(lane), self.ray, self.t_min, self.t_max).is_some() {
                    return true;
                }
            }
            false
        })
    }
}

impl Backend for Octree {
    fn name(&self) -> &'static str {
        "octree"
    }

    fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32, hits: &mut CandidateHits) {
        hits.clear();
        let mut g = Gather {
            ray,
            lanes: RayLanes::new(ray),
            t_min,
            t_max,
            hits,
        };
        self.traverse(ray, t_min, &mut g);
    }

    fn occluded(&self, ray: &Ray, t_min: f32, t_max: f32) -> bool {
        let mut a = AnyHit {
            ray,
            lanes: RayLanes::new(ray),
            t_min,
            t_max,
        };
        self.traverse(ray, t_min, &mut a)
    }

    fn stats(&self) -> &BuildStats {
        &self.stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn disc(c: Vec3, n: Vec3, r: f32) -> Disc {
        Splat::disc(c, n, r).unwrap().disc_geometry()
    }

    #[test]
    fn pack_filter_passes_every_hit_of_intersect_disc() {
        // Rays aimed near the rims (so hits and misses are close calls),
        // some grazing, some with a finite window: every lane that
        // `intersect_disc` hits must be in the mask.
        let mut state = 0x0bad_cafe_1234_5678u64;
        let mut rnd = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 40) as f32) / (1u64 << 24) as f32 - 0.5
        };
        let mut hits = 0;
        for _ in 0..20_000 {
            let mut pack = DiscPack::EMPTY;
            let mut discs = [None; LANES];
            for (lane, slot) in discs.iter_mut().enumerate().take(LANES - 1) {
                let n = Vec3::new(rnd(), rnd(), rnd());
                let c = Vec3::new(rnd(), rnd(), rnd());
                let Some(s) = Splat::disc(c, n, 0.2 + rnd().abs()) else {
                    continue;
                };
                let d = s.disc_geometry();
                pack.set(lane, &d);
                *slot = Some(d);
            }
            let origin = Vec3::new(rnd(), rnd(), rnd()) * 8.0;
            let target =
                discs[0].map_or(Vec3::ZERO, |d| d.center) + Vec3::new(rnd(), rnd(), rnd()) * 0.9;
            let ray = Ray::new(origin, target - origin);
            let t_max = if rnd() > 0.3 {
                f32::INFINITY
            } else {
                4.0 + rnd()
            };
            let mask = pack.may_hit(&RayLanes::new(&ray), 0.0, t_max);
            for (lane, d) in discs.iter().enumerate() {
                let hit = d.is_some_and(|d| intersect_disc(&d, &ray, 0.0, t_max).is_some());
                hits += usize::from(hit);
                assert!(!hit || mask & (1 << lane) != 0, "lane {lane} filtered out");
                if d.is_none() {
                    assert_eq!(mask & (1 << lane), 0, "padding lane passed");
                }
            }
        }
        assert!(hits > 1000, "the rays should often hit: {hits}");
    }

    #[test]
    fn morton_spread_interleaves() {
        assert_eq!(spread3(0b101), 0b001_000_001);
        assert_eq!(spread3(0x1f_ffff).count_ones(), 21);
        let code = spread3(1) | (spread3(0) << 1) | (spread3(1) << 2);
        assert_eq!(octant_at(code << (3 * 20), 0), 0b101);
    }

    #[test]
    fn exact_overlap_known_cases() {
        let d = disc(Vec3::ZERO, Vec3::Z, 1.0);
        // The box corner region near (0.8, 0.8): the disc rim passes at
        // 1/sqrt(2) ≈ 0.707 on the diagonal, so a box from 0.72 misses.
        assert!(!disc_meets_box(
            &d,
            Vec3::new(0.72, 0.72, -1.0),
            Vec3::new(2.0, 2.0, 1.0)
        ));
        assert!(disc_meets_box(
            &d,
            Vec3::new(0.70, 0.70, -1.0),
            Vec3::new(2.0, 2.0, 1.0)
        ));
        // Off the plane: misses however close in x, y.
        assert!(!disc_meets_box(
            &d,
            Vec3::new(-1.0, -1.0, 0.01),
            Vec3::new(1.0, 1.0, 1.0)
        ));
        // Touching the plane with a face: meets.
        assert!(disc_meets_box(
            &d,
            Vec3::new(-0.1, -0.1, 0.0),
            Vec3::new(0.1, 0.1, 1.0)
        ));
        // Box strictly inside the disc's slab but beside it along x.
        assert!(!disc_meets_box(
            &d,
            Vec3::new(1.01, -0.1, -0.1),
            Vec3::new(2.0, 0.1, 0.1)
        ));
        assert!(disc_meets_box(
            &d,
            Vec3::new(0.99, -0.1, -0.1),
            Vec3::new(2.0, 0.1, 0.1)
        ));
    }

    #[test]
    fn exact_overlap_agrees_with_dense_sampling() {
        // Any sampled disc point inside the box forces `true`; a `true`
        // without a sampled point must be a near miss of the sampling.
        let mut state = 0x1234_5678_9abc_def0u64;
        let mut rnd = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 40) as f32) / (1u64 << 24) as f32
        };
        for case in 0..400 {
            let n = Vec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5);
            let s = Splat {
                radii: glam::Vec2::new(0.3 + rnd() * 0.5, 0.1 + rnd() * 0.3),
                ..Splat::disc(Vec3::ZERO, n, 1.0).unwrap()
            };
            let d = s.disc_geometry();
            let lo = Vec3::new(rnd() - 0.9, rnd() - 0.9, rnd() - 0.9);
            let hi = lo + Vec3::new(rnd(), rnd(), rnd()) * 0.6 + Vec3::splat(0.01);
            let exact = disc_meets_box(&d, lo, hi);
            let mut sampled = false;
            let mut near = false;
            for i in 0..64 {
                for j in 0..64 {
                    let a = i as f32 / 63.0 * 2.0 - 1.0;
                    let b = j as f32 / 63.0 * 2.0 - 1.0;
                    if a * a + b * b > 1.0 {
                        continue;
                    }
                    let p = s.center + s.u_axis * (a * s.radii.x) + s.v_axis * (b * s.radii.y);
                    let e = Vec3::splat(0.02);
                    sampled |= p.cmpge(lo).all() && p.cmple(hi).all();
                    near |= p.cmpge(lo - e).all() && p.cmple(hi + e).all();
                }
            }
            assert!(
                !sampled || exact,
                "case {case}: a disc point lies in the box but the exact test says no: {s:?} {lo} {hi}"
            );
            assert!(
                !exact || near,
                "case {case}: exact test says yes but no disc point is near the box: {s:?} {lo} {hi}"
            );
        }
    }
}
