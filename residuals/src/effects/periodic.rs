//! `periodic`: periodic transmission error of one motor. Its output lags it by
//! `A sin(2 pi q / P + phase)` (`[[effects.periodic]]`, one entry per term); the drive commands
//! the motor where its output reaches the target. Tried again after it is added (another term).

use super::joint_fit::{fit_joint, nuisance_change};
use super::profile::search_rows;
use super::{lerp, Effect, Parameter};
use crate::context::Context;
use crate::extension::Extension;
use crate::fitted::{Estimate, Fitted};
use crate::linear::{motor_delta, Columns};
use pcr_robot::effects::{self as robot, Effects};
use pcr_robot::RobotConfig;

/// Fewest periods the data must cover on a motor's travel for a period to be scanned: a
/// "periodic" error that repeats fewer times over the positions the motor took is a smooth
/// function of that position, which a tendon map that the families cannot quite follow
/// imitates as well (on `../shared/data/foreign-f0`, a clean robot, periods of 256 to 320 steps
/// over a travel of 720 steps were named before this rule); the calibration and the
/// `tendon_map` recalibration cover those.
pub const MIN_CYCLES: f64 = 3.0;

/// The `periodic` candidate.
#[derive(Debug)]
pub struct Periodic;

/// Periodic transmission errors on motor outputs (steps, one entry per row), in place.
pub fn apply(q: &mut [[f64; 3]], periodic: &[robot::Periodic]) {
    for p in periodic {
        let i = (p.motor as usize).clamp(1, 3) - 1;
        let ph = p.phase_deg.to_radians();
        for v in q.iter_mut() {
            v[i] -= p.amplitude_steps * (std::f64::consts::TAU * v[i] / p.period_steps + ph).sin();
        }
    }
}

/// Which term of `effects` has the motor and the period of `params`.
fn term(effects: &Effects, params: &[Estimate]) -> Option<usize> {
    let value = |n: &str| params.iter().find(|p| p.name == n).map(|p| p.value);
    effects.periodic.iter().position(|t| {
        value("motor").is_some_and(|m| (m - f64::from(t.motor)).abs() < 0.5)
            && value("period").is_some_and(|p| (p - t.period_steps).abs() < 1e-6)
    })
}

/// The term `held` plus the addition `added` (a fit's parameters: amplitude and phase, with
/// errors) as one term: A sin(x + phase) adds as the phasor A e^(i phase). The amplitude keeps
/// the addition's error, the phase its error over the summed amplitude.
fn with_held(held: &robot::Periodic, added: &[Estimate]) -> Vec<Estimate> {
    let get = |n: &str| added.iter().find(|p| p.name == n);
    let (Some(a), Some(ph)) = (get("amplitude"), get("phase")) else {
        return added.to_vec();
    };
    let (p0, p1) = (held.phase_deg.to_radians(), ph.value.to_radians());
    let s = held.amplitude_steps * p0.cos() + a.value * p1.cos();
    let c = held.amplitude_steps * p0.sin() + a.value * p1.sin();
    let amp = s.hypot(c);
    added
        .iter()
        .map(|p| match p.name.as_str() {
            "amplitude" => Estimate::new("amplitude", amp, p.std, &p.unit),
            "phase" => Estimate::new(
                "phase",
                c.atan2(s).to_degrees(),
                a.std.map(|e| (e / amp.max(1e-12)).to_degrees()),
                &p.unit,
            ),
            _ => p.clone(),
        })
        .collect()
}

impl Extension for Periodic {
    /// Every declared term.
    fn transmission(&self, effects: &Effects, q: &mut [[f64; 3]]) {
        apply(q, &effects.periodic);
    }
}

