//! Step 1 of the paper's calibration: per leg, the tendon map and the leg geometry from the
//! measured passive-joint positions M_i (paper eq. 8), for each of the 13 functions of Table I.
//!
//! The model of a measured point is the leg's forward kinematics (geometry.md eq. 4) at the
//! curvature the candidate map gives for the commanded tendon displacement:
//! `M = B + R(psi) [l_C (1 - cos theta)/theta + l_CE sin theta, l_C sin theta/theta + l_CE cos theta]`,
//! `theta = kappa(dl) l_C`. The paper frees P1 = [l_C, psi, k]; [`FreeGeometry::extended`] frees
//! the base point B (r_base, beta) and the extension l_CE as well, for robots whose base
//! markers or tip extensions are off their drawing (the two sets are compared in
//! docs/calibration.md).

use crate::lsq::{self, Fit, Options, Problem};
use crate::DataError;
use nalgebra::{DMatrix, DVector};
use pcr_kinematics::{Leg, TendonMap};
use pcr_robot::{LegConfig, MapForm, MapReading, TendonMapKind, TendonMapSpec};
use serde::Serialize;

/// Which geometric parameters of a leg the fit frees beside the map coefficients.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct FreeGeometry {
    /// Segment base orientation psi.
    pub psi: bool,
    /// Segment length l_C.
    pub l_c: bool,
    /// Base point B (r_base, beta).
    pub base: bool,
    /// Tip extension l_CE.
    pub l_ce: bool,
}

impl FreeGeometry {
    /// The paper's P1: l_C and psi (with the map coefficients).
    pub const PAPER: FreeGeometry = FreeGeometry {
        psi: true,
        l_c: true,
        base: false,
        l_ce: false,
    };
    /// The paper's set plus the base point B (r_base, beta). The tip extension stays fixed: on
    /// the workspace's bending range l_CE trades against l_C and the map's slope almost exactly
    /// (correlations of 0.999 and more on the prototype's data).
    pub const EXTENDED: FreeGeometry = FreeGeometry {
        psi: true,
        l_c: true,
        base: true,
        l_ce: false,
    };
    /// Map coefficients only (a segment on the bench with known length and frame).
    pub const NONE: FreeGeometry = FreeGeometry {
        psi: false,
        l_c: false,
        base: false,
        l_ce: false,
    };

    /// Names, units, values and bounds of the free geometric parameters around `leg`, in
    /// vector order.
    pub(crate) fn params(
        &self,
        leg: &LegConfig,
    ) -> Vec<(&'static str, &'static str, f64, f64, f64)> {
        let mut v = Vec::new();
        if self.psi {
            v.push((
                "psi_deg",
                "deg",
                leg.psi_deg,
                leg.psi_deg - 15.0,
                leg.psi_deg + 15.0,
            ));
        }
        if self.l_c {
            v.push((
                "l_c_mm",
                "mm",
                leg.l_c_mm,
                0.7 * leg.l_c_mm,
                1.3 * leg.l_c_mm,
            ));
        }
        if self.base {
            v.push((
                "r_base_mm",
                "mm",
                leg.r_base_mm,
                leg.r_base_mm - 20.0,
                leg.r_base_mm + 20.0,
            ));
            v.push((
                "beta_deg",
                "deg",
                leg.beta_deg,
                leg.beta_deg - 10.0,
                leg.beta_deg + 10.0,
            ));
        }
        if self.l_ce {
            v.push(("l_ce_mm", "mm", leg.l_ce_mm, 0.0, 2.0 * leg.l_ce_mm + 20.0));
        }
        v
    }

    /// Writes the geometric part of a parameter vector into a leg; returns the number used.
    fn apply(&self, x: &[f64], leg: &mut LegConfig) -> usize {
        let mut k = 0;
        let mut take = || {
            k += 1;
            x[k - 1]
        };
        if self.psi {
            leg.psi_deg = take();
        }
        if self.l_c {
            leg.l_c_mm = take();
        }
        if self.base {
            leg.r_base_mm = take();
            leg.beta_deg = take();
        }
        if self.l_ce {
            leg.l_ce_mm = take();
        }
        k
    }
}

/// One measured passive-joint position with its commanded tendon displacement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LegObservation {
    /// Tendon displacement, mm.
    pub dl_mm: f64,
    /// Measured M_i (base frame), mm.
    pub m: [f64; 2],
}

