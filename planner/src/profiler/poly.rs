//! Small fixed-capacity real polynomials and a robust real-root finder on an interval.
//!
//! The profile shapes are solved by building, at run time, the polynomial equation of one shape
//! parameter (see `shapes.rs`) and isolating all of its real roots in the parameter's admissible
//! interval. No allocation: coefficients live in a fixed array.

/// Maximal degree a [`Poly`] can hold. The largest equation is the homogenised final position
/// of the no-plateau shape (`shapes.rs`): phase durations of degree 2 times the parameter, state
/// `(u^3 p, u^2 v, u a)`, so degree 6; every intermediate product stays within it.
pub const MAX_DEGREE: usize = 6;

/// Capacity of a root list: simple roots plus (near-)double roots reported at critical points.
pub const ROOTS_CAP: usize = 2 * MAX_DEGREE + 2;

/// A real polynomial `c[0] + c[1] x + ... + c[deg] x^deg` of degree at most [`MAX_DEGREE`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Poly {
    /// Coefficients, lowest degree first; entries above `deg` are zero.
    pub c: [f64; MAX_DEGREE + 1],
    /// Formal degree (the leading coefficient may be zero).
    pub deg: usize,
}

impl Poly {
    /// The constant polynomial `k`.
    pub fn constant(k: f64) -> Self {
        let mut c = [0.0; MAX_DEGREE + 1];
        c[0] = k;
        Poly { c, deg: 0 }
    }

    /// The polynomial `c0 + c1 x`.
    pub fn linear(c0: f64, c1: f64) -> Self {
        let mut p = Self::constant(c0);
        p.c[1] = c1;
        p.deg = 1;
        p
    }

    /// The identity polynomial `x`.
    pub fn x() -> Self {
        Self::linear(0.0, 1.0)
    }

    /// Sum.
    #[inline]
    pub fn add(&self, o: &Poly) -> Poly {
        // Fixed-length loops (entries above `deg` are zero): unrolled and vectorised, and the
        // same result as looping to the degree.
        let mut r = *self;
        r.deg = self.deg.max(o.deg);
        for (rc, oc) in r.c.iter_mut().zip(&o.c) {
            *rc += oc;
        }
        r
    }

    /// Difference.
    #[inline]
    pub fn sub(&self, o: &Poly) -> Poly {
        let mut r = *self;
        r.deg = self.deg.max(o.deg);
        for (rc, oc) in r.c.iter_mut().zip(&o.c) {
            *rc -= oc;
        }
        r
    }

    /// Product with a scalar.
    #[inline]
    pub fn scale(&self, k: f64) -> Poly {
        let mut r = *self;
        for v in r.c.iter_mut() {
            *v *= k;
        }
        r
    }

    /// Sum with a scalar.
    #[inline]
    pub fn add_const(&self, k: f64) -> Poly {
        let mut r = *self;
        r.c[0] += k;
        r
    }

    /// Product. Panics in debug builds if the degree would exceed [`MAX_DEGREE`]
    /// (all products in this crate stay below it by construction).
    pub fn mul(&self, o: &Poly) -> Poly {
        debug_assert!(self.deg + o.deg <= MAX_DEGREE);
        let mut r = Poly::constant(0.0);
        r.deg = (self.deg + o.deg).min(MAX_DEGREE);
        for i in 0..=self.deg {
            if self.c[i] == 0.0 {
                continue;
            }
            for j in 0..=o.deg {
                if i + j <= MAX_DEGREE {
                    r.c[i + j] += self.c[i] * o.c[j];
                }
            }
        }
        r
    }

