//! `external_load`: compliance under an external load. A constant wrench on the platform bends
//! the segments (the kineto-static model of [`super::compliance`], the force and couple of
//! `[effects.compliance]`); the chain's IK is the loaded model's.

use super::{compliance, lerp, Effect, Parameter};
use crate::context::Context;
use crate::extension::Extension;
use crate::fitted::{Estimate, Fitted};
use pcr_kinematics::statics::Loads;
use pcr_robot::effects::Effects;
use pcr_robot::RobotConfig;

/// The `external_load` candidate.
#[derive(Debug)]
pub struct ExternalLoad;

impl Extension for ExternalLoad {
    /// The declared compliance's loads (the same as `joint_springs`').
    fn loads(&self, effects: &Effects) -> Option<Loads> {
        compliance::loads(effects)
    }
}

impl Effect for ExternalLoad {
    fn consistency(&self) -> super::Parts {
        super::Parts::Workspace
    }

    fn name(&self) -> &'static str {
        "external_load"
    }

    fn description(&self) -> &'static str {
        "compliance under an external load: a constant wrench on the platform bends the segments (kineto-static)"
    }

    /// F_x, F_y (N) and M (N mm) with the calibration parameters.
    fn fit(&self, ctx: &Context, train: &[usize]) -> Option<Fitted> {
        compliance::fit(ctx, train, self.name(), &[0, 1, 2])
    }

    fn share(&self, ctx: &Context) {
        compliance::share(ctx);
    }

    fn declared(&self, effects: &Effects, _fitted: &[Estimate]) -> Option<Vec<Estimate>> {
        effects.compliance.as_ref().map(|k| {
            vec![
                Estimate::new("force x", k.force_n[0], None, "N"),
                Estimate::new("force y", k.force_n[1], None, "N"),
                Estimate::new("couple", k.couple_n_mm, None, "N mm"),
                Estimate::new("EI (assumed)", k.ei_n_mm2, None, "N mm^2"),
            ]
        })
    }

    /// The load out; the compliance entry goes when it holds no springs either.
    fn remove(&self, effects: &mut Effects, _params: &[Estimate]) {
        if let Some(c) = &mut effects.compliance {
            c.force_n = [0.0; 2];
            c.couple_n_mm = 0.0;
            if c.k_m_n_mm_per_rad == 0.0 && c.k_p_n_mm_per_rad == 0.0 {
                effects.compliance = None;
            }
        }
    }

    fn file_position(&self) -> u8 {
        5
    }

    /// F_x, F_y (N) and M (100 N mm), when the compliance has a wrench.
    fn parameters(&self, effects: &Effects) -> Vec<Parameter> {
        let Some(c) = &effects.compliance else {
            return Vec::new();
        };
        if c.force_n[0] == 0.0 && c.force_n[1] == 0.0 && c.couple_n_mm == 0.0 {
            return Vec::new();
        }
        (0..3)
            .map(|j| Parameter {
                get: |e, j| {
                    e.compliance.as_ref().map_or(0.0, |c| match j {
                        0 => c.force_n[0],
                        1 => c.force_n[1],
                        _ => c.couple_n_mm / 100.0,
                    })
                },
                set: |e, j, x| {
                    if let Some(c) = e.compliance.as_mut() {
                        match j {
                            0 => c.force_n[0] = x,
                            1 => c.force_n[1] = x,
                            _ => c.couple_n_mm = 100.0 * x,
                        }
                    }
                },
                index: j,
                lo: -50.0,
                hi: 50.0,
                moves_curvatures: false,
                along_path: None,
            })
            .collect()
    }

    fn blend(&self, old: &RobotConfig, new: &mut RobotConfig, s: f64) {
        if let Some(c) = new.effects.compliance.as_mut() {
            let z = Default::default();
            let o: &pcr_robot::effects::Compliance = old.effects.compliance.as_ref().unwrap_or(&z);
            c.force_n = [
                lerp(o.force_n[0], c.force_n[0], s),
                lerp(o.force_n[1], c.force_n[1], s),
            ];
            c.couple_n_mm = lerp(o.couple_n_mm, c.couple_n_mm, s);
        }
    }
}
