//! Thinning a cloud sampled far more densely than `ϵ` needs.
//!
//! Splat growth (§2.1) stops a splat where its points leave the `ϵ` slab,
//! so the splats a surface gets depend on `ϵ`, not on how many points
//! sample it: 10M and 100M samples of the bunny give about the same splats.
//! What the extra points cost (neighbour search, normals, growth, each per
//! point) buys nothing. Space is cut into cubic cells `CELL_EPS` `ϵ` wide,
//! aligned to the coordinates' zero (so a tile of a cloud and the whole
//! cloud cut alike), and a cell holding several points keeps one: the point
//! nearest their centroid (the lowest index on a tie). A cell of one point
//! keeps it. A kept point is an input point, with its normal, colour and
//! scanner.
//!
//! With `CELL_EPS` = 0.5 a splat of the mean radius (about 3.6 `ϵ` on the
//! bunny) still takes about 160 points, against the 8 of the bundled
//! scene's 200k samples.

use glam::DVec3;
use rayon::prelude::*;

/// Cell width in `ϵ`.
pub const CELL_EPS: f64 = 0.5;

/// The finest cell width in `ϵ` of the thinning a cloud gets unasked
/// ([`typical_cell_counts`]): the cells tried are this, twice and four
/// times it ([`AUTO_LEVELS`]). At 100M points sampled from the bunny mesh,
/// thinning at 0.25 `ϵ` cost nothing against the mesh (31.93 → 31.99 dB).
pub const AUTO_CELL_EPS: f64 = 0.25;

/// How many cell widths the unasked rule tries: [`AUTO_CELL_EPS`] `ϵ`
/// doubled each level, 0.25, 0.5 and 1 `ϵ`.
pub const AUTO_LEVELS: usize = 3;

/// A cloud is thinned unasked at the widest of the [`AUTO_LEVELS`] cells
/// whose cell around a typical point holds at least this many points and
/// that [`AUTO_WIDE_EPS_REL`] allows (and not at all when none does).
///
/// Why the widest: growth (§2.1, eq. 1) stops a splat where its points leave
/// the `ϵ` slab, and the density rule (§2.2) seeds by coverage, so what a
/// splat needs of its points is that they sample its disc, whose radius is
/// several `ϵ` (3.9 `ϵ` on average on the bunny, up to
/// [`super::grow::MAX_RADIUS_EPS`]): one point per cell 1 `ϵ` wide still
/// gives a splat of the mean radius about 48 points, four times the
/// `k` = 12 its normals and field are fitted from. A cell holding 8 or
/// more keeps an eighth or less. Measured against the meshes and the
/// surveys' exact surfaces, close views included (`docs/notes/generation.md`,
/// "Issue 54, twenty-first session"), every view gained: the 2M bunny
/// sample (a typical cell 1, 3 and 9 points at 0.25, 0.5, 1 `ϵ`: thinned
/// at 1 `ϵ`) 1.3–1.5 dB, normal error 2.21° → 1.55°; the 3.6M survey (2,
/// 8, 29) 0.4–1.2 dB; 10M bunny samples with noise 0.08 `ϵ` (2, 10, 43)
/// 1.3–2.6 dB, normal error 2.60° → 1.51°: twelve neighbours a third of
/// `ϵ` apart fit normals to a patch far smaller than a splat. Clouds whose
/// typical 1 `ϵ` cell holds fewer than [`AUTO_POINTS_WIDEST`] are left
/// whole.
pub const AUTO_POINTS: usize = 8;

/// The widest cell, 1 `ϵ`, needs only this many points in a typical
/// point's cell, not [`AUTO_POINTS`]: a kept point per `ϵ`² still gives a
/// splat of the mean radius about 48 points (see [`AUTO_POINTS`]), so what
/// bounds the count is where the grid's one-a-cell kept set is no better
/// than the cloud. Measured against the meshes, close views included
/// (`docs/notes/generation.md`, "Issue 54, twenty-second session"): 1M
/// bunny samples (5 a cell) gained at every view (+0.94 / +1.25 / +0.20 dB,
/// normal error 2.03° → 1.55°), 2M with noise 0.31 `ϵ` (7) +0.79 to +2.05
/// dB; at 4 a scan of a gable block (raster, densest near the scanner)
/// lost 0.21 dB from the scanner and its eave's seam grew 608 → 677
/// pixels; at 3 the 450k bunny gained and the default survey moved ±0.05
/// dB; at 2 the far view lost (300k bunny −0.39 dB, the 200k −0.12 dB).
/// So 5: the 200k bunny, the default survey, the scans and the solids'
/// 300k samples are left whole.
pub const AUTO_POINTS_WIDEST: usize = 5;

