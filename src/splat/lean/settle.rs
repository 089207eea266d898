//! Points settled onto their surfaces before sharp lean growth: a scan too
//! noisy for lean growth's slab (its scatter over [`super::SCAN_SHARP_SIGMA`],
//! or with creases over [`super::SCAN_SETTLE_SIGMA`]) but dense enough
//! ([`SETTLE_SPARSE`]).
//!
//! Each pass grows sharp lean splats (clip lines at creases and borders,
//! [`super::sharp`]) in a slab wider than the noise ([`PASSES`]), fits each
//! splat's quadric height field to its points and to those within its
//! field's reach on its kept side (the fit of eq. 4's fields), and moves
//! every point a splat took along its line of sight onto that quadric
//! (along the splat's normal where the sight line grazes it,
//! [`GRAZING_SIN`]); a point taken by several splats moves to the mean of
//! their projections, weighted by `1 - (d/r)^2` of its distance `d` from
//! each centre in a splat of radius `r`. Sharp lean growth then runs at
//! its usual slab on the settled points; the points as given stay the
//! cloud's (coverage, free-space trimming's lines of sight).
//!
//! On the solids scanned from one station the settled splats render above
//! the stages at every noise measured but half a spacing (0.67 dB under
//! there), at about a quarter of their time ([`PASSES`];
//! `docs/notes/generation.md`, "Issue 54, sixtieth" and "sixty-fifth
//! session").

use super::{Grid, Growth, Grown, grow_all_then, quadric};
use crate::data::Viewpoints;
use glam::{DVec3, Vec3};
use rayon::prelude::*;

/// Each settling pass's slab half-width, in the scan's scatter (the gate's
/// median scatter of a point's nearest about their plane): a first pass
/// wide enough for the noise, then a narrower one over the once-moved
/// points. The solids scanned from one station (1000×750 rays, `compare
/// --truth` at 400×300 against the stages, means of seeds 1-3), range
/// noise of 0.2 / 0.22 / 0.3 / 0.5 / 1.0 / 1.5 spacings (scatter 0.069 /
/// 0.074 / 0.10 / 0.17 / 0.32 / 0.43 `ϵ`): +2.23 / +0.79 / +0.61 / -0.67 /
/// +0.50 / +0.65 dB. At half a spacing, 4.9 and 2.9 scatters (0.83 and
/// 0.5 `ϵ`, slabs fixed in `ϵ` as first tried) read -0.93, 3.3 and 2.0
/// -0.89; fixed in `ϵ`, 1.5 spacings fell 6.9 dB (the noise past the
/// slab).
pub const PASSES: [f32; 2] = [4.15, 2.5];

/// A point whose line of sight meets its splat's plane at a sine under
/// this (17°) moves along the splat's normal instead: near grazing, a
/// small error in the quadric moves it far along the sight line.
pub const GRAZING_SIN: f64 = 0.29;

/// The most a scan's median 12th-neighbour distance may be, in `ϵ`, for its
/// points to be settled ([`super::Gate::settle_passes`]): the noisy solids
/// at 1000×750 rays read 1.8-2.1 (settled: above), at 400×300 rays 4.7,
/// where the fixed slabs fell 2 dB short of the stages.
pub const SETTLE_SPARSE: f32 = 2.5;

/// The most scatter, in `ϵ`, at which a scan is settled: the noisy solids
/// at 1.5 spacings read 0.43 (settled: +0.65 dB over the stages, seeds
/// 1-3); with slabs fixed in `ϵ` they fell 6.9 dB, so past what was
/// measured a scan keeps the stages.
pub const SETTLE_SIGMA: f32 = 0.45;

/// The points of `g` (as given, not in grid order), settled by the passes
/// of [`PASSES`] from the scanners of `views`: the splats grown at
/// `growth`'s error and outlier distance, seeded within `within`, their
/// slabs [`PASSES`] times `scatter` (the points as given where it is not
/// a positive length: a window too small for the gate to measure).
pub fn settle(g: &Grid, growth: Growth, within: Option<[Vec3; 2]>, views: &Viewpoints, scatter: f32) -> Vec<Vec3> {
    if !(scatter.is_finite() && scatter > 0.0) {
        let mut given = vec![Vec3::ZERO; g.pos.len()];
        for (i, &p) in g.pos.iter().enumerate() {
            given[g.order[i] as usize] = p;
        }
        return given;
    }
    let pass = |slab: f32| Growth {
        slab: slab * scatter,
        ..growth
    };
    let mut moved = moved(g, pass(PASSES[0]), within, views);
    for &slab in &PASSES[1..] {
        let again = Grid::build(&moved, g.h, true);
        moved = self::moved(&again, pass(slab), within, views);
    }
    moved
}

