//! Construction of the [`Octree`] (§3.1): root cube, split by centres in
//! Morton order, insertion of every primitive into the leaves it overlaps,
//! leaf packs, flattening.

use super::{
    BOX_GROUP, ENTRY_MASK_SHIFT, ENTRY_PACK, INTERIOR, Layout, LeafBox, NO_PRIMITIVE, Node,
    Octree, OctreeParams, OverlapTest, PackBoxes, Tree, child_lo, lanes,
};
use crate::accel::BuildStats;
use crate::primitive::{Pack, Primitive};
use glam::Vec3;
use rayon::prelude::*;
use std::time::Instant;

/// Bits of a Morton code per axis: the deepest level the build can reach.
const MORTON_BITS: u32 = 21;

/// A [`Node::meta`] value no real node has: marks a slot not yet emitted.
const UNEMITTED: u32 = u32::MAX;

/// Step 3 of §3.1, or (for tests only) not.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Insertion {
    /// Every leaf a primitive overlaps gets a reference.
    Overlaps,
    /// Only the leaf holding the centre: the broken tree of
    /// `Octree::without_overlap_insertion`.
    #[cfg_attr(not(feature = "test-backends"), allow(dead_code))]
    CentreOnly,
}

/// Builds the octree: the scene's parts ([`super::parts`]), then per part
/// the steps below, in order (the layout chosen once for every part).
pub(super) fn build<P: Primitive>(
    prims: &[P],
    params: &OctreeParams,
    insertion: Insertion,
) -> Octree<P> {
    let start = Instant::now();
    let n = prims.len();
    assert!(u32::try_from(n).is_ok(), "at most 2^32 - 1 primitives");
    let extents: Vec<Vec3> = prims
        .par_iter()
        .map(|p| match params.overlap {
            OverlapTest::Exact => p.half_extent(),
            OverlapTest::BoundingSquare => p.coarse_half_extent(),
        })
        .collect();
    let groups = super::parts::partition(prims, &extents);
    let staged: Vec<Staged<P>> = if groups.len() <= 1 {
        vec![stage(prims, &extents, None, params, insertion)]
    } else {
        groups
            .into_iter()
            .map(|ids| {
                let sub: Vec<P> = ids.par_iter().map(|&i| prims[i as usize]).collect();
                let ext: Vec<Vec3> = ids.par_iter().map(|&i| extents[i as usize]).collect();
                stage(&sub, &ext, Some(&ids), params, insertion)
            })
            .collect()
    };
    drop(extents);
    let shared = match params.layout {
        Layout::Copies => false,
        Layout::Shared => true,
        Layout::Auto { max_copies_bytes } => {
            let packs: usize = staged
                .iter()
                .flat_map(|s| s.leaf_packs.iter())
                .map(|&c| c as usize)
                .sum();
            let bytes = packs
                * (std::mem::size_of::<P::Pack>() + lanes::<P>() * std::mem::size_of::<u32>());
            bytes > max_copies_bytes
        }
    };
    let isa = match params.simd {
        Some(isa) if isa.supported() => isa,
        _ => crate::config::current().simd,
    };
    let side = std::sync::Arc::new(<P::Pack as Pack<P>>::side(prims));
    let side_bytes = <P::Pack as Pack<P>>::side_bytes(&side);
    let mut nonempty = 0;
    let parts: Vec<Tree<P>> = staged
        .into_iter()
        .map(|s| {
            let (tree, leaves) = finish(s, shared, isa, &side);
            nonempty += leaves;
            tree
        })
        .collect();
    let references: usize = parts.iter().map(|t| t.references).sum();
    assert!(references < INTERIOR as usize, "too many references");
    let stats = BuildStats {
        build_seconds: start.elapsed().as_secs_f64(),
        memory_bytes: parts.iter().map(Tree::bytes).sum::<usize>() + side_bytes,
        nodes: parts.iter().map(|t| t.nodes.len()).sum(),
        leaves: parts
            .iter()
            .map(|t| t.nodes.iter().filter(|nd| nd.meta & INTERIOR == 0).count())
            .sum(),
        mean_refs_per_leaf: if nonempty == 0 {
            0.0
        } else {
            references as f64 / nonempty as f64
        },
    };
    Octree {
        parts,
        references,
        shared,
        isa,
        count: n,
        stats,
        held: std::sync::OnceLock::new(),
    }
}

/// One part taken through steps 1-3 (and the references counted per
/// leaf), waiting for the layout.
struct Staged<P> {
    cube: RootCube,
    root: BuildNode,
    /// Global primitive id of each key.
    order: Vec<u32>,
    leaves: u32,
    sorted: Vec<(P, Vec3)>,
    chunks: Vec<Vec<u64>>,
    leaf_refs: Vec<u32>,
    leaf_packs: Vec<u32>,
}

