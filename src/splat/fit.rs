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
    let (c, m) = covariance(points);
    let (vals, vecs) = plane_eigen3(m);
    (c, vals, vecs)
}

/// [`plane_fit`] with the matrix it solves: (centroid, covariance about
/// it (unnormalised), eigenvalues ascending, eigenvectors).
#[must_use]
pub fn plane_fit_moments(
    points: impl Iterator<Item = Vec3> + Clone,
) -> (DVec3, [[f64; 3]; 3], [f64; 3], [DVec3; 3]) {
    let (c, m) = covariance(points);
    let (vals, vecs) = plane_eigen3(m);
    (c, m, vals, vecs)
}

/// The centroid of `points` and their covariance about it (unnormalised),
/// accumulated in `f64`: the matrix [`plane_fit`] solves.
fn covariance(points: impl Iterator<Item = Vec3> + Clone) -> (DVec3, [[f64; 3]; 3]) {
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
    (c, m)
}

/// Below this gap between the two smallest eigenvalues, as a fraction of
/// the largest, [`plane_eigen3`] leaves the matrix to [`sym_eigen3`]: the
/// smallest eigenvector is then ill-defined (a line, a ball, one point)
/// and the closed form's rounding would pick it anew.
const CLOSED_FORM_GAP: f64 = 1e-3;

/// The eigenvalues (ascending) of the symmetric 3×3 matrix `m` and its
/// eigenvector of the smallest (the plane's normal, §2.1), for what
/// [`plane_fit`]'s callers read: the three eigenvalues and `vecs[0]`
/// (`vecs[1]` and `vecs[2]` are zero where the closed form answered).
/// The eigenvalues by the trigonometric solution of the characteristic
/// cubic, the eigenvector as the longest cross product of two rows of
/// `m − λ₀I` (its null space), turned so its largest component is
/// positive; [`sym_eigen3`] where the two smallest eigenvalues are within
/// [`CLOSED_FORM_GAP`] of the largest or the matrix is zero.
#[must_use]
pub fn plane_eigen3(m: [[f64; 3]; 3]) -> ([f64; 3], [DVec3; 3]) {
    closed_form(&m).unwrap_or_else(|| sym_eigen3(m))
}

