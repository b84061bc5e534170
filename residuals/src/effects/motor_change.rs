//! The change of the predicted pose when the motors' outputs change, linearised through each
//! row's Jacobian: what the motor-side candidates (latency, backlash) predict.

use crate::context::Context;
use crate::linear::motor_delta;
use pcr_robot::effects::Effects;

/// The change of the predicted pose of the rows `rows` (every measured row when `None`) when
/// their motors' outputs become `q_new` (per series and row).
pub(crate) fn motor_change(
    ctx: &Context,
    q_new: &[Vec<[f64; 3]>],
    rows: Option<&[usize]>,
) -> Vec<[f64; 3]> {
    let one = |i: usize| {
        let row = &ctx.rows[i];
        let q = ctx.pred(row).q_eff;
        let o = q_new[row.s][row.k];
        motor_delta(ctx, i, [o[0] - q[0], o[1] - q[1], o[2] - q[2]])
    };
    match rows {
        Some(r) => r.iter().map(|&i| one(i)).collect(),
        None => (0..ctx.rows.len()).map(one).collect(),
    }
}

/// The change of the predicted pose of the rows `rows` (every measured row when `None`) when the
/// motor side of the model (the stages timing, transmission and play of
/// [`crate::extension::Extension`]) runs with `effects` instead of the model's.
pub(crate) fn motor_side_delta(
    ctx: &Context,
    effects: &Effects,
    rows: Option<&[usize]>,
) -> Vec<[f64; 3]> {
    let q_new: Vec<Vec<[f64; 3]>> = ctx
        .series
        .iter()
        .map(|s| ctx.model.effective_steps(s, effects))
        .collect();
    motor_change(ctx, &q_new, rows)
}