/// Steps 1-3 for the primitives `prims` (half extents `extents`), whose
/// global ids are `ids` (`None`: their indices).
fn stage<P: Primitive>(
    prims: &[P],
    extents: &[Vec3],
    ids: Option<&[u32]>,
    params: &OctreeParams,
    insertion: Insertion,
) -> Staged<P> {
    let cube = RootCube::around(prims, extents);
    let (root, order, leaves) = split_by_centres(prims, &cube, params);
    // The primitives and their extents in Morton order (one parallel
    // gather, so every later step reads memory in order).
    let sorted: Vec<(P, Vec3)> = order
        .par_iter()
        .map(|&i| (prims[i as usize], extents[i as usize]))
        .collect();
    let order = match ids {
        None => order,
        Some(ids) => order.par_iter().map(|&i| ids[i as usize]).collect(),
    };
    let chunks = insert_references(&sorted, &root, &cube, params, insertion);
    let leaf_refs = count_per_leaf(&chunks, leaves);
    let leaf_packs: Vec<u32> = leaf_refs
        .iter()
        .map(|&c| c.div_ceil(lanes::<P>() as u32))
        .collect();
    Staged {
        cube,
        root,
        order,
        leaves,
        sorted,
        chunks,
        leaf_refs,
        leaf_packs,
    }
}

/// Steps 4-5 of a staged part in the layout chosen: the tree, and its
/// count of non-empty leaves.
fn finish<P: Primitive>(
    s: Staged<P>,
    shared: bool,
    isa: crate::simd::Isa,
    side: &std::sync::Arc<<P::Pack as Pack<P>>::Side>,
) -> (Tree<P>, usize) {
    let cube = &s.cube;
    let references: usize = s.leaf_refs.iter().map(|&c| c as usize).sum();
    assert!(references < INTERIOR as usize, "too many references");
    let mut leaf_boxes = content_boxes(&s.sorted, &s.chunks, s.leaves, cube.pad);
    clip_to_cells(&s.root, cube.lo, cube.size, cube.pad, &mut leaf_boxes);
    let (packs, pack_ids, entries, leaf_entries, pack_boxes) = if shared {
        let (perm, lowest) = leaf_set_order(&s.chunks, s.sorted.len());
        let (stored, positions) = copy_small_groups::<P>(&s.chunks, &s.leaf_refs, &perm, &lowest);
        let (packs, pack_ids) = shared_packs(&s.sorted, &s.order, &stored);
        let (entries, leaf_entries) = leaf_entries::<P>(&positions, &s.leaf_refs);
        (packs, pack_ids, entries, leaf_entries, Vec::new())
    } else {
        let pack_keys = copies_keys::<P>(&s.chunks, &s.leaf_packs);
        let (packs, pack_ids) = fill_packs(&s.sorted, &s.order, &pack_keys);
        let pack_boxes = pack_boxes(&s.sorted, &pack_keys, &s.leaf_packs, &leaf_boxes, cube.pad);
        // A leaf's packs are contiguous: no entries.
        (packs, pack_ids, Vec::new(), s.leaf_packs, pack_boxes)
    };
    drop(s.sorted);
    drop(s.chunks);
    let leaf_start = prefix_sums(&leaf_entries);
    let (nodes, boxes) = flatten(s.root, &leaf_start, &leaf_entries, &leaf_boxes);
    let nonempty = nodes
        .iter()
        .filter(|nd| nd.meta & INTERIOR == 0 && nd.meta > 0)
        .count();
    let grid = super::Grid::build(&nodes, cube.lo, cube.size);
    let tree = Tree {
        grid,
        nodes,
        boxes,
        packs,
        pack_ids,
        pack_boxes,
        side: std::sync::Arc::clone(side),
        entries,
        shared,
        isa,
        references,
        root_lo: cube.lo,
        root_size: cube.size,
        bounds: [
            cube.content_lo - Vec3::splat(cube.pad),
            cube.content_hi + Vec3::splat(cube.pad),
        ],
        pad: cube.pad,
    };
    (tree, nonempty)
}

impl<P: Primitive> Tree<P> {
    /// Bytes held (the primitives' copies in the packs included; the side
    /// table, shared by the parts, is counted once by the octree).
    fn bytes(&self) -> usize {
        std::mem::size_of_val(self.nodes.as_slice())
            + std::mem::size_of_val(self.packs.as_slice())
            + std::mem::size_of_val(self.pack_ids.as_slice())
            + std::mem::size_of_val(self.entries.as_slice())
            + std::mem::size_of_val(self.boxes.as_slice())
            + std::mem::size_of_val(self.pack_boxes.as_slice())
            + self
                .grid
                .as_ref()
                .map_or(0, |g| std::mem::size_of_val(g.cells.as_slice()))
    }
}

