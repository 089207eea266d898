//! Flat faces fitted whole under strong range noise.
//!
//! `normals::face_normals` gives a point on a flat face the plane of its
//! wide neighbourhood, a few dozen points; under range noise that plane
//! still tilts by a fraction of a degree, and where an edge is near, by
//! several (the neighbourhood is one-sided there, and the noisy points of
//! the face across sit within the tolerance). A splat takes its seed's
//! normal, so the splats along every edge of a noisy scan tilt, and the two
//! planes whose meeting line clips them (`partners`) miss the edge.
//!
//! Here the flat points are gathered into faces, the way plane detection
//! in scans of buildings does (region growing): a region grown over the
//! neighbourhood graph, each point within the tolerance of the region's
//! plane (refitted as it grows) with its normal within [`FACE_AGREE_DEG`]
//! of it. Points at its edges that are not flat themselves (a normal
//! blended with the face across) join it within [`EDGE_AGREE_DEG`] but do
//! not grow it further. A region is a flat face when it has at least
//! [`MIN_FACE_POINTS`] points, no quadric explains their heights over its
//! plane better than the plane does ([`FACE_F`]) or the quadric's slope is
//! negligible ([`FACE_SLOPE_DEG`]), and their own normals
//! turn from the plane's by at most [`FACE_SPREAD_DEG`] on average. Its
//! points take its normal and are moved onto it: along their lines of sight
//! where the scanner positions are known, since range noise moved them
//! along those; a point at a grazing angle moved only along the normal
//! keeps its error along the face, and the last points before a border,
//! seen at a slant, stood past it by a pixel all round. The solids scanned
//! from one station (`compare --truth`, 800×600, seeds 1–3): moved along
//! the normal 33.43, 33.45, 33.76 dB (seed 1: 0.12 % of the image in false
//! hits), along the lines of sight 34.06, 33.87, 34.30 (0.02 %).
//!
//! Only under strong noise (`normals::FlatFaces::Strong`, where k-nearest
//! planes tilt by degrees): under weaker noise the wide planes are close
//! enough, and a face's larger splats overhang its borders more (the 60 m
//! survey of `tests/survey.rs`: 24.77 → 24.74 dB, false hits 0.364 % →
//! 0.379 % of the image).
//!
//! A curved surface does not pass: a strip of a cylinder within the
//! tolerance of a plane bows across its width, which the quadric fits (F of
//! 25–440 on the solids' cylinder, mostly under 3 on their faces); a patch of the
//! scanned bunny bowing less than the noise still turns its points' normals
//! by 5–6° on average, where the solids' faces turn theirs by 0.3–1.9°.
//! A face's splats grow larger than the noise let them (the one-station
//! scan: 3,293 splats instead of 11,460), up to `grow::FACE_RADIUS_FACTOR`.

use super::fit::{COLLINEAR, normal_equations, plane_fit, solve6};
use super::knn::Knn;
use crate::data::Viewpoints;
use glam::Vec3;

/// A point joins a face within this many times the face tolerance of
/// `normals::face_normals` of its plane (three times the noise under range
/// noise). The solids scanned from one station with range noise of half a
/// spacing (`compare --truth`, 800×600, seeds 1–3): at 1× 33.46, 33.13,
/// 33.57 dB, at 1.5× 34.05, 33.78, 34.12, at 2× (and 2.5×, 3×) 34.06, 33.87,
/// 34.30. At 1× the points just past the tolerance are left where they
/// were, and each grows a small splat standing in front of its face that
/// shadows it in specks.
pub const FACE_TOL: f32 = 2.0;

/// A flat point joins a face when its normal is within this many degrees
/// of the face's.
pub const FACE_AGREE_DEG: f32 = 10.0;

/// A point that is not flat (at an edge, its normal blended with the face
/// across) joins a face within this many degrees, and grows it no further.
pub const EDGE_AGREE_DEG: f32 = 20.0;

/// A face has at least this many points: a smaller one is no wider than the
/// wide neighbourhood `face_normals` already fitted.
pub const MIN_FACE_POINTS: usize = 256;

/// A region is flat when a quadric over its plane explains its points'
/// heights no better than the plane: the F statistic of the drop in the
/// residual sum of squares per added parameter (3) over the quadric's
/// residual per degree of freedom stays below this.
pub const FACE_F: f64 = 10.0;

/// ... and the points' own normals (each fitted to its wide neighbourhood)
/// turn from the face's by at most this many degrees on average: a curved
/// patch whose bow the noise hides from the quadric still turns its
/// normals.
pub const FACE_SPREAD_DEG: f32 = 3.0;

