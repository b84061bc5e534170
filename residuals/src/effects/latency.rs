//! `latency`: command-to-motion latency beyond the recording's command delay. The motors are
//! where the command was `latency_s` earlier (`[effects.latency]`); the chain commands ahead by
//! it.

use super::joint_fit::{fit_joint, nuisance_change};
use super::motor_change::motor_side_delta;
use super::profile::{minimise_1d, profile_std, search_rows, sse_at};
use super::{lerp, Effect, Parameter};
use crate::context::Context;
use crate::extension::Extension;
use crate::fitted::{Estimate, Fitted};
use pcr_robot::effects::{self as robot, Effects};
use pcr_robot::RobotConfig;

/// The `latency` candidate.
#[derive(Debug)]
pub struct Latency;

/// The latency the robot file declares, s (0 without `[effects.latency]`).
pub fn held_s(effects: &Effects) -> f64 {
    effects.latency.as_ref().map_or(0.0, |l| l.latency_s)
}

/// `effects` with the latency `tau` (s) instead of its own.
pub fn with(effects: &Effects, tau: f64) -> Effects {
    let mut e = effects.clone();
    e.latency = Some(robot::Latency { latency_s: tau });
    e
}

impl Extension for Latency {
    /// The declared latency.
    fn delay_s(&self, effects: &Effects) -> f64 {
        held_s(effects)
    }
}

impl Effect for Latency {
    fn name(&self) -> &'static str {
        "latency"
    }

    fn description(&self) -> &'static str {
        "command-to-motion latency: the motion lags the command"
    }

    /// The motion lags the command by tau: a profile over tau (the motor side of the model
    /// re-run, linearised through each row's Jacobian), then the calibration parameters with
    /// the change at the best tau.
    fn fit(&self, ctx: &Context, train: &[usize]) -> Option<Fitted> {
        let rows = search_rows(train);
        let shift = |tau: f64, rows: Option<&[usize]>| -> Vec<[f64; 3]> {
            motor_side_delta(ctx, &with(&ctx.model.config.effects, tau), rows)
        };
        // From scratch: -50 ms to 0.5 s. Once the model holds a latency (a Gauss-Newton step of
        // its acceptance), it moves little from one step to the next: 30 ms around it.
        let grid: Vec<f64> = match &ctx.model.config.effects.latency {
            None => (0..=55).map(|k| -0.05 + 0.01 * k as f64).collect(),
            Some(l) => (-3..=3).map(|k| l.latency_s + 0.01 * k as f64).collect(),
        };
        let (tau, sse, curv) =
            minimise_1d(&mut |t| sse_at(ctx, &rows, &shift(t, Some(&rows))), &grid);
        let std = profile_std(sse, 3 * rows.len(), curv);
        let nui = ctx.nuisance().nui.clone();
        let off = shift(tau, None);
        let (fit, delta, alone) = fit_joint(ctx, &nui, train, 0, &|_, _| {}, Some(&off))?;
        let nuis = nuisance_change(nui, fit.x.clone(), 0);
        Some(Fitted {
            name: self.name(),
            params: vec![Estimate::new("latency", tau, std, "s")],
            k: 1,
            delta,
            alone,
            train_sse: fit.sse,
            change: std::sync::Arc::new(move |c| {
                c.effects.latency = Some(robot::Latency { latency_s: tau });
                nuis(c);
            }),
        })
    }

    fn declared(&self, effects: &Effects, _fitted: &[Estimate]) -> Option<Vec<Estimate>> {
        effects
            .latency
            .as_ref()
            .map(|l| vec![Estimate::new("latency", l.latency_s, None, "s")])
    }

    fn remove(&self, effects: &mut Effects, _params: &[Estimate]) {
        effects.latency = None;
    }

    /// Visible in motion only: the first against the second half of the training time.
    fn consistency(&self) -> super::Parts {
        super::Parts::Halves
    }

    fn file_position(&self) -> u8 {
        1
    }

    /// The latency, s.
    fn parameters(&self, effects: &Effects) -> Vec<Parameter> {
        if effects.latency.is_none() {
            return Vec::new();
        }
        vec![Parameter {
            get: |e, _| held_s(e),
            set: |e, _, x| {
                if let Some(l) = e.latency.as_mut() {
                    l.latency_s = x
                }
            },
            index: 0,
            lo: -0.2,
            hi: 1.0,
            moves_curvatures: true,
            along_path: None,
        }]
    }

    fn blend(&self, old: &RobotConfig, new: &mut RobotConfig, s: f64) {
        if let Some(l) = new.effects.latency.as_mut() {
            l.latency_s = lerp(held_s(&old.effects), l.latency_s, s);
        }
    }

    /// A motion that leads its command by more than 10 ms.
    fn unphysical(&self, effects: &Effects, _max_change: f64) -> Option<String> {
        let l = effects.latency.as_ref()?;
        (l.latency_s < -0.01)
            .then(|| format!("the motion leads the command by {:.3} s", -l.latency_s))
    }
}
