//! `geometry`: the remaining geometric error, the calibration parameters (psi, l_C, the map
//! coefficients, r_p, theta_p per leg) refitted on every training row. A recalibration: it
//! absorbs, it does not explain; and the reference every other candidate is scored against.

use super::joint_fit::fit_joint;
use super::{lerp, Effect, Role};
use crate::context::Context;
use crate::extension::Extension;
use crate::fitted::{Estimate, Fitted};
use pcr_robot::RobotConfig;

/// The `geometry` candidate.
#[derive(Debug)]
pub struct Geometry;

/// Written into the legs: no part of the prediction beyond the constant-curvature model's.
impl Extension for Geometry {}

impl Effect for Geometry {
    fn name(&self) -> &'static str {
        "geometry"
    }

    fn description(&self) -> &'static str {
        "remaining geometric error: the calibration parameters refitted on every row"
    }

    fn role(&self) -> Role {
        Role::Reference
    }

    /// The calibration parameters refitted on every training row.
    fn fit(&self, ctx: &Context, train: &[usize]) -> Option<Fitted> {
        let nui = ctx.nuisance().nui.clone();
        let (fit, delta, alone) = fit_joint(ctx, &nui, train, 0, &|_, _| {}, None)?;
        let params = nui
            .names()
            .iter()
            .zip(&fit.x)
            .zip(&fit.std)
            .map(|((n, v), s)| Estimate::new(n, *v, Some(*s), "change"))
            .collect();
        let k = nui.n;
        let sse = fit.sse;
        let x = fit.x;
        Some(Fitted {
            name: self.name(),
            params,
            k,
            delta,
            alone,
            train_sse: sse,
            change: std::sync::Arc::new(move |c| nui.apply(&x, c)),
        })
    }

    fn file_position(&self) -> u8 {
        0
    }

    /// The legs' geometry (every candidate's fit moves it with the calibration parameters).
    fn blend(&self, old: &RobotConfig, new: &mut RobotConfig, s: f64) {
        for (o, a) in new.legs.iter_mut().zip(&old.legs) {
            o.r_base_mm = lerp(a.r_base_mm, o.r_base_mm, s);
            o.beta_deg = lerp(a.beta_deg, o.beta_deg, s);
            o.psi_deg = lerp(a.psi_deg, o.psi_deg, s);
            o.l_c_mm = lerp(a.l_c_mm, o.l_c_mm, s);
            o.l_ce_mm = lerp(a.l_ce_mm, o.l_ce_mm, s);
            o.l_st_mm = lerp(a.l_st_mm, o.l_st_mm, s);
            o.r_p_mm = lerp(a.r_p_mm, o.r_p_mm, s);
            o.theta_p_deg = lerp(a.theta_p_deg, o.theta_p_deg, s);
        }
    }
}