    /// Product with `o` for `self` of degree at most 2 (the phase durations): fixed-length,
    /// branch-free loops with the same operations in the same order as [`Poly::mul`] (the extra
    /// terms are exact zeros), so the same result.
    #[inline]
    pub fn mul_low(&self, o: &Poly) -> Poly {
        debug_assert!(self.deg <= 2 && self.deg + o.deg <= MAX_DEGREE);
        let mut r = Poly::constant(0.0);
        r.deg = (self.deg + o.deg).min(MAX_DEGREE);
        let (t0, t1, t2) = (self.c[0], self.c[1], self.c[2]);
        for k in 0..=MAX_DEGREE {
            r.c[k] = t0 * o.c[k];
        }
        for k in 1..=MAX_DEGREE {
            r.c[k] += t1 * o.c[k - 1];
        }
        for k in 2..=MAX_DEGREE {
            r.c[k] += t2 * o.c[k - 2];
        }
        r
    }

    /// Value at `x` (Horner).
    #[inline]
    pub fn eval(&self, x: f64) -> f64 {
        // Unrolled per degree (no loop over coefficients in memory); the same operations in the
        // same order as the loop below.
        let c = &self.c;
        match self.deg {
            0 => c[0],
            1 => c[1] * x + c[0],
            2 => (c[2] * x + c[1]) * x + c[0],
            3 => ((c[3] * x + c[2]) * x + c[1]) * x + c[0],
            4 => (((c[4] * x + c[3]) * x + c[2]) * x + c[1]) * x + c[0],
            5 => ((((c[5] * x + c[4]) * x + c[3]) * x + c[2]) * x + c[1]) * x + c[0],
            6 => (((((c[6] * x + c[5]) * x + c[4]) * x + c[3]) * x + c[2]) * x + c[1]) * x + c[0],
            _ => {
                let mut acc = 0.0;
                for i in (0..=self.deg.min(MAX_DEGREE)).rev() {
                    acc = acc * x + c[i];
                }
                acc
            }
        }
    }

    /// Derivative.
    pub fn deriv(&self) -> Poly {
        let mut r = Poly::constant(0.0);
        if self.deg == 0 {
            return r;
        }
        r.deg = self.deg - 1;
        for i in 1..=self.deg {
            r.c[i - 1] = self.c[i] * i as f64;
        }
        r
    }

    /// True if `|p|` is provably bounded away from zero on `[lo, hi]` (so there is no root and
    /// no negligible value anywhere there): with the Taylor coefficients `b_k` at the midpoint
    /// `m` and the half-width `r`, `|p(x) - b_0| <= sum_{k>=1} |b_k| r^k`. The margin covers the
    /// rounding of the shift and the "negligible" scale of [`Poly::roots_in`] generously.
    fn excludes_roots(&self, lo: f64, hi: f64) -> bool {
        let d = self.deg;
        let m = 0.5 * (lo + hi);
        let r = 0.5 * (hi - lo);
        // Taylor shift by repeated synthetic division, over the full (fixed) length so that it
        // is unrolled into registers; the coefficients above the degree are zero and stay so.
        let mut b = self.c;
        for i in 0..MAX_DEGREE {
            for k in (i..MAX_DEGREE).rev() {
                b[k] += m * b[k + 1];
            }
        }
        let (mut bound, mut mag, mut rk, mut xk) = (0.0f64, 0.0f64, 1.0f64, 1.0f64);
        let xm = m.abs() + r;
        for (k, (bk, ck)) in b.iter().zip(&self.c).enumerate().take(d + 1) {
            if k > 0 {
                bound += bk.abs() * rk;
            }
            mag += ck.abs() * xk;
            rk *= r;
            xk *= xm;
        }
        b[0].abs() > bound + 1e-10 * mag
    }

    /// All real roots in `[lo, hi]`, ascending, written into `out`; returns their count.
    ///
    /// The interval is split at the roots of the derivative (found recursively) into pieces on
    /// which the polynomial is monotone; each piece with a sign change is bisected to full
    /// precision. A critical point where the value is negligible (a double root) is reported
    /// as a root as well, so that tangential solutions are not lost; callers validate every
    /// root anyway.
    pub fn roots_in(&self, lo: f64, hi: f64, out: &mut [f64; ROOTS_CAP]) -> usize {
        if lo > hi || !lo.is_finite() || !hi.is_finite() {
            return 0;
        }
        // Read in place (a copy of a just-built polynomial stalls on store forwarding); copy
        // only to drop zero leading coefficients.
        let mut deg = self.deg;
        while deg > 0 && self.c[deg] == 0.0 {
            deg -= 1;
        }
        if deg != self.deg {
            let mut p = *self;
            p.deg = deg;
            return p.roots_in_exact(lo, hi, out);
        }
        self.roots_in_exact(lo, hi, out)
    }

