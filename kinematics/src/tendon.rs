//! The robot-dependent model: tendon displacement to curvature (the regression families of the
//! paper's Table I), its derivative and its inverse, and the motor-step conversion.
//!
//! Odd extension: every non-constant basis function b(dl) is evaluated as
//! `sgn(dl) * b(|dl|)`, so that a map fitted to positive displacements bends the segment the
//! other way by the same amount for negative ones; the constant k0 stays an offset. The
//! polynomial terms therefore read `dl`, `dl|dl|`, `dl^3`.
//!
//! Asymmetric reading ([`MapReading::Asymmetric`]): the same odd-extended terms with one set of
//! coefficients for dl >= 0 and another for dl < 0, sharing k0 (a leg whose two tendons bend it
//! differently). For dl >= 0 this is the paper's form as written.

use pcr_robot::{Actuation, LegConfig, MapForm, MapReading, TendonMapKind, TendonMapSpec};

/// Why a curvature could not be mapped back to a tendon displacement.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TendonMapError {
    /// The requested curvature is outside the range the map reaches in the search interval.
    #[error("curvature {kappa} 1/mm is outside the tendon map's range [{lo}, {hi}] 1/mm")]
    OutOfRange {
        /// Requested curvature.
        kappa: f64,
        /// Smallest reachable curvature.
        lo: f64,
        /// Largest reachable curvature.
        hi: f64,
    },
    /// The map is not monotonic where the inverse was needed.
    #[error("tendon map `{0}` is not monotonic on the search interval; it cannot be inverted")]
    NotMonotonic(TendonMapKind),
}

/// Largest |dl| (mm) the inverse searches: far beyond any tendon travel of the prototype.
pub const DL_SEARCH_MM: f64 = 60.0;

/// An evaluated tendon map kappa = f(dl) of one leg.
#[derive(Debug, Clone)]
pub struct TendonMap {
    kind: TendonMapKind,
    reading: MapReading,
    /// Coefficients with k0 first (k0 = 0 for families without an offset), for dl >= 0.
    k: [f64; 7],
    /// Coefficients for dl < 0 (the same as `k` in the symmetric reading; `k_neg[0] = k[0]`).
    k_neg: [f64; 7],
    n: usize,
    /// The interval around dl = 0 (within +-[`DL_SEARCH_MM`]) on which the map is strictly
    /// monotonic: the branch the inverse searches, so that a map that turns back far from
    /// the operating range (a cubic with a negative k3) is inverted on the physical branch.
    /// Found on first use (a fit evaluates many maps it never inverts).
    branch: std::sync::OnceLock<[f64; 2]>,
}

/// Two maps are equal when their family, reading and coefficients are (the branch follows).
impl PartialEq for TendonMap {
    fn eq(&self, other: &TendonMap) -> bool {
        self.kind == other.kind
            && self.reading == other.reading
            && self.k == other.k
            && self.k_neg == other.k_neg
            && self.n == other.n
    }
}

/// The j-th root of `a` >= 0 (square and cube roots exact and cheaper than `powf`).
fn root(a: f64, j: usize) -> f64 {
    match j {
        2 => a.sqrt(),
        3 => a.cbrt(),
        4 => a.sqrt().sqrt(),
        6 => a.cbrt().sqrt(),
        _ => a.powf(1.0 / j as f64),
    }
}

#[inline]
fn odd(dl: f64, v: f64) -> f64 {
    if dl < 0.0 {
        -v
    } else {
        v
    }
}

impl TendonMap {
    /// Builds the map of a leg from its configuration (the linear map with no coefficients is
    /// the nominal `1 / (a l_C)`).
    pub fn from_leg(leg: &LegConfig) -> TendonMap {
        let spec = &leg.tendon_map;
        if spec.model == TendonMapKind::Linear && spec.coeffs.is_empty() {
            return TendonMap::new(
                TendonMapKind::Linear,
                &[1.0 / (leg.actuation.tendon_offset_mm * leg.l_c_mm)],
            );
        }
        TendonMap::from_spec(spec)
    }