/// A fitted parameter.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Param {
    /// Name (`psi_deg`, `l_c_mm`, `k0`, ...).
    pub name: String,
    /// Unit.
    pub unit: String,
    /// Value at the optimum.
    pub value: f64,
    /// Standard error from the Jacobian at the optimum (`None` if it cannot be estimated).
    pub std: Option<f64>,
    /// Nominal (starting) value.
    pub start: f64,
    /// Whether the optimum sits on a bound (its uncertainty then means little).
    pub at_bound: bool,
}

/// Two parameters the data hardly separate.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Correlated {
    /// First parameter.
    pub a: String,
    /// Second parameter.
    pub b: String,
    /// Their correlation coefficient.
    pub rho: f64,
}

/// |rho| above which a pair of parameters is reported as strongly correlated.
pub const CORRELATION_WARNING: f64 = 0.95;

/// The fit of one function to one leg.
#[derive(Debug, Clone, Serialize)]
pub struct LegFit {
    /// Leg index 0..3 (`None` for a lone segment).
    pub leg: Option<usize>,
    /// The function.
    pub kind: TendonMapKind,
    /// Its reading (one set of coefficients for both bending directions, or one per direction).
    pub reading: MapReading,
    /// The fitted leg (geometry and map).
    #[serde(skip)]
    pub config: LegConfig,
    /// Every free parameter.
    pub params: Vec<Param>,
    /// RMS of |M^ - M| over the training points, mm.
    pub train_rms_mm: f64,
    /// RMS of |M^ - M| over the test points, mm (`None` without test points).
    pub test_rms_mm: Option<f64>,
    /// Largest |M^ - M| over the test points, mm.
    pub test_max_mm: Option<f64>,
    /// Training and test points.
    pub n_train: usize,
    /// Test points.
    pub n_test: usize,
    /// Whether the solver converged.
    pub converged: bool,
    /// Solver status word.
    pub status: String,
    /// Residual evaluations.
    pub evaluations: usize,
    /// Strongly correlated parameter pairs.
    pub correlated: Vec<Correlated>,
    /// Whether the fitted map is strictly monotonic over the data's displacement range (10 %
    /// margin each side): a map that turns back cannot be inverted by the IK.
    pub monotonic: bool,
    /// Why the map cannot serve the IK over the leg's travel (set by the robot calibration,
    /// which knows the bending limit; `None`: it can).
    pub refused: Option<String>,
}

/// Why a leg could not be fitted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Step1Error {
    /// Too few points.
    #[error(transparent)]
    Data(#[from] DataError),
    /// The solver failed.
    #[error("{what}: function {label} ({name}, {reading}): {reason}")]
    Solver {
        /// Which leg or segment.
        what: String,
        /// Table I number, `a` for the asymmetric reading.
        label: String,
        /// Family name.
        name: &'static str,
        /// The reading.
        reading: MapReading,
        /// Why.
        reason: String,
    },
}

/// The leg with the map and geometry of a parameter vector (the free geometry, then the flat
/// map coefficients of `form`).
pub(crate) fn leg_of(base: &LegConfig, free: FreeGeometry, form: MapForm, x: &[f64]) -> LegConfig {
    let mut leg = base.clone();
    let k = free.apply(x, &mut leg);
    leg.tendon_map = TendonMapSpec::from_flat(form, &x[k..]);
    leg
}

/// The predicted M for a leg at a tendon displacement.
pub fn predict_m(leg: &Leg, dl_mm: f64) -> [f64; 2] {
    leg.joint_m(leg.map.kappa(dl_mm))
}

/// The bending angle theta (rad) at which the leg's M comes closest to `m`: a scan of
/// [-pi, pi] refined by Newton on the squared distance.
pub fn theta_of_m(leg: &Leg, m: [f64; 2]) -> f64 {
    let local = leg.to_local([m[0] - leg.b[0], m[1] - leg.b[1]]);
    let d2 = |th: f64| {
        let t = leg.local_tip(th);
        (t.m[0] - local[0]).powi(2) + (t.m[1] - local[1]).powi(2)
    };
    let mut best = (0.0, f64::INFINITY);
    for k in 0..=180 {
        let th = -std::f64::consts::PI + k as f64 * std::f64::consts::TAU / 180.0;
        let v = d2(th);
        if v < best.1 {
            best = (th, v);
        }
    }
    // Gauss-Newton on the distance: minimise |m(th) - local|^2.
    let mut th = best.0;
    for _ in 0..30 {
        let t = leg.local_tip(th);
        let r = [t.m[0] - local[0], t.m[1] - local[1]];
        let jj = t.dm[0] * t.dm[0] + t.dm[1] * t.dm[1];
        if jj == 0.0 {
            break;
        }
        let step = (r[0] * t.dm[0] + r[1] * t.dm[1]) / jj;
        th -= step;
        if step.abs() < 1e-14 {
            break;
        }
    }
    if d2(th) <= best.1 {
        th
    } else {
        best.0
    }
}

