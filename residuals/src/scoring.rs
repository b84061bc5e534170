//! How a fitted candidate is judged: on the held-out blocks against a reference (the
//! recalibration, or the model as it is). It is significant when a paired test over the
//! held-out blocks says it lowers the error (Bonferroni-corrected over the round's candidates),
//! by more than the smallest effect worth claiming, when the Bayesian information criterion on
//! the training rows agrees, and when it explains a good share of the structure above the
//! capture noise, or, failing these, when it is the simpler explanation of what the
//! recalibration explains (parsimony).

use crate::context::Context;
use crate::fitted::{Estimate, Fitted};
use crate::options::Options;
use crate::series::Blocks;
use serde::Serialize;
use statrs::distribution::{ContinuousCDF, StudentsT};

/// Smallest share of the held-out mean square above the capture noise that a candidate must
/// explain to be claimed.
pub const MIN_SHARE: f64 = 0.25;

/// How one candidate scored in one round.
#[derive(Debug, Clone, Serialize)]
pub struct Score {
    /// Round (1-based).
    pub round: usize,
    /// Candidate name.
    pub name: String,
    /// Its parameters.
    pub params: Vec<Estimate>,
    /// Held-out RMS of the weighted residual before (the reference) and with the candidate, mm.
    pub held_out_rms_before_mm: f64,
    /// With the candidate, mm.
    pub held_out_rms_after_mm: f64,
    /// sqrt of the held-out mean-square reduction against the reference, mm (negative: it made
    /// things worse). The reference of `geometry` is the model as it is; that of every effect is
    /// the recalibration (`geometry`), so an effect is credited only with what it adds to it.
    pub effect_mm: f64,
    /// sqrt of the held-out mean-square reduction against the model as it is, mm: ranks the
    /// significant candidates.
    pub total_gain_mm: f64,
    /// One-sided p-value of the paired held-out block test.
    pub p_value: f64,
    /// BIC(candidate) - BIC(reference) on the training rows.
    pub delta_bic: f64,
    /// Whether it passed every test.
    pub significant: bool,
    /// Why not, if not.
    pub note: String,
}

/// What a candidate is measured against.
pub(crate) struct Reference<'r> {
    /// The reference's change of every row's residual (`None`: the model as it is).
    pub delta: Option<&'r [[f64; 3]]>,
    /// Its training sum of squares (weighted, mm^2).
    pub train_sse: f64,
    /// Its number of parameters.
    pub k: usize,
    /// The recalibration's held-out gain (mean square per row, mm^2), for the parsimony rule;
    /// `None` when the candidate is the recalibration itself.
    pub recalibration_gain_ms: Option<f64>,
    /// Whether the recalibration was significant this round.
    pub recalibration_significant: bool,
}

impl<'r> Reference<'r> {
    /// The model as it is: the reference of the recalibration itself.
    pub fn model_as_is(ctx: &Context, train: &[usize]) -> Reference<'r> {
        Reference {
            delta: None,
            train_sse: ctx.sse(train, None),
            k: 0,
            recalibration_gain_ms: None,
            recalibration_significant: false,
        }
    }
}

/// The setting every candidate of a round is scored in.
pub(crate) struct Round<'c, 'a> {
    /// Round (1-based).
    pub round: usize,
    /// The model's residuals.
    pub ctx: &'c Context<'a>,
    /// Training rows.
    pub train: &'c [usize],
    /// Held-out rows.
    pub test: &'c [usize],
    /// The time blocks and which are held out.
    pub blocks: &'c Blocks,
    /// The attribution's settings.
    pub opts: &'c Options,
    /// Candidates tried this round (the Bonferroni divisor).
    pub n_candidates: usize,
    /// What the capture noise explains of a row's weighted mean square, mm^2.
    pub noise_ms: f64,
}

