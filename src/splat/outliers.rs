//! Statistical outlier removal: a point whose neighbours are much farther
//! away than is usual, locally or over the whole cloud, is not on a surface
//! the scan sampled (a spurious return, a mixed pixel far behind an edge),
//! and would grow a giant splat.

use super::knn::{Knn, build_tree, morton_order};
use crate::data::Viewpoints;
use glam::Vec3;
use rayon::prelude::*;

/// A point is a local outlier when its k-th neighbour distance exceeds this
/// many times the median k-th neighbour distance of its neighbours (and
/// [`LOCAL_FLOOR`] times the cloud's median). On
/// uniform random samples of a surface the ratio stays below about 2; a half
/// neighbourhood at a boundary gives about √2.
pub const LOCAL_RATIO: f32 = 3.0;

/// ... but only when its k-th neighbour distance also exceeds this many
/// times the cloud's 90th percentile: clouds sampled unevenly (mesh vertices
/// crowded at some places, merged scans) have ordinary points beside
/// crowded ones.
pub const LOCAL_FLOOR: f32 = 1.0;

/// A point is a global outlier when its k-th neighbour distance exceeds this
/// many times the cloud's 90th percentile (robust to a few per cent of
/// outliers, and to a cloud sampled unevenly). Spurious returns scattered through the
/// scanned volume are each other's neighbours, so the local test alone
/// keeps them. With a viewpoint the distances are divided by the range
/// first, since a scan's spacing grows with it.
pub const GLOBAL_RATIO: f32 = 3.0;

/// Flags the outliers among `points` with neighbourhood graph `knn` (see
/// [`LOCAL_RATIO`] and [`GLOBAL_RATIO`]).
#[must_use]
pub fn flag(points: &[Vec3], knn: &Knn, viewpoint: Option<&Viewpoints>) -> Vec<bool> {
    let n = knn.kth_distance.len();
    if n == 0 {
        return Vec::new();
    }
    let scaled: Vec<f32> = match viewpoint {
        Some(vp) => points
            .iter()
            .zip(&knn.kth_distance)
            .enumerate()
            .map(|(i, (p, d))| d / (*p - vp.at(i)).length().max(f32::MIN_POSITIVE))
            .collect(),
        None => knn.kth_distance.clone(),
    };
    let mut sorted = scaled.clone();
    let q = (n - 1) * 9 / 10;
    let global = *sorted.select_nth_unstable_by(q, f32::total_cmp).1;
    (0..n)
        .into_par_iter()
        .with_min_len(1024)
        .map(|i| {
            if scaled[i] > GLOBAL_RATIO * global {
                return true;
            }
            // The floor first: it needs no neighbour, and about nine
            // points in ten (those under the 90th percentile) fail it (on
            // the 200k bunny the medians took 215 M instructions, a
            // tenth of the graph's queries).
            let over_floor = scaled[i] > LOCAL_FLOOR * global;
            if !over_floor {
                return false;
            }
            let mut d: Vec<f32> = knn
                .of(i)
                .iter()
                .map(|&j| knn.kth_distance[j as usize])
                .collect();
            if d.is_empty() {
                return false;
            }
            let mid = d.len() / 2;
            let m = *d.select_nth_unstable_by(mid, f32::total_cmp).1;
            knn.kth_distance[i] > LOCAL_RATIO * m
        })
        .collect()
}

/// [`flag`] on a cloud of distinct points, building its own `k`-nearest
/// neighbour graph.
#[must_use]
pub fn find(points: &[Vec3], k: usize, viewpoint: Option<&Viewpoints>) -> Vec<bool> {
    if points.len() <= k {
        return vec![false; points.len()];
    }
    let tree = build_tree(points);
    // Queried in Morton order: the same graph, each query bounded by a near
    // one's. As read, a scan's points follow its lines, not space: on the
    // noisy scan this graph took 0.23-0.36 s (three runs, loaded machine),
    // more than generation's whole graph stage (docs/notes/generation.md,
    // "Issue 54, eighth session").
    let order = morton_order(points);
    flag(points, &Knn::build_in_order(&tree, points, k, &order), viewpoint)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`flag`] against the test as written in full for every point (the
    /// median of the neighbours' k-th distances, then both floors): the
    /// same flags on a jittered sheet with a few points lifted off it
    /// (local outliers), a far cluster (global ones), and with a scanner;
    /// and some of each kind are flagged.
    #[test]
    fn the_floor_first_flags_what_the_whole_test_flags() {
        let mut s = 0x2545_f491_u32;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            s as f32 / u32::MAX as f32
        };
        let mut pts: Vec<Vec3> = (0..3600)
            .map(|i| {
                let (x, y) = ((i % 60) as f32, (i / 60) as f32);
                Vec3::new(x + 0.3 * next(), y + 0.3 * next(), 0.05 * next())
            })
            .collect();
        for i in (0..3600).step_by(97) {
            pts[i].z += 4.0 + 3.0 * next();
        }
        pts.extend((0..5).map(|i| Vec3::new(200.0 + i as f32 * 9.0, 200.0, 50.0)));
        let tree = build_tree(&pts);
        let knn = Knn::build(&tree, &pts, 12);
        let sights = Viewpoints::One(Vec3::new(30.0, 30.0, 40.0));
        for viewpoint in [None, Some(&sights)] {
            let got = flag(&pts, &knn, viewpoint);
            let scaled: Vec<f32> = (0..pts.len())
                .map(|i| match viewpoint {
                    Some(vp) => knn.kth_distance[i] / (pts[i] - vp.at(i)).length().max(f32::MIN_POSITIVE),
                    None => knn.kth_distance[i],
                })
                .collect();
            let mut sorted = scaled.clone();
            sorted.sort_by(f32::total_cmp);
            let global = sorted[(pts.len() - 1) * 9 / 10];
            let want: Vec<bool> = (0..pts.len())
                .map(|i| {
                    let mut d: Vec<f32> = knn.of(i).iter().map(|&j| knn.kth_distance[j as usize]).collect();
                    d.sort_by(f32::total_cmp);
                    let m = d[d.len() / 2];
                    scaled[i] > GLOBAL_RATIO * global
                        || (knn.kth_distance[i] > LOCAL_RATIO * m && scaled[i] > LOCAL_FLOOR * global)
                })
                .collect();
            assert_eq!(got, want);
            let lifted = (0..3600).step_by(97).filter(|&i| got[i]).count();
            // Measured: 8 of the 38 lifted points without the scanner, 12
            // with it.
            assert!(lifted >= 6 && got[3600..].iter().all(|&f| f), "{lifted}");
        }
    }
}