/// Linear least-squares coefficients of `form` (flat order) for curvature estimates
/// (dl, kappa).
pub fn linear_coefficients(form: MapForm, pts: &[(f64, f64)]) -> Option<Vec<f64>> {
    let nc = form.n_coeffs();
    if pts.len() < nc {
        return None;
    }
    let mut a = DMatrix::zeros(pts.len(), nc);
    let mut b = DVector::zeros(pts.len());
    let mut basis = [0.0; 13];
    for (r, (dl, kappa)) in pts.iter().enumerate() {
        TendonMap::flat_basis(form, *dl, &mut basis);
        for c in 0..nc {
            a[(r, c)] = basis[c];
        }
        b[r] = *kappa;
    }
    // Column scaling keeps the SVD well conditioned (dl^3 vs 1); a column without data (no
    // point on one side of an asymmetric map) keeps a unit scale and a zero coefficient.
    let scale: Vec<f64> = (0..nc)
        .map(|c| {
            let n = a.column(c).norm();
            if n > 0.0 {
                n
            } else {
                1.0
            }
        })
        .collect();
    for (c, s) in scale.iter().enumerate() {
        a.column_mut(c).unscale_mut(*s);
    }
    let sol = a.svd(true, true).solve(&b, 1e-12).ok()?;
    let out: Vec<f64> = (0..nc).map(|c| sol[c] / scale[c]).collect();
    out.iter().all(|v| v.is_finite()).then_some(out)
}

struct LegProblem<'a> {
    base: &'a LegConfig,
    free: FreeGeometry,
    form: MapForm,
    obs: &'a [LegObservation],
}

impl Problem for LegProblem<'_> {
    fn residual_count(&self) -> usize {
        2 * self.obs.len()
    }

    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), String> {
        let leg = Leg::from_config(&leg_of(self.base, self.free, self.form, x));
        m_residuals(&leg, self.obs, r);
        Ok(())
    }
}

/// The residuals of measured M_i, 2 per observation: (dx, dy) of the model's M minus the
/// measured one, mm.
pub(crate) fn m_residuals(leg: &Leg, obs: &[LegObservation], r: &mut [f64]) {
    for (k, o) in obs.iter().enumerate() {
        let m = predict_m(leg, o.dl_mm);
        r[2 * k] = m[0] - o.m[0];
        r[2 * k + 1] = m[1] - o.m[1];
    }
}

/// RMS and maximum of |M^ - M| for a leg over observations.
pub fn m_errors(leg: &LegConfig, obs: &[LegObservation]) -> (f64, f64) {
    let leg = Leg::from_config(leg);
    let mut ss = 0.0;
    let mut mx = 0.0f64;
    for o in obs {
        let m = predict_m(&leg, o.dl_mm);
        let e = (m[0] - o.m[0]).hypot(m[1] - o.m[1]);
        ss += e * e;
        mx = mx.max(e);
    }
    ((ss / obs.len().max(1) as f64).sqrt(), mx)
}