/// A cell wider than [`AUTO_CELL_EPS`] `ϵ`, `c ϵ`, is tried only where
/// `c²` times `ϵ` relative to the diagonal (`epsilon_rel`) is at most this,
/// the default `ϵ`'s: growth (§2.1, eq. 1) stops a splat where a surface of
/// curvature radius `R` leaves the `ϵ` slab, about `√(2Rϵ)` from its
/// centre, so a splat holds about `2πR / (c² ϵ)` of the points kept one a
/// cell, fewer as `c² ϵ` grows. The wider cells were measured at the
/// default `ϵ` (where every view gained); a sweep of 50,000 bunny points
/// at `ϵ` 0.05 of the diagonal, thinned at 1 `ϵ`, grew 166 splats with a
/// Phong normal error of 7.7° against 454 and 5.8° thinned at 0.25 `ϵ`
/// (`tests/sweep.rs`). So 1 `ϵ` at the default, 0.5 `ϵ` up to 0.008, the
/// finest alone past that.
pub const AUTO_WIDE_EPS_REL: f32 = 0.002;

/// How many points a typical point's cell must hold for the unasked rule
/// to thin at each of [`typical_cell_counts`]' widths: [`AUTO_POINTS`] at
/// the finer, [`AUTO_POINTS_WIDEST`] at 1 `ϵ`.
pub const AUTO_POINTS_AT: [usize; AUTO_LEVELS] = [AUTO_POINTS, AUTO_POINTS, AUTO_POINTS_WIDEST];

/// The cell width in `ϵ` to thin at unasked, of [`typical_cell_counts`]'
/// widths, and the count ([`AUTO_POINTS_AT`]) its typical cell reached:
/// the widest whose typical cell holds that many or more and that
/// [`AUTO_WIDE_EPS_REL`] allows at `epsilon_rel`; `None` when none does.
#[must_use]
pub fn auto_cell(held: &[usize; AUTO_LEVELS], epsilon_rel: f32) -> Option<(f64, usize)> {
    let width = |l: usize| AUTO_CELL_EPS * f64::from(1u32 << l);
    let allowed =
        |l: usize| l == 0 || width(l).powi(2) * f64::from(epsilon_rel) <= f64::from(AUTO_WIDE_EPS_REL);
    (0..AUTO_LEVELS)
        .rev()
        .find(|&l| held[l] >= AUTO_POINTS_AT[l] && allowed(l))
        .map(|l| (width(l), AUTO_POINTS_AT[l]))
}

/// Points sampled by [`typical_cell_counts`].
const SAMPLE: usize = 4096;

