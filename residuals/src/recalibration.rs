//! Joint estimation from the drawing. The analysis starts from a calibration made on static
//! poses with no effect in the model; an effect that was already in those poses (a tendon that
//! drifts while the calibration set is recorded, a play, a frame error) bent that calibration,
//! and a fit linearised around it cannot take the bend back. So once an effect is in the
//! model, the calibration is made again **from the robot file's drawing**, with the effects in
//! the model: each static pose's motor positions are the ones the model says the legs reached
//! (drift, creep, play and periodic errors taken off, `Prediction::dl_eff`) and its measurement
//! is corrected by the model's capture frame; the paper's two steps and their joint refinement
//! run on those, with the same function and split as the first calibration. The effects are
//! then refitted on the new calibration ([`crate::refine`]), and the two alternate while the
//! held-out error falls: the better held-out result, from the calibration the analysis began
//! with or from the drawing, is kept ([`crate::attribution`]).
//!
//! Loads (joint springs, an external wrench) bend the segments: with a compliance in the model,
//! each static measurement (platform pose and M_i) is corrected by the deflection the model
//! predicts there (its loaded equilibrium minus its rigid pose and joints at the same
//! curvatures), so that the static model is calibrated on what the unloaded robot would show.
//! Friction in the model likewise: each visit's measurement less what the friction left it
//! deflected at rest, as the model's path through the recording says (the pose and the
//! joints M_i). Without that, the calibration poses, visited in turn around each boundary,
//! carry a deflection that turns with the boundary, which the calibration takes as a turn of
//! the legs' bases (on the sweep's friction at 1x: +0.34 deg on every psi_i, held-out 0.025 mm
//! on noise-free data against 0.010 with the drawing).
//!
//! A capture frame in the model is fitted again with the calibration (the joint refinement with
//! `Options::frame`, on the measurements the model's frame already corrected, the two
//! corrections then composed): the static poses' M_i pin the registration far better than the
//! moving rows' platform poses, along whose valley with the geometry an alternation only crept.

use crate::context::Context;
use pcr_calibration::calibrate::{calibrate_data, Options as CalOptions};
use pcr_calibration::StaticData;
use pcr_robot::RobotConfig;

use crate::options::Recalibration;

/// The calibration made again from `drawing` on the static poses as the model of `ctx` (whose
/// configuration is `config`) says the robot reached and measured them, with `config`'s effects
/// kept; `None` when it cannot be made (a compliance in the model, a pose the model does not
/// predict, a calibration that fails).
pub fn recalibrated(
    config: &RobotConfig,
    ctx: &Context,
    drawing: &RobotConfig,
    recal: &Recalibration,
) -> Option<RobotConfig> {
    let data = static_data(config, ctx, recal)?;
    let opts = options(config, recal);
    // The measurements as the model's capture frame corrects them.
    let framed = config
        .effects
        .frame
        .as_ref()
        .map(|f| pcr_calibration::calibrate::framed(&data, f));
    // With a frame in the model, the frame fitted with the calibration too; kept where the
    // static poses confirm a frame error ([`frame_confirmed`]), else held at the model's.
    let cal = match framed
        .as_ref()
        .and_then(|framed| with_frame(&data, framed, drawing, &opts))
    {
        Some(c) => c,
        None => calibrate_data(drawing, framed.as_ref().unwrap_or(&data), &opts).ok()?,
    };
    // Its maps must stay invertible over every row's displacements, as the first
    // calibration's over its poses and the map candidate's over the rows: the static poses
    // alone may not reach where the paths go (on the prototype plant's small loop, a leg's
    // asymmetric sixth-root map refitted here turned back just below dl = 0, and the extended
    // circle, which bends that leg the other way, stopped its motor at -1 step for -68).
    if let Some(why) = crate::nuisance::map_refusal(&cal.robot, ctx.series) {
        tracing::debug!(why, "calibration from the drawing refused");
        return None;
    }
    let mut out = cal.robot;
    out.name = config.name.clone();
    out.effects = config.effects.clone();
    // The frame fitted with the robot, on the measurements already corrected by the model's:
    // the two corrections composed.
    if let (Some(f), Some(d)) = (out.effects.frame.as_mut(), &cal.frame) {
        *f = f.then(d);
    }
    Some(out)
}