/// Fits one function in one reading to one leg: `base` gives the starting geometry (and
/// everything not freed), `train` the observations fitted, `test` those reported. `what` names
/// the leg in errors.
pub fn fit_leg(
    what: &str,
    leg_index: Option<usize>,
    base: &LegConfig,
    free: FreeGeometry,
    form: MapForm,
    train: &[LegObservation],
    test: &[LegObservation],
) -> Result<LegFit, Step1Error> {
    let kind = form.kind;
    let geo = free.params(base);
    let n = geo.len() + form.n_coeffs();
    let solver_err = |reason: String| Step1Error::Solver {
        what: what.to_string(),
        label: form.label(),
        name: kind.name(),
        reading: form.reading,
        reason,
    };
    if 2 * train.len() <= n {
        return Err(solver_err(format!(
            "{} training points for {n} parameters: at least {} needed",
            train.len(),
            n / 2 + 1
        )));
    }
    if form.reading == MapReading::Asymmetric {
        // Each direction's coefficients need points of their own.
        let need = kind.n_direction_coeffs() + 1;
        for (side, count) in [
            ("dl < 0", train.iter().filter(|o| o.dl_mm < 0.0).count()),
            ("dl > 0", train.iter().filter(|o| o.dl_mm > 0.0).count()),
        ] {
            if count < need {
                return Err(solver_err(format!(
                    "{count} training points with {side} for the {} coefficient(s) of that direction: at least {need} needed",
                    kind.n_direction_coeffs()
                )));
            }
        }
    }
    // Start: nominal geometry, coefficients from the curvatures that reproduce the measured
    // points best on the nominal leg.
    let nominal_leg = Leg::from_config(base);
    let pts: Vec<(f64, f64)> = train
        .iter()
        .map(|o| (o.dl_mm, theta_of_m(&nominal_leg, o.m) / base.l_c_mm))
        .collect();
    let coeffs = linear_coefficients(form, &pts)
        .ok_or_else(|| solver_err("no starting coefficients (degenerate data)".into()))?;
    let mut x0: Vec<f64> = geo.iter().map(|g| g.2).collect();
    let mut lo: Vec<f64> = geo.iter().map(|g| g.3).collect();
    let mut hi: Vec<f64> = geo.iter().map(|g| g.4).collect();
    x0.extend(&coeffs);
    lo.extend(std::iter::repeat_n(f64::NEG_INFINITY, coeffs.len()));
    hi.extend(std::iter::repeat_n(f64::INFINITY, coeffs.len()));
    let mut prob = LegProblem {
        base,
        free,
        form,
        obs: train,
    };
    let fit = lsq::solve(&mut prob, &x0, &lo, &hi, &Options::default())
        .map_err(|e| solver_err(e.to_string()))?;
    let config = leg_of(base, free, form, &fit.x);
    if !fit.x.iter().all(|v| v.is_finite()) {
        return Err(solver_err("the optimum is not finite".into()));
    }
    let names: Vec<(String, String)> = geo
        .iter()
        .map(|g| (g.0.to_string(), g.1.to_string()))
        .chain(
            (0..form.n_coeffs()).map(|j| (form.coeff_name(j), coeff_unit(kind, form.mirrored(j)))),
        )
        .collect();
    let (params, correlated) = describe(&fit, &names, &x0);
    let (train_rms, _) = m_errors(&config, train);
    let (test_rms, test_max) = if test.is_empty() {
        (None, None)
    } else {
        let (r, m) = m_errors(&config, test);
        (Some(r), Some(m))
    };
    let (lo, hi) = train
        .iter()
        .chain(test)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |a, o| {
            (a.0.min(o.dl_mm), a.1.max(o.dl_mm))
        });
    let monotonic = is_monotonic(&TendonMap::from_spec(&config.tendon_map), lo, hi);
    Ok(LegFit {
        monotonic,
        refused: None,
        leg: leg_index,
        kind,
        reading: form.reading,
        config,
        params,
        train_rms_mm: train_rms,
        test_rms_mm: test_rms,
        test_max_mm: test_max,
        n_train: train.len(),
        n_test: test.len(),
        converged: fit.status.converged(),
        status: format!("{:?}", fit.status).to_lowercase(),
        evaluations: fit.evaluations,
        correlated,
    })
}

/// Whether a map can serve the IK over a leg's travel: strictly monotonic over the data's
/// displacements `[lo, hi]` (mm) widened by 10 % of the span each side, and invertible on its
/// monotonic branch around dl = 0 over the curvatures `travel` (1/mm, the range the robot's
/// workspace asks of the leg: `pcr_kinematics::workspace::leg_travel`) widened by 10 % of
/// their span each side. The error says which range fails, in mm of tendon and degrees of
/// bending (`l_c_mm` converts).
pub fn map_coverage(
    map: &TendonMap,
    l_c_mm: f64,
    travel: [f64; 2],
    lo: f64,
    hi: f64,
) -> Result<(), String> {
    displacement_coverage(map, lo, hi)?;
    let [b_lo, b_hi] = map.invertible_range();
    let mk = 0.1 * (travel[1] - travel[0]).abs();
    let (k_lo, k_hi) = (travel[0] - mk, travel[1] + mk);
    if map.dl_for_kappa(k_lo).is_err() || map.dl_for_kappa(k_hi).is_err() {
        let (a, b) = (map.kappa(b_lo), map.kappa(b_hi));
        let deg = |k: f64| (k * l_c_mm).to_degrees();
        return Err(format!(
            "the map cannot be inverted over the leg's travel: the workspace needs bending from {:.1} to {:.1} deg (widened by 10 %), the map reaches {:.1} to {:.1} deg on its monotonic branch dl in [{b_lo:.2}, {b_hi:.2}] mm",
            deg(k_lo),
            deg(k_hi),
            deg(a.min(b)),
            deg(a.max(b)),
        ));
    }
    Ok(())
}

