//! The box `lower <= x <= upper`: keeping the iteration strictly inside it, the Coleman-Li
//! scaling near its faces, and which parameters ended on it.

use nalgebra::DVector;

/// The bounds of every parameter (infinite where a side is open), in the parameters' units.
pub(super) struct Bounds {
    /// Lower bounds.
    pub(super) lower: DVector<f64>,
    /// Upper bounds.
    pub(super) upper: DVector<f64>,
}

impl Bounds {
    /// The box from its lower and upper bounds (same length, `lower < upper`).
    pub(super) fn new(lower: &[f64], upper: &[f64]) -> Self {
        Bounds {
            lower: DVector::from_column_slice(lower),
            upper: DVector::from_column_slice(upper),
        }
    }

    /// Whether `x` lies in the box (its faces included).
    pub(super) fn contains(&self, x: &DVector<f64>) -> bool {
        (0..x.len()).all(|k| x[k] >= self.lower[k] && x[k] <= self.upper[k])
    }

    /// Moves `x` strictly inside the box (one ulp inwards, at least a relative 1e-10, where it
    /// sits on or beyond a bound).
    pub(super) fn strictly_feasible(&self, x: &DVector<f64>) -> DVector<f64> {
        let (lb, ub) = (&self.lower, &self.upper);
        DVector::from_fn(x.len(), |k, _| {
            if x[k] <= lb[k] {
                next_towards(lb[k], ub[k])
            } else if x[k] >= ub[k] {
                next_towards(ub[k], lb[k])
            } else {
                x[k]
            }
        })
    }

    /// Coleman-Li scaling vector v at `x` with gradient `g` and its derivative dv: where the
    /// gradient points out of the box towards a finite bound, v is the distance to that bound
    /// (units of x) and dv its sign; elsewhere v = 1 and dv = 0.
    pub(super) fn coleman_li_scaling(
        &self,
        x: &DVector<f64>,
        g: &DVector<f64>,
    ) -> (DVector<f64>, DVector<f64>) {
        let (lb, ub) = (&self.lower, &self.upper);
        let n = x.len();
        let mut v = DVector::from_element(n, 1.0);
        let mut dv = DVector::zeros(n);
        for k in 0..n {
            if g[k] < 0.0 && ub[k].is_finite() {
                v[k] = ub[k] - x[k];
                dv[k] = -1.0;
            } else if g[k] > 0.0 && lb[k].is_finite() {
                v[k] = x[k] - lb[k];
                dv[k] = 1.0;
            }
        }
        (v, dv)
    }

    /// Which components of `x` lie on a bound (within 1e-10 relative, at least 1e-10 absolute).
    pub(super) fn at_bound(&self, x: &DVector<f64>) -> Vec<bool> {
        let (lb, ub) = (&self.lower, &self.upper);
        (0..x.len())
            .map(|k| {
                let tol = 1e-10 * x[k].abs().max(1.0);
                (x[k] - lb[k]).abs() <= tol || (ub[k] - x[k]).abs() <= tol
            })
            .collect()
    }
}

/// The next representable number after `a` in the direction of `b`.
fn next_towards(a: f64, b: f64) -> f64 {
    if !a.is_finite() || a == b {
        return a;
    }
    let bits = a.to_bits();
    let up = b > a;
    let next = if a == 0.0 {
        if up {
            f64::from_bits(1)
        } else {
            -f64::from_bits(1)
        }
    } else if (a > 0.0) == up {
        f64::from_bits(bits + 1)
    } else {
        f64::from_bits(bits - 1)
    };
    // Keep a relative margin so that sqrt(v) of the Coleman-Li scaling is not denormal.
    let margin = 1e-10 * a.abs().max(1e-10);
    if up {
        next.max(a + margin).min(b)
    } else {
        next.min(a - margin).max(b)
    }
}