/// Step 1: the root cell.
struct RootCube {
    /// Lower corner.
    lo: Vec3,
    /// Edge length.
    size: f32,
    /// Padding added to every cell, in world units.
    pad: f32,
    /// The box around every primitive's box (the cube when there is
    /// nothing finite to bound).
    content_lo: Vec3,
    content_hi: Vec3,
}

impl RootCube {
    /// The cube around every primitive's box (half extents `extents`),
    /// slightly enlarged; the unit cube at the origin when there is nothing
    /// finite to bound.
    fn around<P: Primitive>(prims: &[P], extents: &[Vec3]) -> RootCube {
        let (lo, hi) = prims
            .par_iter()
            .zip(extents)
            .map(|(p, e)| (p.center() - *e, p.center() + *e))
            .reduce(
                || (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
                |a, b| (a.0.min(b.0), a.1.max(b.1)),
            );
        let nothing = prims.is_empty() || !lo.is_finite() || !hi.is_finite();
        let (content_lo, content_hi) = (lo, hi);
        let (lo, size) = if nothing {
            (Vec3::ZERO, 1.0)
        } else {
            let size = (hi - lo).max_element();
            let size = (size * (1.0 + 1e-5)).max(f32::MIN_POSITIVE * 1e10);
            (lo - Vec3::splat(size * 1e-6), size * (1.0 + 2e-6))
        };
        // Padding: a few ulps of the largest coordinate of the root, which
        // bounds the rounding of slab distances and hit positions for rays
        // starting within a few scene sizes (module doc).
        let magnitude = lo.abs().max(lo + Vec3::splat(size)).max_element();
        let pad = 16.0 * f32::EPSILON * (magnitude.abs() + size);
        let (content_lo, content_hi) = if nothing {
            (lo, lo + Vec3::splat(size))
        } else {
            (content_lo, content_hi)
        };
        RootCube {
            lo,
            size,
            pad,
            content_lo,
            content_hi,
        }
    }
}

/// Step 2: sorts the centres by Morton code and splits the sorted range.
/// Returns the pointer tree, the primitive ids in Morton order (a
/// primitive's position in it is its *key*) and the leaf count.
fn split_by_centres<P: Primitive>(
    prims: &[P],
    cube: &RootCube,
    params: &OctreeParams,
) -> (BuildNode, Vec<u32>, u32) {
    let n = prims.len();
    let scale = (1u64 << MORTON_BITS) as f32 / cube.size;
    let max_q = ((1u64 << MORTON_BITS) - 1) as f32;
    let mut keyed: Vec<(u64, u32)> = prims
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let q = ((p.center() - cube.lo) * scale).clamp(Vec3::ZERO, Vec3::splat(max_q));
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
        deep_leaf: params.deep_leaf.max(1),
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
    (root, order, leaves)
}

/// Step 3: every leaf each primitive overlaps. Primitives are read in Morton
/// order (`sorted`: each with its half extent), in chunks of consecutive
/// keys; each chunk lists `(leaf << 32) | key` in key order, so the chunks
/// concatenated are sorted by key and a stable counting sort by leaf yields
/// every leaf's keys in order.
fn insert_references<P: Primitive>(
    sorted: &[(P, Vec3)],
    root: &BuildNode,
    cube: &RootCube,
    params: &OctreeParams,
    insertion: Insertion,
) -> Vec<Vec<u64>> {
    const CHUNK: usize = 2048;
    sorted
        .par_chunks(CHUNK)
        .enumerate()
        .map(|(c, chunk)| {
            let mut out = Vec::with_capacity(chunk.len() * 8);
            for (j, (prim, extent)) in chunk.iter().enumerate() {
                let key = (c * CHUNK + j) as u32;
                let e = *extent + Vec3::splat(cube.pad);
                // The broken test-only tree: an empty footprint meets no
                // cell, so only the leaf holding the centre gets it.
                let (lo, hi) = match insertion {
                    Insertion::CentreOnly => {
                        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY))
                    }
                    Insertion::Overlaps => (prim.center() - e, prim.center() + e),
                };
                let fp = Footprint {
                    lo,
                    hi,
                    prim: *prim,
                    exact: params.overlap == OverlapTest::Exact,
                };
                insert_one(root, cube, key, &fp, &mut out);
            }
            out
        })
        .collect()
}

/// References per leaf.
fn count_per_leaf(chunks: &[Vec<u64>], leaves: u32) -> Vec<u32> {
    let mut count = vec![0u32; leaves as usize];
    for p in chunks.iter().flatten() {
        count[(p >> 32) as usize] += 1;
    }
    count
}