/// The first half of [`map_coverage`]: whether a map is strictly monotonic over the
/// displacements `[lo, hi]` (mm) widened by 10 % of the span each side, on its monotonic branch
/// around dl = 0 (where its inverse searches). The error says where it turns back.
pub fn displacement_coverage(map: &TendonMap, lo: f64, hi: f64) -> Result<(), String> {
    let [b_lo, b_hi] = map.invertible_range();
    let m = 0.1 * (hi - lo).max(1e-3);
    let (need_lo, need_hi) = (lo - m, hi + m);
    if b_lo > need_lo || b_hi < need_hi || !is_monotonic(map, lo, hi) {
        let turn = if b_lo > need_lo { b_lo } else { b_hi };
        return Err(format!(
            "the map turns back at dl = {turn:.2} mm: it is monotonic on [{b_lo:.2}, {b_hi:.2}] mm, but the leg's travel in the data needs [{need_lo:.2}, {need_hi:.2}] mm (the data's range widened by 10 %)"
        ));
    }
    Ok(())
}

/// Whether the map can be inverted for every bending up to the robot's limit (+-bending_max
/// over l_C): the inverse stays on its monotonic branch around dl = 0, so a map that turns
/// back before the limit would leave poses the robot must reach without motor positions.
pub fn reaches_bending_limit(map: &TendonMap, l_c_mm: f64, bending_max_deg: f64) -> bool {
    let k = bending_max_deg.to_radians() / l_c_mm;
    k.is_finite() && map.dl_for_kappa(k).is_ok() && map.dl_for_kappa(-k).is_ok()
}

/// Whether a map is strictly monotonic on [lo, hi] widened by 10 % of the span each side.
pub fn is_monotonic(map: &TendonMap, lo: f64, hi: f64) -> bool {
    if !(lo.is_finite() && hi.is_finite()) {
        return false;
    }
    let m = 0.1 * (hi - lo).max(1e-3);
    let (a, b) = (lo - m, hi + m);
    let n = 800;
    let mut prev = map.kappa(a);
    let mut sign = 0.0;
    for k in 1..=n {
        let v = map.kappa(a + (b - a) * k as f64 / n as f64);
        let d = v - prev;
        if d == 0.0 || !d.is_finite() {
            return false;
        }
        if sign == 0.0 {
            sign = d.signum();
        } else if d.signum() != sign {
            return false;
        }
        prev = v;
    }
    // Near dl = 0 too, on a log scale: the root families' terms change fastest there, and a
    // fit can turn a map back in a dip far narrower than the grid (a sixth-root map whose
    // curvature fell from -1e-4 to -0.035 1/mm within a few thousandths of a mm of dl = 0). A
    // turn back by less than the map's mean slope over one interval of the grid is one the grid
    // would not have seen either (a root map whose slope changes sign a few thousandths of a mm
    // from zero): its inverse errs by less than that interval.
    let h = (b - a) / n as f64;
    let tolerance = ((map.kappa(b) - map.kappa(a)) / (b - a)).abs() * h;
    if a < 0.0 && b > 0.0 {
        let mut xs: Vec<f64> = std::iter::successors(Some(NEAR_ZERO_MM), |x| {
            Some(x * NEAR_ZERO_RATIO).filter(|&y| y < h)
        })
        .flat_map(|x| [-x, x])
        .filter(|&x| x > a && x < b)
        .collect();
        xs.push(0.0);
        xs.sort_by(f64::total_cmp);
        let mut extreme = f64::NEG_INFINITY;
        for x in xs {
            let v = sign * map.kappa(x);
            if !v.is_finite() || v < extreme - tolerance {
                return false;
            }
            extreme = extreme.max(v);
        }
    }
    true
}

