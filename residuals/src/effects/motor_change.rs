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
        towards(ctx, i, q_new[row.s][row.k])
    };
    match rows {
        Some(r) => r.iter().map(|&i| one(i)).collect(),
        None => (0..ctx.rows.len()).map(one).collect(),
    }
}

/// The change of the predicted pose of the rows `rows` (every measured row when `None`) when the
/// motor side of the model (the stages timing, transmission and play of
/// [`crate::extension::Extension`]) runs with `effects` instead of the model's. With `rows`,
/// only their series, and without a play only their rows
/// ([`crate::model::ExtendedModel::effective_steps_at`]).
pub(crate) fn motor_side_delta(
    ctx: &Context,
    effects: &Effects,
    rows: Option<&[usize]>,
) -> Vec<[f64; 3]> {
    let Some(rows) = rows else {
        let q_new: Vec<Vec<[f64; 3]>> = ctx
            .series
            .iter()
            .map(|s| ctx.model.effective_steps(s, effects))
            .collect();
        return motor_change(ctx, &q_new, None);
    };
    // Per series, the rows' indices in it (ascending) and their motor outputs.
    let mut ks: Vec<Vec<usize>> = vec![Vec::new(); ctx.series.len()];
    for &i in rows {
        ks[ctx.rows[i].s].push(ctx.rows[i].k);
    }
    let q: Vec<Vec<[f64; 3]>> = ctx
        .series
        .iter()
        .zip(&mut ks)
        .map(|(s, k)| {
            k.sort_unstable();
            k.dedup();
            if k.is_empty() {
                Vec::new()
            } else {
                ctx.model.effective_steps_at(s, effects, k)
            }
        })
        .collect();
    rows.iter()
        .map(|&i| {
            let row = &ctx.rows[i];
            let at = ks[row.s].binary_search(&row.k).unwrap_or(0);
            towards(ctx, i, q[row.s][at])
        })
        .collect()
}

/// The change of row `i`'s predicted pose when its motor outputs become `o` (steps).
pub(crate) fn towards(ctx: &Context, i: usize, o: [f64; 3]) -> [f64; 3] {
    let now = ctx.pred(&ctx.rows[i]).q_eff;
    motor_delta(ctx, i, [o[0] - now[0], o[1] - now[1], o[2] - now[2]])
}