/// Exclusive prefix sums: each leaf's first pack, entry or reference.
fn prefix_sums(counts: &[u32]) -> Vec<u32> {
    let mut acc = 0u32;
    counts
        .iter()
        .map(|&c| {
            let s = acc;
            acc += c;
            s
        })
        .collect()
}

/// The counting sort of step 4: every reference's key placed at its leaf's
/// cursor (leaf `l`'s keys from `slots[l] * stride`, in key order, since
/// the chunks are), in an array of `len` slots ([`NO_PRIMITIVE`] where no
/// key goes: padding).
fn keys_by_leaf(chunks: &[Vec<u64>], slots: &[u32], stride: u32, len: usize) -> Vec<u32> {
    let mut keys = vec![NO_PRIMITIVE; len];
    let mut cursor: Vec<u32> = slots.iter().map(|&s| s * stride).collect();
    for p in chunks.iter().flatten() {
        let c = &mut cursor[(p >> 32) as usize];
        keys[*c as usize] = (p & 0xffff_ffff) as u32;
        *c += 1;
    }
    keys
}

/// Step 4, [`Layout::Copies`]: the references' keys sorted by leaf, each
/// leaf's padded to whole packs ([`NO_PRIMITIVE`] on padding).
fn copies_keys<P: Primitive>(chunks: &[Vec<u64>], leaf_packs: &[u32]) -> Vec<u32> {
    let lanes = lanes::<P>();
    let total = leaf_packs.iter().map(|&c| c as usize).sum::<usize>();
    keys_by_leaf(
        chunks,
        &prefix_sums(leaf_packs),
        lanes as u32,
        total * lanes,
    )
}

/// Step 4, [`Layout::Copies`], continued: the packs of the keys
/// `pack_keys` ([`copies_keys`]) and their lanes' ids.
fn fill_packs<P: Primitive>(
    sorted: &[(P, Vec3)],
    order: &[u32],
    pack_keys: &[u32],
) -> (Vec<P::Pack>, Vec<u32>) {
    let lanes = lanes::<P>();
    let packs: Vec<P::Pack> = pack_keys
        .par_chunks(lanes)
        .map(|keys| {
            <P::Pack as Pack<P>>::from_fn(|lane| {
                let k = *keys.get(lane)?;
                (k != NO_PRIMITIVE).then(|| sorted[k as usize].0)
            })
        })
        .collect();
    let pack_ids: Vec<u32> = pack_keys
        .par_iter()
        .map(|&k| {
            if k == NO_PRIMITIVE {
                NO_PRIMITIVE
            } else {
                order[k as usize]
            }
        })
        .collect();
    (packs, pack_ids)
}

/// Step 4, [`Layout::Copies`], last: each pack's box
/// ([`super::Tree::pack_boxes`]), the box around its lanes' padded
/// footprints (those of [`content_boxes`]) clipped to its leaf's content
/// box, [`BOX_GROUP`] packs to a group (the last group's spare lanes empty
/// boxes). A hit of a lane inside the leaf's box lies in the lane's
/// footprint, hence in the pack's box (with a padding's margin, as for the
/// leaves); a hit outside the leaf's box lies in another leaf holding the
/// primitive, which the ray visits as it would without the boxes.
fn pack_boxes<P: Primitive>(
    sorted: &[(P, Vec3)],
    pack_keys: &[u32],
    leaf_packs: &[u32],
    leaf_boxes: &[LeafBox],
    pad: f32,
) -> Vec<PackBoxes> {
    let leaf_of: Vec<u32> = leaf_packs
        .iter()
        .enumerate()
        .flat_map(|(l, &c)| std::iter::repeat_n(l as u32, c as usize))
        .collect();
    let boxes: Vec<LeafBox> = pack_keys
        .par_chunks(lanes::<P>())
        .zip(leaf_of.par_iter())
        .map(|(keys, &l)| {
            let mut b = EMPTY_BOX;
            for &k in keys.iter().filter(|&&k| k != NO_PRIMITIVE) {
                let (p, e) = &sorted[k as usize];
                let (c, e) = (p.center(), *e + Vec3::splat(pad));
                b = [b[0].min(c - e), b[1].max(c + e)];
            }
            let leaf = leaf_boxes[l as usize];
            [b[0].max(leaf[0]), b[1].min(leaf[1])]
        })
        .collect();
    boxes
        .chunks(BOX_GROUP)
        .map(|g| {
            let col = |k: usize, a: usize| {
                glam::Vec4::from_array(std::array::from_fn(|i| {
                    g.get(i).map_or(EMPTY_BOX[k][a], |b| b[k][a])
                }))
            };
            [col(0, 0), col(0, 1), col(0, 2), col(1, 0), col(1, 1), col(1, 2)]
        })
        .collect()
}

