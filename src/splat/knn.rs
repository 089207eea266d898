//! The neighbourhood graph `N = (P, E)` of §2: each point's `k` nearest
//! neighbours, from a kd-tree (`kiddo`), queried in parallel.

use glam::Vec3;
use kiddo::SquaredEuclidean;
use kiddo::immutable::float::kdtree::ImmutableKdTree;
use rayon::prelude::*;
use std::num::NonZero;

/// Points searched in order by one task (each bounds its search by the
/// one before).
const CHUNK: usize = 1024;

/// How many points ahead in the order of queries the graph's builds point
/// [`Nearest`]'s next cached ball ([`Nearest::look_ahead`]).
const AHEAD: usize = 8;

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
    /// The tree queries that made it: one a point when built, those of
    /// the points whose neighbours were dropped when repaired
    /// ([`Knn::retain`]).
    pub queries: usize,
    /// Each point's wide neighbourhood, from the same queries
    /// ([`Knn::build_wide`]), while the stages that read it run; `None`
    /// once they are done (or never asked for).
    pub wide: Option<Wide>,
}

/// Each point's `m` nearest points of the cloud, itself among them,
/// nearest first, ties by index: the wide neighbourhoods the normals'
/// estimate and the face search read (`normals::estimate_multiscale`,
/// `normals::face_normals`), kept from the one query a point that made
/// the graph. A row is the point itself, then its graph row (its `k`
/// nearest others), then a tail, and only the tails are stored:
/// `4 (m - k - 1) + 4` bytes a point while all are kept
/// ([`Knn::keep_wide`] keeps fewer).
#[derive(Clone, Debug)]
pub struct Wide {
    /// Points a row.
    pub m: usize,
    /// Points a tail (`m - k - 1`, at least 1).
    t: usize,
    /// The tails kept, `t` each.
    tail: Vec<u32>,
    /// Which tail each point's is (`u32::MAX`: not kept); `None`: every
    /// point's, in order.
    slot: Option<Vec<u32>>,
    /// Each row's last squared distance, while every row is kept.
    last: Vec<f32>,
}

impl Wide {
    /// Which kept tail is point `i`'s, where kept.
    fn row(&self, i: usize) -> Option<usize> {
        let r = match &self.slot {
            None => i,
            Some(slot) => match slot.get(i) {
                Some(&r) if r != u32::MAX => r as usize,
                _ => return None,
            },
        };
        ((r + 1) * self.t <= self.tail.len()).then_some(r)
    }