    /// [`Poly::roots_in`] for a polynomial whose leading coefficient is not zero.
    fn roots_in_exact(&self, lo: f64, hi: f64, out: &mut [f64; ROOTS_CAP]) -> usize {
        let p = self;
        match p.deg {
            0 => 0,
            2 => quadratic_roots_in(p, lo, hi, out),
            3 => cubic_roots_in(p, lo, hi, out),
            1 => {
                let r = -p.c[0] / p.c[1];
                if r >= lo && r <= hi {
                    out[0] = r;
                    1
                } else {
                    0
                }
            }
            4 => {
                if p.excludes_roots4(lo, hi) {
                    return 0;
                }
                match quartic_roots_in(p, lo, hi, out) {
                    Some(n) => n,
                    None => p.isolate_roots(lo, hi, out),
                }
            }
            _ if p.excludes_roots(lo, hi) => 0,
            _ => p.isolate_roots(lo, hi, out),
        }
    }

    /// [`Poly::excludes_roots`] for a quartic, with the Taylor coefficients at the midpoint
    /// written out (independent products instead of a chain of synthetic divisions).
    fn excludes_roots4(&self, lo: f64, hi: f64) -> bool {
        let [c0, c1, c2, c3, c4, ..] = self.c;
        let m = 0.5 * (lo + hi);
        let r = 0.5 * (hi - lo);
        let m2 = m * m;
        let b3 = c3 + 4.0 * c4 * m;
        let b2 = c2 + 3.0 * c3 * m + 6.0 * c4 * m2;
        let b1 = c1 + 2.0 * c2 * m + (3.0 * c3 + 4.0 * c4 * m) * m2;
        let b0 = c0 + m * (c1 + m * (c2 + m * (c3 + m * c4)));
        let r2 = r * r;
        let bound = (b1.abs() + b2.abs() * r) * r + (b3.abs() + c4.abs() * r) * r * r2;
        let xm = m.abs() + r;
        let xm2 = xm * xm;
        let mag =
            c0.abs() + c1.abs() * xm + (c2.abs() + c3.abs() * xm) * xm2 + c4.abs() * xm2 * xm2;
        b0.abs() > bound + 1e-10 * mag
    }

    /// The general root isolation of [`Poly::roots_in`] (degree >= 4): split at the roots of
    /// the derivative, safeguarded Newton iteration in every monotone piece with a sign change.
    fn isolate_roots(&self, lo: f64, hi: f64, out: &mut [f64; ROOTS_CAP]) -> usize {
        let p = *self;
        let mut crit = [0.0; ROOTS_CAP];
        let dp = p.deriv();
        let nc = dp.roots_in(lo, hi, &mut crit);
        let mut pts = [0.0; ROOTS_CAP + 2];
        pts[0] = lo;
        pts[1..=nc].copy_from_slice(&crit[..nc]);
        pts[nc + 1] = hi;
        let npts = nc + 2;
        let xs = lo.abs().max(hi.abs()).max(1e-300);
        let mut n = 0;
        let mut push = |r: f64, n: &mut usize| {
            if *n > 0 && (r - out[*n - 1]).abs() <= 1e-14 * xs {
                return;
            }
            if *n < ROOTS_CAP {
                out[*n] = r;
                *n += 1;
            }
        };
        for k in 0..npts - 1 {
            let (a, b) = (pts[k], pts[k + 1]);
            let (fa, fb) = (p.eval(a), p.eval(b));
            if fa == 0.0 {
                push(a, &mut n);
                continue;
            }
            if k > 0 && fa.abs() <= tiny_at(&p, a) {
                // Possibly a double root at a critical point; keep looking for a
                // sign change in the piece as well.
                push(a, &mut n);
            }
            if fa.signum() != fb.signum() && fb != 0.0 {
                push(bisect(&p, &dp, a, b, fa), &mut n);
            }
        }
        let fh = p.eval(hi);
        if fh == 0.0 {
            push(hi, &mut n);
        }
        n
    }
}

