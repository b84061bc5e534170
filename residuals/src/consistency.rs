//! Consistency before naming. A physical effect takes the same parameters in independent parts
//! of the data, within their uncertainty: a play of 4 steps is 4 steps in the first half of a
//! recording and in the second, a load of 0.4 N pulls as hard on the static poses as on the
//! moving rows. A candidate that explains a residual only by taking different values in
//! different parts imitates a cause outside the library (a tendon cross-coupling looks like a
//! load on some poses and like something else on others); it is reported as "acts partly like
//! X, but its parameters disagree between ...", and is neither named nor compensated.
//!
//! The parts ([`Parts`]) are the static rows against the moving rows for the effects visible in
//! both, and for the effects only motion shows (latency, backlash, creep) one recording against
//! the others, or the first against the second half of the training time when there is one
//! recording; a load and the joint springs also over the workspace ([`Parts::Workspace`]: for
//! each leg, the poses where it bends less than its median against those where it bends more,
//! the first disagreement refusing them). The candidate is fitted on each part as on the whole (with the calibration
//! parameters), and a parameter disagrees when it is clearly non-zero in the whole fit and the
//! two parts' values differ by more than [`Z`] combined standard errors *and* by more than
//! [`REL`] of the larger of the two and the whole's value (the standard errors of a linear fit over thousands of
//! correlated rows are optimistic; a physical effect's values differ between parts by far less
//! than a third, an imitation's by far more).

use crate::context::Context;
use crate::effects::{Effect, Parts};
use crate::fitted::{significant, Estimate};
use rayon::prelude::*;

/// Fewest training rows a part needs for the check (fewer: not checked).
pub const MIN_ROWS: usize = 400;
/// Combined standard errors two parts' values must differ by to disagree.
pub const Z: f64 = 3.5;
/// Share of the larger value two parts' values must differ by to disagree.
pub const REL: f64 = 0.35;