    /// Builds a map from a validated specification (either reading).
    pub fn from_spec(spec: &TendonMapSpec) -> TendonMap {
        match spec.reading {
            MapReading::Symmetric => TendonMap::new(spec.model, &spec.coeffs),
            MapReading::Asymmetric => {
                TendonMap::asymmetric(spec.model, &spec.coeffs, &spec.coeffs_neg)
            }
        }
    }

    /// Builds an asymmetric map: `coeffs` as in [`TendonMap::new`] for dl >= 0, `coeffs_neg`
    /// (the non-constant coefficients, without k0) for dl < 0. Missing coefficients are zero.
    pub fn asymmetric(kind: TendonMapKind, coeffs: &[f64], coeffs_neg: &[f64]) -> TendonMap {
        let mut m = TendonMap::new(kind, coeffs);
        m.reading = MapReading::Asymmetric;
        m.k_neg = [0.0; 7];
        m.k_neg[0] = m.k[0];
        for (j, c) in coeffs_neg
            .iter()
            .take(kind.n_direction_coeffs())
            .enumerate()
        {
            m.k_neg[j + 1] = *c;
        }
        m.branch = std::sync::OnceLock::new();
        m
    }

    /// Builds a map from its family and coefficients as written in the configuration
    /// (k0 first for families with an offset). Missing coefficients are zero.
    pub fn new(kind: TendonMapKind, coeffs: &[f64]) -> TendonMap {
        let mut k = [0.0; 7];
        let off = usize::from(!kind.has_offset());
        for (j, c) in coeffs.iter().take(kind.n_coeffs()).enumerate() {
            k[j + off] = *c;
        }
        TendonMap {
            kind,
            reading: MapReading::Symmetric,
            k,
            k_neg: k,
            n: kind.n_coeffs() + off,
            branch: std::sync::OnceLock::new(),
        }
    }

    /// The interval around dl = 0 where the slope keeps the sign it has at 0 (boundaries to
    /// 1e-6 mm; a coarse scan at 0.25 mm finds where it turns).
    fn monotone_branch(&self) -> [f64; 2] {
        let sign0 = (self.kappa(1e-6) - self.kappa(-1e-6)).signum();
        if sign0 == 0.0 || !sign0.is_finite() {
            return [0.0, 0.0];
        }
        let keeps = |x: f64| {
            let s = self.kappa_and_slope(x).1;
            s.is_finite() && s * sign0 > 0.0
        };
        let mut out = [-DL_SEARCH_MM, DL_SEARCH_MM];
        for (side, dir) in [-1.0f64, 1.0].into_iter().enumerate() {
            const STEP: f64 = 0.25;
            let mut inside = 0.0;
            loop {
                let next = inside + dir * STEP;
                if next.abs() >= DL_SEARCH_MM {
                    if !keeps(dir * DL_SEARCH_MM) {
                        let (mut a, mut b) = (inside, dir * DL_SEARCH_MM);
                        while (b - a).abs() > 1e-6 {
                            let m = 0.5 * (a + b);
                            if keeps(m) {
                                a = m;
                            } else {
                                b = m;
                            }
                        }
                        out[side] = a;
                    }
                    break;
                }
                if !keeps(next) {
                    let (mut a, mut b) = (inside, next);
                    while (b - a).abs() > 1e-6 {
                        let m = 0.5 * (a + b);
                        if keeps(m) {
                            a = m;
                        } else {
                            b = m;
                        }
                    }
                    out[side] = a;
                    break;
                }
                inside = next;
            }
        }
        out
    }

    /// The interval of tendon displacements (mm) around 0 on which the map is strictly
    /// monotonic (within +-[`DL_SEARCH_MM`]): where [`TendonMap::dl_for_kappa`] searches.
    pub fn invertible_range(&self) -> [f64; 2] {
        *self.branch.get_or_init(|| self.monotone_branch())
    }

    /// The family.
    pub fn kind(&self) -> TendonMapKind {
        self.kind
    }