    /// Point `i`'s tail, where kept.
    fn tail(&self, i: usize) -> Option<&[u32]> {
        self.row(i).map(|r| &self.tail[r * self.t..(r + 1) * self.t])
    }
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
        // Points come in spatial (Morton) order, so a point's k + 1
        // nearest lie about as far as its predecessor's: each chunk's
        // queries are [`Nearest`]'s, bounded by the one before, exact, ties
        // by index (a grid's or an organised capture's neighbours in a fixed
        // order, not the tree's). Against the heap of `nearest_n_within`
        // bounded the same way: 0.97x the CPU of the whole `splat` of 200k
        // bunny points (paired runs in turns, 5 pairs).
        Knn::rows(points.len(), k, |nearest, i, row| {
            nearest.look_ahead(points[(i + AHEAD).min(points.len() - 1)]);
            nearest_row(nearest, tree, points, i, row)
        })
    }

    /// [`Knn::build`] with the queries made in `order` (a permutation of
    /// the points' indices): the same graph bit for bit, since each row is
    /// its point's exact nearest, ties by index, whatever bound the query
    /// before it gave ([`Nearest::query`]). For points that are not in
    /// spatial order (a scan's lines, as read) queried in [`morton_order`]:
    /// each query is then bounded by a near one's and served from its
    /// cached ball ([`super::outliers::find`]'s graph of a cloud as read).
    #[must_use]
    pub fn build_in_order(tree: &PointTree, points: &[Vec3], k: usize, order: &[u32]) -> Knn {
        let k = k.clamp(1, points.len().saturating_sub(1).max(1));
        debug_assert_eq!(order.len(), points.len());
        let by_order = Knn::rows(points.len(), k, |nearest, j, row| {
            nearest.look_ahead(points[order[(j + AHEAD).min(order.len() - 1)] as usize]);
            nearest_row(nearest, tree, points, order[j] as usize, row)
        });
        let mut idx = vec![0u32; points.len() * k];
        let mut kth_distance = vec![0f32; points.len()];
        for (j, &i) in order.iter().enumerate() {
            let i = i as usize;
            idx[i * k..(i + 1) * k].copy_from_slice(by_order.of(j));
            kth_distance[i] = by_order.kth_distance[j];
        }
        Knn {
            k,
            idx,
            kth_distance,
            queries: by_order.queries,
            wide: None,
        }
    }

    /// The graph of `n` points, `k` neighbours each, row by row in chunks
    /// of [`CHUNK`] in parallel: `row(nearest, i, row)` fills point `i`'s
    /// row (querying with the chunk's `nearest`, counted) and returns its
    /// k-th distance.
    fn rows(
        n: usize,
        k: usize,
        row: impl Fn(&mut Nearest<'_>, usize, &mut [u32]) -> f32 + Sync,
    ) -> Knn {
        let mut idx = vec![0u32; n * k];
        let mut kth_distance = vec![0f32; n];
        let tally = Tally::default();
        idx.par_chunks_mut(k * CHUNK)
            .zip(kth_distance.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, (rows, kths))| {
                let mut nearest = Nearest::counted(&tally);
                for (j, (r, kth)) in rows.chunks_mut(k).zip(kths.iter_mut()).enumerate() {
                    *kth = row(&mut nearest, c * CHUNK + j, r);
                }
            });
        Knn {
            k,
            idx,
            kth_distance,
            queries: tally.get(),
            wide: None,
        }
    }

    /// [`Knn::build`] with each point's wide neighbourhood of its `m`
    /// nearest ([`Wide`]; `m` at most the points), from one query a point:
    /// the `k + 1` nearest, ties by index, are the prefix of the `m`
    /// nearest, so the graph is [`Knn::build`]'s bit for bit. Without wide
    /// rows where `m` is under `k + 2`, or where a point is not the first of
    /// its own row (another at distance 0 before it: not a cloud of
    /// distinct points).
    #[must_use]
    pub fn build_wide(tree: &PointTree, points: &[Vec3], k: usize, m: usize) -> Knn {
        let n = points.len();
        let k = k.clamp(1, n.saturating_sub(1).max(1));
        let m = m.min(n);
        if m < k + 2 {
            return Knn::build(tree, points, k);
        }
        Knn::rows_wide(n, k, m, |nearest, i, row, tail| {
            nearest.look_ahead(points[(i + AHEAD).min(n - 1)]);
            let found = nearest.query(tree, points, points[i], m);
            wide_row(found, i, row, tail)
        })
    }

    /// [`Knn::rows`] with the wide rows' tails: `row(nearest, i, row,
    /// tail)` fills point `i`'s graph row and tail and returns the k-th's
    /// distance, the row's last squared distance, and whether the point
    /// came first in its row (else no wide rows are kept).
    fn rows_wide(
        n: usize,
        k: usize,
        m: usize,
        row: impl Fn(&mut Nearest<'_>, usize, &mut [u32], &mut [u32]) -> (f32, f32, bool) + Sync,
    ) -> Knn {
        let t = m - k - 1;
        let mut idx = vec![0u32; n * k];
        let mut kth_distance = vec![0f32; n];
        let mut tail = vec![0u32; n * t];
        let mut last = vec![0f32; n];
        let tally = Tally::default();
        let odd = std::sync::atomic::AtomicBool::new(false);
        idx.par_chunks_mut(k * CHUNK)
            .zip(kth_distance.par_chunks_mut(CHUNK))
            .zip(tail.par_chunks_mut(t * CHUNK))
            .zip(last.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, (((rows, kths), tails), lasts))| {
                let mut nearest = Nearest::counted(&tally);
                let per_point = rows
                    .chunks_mut(k)
                    .zip(kths.iter_mut())
                    .zip(tails.chunks_mut(t))
                    .zip(lasts.iter_mut());
                for (j, (((r, kth), w), l)) in per_point.enumerate() {
                    let first;
                    (*kth, *l, first) = row(&mut nearest, c * CHUNK + j, r, w);
                    if !first {
                        odd.store(true, std::sync::atomic::Ordering::Relaxed);
                    }
                }
            });
        let wide = (!odd.into_inner()).then_some(Wide {
            m,
            t,
            tail,
            slot: None,
            last,
        });
        Knn {
            k,
            idx,
            kth_distance,
            queries: tally.get(),
            wide,
        }
    }

    /// Point `i`'s wide row of `m` points into `out` (the point, its graph
    /// row, its tail), where this graph keeps it ([`Knn::build_wide`]):
    /// whether it did.
    pub fn wide_into(&self, i: usize, m: usize, out: &mut Vec<u32>) -> bool {
        let Some(tail) = self.wide.as_ref().filter(|w| w.m == m).and_then(|w| w.tail(i)) else {
            return false;
        };
        out.push(i as u32);
        out.extend_from_slice(self.of(i));
        out.extend_from_slice(tail);
        true
    }

    /// Keeps the wide rows of the points `keep` marks only (the others'
    /// readers are done); none where it marks none. The kept tails move
    /// down in place (a kept row's new place is never after its old one)
    /// and the buffer is cut to them: no second buffer, grown by doubling
    /// beside the whole one (on the 200k bunny with every unsettled row
    /// kept, that copy had raised the peak from 72 to 91 MiB).
    pub fn keep_wide(&mut self, keep: impl Fn(usize) -> bool) {
        let Some(mut w) = self.wide.take() else {
            return;
        };
        let n = self.kth_distance.len();
        let mut slot = vec![u32::MAX; n];
        let mut kept = 0;
        for (i, s) in slot.iter_mut().enumerate() {
            if !keep(i) {
                continue;
            }
            let Some(r) = w.row(i) else {
                continue;
            };
            w.tail.copy_within(r * w.t..(r + 1) * w.t, kept * w.t);
            *s = kept as u32;
            kept += 1;
        }
        w.tail.truncate(kept * w.t);
        w.tail.shrink_to_fit();
        self.wide = (kept > 0).then_some(Wide {
            slot: Some(slot),
            last: Vec::new(),
            ..w
        });
    }

    /// This graph widened to `k` neighbours (more than its own): from the
    /// wide rows where they hold `k + 1` points ([`Knn::build_wide`]),
    /// each row less the point itself (its first), with its last
    /// distance, bit for bit [`Knn::build`]'s (the same query's answer);
    /// else built. Without wide rows.
    #[must_use]
    pub fn widened(&self, k: usize, tree: &PointTree, points: &[Vec3]) -> Knn {
        let k = k.clamp(1, points.len().saturating_sub(1).max(1));
        let Some(w) = self
            .wide
            .as_ref()
            .filter(|w| w.m == k + 1 && w.slot.is_none() && w.last.len() == points.len())
        else {
            return Knn::build(tree, points, k);
        };
        Knn::rows(points.len(), k, |_, i, row| {
            let (head, tail) = row.split_at_mut(self.k);
            head.copy_from_slice(self.of(i));
            tail.copy_from_slice(&w.tail[i * w.t..(i + 1) * w.t]);
            w.last[i].sqrt()
        })
    }

    /// This graph cut down to the points `keep` holds (`points` and
    /// `tree` are the kept ones', in the same order), in place: a point
    /// none of whose neighbours was dropped keeps its row (renumbered), and
    /// only the others are queried again. The same graph as [`Knn::build`]
    /// over the kept points, bit for bit: a kept row's `k` nearest are
    /// nearest among fewer points too, and renumbering keeps the order of
    /// indices, so ties break the same way. With wide rows
    /// ([`Knn::build_wide`]), the same holds of them: a point whose wide
    /// row held a dropped one is queried again, for both rows.
    ///
    /// In place, because a second graph beside the first doubled the
    /// peak memory of a cloud with outliers: the wide rows alone take
    /// 148 B a point (a survey's tile peaked at 480 B a point with both).
    pub fn retain(&mut self, keep: &[bool], tree: &PointTree, points: &[Vec3]) {
        match self.compact_kept(keep, points) {
            Some((again, m)) => self.requery(&again, tree, points, m),
            None => self.rebuild(tree, points),
        }
    }

    /// [`Knn::retain`] with the kd-tree over the kept `points` built
    /// beside the kept rows' move (which reads no tree): the same graph,
    /// and the tree, which the caller keeps. The calling thread built the
    /// tree alone before, while the workers waited (kiddo's build is
    /// serial).
    #[must_use]
    pub fn retain_building(&mut self, keep: &[bool], points: &[Vec3]) -> PointTree {
        let (tree, kept) = rayon::join(|| build_tree(points), || self.compact_kept(keep, points));
        match kept {
            Some((again, m)) => self.requery(&again, &tree, points, m),
            None => self.rebuild(&tree, points),
        }
        tree
    }

    /// [`Knn::retain`]'s first part, which reads no tree: the kept rows
    /// moved down and renumbered, and which kept points are to be queried
    /// again (with the wide rows' size, 0 for none); `None` where the
    /// graph is to be built afresh ([`Knn::rebuild`]).
    fn compact_kept(&mut self, keep: &[bool], points: &[Vec3]) -> Option<(Vec<bool>, usize)> {
        let k = self.k.clamp(1, points.len().saturating_sub(1).max(1));
        let mut new_of = vec![u32::MAX; keep.len()];
        let mut kept_old = Vec::with_capacity(points.len());
        for i in (0..keep.len()).filter(|&i| keep[i]) {
            new_of[i] = kept_old.len() as u32;
            kept_old.push(i);
        }
        let whole = self.wide.as_ref().filter(|w| w.slot.is_none());
        let m = whole.map_or(0, |w| w.m.min(points.len()));
        if k != self.k || kept_old.len() != points.len() || whole.is_some_and(|w| w.m != m) {
            // Fewer points than a neighbourhood (or a caller's mismatch).
            return None;
        }
        if whole.is_none() {
            self.wide = None;
        }
        // Which kept points had a dropped neighbour (in either row).
        let again: Vec<bool> = kept_old
            .par_iter()
            .map(|&old| {
                let tail = self.wide.as_ref().and_then(|w| w.tail(old)).unwrap_or(&[]);
                !self.of(old).iter().chain(tail).all(|&o| keep[o as usize])
            })
            .collect();
        self.compact(&kept_old, &new_of, &again);
        Some((again, m))
    }

    /// This graph built afresh over `points` (with wide rows where it had
    /// every point's), the old one dropped first: [`Knn::retain`] where
    /// fewer points are kept than a neighbourhood holds.
    fn rebuild(&mut self, tree: &PointTree, points: &[Vec3]) {
        let k = self.k.clamp(1, points.len().saturating_sub(1).max(1));
        let whole = self.wide.as_ref().filter(|w| w.slot.is_none());
        let m = whole.map(|w| w.m.min(points.len()));
        self.idx = Vec::new();
        self.wide = None;
        *self = match m {
            Some(m) => Knn::build_wide(tree, points, k, m),
            None => Knn::build(tree, points, k),
        };
    }

    /// [`Knn::retain`]'s move of the kept rows down to their new places,
    /// renumbered, in order (a new index is at most its old one, so a row
    /// is read before any write reaches it); rows marked `again` are left
    /// for [`Knn::requery`].
    fn compact(&mut self, kept_old: &[usize], new_of: &[u32], again: &[bool]) {
        let (k, n) = (self.k, kept_old.len());
        let renumber = |v: &mut [u32], i: usize, old: usize, w: usize| {
            for j in 0..w {
                v[i * w + j] = new_of[v[old * w + j] as usize];
            }
        };
        for (i, &old) in kept_old.iter().enumerate() {
            if again[i] {
                continue;
            }
            renumber(&mut self.idx, i, old, k);
            self.kth_distance[i] = self.kth_distance[old];
            if let Some(w) = self.wide.as_mut() {
                renumber(&mut w.tail, i, old, w.t);
                w.last[i] = w.last[old];
            }
        }
        self.idx.truncate(n * k);
        self.kth_distance.truncate(n);
        if let Some(w) = self.wide.as_mut() {
            w.tail.truncate(n * w.t);
            w.last.truncate(n);
        }
    }

    /// [`Knn::retain`]'s queries: the rows marked `again` (and their wide
    /// rows of `m`, where kept), in chunks of [`CHUNK`] in parallel,
    /// counted in [`Knn::queries`]; the wide rows are dropped where a point
    /// is not the first of its own.
    fn requery(&mut self, again: &[bool], tree: &PointTree, points: &[Vec3], m: usize) {
        let k = self.k;
        let tally = Tally::default();
        let odd = std::sync::atomic::AtomicBool::new(false);
        let (t, mut tails, mut lasts) = match self.wide.as_mut() {
            Some(w) => (w.t, Some(&mut w.tail), Some(&mut w.last)),
            None => (0, None, None),
        };
        let tail_chunks = tails.as_mut().map(|v| v.par_chunks_mut(t * CHUNK));
        let last_chunks = lasts.as_mut().map(|v| v.par_chunks_mut(CHUNK));
        let rows = self
            .idx
            .par_chunks_mut(k * CHUNK)
            .zip(self.kth_distance.par_chunks_mut(CHUNK))
            .enumerate();
        let each = |c: usize, rows: &mut [u32], kths: &mut [f32], mut wide: Option<(&mut [u32], &mut [f32])>| {
            let mut nearest = Nearest::counted(&tally);
            for (j, (r, kth)) in rows.chunks_mut(k).zip(kths.iter_mut()).enumerate() {
                let i = c * CHUNK + j;
                if !again[i] {
                    continue;
                }
                match wide.as_mut() {
                    Some((tail, last)) => {
                        let found = nearest.query(tree, points, points[i], m);
                        let first;
                        (*kth, last[j], first) = wide_row(found, i, r, &mut tail[j * t..(j + 1) * t]);
                        if !first {
                            odd.store(true, std::sync::atomic::Ordering::Relaxed);
                        }
                    }
                    None => *kth = nearest_row(&mut nearest, tree, points, i, r),
                }
            }
        };
        match (tail_chunks, last_chunks) {
            (Some(tc), Some(lc)) => rows
                .zip(tc)
                .zip(lc)
                .for_each(|(((c, (r, kth)), tail), last)| each(c, r, kth, Some((tail, last)))),
            _ => rows.for_each(|(c, (r, kth))| each(c, r, kth, None)),
        }
        self.queries = tally.get();
        if odd.into_inner() {
            self.wide = None;
        }
    }
}

