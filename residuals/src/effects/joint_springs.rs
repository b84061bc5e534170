//! `joint_springs`: compliance under the coupling forces. Springs in the passive joints,
//! relaxed where the robot was homed (the joint angles at the home motor positions), bend the
//! segments, large elastica deflections, through the link forces (the kineto-static model of
//! [`super::compliance`], `k_M`, `k_P` of `[effects.compliance]`); the chain's IK is the loaded
//! model's.

use super::{compliance, lerp, Effect, Parameter};
use crate::context::Context;
use crate::extension::Extension;
use crate::fitted::{Estimate, Fitted};
use pcr_kinematics::statics::Loads;
use pcr_robot::effects::Effects;
use pcr_robot::RobotConfig;

/// The `joint_springs` candidate.
#[derive(Debug)]
pub struct JointSprings;

impl Extension for JointSprings {
    /// The declared compliance's loads (the same as `external_load`'s).
    fn loads(&self, effects: &Effects) -> Option<Loads> {
        compliance::loads(effects)
    }
}

impl Effect for JointSprings {
    fn consistency(&self) -> super::Parts {
        super::Parts::Workspace
    }

    fn name(&self) -> &'static str {
        "joint_springs"
    }

    fn description(&self) -> &'static str {
        "compliance under the coupling forces: springs in the passive joints bend the segments (kineto-static)"
    }

    /// k_M and k_P (N mm/rad) with the calibration parameters.
    fn fit(&self, ctx: &Context, train: &[usize]) -> Option<Fitted> {
        compliance::fit(ctx, train, self.name(), &[3, 4])
    }

    fn share(&self, ctx: &Context) {
        compliance::share(ctx);
    }

    fn declared(&self, effects: &Effects, _fitted: &[Estimate]) -> Option<Vec<Estimate>> {
        effects.compliance.as_ref().map(|k| {
            vec![
                Estimate::new("k_M", k.k_m_n_mm_per_rad, None, "N mm/rad"),
                Estimate::new("k_P", k.k_p_n_mm_per_rad, None, "N mm/rad"),
                Estimate::new("EI (assumed)", k.ei_n_mm2, None, "N mm^2"),
            ]
        })
    }

    /// The springs out; the compliance entry goes when it holds no load either.
    fn remove(&self, effects: &mut Effects, _params: &[Estimate]) {
        if let Some(c) = &mut effects.compliance {
            c.k_m_n_mm_per_rad = 0.0;
            c.k_p_n_mm_per_rad = 0.0;
            if c.force_n == [0.0; 2] && c.couple_n_mm == 0.0 {
                effects.compliance = None;
            }
        }
    }

    fn file_position(&self) -> u8 {
        6
    }

    /// k_M and k_P in 100 N mm/rad, when the compliance has springs.
    fn parameters(&self, effects: &Effects) -> Vec<Parameter> {
        let Some(c) = &effects.compliance else {
            return Vec::new();
        };
        if c.k_m_n_mm_per_rad == 0.0 && c.k_p_n_mm_per_rad == 0.0 {
            return Vec::new();
        }
        (0..2)
            .map(|j| Parameter {
                get: |e, j| {
                    e.compliance.as_ref().map_or(0.0, |c| {
                        if j == 0 {
                            c.k_m_n_mm_per_rad / 100.0
                        } else {
                            c.k_p_n_mm_per_rad / 100.0
                        }
                    })
                },
                set: |e, j, x| {
                    if let Some(c) = e.compliance.as_mut() {
                        if j == 0 {
                            c.k_m_n_mm_per_rad = 100.0 * x
                        } else {
                            c.k_p_n_mm_per_rad = 100.0 * x
                        }
                    }
                },
                index: j,
                lo: -100.0,
                hi: 100.0,
                moves_curvatures: false,
                along_path: None,
            })
            .collect()
    }

    fn blend(&self, old: &RobotConfig, new: &mut RobotConfig, s: f64) {
        if let Some(c) = new.effects.compliance.as_mut() {
            let z = Default::default();
            let o: &pcr_robot::effects::Compliance = old.effects.compliance.as_ref().unwrap_or(&z);
            c.k_m_n_mm_per_rad = lerp(o.k_m_n_mm_per_rad, c.k_m_n_mm_per_rad, s);
            c.k_p_n_mm_per_rad = lerp(o.k_p_n_mm_per_rad, c.k_p_n_mm_per_rad, s);
        }
    }

    /// Springs of negative stiffness.
    fn unphysical(&self, effects: &Effects, _max_change: f64) -> Option<String> {
        let k = effects.compliance.as_ref()?;
        (k.k_m_n_mm_per_rad < 0.0 || k.k_p_n_mm_per_rad < 0.0).then(|| {
            format!(
                "negative joint springs (k_M {:.1}, k_P {:.1} N mm/rad)",
                k.k_m_n_mm_per_rad, k.k_p_n_mm_per_rad
            )
        })
    }
}
