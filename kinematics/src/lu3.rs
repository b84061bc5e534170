//! The 3x3 LU decomposition with partial pivoting that the forward kinematics' Newton steps and
//! the Jacobian solve with, written out for 3x3: bit for bit nalgebra's `Matrix3::lu()` and
//! `LU::solve` (the same pivots, the same operations in the same order; a test holds them to
//! it), without its generic loops (under `perf` its `LU::new` and triangular solves took 3-4 %
//! of a residual analysis, most of it on these 3x3 systems).

use nalgebra::{Matrix3, Vector3};

/// A 3x3 matrix decomposed as P A = L U (L unit lower, U upper, stored together).
#[derive(Debug, Clone, Copy)]
pub struct Lu3 {
    /// Row-major: below the diagonal L's multipliers, on and above it U.
    m: [[f64; 3]; 3],
    /// The row swaps, in order (none where the pivot was already in place).
    swaps: [(usize, usize); 3],
    n_swaps: usize,
}

/// The row of column `i`'s pivot in `m` (row-major): the first largest magnitude on or below
/// the diagonal, as nalgebra's `icamax` finds it (its LU decomposition's and inversion's).
#[inline]
pub(crate) fn pivot<const N: usize>(m: &[[f64; N]; N], i: usize) -> usize {
    let mut piv = i;
    let mut best = m[i][i].abs();
    for (r, row) in m.iter().enumerate().skip(i + 1) {
        let v = row[i].abs();
        if v > best {
            best = v;
            piv = r;
        }
    }
    piv
}

impl Lu3 {
    /// Decomposes `a` (nalgebra's `LU::new`: the first largest magnitude of each column on or
    /// below the diagonal is the pivot; a column with none above zero is skipped).
    #[inline]
    pub fn new(a: &Matrix3<f64>) -> Lu3 {
        let mut m = [[0.0; 3]; 3];
        for (r, row) in m.iter_mut().enumerate() {
            for (c, x) in row.iter_mut().enumerate() {
                *x = a[(r, c)];
            }
        }
        let mut swaps = [(0, 0); 3];
        let mut n_swaps = 0;
        for i in 0..3 {
            let piv = pivot(&m, i);
            let diag = m[piv][i];
            if diag == 0.0 {
                continue;
            }
            if piv != i {
                swaps[n_swaps] = (i, piv);
                n_swaps += 1;
                m.swap(i, piv);
            }
            let inv = 1.0 / diag;
            for r in i + 1..3 {
                m[r][i] *= inv;
            }
            for k in i + 1..3 {
                let p = -m[i][k];
                for r in i + 1..3 {
                    m[r][k] += p * m[r][i];
                }
            }
        }
        Lu3 { m, swaps, n_swaps }
    }

    /// Solves A x = b in place (nalgebra's `LU::solve_mut` on one column); `false` where U has a
    /// zero on its diagonal (`b` then holds a partial result, as nalgebra leaves it).
    #[inline]
    fn solve_in(&self, b: &mut [f64; 3]) -> bool {
        for &(i, j) in &self.swaps[..self.n_swaps] {
            b.swap(i, j);
        }
        let m = &self.m;
        // L's diagonal is one: nalgebra divides by it, which changes no value.
        for i in 0..2 {
            let c = -b[i];
            for r in i + 1..3 {
                b[r] += c * m[r][i];
            }
        }
        for i in (0..3).rev() {
            let d = m[i][i];
            if d == 0.0 {
                return false;
            }
            let c = b[i] / d;
            b[i] = c;
            let c = -c;
            for r in 0..i {
                b[r] += c * m[r][i];
            }
        }
        true
    }

    /// x with A x = b, or `None` where A is singular (nalgebra's `LU::solve`).
    #[inline]
    pub fn solve(&self, b: &Vector3<f64>) -> Option<Vector3<f64>> {
        let mut x = [b[0], b[1], b[2]];
        self.solve_in(&mut x)
            .then(|| Vector3::new(x[0], x[1], x[2]))
    }

    /// X with A X = B, column by column, or `None` where A is singular.
    #[inline]
    pub fn solve_matrix(&self, b: &Matrix3<f64>) -> Option<Matrix3<f64>> {
        let mut out = Matrix3::zeros();
        for c in 0..3 {
            let mut x = [b[(0, c)], b[(1, c)], b[(2, c)]];
            if !self.solve_in(&mut x) {
                return None;
            }
            for r in 0..3 {
                out[(r, c)] = x[r];
            }
        }
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// The bits of each entry, every NaN as one (a NaN's sign bit is the one thing that may
    /// differ: nalgebra multiplies by one where this does not).
    fn bits(v: &[f64]) -> Vec<u64> {
        v.iter()
            .map(|x| {
                if x.is_nan() {
                    f64::NAN.to_bits()
                } else {
                    x.to_bits()
                }
            })
            .collect()
    }

    /// Random matrices, with repeated magnitudes (pivot ties), zero columns, exact zeros, signed
    /// zeros, huge and tiny entries and NaN: the same answers as nalgebra, bit for bit (NaN for
    /// NaN).
    #[test]
    fn solves_bit_for_bit_as_nalgebra_does() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let specials = [0.0, -0.0, 1.0, -1.0, 2.0, 1e-300, 1e300, f64::NAN, 3.0];
        let (mut solved, mut singular) = (0, 0);
        for trial in 0..200_000 {
            let mut a = Matrix3::from_fn(|_, _| rng.random_range(-10.0..10.0));
            let b = Vector3::from_fn(|_, _| rng.random_range(-10.0..10.0));
            let bm = Matrix3::from_fn(|_, _| rng.random_range(-10.0..10.0));
            if trial % 3 == 1 {
                for _ in 0..rng.random_range(1..5) {
                    let (r, c) = (rng.random_range(0..3), rng.random_range(0..3));
                    a[(r, c)] = specials[rng.random_range(0..specials.len())];
                }
            }
            if trial % 7 == 2 {
                let c = rng.random_range(0..3);
                let v = a[(0, c)];
                for r in 0..3 {
                    a[(r, c)] = if rng.random_bool(0.5) { v } else { -v };
                }
            }
            let same = |want: Option<&[f64]>, got: Option<&[f64]>, rhs: &dyn std::fmt::Display| {
                assert_eq!(want.map(bits), got.map(bits), "{a} {rhs}");
            };
            let (want, got) = (a.lu().solve(&b), Lu3::new(&a).solve(&b));
            same(
                want.as_ref().map(|x| x.as_slice()),
                got.as_ref().map(|x| x.as_slice()),
                &b,
            );
            let (want, got) = (a.lu().solve(&bm), Lu3::new(&a).solve_matrix(&bm));
            same(
                want.as_ref().map(|x| x.as_slice()),
                got.as_ref().map(|x| x.as_slice()),
                &bm,
            );
            if want.is_some() {
                solved += 1;
            } else {
                singular += 1;
            }
        }
        assert!(solved > 100_000 && singular > 100, "{solved} {singular}");
    }
}