/// Rounding-error scale of evaluating `p` at `x`: below it a value is negligible.
fn tiny_at(p: &Poly, x: f64) -> f64 {
    let mut mag = 0.0f64;
    let mut xp = 1.0;
    for i in 0..=p.deg {
        mag += (p.c[i] * xp).abs();
        xp *= x.abs();
    }
    mag * 1e-13
}

/// [`Poly::roots_in`] for an exact quadratic (`c[2] != 0`), in closed form: the numerically
/// stable pair `q = -(b + sign(b) sqrt(b^2 - 4ac)) / 2`, roots `q / a` and `c / q`. As the
/// general routine, the vertex is reported as well when the value there is negligible (a
/// double root, possibly with a slightly negative discriminant).
fn quadratic_roots_in(p: &Poly, lo: f64, hi: f64, out: &mut [f64; ROOTS_CAP]) -> usize {
    let (c, b, a) = (p.c[0], p.c[1], p.c[2]);
    let mut cand = [f64::NAN; 3];
    let disc = b * b - 4.0 * a * c;
    if disc >= 0.0 {
        let q = -0.5 * (b + disc.sqrt().copysign(b));
        if q != 0.0 {
            cand[0] = q / a;
            cand[1] = c / q;
        } else {
            cand[0] = 0.0;
        }
    }
    let xv = -b / (2.0 * a);
    if xv > lo && xv < hi && p.eval(xv).abs() <= tiny_at(p, xv) {
        cand[2] = xv;
    }
    collect_roots(&mut cand, lo, hi, out)
}

/// Writes the finite candidates of `cand` within `[lo, hi]` into `out`, ascending, dropping
/// near-duplicates (as the general routine); returns their count.
fn collect_roots(cand: &mut [f64], lo: f64, hi: f64, out: &mut [f64; ROOTS_CAP]) -> usize {
    // Keep the candidates in range (NaN is not), then an insertion sort of the few left.
    let mut m = 0;
    for i in 0..cand.len() {
        let r = cand[i];
        if r >= lo && r <= hi {
            let mut k = m;
            while k > 0 && cand[k - 1] > r {
                cand[k] = cand[k - 1];
                k -= 1;
            }
            cand[k] = r;
            m += 1;
        }
    }
    let xs = lo.abs().max(hi.abs()).max(1e-300);
    let mut n = 0;
    for &r in cand[..m].iter() {
        if n > 0 && (r - out[n - 1]).abs() <= 1e-14 * xs {
            continue;
        }
        out[n] = r;
        n += 1;
    }
    n
}

/// Two Newton steps on `p` from `x`, each kept only if it does not increase `|p|`.
#[inline]
fn newton_polish(p: &Poly, dp: &Poly, mut x: f64) -> f64 {
    let mut fx = p.eval(x);
    for _ in 0..2 {
        let d = dp.eval(x);
        if fx == 0.0 || d == 0.0 {
            break;
        }
        let y = x - fx / d;
        let fy = p.eval(y);
        if fy.is_nan() || fy.abs() > fx.abs() {
            break;
        }
        (x, fx) = (y, fy);
    }
    x
}