/// Point `i`'s row of the graph: its `row.len()` nearest others, nearest
/// first (padded with the last where fewer exist); returns the last one's
/// distance.
fn nearest_row(
    nearest: &mut Nearest<'_>,
    tree: &PointTree,
    points: &[Vec3],
    i: usize,
    row: &mut [u32],
) -> f32 {
    let found = nearest.query(tree, points, points[i], row.len() + 1);
    take_row(found, i, row)
}

/// Point `i`'s rows from its nearest `found` (nearest first, ties by
/// index, `row.len() + 1 + tail.len()` of them): `row` from their prefix
/// as [`nearest_row`] takes it, `tail` the rest; returns the k-th's
/// distance, the last one's squared distance, and whether the point came
/// first (so that the row is the point, `row`, `tail`).
fn wide_row(found: &[(f32, u32)], i: usize, row: &mut [u32], tail: &mut [u32]) -> (f32, f32, bool) {
    let k = row.len();
    let kth = take_row(&found[..found.len().min(k + 1)], i, row);
    let rest = found.get(k + 1..).unwrap_or(&[]);
    for (t, f) in tail.iter_mut().zip(rest) {
        *t = f.1;
    }
    let first = found.first().is_some_and(|f| f.1 as usize == i) && rest.len() == tail.len();
    (kth, found.last().map_or(0.0, |f| f.0), first)
}

/// Point `i`'s row of the graph from its nearest `found` (nearest first,
/// ties by index, at most `row.len() + 1`): the others, padded with the
/// last where fewer; returns the last one's distance.
fn take_row(found: &[(f32, u32)], i: usize, row: &mut [u32]) -> f32 {
    let k = row.len();
    let mut len = 0usize;
    let mut last = 0f32;
    for &(d, item) in found {
        if item as usize == i || len == k {
            continue;
        }
        row[len] = item;
        len += 1;
        last = d;
    }
    // Pad (only with fewer found than asked) with the last one.
    let fill = if len > 0 {
        row[len - 1]
    } else {
        u32::from(i == 0)
    };
    row[len..].fill(fill);
    last.sqrt()
}

