//! `frame`: capture-frame misregistration. The measured pose is the robot's through a small
//! rigid transform; the model corrects every measurement by the declared transform
//! (`[effects.frame]`) before comparing it.

use super::joint_fit::{fit_joint, nuisance_change};
use super::{lerp, Effect, Parameter};
use crate::context::Context;
use crate::extension::Extension;
use crate::fitted::{Estimate, Fitted};
use crate::linear::Columns;
use pcr_robot::effects::{self as robot, Effects};
use pcr_robot::RobotConfig;

/// How much farther than the geometry a plausible capture frame may be off
/// ([`Effect::unphysical`]). Ten times was tried: a tendon cross-coupling of 3 % (outside the
/// vocabulary) was then named a 1.6 deg frame error, of 15 % a 4.7 deg one. A larger frame is
/// physical only where the static poses confirm it ([`CONFIRMED_FRAME_SCALE`]): 8 mm / 3 deg
/// is then found, and the cross-coupling's are not confirmed.
pub const FRAME_SCALE: f64 = 1.0;

/// How much farther than [`FRAME_SCALE`] a capture frame may be off where the static poses
/// confirm it ([`crate::recalibration::confirms_frame`]): a registration error that the
/// calibration's own poses show is a frame error whatever its size, up to this.
pub const CONFIRMED_FRAME_SCALE: f64 = 10.0;

/// How far beyond a plausible registration error the capture frame of `effects` is: the larger
/// of its offset over `max_change` mm and its rotation over a third of it in degrees (as
/// [`Effect::unphysical`] judges them at [`FRAME_SCALE`]); above 1 it is unphysical unless the
/// static poses confirm it, 0 without a frame.
pub fn excess(effects: &Effects, max_change: f64) -> f64 {
    effects.frame.as_ref().map_or(0.0, |f| {
        let (mm, deg) = (FRAME_SCALE * max_change, FRAME_SCALE * max_change / 3.0);
        (f.dx_mm.hypot(f.dy_mm) / mm).max(f.dphi_deg.abs() / deg)
    })
}

/// The `frame` candidate.
#[derive(Debug)]
pub struct Frame;

/// No correction: the frame of an effects section without `[effects.frame]`.
fn zero() -> robot::FrameCorrection {
    robot::FrameCorrection {
        dx_mm: 0.0,
        dy_mm: 0.0,
        dphi_deg: 0.0,
    }
}

impl Extension for Frame {
    /// The measurement corrected: R(dphi) m + d.
    fn corrected(&self, effects: &Effects, m: [f64; 3]) -> [f64; 3] {
        match &effects.frame {
            Some(f) => f.apply(m),
            None => m,
        }
    }
}

impl Effect for Frame {
    fn name(&self) -> &'static str {
        "frame"
    }

    fn description(&self) -> &'static str {
        "capture-frame misregistration: a rigid transform between the measured and the robot frame"
    }

    /// Measured = robot pose through a small rigid transform (dx, dy mm, dphi deg), added to
    /// the one the model holds.
    fn fit(&self, ctx: &Context, train: &[usize]) -> Option<Fitted> {
        let nui = ctx.nuisance().nui.clone();
        let effect = |i: usize, c: &mut Columns| {
            let row = &ctx.rows[i];
            let m = ctx.series[row.s].samples[row.k].pose.unwrap_or([0.0; 3]);
            // Correcting the measurement by (dx, dy, dphi) adds these to the residual; as a
            // predicted change of the residual they enter with the opposite sign.
            c[0] = [-1.0, 0.0, 0.0];
            c[1] = [0.0, -1.0, 0.0];
            c[2] = [m[1], -m[0], -ctx.w_phi];
        };
        let (fit, delta, alone) = fit_joint(ctx, &nui, train, 3, &effect, None)?;
        let prev = ctx.model.config.effects.frame.clone().unwrap_or_else(zero);
        let f = robot::FrameCorrection {
            dx_mm: prev.dx_mm + fit.x[0],
            dy_mm: prev.dy_mm + fit.x[1],
            dphi_deg: prev.dphi_deg + fit.x[2].to_degrees(),
        };
        let params = vec![
            Estimate::new("dx", f.dx_mm, Some(fit.std[0]), "mm"),
            Estimate::new("dy", f.dy_mm, Some(fit.std[1]), "mm"),
            Estimate::new("dphi", f.dphi_deg, Some(fit.std[2].to_degrees()), "deg"),
        ];
        let nuis = nuisance_change(nui, fit.x.clone(), 3);
        Some(Fitted {
            name: self.name(),
            params,
            k: 3,
            delta,
            alone,
            train_sse: fit.sse,
            change: std::sync::Arc::new(move |c| {
                c.effects.frame = Some(f.clone());
                nuis(c);
            }),
        })
    }

    fn declared(&self, effects: &Effects, _fitted: &[Estimate]) -> Option<Vec<Estimate>> {
        effects.frame.as_ref().map(|f| {
            vec![
                Estimate::new("dx", f.dx_mm, None, "mm"),
                Estimate::new("dy", f.dy_mm, None, "mm"),
                Estimate::new("dphi", f.dphi_deg, None, "deg"),
            ]
        })
    }

    fn remove(&self, effects: &mut Effects, _params: &[Estimate]) {
        effects.frame = None;
    }

    fn file_position(&self) -> u8 {
        7
    }

    /// dx, dy (mm), dphi (deg).
    fn parameters(&self, effects: &Effects) -> Vec<Parameter> {
        if effects.frame.is_none() {
            return Vec::new();
        }
        (0..3)
            .map(|j| Parameter {
                get: |e, j| {
                    e.frame.as_ref().map_or(0.0, |f| match j {
                        0 => f.dx_mm,
                        1 => f.dy_mm,
                        _ => f.dphi_deg,
                    })
                },
                set: |e, j, x| {
                    if let Some(f) = e.frame.as_mut() {
                        match j {
                            0 => f.dx_mm = x,
                            1 => f.dy_mm = x,
                            _ => f.dphi_deg = x,
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
        if let Some(f) = new.effects.frame.as_mut() {
            let z = zero();
            let o = old.effects.frame.as_ref().unwrap_or(&z);
            f.dx_mm = lerp(o.dx_mm, f.dx_mm, s);
            f.dy_mm = lerp(o.dy_mm, f.dy_mm, s);
            f.dphi_deg = lerp(o.dphi_deg, f.dphi_deg, s);
        }
    }

    /// A registration off by more than `max_change` mm or a third of it in degrees would be
    /// seen at once (1 deg is 5 mm at the base points), and larger rotations are what a
    /// coupling of the legs imitates ([`FRAME_SCALE`]); the search lets a larger one through
    /// where the static poses confirm it ([`CONFIRMED_FRAME_SCALE`]).
    fn unphysical(&self, effects: &Effects, max_change: f64) -> Option<String> {
        let f = effects.frame.as_ref()?;
        let (mm, deg) = (FRAME_SCALE * max_change, FRAME_SCALE * max_change / 3.0);
        (f.dx_mm.hypot(f.dy_mm) > mm || f.dphi_deg.abs() > deg).then(|| {
            format!(
                "a capture frame off by ({:.2}, {:.2}) mm and {:.2} deg",
                f.dx_mm, f.dy_mm, f.dphi_deg
            )
        })
    }
}