/// A point is moved onto its face along its line of sight where that line
/// meets the face at least this steeply (the sine of the angle), else along
/// the face's normal.
pub const SIGHT_MIN_SIN: f32 = 0.1;

/// ... or, however significant its bow, the quadric's slope over the
/// region's points is under this many degrees on average: the normal error
/// a plane makes there. The ground of the solids scanned from two stations
/// with seed 2 (67,510 points) had F = 11.1 and a mean slope of 0.004°
/// (with it fitted, 34.04 → 34.42 dB); the strips of their cylinder slope
/// by 3.7–6.2°.
pub const FACE_SLOPE_DEG: f32 = 0.25;

/// What [`fit_faces`] found.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Faces {
    /// Flat faces fitted.
    pub faces: usize,
    /// Points moved onto them.
    pub points: usize,
    /// For each point: is it on one of them? (Empty when none was found.)
    pub on_face: Vec<bool>,
}

/// Gather the `flat` points (those `normals::face_normals` found on flat
/// faces) into whole faces and move every point of a face onto the face's
/// plane, its normal the plane's (see the module notes). Points `fixed`
/// (given normals) are left alone. `tol` is the face tolerance of
/// `face_normals`, times [`FACE_TOL`]. Where the scanner positions are
/// known (`sights`), points move along their lines of sight, which is where
/// range noise moved them. Marks the points of every face flat.
pub fn fit_faces(
    points: &mut [Vec3],
    normals: &mut [Vec3],
    fixed: &[bool],
    flat: &mut [bool],
    knn: &Knn,
    tol: f32,
    sights: Option<&Viewpoints>,
) -> Faces {
    let n = points.len();
    if flat.len() != n || fixed.len() != n || tol <= 0.0 {
        return Faces::default();
    }
    const FREE: u32 = u32::MAX;
    const TRIED: u32 = u32::MAX - 1;
    let mut label = vec![FREE; n];
    let face_cos = FACE_AGREE_DEG.to_radians().cos();
    let edge_cos = EDGE_AGREE_DEG.to_radians().cos();
    let mut found = Faces::default();
    let mut members: Vec<u32> = Vec::new();
    let mut stack: Vec<u32> = Vec::new();
    for seed in 0..n {
        if label[seed] != FREE || !flat[seed] || fixed[seed] {
            continue;
        }
        let id = found.faces as u32;
        members.clear();
        stack.clear();
        let mut plane = Plane::new(points[seed], normals[seed]);
        let mut refit_at = 16usize;
        label[seed] = id;
        members.push(seed as u32);
        stack.push(seed as u32);
        while let Some(i) = stack.pop() {
            for &j in knn.of(i as usize) {
                let ju = j as usize;
                if label[ju] != FREE || fixed[ju] {
                    continue;
                }
                let (p, m) = (points[ju], normals[ju]);
                if plane.height(p).abs() > tol {
                    continue;
                }
                let agree = m.dot(plane.normal);
                let grows = flat[ju] && agree >= face_cos;
                if !grows && agree < edge_cos {
                    continue;
                }
                label[ju] = id;
                members.push(j);
                if grows {
                    stack.push(j);
                }
                // Refitted at each doubling: every fit over all the
                // members, twice the final count in all.
                if members.len() >= refit_at {
                    refit_at *= 2;
                    if let Some(p) = Plane::fit(&members, points, plane.normal) {
                        plane = p;
                    }
                }
            }
        }
        let face = accepted_face(&members, points, normals, plane.normal);
        match face {
            Some(plane) => settle(
                &plane,
                &members,
                (points, normals, flat),
                sights,
                &mut found,
            ),
            None => {
                for &j in &members {
                    label[j as usize] = TRIED;
                }
            }
        }
    }
    found
}

/// The plane fitted to a face's `members` (starting from `normal`) where
/// the face holds at least [`MIN_FACE_POINTS`], their normals spread by at
/// most [`FACE_SPREAD_DEG`] about it on average and it is flat enough
/// ([`flat_enough`]); `None` otherwise.
fn accepted_face(
    members: &[u32],
    points: &[Vec3],
    normals: &[Vec3],
    normal: Vec3,
) -> Option<Plane> {
    if members.len() < MIN_FACE_POINTS {
        return None;
    }
    let plane = Plane::fit(members, points, normal)?;
    let spread = members
        .iter()
        .map(|&j| {
            normals[j as usize]
                .dot(plane.normal)
                .clamp(-1.0, 1.0)
                .acos()
        })
        .sum::<f32>()
        / members.len() as f32;
    (spread <= FACE_SPREAD_DEG.to_radians()
        && flat_enough(&plane, members.iter().map(|&j| points[j as usize])))
    .then_some(plane)
}