impl Round<'_, '_> {
    /// Scores a fitted candidate against `reference`.
    pub fn score(&self, f: &Fitted, reference: &Reference) -> Score {
        let (ctx, test, nb) = (self.ctx, self.test, self.blocks.len());
        let n_test = test.len().max(1) as f64;
        let raw: f64 = sse_per_block(ctx, test, None, nb).iter().sum();
        let a = sse_per_block(ctx, test, reference.delta, nb);
        let b = sse_per_block(ctx, test, Some(&f.delta), nb);
        let (sa, sb): (f64, f64) = (a.iter().sum(), b.iter().sum());
        let p = paired_ratio_p(&a, &b, &self.blocks.held_out);
        let delta_bic = self.delta_bic(f, reference);
        // Position part of the reduction, per row (mm^2): the weighted residual has three parts.
        let red = (sa - sb) / n_test;
        let effect_mm = signed_sqrt(red);
        let share = self.structured_share(red, sa / n_test);
        let mut note = self.failed_tests(p, effect_mm, delta_bic, share);
        if !note.is_empty() && self.simpler_than_recalibration(f, reference, raw) {
            note.clear();
        }
        Score {
            round: self.round,
            name: f.name.to_string(),
            params: f.params.clone(),
            held_out_rms_before_mm: rms(sa, test.len()),
            held_out_rms_after_mm: rms(sb, test.len()),
            effect_mm,
            total_gain_mm: signed_sqrt((raw - sb) / n_test),
            p_value: p,
            delta_bic,
            significant: note.is_empty(),
            note: note.join("; "),
        }
    }

    /// The round's significance level of one candidate (Bonferroni).
    fn alpha(&self) -> f64 {
        self.opts.alpha / self.n_candidates.max(1) as f64
    }

    /// BIC(reference + candidate) - BIC(reference) on the training rows.
    fn delta_bic(&self, f: &Fitted, reference: &Reference) -> f64 {
        let n = 3 * self.train.len();
        let bic = |sse: f64, k: usize| {
            n as f64 * (sse.max(1e-300) / n as f64).ln() + k as f64 * (n as f64).ln()
        };
        bic(f.train_sse, reference.k + f.k) - bic(reference.train_sse, reference.k)
    }

    /// The share of the reference's held-out mean square above the capture noise that the
    /// reduction `red` (mm^2 per row) removes (0 when nothing is above the noise).
    fn structured_share(&self, red: f64, reference_ms: f64) -> f64 {
        let excess = reference_ms - self.noise_ms;
        if excess > 0.0 {
            red / excess
        } else {
            0.0
        }
    }

    /// Why a candidate is not claimed by the main rule, one note per failed test.
    fn failed_tests(&self, p: f64, effect_mm: f64, delta_bic: f64, share: f64) -> Vec<String> {
        let (alpha, min_effect) = (self.alpha(), self.opts.min_effect_mm);
        let mut note = Vec::new();
        if p >= alpha {
            note.push(format!("p = {p:.2e} >= {alpha:.1e}"));
        }
        if effect_mm < min_effect {
            note.push(format!("held-out gain {effect_mm:.4} mm < {min_effect} mm"));
        }
        if delta_bic >= 0.0 {
            note.push(format!("BIC does not improve ({delta_bic:+.1})"));
        }
        // A cause explains a good part of the structure it is tested on; a candidate that only
        // projects a little of an unknown cause is not claimed.
        if share < MIN_SHARE {
            note.push(format!(
                "explains {:.0} % of the structured residual (< {:.0} %)",
                100.0 * share,
                100.0 * MIN_SHARE
            ));
        }
        note
    }

    /// Parsimony: an effect that alone (without the recalibration) gains at least 90 % of what
    /// a significant recalibration gains, significantly, is the simpler explanation of the same
    /// residual. `raw`: the held-out sum of squares of the model as it is.
    fn simpler_than_recalibration(&self, f: &Fitted, reference: &Reference, raw: f64) -> bool {
        let (Some(alone), Some(recal)) = (&f.alone, reference.recalibration_gain_ms) else {
            return false;
        };
        let (ctx, test, nb) = (self.ctx, self.test, self.blocks.len());
        let c = sse_per_block(ctx, test, Some(alone), nb);
        let raw_b = sse_per_block(ctx, test, None, nb);
        let sc: f64 = c.iter().sum();
        let gain = (raw - sc) / test.len().max(1) as f64;
        let pa = paired_ratio_p(&raw_b, &c, &self.blocks.held_out);
        reference.recalibration_significant
            && recal > 0.0
            && gain >= 0.9 * recal
            && pa < self.alpha()
            && gain.sqrt() >= self.opts.min_effect_mm
    }
}

/// The weighted sum of squares of the rows `idx` per block, with the residual change `delta`
/// taken off.
pub(crate) fn sse_per_block(
    ctx: &Context,
    idx: &[usize],
    delta: Option<&[[f64; 3]]>,
    nb: usize,
) -> Vec<f64> {
    let mut out = vec![0.0; nb];
    for &i in idx {
        let r = ctx.rows[i].r;
        let d = delta.map_or([0.0; 3], |d| d[i]);
        out[ctx.rows[i].block] +=
            (r[0] - d[0]).powi(2) + (r[1] - d[1]).powi(2) + (r[2] - d[2]).powi(2);
    }
    out
}