/// How many points the cell around a typical point of `indices` holds (the
/// point itself included), for cells `cell`, 2 `cell`, 4 `cell`, …
/// ([`AUTO_LEVELS`] widths) wide: at each width the median over about
/// [`SAMPLE`] points taken at even steps through `indices`, each counted
/// against every point. One pass over the points: the cells are aligned
/// to the coordinates' zero, so a cell twice as wide holds whole cells of
/// the finer width (a coarser key is the finer one halved, `>> 1`, exactly:
/// `x / (2w)` is `(x / w) / 2` in floating point), and a point outside
/// every sampled widest cell, most points, costs one binary search.
///
/// The count is a sum, so the pass reads the points in the order of their
/// indices (`member`: [`members`] of `indices`), not in `indices`' own: a
/// cloud's points in Morton order are scattered through memory as read,
/// and that pass's loads missed the cache (10 % of the graph stage of the
/// 2M bunny sample, docs/notes/generation.md, "fourteenth session").
#[must_use]
pub fn typical_cell_counts(
    indices: &[u32],
    member: &[bool],
    world: impl Fn(u32) -> DVec3 + Sync,
    cell: f64,
) -> [usize; AUTO_LEVELS] {
    if !(cell.is_finite() && cell > 0.0) || indices.is_empty() {
        return [0; AUTO_LEVELS];
    }
    let key = |i: u32| cell_of(world(i), cell);
    let stride = indices.len().div_ceil(SAMPLE).max(1);
    let fine: Vec<[i64; 3]> = indices.iter().step_by(stride).map(|&i| key(i)).collect();
    let probes: Vec<Vec<[i64; 3]>> = (0..AUTO_LEVELS)
        .map(|l| {
            let mut p: Vec<[i64; 3]> = fine.iter().map(|&k| coarser(k, l)).collect();
            p.sort_unstable();
            p.dedup();
            p
        })
        .collect();
    const CHUNK: usize = 1 << 14;
    let zero = || probes.iter().map(|p| vec![0usize; p.len()]).collect::<Vec<_>>();
    let counts = member
        .par_chunks(CHUNK)
        .enumerate()
        .map(|(c, chunk)| {
            let mut counts = zero();
            for (j, _) in chunk.iter().enumerate().filter(|e| *e.1) {
                let k = key((c * CHUNK + j) as u32);
                // Widest first: a point outside a sampled cell is outside
                // every sampled cell it holds.
                for l in (0..AUTO_LEVELS).rev() {
                    match probes[l].binary_search(&coarser(k, l)) {
                        Ok(at) => counts[l][at] += 1,
                        Err(_) => break,
                    }
                }
            }
            counts
        })
        .reduce(zero, |mut a, b| {
            for (x, y) in a.iter_mut().zip(b) {
                x.iter_mut().zip(y).for_each(|(x, y)| *x += y);
            }
            a
        });
    std::array::from_fn(|l| {
        let mut held: Vec<usize> = (fine.iter())
            .map(|&k| counts[l][probes[l].binary_search(&coarser(k, l)).unwrap_or(0)])
            .collect();
        let mid = held.len() / 2;
        *held.select_nth_unstable(mid).1
    })
}

/// The key of the cell `2^level` times as wide holding cell `k`.
fn coarser(k: [i64; 3], level: usize) -> [i64; 3] {
    k.map(|c| c >> level)
}

/// Which of `len` points `indices` (distinct, each below `len`) names: the
/// same points as a mask, to read them in memory order.
#[must_use]
pub fn members(indices: &[u32], len: usize) -> Vec<bool> {
    let mut member = vec![false; len];
    for &i in indices {
        member[i as usize] = true;
    }
    member
}

/// Bits per axis of a packed cell key.
const KEY_BITS: u32 = 21;

/// The cell `cell` wide holding `p` (cells aligned to the coordinates'
/// zero).
fn cell_of(p: DVec3, cell: f64) -> [i64; 3] {
    let c = (p / cell).floor();
    [c.x as i64, c.y as i64, c.z as i64]
}

