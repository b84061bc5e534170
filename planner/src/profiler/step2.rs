//! Step 2: the common duration of several DoFs and their profiles of that duration.
//!
//! The synchronised duration is the smallest `T >= max(minimum duration, max_i Tmin_i)` that is
//! feasible for every DoF (i.e. lies in none of their blocked intervals). The candidates are the
//! lower bound itself and the boundaries of every DoF's feasible set above it (the ends of the
//! blocked intervals are among them); each is tested directly with fixed-duration solves.

use super::step1::{Step1, MAX_CANDIDATES};

/// The smallest duration (s) feasible for every DoF in `steps`, at least `t_lower`.
pub fn synchronized_duration(steps: &[Step1], t_lower: f64) -> Option<f64> {
    let mut cands = [f64::INFINITY; 1 + MAX_CANDIDATES * super::MAX_DOFS];
    cands[0] = t_lower;
    let mut n = 1;
    for s in steps {
        for a in s.boundaries() {
            if a > t_lower && n < cands.len() {
                cands[n] = a;
                n += 1;
            }
        }
    }
    let cands = &mut cands[..n];
    cands.sort_by(f64::total_cmp);
    cands
        .iter()
        .copied()
        .find(|&t| steps.iter().all(|s| s.is_feasible(t)))
}
