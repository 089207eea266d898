//! The normal equations of a six-term least-squares fit (the quadratic
//! height fields of generation, `crate::splat::fit`), four entries at a
//! time on AVX2.
//!
//! Each entry is summed from zero over the rows in their order, one product
//! `a·b` a row, as the portable sums take them; a product and its mirror
//! (`b·a`) are equal, so every path gives the same matrix bit for bit.

use super::Isa;

/// One row: the six terms and the right-hand side.
pub type Row6 = ([f64; 6], f64);

/// The normal equations `(AᵀA, Aᵀh)` of `rows` on the path `isa`, or
/// `None` where the path is not AVX2 (or AVX-512) on a CPU that runs it:
/// the caller then takes its portable sums, which give the same entries.
#[must_use]
#[inline]
pub fn normal_equations6(rows: &[Row6], isa: Isa) -> Option<([[f64; 6]; 6], [f64; 6])> {
    match isa {
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2 | Isa::Avx512 if Isa::Avx2.supported() => {
            // SAFETY: the guard checked that the CPU runs AVX2.
            Some(unsafe { avx2_normal_equations(rows) })
        }
        _ => None,
    }
}

/// [`normal_equations6`] on AVX2: for each term `r`, the products of
/// `row[r]` with terms 0–3 in one register and with terms 4, 5 and `h` in
/// another, summed over the rows.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn avx2_normal_equations(rows: &[Row6]) -> ([[f64; 6]; 6], [f64; 6]) {
    use std::arch::x86_64::*;
    let mut lo = [_mm256_setzero_pd(); 6];
    let mut hi = [_mm256_setzero_pd(); 6];
    for (row, h) in rows {
        // SAFETY: `row` is six f64; the load reads its first four.
        let a = unsafe { _mm256_loadu_pd(row.as_ptr()) };
        let b = _mm256_set_pd(0.0, *h, row[5], row[4]);
        for r in 0..6 {
            let s = _mm256_set1_pd(row[r]);
            lo[r] = _mm256_add_pd(lo[r], _mm256_mul_pd(s, a));
            hi[r] = _mm256_add_pd(hi[r], _mm256_mul_pd(s, b));
        }
    }
    let mut ata = [[0f64; 6]; 6];
    let mut atb = [0f64; 6];
    for r in 0..6 {
        let (mut l, mut u) = ([0f64; 4], [0f64; 4]);
        // SAFETY: each store writes four f64 into a four-long array.
        unsafe {
            _mm256_storeu_pd(l.as_mut_ptr(), lo[r]);
            _mm256_storeu_pd(u.as_mut_ptr(), hi[r]);
        }
        ata[r] = [l[0], l[1], l[2], l[3], u[0], u[1]];
        atb[r] = u[2];
    }
    (ata, atb)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// The portable sums: each entry from zero over the rows in order.
    fn whole(rows: &[Row6]) -> ([[f64; 6]; 6], [f64; 6]) {
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

    /// Row sets of every length to 60, terms of mixed scales, signed zeros
    /// and a NaN row among them: every path this CPU runs gives the
    /// portable sums bit for bit (or leaves them to the portable path).
    #[test]
    fn every_path_gives_the_portable_sums() {
        let mut rng = SplitMix64::new(5);
        let mut f = |s: f64| (rng.next_f64() * 2.0 - 1.0) * s;
        let bits = |m: ([[f64; 6]; 6], [f64; 6])| {
            let mut v: Vec<u64> = m.0.iter().flatten().map(|x| x.to_bits()).collect();
            v.extend(m.1.iter().map(|x| x.to_bits()));
            v
        };
        let mut compared = 0;
        for len in 0..61 {
            let rows: Vec<Row6> = (0..len)
                .map(|i| {
                    let (x, y) = (f(1.0), f(1e-3));
                    let mut row = [1.0, x, y, x * x, x * y, y * y];
                    if i % 7 == 3 {
                        row[2] = -0.0;
                    }
                    if len == 37 && i == 5 {
                        row[4] = f64::NAN;
                    }
                    (row, f(1e3))
                })
                .collect();
            let want = bits(whole(&rows));
            for isa in super::super::available() {
                if let Some(got) = normal_equations6(&rows, isa) {
                    assert_eq!(bits(got), want, "{isa} at {len}");
                    compared += 1;
                }
            }
        }
        if Isa::Avx2.supported() {
            assert!(compared >= 61);
        }
    }
}