/// Every point of an accepted face moved onto its `plane` (along its line
/// of sight where `sights` are known), its normal the plane's on its own
/// side, marked flat and on a face; the face counted in `found`.
fn settle(
    plane: &Plane,
    members: &[u32],
    (points, normals, flat): (&mut [Vec3], &mut [Vec3], &mut [bool]),
    sights: Option<&Viewpoints>,
    found: &mut Faces,
) {
    if found.on_face.is_empty() {
        found.on_face = vec![false; points.len()];
    }
    for &j in members {
        let ju = j as usize;
        points[ju] = plane.onto(points[ju], sights.map(|s| s.at(ju)));
        normals[ju] = if normals[ju].dot(plane.normal) < 0.0 {
            -plane.normal
        } else {
            plane.normal
        };
        flat[ju] = true;
        found.on_face[ju] = true;
    }
    found.faces += 1;
    found.points += members.len();
}

/// A plane through `origin` with unit `normal`.
#[derive(Clone, Copy, Debug)]
struct Plane {
    origin: Vec3,
    normal: Vec3,
}

impl Plane {
    fn new(origin: Vec3, normal: Vec3) -> Plane {
        Plane {
            origin,
            normal: normal.normalize_or_zero(),
        }
    }

    /// The least-squares plane of the points `members` picks (`fit::plane_fit`),
    /// its normal turned to `side`; `None` when they do not span a plane.
    fn fit(members: &[u32], points: &[Vec3], side: Vec3) -> Option<Plane> {
        let (c, vals, vecs) = plane_fit(members.iter().map(|&j| points[j as usize]));
        if vals[1] <= COLLINEAR * vals[2] {
            return None;
        }
        let m = vecs[0].as_vec3();
        let m = if m.dot(side) < 0.0 { -m } else { m };
        m.is_finite().then(|| Plane::new(c.as_vec3(), m))
    }

    fn height(&self, p: Vec3) -> f32 {
        self.normal.dot(p - self.origin)
    }

    /// `p` moved onto the plane: along its line of sight from `eye` (range
    /// noise lies along it), or along the normal without one or where the
    /// line meets the plane at less than [`SIGHT_MIN_SIN`].
    fn onto(&self, p: Vec3, eye: Option<Vec3>) -> Vec3 {
        let h = self.height(p);
        let along = eye
            .and_then(|e| (p - e).try_normalize())
            .filter(|d| d.dot(self.normal).abs() >= SIGHT_MIN_SIN);
        match along {
            Some(d) => p - d * (h / d.dot(self.normal)),
            None => p - self.normal * h,
        }
    }
}