/// [`Poly::roots_in`] for an exact cubic (`c[3] != 0`), in closed form (Cardano with the
/// cancellation-free pair for one real root, the trigonometric form for three), each root
/// polished by Newton steps on `p`. As the general routine, a critical point is reported as
/// well when the value there is negligible (a double root the closed form may split or lose).
fn cubic_roots_in(p: &Poly, lo: f64, hi: f64, out: &mut [f64; ROOTS_CAP]) -> usize {
    let a = p.c[3];
    let (b, c, d) = (p.c[2] / a, p.c[1] / a, p.c[0] / a);
    // x = y - b/3: y^3 + 3 q y - 2 r = 0.
    let shift = b / 3.0;
    let q = (3.0 * c - b * b) / 9.0;
    let r = (9.0 * b * c - 27.0 * d - 2.0 * b * b * b) / 54.0;
    let disc = q * q * q + r * r;
    let dp = p.deriv();
    let mut cand = [f64::NAN; 5];
    if disc > 0.0 {
        let s1 = (r + disc.sqrt().copysign(r)).cbrt();
        let y = if s1 != 0.0 { s1 - q / s1 } else { 0.0 };
        cand[0] = newton_polish(p, &dp, y - shift);
    } else {
        // q <= 0 here.
        let m = (-q).sqrt();
        let cos_arg = if m > 0.0 {
            (r / (m * m * m)).clamp(-1.0, 1.0)
        } else {
            0.0
        };
        let th = cos_arg.acos() / 3.0;
        let k = std::f64::consts::TAU / 3.0;
        for (i, cv) in cand.iter_mut().take(3).enumerate() {
            let y = 2.0 * m * (th + k * i as f64).cos();
            *cv = newton_polish(p, &dp, y - shift);
        }
    }
    // Critical points (roots of the derivative) with a negligible value.
    let mut crit = [0.0; ROOTS_CAP];
    let nc = quadratic_roots_in(&dp, lo, hi, &mut crit);
    for (i, &x) in crit[..nc].iter().enumerate() {
        if p.eval(x).abs() <= tiny_at(p, x) {
            cand[3 + i] = x;
        }
    }
    collect_roots(&mut cand, lo, hi, out)
}

/// Largest real root of the monic cubic `x^3 + b x^2 + c x + d` (closed form: Cardano with the
/// cancellation-free pair for one real root, the trigonometric form for three), polished by
/// two Newton steps.
fn cubic_largest_root(b: f64, c: f64, d: f64) -> f64 {
    let shift = b / 3.0;
    let q = (3.0 * c - b * b) / 9.0;
    let r = (9.0 * b * c - 27.0 * d - 2.0 * b * b * b) / 54.0;
    let disc = q * q * q + r * r;
    let y = if disc > 0.0 {
        let s1 = (r + disc.sqrt().copysign(r)).cbrt();
        if s1 != 0.0 {
            s1 - q / s1
        } else {
            0.0
        }
    } else {
        let m = (-q).sqrt();
        let cos_arg = if m > 0.0 {
            (r / (m * m * m)).clamp(-1.0, 1.0)
        } else {
            0.0
        };
        2.0 * m * (cos_arg.acos() / 3.0).cos()
    };
    let mut x = y - shift;
    for _ in 0..2 {
        let f = ((x + b) * x + c) * x + d;
        let df = (3.0 * x + 2.0 * b) * x + c;
        if f == 0.0 || df == 0.0 {
            break;
        }
        let nx = x - f / df;
        let nf = ((nx + b) * nx + c) * nx + d;
        if nf.is_nan() || nf.abs() > f.abs() {
            break;
        }
        x = nx;
    }
    x
}