/// One-sided paired t-test over the held-out blocks that `b` is smaller than `a`.
pub(crate) fn paired_p(a: &[f64], b: &[f64], held: &[bool]) -> f64 {
    let d: Vec<f64> = a
        .iter()
        .zip(b)
        .zip(held)
        .filter(|(_, h)| **h)
        .map(|((x, y), _)| x - y)
        .collect();
    let n = d.len();
    if n < 3 {
        return 1.0;
    }
    let m = d.iter().sum::<f64>() / n as f64;
    let sd = (d.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
    if sd == 0.0 {
        return if m > 0.0 { 0.0 } else { 1.0 };
    }
    let t = m / (sd / (n as f64).sqrt());
    let Ok(dist) = StudentsT::new(0.0, 1.0, (n - 1) as f64) else {
        return 1.0;
    };
    1.0 - dist.cdf(t)
}

/// One-sided paired t-test over the held-out blocks that `b` is smaller than `a`, on the
/// logarithms of the per-block ratios a/b: the test a candidate passes.
///
/// An effect takes off a share of what it leaves in each block, and that share is much the same
/// from block to block, where the differences a - b are not: a creep or a drift is large in the
/// blocks long after a move and small in the others, so that a test on the differences sees a
/// few large ones and many small and doubts an improvement that every block shows (on a
/// 12,000-row recording with a creep, every held-out block better by a factor of 2 to 20 had
/// p = 3e-3 on the differences). Blocks without a positive sum on both sides are left out.
pub(crate) fn paired_ratio_p(a: &[f64], b: &[f64], held: &[bool]) -> f64 {
    let (la, lb): (Vec<f64>, Vec<f64>) = a
        .iter()
        .zip(b)
        .zip(held)
        .filter(|((x, y), h)| **h && **x > 0.0 && **y > 0.0)
        .map(|((x, y), _)| (x.ln(), y.ln()))
        .unzip();
    paired_p(&la, &lb, &vec![true; la.len()])
}

/// RMS of a sum of squares over `n` rows.
pub(crate) fn rms(sse: f64, n: usize) -> f64 {
    (sse / n.max(1) as f64).sqrt()
}

/// The square root with the sign of `v`: a mean-square reduction as a length (negative: worse).
fn signed_sqrt(v: f64) -> f64 {
    v.signum() * v.abs().sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paired_p_is_small_when_every_held_out_block_improves() {
        let a = [10.0, 11.0, 9.5, 10.5, 10.2, 100.0];
        let b = [9.0, 10.1, 8.4, 9.6, 9.1, 1.0];
        let held = [true, true, true, true, true, false];
        assert!(paired_p(&a, &b, &held) < 1e-3);
        // The other way round it is near 1; the training block (100 -> 1) is not counted.
        assert!(paired_p(&b, &a, &held) > 0.99);
    }

    #[test]
    fn the_ratio_test_sees_an_improvement_every_block_shows_whatever_its_size() {
        // Every held-out block better by a factor of 2 to 20: the differences range over three
        // orders of magnitude, the logarithms of the ratios do not.
        let a = [
            0.02, 0.03, 0.05, 1.0, 8.0, 0.04, 0.02, 30.0, 0.03, 0.05, 100.0,
        ];
        let b = [
            0.01, 0.01, 0.02, 0.1, 0.4, 0.02, 0.01, 1.5, 0.01, 0.02, 500.0,
        ];
        let held = [
            true, true, true, true, true, true, true, true, true, true, false,
        ];
        assert!(
            paired_p(&a, &b, &held) > 0.05,
            "{}",
            paired_p(&a, &b, &held)
        );
        assert!(paired_ratio_p(&a, &b, &held) < 1e-3);
        assert!(paired_ratio_p(&b, &a, &held) > 0.99);
        // A candidate that fits the noise: ratios about 1 either way.
        let c = [
            0.021, 0.029, 0.051, 1.01, 7.9, 0.041, 0.0199, 30.2, 0.0301, 0.049, 1.0,
        ];
        assert!(paired_ratio_p(&a, &c, &held) > 0.01);
    }

    #[test]
    fn paired_p_needs_three_held_out_blocks() {
        assert_eq!(paired_p(&[2.0, 2.0], &[1.0, 1.0], &[true, true]), 1.0);
    }

    #[test]
    fn signed_sqrt_keeps_the_sign() {
        assert_eq!(signed_sqrt(4.0), 2.0);
        assert_eq!(signed_sqrt(-9.0), -3.0);
    }
}
