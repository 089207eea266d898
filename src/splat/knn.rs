//! The neighbourhood graph `N = (P, E)` of §2: each point's `k` nearest
//! neighbours, from a kd-tree (`kiddo`), queried in parallel.

use glam::Vec3;
use kiddo::SquaredEuclidean;
use kiddo::immutable::float::kdtree::ImmutableKdTree;
use rayon::prelude::*;
use std::num::NonZero;

/// The kd-tree over the points (item = point index).
pub type PointTree = ImmutableKdTree<f32, u32, 3, 32>;

/// Build the kd-tree over `points`.
#[must_use]
pub fn build_tree(points: &[Vec3]) -> PointTree {
    let coords: Vec<[f32; 3]> = points.iter().map(|p| p.to_array()).collect();
    ImmutableKdTree::new_from_slice(&coords)
}

/// The k-nearest-neighbour graph, stored flat: the neighbours of point `i`
/// are `idx[i*k .. (i+1)*k]`, nearest first, the point itself excluded.
#[derive(Clone, Debug)]
pub struct Knn {
    /// Neighbours per point.
    pub k: usize,
    /// Neighbour indices, `k` per point.
    pub idx: Vec<u32>,
    /// The distance `d_i = |p_i - p_k|` to the k-th neighbour: the local
    /// sampling density estimate of §2.
    pub kth_distance: Vec<f32>,
}

impl Knn {
    /// The neighbours of point `i`, nearest first.
    #[must_use]
    pub fn of(&self, i: usize) -> &[u32] {
        &self.idx[i * self.k..(i + 1) * self.k]
    }

    /// Query the `k` nearest neighbours of every point (`k < points.len()`,
    /// `k >= 1`; the points must be distinct).
    #[must_use]
    pub fn build(tree: &PointTree, points: &[Vec3], k: usize) -> Knn {
        let k = k.clamp(1, points.len().saturating_sub(1).max(1));
        let q = NonZero::new(k + 1).unwrap_or(NonZero::<usize>::MIN);
        let rows: Vec<(Vec<u32>, f32)> = points
            .par_iter()
            .enumerate()
            .with_min_len(1024)
            .map(|(i, p)| {
                let found = tree.nearest_n::<SquaredEuclidean>(&p.to_array(), q);
                let mut row: Vec<u32> = Vec::with_capacity(k);
                let mut last = 0f32;
                for nb in found {
                    if nb.item as usize == i || row.len() == k {
                        continue;
                    }
                    row.push(nb.item);
                    last = nb.distance;
                }
                // Pad (only with fewer found than asked) with the last one.
                while row.len() < k {
                    let fill = row.last().copied().unwrap_or(if i == 0 { 1 } else { 0 });
                    row.push(fill);
                }
                (row, last.sqrt())
            })
            .collect();
        let mut idx = Vec::with_capacity(points.len() * k);
        let mut kth_distance = Vec::with_capacity(points.len());
        for (row, d) in rows {
            idx.extend_from_slice(&row);
            kth_distance.push(d);
        }
        Knn {
            k,
            idx,
            kth_distance,
        }
    }
}
