//! The least-squares fits the generation's steps share: the plane of a
//! neighbourhood by principal components (§2.1's normal) and height fields
//! over a plane, `h(x, y) = a + b x + c y + d x² + e xy + f y²` or its
//! first three terms (the quadric of `super::denoise`, the two-plane
//! against one-quadric tests of `super::normals::face_normals` and
//! `super::grow`), scored as MSAC scores them.

use glam::{DVec3, Vec3};

/// Quadratic fits of fewer points than this are not made (six parameters).
pub const MIN_QUADRIC_POINTS: usize = 10;

/// Eigen-decomposition of a symmetric 3×3 matrix by cyclic Jacobi rotations
/// (robust for repeated and zero eigenvalues). Returns the eigenvalues in
/// ascending order and the matching unit eigenvectors.
#[must_use]
#[allow(clippy::needless_range_loop)] // index form mirrors the rotation formulas
pub fn sym_eigen3(m: [[f64; 3]; 3]) -> ([f64; 3], [DVec3; 3]) {
    let mut a = m;
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let scale = a[0][0].abs() + a[1][1].abs() + a[2][2].abs() + 1e-300;
    for _sweep in 0..50 {
        let off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        if off <= (1e-15 * scale) * (1e-15 * scale) {
            break;
        }
        for (p, q) in [(0usize, 1usize), (0, 2), (1, 2)] {
            let apq = a[p][q];
            if apq == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * apq);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for row in &mut a {
                let (kp, kq) = (row[p], row[q]);
                row[p] = c * kp - s * kq;
                row[q] = s * kp + c * kq;
            }
            for k in 0..3 {
                let (pk, qk) = (a[p][k], a[q][k]);
                a[p][k] = c * pk - s * qk;
                a[q][k] = s * pk + c * qk;
            }
            for row in &mut v {
                let (kp, kq) = (row[p], row[q]);
                row[p] = c * kp - s * kq;
                row[q] = s * kp + c * kq;
            }
        }
    }
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| a[i][i].total_cmp(&a[j][j]));
    let vals = order.map(|i| a[i][i]);
    let vecs = order.map(|i| DVec3::new(v[0][i], v[1][i], v[2][i]).normalize_or_zero());
    (vals, vecs)
}

/// The least-squares plane of `points`, accumulated relative to their
/// centroid in `f64`: (centroid, eigenvalues ascending, eigenvectors).
#[must_use]
pub fn plane_fit(points: impl Iterator<Item = Vec3> + Clone) -> (DVec3, [f64; 3], [DVec3; 3]) {
    let mut c = DVec3::ZERO;
    let mut n = 0f64;
    for p in points.clone() {
        c += p.as_dvec3();
        n += 1.0;
    }
    c /= n.max(1.0);
    let mut m = [[0f64; 3]; 3];
    for p in points {
        let d = p.as_dvec3() - c;
        let d = d.to_array();
        for r in 0..3 {
            for s in r..3 {
                m[r][s] += d[r] * d[s];
            }
        }
    }
    m[1][0] = m[0][1];
    m[2][0] = m[0][2];
    m[2][1] = m[1][2];
    let (vals, vecs) = sym_eigen3(m);
    (c, vals, vecs)
}

/// A neighbourhood is collinear (no plane to fit) when its middle
/// eigenvalue is below this fraction of the largest.
pub const COLLINEAR: f64 = 1e-3;

/// How closely `offsets` (points minus a point on the surface) lie on the
/// quadratic height field over the plane of normal `n` fitted to them by
/// least squares (the fit of the module notes): MSAC's score, the sum of
/// `1 - (r / tol)²` over the residuals `r` within `tol`, as
/// `normals::face_normals` scores its planes; `None` where they do not
/// determine a quadric. A smooth surface's neighbourhood, curved beyond
/// one plane's `tol`, lies on its quadric within the noise; two faces
/// meeting at an edge lie closer to their two planes.
#[must_use]
pub fn quadric_fit(offsets: &[Vec3], n: Vec3, tol: f32) -> Option<f32> {
    height_fit(offsets, n, tol, 6, MIN_QUADRIC_POINTS)
}

/// One least-squares row of a height field: `(1, x, y, x², xy, y²)` and `h`.
pub(crate) type HeightRow = ([f64; 6], f64);