/// Whether the heights of `pts` over `plane` are explained no better by a
/// quadric than by the plane itself ([`FACE_F`]).
fn flat_enough(plane: &Plane, pts: impl Iterator<Item = Vec3> + Clone) -> bool {
    let n = plane.normal.as_dvec3();
    let u = n.any_orthonormal_vector();
    let v = n.cross(u);
    let o = plane.origin.as_dvec3();
    let scale = pts
        .clone()
        .map(|p| (p.as_dvec3() - o).length())
        .fold(0.0f64, f64::max);
    if scale.is_nan() || scale <= 0.0 {
        return false;
    }
    let rows: Vec<([f64; 6], f64)> = pts
        .map(|p| {
            let d = (p.as_dvec3() - o) / scale;
            let (x, y) = (d.dot(u), d.dot(v));
            ([1.0, x, y, x * x, x * y, y * y], d.dot(n))
        })
        .collect();
    if rows.len() < 12 {
        return false;
    }
    let rss = |coef: &[f64; 6]| -> f64 {
        rows.iter()
            .map(|(r, h)| {
                let e = h - r.iter().zip(coef).map(|(a, b)| a * b).sum::<f64>();
                e * e
            })
            .sum()
    };
    let (ata, atb) = normal_equations(&rows);
    let Some(quad) = solve6(ata, atb) else {
        return false;
    };
    // The plane's own residuals: the plane is the least-squares one, so
    // its heights are the residuals of the plane model.
    let rss_plane = rss(&[0.0; 6]);
    let rss_quad = rss(&quad);
    let dof = (rows.len() - 6) as f64;
    if rss_quad <= 0.0 {
        return rss_plane <= 0.0;
    }
    let f = ((rss_plane - rss_quad) / 3.0) / (rss_quad / dof);
    // Over tens of thousands of points the F test sees bows no normal
    // would show: the quadric's mean slope over the points decides then.
    let slope = rows
        .iter()
        .map(|(r, _)| {
            let (x, y) = (r[1], r[2]);
            let gx = quad[1] + 2.0 * quad[3] * x + quad[4] * y;
            let gy = quad[2] + quad[4] * x + 2.0 * quad[5] * y;
            gx.hypot(gy)
        })
        .sum::<f64>()
        / rows.len() as f64;
    f < FACE_F || slope.atan() < f64::from(FACE_SLOPE_DEG).to_radians()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use crate::splat::knn::build_tree;

    /// Points on a 60×60 grid of spacing 0.01 over `(x, y)`, mapped to 3D by
    /// `at`, each moved by Gaussian noise `sd` along `noise_dir` at it.
    fn sample(
        at: impl Fn(f32, f32) -> (Vec3, Vec3),
        sd: f32,
        seed: u64,
    ) -> (Vec<Vec3>, Vec<Vec3>, Vec<Vec3>) {
        let mut rng = SplitMix64::new(seed);
        let (mut pts, mut clean, mut nrm) = (Vec::new(), Vec::new(), Vec::new());
        for i in 0..60 {
            for j in 0..60 {
                let (x, y) = (i as f32 * 0.01 - 0.3, j as f32 * 0.01 - 0.3);
                let (p, n) = at(x, y);
                clean.push(p);
                pts.push(p + n * sd * rng.next_gaussian() as f32);
                nrm.push(n);
            }
        }
        (pts, clean, nrm)
    }

    fn fit(pts: &mut [Vec3], nrm: &mut [Vec3], flat: &mut [bool], tol: f32) -> Faces {
        let tree = build_tree(pts);
        let knn = Knn::build(&tree, pts, 16);
        let fixed = vec![false; pts.len()];
        fit_faces(pts, nrm, &fixed, flat, &knn, tol, None)
    }

    fn deg(a: Vec3, b: Vec3) -> f32 {
        a.dot(b).clamp(-1.0, 1.0).acos().to_degrees()
    }

    /// A floor and a wall meeting at an edge, noisy, their normals tilted
    /// by a few degrees (as `face_normals` leaves them) and those within two
    /// spacings of the edge not flat: two faces, every point on its plane,
    /// every normal the plane's.
    #[test]
    fn a_noisy_floor_and_wall_are_fitted_whole() {
        let floor = |x: f32, y: f32| (Vec3::new(x, y, 0.0), Vec3::Z);
        let wall = |x: f32, y: f32| (Vec3::new(0.3, x, y + 0.31), Vec3::NEG_X);
        let (mut pts, _, mut nrm) = sample(floor, 0.002, 1);
        let (p2, _, n2) = sample(wall, 0.002, 2);
        pts.extend(p2);
        nrm.extend(n2);
        let mut rng = SplitMix64::new(3);
        let mut flat = Vec::new();
        for (p, n) in pts.iter().zip(nrm.iter_mut()) {
            *n = (*n + rng.unit() * 0.05).normalize();
            flat.push(p.z.abs() < 0.01 && p.x < 0.28 || p.x > 0.29 && p.z > 0.03);
        }
        let tilted = nrm.clone();
        let found = fit(&mut pts, &mut nrm, &mut flat, 0.012);
        assert_eq!(found.faces, 2, "{found:?}");
        // Every point joined a face, those at the edge within
        // EDGE_AGREE_DEG.
        assert_eq!(found.points, pts.len());
        // Noise of 0.002 over 3,600 points: each plane within about
        // 0.002 / sqrt(3600) of the truth (measured 7.8e-5 and 8.1e-5), its
        // normal within a few hundredths of a degree (0.020° and 0°); all
        // 3,600 points on it to rounding.
        let floor: Vec<(Vec3, Vec3)> = pts
            .iter()
            .zip(&nrm)
            .filter(|(p, _)| p.z < 0.005)
            .map(|(p, n)| (*p, *n))
            .collect();
        let wall: Vec<(Vec3, Vec3)> = pts
            .iter()
            .zip(&nrm)
            .filter(|(p, _)| p.z >= 0.005)
            .map(|(p, n)| (*p, *n))
            .collect();
        for (side, truth) in [(&floor, Vec3::Z), (&wall, Vec3::NEG_X)] {
            let (n0, p0) = (side[0].1, side[0].0);
            let on = side
                .iter()
                .filter(|(p, n)| *n == n0 && n0.dot(*p - p0).abs() < 1e-5)
                .count();
            assert_eq!(on, side.len(), "points off the face");
            assert!(deg(n0, truth) < 0.04, "{n0}");
            let origin = if truth == Vec3::Z {
                Vec3::ZERO
            } else {
                Vec3::X * 0.3
            };
            assert!(truth.dot(p0 - origin).abs() < 1.5e-4);
        }
        // (The normals given were 2.3° off on average.)
        let before: f32 = tilted.iter().map(|&n| deg(n, n.round())).sum::<f32>() / 7200.0;
        assert!(before > 2.0, "the test's normals were tilted by {before}°");
    }

    /// A cylinder of radius 0.5 (a sagitta of 0.022 over the patch, the
    /// noise 0.002) is no face, whatever its normals.
    #[test]
    fn a_cylinder_is_no_face() {
        let cyl = |x: f32, y: f32| {
            let a = x / 0.5;
            (
                Vec3::new(0.5 * a.sin(), y, 0.5 * a.cos()),
                Vec3::new(a.sin(), 0.0, a.cos()),
            )
        };
        let (mut pts, _, mut nrm) = sample(cyl, 0.002, 4);
        let mut flat = vec![true; pts.len()];
        // Its normals as flat as a plane's: only the quadric can tell.
        let mut level = vec![Vec3::Z; pts.len()];
        let before = pts.clone();
        assert_eq!(fit(&mut pts, &mut level, &mut flat, 0.03), Faces::default());
        assert_eq!(fit(&mut pts, &mut nrm, &mut flat, 0.03), Faces::default());
        assert_eq!(pts, before);
    }

    /// Points on a noisy plane whose normals turn as a sphere's of radius 4
    /// would, by 3.28° on average: no face, even though the quadric sees no
    /// bow (a patch of the scanned bunny of `scenes/scan.toml`, 798 points,
    /// bowed less than its noise, turned its normals by 5.7°). With level
    /// normals the same points are one.
    #[test]
    fn a_patch_whose_normals_turn_is_no_face() {
        let level = |x: f32, y: f32| (Vec3::new(x, y, 0.0), Vec3::Z);
        let (pts, _, _) = sample(level, 0.002, 5);
        let turned: Vec<Vec3> = pts
            .iter()
            .map(|p| Vec3::new(p.x / 4.0, p.y / 4.0, 1.0).normalize())
            .collect();
        let spread: f32 =
            turned.iter().map(|&n| deg(n, Vec3::Z)).sum::<f32>() / turned.len() as f32;
        assert!(spread > FACE_SPREAD_DEG, "{spread}");
        let (mut a, mut na, mut flat) = (pts.clone(), turned, vec![true; pts.len()]);
        assert_eq!(fit(&mut a, &mut na, &mut flat, 0.012).faces, 0);
        let (mut b, mut nb) = (pts.clone(), vec![Vec3::Z; pts.len()]);
        assert_eq!(fit(&mut b, &mut nb, &mut flat, 0.012).faces, 1);
    }

    /// Range noise along the lines of sight from a scanner 1.0 above a
    /// floor, seen at a slant: moved back along them, the points land where
    /// the scanner's rays met the floor; moved along the normal, they keep
    /// the noise's share along the floor.
    #[test]
    fn points_move_back_along_their_lines_of_sight() {
        let eye = Vec3::new(-1.5, 0.0, 1.0);
        let mut rng = SplitMix64::new(6);
        let (mut pts, mut clean) = (Vec::new(), Vec::new());
        for i in 0..60 {
            for j in 0..60 {
                let p = Vec3::new(i as f32 * 0.01 - 0.3, j as f32 * 0.01 - 0.3, 0.0);
                let d = (p - eye).normalize();
                clean.push(p);
                pts.push(p + d * 0.004 * rng.next_gaussian() as f32);
            }
        }
        let run = |sights: Option<&Viewpoints>| {
            let mut p = pts.clone();
            let mut n = vec![Vec3::Z; p.len()];
            let mut flat = vec![true; p.len()];
            let tree = build_tree(&p);
            let knn = Knn::build(&tree, &p, 16);
            let fixed = vec![false; p.len()];
            let found = fit_faces(&mut p, &mut n, &fixed, &mut flat, &knn, 0.01, sights);
            assert_eq!(found.faces, 1);
            p.iter()
                .zip(&clean)
                .map(|(a, b)| a.distance(*b))
                .sum::<f32>()
                / p.len() as f32
        };
        let along_normal = run(None);
        let along_sight = run(Some(&Viewpoints::One(eye)));
        // Measured: 2.6e-3 along the normal, 1.1e-4 along the lines of
        // sight (what is left is the face's own tilt and offset).
        assert!(along_normal > 2.0e-3, "{along_normal}");
        assert!(along_sight < 2.0e-4, "{along_sight}");
    }
}
