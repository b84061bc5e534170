//! The inverse of a small square matrix by LU decomposition with partial pivoting, written out
//! over arrays: bit for bit nalgebra's `Matrix::try_inverse` for sizes above 4 (its
//! `lu::try_invert_to`: the same pivots, and every element's operations in the same order; a
//! test holds it to that), without its generic column views. The loaded statics invert their
//! 15 x 15 Jacobian for every chord of their quasi-Newton solve and for every linearisation
//! along a series; under `perf` nalgebra's inversion and its triangular solves took 8 % of an
//! analysis of joint springs + frame + backlash.

use nalgebra::SMatrix;

/// The inverse of `a` (N > 4), as nalgebra's `try_inverse` computes it; `None` where a pivot is
/// zero.
pub(crate) fn try_inverse<const N: usize>(a: &SMatrix<f64, N, N>) -> Option<SMatrix<f64, N, N>> {
    // Row-major copies: `m` becomes L (unit, below the diagonal) and U (on and above it) of
    // P A = L U; `b` starts as the identity, its rows swapped with `m`'s, and becomes A^-1.
    let mut m = [[0.0f64; N]; N];
    for (r, row) in m.iter_mut().enumerate() {
        for (c, x) in row.iter_mut().enumerate() {
            *x = a[(r, c)];
        }
    }
    let mut b = [[0.0f64; N]; N];
    for (i, row) in b.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    for i in 0..N {
        let piv = crate::lu3::pivot(&m, i);
        let diag = m[piv][i];
        if diag == 0.0 {
            return None;
        }
        if piv != i {
            // The whole rows: L's multipliers so far, the pivot column and U's part.
            m.swap(i, piv);
            b.swap(i, piv);
        }
        let inv_diag = 1.0 / diag;
        let pivot_row = m[i];
        for row in m.iter_mut().skip(i + 1) {
            row[i] *= inv_diag;
            let coeff = row[i];
            for k in i + 1..N {
                row[k] += -pivot_row[k] * coeff;
            }
        }
    }
    // L y = P e_k for every column at once (L's diagonal is one: nalgebra's division by it
    // leaves every value as it is).
    for i in 0..N - 1 {
        let coeffs = b[i];
        for r in i + 1..N {
            let l = m[r][i];
            for (x, c) in b[r].iter_mut().zip(&coeffs) {
                *x += -c * l;
            }
        }
    }
    // U x = y, from the last row up.
    for i in (0..N).rev() {
        let d = m[i][i];
        if d == 0.0 {
            return None;
        }
        for x in b[i].iter_mut() {
            *x /= d;
        }
        let coeffs = b[i];
        for r in 0..i {
            let u = m[r][i];
            for (x, c) in b[r].iter_mut().zip(&coeffs) {
                *x += -c * u;
            }
        }
    }
    Some(SMatrix::from_fn(|r, c| b[r][c]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::SMatrix;

    /// A pseudo-random matrix (a linear congruential sequence in [-1, 1)), `diag` added on the
    /// diagonal.
    fn matrix<const N: usize>(seed: u64, diag: f64) -> SMatrix<f64, N, N> {
        let mut s = seed;
        SMatrix::from_fn(|r, c| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let v = (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0;
            v + if r == c { diag } else { 0.0 }
        })
    }

    /// The inverse is nalgebra's to the bit, with and without row swaps, at the statics' size
    /// and another; a matrix with a zero column has none, as in nalgebra.
    #[test]
    fn the_inverse_is_nalgebra_s_to_the_bit() {
        for seed in 0..200 {
            // Diagonally dominant (few swaps) and general (many).
            for diag in [0.0, 0.3, 20.0] {
                let a = matrix::<15>(seed, diag);
                let ours = try_inverse(&a).unwrap();
                let theirs = a.try_inverse().unwrap();
                assert!(
                    ours.iter()
                        .zip(theirs.iter())
                        .all(|(x, y)| x.to_bits() == y.to_bits()),
                    "seed {seed}, diagonal {diag}"
                );
                let a = matrix::<7>(seed, diag);
                let (ours, theirs) = (try_inverse(&a).unwrap(), a.try_inverse().unwrap());
                assert!(ours
                    .iter()
                    .zip(theirs.iter())
                    .all(|(x, y)| x.to_bits() == y.to_bits()));
            }
        }
        let mut a = matrix::<15>(3, 0.0);
        a.column_mut(4).fill(0.0);
        assert!(try_inverse(&a).is_none() && a.try_inverse().is_none());
        // And it inverts.
        let a = matrix::<15>(7, 0.0);
        let e = (a * try_inverse(&a).unwrap() - SMatrix::<f64, 15, 15>::identity()).amax();
        assert!(e < 1e-10, "{e}");
    }
}