/// Step 4, [`Layout::Shared`]: the order the primitives are stored in,
/// as keys: by the leaves referencing them (the first two, in leaf
/// order; ties in key order), so a leaf's primitives referenced by it
/// alone fill packs of their own, and the primitives it shares with one
/// neighbour sit together (in Morton order a pack mixed primitives of
/// several leaves, and a leaf tested about twice the packs of its
/// copies: `docs/notes/backends.md`, issue 55 round 3). Returns the
/// order and each key's lowest leaf (`u32::MAX`: none).
fn leaf_set_order(chunks: &[Vec<u64>], keys: usize) -> (Vec<u32>, Vec<u32>) {
    // Per key, its lowest and second-lowest leaf + 1 (0: none).
    let mut code = vec![(u32::MAX, 0u32); keys];
    for p in chunks.iter().flatten() {
        let (leaf, c) = ((p >> 32) as u32, &mut code[(p & 0xffff_ffff) as usize]);
        if leaf < c.0 {
            c.1 = if c.0 == u32::MAX { 0 } else { c.0 + 1 };
            c.0 = leaf;
        } else if c.1 == 0 || leaf + 1 < c.1 {
            c.1 = leaf + 1;
        }
    }
    let mut perm: Vec<u32> = (0..keys as u32).collect();
    perm.par_sort_unstable_by_key(|&k| (code[k as usize], k));
    (perm, code.iter().map(|c| c.0).collect())
}

/// Step 4, [`Layout::Shared`], continued: the primitives of keys `perm`
/// in that order, `P::Pack::LANES` to a pack (pack `i / LANES`, lane
/// `i % LANES` holds key `perm[i]`; the last pack padded with empty
/// lanes), and each lane's primitive id.
fn shared_packs<P: Primitive>(
    sorted: &[(P, Vec3)],
    order: &[u32],
    perm: &[u32],
) -> (Vec<P::Pack>, Vec<u32>) {
    let lanes = lanes::<P>();
    assert!(
        perm.len().div_ceil(lanes) <= ENTRY_PACK as usize,
        "too many primitives for an entry's pack index"
    );
    let packs: Vec<P::Pack> = perm
        .par_chunks(lanes)
        .map(|chunk| {
            <P::Pack as Pack<P>>::from_fn(|lane| chunk.get(lane).map(|&k| sorted[k as usize].0))
        })
        .collect();
    let mut pack_ids: Vec<u32> = perm.par_iter().map(|&k| order[k as usize]).collect();
    pack_ids.resize(packs.len() * lanes, NO_PRIMITIVE);
    (packs, pack_ids)
}

/// Groups of a leaf's references to another leaf's primitives that fill
/// at most this many lanes of a pack are copied after the leaf's own
/// primitives ([`copy_small_groups`]).
/// (1: at 1M splats of the accel bench's surface 3 % of the references
/// copied, 3-5 % faster; 2 copied 7 % for 0-2 % more.)
const COPY_LANES: usize = 1;

/// Step 4, [`Layout::Shared`], continued: the primitives stored, as keys,
/// and each leaf's references as positions in them (leaf after leaf, each
/// leaf's ascending). The keys `perm` (by [`leaf_set_order`], `lowest` each
/// key's lowest leaf) are stored once, leaf after leaf, except that where
/// a leaf's references to the primitives of a lower leaf fill at most
/// [`COPY_LANES`] lanes of one pack there, those primitives are copied
/// after the leaf's own: a pack read for one lane costs a whole pack's
/// filter, so the leaf then reads fewer packs (1.60 → 1.51 times the
/// copies' packs on the unit test's sheet, 3.2 % of the references
/// copied; at 1M splats of the accel bench's surface 55.1 → 58.2 MB and
/// 3-5 % faster: `docs/notes/backends.md`, issue 55 round 4).
fn copy_small_groups<P: Primitive>(
    chunks: &[Vec<u64>],
    leaf_refs: &[u32],
    perm: &[u32],
    lowest: &[u32],
) -> (Vec<u32>, Vec<u32>) {
    let lanes = lanes::<P>() as u32;
    let start = prefix_sums(leaf_refs);
    let total = leaf_refs.iter().map(|&c| c as usize).sum::<usize>();
    let mut home = vec![0u32; perm.len()];
    for (i, &k) in perm.iter().enumerate() {
        home[k as usize] = i as u32;
    }
    // Each leaf's keys, in the order of `perm`.
    let mut keys = keys_by_leaf(chunks, &start, 1, total);
    let mut copied = vec![false; total];
    for (leaf, (&s, &n)) in start.iter().zip(leaf_refs).enumerate() {
        let refs = &mut keys[s as usize..(s + n) as usize];
        refs.sort_unstable_by_key(|&k| home[k as usize]);
        let copy = &mut copied[s as usize..(s + n) as usize];
        let mut j = 0;
        while j < refs.len() {
            let pack = home[refs[j] as usize] / lanes;
            let end = j + refs[j..]
                .iter()
                .take_while(|&&k| home[k as usize] / lanes == pack)
                .count();
            if end - j <= COPY_LANES
                && refs[j..end].iter().all(|&k| lowest[k as usize] != leaf as u32)
            {
                copy[j..end].fill(true);
            }
            j = end;
        }
    }
    let copies = copied.iter().filter(|&&c| c).count();
    let mut stored = Vec::with_capacity(perm.len() + copies);
    let mut positions = vec![0u32; total];
    let mut next = 0;
    for (leaf, (&s, &n)) in start.iter().zip(leaf_refs).enumerate() {
        while next < perm.len() && lowest[perm[next] as usize] == leaf as u32 {
            home[perm[next] as usize] = stored.len() as u32;
            stored.push(perm[next]);
            next += 1;
        }
        for i in s as usize..(s + n) as usize {
            if copied[i] {
                positions[i] = stored.len() as u32;
                stored.push(keys[i]);
            }
        }
    }
    for &k in &perm[next..] {
        home[k as usize] = stored.len() as u32;
        stored.push(k);
    }
    for (i, p) in positions.iter_mut().enumerate() {
        if !copied[i] {
            *p = home[keys[i] as usize];
        }
    }
    let mut rest = positions.as_mut_slice();
    for &n in leaf_refs {
        let (leaf, tail) = rest.split_at_mut(n as usize);
        leaf.sort_unstable();
        rest = tail;
    }
    (stored, positions)
}