impl Periodic {
    /// The fit, its motor and period scanned (`only`: the motor index and the period given).
    fn fit_searched(
        &self,
        ctx: &Context,
        train: &[usize],
        only: Option<(usize, f64)>,
    ) -> Option<Fitted> {
        let spr = ctx.model.config.legs[0].actuation.steps_per_rev as f64;
        let mut periods: Vec<f64> = (4..=256).map(f64::from).collect();
        let mut p = 272.0;
        while p <= spr {
            periods.push(p);
            p += 16.0;
        }
        // Precompute each train row's motor column (d weighted pose / d q_m) dotted with r and
        // with itself, then scan.
        let mut best: Option<(f64, usize, f64)> = None; // (sse reduction, motor, period)
        for m in 0..3 {
            if only.is_some_and(|(om, _)| om != m) {
                continue;
            }
            let (lo, hi) = train
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |a, &i| {
                    let q = ctx.pred(&ctx.rows[i]).q_eff[m];
                    (a.0.min(q), a.1.max(q))
                });
            let longest = (hi - lo) / MIN_CYCLES;
            // Per motor position (to a millionth of a step): the sums over its rows of the
            // column dotted with the residual and with itself. Rows at rest and rows that
            // return to a position share one: the scan below evaluates sin and cos once per
            // position and period, not once per row.
            let mut at: Vec<(f64, f64, f64)> = search_rows(train)
                .iter()
                .map(|&i| {
                    let mut dq = [0.0; 3];
                    dq[m] = 1.0;
                    let c = motor_delta(ctx, i, dq);
                    let r = ctx.rows[i].r;
                    let q = ctx.pred(&ctx.rows[i]).q_eff[m];
                    (
                        q,
                        c[0] * r[0] + c[1] * r[1] + c[2] * r[2],
                        c[0] * c[0] + c[1] * c[1] + c[2] * c[2],
                    )
                })
                .collect();
            at.sort_by(|a, b| a.0.total_cmp(&b.0));
            let mut rows: Vec<(f64, f64, f64)> = Vec::with_capacity(at.len());
            for (q, cr, c2) in at {
                match rows.last_mut() {
                    Some(last) if (q - last.0).abs() <= 1e-6 => {
                        last.1 += cr;
                        last.2 += c2;
                    }
                    _ => rows.push((q, cr, c2)),
                }
            }
            for &per in periods
                .iter()
                .filter(|p| only.map_or(**p <= longest, |(_, op)| (**p - op).abs() < 1e-9))
            {
                let w = std::f64::consts::TAU / per;
                let (mut ss, mut sc, mut cc, mut rs, mut rc) = (0.0, 0.0, 0.0, 0.0, 0.0);
                for &(q, cr, c2) in &rows {
                    let (sn, cs) = (w * q).sin_cos();
                    ss += c2 * sn * sn;
                    sc += c2 * sn * cs;
                    cc += c2 * cs * cs;
                    rs += cr * sn;
                    rc += cr * cs;
                }
                let det = ss * cc - sc * sc;
                if det <= 0.0 {
                    continue;
                }
                let a = (cc * rs - sc * rc) / det;
                let b = (ss * rc - sc * rs) / det;
                let red = a * rs + b * rc;
                if best.is_none_or(|x| red > x.0) {
                    best = Some((red, m, per));
                }
            }
        }
        let (_, m, per) = best?;
        let w = std::f64::consts::TAU / per;
        let effect = |i: usize, c: &mut Columns| {
            let q = ctx.pred(&ctx.rows[i]).q_eff[m];
            let mut dq = [0.0; 3];
            dq[m] = 1.0;
            let col = motor_delta(ctx, i, dq);
            let (sn, cs) = (w * q).sin_cos();
            c[0] = col.map(|v| v * sn);
            c[1] = col.map(|v| v * cs);
        };
        let nui = ctx.nuisance().nui.clone();
        let (fit, delta, alone) = fit_joint(ctx, &nui, train, 2, &effect, None)?;
        // Output = q - A sin(w q + phase): the residual change is -A(sin cos(ph) + cos sin(ph)).
        let (a_s, a_c) = (-fit.x[0], -fit.x[1]);
        let amp = a_s.hypot(a_c);
        let phase = a_c.atan2(a_s);
        let amp_std = (fit.std[0].hypot(fit.std[1])) / 2f64.sqrt();
        let nuis = nuisance_change(nui, fit.x.clone(), 2);
        let entry = robot::Periodic {
            motor: (m + 1) as u8,
            period_steps: per,
            amplitude_steps: amp,
            phase_deg: phase.to_degrees(),
        };
        Some(Fitted {
            name: self.name(),
            params: vec![
                Estimate::new("motor", (m + 1) as f64, None, ""),
                Estimate::new("period", per, None, "steps"),
                Estimate::new("amplitude", amp, Some(amp_std), "steps"),
                Estimate::new(
                    "phase",
                    phase.to_degrees(),
                    Some((amp_std / amp.max(1e-12)).to_degrees()),
                    "deg",
                ),
            ],
            k: 4,
            delta,
            alone,
            train_sse: fit.sse,
            change: std::sync::Arc::new(move |c| {
                c.effects.periodic.push(entry.clone());
                nuis(c);
            }),
        })
    }
}

