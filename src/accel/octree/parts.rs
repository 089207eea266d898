//! The top-level split of the scene into parts, each given a tree of its
//! own (its own cube, grid and clip box).
//!
//! One octree over a model standing on a wide floor has a cube as wide as
//! the floor and a clip box as tall as the model: every ray leaving the
//! floor walks the grid's coarse cells up through the empty space beside
//! the model, and the model's own rays descend from cells sized for the
//! floor. A part is split in two when a plane across its centres leaves two
//! groups whose boxes together take a small fraction of its box's volume
//! (the floor a thin slab, the model a box of its own); then a ray tests
//! each part's box and walks only the parts it meets, nearest first. A
//! compact model (the benchmark's surface, a scan) is not split. Groups
//! whose boxes nearly coincide or nest are merged again afterwards (the
//! model's feet, cut off with the floor by the binning, go back to the
//! model).

use crate::primitive::Primitive;
use glam::Vec3;
use rayon::prelude::*;

/// Most parts a scene is split into.
pub(super) const MAX_PARTS: usize = 4;

/// Fewest primitives a part of a split may hold.
const MIN_PART: usize = 1024;

/// Candidate planes per axis: the boundaries of this many bins of the
/// centres' range.
const BINS: usize = 32;

/// At most this many primitives (every `k`-th) are binned to choose a plane.
const SAMPLES: usize = 1 << 16;

/// A split is made when the two groups' boxes take less than this fraction
/// of the part's box volume.
const MAX_VOLUME: f32 = 0.25;

/// The groups of primitive ids the scene is split into: one group (empty
/// list: every primitive) when it is not split.
pub(super) fn partition<P: Primitive>(prims: &[P], extents: &[Vec3]) -> Vec<Vec<u32>> {
    let Some((a, b)) = split(prims, extents, None) else {
        return Vec::new();
    };
    let mut done = Vec::new();
    let mut todo = vec![a, b];
    while let Some(g) = todo.pop() {
        if done.len() + todo.len() + 2 <= MAX_PARTS
            && let Some((a, b)) = split(prims, extents, Some(&g))
        {
            todo.push(a);
            todo.push(b);
        } else {
            done.push(g);
        }
    }
    merge_overlapping(prims, extents, &mut done);
    // Each group's ids in increasing order, groups by their first id: the
    // same parts whatever order they were split in.
    for g in &mut done {
        g.sort_unstable();
    }
    done.sort_unstable_by_key(|g| g[0]);
    done
}

/// Merges two groups while the box around both takes at most
/// [`MAX_MERGED`] times their two boxes' volumes: a piece the binning cut
/// off a model (the bunny's feet, whose centres share the floor's bin) goes
/// back to it, so the floor's box is the floor's alone and the model is
/// one tree.
fn merge_overlapping<P: Primitive>(prims: &[P], extents: &[Vec3], groups: &mut Vec<Vec<u32>>) {
    let mut boxes: Vec<[Vec3; 2]> = groups
        .iter()
        .map(|g| {
            g.par_iter()
                .map(|&i| prim_box(prims, extents, i))
                .reduce(|| EMPTY, union)
        })
        .collect();
    'merged: loop {
        for a in 0..groups.len() {
            for b in a + 1..groups.len() {
                let both = volume(union(boxes[a], boxes[b]));
                if both <= MAX_MERGED * (volume(boxes[a]) + volume(boxes[b])) {
                    let g = groups.remove(b);
                    groups[a].extend(g);
                    boxes[a] = union(boxes[a], boxes.remove(b));
                    continue 'merged;
                }
            }
        }
        return;
    }
}

/// Two groups whose joint box takes at most this many times their boxes'
/// volumes are one part.
const MAX_MERGED: f32 = 1.1;

/// A primitive's box.
fn prim_box<P: Primitive>(prims: &[P], extents: &[Vec3], i: u32) -> [Vec3; 2] {
    let c = prims[i as usize].center();
    let e = extents[i as usize];
    [c - e, c + e]
}

fn union(a: [Vec3; 2], b: [Vec3; 2]) -> [Vec3; 2] {
    [a[0].min(b[0]), a[1].max(b[1])]
}

/// Volume of a box, 0 when empty (NaN on NaN bounds).
fn volume(b: [Vec3; 2]) -> f32 {
    (b[1] - b[0]).max(Vec3::ZERO).element_product()
}

const EMPTY: [Vec3; 2] = [Vec3::INFINITY, Vec3::NEG_INFINITY];

/// The two groups of the best plane across the centres of `group` (`None`:
/// every primitive), if it is worth a split.
fn split<P: Primitive>(
    prims: &[P],
    extents: &[Vec3],
    group: Option<&[u32]>,
) -> Option<(Vec<u32>, Vec<u32>)> {
    let len = group.map_or(prims.len(), <[u32]>::len);
    if len < 2 * MIN_PART {
        return None;
    }
    let id = |k: usize| group.map_or(k as u32, |g| g[k]);
    let stride = len.div_ceil(SAMPLES);
    let sample: Vec<u32> = (0..len).step_by(stride).map(id).collect();
    let (clo, chi, whole) = sample
        .iter()
        .map(|&i| {
            let c = prims[i as usize].center();
            (c, c, prim_box(prims, extents, i))
        })
        .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1), union(a.2, b.2)))?;
    let whole = volume(whole);
    let usable = clo.is_finite() && chi.is_finite() && whole > 0.0 && whole.is_finite();
    if !usable {
        return None;
    }
    let bin = |c: Vec3, axis: usize| {
        let (lo, hi) = (clo[axis], chi[axis]);
        let b = (c[axis] - lo) / (hi - lo) * BINS as f32;
        // NaN and out-of-range centres saturate into the end bins.
        (b as usize).min(BINS - 1)
    };
    // Best (volume, axis, last bin of the lower group).
    let mut best: Option<(f32, usize, usize)> = None;
    for axis in 0..3 {
        if chi[axis] <= clo[axis] {
            continue;
        }
        let mut bins = [(0usize, EMPTY); BINS];
        for &i in &sample {
            let b = &mut bins[bin(prims[i as usize].center(), axis)];
            b.0 += 1;
            b.1 = union(b.1, prim_box(prims, extents, i));
        }
        let mut below = [(0usize, EMPTY); BINS];
        let mut acc = (0usize, EMPTY);
        for (k, b) in bins.iter().enumerate() {
            acc = (acc.0 + b.0, union(acc.1, b.1));
            below[k] = acc;
        }
        let mut above = (0usize, EMPTY);
        for k in (0..BINS - 1).rev() {
            above = (above.0 + bins[k + 1].0, union(above.1, bins[k + 1].1));
            let (n_lo, box_lo) = below[k];
            if n_lo * stride < MIN_PART || above.0 * stride < MIN_PART {
                continue;
            }
            let v = volume(box_lo) + volume(above.1);
            if best.is_none_or(|b| v < b.0) {
                best = Some((v, axis, k));
            }
        }
    }
    let (v, axis, k) = best?;
    if v.is_nan() || v >= MAX_VOLUME * whole {
        return None;
    }
    let (lower, upper): (Vec<u32>, Vec<u32>) = (0..len)
        .into_par_iter()
        .map(id)
        .partition(|&i| bin(prims[i as usize].center(), axis) <= k);
    (!lower.is_empty() && !upper.is_empty()).then_some((lower, upper))
}