/// Step 4, [`Layout::Shared`], last: each leaf's positions (leaf after
/// leaf, each leaf's ascending, as [`copy_small_groups`] gives them) as
/// entries: the index of a pack of [`shared_packs`] with the mask of its
/// lanes the leaf references ([`ENTRY_PACK`], [`ENTRY_MASK_SHIFT`]).
/// Returns the entries, leaf after leaf, and each leaf's entry count.
fn leaf_entries<P: Primitive>(positions: &[u32], leaf_refs: &[u32]) -> (Vec<u32>, Vec<u32>) {
    let lanes = lanes::<P>() as u32;
    let start = prefix_sums(leaf_refs);
    let mut entries = Vec::with_capacity(positions.len() / 2 + 1);
    let counts = start
        .iter()
        .zip(leaf_refs)
        .map(|(&s, &n)| {
            let before = entries.len();
            let mut current: Option<(u32, u32)> = None;
            for &k in &positions[s as usize..(s + n) as usize] {
                let (pack, lane) = (k / lanes, k % lanes);
                match &mut current {
                    Some((p, mask)) if *p == pack => *mask |= 1 << lane,
                    _ => {
                        if let Some((p, mask)) = current {
                            entries.push(p | mask << ENTRY_MASK_SHIFT);
                        }
                        current = Some((pack, 1 << lane));
                    }
                }
            }
            if let Some((p, mask)) = current {
                entries.push(p | mask << ENTRY_MASK_SHIFT);
            }
            (entries.len() - before) as u32
        })
        .collect();
    (entries, counts)
}

/// Step 5: the pointer tree flattened into [`Node`]s (the build-time tree is
/// dropped here).
fn flatten(
    mut root: BuildNode,
    leaf_start: &[u32],
    leaf_packs: &[u32],
    leaf_boxes: &[LeafBox],
) -> (Vec<Node>, Vec<LeafBox>) {
    count_refs(&mut root, leaf_packs);
    let mut out = Flat {
        nodes: vec![Node { first: 0, meta: 0 }],
        boxes: vec![EMPTY_BOX],
        leaf_start,
        leaf_count: leaf_packs,
        leaf_boxes,
        emitted: 0,
    };
    emit(&root, 0, &mut out);
    debug_assert_eq!(out.emitted, out.nodes.len(), "every node slot emitted once");
    debug_assert!(
        out.nodes.iter().all(|nd| nd.meta != UNEMITTED),
        "a node slot was never emitted"
    );
    (out.nodes, out.boxes)
}

/// What [`emit`] writes and reads.
struct Flat<'a> {
    nodes: Vec<Node>,
    /// Per node: its content box (a leaf's from `leaf_boxes`, an interior
    /// node's the union of its children's).
    boxes: Vec<LeafBox>,
    leaf_start: &'a [u32],
    leaf_count: &'a [u32],
    leaf_boxes: &'a [LeafBox],
    emitted: usize,
}

/// The box of nothing (every ray misses it).
const EMPTY_BOX: LeafBox = [Vec3::INFINITY, Vec3::NEG_INFINITY];