/// The calibration's settings for the model `config`: the first calibration's, with the map
/// function the model holds (fitted alone: nothing here reads the rest of Table I), the frame
/// held.
fn options(config: &RobotConfig, recal: &Recalibration) -> CalOptions {
    CalOptions {
        function: Some(config.legs[0].tendon_map.model),
        every_function: false,
        diagnose: false,
        frame: false,
        ..recal.options.clone()
    }
}

/// The calibration with a capture frame fitted from the measurements `framed` (the static poses
/// `data` as the model's frame corrects them), where the static poses confirm a frame error
/// ([`frame_confirmed`], against the calibration of `data` with no frame correction).
fn with_frame(
    data: &StaticData,
    framed: &StaticData,
    drawing: &RobotConfig,
    opts: &CalOptions,
) -> Option<pcr_calibration::calibrate::Calibration> {
    let free = CalOptions {
        frame: true,
        ..opts.clone()
    };
    // The two calibrations are independent: one per thread.
    let (free, none) = rayon::join(
        || calibrate_data(drawing, framed, &free),
        || calibrate_data(drawing, data, opts),
    );
    let (free, none) = (free.ok()?, none.ok()?);
    frame_confirmed(&free, &none, drawing).then_some(free)
}

/// The static poses as the model of `ctx` (configuration `config`) says the robot reached them:
/// each visit's motor positions those its legs reached (`q_eff`), and under loads its
/// measurements less the deflection the loads cause there (the capture frame not yet applied).
fn static_data(config: &RobotConfig, ctx: &Context, recal: &Recalibration) -> Option<StaticData> {
    let series = ctx.series.get(recal.series)?;
    let preds = ctx.preds.get(recal.series)?;
    let mut data = recal.data.clone();
    // The friction's deflection of every row of the series (the pose and the joints M_i): at
    // rest each visit holds what its approach left stuck. The pass is made with the
    // derivatives, which the refinement of the effects on this calibration linearises its
    // friction with (`refine::search_with_errors`): 1.4 passes instead of two.
    let rubbing = ctx.model.friction.as_ref().map(|f| {
        let paths = ctx.paths();
        let (rigid, kappa) = &paths[recal.series];
        ctx.model.friction_path_with_joints(rigid, kappa, f, true)
    });
    for p in &mut data.poses {
        let s = &p.settled;
        // The visit's settled rows with the command it held.
        let rows: Vec<usize> = (s.first_row..series.samples.len())
            .take_while(|&k| series.samples[k].settled)
            .filter(|&k| series.samples[k].q == s.q.map(f64::from))
            .collect();
        if rows.is_empty() {
            return None;
        }
        let mut q = [0.0; 3];
        for (i, qi) in q.iter_mut().enumerate() {
            let mmps = config.legs[i].actuation.mm_per_step();
            *qi = rows
                .iter()
                .map(|&k| preds.get(k).map_or(f64::NAN, |x| x.dl_eff[i]))
                .sum::<f64>()
                / rows.len() as f64
                / mmps;
        }
        if !q.iter().all(|v| v.is_finite()) {
            return None;
        }
        p.q_eff = Some(q);
        if let Some(rubbing) = &rubbing {
            let (d, dm) = (*rubbing.get(rows[0])?)?;
            let s = &mut p.settled;
            if let Some(pose) = &mut s.pose {
                pose[0] -= d[0];
                pose[1] -= d[1];
                pose[2] -= d[2].to_degrees();
            }
            for (m, dm) in s.m.iter_mut().zip(dm) {
                if let Some(m) = m {
                    m[0] -= dm[0];
                    m[1] -= dm[1];
                }
            }
        }
        if let Some(loads) = &ctx.model.loads {
            let d = deflection(ctx, loads, q, p.settled.pose?)?;
            let s = &mut p.settled;
            if let Some(pose) = &mut s.pose {
                for k in 0..3 {
                    pose[k] -= d.0[k];
                }
            }
            for (m, dm) in s.m.iter_mut().zip(d.1) {
                if let Some(m) = m {
                    m[0] -= dm[0];
                    m[1] -= dm[1];
                }
            }
        }
    }
    Some(data)
}