fn closed_form(m: &[[f64; 3]; 3]) -> Option<([f64; 3], [DVec3; 3])> {
    let q = (m[0][0] + m[1][1] + m[2][2]) / 3.0;
    let (a, b, c) = (m[0][0] - q, m[1][1] - q, m[2][2] - q);
    let (d, e, f) = (m[0][1], m[0][2], m[1][2]);
    let p2 = (a * a + b * b + c * c + 2.0 * (d * d + e * e + f * f)) / 6.0;
    let p = p2.sqrt();
    if !(p > 0.0 && p.is_finite()) {
        return None;
    }
    // det(B) / 2 with B = (m − qI) / p.
    let det = a * (b * c - f * f) - d * (d * c - f * e) + e * (d * f - b * e);
    let r = (det / (2.0 * p2 * p)).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    let hi = q + 2.0 * p * phi.cos();
    let lo = q + 2.0 * p * (phi + 2.0 * std::f64::consts::FRAC_PI_3).cos();
    let mid = 3.0 * q - hi - lo;
    let gap = mid - lo;
    if gap.is_nan() || gap <= CLOSED_FORM_GAP * hi.abs() {
        return None;
    }
    let rows = [
        DVec3::new(m[0][0] - lo, d, e),
        DVec3::new(d, m[1][1] - lo, f),
        DVec3::new(e, f, m[2][2] - lo),
    ];
    let crosses = [
        rows[0].cross(rows[1]),
        rows[0].cross(rows[2]),
        rows[1].cross(rows[2]),
    ];
    let best = crosses
        .into_iter()
        .max_by(|x, y| x.length_squared().total_cmp(&y.length_squared()))?;
    let v = best.try_normalize()?;
    let big = v.abs().max_element();
    let v = if [v.x, v.y, v.z].into_iter().find(|x| x.abs() == big)? < 0.0 {
        -v
    } else {
        v
    };
    // The smallest eigenvalue again as the Rayleigh quotient of its vector:
    // the cubic's roots lose half their digits where two coincide (a round
    // flat neighbourhood), the quotient keeps them all.
    let mv = DVec3::new(
        m[0][0] * v.x + d * v.y + e * v.z,
        d * v.x + m[1][1] * v.y + f * v.z,
        e * v.x + f * v.y + m[2][2] * v.z,
    );
    Some(([v.dot(mv), mid, hi], [v, DVec3::ZERO, DVec3::ZERO]))
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

/// The axes `(n, u, v)` of [`height_rows`]' height field (`x` along `u`,
/// `y` along `v`, `h` along `n`); `None` for a zero normal.
pub(crate) fn height_axes(n: Vec3) -> Option<(DVec3, DVec3, DVec3)> {
    let n = n.as_dvec3().try_normalize()?;
    let u = n.any_orthonormal_vector();
    Some((n, u, n.cross(u)))
}

/// The rows `(1, x, y, x², xy, y²; h)` of the height field over the plane
/// of normal `n` through the origin, `offsets` scaled into the unit ball,
/// and that scale; `None` for fewer than `min_points`, a zero normal or no
/// extent.
pub(crate) fn height_rows(
    offsets: &[Vec3],
    n: Vec3,
    min_points: usize,
) -> Option<(Vec<HeightRow>, f64)> {
    let (n, u, v) = height_axes(n)?;
    // The longest offset's length: the root of the largest square (a
    // root is monotonic and correctly rounded, so it is the largest of
    // the roots, bit for bit; NaN passed over either way).
    let scale = offsets
        .iter()
        .map(|d| d.as_dvec3().length_squared())
        .fold(0.0f64, f64::max)
        .sqrt();
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
/// Each entry sums its products in the order of `rows`, from zero; the
/// rows of `AᵀA` are summed two at a time from their diagonal on (few
/// sums live at once, in adjacent pairs), and the lower triangle is the
/// mirror of the upper, bit for bit what summing it would give (each
/// product `a·b` equals `b·a`). On AVX2 every entry is summed four at a
/// time ([`crate::simd::normal_equations6`]), bit for bit these sums.
pub(crate) fn normal_equations(rows: &[([f64; 6], f64)]) -> ([[f64; 6]; 6], [f64; 6]) {
    // The process's SIMD path where it has a kernel: the same sums.
    crate::simd::normal_equations6(rows, crate::config::current().simd)
        .unwrap_or_else(|| mirrored_sums(rows))
}

/// [`normal_equations`] on the portable path: the upper triangle's sums,
/// two matrix rows at a time, mirrored.
#[allow(clippy::needless_range_loop)] // index form mirrors the matrix
fn mirrored_sums(rows: &[([f64; 6], f64)]) -> ([[f64; 6]; 6], [f64; 6]) {
    let mut ata = [[0f64; 6]; 6];
    let mut atb = [0f64; 6];
    for r in [0, 2, 4] {
        let (mut upper, mut lower) = ([0f64; 6], [0f64; 6]);
        for (row, _) in rows {
            for c in r..6 {
                upper[c] += row[r] * row[c];
                lower[c] += row[r + 1] * row[c];
            }
        }
        ata[r] = upper;
        ata[r + 1] = lower;
    }
    for (row, h) in rows {
        for r in 0..6 {
            atb[r] += row[r] * h;
        }
    }
    for r in 1..6 {
        for c in 0..r {
            ata[r][c] = ata[c][r];
        }
    }
    (ata, atb)
}

/// Solves the 6×6 normal equations by Gaussian elimination with partial
/// pivoting; `None` when they are singular (the points do not determine a
/// quadratic surface, e.g. they lie on one line).
///
/// Each column's step ([`eliminate`]) is unrolled at its own width, with
/// `b` carried as a seventh column of the rows; the pivot is the last of
/// the largest magnitudes (as `total_cmp` orders them: on magnitudes, sign
/// bits clear, the order of their bits). The same divisions, products and
/// differences, in the same order, as the plain elimination (the unit
/// test's reference), so the same answer bit for bit.
pub(crate) fn solve6(a: [[f64; 6]; 6], b: [f64; 6]) -> Option<[f64; 6]> {
    // The largest magnitude, column by column then across (`f64::max`
    // returns one of its operands and passes over NaN, so any order
    // gives the same).
    let mut top = [0f64; 6];
    for row in &a {
        for (t, x) in top.iter_mut().zip(row) {
            *t = t.max(x.abs());
        }
    }
    let limit = 1e-10 * top.iter().fold(0.0f64, |m, &x| m.max(x));
    let mut m = [[0f64; 7]; 6];
    for ((mr, ar), br) in m.iter_mut().zip(&a).zip(&b) {
        mr[..6].copy_from_slice(ar);
        mr[6] = *br;
    }
    eliminate::<0>(&mut m, limit)?;
    eliminate::<1>(&mut m, limit)?;
    eliminate::<2>(&mut m, limit)?;
    eliminate::<3>(&mut m, limit)?;
    eliminate::<4>(&mut m, limit)?;
    eliminate::<5>(&mut m, limit)?;
    let mut x = [0f64; 6];
    for r in (0..6).rev() {
        let s: f64 = (r + 1..6).map(|c| m[r][c] * x[c]).sum();
        x[r] = (m[r][6] - s) / m[r][r];
    }
    Some(x)
}

/// [`solve6`]'s step at column `COL` of the rows `m` (`b` their seventh
/// entry): the pivot, `None` where it is at most `limit`, and the rows
/// below it reduced (their column `COL` is read no more: not updated).
#[inline(always)]
#[allow(clippy::needless_range_loop)] // index form mirrors the elimination
fn eliminate<const COL: usize>(m: &mut [[f64; 7]; 6], limit: f64) -> Option<()> {
    let (mut piv, mut big) = (COL, m[COL][COL].abs());
    for r in COL + 1..6 {
        let v = m[r][COL].abs();
        if big.to_bits() <= v.to_bits() {
            (piv, big) = (r, v);
        }
    }
    if big <= limit {
        return None;
    }
    m.swap(COL, piv);
    let pivot = m[COL];
    for r in COL + 1..6 {
        let f = m[r][COL] / pivot[COL];
        for c in COL + 1..7 {
            m[r][c] -= f * pivot[c];
        }
    }
    Some(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DMat3;

    /// Angle between two lines (sign ignored), radians.
    fn angle(a: DVec3, b: DVec3) -> f64 {
        a.cross(b).length().atan2(a.dot(b).abs())
    }

    struct Rng(u64);
    impl Rng {
        fn unit(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
        fn rotation(&mut self) -> DMat3 {
            let axis = DVec3::new(self.unit() - 0.5, self.unit() - 0.5, self.unit() - 0.5);
            DMat3::from_axis_angle(axis.normalize(), self.unit() * std::f64::consts::TAU)
        }
    }

    /// An eigen-solver: eigenvalues ascending, their vectors.
    type Solver = fn([[f64; 3]; 3]) -> ([f64; 3], [DVec3; 3]);

    /// `R diag(l) Rᵀ` as rows: a matrix of known eigen-decomposition.
    fn with_spectrum(r: DMat3, l: [f64; 3]) -> [[f64; 3]; 3] {
        let m = r * DMat3::from_diagonal(DVec3::from(l)) * r.transpose();
        [0, 1, 2].map(|i| [0, 1, 2].map(|j| m.col(j)[i]))
    }

    /// The largest angle error of the smallest eigenvector, error of the
    /// smallest eigenvalue and of all three (against the largest) over
    /// random rotations of the spectrum `l`.
    fn spectrum_errors(
        l: [f64; 3],
        solve: Solver,
    ) -> (f64, f64, f64) {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let (mut worst_angle, mut worst_low, mut worst_val) = (0.0f64, 0.0f64, 0.0f64);
        for _ in 0..2000 {
            let r = rng.rotation();
            let (vals, vecs) = solve(with_spectrum(r, l));
            worst_angle = worst_angle.max(angle(vecs[0], r.col(0)));
            worst_low = worst_low.max((vals[0] - l[0]).abs() / l[2]);
            for (v, want) in vals.iter().zip(l) {
                worst_val = worst_val.max((v - want).abs() / l[2]);
            }
        }
        (worst_angle, worst_low, worst_val)
    }

    #[test]
    fn closed_form_against_known_spectra() {
        // (spectrum, bound on the normal's angle error in radians) at three
        // scales, 2000 random rotations each. Measured worst: 2.0e-15 rad
        // where the gap is wide (Jacobi 6.1e-15), 1.3e-11 just past
        // `CLOSED_FORM_GAP` (Jacobi 9.7e-13); λ₀ within 8.2e-16 of the
        // largest, the others 8.1e-9 where λ₁ = λ₂ (the cubic's double root).
        // An f32 normal rounds at 6e-8 rad.
        let cases: [([f64; 3], f64); 7] = [
            ([0.0, 1.0, 1.0], 3e-15),       // a flat disc, λ₁ = λ₂
            ([1e-12, 0.5, 1.0], 3e-15),     // flat, no noise
            ([1e-4, 0.7, 1.0], 3e-15),      // a plane with noise
            ([0.3, 0.6, 1.0], 3e-15),       // a fat blob
            ([0.0, 2e-3, 1.0], 2e-11),      // nearly a line, just past the gap
            ([0.5, 0.5 + 2e-3, 1.0], 2e-11),// nearly a ball, just past the gap
            ([1e-9, 1.0, 1.0 + 1e-12], 3e-15),// λ₁ and λ₂ repeated to 1e-12
        ];
        let mut failed = false;
        for (l, bound) in cases {
            let (jac, jac_low, jac_val) = spectrum_errors(l, sym_eigen3);
            for scale in [1e-8, 1.0, 1e8] {
                let l = l.map(|x| x * scale);
                let (a, low, v) = spectrum_errors(l, plane_eigen3);
                eprintln!(
                    "{l:?}: closed form angle {a:.3e} λ₀ {low:.3e} all {v:.3e}; \
                     Jacobi {jac:.3e} {jac_low:.3e} {jac_val:.3e}"
                );
                failed |= a >= bound || low >= 2e-15 || v >= 2e-8;
            }
        }
        assert!(!failed, "see the errors above");
    }

    /// A grid of `n × n` points on a tilted plane through `at`, spacing
    /// `h`, heights `noise` times a fixed pattern, and `stretch` along x.
    fn patch(at: Vec3, h: f32, noise: f32, stretch: f32) -> Vec<Vec3> {
        let (u, v) = (Vec3::new(0.8, 0.6, 0.0), Vec3::new(-0.36, 0.48, 0.8));
        let n = u.cross(v);
        let mut out = Vec::new();
        for i in 0..5 {
            for j in 0..5 {
                let (x, y) = (i as f32 - 2.0, j as f32 - 2.0);
                let z = noise * ((i * 7 + j * 3) % 5) as f32 - 2.0 * noise;
                out.push(at + h * (u * x * stretch + v * y + n * z));
            }
        }
        out
    }

    /// `plane_fit`'s normal and eigenvalues against the Jacobi rotations'
    /// (the f64 reference) on neighbourhoods as generation meets them.
    #[test]
    fn closed_form_against_jacobi_on_points() {
        // (name, points, bound on the normal's angle in radians). Measured:
        // 9.1e-16 at most but 1.7e-11 on the stretched patch (λ₁ at 1e-3 of
        // λ₂); the line and the repeated point fall back to the Jacobi
        // rotations, bit for bit. λ₀ within 7.4e-17 of the largest, the
        // others 5.0e-10.
        let far = Vec3::splat(1e5);
        let cases: Vec<(&str, Vec<Vec3>, f64)> = vec![
            ("flat", patch(Vec3::ZERO, 0.01, 0.0, 1.0), 1e-12),
            ("noisy", patch(Vec3::ZERO, 0.01, 0.1, 1.0), 1e-12),
            ("far", patch(far, 1.0, 0.05, 1.0), 1e-12),
            ("tiny", patch(Vec3::ONE, 1e-4, 0.05, 1.0), 1e-12),
            ("huge", patch(Vec3::ONE, 1e4, 0.05, 1.0), 1e-12),
            ("stretched", patch(Vec3::ZERO, 0.01, 0.01, 30.0), 3e-11),
            ("line", patch(Vec3::ZERO, 0.01, 0.0, 1e4), 0.0),
            ("one point", vec![far; 12], 0.0),
        ];
        let mut failed = false;
        for (name, points, bound) in cases {
            let (_, m) = covariance(points.iter().copied());
            let (want_vals, want) = sym_eigen3(m);
            let (_, vals, got) = plane_fit(points.iter().copied());
            let a = angle(got[0], want[0]);
            eprintln!("{name}: angle {a:.3e}, values {vals:?} against {want_vals:?}");
            let low = (vals[0] - want_vals[0]).abs() / want_vals[2].abs().max(1e-300);
            let all = (0..3)
                .map(|i| (vals[i] - want_vals[i]).abs() / want_vals[2].abs().max(1e-300))
                .fold(0.0, f64::max);
            eprintln!("  λ₀ off by {low:.3e}, all by {all:.3e} of the largest");
            failed |= a > bound || low > 2e-16 || all > 1e-9;
        }
        assert!(!failed, "see the errors above");
    }

    /// The normal equations summed whole, every entry (as before the
    /// mirror): the reference `normal_equations` must equal bit for bit.
    fn normal_equations_whole(rows: &[HeightRow]) -> ([[f64; 6]; 6], [f64; 6]) {
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

    /// The plain elimination (before [`solve6`] was unrolled): partial
    /// pivoting, the last of the largest by `total_cmp`.
    #[allow(clippy::needless_range_loop)]
    fn solve6_reference(mut a: [[f64; 6]; 6], mut b: [f64; 6]) -> Option<[f64; 6]> {
        let norm = a.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        for col in 0..6 {
            let (mut piv, mut big) = (col, a[col][col].abs());
            for r in col + 1..6 {
                let v = a[r][col].abs();
                if big.total_cmp(&v).is_le() {
                    (piv, big) = (r, v);
                }
            }
            if big <= 1e-10 * norm {
                return None;
            }
            a.swap(col, piv);
            b.swap(col, piv);
            for r in col + 1..6 {
                let f = a[r][col] / a[col][col];
                for c in col + 1..6 {
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

    #[test]
    fn unrolled_solve6_is_the_plain_elimination() {
        let mut rng = Rng(0x2545_f491_4f6c_dd1d);
        let bits = |x: Option<[f64; 6]>| x.map(|x| x.map(f64::to_bits));
        let (mut solved, mut singular) = (0, 0);
        for case in 0..20_000 {
            let len = case % 40;
            // Normal equations of height rows (some on a line, some with
            // repeated points, terms and heights of mixed scales and some
            // exact zeros), a plane's identity rows, or any matrix.
            let line = case % 7 == 3;
            let mut t = || match (rng.unit() * 10.0) as u32 {
                0 => 0.0,
                1 => -0.0,
                2 => 0.25,
                _ => (rng.unit() - 0.5) * 10f64.powi((rng.unit() * 8.0) as i32 - 4),
            };
            let rows: Vec<HeightRow> = (0..len)
                .map(|_| {
                    let x = t();
                    let y = if line { 0.5 * x } else { t() };
                    ([1.0, x, y, x * x, x * y, y * y], t())
                })
                .collect();
            let (mut ata, mut atb) = normal_equations(&rows);
            match case % 5 {
                1 => {
                    for r in 3..6 {
                        ata[r] = [0.0; 6];
                        for row in &mut ata {
                            row[r] = 0.0;
                        }
                        ata[r][r] = 1.0;
                        atb[r] = 0.0;
                    }
                }
                2 => {
                    for row in &mut ata {
                        for x in row.iter_mut() {
                            *x = t();
                        }
                    }
                    if case % 11 == 0 {
                        ata[(case / 5) % 6][(case / 7) % 6] = f64::NAN;
                    }
                }
                _ => {}
            }
            let want = solve6_reference(ata, atb);
            assert_eq!(bits(solve6(ata, atb)), bits(want), "case {case}");
            if want.is_some() {
                solved += 1;
            } else {
                singular += 1;
            }
        }
        // Both answers met often (measured: see the message).
        eprintln!("solved {solved}, singular {singular}");
        assert!(solved > 5_000 && singular > 1_000, "{solved} solved, {singular} singular");
    }

    #[test]
    fn mirrored_normal_equations_are_the_whole_sums() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let bits = |m: &([[f64; 6]; 6], [f64; 6])| {
            (m.0.map(|r| r.map(f64::to_bits)), m.1.map(f64::to_bits))
        };
        for len in 0..80 {
            // Heights and terms of mixed signs and scales, some exact
            // zeros of either sign (the first term is the rows' 1).
            let rows: Vec<HeightRow> = (0..len)
                .map(|_| {
                    let mut t = || match (rng.unit() * 8.0) as u32 {
                        0 => 0.0,
                        1 => -0.0,
                        _ => (rng.unit() - 0.5) * 10f64.powi((rng.unit() * 12.0) as i32 - 6),
                    };
                    let (x, y) = (t(), t());
                    ([1.0, x, y, x * x, x * y, y * y], t())
                })
                .collect();
            let want = normal_equations_whole(&rows);
            assert_eq!(bits(&normal_equations(&rows)), bits(&want), "{len} rows");
            assert_eq!(bits(&mirrored_sums(&rows)), bits(&want), "{len} rows, portable");
        }
    }
}