/// Step 4c: per leaf, the box around the padded footprints of the
/// primitives it references (the footprints of step 3).
fn content_boxes<P: Primitive>(
    sorted: &[(P, Vec3)],
    chunks: &[Vec<u64>],
    leaves: u32,
    pad: f32,
) -> Vec<LeafBox> {
    let by_key: Vec<LeafBox> = sorted
        .par_iter()
        .map(|(p, e)| {
            let (c, e) = (p.center(), *e + Vec3::splat(pad));
            [c - e, c + e]
        })
        .collect();
    let mut boxes = vec![EMPTY_BOX; leaves as usize];
    for r in chunks.iter().flatten() {
        let b = &mut boxes[(r >> 32) as usize];
        let k = &by_key[(r & 0xffff_ffff) as usize];
        b[0] = b[0].min(k[0]);
        b[1] = b[1].max(k[1]);
    }
    boxes
}

/// Step 4c, continued: each leaf's content box clipped to its padded cell.
/// A hit a ray finds on a primitive of the leaf inside the leaf's cell lies
/// in both (with a padding's margin, as for the cells themselves); a hit
/// outside the cell lies in another leaf holding the same primitive.
fn clip_to_cells(node: &BuildNode, lo: Vec3, size: f32, pad: f32, boxes: &mut [LeafBox]) {
    match node {
        BuildNode::Leaf { id, .. } => {
            let b = &mut boxes[*id as usize];
            b[0] = b[0].max(lo - Vec3::splat(pad));
            b[1] = b[1].min(lo + Vec3::splat(size + pad));
        }
        BuildNode::Interior { children, .. } => {
            let half = size * 0.5;
            for (oct, c) in children.iter().enumerate() {
                clip_to_cells(c, child_lo(lo, half, oct), half, pad, boxes);
            }
        }
    }
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
    deep_leaf: usize,
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
        let most = if depth >= super::GRID_LEVEL {
            self.deep_leaf
        } else {
            self.max_leaf
        };
        if end - begin <= most
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

/// What step 3 tests a primitive with.
struct Footprint<P> {
    /// Padded bounds of the tested box (tight or coarse).
    lo: Vec3,
    hi: Vec3,
    prim: P,
    exact: bool,
}

/// Step 3 for one primitive: pushes `(leaf << 32) | key` for every leaf whose
/// padded cell the primitive overlaps, plus the leaf holding its centre.
#[allow(clippy::too_many_arguments)]
fn insert_overlaps<P: Primitive>(
    node: &BuildNode,
    lo: Vec3,
    size: f32,
    pad: f32,
    key: u32,
    fp: &Footprint<P>,
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
            if holds_centre || !fp.exact || fp.prim.meets_box(cell_lo, cell_hi) {
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

/// Step 3 for one primitive, started below the root: descends along the cells
/// holding the splat's centre while the child cell contains the whole
/// (padded) footprint with a margin of two more paddings, then runs
/// [`insert_overlaps`] from there. Every cell left out lies outside that
/// child, so its padded box cannot meet the footprint and holds no centre:
/// the references are exactly those of [`insert_overlaps`] from the root.
fn insert_one<P: Primitive>(
    root: &BuildNode,
    cube: &RootCube,
    key: u32,
    fp: &Footprint<P>,
    out: &mut Vec<u64>,
) {
    let pad = cube.pad;
    let (mut node, mut lo, mut size) = (root, cube.lo, cube.size);
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

/// Writes `node` into `nodes[slot]` (and its box into `boxes[slot]`),
/// appending its non-empty children contiguously (pbrt's flattening, depth
/// first).
fn emit(node: &BuildNode, slot: usize, out: &mut Flat) {
    out.emitted += 1;
    match node {
        BuildNode::Leaf { id, .. } => {
            let id = *id as usize;
            out.nodes[slot] = Node {
                first: out.leaf_start[id],
                meta: out.leaf_count[id],
            };
            out.boxes[slot] = out.leaf_boxes[id];
        }
        BuildNode::Interior { children, .. } => {
            let mut mask = 0u32;
            for (oct, c) in children.iter().enumerate() {
                if subtree_refs(c, out.leaf_count) > 0 {
                    mask |= 1 << oct;
                }
            }
            let first = out.nodes.len();
            let stored = first + mask.count_ones() as usize;
            out.nodes.resize(
                stored,
                Node {
                    first: 0,
                    meta: UNEMITTED,
                },
            );
            out.boxes.resize(stored, EMPTY_BOX);
            out.nodes[slot] = Node {
                first: first as u32,
                meta: INTERIOR | mask,
            };
            let mut j = first;
            for (oct, c) in children.iter().enumerate() {
                if mask & (1 << oct) != 0 {
                    emit(c, j, out);
                    j += 1;
                }
            }
            out.boxes[slot] = out.boxes[first..j]
                .iter()
                .fold(EMPTY_BOX, |a, b| [a[0].min(b[0]), a[1].max(b[1])]);
        }
    }
}

impl super::Grid {
    /// The grid over the nodes of level [`super::GRID_LEVEL`]; `None` when
    /// the root is a leaf.
    pub(super) fn build(nodes: &[Node], root_lo: Vec3, root_size: f32) -> Option<super::Grid> {
        if nodes.first().is_none_or(|r| r.meta & INTERIOR == 0) {
            return None;
        }
        let level = super::GRID_LEVEL;
        let n = 1usize << level;
        let cell = (0..level).fold(root_size, |s, _| s * 0.5);
        let mut cells = vec![
            super::GridCell {
                lo: Vec3::ZERO,
                size: 0.0,
                node: super::NO_NODE,
            };
            n * n * n
        ];
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    // Descend along the cell's octants (most significant
                    // bit first) until its level or a leaf.
                    let (mut at, mut l, mut s) = (0usize, root_lo, root_size);
                    let mut found = true;
                    for d in (0..level).rev() {
                        let nd = nodes[at];
                        if nd.meta & INTERIOR == 0 {
                            break;
                        }
                        let oct = ((x >> d) & 1) | ((y >> d) & 1) << 1 | ((z >> d) & 1) << 2;
                        let mask = nd.meta & 0xff;
                        if mask & (1 << oct) == 0 {
                            found = false;
                            break;
                        }
                        at = nd.first as usize + (mask & ((1 << oct) - 1)).count_ones() as usize;
                        s *= 0.5;
                        l = child_lo(l, s, oct);
                    }
                    let i = x + n * (y + n * z);
                    if found {
                        cells[i] = super::GridCell {
                            lo: l,
                            size: s,
                            node: at as u32,
                        };
                    }
                }
            }
        }
        Some(super::Grid { n, cell, cells })
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Layout, Octree, OctreeParams};
    use crate::primitive::Disc;
    use crate::splat::Splat;
    use glam::Vec3;

    /// `n * n` overlapping discs on a wavy sheet, with normals tilted by
    /// the waves.
    fn sheet(n: usize) -> Vec<Disc> {
        let step = 1.0 / n as f32;
        (0..n * n)
            .map(|i| {
                let (x, y) = ((i % n) as f32 * step, (i / n) as f32 * step);
                let z = 0.05 * (9.0 * x).sin() * (7.0 * y).cos();
                let normal = Vec3::new(-0.45 * (9.0 * x).cos(), 0.35 * (7.0 * y).sin(), 1.0);
                let s = Splat::disc(Vec3::new(x, y, z), normal, 1.3 * step).unwrap();
                s.disc_geometry()
            })
            .collect()
    }

    #[test]
    fn shared_packs_hold_every_disc_few_twice_and_leaves_read_few_more_packs_than_their_copies() {
        let discs = sheet(160);
        let build = |layout| {
            Octree::new(
                &discs,
                &OctreeParams {
                    layout,
                    ..OctreeParams::default()
                },
            )
        };
        let (copies, shared) = (build(Layout::Copies), build(Layout::Shared));
        assert_eq!(shared.layout(), Layout::Shared);
        assert_eq!(copies.references(), shared.references());
        let packs = |o: &Octree<Disc>| o.parts.iter().map(|t| t.packs.len()).sum::<usize>();
        let entries: usize = shared.parts.iter().map(|t| t.entries.len()).sum();
        // Every disc stored, a few twice: those a leaf references alone in
        // a pack of a lower leaf's, copied after its own.
        let stored: Vec<u32> = shared.parts.iter().flat_map(|t| t.pack_ids.iter().copied()).filter(|&id| id != super::NO_PRIMITIVE).collect();
        let mut once = stored.clone();
        once.sort_unstable();
        once.dedup();
        assert_eq!(once.len(), discs.len());
        // 1,756 copies here (27,356 lanes for 25,600 discs): 3.2 % of the
        // references.
        let extra = (stored.len() - discs.len()) as f64 / copies.references() as f64;
        assert!(extra < 0.035, "{} lanes stored: {extra}", stored.len());
        assert!(copies.references() as f64 > 1.5 * discs.len() as f64);
        // The pack reads of a ray through every leaf: the shared layout's
        // entries against the copies' packs. Stored in Morton order, the
        // shared packs needed 2.19 times as many here (16,017 entries,
        // 7,323 packs); grouped by the leaves that reference them, 1.60
        // (11,694); with a leaf's lone lanes in a lower leaf's packs
        // copied after its own, 1.51 (11,089).
        let ratio = entries as f64 / packs(&copies) as f64;
        assert!(ratio < 1.55, "{entries} entries, {} packs: {ratio}", packs(&copies));
    }
}