/// One pass: the points of `g` (as given) moved onto the quadrics of the
/// sharp lean splats grown at `growth`.
fn moved(g: &Grid, growth: Growth, within: Option<[Vec3; 2]>, views: &Viewpoints) -> Vec<Vec3> {
    // The reciprocal of each point's distance from its viewpoint, once (a
    // point lies in several splats; 0 where its sight line has no length).
    let recips: Vec<f64> = (g.pos.par_iter().zip(&g.order))
        .map(|(p, &i)| {
            let r = (p.as_dvec3() - views.at(i as usize).as_dvec3()).length_recip();
            if r.is_finite() && r > 0.0 { r } else { 0.0 }
        })
        .collect();
    let sights = (views, recips.as_slice());
    // Each slab's projections as soon as it is grown, beside the others.
    let project = |grown: &[Grown]| -> Vec<Vec<(u32, Vec3, f32)>> { grown.par_iter().map(|s| projections(g, s, sights)).collect() };
    let (_, _, per_slab) = grow_all_then(g, growth, within, &project);
    let onto = per_slab.into_iter().flatten();
    let mut sum = vec![(Vec3::ZERO, 0.0f32); g.pos.len()];
    for (k, q, w) in onto.flatten() {
        let e = &mut sum[k as usize];
        e.0 += q * w;
        e.1 += w;
    }
    let mut out = vec![Vec3::ZERO; g.pos.len()];
    for (i, &(q, w)) in sum.iter().enumerate() {
        let to = if w > 0.0 { q / w } else { g.pos[i] };
        out[g.order[i] as usize] = if to.is_finite() { to } else { g.pos[i] };
    }
    out
}

/// Where the quadric of splat `s` moves each point it took (grid order),
/// with the point's weight: along its line of sight (from its viewpoint,
/// scaled by the reciprocal of its length, both in `sights` by grid
/// order), or along the splat's normal where that line grazes the splat
/// or misses the quadric; none where the fit fails.
fn projections(g: &Grid, s: &Grown, (views, recips): (&Viewpoints, &[f64])) -> Vec<(u32, Vec3, f32)> {
    let Some(q) = quadric(g, s) else {
        return Vec::new();
    };
    let [f, d, e, a, b, c] = q.coef;
    let (n, u, v) = (q.n, q.u, q.v);
    let centre = s.centre.as_dvec3();
    let r2 = f64::from(s.radius).powi(2);
    let mut out = Vec::with_capacity(s.members.len());
    for &k in &s.members {
        let p = g.pos[k as usize].as_dvec3();
        let o = (p - centre) / q.scale;
        let (x, y, h) = (o.dot(u), o.dot(v), o.dot(n));
        let height = f + d * x + e * y + a * x * x + b * x * y + c * y * y;
        // `normalize_or_zero`, its reciprocal computed once.
        let r = recips[k as usize];
        let from_view = p - views.at(g.order[k as usize] as usize).as_dvec3();
        let sight = if r > 0.0 { from_view * r } else { DVec3::ZERO };
        let dn = sight.dot(n);
        let t = if dn.abs() < GRAZING_SIN {
            None
        } else {
            along_sight(o, sight, &q.coef, (u, v, n))
        };
        let to = match t {
            Some(t) => p + sight * (t * q.scale),
            None => p - n * ((h - height) * q.scale),
        };
        let flat = (p - centre) - n * (p - centre).dot(n);
        let w = (1.0 - flat.length_squared() / r2).max(0.0);
        if w > 0.0 && to.is_finite() {
            out.push((k, to.as_vec3(), w as f32));
        }
    }
    out
}

/// The step `t` along the unit `sight` from the scaled offset `o` onto the
/// height field `h = f + d x + e y + a x² + b x y + c y²` over the axes
/// `(u, v, n)`, the root nearest the point; `None` where the line misses
/// it.
fn along_sight(o: DVec3, sight: DVec3, coef: &[f64; 6], (u, v, n): (DVec3, DVec3, DVec3)) -> Option<f64> {
    let [f, d, e, a, b, c] = *coef;
    let (x, y, h) = (o.dot(u), o.dot(v), o.dot(n));
    let (du, dv, dn) = (sight.dot(u), sight.dot(v), sight.dot(n));
    // h + t dn = H(x + t du, y + t dv): a quadratic A t² + B t + C = 0.
    let hx = d + 2.0 * a * x + b * y;
    let hy = e + b * x + 2.0 * c * y;
    let qa = -(a * du * du + b * du * dv + c * dv * dv);
    let qb = dn - hx * du - hy * dv;
    let qc = h - (f + d * x + e * y + a * x * x + b * x * y + c * y * y);
    if qa.abs() <= 1e-12 * qb.abs() {
        return (qb != 0.0).then(|| -qc / qb);
    }
    let disc = qb * qb - 4.0 * qa * qc;
    if disc < 0.0 {
        return None;
    }
    // The stable pair of roots; the nearer is the point's own surface.
    let s = -0.5 * (qb + qb.signum() * disc.sqrt());
    let (t1, t2) = (s / qa, if s == 0.0 { f64::INFINITY } else { qc / s });
    let t = if t1.abs() < t2.abs() { t1 } else { t2 };
    t.is_finite().then_some(t)
}