/// Whether the static poses confirm the capture frame `config` declares
/// ([`frame_confirmed`]): the calibration with the frame fitted from it against the calibration
/// with no frame correction. `false` without a frame, or when a calibration fails.
pub(crate) fn confirms_frame(
    config: &RobotConfig,
    ctx: &Context,
    drawing: &RobotConfig,
    recal: &Recalibration,
) -> bool {
    let (Some(f), Some(data)) = (
        config.effects.frame.as_ref(),
        static_data(config, ctx, recal),
    ) else {
        return false;
    };
    let framed = pcr_calibration::calibrate::framed(&data, f);
    with_frame(&data, &framed, drawing, &options(config, recal)).is_some()
}

/// Whether the static poses confirm a capture-frame error: the calibration with the frame
/// fitted (`free`) predicts their held-out poses with at least [`crate::scoring::MIN_SHARE`] of
/// the mean square of the calibration with no frame correction (`none`) taken off, the share a
/// candidate must explain to be claimed. A frame the static poses do not show only takes up what
/// something else bends: on a tendon cross-coupling of 3 % (outside the vocabulary) the frame
/// fitted there was -0.95 deg and left the static held-out M_i at 0.887 mm against 0.879 mm
/// without; a frame off by (2.4 mm, 0, 0.9 deg) takes them from 0.112 to 0.014 mm.
fn frame_confirmed(
    free: &pcr_calibration::calibrate::Calibration,
    none: &pcr_calibration::calibrate::Calibration,
    drawing: &RobotConfig,
) -> bool {
    let w = pcr_calibration::step2::default_phi_weight(drawing);
    static_held_out(free, w) < (1.0 - crate::scoring::MIN_SHARE) * static_held_out(none, w)
}

/// The mean square of a calibration's errors on the static poses it held out (its training
/// poses' without a test set): M_i, the platform position, and the orientation weighted as `w`
/// mm per degree (mm^2).
fn static_held_out(cal: &pcr_calibration::calibrate::Calibration, w: f64) -> f64 {
    let a = cal.after.test.as_ref().unwrap_or(&cal.after.train);
    a.m_rms_mm.powi(2) + a.pose.position_rms_mm.powi(2) + (w * a.pose.orientation_rms_deg).powi(2)
}

/// The deflection the loads of the model cause at motor positions `q` (steps) near the measured
/// pose `near` (x mm, y mm, phi deg): the loaded equilibrium minus the rigid pose (x mm, y mm,
/// phi deg) and M_i (mm) at the same curvatures.
fn deflection(
    ctx: &Context,
    loads: &pcr_kinematics::statics::Loads,
    q: [f64; 3],
    near: [f64; 3],
) -> Option<([f64; 3], [[f64; 2]; 3])> {
    let robot = &ctx.model.robot;
    let kappa: [f64; 3] = std::array::from_fn(|i| robot.steps_to_kappa(i, q[i]));
    let guess = pcr_kinematics::Pose::from_mm_deg(near[0], near[1], near[2]);
    let rigid = robot.fk_warm(&kappa, &guess).ok()?;
    let loaded = robot.fk_loaded(&kappa, loads, &rigid).ok()?;
    let m_rigid: [[f64; 2]; 3] = std::array::from_fn(|i| robot.legs[i].joint_m(kappa[i]));
    Some((
        [
            loaded.pose.x - rigid.x,
            loaded.pose.y - rigid.y,
            (loaded.pose.phi - rigid.phi).to_degrees(),
        ],
        std::array::from_fn(|i| {
            [
                loaded.m[i][0] - m_rigid[i][0],
                loaded.m[i][1] - m_rigid[i][1],
            ]
        }),
    ))
}