    /// The reading.
    pub fn reading(&self) -> MapReading {
        self.reading
    }

    /// The family and reading.
    pub fn form(&self) -> MapForm {
        MapForm {
            kind: self.kind,
            reading: self.reading,
        }
    }

    /// Coefficients k0, k1, ... as in the configuration file (k0 omitted for families without
    /// it); those of dl >= 0 in the asymmetric reading.
    pub fn coeffs(&self) -> Vec<f64> {
        let off = usize::from(!self.kind.has_offset());
        self.k[off..self.n].to_vec()
    }

    /// The specification of this map (what a robot file holds).
    pub fn spec(&self) -> TendonMapSpec {
        let mut spec = TendonMapSpec::symmetric(self.kind, self.coeffs());
        if self.reading == MapReading::Asymmetric {
            spec.reading = MapReading::Asymmetric;
            spec.coeffs_neg = self.k_neg[1..self.n].to_vec();
        }
        spec
    }

    /// The columns of the flat coefficient vector of `form` at `dl` (mm): the map is linear in
    /// its coefficients, `kappa = sum_j out[j] x[j]` with `x` =
    /// [`TendonMapSpec::flat_coeffs`]. Returns the number of columns ([`MapForm::n_coeffs`]).
    /// Used by the regressions.
    pub fn flat_basis(form: MapForm, dl: f64, out: &mut [f64; 13]) -> usize {
        let mut b = [0.0; 7];
        let n = TendonMap::basis(form.kind, dl, &mut b);
        let off = usize::from(!form.kind.has_offset());
        let direct = &b[off..n];
        match form.reading {
            MapReading::Symmetric => {
                out[..direct.len()].copy_from_slice(direct);
                direct.len()
            }
            MapReading::Asymmetric => {
                // [k0], then the dl >= 0 terms, then the dl < 0 terms.
                let shared = usize::from(form.kind.has_offset());
                let terms = &b[1..n];
                out[..shared].copy_from_slice(&b[..shared]);
                let (pos, neg) = if dl >= 0.0 { (1.0, 0.0) } else { (0.0, 1.0) };
                for (j, t) in terms.iter().enumerate() {
                    out[shared + j] = pos * t;
                    out[shared + terms.len() + j] = neg * t;
                }
                shared + 2 * terms.len()
            }
        }
    }

    /// Basis functions of the family at `dl` (mm), including the constant 1 first; returns the
    /// number written. Used by the regression (linear least squares in the coefficients).
    pub fn basis(kind: TendonMapKind, dl: f64, out: &mut [f64; 7]) -> usize {
        let a = dl.abs();
        out[0] = 1.0;
        let n = kind.n_coeffs() + usize::from(!kind.has_offset());
        match kind {
            TendonMapKind::Linear | TendonMapKind::Affine => out[1] = dl,
            TendonMapKind::Poly2 | TendonMapKind::Poly3 => {
                out[1] = dl;
                out[2] = dl * a;
                out[3] = dl * dl * dl;
            }
            TendonMapKind::Root2
            | TendonMapKind::Root3
            | TendonMapKind::Root4
            | TendonMapKind::Root5
            | TendonMapKind::Root6 => {
                out[1] = dl;
                for (j, o) in out.iter_mut().enumerate().take(n).skip(2) {
                    *o = odd(dl, root(a, j));
                }
            }
            TendonMapKind::Log | TendonMapKind::LogAffine => out[1] = odd(dl, a.ln_1p()),
            TendonMapKind::LinLog => {
                out[1] = dl;
                out[2] = odd(dl, a.ln_1p());
            }
            TendonMapKind::PolyLog => {
                out[1] = dl;
                out[2] = dl * a;
                out[3] = odd(dl, a.ln_1p());
            }
        }
        n
    }

    /// Curvature (1/mm) for a signed tendon displacement `dl` (mm).
    pub fn kappa(&self, dl: f64) -> f64 {
        self.kappa_and_slope(dl).0
    }