/// Morton (Z-curve) keys over a box: 21 bits an axis, interleaved.
pub(crate) struct MortonGrid {
    lo: Vec3,
    scale: Vec3,
}

impl MortonGrid {
    /// The grid over the box `lo`..`hi` (of finite points).
    pub(crate) fn new(lo: Vec3, hi: Vec3) -> MortonGrid {
        let scale = Vec3::splat((1u32 << 21) as f32 - 1.0) / (hi - lo).max(Vec3::splat(1e-30));
        MortonGrid { lo, scale }
    }

    /// The key of finite `p` inside the box.
    pub(crate) fn key(&self, p: Vec3) -> u64 {
        let spread = |v: u32| {
            let mut x = u64::from(v) & 0x1f_ffff;
            x = (x | x << 32) & 0x1f00000000ffff;
            x = (x | x << 16) & 0x1f0000ff0000ff;
            x = (x | x << 8) & 0x100f00f00f00f00f;
            x = (x | x << 4) & 0x10c30c30c30c30c3;
            (x | x << 2) & 0x1249249249249249
        };
        let q = ((p - self.lo) * self.scale).as_uvec3();
        spread(q.x) | spread(q.y) << 1 | spread(q.z) << 2
    }
}

/// The points' indices in Morton (Z-curve) order over their bounding box,
/// ties by index, the non-finite last: an order of queries, not of the
/// points (see [`Knn::build_in_order`]).
#[must_use]
pub fn morton_order(points: &[Vec3]) -> Vec<u32> {
    let (lo, hi) = points
        .iter()
        .filter(|p| p.is_finite())
        .fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |a, &p| {
            (a.0.min(p), a.1.max(p))
        });
    let grid = MortonGrid::new(lo, hi);
    let mut keyed: Vec<(u64, u32)> = points
        .par_iter()
        .enumerate()
        .map(|(i, &p)| {
            let m = if p.is_finite() { grid.key(p) } else { u64::MAX };
            (m, i as u32)
        })
        .collect();
    keyed.par_sort_unstable();
    keyed.into_iter().map(|(_, i)| i).collect()
}

/// A count of tree queries shared by the threads of one stage: each
/// [`Nearest`] adds its own when dropped.
#[derive(Default)]
pub struct Tally(std::sync::atomic::AtomicUsize);

impl Tally {
    /// Queries counted so far.
    #[must_use]
    pub fn get(&self) -> usize {
        self.0.load(std::sync::atomic::Ordering::Relaxed)
    }

    fn add(&self, n: usize) {
        self.0.fetch_add(n, std::sync::atomic::Ordering::Relaxed);
    }
}

/// How far past the previous query's `m`-th nearest a bounded query
/// ([`Nearest::query`]) looks, as a factor on squared distances: 1.2² (a
/// surface's `m` nearest cover 1.44 times the area the previous point's
/// did).
const BOUND_GROWTH_SQ: f32 = 1.44;

/// Exact `m`-nearest queries for points visited in spatial (Morton) order,
/// without a result heap: all points within a bound taken from the
/// previous query, the `m` nearest of them selected, and an unbounded
/// `nearest_n` (and the ties of its last) only where the bound holds fewer
/// than `m`.
///
/// The points within the bound come from a cache: one tree query
/// (`within_unsorted`) of a ball [`cache_reach`] times the bound's radius
/// serves every following query whose own ball it holds (consecutive
/// points in Morton order lie close), each then a scan of the cached
/// points, kept in shells of squared distance from the ball's centre, in
/// the shells the query's own ball reaches (between its centre's distance
/// less and plus its radius). The distances are the tree's own sum, so the set is the
/// tree's bit for bit (each refill checks it, and queries the tree itself
/// from then on where the points given are not the tree's).
/// One per thread (the bound carries from one query to the next); results
/// in `found`, sorted by (squared distance, index), the query point itself
/// included when it is one of the tree's.
/// Queries are counted into a [`Tally`] when it is dropped.
#[derive(Default)]
pub struct Nearest<'t> {
    /// The bound on the next query's squared distance (infinite: none).
    bound: f32,
    /// The last query's result: (squared distance, index), nearest first.
    pub found: Vec<(f32, u32)>,
    /// Scratch: the candidates as [`key`]s.
    keys: Vec<u64>,
    /// The cached ball: its centre, its radius (none yet: not positive)
    /// and the points in it, coordinates apart, with their indices.
    cache: Cache,
    /// Where the next queries go ([`Nearest::look_ahead`]), for the next
    /// query only.
    ahead: Option<[f32; 3]>,
    /// Queries made, and where they are counted.
    queries: usize,
    /// Queries whose candidates were all sorted at once (no selection).
    whole_sorts: usize,
    tally: Option<&'t Tally>,
}

/// [`Nearest`]'s cached ball of points, in [`SHELLS`] shells about its
/// centre: a query scans only the shells its own ball can reach.
struct Cache {
    centre: [f32; 3],
    radius: f32,
    x: Vec<f32>,
    y: Vec<f32>,
    z: Vec<f32>,
    items: Vec<u32>,
    /// Scratch of [`Cache::fill`]: each found point's shell.
    shells: Vec<u8>,
    /// Where each shell's points start in `x`, `y`, `z` and `items`, and
    /// where the last ends.
    starts: [usize; SHELLS + 1],
    /// [`SHELLS`] over the squared radius (see [`Cache::shell`]).
    scale: f32,
    /// The points given were not the tree's: no cache.
    off: bool,
    /// Tree queries that filled it.
    fills: usize,
    /// Its radius over the radius of the query that filled it.
    reach: f32,
    /// The SIMD path of its scan ([`Cache::within`]).
    isa: crate::simd::Isa,
}

impl Default for Cache {
    fn default() -> Cache {
        Cache {
            centre: [0.0; 3],
            radius: 0.0,
            x: Vec::new(),
            y: Vec::new(),
            z: Vec::new(),
            items: Vec::new(),
            shells: Vec::new(),
            starts: [0; SHELLS + 1],
            scale: 0.0,
            off: false,
            fills: 0,
            reach: 0.0,
            isa: crate::config::current().simd,
        }
    }
}

/// A cached ball's radius, in radii of the bound that filled it, for
/// queries of `m` points: about [`CACHE_POINTS`] points on a surface, at
/// least [`MIN_REACH`] radii (six times the points of one query, reused
/// while the query point stays within 1.5 radii of its centre).
fn cache_reach(m: usize) -> f32 {
    (CACHE_POINTS / (BOUND_GROWTH_SQ * m.max(1) as f32))
        .sqrt()
        .max(MIN_REACH)
}

/// See [`cache_reach`]. At 2.0 the graph of the 2M bunny sample filled a
/// ball for 8.4 % of its queries and scanned 162 points a query; at 2.5,
/// centred ahead ([`towards`]), 3.2 % and 217: 0.85-0.93x the CPU of its
/// graph (docs/notes/generation.md, "twelfth session").
const MIN_REACH: f32 = 2.5;