/// The two parts of the training rows `train` (indices into `ctx.rows`) and their names;
/// `None` when a part has fewer than [`MIN_ROWS`] rows.
pub fn split(
    parts: Parts,
    ctx: &Context,
    train: &[usize],
) -> Option<([Vec<usize>; 2], [&'static str; 2])> {
    let sample = |i: usize| &ctx.series[ctx.rows[i].s].samples[ctx.rows[i].k];
    let (a, b, names): (Vec<usize>, Vec<usize>, [&'static str; 2]) = match parts {
        Parts::Bending(leg) => {
            let bending = |i: usize| ctx.pred(&ctx.rows[i]).kappa[leg.min(2)];
            let mut v: Vec<f64> = train.iter().map(|&i| bending(i)).collect();
            v.sort_by(f64::total_cmp);
            let median = *v.get(v.len() / 2)?;
            let (a, b) = train.iter().partition(|&&i| bending(i) < median);
            const NAMES: [[&str; 2]; 3] = [
                [
                    "the poses where leg 1 bends less",
                    "those where it bends more",
                ],
                [
                    "the poses where leg 2 bends less",
                    "those where it bends more",
                ],
                [
                    "the poses where leg 3 bends less",
                    "those where it bends more",
                ],
            ];
            (a, b, NAMES[leg.min(2)])
        }
        Parts::StaticMoving | Parts::Workspace => {
            let (a, b) = train.iter().partition(|&&i| sample(i).settled);
            (a, b, ["static rows", "moving rows"])
        }
        Parts::Halves => {
            let first = train.first().map(|&i| ctx.rows[i].s)?;
            let others = train.iter().filter(|&&i| ctx.rows[i].s != first).count();
            if others >= MIN_ROWS {
                let (a, b) = train.iter().partition(|&&i| ctx.rows[i].s == first);
                (a, b, ["the first recording", "the others"])
            } else {
                let mut by_time: Vec<usize> = train.to_vec();
                by_time.sort_by(|&x, &y| {
                    (ctx.rows[x].s, sample(x).t_s)
                        .partial_cmp(&(ctx.rows[y].s, sample(y).t_s))
                        .unwrap_or(std::cmp::Ordering::Equal)
                });
                let b = by_time.split_off(by_time.len() / 2);
                (
                    by_time,
                    b,
                    ["the first half of the recording", "the second half"],
                )
            }
        }
    };
    (a.len() >= MIN_ROWS && b.len() >= MIN_ROWS).then_some(([a, b], names))
}

/// Why `effect`, fitted on the whole training set with the parameters `whole`, is not a
/// consistent explanation, if it is not: it is fitted on the two parts of [`split`] and its
/// parameters compared. `None` when they agree, or when the data cannot tell (a part too small,
/// a fit that fails).
pub fn inconsistency(
    effect: &dyn Effect,
    ctx: &Context,
    train: &[usize],
    whole: &[Estimate],
) -> Option<String> {
    let checks: Vec<Parts> = match effect.consistency() {
        Parts::Workspace => vec![
            Parts::StaticMoving,
            Parts::Bending(0),
            Parts::Bending(1),
            Parts::Bending(2),
        ],
        p => vec![p],
    };
    // The checks, and the two parts of each, are fitted independently: one per thread, the
    // first disagreement in the checks' order reported; what every fit reads of the context is
    // computed first.
    effect.share(ctx);
    checks.into_par_iter().find_map_first(|p| {
        let (parts, names) = split(p, ctx, train)?;
        let (fa, fb) = rayon::join(
            || effect.fit_like(ctx, &parts[0], whole),
            || effect.fit_like(ctx, &parts[1], whole),
        );
        let (fa, fb) = (fa?, fb?);
        let disagree = disagreements(whole, &fa.params, &fb.params);
        (!disagree.is_empty()).then(|| {
            format!(
                "acts partly like {}, but its parameters disagree between {} and {} ({})",
                effect.name(),
                names[0],
                names[1],
                disagree.join("; ")
            )
        })
    })
}

/// The parameters whose values in the two parts disagree, as text (`name a +- sa against
/// b +- sb unit`). A fitted parameter is judged when the whole fit makes it clearly non-zero
/// (three standard errors) and at least a tenth of the largest of the effect's parameters of
/// the same unit (a leg whose drift is a thousandth of another's is not the effect).
pub fn disagreements(whole: &[Estimate], a: &[Estimate], b: &[Estimate]) -> Vec<String> {
    let mut out = Vec::new();
    let largest = |unit: &str| {
        whole
            .iter()
            .filter(|p| p.unit == unit)
            .fold(0.0f64, |m, p| m.max(p.value.abs()))
    };
    for w in whole {
        let (Some(pa), Some(pb)) = (
            a.iter().find(|p| p.name == w.name),
            b.iter().find(|p| p.name == w.name),
        ) else {
            continue;
        };
        // A phase is an angle: the difference the short way round.
        let diff = if w.name == "phase" {
            ((pa.value - pb.value + 180.0).rem_euclid(360.0) - 180.0).abs()
        } else {
            (pa.value - pb.value).abs()
        };
        // The parts are fitted around the model that holds the effect: some effects report the
        // value they hold plus what a part adds (a load), others only what a part adds (a creep
        // gain, a drift rate). The share is of the largest of the three, the held value among
        // them: two small additions 0.002 apart on a gain of 0.019 agree.
        let larger = pa.value.abs().max(pb.value.abs()).max(w.value.abs());
        let differs = match (w.std, pa.std, pb.std) {
            // A fitted value: clearly non-zero in the whole fit, apart by Z combined errors and
            // by REL of the larger.
            (Some(sw), Some(sa), Some(sb)) => {
                w.value.abs() > 3.0 * sw
                    && w.value.abs() >= 0.1 * largest(&w.unit)
                    && diff > Z * sa.hypot(sb)
                    && diff > REL * larger
            }
            // Fitted in the parts, held in the whole fit (a limit its bound held at zero,
            // which the acceptance's refinement then moved): apart by Z combined errors and
            // by REL of the larger.
            (None, Some(sa), Some(sb)) => diff > Z * sa.hypot(sb) && diff > REL * larger,
            // Held at its bound in one part and fitted in the other (a friction's joints at
            // zero in one half, 0.08 +- 0.05 N mm in the other, on supports' friction alone;
            // 0.12 +- 0.034 with the supports at 10x): the held value as uncertain as the
            // fitted one (its estimate was cut at the bound), apart by Z combined errors and by
            // REL of the larger.
            (None, Some(s), None) | (None, None, Some(s)) => {
                diff > Z * std::f64::consts::SQRT_2 * s && diff > REL * larger
            }
            // A searched or fixed one (a motor, a period): the same value.
            (None, _, _) => diff > 0.02 * larger.max(1e-12),
            _ => false,
        };
        if differs {
            let pm = |p: &Estimate| match p.std {
                Some(s) => format!("{} +- {}", significant(p.value), significant(s)),
                None => significant(p.value),
            };
            out.push(format!(
                "{} {} against {} {}",
                w.name,
                pm(pa),
                pm(pb),
                w.unit
            ));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn e(name: &str, value: f64, std: Option<f64>) -> Estimate {
        Estimate::new(name, value, std, "N")
    }

    #[test]
    fn a_physical_effect_agrees_and_an_imitation_does_not() {
        let whole = [
            e("force x", 0.40, Some(0.01)),
            e("force y", 0.01, Some(0.02)),
        ];
        // Within the errors, or apart by many errors but by less than a third: agrees.
        let a = [
            e("force x", 0.41, Some(0.002)),
            e("force y", 0.05, Some(0.01)),
        ];
        let b = [
            e("force x", 0.37, Some(0.002)),
            e("force y", -0.05, Some(0.01)),
        ];
        assert!(disagreements(&whole, &a, &b).is_empty());
        // Apart by a factor of two and many errors: disagrees (force y is noise in the whole
        // fit and is not judged).
        let b = [
            e("force x", 0.18, Some(0.01)),
            e("force y", 0.9, Some(0.01)),
        ];
        let d = disagreements(&whole, &a, &b);
        assert_eq!(d.len(), 1, "{d:?}");
        assert!(d[0].starts_with("force x 0.4100 +- 0.002000"), "{d:?}");
        // A searched value must be the same.
        let whole = [e("period", 64.0, None)];
        assert!(disagreements(
            &whole,
            &[e("period", 64.0, None)],
            &[e("period", 64.0, None)]
        )
        .is_empty());
        assert_eq!(
            disagreements(
                &whole,
                &[e("period", 64.0, None)],
                &[e("period", 97.0, None)]
            )
            .len(),
            1
        );
    }

    /// A limit held at its bound (zero, no error) in one part and fitted in the other is judged
    /// with the held value as uncertain as the fitted one: 0.08 +- 0.05 and 0.12 +- 0.034 agree
    /// with zero, 0.8 +- 0.05 does not. (It was judged as a searched value, which must be the
    /// same to 2 %: a friction in the supports alone was refused for joints of 0 against
    /// 0.081 +- 0.049 N mm, and at 10x for 0.12 +- 0.034 against 0.)
    #[test]
    fn a_limit_held_at_zero_in_one_part_is_judged_on_the_other_s_error() {
        let whole = [e("joint torque", 0.0, None)];
        let held = [e("joint torque", 0.0, None)];
        let near = [e("joint torque", 0.08, Some(0.05))];
        let closer = [e("joint torque", 0.1227, Some(0.034))];
        assert!(disagreements(&whole, &held, &closer).is_empty());
        let far = [e("joint torque", 0.8, Some(0.05))];
        assert!(disagreements(&whole, &held, &near).is_empty());
        assert!(disagreements(&whole, &near, &held).is_empty());
        assert_eq!(disagreements(&whole, &held, &far).len(), 1);
        assert_eq!(disagreements(&whole, &far, &held).len(), 1);
    }
}