    /// Curvature (1/mm) and its derivative d kappa / d dl (1/mm^2) at `dl` (mm).
    ///
    /// The root families have an infinite slope at dl = 0; there the slope at |dl| = 1e-9 mm
    /// is returned.
    pub fn kappa_and_slope(&self, dl: f64) -> (f64, f64) {
        let k = if dl < 0.0 { &self.k_neg } else { &self.k };
        let a = dl.abs();
        match self.kind {
            TendonMapKind::Linear | TendonMapKind::Affine => (k[0] + k[1] * dl, k[1]),
            TendonMapKind::Poly2 | TendonMapKind::Poly3 => (
                k[0] + k[1] * dl + k[2] * dl * a + k[3] * dl * dl * dl,
                k[1] + 2.0 * k[2] * a + 3.0 * k[3] * dl * dl,
            ),
            TendonMapKind::Root2
            | TendonMapKind::Root3
            | TendonMapKind::Root4
            | TendonMapKind::Root5
            | TendonMapKind::Root6 => {
                let a_eff = a.max(1e-9);
                let mut v = k[0] + k[1] * dl;
                let mut s = k[1];
                for (j, kj) in k.iter().enumerate().take(self.n).skip(2) {
                    let e = 1.0 / j as f64;
                    let p = root(a, j);
                    v += odd(dl, kj * p);
                    // a^(e - 1) = a^e / a.
                    let p_eff = if a_eff == a { p } else { root(a_eff, j) };
                    s += kj * e * p_eff / a_eff;
                }
                (v, s)
            }
            TendonMapKind::Log | TendonMapKind::LogAffine => {
                (k[0] + odd(dl, k[1] * a.ln_1p()), k[1] / (1.0 + a))
            }
            TendonMapKind::LinLog => (
                k[0] + k[1] * dl + odd(dl, k[2] * a.ln_1p()),
                k[1] + k[2] / (1.0 + a),
            ),
            TendonMapKind::PolyLog => (
                k[0] + k[1] * dl + k[2] * dl * a + odd(dl, k[3] * a.ln_1p()),
                k[1] + 2.0 * k[2] * a + k[3] / (1.0 + a),
            ),
        }
    }

    /// Inverse: the tendon displacement (mm) that gives curvature `kappa` (1/mm), searched on
    /// the map's monotonic branch around dl = 0 ([`TendonMap::invertible_range`], within
    /// |dl| <= [`DL_SEARCH_MM`]); a curvature beyond that branch is out of range. (Every calibrated map of a real
    /// segment is).
    pub fn dl_for_kappa(&self, kappa: f64) -> Result<f64, TendonMapError> {
        if (self.kind == TendonMapKind::Linear || self.kind == TendonMapKind::Affine)
            && self.reading == MapReading::Symmetric
        {
            if self.k[1] == 0.0 {
                return Err(TendonMapError::NotMonotonic(self.kind));
            }
            let dl = (kappa - self.k[0]) / self.k[1];
            if dl.abs() > DL_SEARCH_MM {
                return Err(self.out_of_range(kappa));
            }
            return Ok(dl);
        }
        let [mut lo, mut hi] = self.invertible_range();
        if hi - lo <= 0.0 {
            return Err(TendonMapError::NotMonotonic(self.kind));
        }
        let (flo, fhi) = (self.kappa(lo) - kappa, self.kappa(hi) - kappa);
        if flo * fhi > 0.0 {
            return Err(self.out_of_range(kappa));
        }
        let increasing = fhi > flo;
        // Safeguarded Newton: keep a bracket, take Newton steps when they stay inside it.
        let mut x = 0.0f64;
        for _ in 0..200 {
            let (v, s) = self.kappa_and_slope(x);
            let f = v - kappa;
            if (f > 0.0) == increasing {
                hi = x;
            } else {
                lo = x;
            }
            if f == 0.0 || hi - lo < 1e-13 {
                return Ok(x);
            }
            let newton = x - f / s;
            x = if s != 0.0 && newton > lo && newton < hi && s.is_finite() {
                newton
            } else {
                0.5 * (lo + hi)
            };
            if (x - lo).abs() < 1e-15 || (hi - x).abs() < 1e-15 {
                x = 0.5 * (lo + hi);
            }
        }
        // A bracket that does not shrink means the map turns back inside it.
        if (self.kappa(x) - kappa).abs() < 1e-12 {
            Ok(x)
        } else {
            Err(TendonMapError::NotMonotonic(self.kind))
        }
    }