/// The centre of a ball `reach` times `r` for a query at `q` whose next
/// queries go towards `a`: `q` moved towards `a` by at most 0.8 of the
/// room the query's own ball of radius `r` leaves, so that ball stays
/// inside with [`CACHE_MARGIN`] to spare (else `q` itself).
fn towards(q: [f32; 3], a: [f32; 3], reach: f32, r: f32) -> [f32; 3] {
    let len = dist_sq(a, q).sqrt();
    let room = 0.8 * (reach - 1.0) * r;
    let f = if len > room { room / len } else { 1.0 };
    let c = [
        q[0] + f * (a[0] - q[0]),
        q[1] + f * (a[1] - q[1]),
        q[2] + f * (a[2] - q[2]),
    ];
    let inside = (dist_sq(q, c).sqrt() + r) * (1.0 + CACHE_MARGIN) <= reach * r;
    if inside && c.iter().all(|v| v.is_finite()) {
        c
    } else {
        q
    }
}

/// See [`cache_reach`].
const CACHE_POINTS: f32 = 200.0;

/// The relative margin by which a query's ball must lie inside the cached
/// one, far above the rounding of squared distances in `f32`.
const CACHE_MARGIN: f32 = 1e-4;

/// The shells of a cached ball: equal steps of squared distance from its
/// centre (equal areas on a surface through it).
const SHELLS: usize = 32;

/// The tree's squared distance (`SquaredEuclidean`'s sum, in its order).
#[inline]
pub(crate) fn dist_sq(a: [f32; 3], b: [f32; 3]) -> f32 {
    let (dx, dy, dz) = (a[0] - b[0], a[1] - b[1], a[2] - b[2]);
    dx * dx + dy * dy + dz * dz
}

impl Cache {
    /// Whether the ball of radius `r` round `q` lies inside the cached one,
    /// and that one is at most twice the size a fill for it would take (a
    /// ball filled round an outlier, wide as the cloud, is not scanned for
    /// the small neighbourhoods after it).
    fn holds(&self, q: [f32; 3], r: f32) -> bool {
        self.radius > 0.0
            && self.radius <= 2.0 * self.reach * r
            && (dist_sq(q, self.centre).sqrt() + r) * (1.0 + CACHE_MARGIN) <= self.radius
    }

    /// The shell of a point at squared distance `d` from the centre: a
    /// function of `d` that never decreases, so the points between two
    /// squared distances lie in the shells between theirs.
    #[inline]
    fn shell(&self, d: f32) -> usize {
        ((d * self.scale) as usize).min(SHELLS - 1)
    }

    /// The points of `tree` (whose coordinates are `points`) within
    /// `radius` of `q`, shell by shell; turned off where `points` are not
    /// the tree's.
    fn fill(&mut self, tree: &PointTree, points: &[Vec3], q: [f32; 3], reach: f32, r: f32) {
        let radius = reach * r;
        self.reach = reach;
        self.fills += 1;
        self.centre = q;
        self.radius = radius;
        self.scale = SHELLS as f32 / (radius * radius);
        let found = tree.within_unsorted::<SquaredEuclidean>(&q, radius * radius);
        let mut starts = [0usize; SHELLS + 1];
        // Each found point's shell, kept for the placing pass below.
        self.shells.clear();
        for f in &found {
            let p = points.get(f.item as usize);
            if p.is_none_or(|p| dist_sq(p.to_array(), q).to_bits() != f.distance.to_bits()) {
                self.off = true;
                self.radius = 0.0;
                return;
            }
            let s = self.shell(f.distance);
            starts[s + 1] += 1;
            self.shells.push(s as u8);
        }
        for s in 1..=SHELLS {
            starts[s] += starts[s - 1];
        }
        self.starts = starts;
        let n = found.len();
        for v in [&mut self.x, &mut self.y, &mut self.z] {
            v.resize(n, 0.0);
        }
        self.items.resize(n, 0);
        // A counting sort by shell: `starts` moves on to each shell's end.
        // (Every point was checked above to be one of `points`.)
        for (f, &s) in found.iter().zip(&self.shells) {
            let at = &mut starts[usize::from(s)];
            let p = points[f.item as usize];
            (self.x[*at], self.y[*at], self.z[*at], self.items[*at]) = (p.x, p.y, p.z, f.item);
            *at += 1;
        }
    }

    /// The cached points whose shells a ball of squared radius `bound`
    /// round `q` reaches: by the triangle inequality its points lie between
    /// `|q - c| - r` and `|q - c| + r` of the centre `c` (widened by
    /// [`CACHE_MARGIN`] of the sum, far past rounding).
    fn reach_of(&self, q: [f32; 3], bound: f32) -> std::ops::Range<usize> {
        let (off, r) = (dist_sq(q, self.centre).sqrt(), bound.sqrt());
        let margin = CACHE_MARGIN * (off + r);
        let lo = (off - r - margin).max(0.0);
        let hi = off + r + margin;
        self.starts[self.shell(lo * lo)]..self.starts[self.shell(hi * hi) + 1]
    }

    /// The cached points within squared distance `bound` of `q`, as keys
    /// into `keys` (at least 8 longer than the cache), in no order;
    /// returns how many. Eight points at a time, on the process's SIMD
    /// path ([`crate::simd::keys_within`]: the same points and distances
    /// on every path).
    fn within(&self, q: [f32; 3], bound: f32, keys: &mut [u64]) -> usize {
        let range = self.reach_of(q, bound);
        let (x, y, z) = (&self.x[range.clone()], &self.y[range.clone()], &self.z[range.clone()]);
        let items = &self.items[range];
        crate::simd::keys_within([x, y, z], items, q, bound, self.isa, keys)
    }
}

impl Drop for Nearest<'_> {
    fn drop(&mut self) {
        if let Some(t) = self.tally {
            t.add(self.queries);
        }
    }
}