/// The rows `(1, x, y, x², xy, y²; h)` of the height field over the plane
/// of normal `n` through the origin, `offsets` scaled into the unit ball,
/// and that scale; `None` for fewer than `min_points`, a zero normal or no
/// extent.
pub(crate) fn height_rows(
    offsets: &[Vec3],
    n: Vec3,
    min_points: usize,
) -> Option<(Vec<HeightRow>, f64)> {
    let n = n.as_dvec3().try_normalize()?;
    let u = n.any_orthonormal_vector();
    let v = n.cross(u);
    let scale = offsets
        .iter()
        .map(|d| d.as_dvec3().length())
        .fold(0.0f64, f64::max);
    if scale.is_nan() || scale <= 0.0 || offsets.len() < min_points {
        return None;
    }
    Some((
        offsets
            .iter()
            .map(|d| {
                let d = d.as_dvec3() / scale;
                let (x, y) = (d.dot(u), d.dot(v));
                ([1.0, x, y, x * x, x * y, y * y], d.dot(n))
            })
            .collect(),
        scale,
    ))
}

/// The MSAC score (as [`quadric_fit`]'s) of the height field over the
/// plane of normal `n` fitted to `offsets` by least squares with its first
/// `terms` of `1, x, y, x², xy, y²`: 3 a plane, 6 a quadric; `None` where
/// fewer than `min_points` or they do not determine it.
#[must_use]
pub fn height_fit(
    offsets: &[Vec3],
    n: Vec3,
    tol: f32,
    terms: usize,
    min_points: usize,
) -> Option<f32> {
    let (rows, scale) = height_rows(offsets, n, min_points.max(terms))?;
    let (mut ata, mut atb) = normal_equations(&rows);
    // Unused terms: identity rows, so their coefficients solve to 0.
    for r in terms.min(6)..6 {
        ata[r] = [0.0; 6];
        for row in &mut ata {
            row[r] = 0.0;
        }
        ata[r][r] = 1.0;
        atb[r] = 0.0;
    }
    let coef = solve6(ata, atb)?;
    let tol = f64::from(tol) / scale;
    Some(
        rows.iter()
            .map(|(row, h)| {
                let f: f64 = row.iter().zip(&coef).map(|(a, b)| a * b).sum();
                (1.0 - ((h - f) / tol).powi(2)).max(0.0)
            })
            .sum::<f64>() as f32,
    )
}

/// The normal equations `(AᵀA, Aᵀh)` of the height field's least squares
/// over `rows` (each the terms `1, x, y, x², xy, y²` and the height `h`).
#[allow(clippy::needless_range_loop)] // index form mirrors the matrix
pub(crate) fn normal_equations(rows: &[([f64; 6], f64)]) -> ([[f64; 6]; 6], [f64; 6]) {
    let mut ata = [[0f64; 6]; 6];
    let mut atb = [0f64; 6];
    for (row, h) in rows {
        for r in 0..6 {
            for c in 0..6 {
                ata[r][c] += row[r] * row[c];
            }
            atb[r] += row[r] * h;
        }
    }
    (ata, atb)
}

/// Solves the 6×6 normal equations by Gaussian elimination with partial
/// pivoting; `None` when they are singular (the points do not determine a
/// quadratic surface, e.g. they lie on one line).
#[allow(clippy::needless_range_loop)] // index form mirrors the elimination
pub(crate) fn solve6(mut a: [[f64; 6]; 6], mut b: [f64; 6]) -> Option<[f64; 6]> {
    let norm = a.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    for col in 0..6 {
        let piv = (col..6).max_by(|&r, &s| a[r][col].abs().total_cmp(&a[s][col].abs()))?;
        if a[piv][col].abs() <= 1e-10 * norm {
            return None;
        }
        a.swap(col, piv);
        b.swap(col, piv);
        for r in col + 1..6 {
            let f = a[r][col] / a[col][col];
            for c in col..6 {
                a[r][c] -= f * a[col][c];
            }
            b[r] -= f * b[col];
        }
    }
    let mut x = [0f64; 6];
    for r in (0..6).rev() {
        let s: f64 = (r + 1..6).map(|c| a[r][c] * x[c]).sum();
        x[r] = (b[r] - s) / a[r][r];
    }
    Some(x)
}
