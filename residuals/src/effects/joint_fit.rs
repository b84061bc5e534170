//! The joint fit of a candidate with the calibration parameters ([`crate::nuisance`]): the
//! effect's columns first, then the nuisance's, with the nuisance's prior; and the change of
//! the robot file its nuisance part makes.

use crate::context::Context;
use crate::linear::{self, Columns};
use crate::nuisance::Nuisance;
use pcr_robot::RobotConfig;

/// A joint fit: the solution, every row's change, and the effect's change alone.
pub(crate) type JointFit = (linear::LinearFit, Vec<[f64; 3]>, Option<Vec<[f64; 3]>>);

/// Fits with the nuisance: effect columns first, then the calibration parameters. `offset` is a
/// fixed change of the residual (an effect with no free linear parameter at the chosen value).
pub(crate) fn fit_joint(
    ctx: &Context,
    nui: &Nuisance,
    train: &[usize],
    n_e: usize,
    effect: &(dyn Fn(usize, &mut Columns) + Sync),
    offset: Option<&[[f64; 3]]>,
) -> Option<JointFit> {
    fit_joint_beside(ctx, nui, train, n_e, 0, effect, offset)
}

/// [`fit_joint`] whose last `beside` of the `n_e` effect columns are fitted beside the effect
/// and left out of its change (every row's, and the effect's alone) and of the training error
/// reported (the error with that change): what another effect would take, so that the effect
/// is fitted beyond it (a play's columns beside a friction's first step).
pub(crate) fn fit_joint_beside(
    ctx: &Context,
    nui: &Nuisance,
    train: &[usize],
    n_e: usize,
    beside: usize,
    effect: &(dyn Fn(usize, &mut Columns) + Sync),
    offset: Option<&[[f64; 3]]>,
) -> Option<JointFit> {
    // The solution with the columns beside taken out of it.
    let kept = |x: &[f64]| -> Vec<f64> {
        let mut x = x.to_vec();
        x[n_e - beside..n_e].fill(0.0);
        x
    };
    let n_g = nui.n;
    let n = n_e + n_g;
    let mut prior = vec![0.0; n_e];
    prior.extend(nui.prior().into_iter().take(n_g));
    if n == 0 {
        // Nothing free: the offset alone (a profiled effect without the nuisance).
        let o = offset?;
        let sse = ctx.sse(train, Some(o));
        return Some((
            linear::LinearFit {
                x: Vec::new(),
                std: Vec::new(),
                sse,
            },
            o.to_vec(),
            Some(o.to_vec()),
        ));
    }
    let alone = match offset {
        Some(o) => Some(o.to_vec()),
        None if n_e > 0 => linear::solve(ctx, train, n_e, effect)
            .map(|f| linear::deltas(ctx, n_e, &kept(&f.x), effect, None)),
        None => None,
    };
    let table = (n_g > 0).then(|| ctx.nuisance());
    // The residual with the offset taken out. Without the nuisance (n_g = 0) the effect's
    // columns are all of them.
    let fit = match &table {
        Some(t) => linear::solve_joint(ctx, train, n_e, effect, t, Some(&prior), offset),
        None => linear::solve_with_prior(ctx, train, n, effect, Some(&prior), offset),
    }?;
    let mut fit = fit;
    let mut delta = linear::deltas(ctx, n_e, &kept(&fit.x), effect, table.as_deref());
    if let Some(o) = offset {
        for (d, oo) in delta.iter_mut().zip(o) {
            for k in 0..3 {
                d[k] += oo[k];
            }
        }
    }
    if beside > 0 {
        fit.sse = ctx.sse(train, Some(&delta));
    }
    Some((fit, delta, alone))
}

/// Applies the nuisance part (after `n_e` effect parameters) of a joint fit to a config.
pub(crate) fn nuisance_change(nui: Nuisance, x: Vec<f64>, n_e: usize) -> impl Fn(&mut RobotConfig) {
    move |c: &mut RobotConfig| {
        if x.len() > n_e {
            nui.apply(&x[n_e..], c)
        }
    }
}