    fn out_of_range(&self, kappa: f64) -> TendonMapError {
        let [lo, hi] = self.invertible_range();
        let (a, b) = (self.kappa(lo), self.kappa(hi));
        TendonMapError::OutOfRange {
            kappa,
            lo: a.min(b),
            hi: a.max(b),
        }
    }
}

/// Motor steps to tendon displacement (mm): dl = q 2 pi r_act / n_spr.
#[inline]
pub fn steps_to_dl(act: &Actuation, q: f64) -> f64 {
    q * act.mm_per_step()
}

/// Tendon displacement (mm) to motor steps (not rounded).
#[inline]
pub fn dl_to_steps(act: &Actuation, dl: f64) -> f64 {
    dl / act.mm_per_step()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample_map(kind: TendonMapKind) -> TendonMap {
        // Coefficients of a plausible, monotonic map: slope ~1/(7*125) 1/mm^2.
        let c = match kind.n_coeffs() {
            1 => vec![1.0 / 875.0],
            2 => vec![1e-5, 1.0 / 875.0],
            3 => vec![1e-5, 1.0 / 900.0, 2e-5],
            4 => vec![1e-5, 1.0 / 900.0, 2e-6, 1e-7],
            n => {
                let mut v = vec![1e-5, 1.0 / 900.0];
                v.extend((2..n).map(|j| 1e-5 / j as f64));
                v
            }
        };
        TendonMap::new(kind, &c)
    }

    #[test]
    fn nominal_linear_matches_geometry_md() {
        let leg = LegConfig::nominal(0);
        let m = TendonMap::from_leg(&leg);
        // 176 steps -> dl = 176 * 2 pi 5 / 2048 mm -> kappa = dl / 875
        let dl = steps_to_dl(&leg.actuation, 176.0);
        assert!((m.kappa(dl) - dl / 875.0).abs() < 1e-18);
        assert!((dl_to_steps(&leg.actuation, dl) - 176.0).abs() < 1e-12);
    }

    #[test]
    fn every_family_inverts_and_has_the_right_slope() {
        for kind in TendonMapKind::ALL {
            let m = sample_map(kind);
            for i in -40..=40 {
                let dl = i as f64 * 0.37 + 0.013;
                let (k, s) = m.kappa_and_slope(dl);
                // odd extension of the non-constant part
                let (kn, _) = m.kappa_and_slope(-dl);
                let k0 = if kind.has_offset() {
                    m.coeffs()[0]
                } else {
                    0.0
                };
                assert!(((k - k0) + (kn - k0)).abs() < 1e-15, "{kind} not odd");
                let h = 1e-6;
                let fd = (m.kappa(dl + h) - m.kappa(dl - h)) / (2.0 * h);
                assert!(
                    (fd - s).abs() < 1e-7 * s.abs().max(1e-3),
                    "{kind} slope {s} vs {fd}"
                );
                let back = m.dl_for_kappa(k).unwrap();
                assert!((back - dl).abs() < 1e-9, "{kind}: {back} vs {dl}");
            }
        }
    }

    #[test]
    fn table_one_forms_on_positive_displacements() {
        // For dl > 0 each family is the paper's form, with ln(1 + dl) for ln(dl).
        let k = [2e-4, 1.1e-3, -3e-5, 4e-6, 7e-6, -2e-6, 1e-6];
        type Form = fn(f64, &[f64; 7]) -> f64;
        let forms: [(TendonMapKind, Form); 13] = [
            (TendonMapKind::Linear, |d, k| k[0] * d),
            (TendonMapKind::Affine, |d, k| k[0] + k[1] * d),
            (TendonMapKind::Poly2, |d, k| k[0] + k[1] * d + k[2] * d * d),
            (TendonMapKind::Poly3, |d, k| {
                k[0] + k[1] * d + k[2] * d * d + k[3] * d * d * d
            }),
            (TendonMapKind::Root2, |d, k| {
                k[0] + k[1] * d + k[2] * d.sqrt()
            }),
            (TendonMapKind::Root3, |d, k| {
                k[0] + k[1] * d + k[2] * d.sqrt() + k[3] * d.cbrt()
            }),
            (TendonMapKind::Root4, |d, k| {
                k[0] + k[1] * d + k[2] * d.sqrt() + k[3] * d.cbrt() + k[4] * d.powf(0.25)
            }),
            (TendonMapKind::Root5, |d, k| {
                k[0] + k[1] * d + (2..6).map(|j| k[j] * d.powf(1.0 / j as f64)).sum::<f64>()
            }),
            (TendonMapKind::Root6, |d, k| {
                k[0] + k[1] * d + (2..7).map(|j| k[j] * d.powf(1.0 / j as f64)).sum::<f64>()
            }),
            (TendonMapKind::Log, |d, k| k[0] * d.ln_1p()),
            (TendonMapKind::LogAffine, |d, k| k[0] + k[1] * d.ln_1p()),
            (TendonMapKind::LinLog, |d, k| {
                k[0] + k[1] * d + k[2] * d.ln_1p()
            }),
            (TendonMapKind::PolyLog, |d, k| {
                k[0] + k[1] * d + k[2] * d * d + k[3] * d.ln_1p()
            }),
        ];
        for (i, (kind, f)) in forms.iter().enumerate() {
            assert_eq!(kind.table_index(), i + 1);
            assert_eq!(TendonMapKind::from_table_index(i + 1), Some(*kind));
            let m = TendonMap::new(*kind, &k[..kind.n_coeffs()]);
            for dl in [0.01, 0.7, 2.5, 6.0] {
                assert!((m.kappa(dl) - f(dl, &k)).abs() < 1e-15, "{kind} at {dl}");
            }
        }
        assert_eq!(TendonMapKind::from_table_index(0), None);
        assert_eq!(TendonMapKind::from_table_index(14), None);
    }

    #[test]
    fn out_of_range_is_an_error() {
        let m = sample_map(TendonMapKind::Log);
        assert!(matches!(
            m.dl_for_kappa(10.0),
            Err(TendonMapError::OutOfRange { .. })
        ));
        let m = TendonMap::new(TendonMapKind::Linear, &[0.0]);
        assert!(m.dl_for_kappa(0.1).is_err());
        // A cubic that turns back at about +-30 mm (negative k3): inverted on the branch
        // through 0, never on the outer branch where the same curvature comes back.
        let m = TendonMap::new(TendonMapKind::Poly3, &[0.0, 1.1e-3, 1.2e-6, -4.1e-7]);
        let [lo, hi] = m.invertible_range();
        let turn = |x: f64| 1.1e-3 + 2.0 * 1.2e-6 * x.abs() + 3.0 * -4.1e-7 * x * x;
        assert!(
            turn(lo).abs() < 1e-8 && turn(hi).abs() < 1e-8,
            "[{lo}, {hi}]"
        );
        assert!(lo < -25.0 && hi > 25.0);
        for dl in [-20.0, -5.0, 0.3, 12.0, 25.0] {
            let back = m.dl_for_kappa(m.kappa(dl)).expect("on the branch");
            assert!((back - dl).abs() < 1e-9, "{dl} -> {back}");
        }
        assert!(matches!(
            m.dl_for_kappa(m.kappa(hi) + 1e-4),
            Err(TendonMapError::OutOfRange { .. })
        ));
    }

    /// An asymmetric map of `kind`: the sample map for dl >= 0, other coefficients for dl < 0.
    fn asymmetric_sample(kind: TendonMapKind) -> TendonMap {
        let m = sample_map(kind);
        let off = usize::from(kind.has_offset());
        let neg: Vec<f64> = m.coeffs()[off..]
            .iter()
            .enumerate()
            .map(|(j, c)| c * (0.7 + 0.1 * j as f64))
            .collect();
        TendonMap::asymmetric(kind, &m.coeffs(), &neg)
    }

    #[test]
    fn the_asymmetric_reading_is_the_paper_form_for_positive_dl_and_its_own_for_negative() {
        for kind in TendonMapKind::ALL {
            let sym = sample_map(kind);
            let asym = asymmetric_sample(kind);
            let same = TendonMap::asymmetric(kind, &sym.coeffs(), &sym.k[1..sym.n]);
            for i in -40..=40 {
                let dl = i as f64 * 0.37 + 0.013;
                // Equal coefficient lists give the symmetric map.
                assert_eq!(same.kappa_and_slope(dl), sym.kappa_and_slope(dl), "{kind}");
                let (k, s) = asym.kappa_and_slope(dl);
                if dl >= 0.0 {
                    assert_eq!((k, s), sym.kappa_and_slope(dl), "{kind}");
                } else if i < -1 {
                    assert!((k - sym.kappa(dl)).abs() > 1e-9, "{kind} at {dl}");
                }
                let h = 1e-6;
                let fd = (asym.kappa(dl + h) - asym.kappa(dl - h)) / (2.0 * h);
                assert!((fd - s).abs() < 1e-7 * s.abs().max(1e-3), "{kind}");
                let back = asym.dl_for_kappa(k).unwrap();
                assert!((back - dl).abs() < 1e-9, "{kind}: {back} vs {dl}");
            }
            // Continuous at 0 (the shared k0).
            assert!(
                (asym.kappa(1e-60) - asym.kappa(-1e-60)).abs() < 1e-9,
                "{kind}"
            );
            assert_eq!(TendonMap::from_spec(&asym.spec()), asym);
            assert_eq!(asym.spec().form(), MapForm::asymmetric(kind));
        }
        // The cubic taken literally on both signs (k2 dl^2 keeps an even part) is an
        // asymmetric poly3: k_neg = (k1, -k2, k3).
        let (k0, k1, k2, k3) = (2e-5, 1.1e-3, -2e-6, 3e-8);
        let literal =
            TendonMap::asymmetric(TendonMapKind::Poly3, &[k0, k1, k2, k3], &[k1, -k2, k3]);
        for dl in [-2.5, -0.4, 0.0, 0.3, 7.0] {
            let want = k0 + k1 * dl + k2 * dl * dl + k3 * dl * dl * dl;
            assert!((literal.kappa(dl) - want).abs() < 1e-15, "{dl}");
        }
    }

    #[test]
    fn flat_basis_reproduces_evaluation_in_both_readings() {
        for kind in TendonMapKind::ALL {
            for m in [sample_map(kind), asymmetric_sample(kind)] {
                let x = m.spec().flat_coeffs();
                assert_eq!(x.len(), m.form().n_coeffs());
                let mut b = [0.0; 13];
                for dl in [-3.1, -0.2, 0.0, 0.5, 7.7] {
                    let n = TendonMap::flat_basis(m.form(), dl, &mut b);
                    assert_eq!(n, x.len());
                    let v: f64 = (0..n).map(|j| b[j] * x[j]).sum();
                    assert!((v - m.kappa(dl)).abs() < 1e-15, "{kind}");
                }
            }
        }
    }

    #[test]
    fn basis_reproduces_evaluation() {
        for kind in TendonMapKind::ALL {
            let m = sample_map(kind);
            let mut b = [0.0; 7];
            for dl in [-3.1, -0.2, 0.0, 0.5, 7.7] {
                let n = TendonMap::basis(kind, dl, &mut b);
                let v: f64 = (0..n).map(|j| b[j] * m.k[j]).sum();
                assert!((v - m.kappa(dl)).abs() < 1e-15, "{kind}");
            }
        }
    }
}