/// [`Poly::roots_in`] for an exact quartic in closed form (Ferrari): with `x = y - b/4` the
/// depressed quartic `y^4 + p y^2 + q y + r` is `(y^2 + p/2 + m)^2 - (s y - q/(2s))^2` for
/// `s = sqrt(2m)` and `m > 0` the largest root of the resolvent cubic
/// `m^3 + p m^2 + (p^2/4 - r) m - q^2/8`; its roots are those of the two quadratics
/// `y^2 -+ s y + p/2 + m +- q/(2s)`. Each root is polished by Newton steps on `p`. Where a
/// quadratic factor has a (slightly) negative discriminant its vertex is a candidate double root,
/// reported if the value there is negligible (as the general routine does at critical points).
/// Returns None if the closed form breaks down numerically (the caller then isolates the roots
/// iteratively).
fn quartic_roots_in(p: &Poly, lo: f64, hi: f64, out: &mut [f64; ROOTS_CAP]) -> Option<usize> {
    let a4 = p.c[4];
    let (b, c, d, e) = (p.c[3] / a4, p.c[2] / a4, p.c[1] / a4, p.c[0] / a4);
    let s4 = 0.25 * b;
    let s42 = s4 * s4;
    let pp = c - 6.0 * s42;
    let qq = d - 2.0 * c * s4 + 8.0 * s42 * s4;
    let rr = e - d * s4 + c * s42 - 3.0 * s42 * s42;
    let dp = p.deriv();
    // Candidate y values; `vertex` marks those that are the vertex of a complex pair.
    let mut ys = [f64::NAN; 4];
    let mut vertex = [false; 4];
    let mut ny = 0;
    let m = if qq != 0.0 {
        cubic_largest_root(pp, 0.25 * pp * pp - rr, -0.125 * qq * qq)
    } else {
        0.0
    };
    if !m.is_finite() {
        return None;
    }
    if m > 0.0 {
        // Quadratic factors y^2 + f1 y + f0.
        let s = (2.0 * m).sqrt();
        let h = qq / (2.0 * s);
        let base = 0.5 * pp + m;
        for (f1, f0) in [(-s, base + h), (s, base - h)] {
            let disc = f1 * f1 - 4.0 * f0;
            if disc >= 0.0 {
                let qd = -0.5 * (f1 + disc.sqrt().copysign(f1));
                if qd != 0.0 {
                    ys[ny] = qd;
                    ys[ny + 1] = f0 / qd;
                } else {
                    ys[ny] = 0.0;
                    ys[ny + 1] = 0.0;
                }
                ny += 2;
            } else {
                ys[ny] = -0.5 * f1;
                vertex[ny] = true;
                ny += 1;
            }
        }
    } else {
        // Biquadratic (q = 0): y^2 = z with z^2 + p z + r = 0.
        let disc = pp * pp - 4.0 * rr;
        if disc >= 0.0 {
            let qz = -0.5 * (pp + disc.sqrt().copysign(pp));
            let zs = if qz != 0.0 { [qz, rr / qz] } else { [0.0, 0.0] };
            for z in zs {
                if z >= 0.0 {
                    let y = z.sqrt();
                    ys[ny] = y;
                    ys[ny + 1] = -y;
                    ny += 2;
                } else {
                    ys[ny] = 0.0;
                    vertex[ny] = true;
                    ny += 1;
                }
            }
        } else {
            // z complex: critical points at y = 0 and y^2 = -p/2.
            ys[0] = 0.0;
            vertex[0] = true;
            ny = 1;
            if pp < 0.0 {
                let y = (-0.5 * pp).sqrt();
                ys[1] = y;
                ys[2] = -y;
                vertex[1] = true;
                vertex[2] = true;
                ny = 3;
            }
        }
    }
    let ddp = dp.deriv();
    let mut cand = [f64::NAN; 4];
    // Candidates clearly outside the range are not polished (polishing moves a root by far
    // less than this margin).
    let margin = 1e-6 * lo.abs().max(hi.abs()).max(hi - lo);
    for i in 0..ny {
        let x = ys[i] - s4;
        if !x.is_finite() {
            return None;
        }
        if x < lo - margin || x > hi + margin {
            continue;
        }
        cand[i] = if vertex[i] {
            // A complex pair near the axis is a (near) double root at a critical point:
            // move to the critical point and report it if the value there is negligible.
            let xc = newton_polish(&dp, &ddp, x);
            if p.eval(xc).abs() <= tiny_at(p, xc) {
                xc
            } else {
                f64::NAN
            }
        } else {
            newton_polish(p, &dp, x)
        };
    }
    Some(collect_roots(&mut cand[..ny], lo, hi, out))
}