/// Which of `indices` to keep: `keep[i]` for every `i` in `indices` (the
/// positions `world(i)` in the cloud's coordinates, f64), cutting space into
/// cells `cell` wide. `None` when nothing would be thinned, or when the
/// cloud spans more than 2^21 cells along an axis (too fine to key; it is
/// then left as it is).
#[must_use]
pub fn keep(
    indices: &[u32],
    len: usize,
    world: impl Fn(u32) -> DVec3 + Sync,
    cell: f64,
) -> Option<Vec<bool>> {
    if !(cell.is_finite() && cell > 0.0) || indices.len() < 2 {
        return None;
    }
    let cells: Vec<[i64; 3]> = indices
        .par_iter()
        .map(|&i| cell_of(world(i), cell))
        .collect();
    let mut lo = [i64::MAX; 3];
    let mut hi = [i64::MIN; 3];
    for c in &cells {
        for a in 0..3 {
            lo[a] = lo[a].min(c[a]);
            hi[a] = hi[a].max(c[a]);
        }
    }
    if (0..3).any(|a| hi[a] - lo[a] >= 1 << KEY_BITS) {
        return None;
    }
    let mut keyed: Vec<(u64, u32)> = cells
        .par_iter()
        .zip(indices.par_iter())
        .map(|(c, &i)| {
            let k = (0..3).fold(0u64, |k, a| k << KEY_BITS | (c[a] - lo[a]) as u64);
            (k, i)
        })
        .collect();
    drop(cells);
    keyed.par_sort_unstable();
    if keyed.windows(2).all(|w| w[0].0 != w[1].0) {
        return None;
    }
    let mut keep = vec![false; len];
    let mut start = 0;
    while start < keyed.len() {
        let key = keyed[start].0;
        let end = start + keyed[start..].partition_point(|e| e.0 == key);
        if end - start == 1 {
            keep[keyed[start].1 as usize] = true;
        } else {
            let run = &keyed[start..end];
            let centroid = run.iter().map(|e| world(e.1)).sum::<DVec3>() / (end - start) as f64;
            // Sorted by index within the run: `<` keeps the lowest on a tie.
            let mut best = (f64::INFINITY, run[0].1);
            for e in run {
                let d = world(e.1).distance_squared(centroid);
                if d < best.0 {
                    best = (d, e.1);
                }
            }
            keep[best.1 as usize] = true;
        }
        start = end;
    }
    Some(keep)
}

#[cfg(test)]
mod tests {
    use super::keep;
    use glam::DVec3;

    #[test]
    fn one_point_a_cell_the_nearest_its_centroid() {
        // Cell 1 wide. Cell (0,0,0): three points, centroid (0.5, 0.5, 0.5):
        // index 1 is nearest. Cell (5,0,0): one point. Cell (-1,0,0): two
        // at the same distance from their centroid: the lower index.
        let p = [
            DVec3::new(0.1, 0.1, 0.1),
            DVec3::new(0.45, 0.5, 0.55),
            DVec3::new(0.95, 0.9, 0.85),
            DVec3::new(5.5, 0.5, 0.5),
            DVec3::new(-0.9, 0.5, 0.5),
            DVec3::new(-0.1, 0.5, 0.5),
        ];
        let idx: Vec<u32> = (0..p.len() as u32).collect();
        let k = keep(&idx, p.len(), |i| p[i as usize], 1.0).unwrap();
        assert_eq!(k, [false, true, false, true, true, false]);
        // Far from zero, the same cells relative to each other.
        let far: Vec<DVec3> = p
            .iter()
            .map(|q| *q + DVec3::new(4.0e6, -3.0e5, 7.0))
            .collect();
        let k2 = keep(&idx, p.len(), |i| far[i as usize], 1.0).unwrap();
        assert_eq!(k, k2);
    }

    #[test]
    fn wider_cells_are_tried_only_where_epsilon_is_fine_enough() {
        use super::auto_cell;
        // The 2M bunny sample at the default ϵ: 1, 3 and 9 a cell.
        assert_eq!(auto_cell(&[1, 3, 9], 0.002).map(|c| c.0), Some(1.0));
        // 2M bunny samples with noise 0.31 ϵ (1, 2, 7) and 1M clean ones
        // (1, 2, 5) at 1 ϵ; the gable scan (1, 2, 4), the default survey
        // (1, 1, 3) and the 200k bunny (1, 1, 2) whole.
        assert_eq!(auto_cell(&[1, 2, 7], 0.002).map(|c| c.0), Some(1.0));
        assert_eq!(auto_cell(&[1, 2, 5], 0.002), Some((1.0, 5)));
        assert_eq!(auto_cell(&[1, 2, 4], 0.002), None);
        assert_eq!(auto_cell(&[1, 1, 3], 0.002), None);
        // Coarser ϵ keeps 1 ϵ out whatever the count.
        assert_eq!(auto_cell(&[1, 2, 7], 0.004), None);
        assert_eq!(auto_cell(&[1, 8, 30], 0.004), Some((0.5, 8)));
        assert_eq!(auto_cell(&[8, 30, 100], 0.001).map(|c| c.0), Some(1.0));
        // Coarser ϵ: 0.5 ϵ up to 0.008, then the finest alone.
        assert_eq!(auto_cell(&[8, 30, 100], 0.004).map(|c| c.0), Some(0.5));
        assert_eq!(auto_cell(&[8, 30, 100], 0.008).map(|c| c.0), Some(0.5));
        assert_eq!(auto_cell(&[8, 30, 100], 0.0081).map(|c| c.0), Some(0.25));
        assert_eq!(auto_cell(&[8, 30, 100], 0.05).map(|c| c.0), Some(0.25));
        assert_eq!(auto_cell(&[7, 30, 100], 0.05), None);
    }