impl<'t> Nearest<'t> {
    /// A query state with no bound yet, counted nowhere.
    #[must_use]
    pub fn new() -> Nearest<'t> {
        Nearest {
            bound: f32::INFINITY,
            found: Vec::new(),
            keys: Vec::new(),
            cache: Cache::default(),
            ahead: None,
            queries: 0,
            whole_sorts: 0,
            tally: None,
        }
    }

    /// A query state with no bound yet, its queries counted in `tally`.
    #[must_use]
    pub fn counted(tally: &'t Tally) -> Nearest<'t> {
        Nearest {
            bound: f32::INFINITY,
            found: Vec::new(),
            keys: Vec::new(),
            cache: Cache::default(),
            ahead: None,
            queries: 0,
            whole_sorts: 0,
            tally: Some(tally),
        }
    }

    /// Tells the next query where the ones after it go (a point a few
    /// queries ahead in the same order): a ball it fills is centred
    /// towards there, as far as its own ball allows, so it serves more of
    /// them. The answers are the same wherever the ball is (each is
    /// exactly the points within the bound); only fills and scans change.
    pub fn look_ahead(&mut self, p: Vec3) {
        self.ahead = Some(p.to_array());
    }

    /// Counts a query the caller made on the tree itself.
    pub fn count_other(&mut self) {
        self.queries += 1;
    }

    /// The `m` nearest points of `tree` (whose coordinates are `points`)
    /// to `q` into [`Nearest::found`] (fewer only when the tree holds
    /// fewer), nearest first, ties by index.
    pub fn query(&mut self, tree: &PointTree, points: &[Vec3], q: Vec3, m: usize) -> &[(f32, u32)] {
        self.queries += 1;
        self.found.clear();
        let Some(mq) = NonZero::new(m) else {
            return &self.found;
        };
        let q = q.to_array();
        // The candidates are `keys[..len]` (`keys` is kept as long as the
        // cache, not cleared and refilled each query).
        let mut len = 0;
        let ahead = self.ahead.take();
        if self.bound.is_finite() {
            let r = self.bound.sqrt();
            if !self.cache.off && !self.cache.holds(q, r) {
                let reach = cache_reach(m);
                let centre = ahead.map_or(q, |a| towards(q, a, reach, r));
                self.cache.fill(tree, points, centre, reach, r);
            }
            if self.cache.off {
                self.keys.clear();
                self.keys.extend(
                    tree.within_unsorted::<SquaredEuclidean>(&q, self.bound)
                        .into_iter()
                        .map(|f| key(f.distance, f.item)),
                );
                len = self.keys.len();
            } else {
                if self.keys.len() < self.cache.items.len() + 8 {
                    self.keys.resize(self.cache.items.len() + 8, 0);
                }
                len = self.cache.within(q, self.bound, &mut self.keys);
            }
        }
        if len < m {
            // Too few within the bound: the m nearest found without one,
            // then every point as near as the m-th (its ties, which
            // `nearest_n` breaks in no fixed order).
            let reach = tree
                .nearest_n::<SquaredEuclidean>(&q, mq)
                .last()
                .map_or(0.0, |f| f.distance);
            self.keys.clear();
            self.keys.extend(
                tree.within_unsorted::<SquaredEuclidean>(&q, reach)
                    .into_iter()
                    .map(|f| key(f.distance, f.item)),
            );
            len = self.keys.len();
        }
        let keys = &mut self.keys[..len];
        let isa = self.cache.isa;
        if len > m && crate::simd::same_network(len, m, isa) {
            // All the candidates fit the network the `m` kept would take:
            // sorting them all costs that sort alone, and the `m` least
            // are its first `m` (the same keys, in the same order).
            crate::simd::sort_keys(keys, isa);
            self.whole_sorts += 1;
        } else {
            if len > m {
                // The previous query's m-th (the bound less its growth)
                // lies close to this one's: split there first.
                least_first(keys, m, key(self.bound / BOUND_GROWTH_SQ, u32::MAX));
            }
            crate::simd::sort_keys(&mut keys[..len.min(m)], isa);
        }
        let keys = &keys[..len.min(m)];
        self.found.extend(
            keys.iter()
                .map(|&k| (f32::from_bits((k >> 32) as u32), k as u32)),
        );
        let last = self.found.last().map_or(0.0, |f| f.0);
        self.bound = if last > 0.0 {
            BOUND_GROWTH_SQ * last
        } else {
            f32::INFINITY
        };
        &self.found
    }
}

/// The `m` least of `keys` (more than `m`; `m` at least 1) moved to
/// its front, in no order: split first at `pivot` without a branch (a
/// guess at the `m`-th), then selected among the few on the wrong side of
/// it. Against `select_nth_unstable` alone: 0.95x the CPU of the 2M bunny
/// sample's graph (docs/notes/generation.md, "twelfth session").
fn least_first(keys: &mut [u64], m: usize, pivot: u64) {
    let mut below = 0;
    for i in 0..keys.len() {
        let k = keys[i];
        keys.swap(i, below);
        below += usize::from(k <= pivot);
    }
    match below.cmp(&m) {
        std::cmp::Ordering::Greater => {
            keys[..below].select_nth_unstable(m - 1);
        }
        std::cmp::Ordering::Less => {
            keys[below..].select_nth_unstable(m - below - 1);
        }
        std::cmp::Ordering::Equal => {}
    }
}