/// The smallest |dl| (mm) [`is_monotonic`] looks at near dl = 0, a millionth of a step.
const NEAR_ZERO_MM: f64 = 1e-8;

/// The ratio of two points of [`is_monotonic`]'s log scale near dl = 0 (four a decade).
const NEAR_ZERO_RATIO: f64 = 1.778_279_410_038_923;

/// The unit of coefficient `j` of a family (kappa in 1/mm, dl in mm).
pub fn coeff_unit(kind: TendonMapKind, j: usize) -> String {
    let j = j + usize::from(!kind.has_offset());
    let power = match kind {
        TendonMapKind::Linear | TendonMapKind::Affine => [0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0][j],
        TendonMapKind::Poly2 | TendonMapKind::Poly3 => [0.0, 1.0, 2.0, 3.0, 0.0, 0.0, 0.0][j],
        TendonMapKind::Root2
        | TendonMapKind::Root3
        | TendonMapKind::Root4
        | TendonMapKind::Root5
        | TendonMapKind::Root6 => match j {
            0 => 0.0,
            1 => 1.0,
            n => 1.0 / n as f64,
        },
        // ln(1 + |dl|) is dimensionless in mm
        TendonMapKind::Log | TendonMapKind::LogAffine => 0.0,
        TendonMapKind::LinLog => [0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0][j],
        TendonMapKind::PolyLog => [0.0, 1.0, 2.0, 0.0, 0.0, 0.0, 0.0][j],
    };
    if power == 0.0 {
        "1/mm".into()
    } else if power == 1.0 {
        "1/mm^2".into()
    } else if power.fract() == 0.0 {
        format!("1/mm^{}", 1.0 + power)
    } else {
        format!("mm^-{}", 1.0 + power)
    }
}