#[cfg(test)]
mod tests {
    use super::super::{CELL_EPS, GROW_EPS};
    use super::*;
    use crate::rng::SplitMix64;

    /// The step onto `h = 2 x²` from `(0.1, 0, 0.3)` along `(1, 0, -1)/√2`:
    /// `0.3 - s = 2 (0.1 + s)²` with `s = t/√2`, roots 0.1623 and -0.8623;
    /// the nearer is the point's surface.
    #[test]
    fn a_step_along_the_sight_line_lands_on_the_nearer_root() {
        let axes = (DVec3::X, DVec3::Y, DVec3::Z);
        let sight = DVec3::new(1.0, 0.0, -1.0).normalize();
        let coef = [0.0, 0.0, 0.0, 2.0, 0.0, 0.0];
        let t = along_sight(DVec3::new(0.1, 0.0, 0.3), sight, &coef, axes).unwrap();
        let s = (-1.4 + (1.4f64 * 1.4 + 4.0 * 2.0 * 0.28).sqrt()) / 4.0;
        assert!((t - s * 2f64.sqrt()).abs() < 1e-12, "{t} against {}", s * 2f64.sqrt());
        // A plane h = 0.1 + 0.2 x, reached from below along a tilted line.
        let plane = [0.1, 0.2, 0.0, 0.0, 0.0, 0.0];
        let (o, sight) = (DVec3::new(0.3, -0.2, -0.5), DVec3::new(-0.2, 0.1, 1.0).normalize());
        let q = o + sight * along_sight(o, sight, &plane, axes).unwrap();
        assert!((q.z - (0.1 + 0.2 * q.x)).abs() < 1e-12, "{q}");
        // A line that misses the field: none.
        let bowl = [1.0, 0.0, 0.0, 1.0, 0.0, 1.0];
        assert_eq!(along_sight(DVec3::new(0.0, 0.0, 0.5), DVec3::X, &bowl, axes), None);
    }

    /// A flat square scanned from above and off to one side, range noise
    /// along its lines of sight: settled, its points lie nearer its plane
    /// and each still on its own line of sight.
    #[test]
    fn settled_points_move_toward_the_surface_along_their_sight_lines() {
        let eye = Vec3::new(0.3, 0.2, 2.0);
        let mut rng = SplitMix64::new(7);
        let n = 150;
        let sigma = 0.003;
        let mut pts = Vec::new();
        for i in 0..n {
            for j in 0..n {
                let on = Vec3::new((i as f32 + rng.next_f32()) / n as f32 - 0.5, (j as f32 + rng.next_f32()) / n as f32 - 0.5, 0.0);
                let d = (on - eye).normalize();
                pts.push(on + d * (sigma * rng.next_gaussian() as f32));
            }
        }
        let eps = 0.02;
        let g = Grid::build(&pts, CELL_EPS * eps, true);
        let growth = Growth { eps, slab: GROW_EPS * eps, far: 1.0, scanners: None };
        let views = Viewpoints::One(eye);
        let moved = settle(&g, growth, None, &views, sigma * 0.8);
        let mean_off = |p: &[Vec3]| p.iter().map(|q| f64::from(q.z.abs())).sum::<f64>() / p.len() as f64;
        let (before, after) = (mean_off(&pts), mean_off(&moved));
        // Measured: 2.31e-3 before, 8.4e-5 after (0.036 of it).
        assert!(after < 0.05 * before, "mean height {after} after, {before} before");
        let off_sight = pts
            .iter()
            .zip(&moved)
            .map(|(p, q)| (*q - eye).cross((*p - eye).normalize()).length())
            .fold(0.0f32, f32::max);
        // Measured: 2.0e-7 (rounding); moved along the normal instead, 6.0e-3.
        assert!(off_sight < 2e-6, "{off_sight}");
    }
}