/// Safeguarded Newton iteration on a bracket `[a, b]` where `p(a)` has the sign of `fa` and
/// `p(b)` the opposite sign: Newton steps while they stay inside the shrinking bracket, bisection
/// otherwise; converges to (nearly) adjacent floating point numbers.
fn bisect(p: &Poly, dp: &Poly, mut a: f64, mut b: f64, fa: f64) -> f64 {
    let sa = fa.signum();
    let mut x = 0.5 * (a + b);
    for _ in 0..100 {
        let fx = p.eval(x);
        if fx == 0.0 {
            return x;
        }
        if fx.signum() == sa {
            a = x;
        } else {
            b = x;
        }
        let d = dp.eval(x);
        let newton = x - fx / d;
        let (lo, hi) = (a.min(b), a.max(b));
        let next = if d != 0.0 && newton > lo && newton < hi {
            newton
        } else {
            0.5 * (a + b)
        };
        if (next - x).abs() <= 4.0 * f64::EPSILON * x.abs().max(f64::MIN_POSITIVE)
            || (hi - lo) <= 4.0 * f64::EPSILON * lo.abs().max(hi.abs())
        {
            return next;
        }
        x = next;
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    fn from_roots(rs: &[f64]) -> Poly {
        rs.iter().fold(Poly::constant(1.0), |acc, r| {
            acc.mul(&Poly::linear(-r, 1.0))
        })
    }

    #[test]
    fn finds_all_simple_roots() {
        let p = from_roots(&[-2.0, -0.5, 0.1, 0.3, 1.7, 4.0]);
        let mut out = [0.0; ROOTS_CAP];
        let n = p.roots_in(-10.0, 10.0, &mut out);
        assert_eq!(n, 6);
        for (r, e) in out[..n].iter().zip([-2.0, -0.5, 0.1, 0.3, 1.7, 4.0]) {
            assert!((r - e).abs() < 1e-12, "{r} vs {e}");
        }
        let n = p.roots_in(0.0, 1.0, &mut out);
        assert_eq!(n, 2);
    }

    #[test]
    fn finds_double_root() {
        let p = from_roots(&[1.0, 1.0, 3.0]);
        let mut out = [0.0; ROOTS_CAP];
        let n = p.roots_in(0.0, 2.0, &mut out);
        assert_eq!(n, 1);
        assert!((out[0] - 1.0).abs() < 1e-7);
    }

    #[test]
    fn quadratic_closed_form() {
        let mut out = [0.0; ROOTS_CAP];
        // Widely separated roots (cancellation-prone in the textbook formula).
        let p = from_roots(&[1e-9, 3e5]);
        let n = p.roots_in(-1.0, 1e6, &mut out);
        assert_eq!(n, 2);
        assert!((out[0] - 1e-9).abs() < 1e-22 && (out[1] - 3e5).abs() < 1e-9);
        // Range filter.
        assert_eq!(p.roots_in(1.0, 2.0, &mut out), 0);
        // Exact and rounded double roots are reported once.
        let p = from_roots(&[0.1, 0.1]);
        assert_eq!(p.roots_in(0.0, 1.0, &mut out), 1);
        assert!((out[0] - 0.1).abs() < 1e-7);
        let mut q = from_roots(&[0.5, 0.5]);
        q.c[0] += 1e-17;
        assert_eq!(q.roots_in(0.0, 1.0, &mut out), 1);
        assert!((out[0] - 0.5).abs() < 1e-7);
    }

    #[test]
    fn cubic_closed_form() {
        let mut out = [0.0; ROOTS_CAP];
        for rs in [
            [-2.0, 0.5, 3.0],
            [1e-6, 2.0, 2.000001],
            [-1e3, 0.1, 7.0],
            [0.3, 0.3, 0.3],
        ] {
            let p = from_roots(&rs).scale(-2.5);
            let n = p.roots_in(-1e4, 1e4, &mut out);
            // Roots, plus critical points where the value is negligible (close roots).
            assert!((1..=5).contains(&n), "{rs:?}: {n}");
            for r in rs {
                let near = out[..n]
                    .iter()
                    .any(|x| (x - r).abs() <= 1e-5 * r.abs().max(1.0));
                assert!(near, "{rs:?}: {:?}", &out[..n]);
            }
        }
        // One real root.
        let p = Poly::linear(1.0, 0.0).add(&Poly::x().mul(&Poly::x()).mul(&Poly::x()));
        assert_eq!(p.roots_in(-5.0, 5.0, &mut out), 1);
        assert!((out[0] + 1.0).abs() < 1e-14);
        assert_eq!(p.roots_in(0.0, 5.0, &mut out), 0);
    }

    #[test]
    fn quartic_closed_form_matches_isolation() {
        let mut seed = 777u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        let mut out = [0.0; ROOTS_CAP];
        let mut iso = [0.0; ROOTS_CAP];
        for k in 0..4000 {
            // Real roots (some repeated), or a complex pair, scaled over decades.
            let sc = 10f64.powf(2.0 * rnd());
            let r = [rnd() * sc, rnd() * sc, rnd() * sc, rnd() * sc];
            let mut p = match k % 4 {
                0 => from_roots(&r),
                1 => from_roots(&[r[0], r[0], r[1], r[2]]),
                2 => from_roots(&[r[0], r[1]]).mul(
                    &Poly::linear(r[2] * r[2] + (0.1 * sc).powi(2), -2.0 * r[2])
                        .add(&Poly::x().mul(&Poly::x())),
                ),
                _ => from_roots(&[r[0], r[0], r[1], r[1]]),
            };
            p = p.scale(1.0 + 3.0 * rnd().abs());
            let (lo, hi) = (-sc, sc);
            let n = quartic_roots_in(&p, lo, hi, &mut out).unwrap();
            let m = p.isolate_roots(lo, hi, &mut iso);
            // Every root found by the isolation is found (double roots are determined to about
            // the square root of the rounding error only).
            let tol = if k % 4 == 0 { 1e-9 } else { 1e-5 } * sc;
            for x in &iso[..m] {
                let near = out[..n].iter().any(|y| (x - y).abs() <= tol);
                assert!(near, "case {k}: {:?} vs {:?} ({p:?})", &out[..n], &iso[..m]);
            }
            for y in &out[..n] {
                assert!(p.eval(*y).abs() <= 1e3 * tiny_at(&p, *y), "case {k}: {y}");
            }
        }
    }

    #[test]
    fn quartic_exclusion_agrees_with_general_test() {
        let mut seed = 99u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        let mut iso = [0.0; ROOTS_CAP];
        let mut excluded = 0;
        for _ in 0..5000 {
            let sc = 10f64.powf(2.0 * rnd());
            let p = from_roots(&[rnd() * sc, rnd() * sc, rnd() * sc, rnd() * sc])
                .add(&Poly::constant(rnd() * sc.powi(4)));
            let (lo, hi) = (rnd() * sc, rnd() * sc);
            let (lo, hi) = (lo.min(hi), lo.max(hi));
            let e4 = p.excludes_roots4(lo, hi);
            let e = p.excludes_roots(lo, hi);
            if e4 {
                excluded += 1;
                assert_eq!(p.isolate_roots(lo, hi, &mut iso), 0);
            }
            // Same test up to rounding: they may only disagree when the margin is tight.
            if e4 != e {
                let m = 0.5 * (lo + hi);
                assert!(p.eval(m).abs() < 1e-6 * tiny_at(&p, m) * 1e13);
            }
        }
        assert!(excluded > 1000, "{excluded}");
    }

    #[test]
    fn no_roots_for_positive_polynomial() {
        let p = Poly::constant(1.0).add(&Poly::x().mul(&Poly::x()));
        let mut out = [0.0; ROOTS_CAP];
        assert_eq!(p.roots_in(-5.0, 5.0, &mut out), 0);
    }
}