/// Parameters with their uncertainties, and the strongly correlated pairs.
pub(crate) fn describe(
    fit: &Fit,
    names: &[(String, String)],
    start: &[f64],
) -> (Vec<Param>, Vec<Correlated>) {
    let se = fit.standard_errors();
    let params = names
        .iter()
        .enumerate()
        .map(|(k, (name, unit))| Param {
            name: name.clone(),
            unit: unit.clone(),
            value: fit.x[k],
            std: se
                .as_ref()
                .map(|s| s[k])
                .filter(|s| s.is_finite() && *s > 0.0),
            start: start[k],
            at_bound: fit.at_bound[k],
        })
        .collect();
    let mut correlated = Vec::new();
    if let Some(c) = fit.correlation() {
        for i in 0..names.len() {
            for j in i + 1..names.len() {
                let rho = c[(i, j)];
                if rho.abs() > CORRELATION_WARNING {
                    correlated.push(Correlated {
                        a: names[i].0.clone(),
                        b: names[j].0.clone(),
                        rho,
                    });
                }
            }
        }
    }
    (params, correlated)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A leg-1 map of the prototype plant's small loop (an asymmetric sixth-root map refitted by
    /// the residual analysis), with a dip a few thousandths of a mm wide at dl = 0, where the
    /// roots' terms change fastest, so that its inverse put every small negative bending on the
    /// positive side (the extended circle held that motor at -1 step for -68). Over
    /// [-1.4, 7.66] mm the 800 points of the grid step over the dip; the log scale near zero
    /// does not.
    #[test]
    fn a_dip_at_zero_narrower_than_the_grid_is_not_monotonic() {
        let spec = TendonMapSpec {
            model: TendonMapKind::Root6,
            reading: pcr_robot::MapReading::Asymmetric,
            coeffs: vec![
                -0.03470458163665878,
                0.00013819822938429015,
                0.0930112682812078,
                -1.1471095520998265,
                4.3172750585611,
                -6.136632043454229,
                2.9090297827252733,
            ],
            coeffs_neg: vec![
                0.0023475792554761995,
                -0.09462406227769143,
                1.1340708145622584,
                -4.245886576382241,
                6.03275792141117,
                -2.8621659779806174,
            ],
        };
        let map = TendonMap::from_spec(&spec);
        for hi in [7.6, 7.66] {
            assert!(!is_monotonic(&map, -1.4, hi), "{hi}");
            assert!(displacement_coverage(&map, -1.4, hi).is_err(), "{hi}");
        }
    }

    /// Observations of a leg with a known map and geometry, with a deterministic "noise".
    fn synthetic(truth: &LegConfig, noise: f64) -> Vec<LegObservation> {
        let leg = Leg::from_config(truth);
        (0..60)
            .map(|k| {
                let dl = -1.5 + 8.0 * k as f64 / 59.0;
                let m = predict_m(&leg, dl);
                let e = noise * ((k * 7919 % 13) as f64 / 6.0 - 1.0);
                LegObservation {
                    dl_mm: dl,
                    m: [m[0] + e, m[1] - 0.5 * e],
                }
            })
            .collect()
    }

    #[test]
    fn recovers_geometry_and_map_of_a_known_leg() {
        let nominal = LegConfig::nominal(1);
        let mut truth = nominal.clone();
        truth.psi_deg += 0.4;
        truth.l_c_mm -= 0.6;
        truth.tendon_map = TendonMapSpec::symmetric(TendonMapKind::Affine, vec![1.5e-4, 1.08e-3]);
        let obs = synthetic(&truth, 0.0);
        let (train, test) = obs.split_at(40);
        let fit = fit_leg(
            "leg 2",
            Some(1),
            &nominal,
            FreeGeometry::PAPER,
            MapForm::symmetric(TendonMapKind::Affine),
            train,
            test,
        )
        .unwrap();
        assert!(fit.converged);
        assert!(fit.train_rms_mm < 1e-6, "{}", fit.train_rms_mm);
        assert!(fit.test_rms_mm.unwrap() < 1e-6);
        assert!((fit.config.psi_deg - truth.psi_deg).abs() < 1e-6);
        assert!((fit.config.l_c_mm - truth.l_c_mm).abs() < 1e-5);
        let c = &fit.config.tendon_map.coeffs;
        assert!((c[0] - 1.5e-4).abs() < 1e-9 && (c[1] - 1.08e-3).abs() < 1e-9);
    }

    #[test]
    fn every_function_fits_and_the_true_family_wins() {
        let nominal = LegConfig::nominal(0);
        let mut truth = nominal.clone();
        truth.tendon_map =
            TendonMapSpec::symmetric(TendonMapKind::Root2, vec![0.0, 9.0e-4, 2.5e-4]);
        let obs = synthetic(&truth, 0.05);
        let (train, test): (Vec<_>, Vec<_>) = obs
            .iter()
            .enumerate()
            .partition::<Vec<_>, _>(|(k, _)| k % 3 != 1);
        let train: Vec<_> = train.into_iter().map(|(_, o)| *o).collect();
        let test: Vec<_> = test.into_iter().map(|(_, o)| *o).collect();
        let mut best = (f64::INFINITY, TendonMapKind::Linear);
        for kind in TendonMapKind::ALL {
            let f = fit_leg(
                "leg 1",
                Some(0),
                &nominal,
                FreeGeometry::PAPER,
                MapForm::symmetric(kind),
                &train,
                &test,
            )
            .unwrap();
            let t = f.test_rms_mm.unwrap();
            if t < best.0 {
                best = (t, kind);
            }
        }
        // The root families contain the truth; the winner is one of them, at the noise level.
        assert!(
            matches!(
                best.1,
                TendonMapKind::Root2
                    | TendonMapKind::Root3
                    | TendonMapKind::Root4
                    | TendonMapKind::Root5
                    | TendonMapKind::Root6
            ),
            "{best:?}"
        );
        assert!(best.0 < 0.1, "{best:?}");
    }

    #[test]
    fn too_few_points_is_an_error_naming_the_leg() {
        let nominal = LegConfig::nominal(2);
        let obs = synthetic(&nominal, 0.0);
        let e = fit_leg(
            "leg 3",
            Some(2),
            &nominal,
            FreeGeometry::EXTENDED,
            MapForm::symmetric(TendonMapKind::Root6),
            &obs[..3],
            &[],
        )
        .unwrap_err();
        let s = e.to_string();
        assert!(s.contains("leg 3") && s.contains("function 9"), "{s}");
    }

    #[test]
    fn theta_of_m_inverts_the_leg() {
        let leg = Leg::from_config(&LegConfig::nominal(2));
        for th in [-1.2, -0.3, 0.0, 0.01, 0.5, 2.0] {
            let m = leg.joint_m(th / leg.l_c);
            assert!((theta_of_m(&leg, m) - th).abs() < 1e-9, "{th}");
        }
    }
}