    #[test]
    fn a_typical_cell_is_counted() {
        use super::{AUTO_LEVELS, members, typical_cell_counts};
        // A 100 x 100 grid 0.1 apart in cells 1 wide: 100 points a cell;
        // cells 2 wide hold 400; cells 4 wide 40 x 40 where both axes fall
        // in [0, 4) or [4, 8) (64 % of the points), fewer past 8: a typical
        // point's holds 1600. Cells 0.05 wide hold one point, 0.1 one, 0.2
        // two by two.
        let grid: Vec<DVec3> = (0..10_000)
            .map(|i| DVec3::new((i % 100) as f64 * 0.1 + 0.05, (i / 100) as f64 * 0.1 + 0.05, 0.5))
            .collect();
        let idx: Vec<u32> = (0..grid.len() as u32).collect();
        let all = members(&idx, idx.len());
        assert_eq!(typical_cell_counts(&idx, &all, |i| grid[i as usize], 1.0), [100, 400, 1600]);
        assert_eq!(typical_cell_counts(&idx, &all, |i| grid[i as usize], 0.05), [1, 1, 4]);
        // Three quarters of the points in one cell: it is the typical one.
        let mut lumped = grid.clone();
        for p in lumped.iter_mut().take(7_500) {
            *p = DVec3::new(0.5, 0.5, 0.5) + (*p - DVec3::new(5.0, 5.0, 0.5)) * 1e-3;
        }
        assert_eq!(typical_cell_counts(&idx, &all, |i| lumped[i as usize], 1.0)[0], 7_500);
        assert_eq!(typical_cell_counts(&[], &[], |i| grid[i as usize], 1.0), [0; AUTO_LEVELS]);
        // Some of the points, scattered through memory (a stride of 7 mod
        // the length), some cells straddling zero: the count is over those
        // only, at every width, as a brute-force count of each sampled
        // point's cell finds it.
        let shifted: Vec<DVec3> = lumped.iter().map(|p| *p - DVec3::new(3.3, 2.2, 0.0)).collect();
        let some: Vec<u32> = (0..6_000u32).map(|i| i * 7 % 10_000).collect();
        for cloud in [&lumped, &shifted] {
            for cell in [0.35, 1.0, 2.5] {
                let got = typical_cell_counts(&some, &members(&some, cloud.len()), |i| cloud[i as usize], cell);
                for (level, got) in got.into_iter().enumerate() {
                    let width = cell * f64::from(1u32 << level);
                    let key = |i: u32| (cloud[i as usize] / width).floor();
                    let stride = some.len().div_ceil(super::SAMPLE);
                    let mut held: Vec<usize> = (some.iter().step_by(stride))
                        .map(|&s| some.iter().filter(|&&i| key(i) == key(s)).count())
                        .collect();
                    let mid = held.len() / 2;
                    let want = *held.select_nth_unstable(mid).1;
                    assert_eq!(got, want, "cell {cell}, level {level}");
                }
            }
        }
    }

    #[test]
    fn nothing_to_thin_is_none() {
        let p = [
            DVec3::ZERO,
            DVec3::new(2.0, 0.0, 0.0),
            DVec3::new(0.0, 3.0, 0.0),
        ];
        let idx: Vec<u32> = (0..3).collect();
        assert!(keep(&idx, 3, |i| p[i as usize], 1.0).is_none());
        // A span of more cells than a key holds: left as it is.
        let q = [DVec3::ZERO, DVec3::ZERO, DVec3::new(1.0e7, 0.0, 0.0)];
        assert!(keep(&idx, 3, |i| q[i as usize], 1.0).is_none());
    }
}