impl Effect for Periodic {
    fn name(&self) -> &'static str {
        "periodic"
    }

    fn description(&self) -> &'static str {
        "periodic transmission error: the output of one motor lags it periodically in its position"
    }

    /// Fitted once: its motor and period are scanned from scratch.
    fn iterable(&self) -> bool {
        false
    }

    /// Every acceptance adds a term.
    fn repeatable(&self) -> bool {
        true
    }

    /// The output of one motor lags it by A sin(2 pi q / P + phase): every motor and every
    /// period from 4 steps to a revolution that repeats at least [`MIN_CYCLES`] times over the
    /// motor's travel in the data is scanned, the best pair is fitted.
    fn fit(&self, ctx: &Context, train: &[usize]) -> Option<Fitted> {
        self.fit_searched(ctx, train, None)
    }

    /// The motor and the period of the whole fit `whole`, their amplitude and phase fitted
    /// again: a part of the data holds too few positions of a motor to scan them afresh. Where
    /// the model already holds that term, the part's fit is what it adds to it, and the term
    /// reported is the sum ([`with_held`]): the phase of a near-zero addition says nothing.
    fn fit_like(&self, ctx: &Context, train: &[usize], whole: &[Estimate]) -> Option<Fitted> {
        let value = |n: &str| whole.iter().find(|p| p.name == n).map(|p| p.value);
        match (value("motor"), value("period")) {
            (Some(m), Some(p)) if (1.0..=3.0).contains(&m) => {
                let mut f = self.fit_searched(ctx, train, Some((m.round() as usize - 1, p)))?;
                if let Some(i) = term(&ctx.model.config.effects, whole) {
                    f.params = with_held(&ctx.model.config.effects.periodic[i], &f.params);
                }
                Some(f)
            }
            _ => self.fit(ctx, train),
        }
    }

    /// The term of the motor and period it was added with (the last term if they match none).
    fn remove(&self, effects: &mut Effects, params: &[Estimate]) {
        if let Some(i) = term(effects, params).or(effects.periodic.len().checked_sub(1)) {
            effects.periodic.remove(i);
        }
    }

    /// The term of the motor and period it was fitted with, as the file holds it now (the joint
    /// refinement and the calibration from the drawing move its amplitude and phase after the
    /// round's linearised fit).
    fn declared(&self, effects: &Effects, fitted: &[Estimate]) -> Option<Vec<Estimate>> {
        let t = &effects.periodic[term(effects, fitted)?];
        Some(vec![
            Estimate::new("motor", f64::from(t.motor), None, ""),
            Estimate::new("period", t.period_steps, None, "steps"),
            Estimate::new("amplitude", t.amplitude_steps, None, "steps"),
            Estimate::new("phase", t.phase_deg, None, "deg"),
        ])
    }

    fn file_position(&self) -> u8 {
        8
    }

    /// The first half of the training time against the second: both halves take every position
    /// of the motor at rest and moving, the static rows alone take too few of them.
    fn consistency(&self) -> super::Parts {
        super::Parts::Halves
    }

    /// The amplitude (steps) and the phase (deg) of every term.
    fn parameters(&self, effects: &Effects) -> Vec<Parameter> {
        let mut v = Vec::new();
        for k in 0..effects.periodic.len() {
            v.push(Parameter {
                get: |e, k| e.periodic[k].amplitude_steps,
                set: |e, k, x| e.periodic[k].amplitude_steps = x,
                index: k,
                lo: -50.0,
                hi: 50.0,
                moves_curvatures: true,
                along_path: None,
            });
            v.push(Parameter {
                get: |e, k| e.periodic[k].phase_deg,
                set: |e, k, x| e.periodic[k].phase_deg = x,
                index: k,
                lo: -720.0,
                hi: 720.0,
                moves_curvatures: true,
                along_path: None,
            });
        }
        v
    }

    /// The amplitudes, when `new` has at least the terms of `old` (a term absent from `old`
    /// counting as zero).
    fn blend(&self, old: &RobotConfig, new: &mut RobotConfig, s: f64) {
        let eo = &old.effects;
        if eo.periodic.len() <= new.effects.periodic.len() {
            for (k, p) in new.effects.periodic.iter_mut().enumerate() {
                let a0 = eo.periodic.get(k).map_or(0.0, |x| x.amplitude_steps);
                p.amplitude_steps = lerp(a0, p.amplitude_steps, s);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn term(motor: u8, period: f64, amplitude: f64, phase: f64) -> robot::Periodic {
        robot::Periodic {
            motor,
            period_steps: period,
            amplitude_steps: amplitude,
            phase_deg: phase,
        }
    }

    /// A part's fit around a model that holds the term is the term plus the part's addition:
    /// a near-zero addition leaves the held term (its phase does not count), an addition in
    /// phase adds to the amplitude.
    #[test]
    fn a_parts_addition_is_reported_with_the_held_term() {
        let held = term(3, 64.0, 10.0, 30.0);
        let added = |amp: f64, phase: f64| {
            vec![
                Estimate::new("motor", 3.0, None, ""),
                Estimate::new("period", 64.0, None, "steps"),
                Estimate::new("amplitude", amp, Some(0.01), "steps"),
                Estimate::new("phase", phase, Some(40.0), "deg"),
            ]
        };
        let value = |v: &[Estimate], n: &str| v.iter().find(|p| p.name == n).unwrap().value;
        let tiny = with_held(&held, &added(0.004, -150.0));
        assert!((value(&tiny, "amplitude") - 9.996).abs() < 1e-3, "{tiny:?}");
        assert!((value(&tiny, "phase") - 30.0).abs() < 0.02, "{tiny:?}");
        let std = tiny
            .iter()
            .find(|p| p.name == "phase")
            .unwrap()
            .std
            .unwrap();
        assert!((std - (0.01f64 / 9.996).to_degrees()).abs() < 1e-6);
        let same = with_held(&held, &added(0.5, 30.0));
        assert!((value(&same, "amplitude") - 10.5).abs() < 1e-9);
        assert!((value(&same, "phase") - 30.0).abs() < 1e-9);
        assert_eq!(value(&same, "period"), 64.0);
    }

    /// The report gives the term the file holds after the refinements, not the round's
    /// linearised fit (periodic-10x: 9.883 reported while the file held 10.014).
    #[test]
    fn the_declared_term_is_the_one_of_the_fits_motor_and_period() {
        let mut e = Effects {
            periodic: vec![term(1, 32.0, 0.5, 10.0), term(3, 64.0, 10.014, 29.93)],
            ..Effects::default()
        };
        let fitted = vec![
            Estimate::new("motor", 3.0, None, ""),
            Estimate::new("period", 64.0, None, "steps"),
            Estimate::new("amplitude", 9.883, Some(0.003), "steps"),
            Estimate::new("phase", 29.97, Some(0.02), "deg"),
        ];
        let d = Periodic.declared(&e, &fitted).expect("declared");
        let value = |n: &str| d.iter().find(|p| p.name == n).map(|p| p.value);
        assert_eq!(value("motor"), Some(3.0));
        assert_eq!(value("period"), Some(64.0));
        assert_eq!(value("amplitude"), Some(10.014));
        assert_eq!(value("phase"), Some(29.93));
        // A term the file no longer holds is not reported from the file.
        let other = vec![
            Estimate::new("motor", 2.0, None, ""),
            Estimate::new("period", 64.0, None, "steps"),
        ];
        assert!(Periodic.declared(&e, &other).is_none());
        // Removing takes out that term, not the last one.
        Periodic.remove(&mut e, &fitted[..2]);
        assert_eq!(e.periodic, vec![term(1, 32.0, 0.5, 10.0)]);
    }
}