/// A found point as one integer ordered as (squared distance, index): a
/// squared distance is never negative, and non-negative floats order as
/// their bits do (`total_cmp`'s order), so one integer compare sorts them.
fn key(distance: f32, item: u32) -> u64 {
    debug_assert!(distance.is_sign_positive());
    (u64::from(distance.to_bits()) << 32) | u64::from(item)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The `m` nearest of `pts` to `p` by sorting them all, ties by index.
    fn brute_nearest(pts: &[Vec3], p: Vec3, m: usize) -> Vec<u32> {
        let mut all: Vec<(f32, u32)> = pts
            .iter()
            .enumerate()
            .map(|(j, q)| (p.distance_squared(*q), j as u32))
            .collect();
        all.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        all[..m].iter().map(|f| f.1).collect()
    }

    /// The bounded queries of [`Nearest`] find exactly the `m` nearest, ties
    /// by index, whether the bound held enough points or the unbounded
    /// query ran: checked against a brute-force sort on a cloud with a
    /// dense patch, a sparse one, a line and exact duplicated distances.
    #[test]
    fn nearest_finds_exactly_the_m_nearest() {
        let mut pts = Vec::new();
        for i in 0..40 {
            for j in 0..40 {
                pts.push(Vec3::new(i as f32 * 0.01, j as f32 * 0.01, 0.0));
            }
        }
        for i in 0..300 {
            let t = i as f32;
            pts.push(Vec3::new(
                1.0 + (t * 0.37).sin(),
                2.0 + (t * 0.11).cos(),
                t * 0.01,
            ));
        }
        for i in 0..100 {
            pts.push(Vec3::new(5.0 + i as f32 * 0.2, 5.0, 5.0));
        }
        let tree = build_tree(&pts);
        let mut near = Nearest::new();
        let mut bounded = 0;
        for m in [1usize, 13, 40, 49, 120] {
            let whole_before = near.whole_sorts;
            for (i, &p) in pts.iter().enumerate() {
                let had_bound = near.bound.is_finite();
                let got: Vec<(f32, u32)> = near.query(&tree, &pts, p, m).to_vec();
                bounded += usize::from(had_bound);
                let ids: Vec<u32> = got.iter().map(|f| f.1).collect();
                assert_eq!(ids, brute_nearest(&pts, p, m), "point {i}, m = {m}");
            }
            // Where the candidates fit the network of the `m` kept, they
            // were sorted whole, without a selection (measured on AVX2, of
            // the 2,000 queries: 1,825 for m = 40, 441 for m = 49); never
            // for the other m.
            let whole = near.whole_sorts - whole_before;
            if crate::simd::same_network(m + 8, m, near.cache.isa) {
                let least = if m == 40 { 1_650 } else { 380 };
                assert!(whole >= least, "m = {m}: {whole}");
            } else {
                assert_eq!(whole, 0, "m = {m}");
            }
        }
        // Most queries took the bound of the one before, and most of
        // those were served by the cached ball (measured: FILLS of them
        // filled it).
        assert!(bounded * 2 > 4 * pts.len(), "{bounded}");
        assert!(near.cache.fills * 4 < bounded, "{} of {bounded}", near.cache.fills);
        // Points that are not the tree's turn the cache off, and the
        // answers are still exact (from the tree).
        let moved: Vec<Vec3> = pts.iter().map(|p| *p + Vec3::X).collect();
        let mut near = Nearest::new();
        for (i, &p) in pts.iter().enumerate().take(200) {
            let got: Vec<u32> = near.query(&tree, &moved, p, 13).iter().map(|f| f.1).collect();
            assert_eq!(got, brute_nearest(&pts, p, 13), "point {i}, points not the tree's");
        }
        assert!(near.cache.off);
    }

    /// A cached ball's query ([`Cache::within`], scanning only the shells
    /// its ball reaches) finds every cached point within the bound, and
    /// only those, against a scan of the whole cache: on a lattice (points
    /// exactly on the bound and on shell boundaries) and scattered points,
    /// balls round many centres and queries anywhere inside them. The
    /// shells skip most of the cache (the test fails if they stop to).
    #[test]
    fn cached_shells_miss_no_point_within_the_bound() {
        let mut lattice = Vec::new();
        for i in -12..=12 {
            for j in -12..=12 {
                for k in -2..=2 {
                    lattice.push(Vec3::new(i as f32, j as f32, k as f32) * 0.25);
                }
            }
        }
        let scattered = scattered(0x9e37_79b9, 4000, Vec3::new(6.0, 6.0, 0.5), 0.5);
        let (mut scanned, mut cached) = (0usize, 0usize);
        for pts in [lattice, scattered] {
            let tree = build_tree(&pts);
            let mut keys = vec![0u64; pts.len() + 8];
            for c in 0..12 {
                let centre = pts[c * pts.len() / 12].to_array();
                let mut cache = Cache::default();
                cache.fill(&tree, &pts, centre, 2.5, 0.5);
                assert!(!cache.off);
                for t in 0..200 {
                    let (r, a) = (0.5 * (1.0 + t as f32 / 200.0) / 2.0, t as f32 * 0.37);
                    let q = [
                        centre[0] + 0.7 * r * a.cos() * (t % 7) as f32 / 6.0,
                        centre[1] + 0.7 * r * a.sin() * (t % 5) as f32 / 4.0,
                        centre[2],
                    ];
                    // Bounds that fall exactly on lattice distances too.
                    for bound in [r * r, 0.0625, 0.125, 0.25] {
                        if !cache.holds(q, bound.sqrt()) {
                            continue;
                        }
                        let mut want: Vec<u64> = (0..cache.items.len())
                            .map(|j| {
                                let p = [cache.x[j], cache.y[j], cache.z[j]];
                                (dist_sq(p, q), cache.items[j])
                            })
                            .filter(|&(d, _)| d <= bound)
                            .map(|(d, j)| key(d, j))
                            .collect();
                        let len = cache.within(q, bound, &mut keys);
                        let mut got = keys[..len].to_vec();
                        got.sort_unstable();
                        want.sort_unstable();
                        assert_eq!(got, want, "centre {c}, query {t}, bound {bound}");
                        scanned += cache.reach_of(q, bound).len();
                        cached += cache.items.len();
                    }
                }
            }
        }
        assert!(scanned * 10 < cached * 8, "{scanned} of {cached}");
    }

    /// [`least_first`] moves the `m` least keys to the front whatever its
    /// pivot: below all, above all, inside and on a key, with repeated
    /// distances; and a cache centred ahead ([`Nearest::look_ahead`])
    /// answers the same as one centred on each query, with fewer fills.
    #[test]
    fn the_least_come_first_and_look_ahead_changes_no_answer() {
        let mut s = 0x5851_f42d_u64;
        for len in [2usize, 13, 50, 70, 200] {
            let keys: Vec<u64> = (0..len)
                .map(|i| {
                    s ^= s << 13;
                    s ^= s >> 7;
                    s ^= s << 17;
                    key((s % 17) as f32 * 0.25, i as u32)
                })
                .collect();
            let mut sorted = keys.clone();
            sorted.sort_unstable();
            for m in (1..len).step_by(7) {
                for pivot in [0, u64::MAX, sorted[m - 1], sorted[m], sorted[len / 2], sorted[0] + 1] {
                    let mut got = keys.clone();
                    least_first(&mut got, m, pivot);
                    got[..m].sort_unstable();
                    assert_eq!(got[..m], sorted[..m], "len {len}, m {m}, pivot {pivot}");
                }
            }
        }
        let pts = scattered(0x1405_7b7e, 3000, Vec3::new(1.0, 1.0, 0.02), 0.0);
        let order = morton_order(&pts);
        let pts: Vec<Vec3> = order.iter().map(|&i| pts[i as usize]).collect();
        let tree = build_tree(&pts);
        let (mut plain, mut ahead) = (Nearest::new(), Nearest::new());
        for (i, &p) in pts.iter().enumerate() {
            let want = plain.query(&tree, &pts, p, 49).to_vec();
            ahead.look_ahead(pts[(i + AHEAD).min(pts.len() - 1)]);
            assert_eq!(ahead.query(&tree, &pts, p, 49), &want[..], "point {i}");
        }
        assert!(ahead.cache.fills < plain.cache.fills, "{} {}", ahead.cache.fills, plain.cache.fills);
    }

    /// A `w × h` grid of spacing 0.5 in `z = 0`, row by row (most
    /// distances tie).
    /// `n` points of a xorshift sequence from `seed`: each coordinate a
    /// step in `[0, 1)` less `shift`, times `scale`'s.
    fn scattered(seed: u64, n: usize, scale: Vec3, shift: f32) -> Vec<Vec3> {
        let mut s = seed;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32 - shift
        };
        (0..n)
            .map(|_| Vec3::new(scale.x * next(), scale.y * next(), scale.z * next()))
            .collect()
    }

    fn grid(w: usize, h: usize) -> Vec<Vec3> {
        (0..w)
            .flat_map(|i| (0..h).map(move |j| Vec3::new(i as f32 * 0.5, j as f32 * 0.5, 0.0)))
            .collect()
    }

    /// A graph repaired around dropped points ([`Knn::retain`]) is the
    /// graph built over the points left, bit for bit, on a grid (where
    /// most distances tie) and a scattered cloud, with single points, a
    /// block and every third point dropped; and only the points that had a
    /// dropped neighbour are queried again.
    #[test]
    fn a_repaired_graph_is_the_graph_built_without_the_dropped() {
        let grid = grid(30, 30);
        let scattered = scattered(0x2545_f491, 1500, Vec3::new(1.0, 1.0, 0.1), 0.0);
        for pts in [grid, scattered] {
            let n = pts.len();
            let drops: [Vec<bool>; 3] = [
                (0..n).map(|i| i == 7 || i == n / 2).collect(),
                (0..n).map(|i| (200..260).contains(&i)).collect(),
                (0..n).map(|i| i % 3 == 0).collect(),
            ];
            let all = Knn::build(&build_tree(&pts), &pts, 12);
            for drop in drops {
                let keep: Vec<bool> = drop.iter().map(|&d| !d).collect();
                let left: Vec<Vec3> = (0..n).filter(|&i| keep[i]).map(|i| pts[i]).collect();
                let tree = build_tree(&left);
                let want = Knn::build(&tree, &left, 12);
                let mut got = all.clone();
                got.retain(&keep, &tree, &left);
                assert_eq!(got.idx, want.idx);
                assert_eq!(got.kth_distance, want.kth_distance);
                let touched = (0..n)
                    .filter(|&i| keep[i] && all.of(i).iter().any(|&j| drop[j as usize]))
                    .count();
                assert_eq!(got.queries, touched);
                assert_eq!(want.queries, left.len());
                // With the tree built beside the rows' move: the same
                // graph, the same queries, and a tree as the one built
                // alone.
                let mut beside = all.clone();
                let built = beside.retain_building(&keep, &left);
                assert_eq!(beside.idx, want.idx);
                assert_eq!(beside.kth_distance, want.kth_distance);
                assert_eq!(beside.queries, touched);
                assert!(built == tree);
            }
        }
    }

    /// One query a point gives the graph and the wide rows
    /// ([`Knn::build_wide`]): the graph is [`Knn::build`]'s bit for bit,
    /// each wide row the point's `m` nearest (itself among them) by a
    /// brute-force sort, ties by index; the graph widened to `m - 1` from
    /// the rows is [`Knn::build`]'s at `m - 1` without a query; repaired
    /// around dropped points, both are the ones built over the points
    /// left, and only the points whose wide row held a dropped one are
    /// queried again; rows kept for some points are theirs.
    #[test]
    fn the_wide_rows_hold_the_graph() {
        let scattered = scattered(0x853c_49e6, 1200, Vec3::new(1.0, 1.0, 0.1), 0.0);
        let bits = |k: &Knn| k.kth_distance.iter().map(|d| d.to_bits()).collect::<Vec<_>>();
        let row = |k: &Knn, i: usize, m: usize| {
            let mut out = Vec::new();
            k.wide_into(i, m, &mut out).then_some(out)
        };
        for pts in [grid(30, 30), scattered] {
            let n = pts.len();
            let tree = build_tree(&pts);
            let plain = Knn::build(&tree, &pts, 12);
            let wide = Knn::build_wide(&tree, &pts, 12, 49);
            assert_eq!(wide.idx, plain.idx);
            assert_eq!(bits(&wide), bits(&plain));
            assert_eq!(wide.queries, n);
            for (i, &p) in pts.iter().enumerate() {
                assert_eq!(row(&wide, i, 49).unwrap(), brute_nearest(&pts, p, 49));
            }
            assert!(row(&wide, 0, 48).is_none() && row(&plain, 0, 49).is_none());
            let widened = wide.widened(48, &tree, &pts);
            let want = Knn::build(&tree, &pts, 48);
            assert_eq!(widened.idx, want.idx);
            assert_eq!(bits(&widened), bits(&want));
            assert_eq!(widened.queries, 0);
            for drop in [
                (0..n).map(|i| i == 7 || i == n / 2).collect::<Vec<bool>>(),
                (0..n).map(|i| i % 3 == 0).collect(),
            ] {
                let keep: Vec<bool> = drop.iter().map(|&d| !d).collect();
                let left: Vec<Vec3> = (0..n).filter(|&i| keep[i]).map(|i| pts[i]).collect();
                let tree = build_tree(&left);
                let want = Knn::build_wide(&tree, &left, 12, 49);
                let mut got = wide.clone();
                got.retain(&keep, &tree, &left);
                assert_eq!(got.idx, want.idx);
                assert_eq!(bits(&got), bits(&want));
                for i in 0..left.len() {
                    assert_eq!(row(&got, i, 49), row(&want, i, 49), "{i}");
                }
                let mut beside = wide.clone();
                assert!(beside.retain_building(&keep, &left) == tree);
                assert_eq!(beside.idx, want.idx);
                assert_eq!(bits(&beside), bits(&want));
                for i in 0..left.len() {
                    assert_eq!(row(&beside, i, 49), row(&want, i, 49), "{i}");
                }
                let touched = (0..n)
                    .filter(|&i| keep[i] && row(&wide, i, 49).unwrap().iter().any(|&j| drop[j as usize]))
                    .count();
                assert_eq!(got.queries, touched);
            }
            let mut some = wide.clone();
            some.keep_wide(|i| i % 5 == 1);
            for i in 0..n {
                let want = row(&wide, i, 49).filter(|_| i % 5 == 1);
                assert_eq!(row(&some, i, 49), want, "{i}");
            }
            // Kept for some points only: widened by queries.
            assert_eq!(some.widened(48, &tree, &pts).queries, n);
        }
    }

    /// The graph holds each point's `k` nearest others, nearest first and
    /// ties by index (on a grid, where most distances tie), whatever order
    /// the tree keeps them in; and the k-th one's distance.
    #[test]
    fn the_graph_breaks_ties_by_index() {
        let pts = grid(30, 30);
        let tree = build_tree(&pts);
        let knn = Knn::build(&tree, &pts, 12);
        for (i, &p) in pts.iter().enumerate() {
            let mut all: Vec<(f32, u32)> = pts
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(j, q)| (p.distance_squared(*q), j as u32))
                .collect();
            all.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let want: Vec<u32> = all[..12].iter().map(|f| f.1).collect();
            assert_eq!(knn.of(i), &want[..], "point {i}");
            assert_eq!(knn.kth_distance[i], all[11].0.sqrt(), "point {i}");
        }
    }

    #[test]
    fn a_graph_queried_in_any_order_is_the_graph() {
        // A grid (distances tie everywhere) in row order, and scattered
        // noisy points along scan lines.
        let grid = grid(40, 25);
        let mut state = 12345u64;
        let mut r = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let lines: Vec<Vec3> = (0..1500)
            .map(|i| {
                let (a, b) = ((i % 60) as f32 * 0.03, (i / 60) as f32 * 0.1);
                Vec3::new(a.cos() * (2.0 + 0.01 * r()), b, a.sin() * 2.0 + 0.01 * r())
            })
            .collect();
        for pts in [grid, lines] {
            let tree = build_tree(&pts);
            let want = Knn::build(&tree, &pts, 12);
            let mut reversed: Vec<u32> = (0..pts.len() as u32).collect();
            reversed.reverse();
            let morton = morton_order(&pts);
            let mut sorted = morton.clone();
            sorted.sort_unstable();
            assert!(sorted.iter().enumerate().all(|(i, &j)| j as usize == i));
            assert_ne!(morton, (0..pts.len() as u32).collect::<Vec<_>>());
            for order in [&morton, &reversed] {
                let got = Knn::build_in_order(&tree, &pts, 12, order);
                assert_eq!(got.idx, want.idx);
                let bits = |k: &Knn| k.kth_distance.iter().map(|d| d.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&got), bits(&want));
                assert_eq!(got.queries, want.queries);
            }
        }
    }
}
