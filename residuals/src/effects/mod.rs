//! The library of candidate effects a tendon-driven parallel continuum robot is known to have,
//! one module per effect behind one trait ([`Effect`]), registered in one list ([`ALL`]).
//!
//! An effect has a name from a fixed vocabulary, a physical parameterisation, a fit against the
//! residuals of the current model (linearised: the model's Jacobians at each row turn the
//! effect's change of motor position, curvature, load or frame into a change of the predicted
//! pose), its part of the extended model's prediction ([`Extension`]), the entry it writes into
//! the robot file when it is accepted (and reads back), the parameters the joint refinement
//! moves, and what makes its entry unphysical. The attribution, the scoring, the acceptance and
//! the report ask the registry and never name an effect.
//!
//! Every candidate is fitted together with the calibration parameters ([`crate::nuisance`]:
//! the paper's step-1 and step-2 set; [`joint_fit`]), so that an effect the calibration partly
//! absorbed is estimated whole, and so that no effect gets the credit for a plain
//! recalibration (which is the `geometry` candidate of its own).
//!
//! | name | effect | parameters |
//! |---|---|---|
//! | `backlash` | gear backlash / friction hysteresis: play on each motor | play b_i, steps |
//! | `latency` | command-to-motion latency | tau, s |
//! | `creep` | slow drift: tendon creep, first-order in time | gain_i, time constant T s |
//! | `drift` | steady drift: each tendon lengthens at a constant rate | rate_i mm/s |
//! | `joint_springs` | compliance under the coupling forces: springs in the passive joints bend the segments (kineto-static) | k_M, k_P N mm/rad |
//! | `external_load` | compliance under an external load: a constant wrench on the platform | F_x, F_y N, M N mm |
//! | `frame` | capture-frame misregistration | dx, dy mm, dphi deg |
//! | `tendon_map` | remaining tendon-map nonlinearity | a richer Table I function per leg |
//! | `geometry` | remaining geometric error (recalibration on every row) | the calibration parameters |
//! | `periodic` | periodic transmission error of one motor | period P steps, amplitude A steps, phase |
//! | `friction` | friction of the passive joints and their supports: stick-slip hysteresis of the pose through the segments' compliance | joint couple N mm, support force N |
//!
//! A new effect is one module here implementing [`Extension`] and [`Effect`], and its line in
//! [`ALL`] (and its compensation in the chain, `pcr-control`).

pub mod backlash;
pub mod compliance;
pub mod creep;
pub mod drift;
pub mod external_load;
pub mod frame;
pub mod friction;
pub mod geometry;
pub mod joint_fit;
pub mod joint_springs;
pub mod latency;
pub mod motor_change;
pub mod periodic;
pub mod profile;
pub mod tendon_map;

use crate::context::Context;
use crate::extension::{Chain, Extension};
use crate::fitted::{Estimate, Fitted};
use pcr_robot::effects::Effects;
use pcr_robot::RobotConfig;
use std::sync::LazyLock;

/// What accepting an effect says about the robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// A physical effect beyond the calibrated model: it explains part of the residual.
    Physical,
    /// A refit of some calibration parameters (written into the legs): it absorbs a residual,
    /// it does not explain it.
    Recalibration,
    /// The refit of every calibration parameter: a recalibration, and the reference every other
    /// candidate of a round is scored against (one effect of the registry).
    Reference,
}

/// A continuous parameter of an effect the robot file declares, as the joint refinement
/// ([`crate::refine`]) moves it: read and written in the solver's unit (chosen so that the
/// solver's steps are of the order of the others'), within bounds.
pub struct Parameter {
    /// Its value in `effects`; the second argument is [`Parameter::index`].
    pub get: fn(&Effects, usize) -> f64,
    /// Sets it in `effects`; the second argument is [`Parameter::index`].
    pub set: fn(&mut Effects, usize, f64),
    /// Which of the effect's values (a motor, a leg, a component, a periodic term).
    pub index: usize,
    /// Lower bound, in the solver's unit.
    pub lo: f64,
    /// Upper bound, in the solver's unit.
    pub hi: f64,
    /// Whether it acts in the stages before the kinematics (timing, transmission, play,
    /// tendons: [`crate::extension::Extension`] stages 1 to 4), so that the curvatures move
    /// with it. A load's or the capture frame's does not: a refinement's Jacobian takes the
    /// curvatures at the point for it instead of running those stages over every row again.
    pub moves_curvatures: bool,
    /// Whether it acts through the pass of the friction along every row of the series in order
    /// (its history), which a refinement linearises at its start rather than running at each of
    /// its evaluations ([`crate::refine`]): which of the friction's fitted values it is (the
    /// column of `pcr_kinematics::Robot::friction_step_tangent`) and how much of that value one
    /// unit of the solver's is.
    pub along_path: Option<(usize, f64)>,
}

/// Which independent parts of the training rows a candidate's parameters are compared on
/// ([`Effect::consistency`]; [`crate::consistency`] splits the rows).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Parts {
    /// Settled (static) rows against moving rows.
    StaticMoving,
    /// One recording against the others, or the first against the second half of the training
    /// time when there is one recording.
    Halves,
    /// Static against moving rows, and then, for each leg, the rows where it bends less than
    /// its median against those where it bends more: a load or a stiffness is the same over
    /// the whole workspace, while an imitation of a cause that depends on the configuration
    /// (a tendon pulling on another leg's) is not.
    Workspace,
    /// Leg i's bending below its median over the rows against above it.
    Bending(usize),
}

/// One candidate effect: its vocabulary, its fit, its entry in the robot file. Its part of the
/// prediction is the supertrait [`Extension`].
pub trait Effect: Extension {
    /// Vocabulary name (`--candidates`, the JSON, the report).
    fn name(&self) -> &'static str;

    /// One line: what it is.
    fn description(&self) -> &'static str;

    /// What accepting it says (physical by default).
    fn role(&self) -> Role {
        Role::Physical
    }

    /// Whether re-running its fit on a model that already holds it refines it (a Gauss-Newton
    /// step of its acceptance); true by default.
    fn iterable(&self) -> bool {
        true
    }

    /// The share of the training error a Gauss-Newton step of its acceptance must keep at most
    /// for the next step to be taken (the default: a step gaining less than 3 % is the last).
    fn acceptance_min_gain(&self) -> f64 {
        0.97
    }

    /// Whether it is tried again once it is in the model (each acceptance adds another term);
    /// false by default.
    fn repeatable(&self) -> bool {
        false
    }

    /// Fits it, with the calibration parameters, on the rows `train` (indices into `ctx.rows`)
    /// of the current model's residuals; `None` when it cannot be fitted.
    fn fit(&self, ctx: &Context, train: &[usize]) -> Option<Fitted>;

    /// [`Effect::fit`] in a round where another candidate's fit already left `beaten` of the
    /// training error (its training SSE): an effect whose fit is re-linearised, a pass over
    /// every row each time, stops re-linearising where it can no longer come below that
    /// ([`Effect::fitted_last`]). [`Effect::fit`] by default.
    fn fit_against(&self, ctx: &Context, train: &[usize], _beaten: f64) -> Option<Fitted> {
        self.fit(ctx, train)
    }

    /// Whether a round fits it after the other candidates, against the best of them
    /// ([`Effect::fit_against`]); false by default.
    fn fitted_last(&self) -> bool {
        false
    }

    /// A Gauss-Newton step of its acceptance from a model that holds it: fits it again on
    /// `train` ([`Effect::fit`] by default).
    fn step(&self, ctx: &Context, train: &[usize]) -> Option<Fitted> {
        self.fit(ctx, train)
    }

    /// Computes what its fits read of `ctx` that every fit on `ctx` shares, each computed once
    /// per context (the nuisance columns by default): called before several fits on one
    /// context run in parallel (a round's candidates, the two parts of a consistency check).
    /// A fit that finds it missing computes it itself and the other fits wait for it, each on
    /// a core that then takes no other work: on two cores a third of a loaded model's nuisance
    /// columns was solved with the other core idle.
    fn share(&self, ctx: &Context) {
        let _ = ctx.nuisance();
    }

    /// Fits it on `train` as the whole fit `whole` was made: its searched values (a motor, a
    /// period) kept, its continuous parameters fitted again. The consistency check compares
    /// parts of the data with it ([`crate::consistency`]). [`Effect::fit`] by default.
    fn fit_like(&self, ctx: &Context, train: &[usize], _whole: &[Estimate]) -> Option<Fitted> {
        self.fit(ctx, train)
    }

    /// Its parameters as the robot file declares them (without standard errors), as its fit
    /// `fitted` names them (`fitted` also tells which entry, for an effect that holds several);
    /// `None` when the file does not declare it or the fitted values stand (the default).
    fn declared(&self, _effects: &Effects, _fitted: &[Estimate]) -> Option<Vec<Estimate>> {
        None
    }

    /// Where its entry is in the robot file: the place of the fields it writes among those of
    /// `pcr_robot::effects::Effects` (latency 1, ..., periodic 8, friction 9; the compliance's
    /// load before its springs), 0 for the legs. The joint refinement takes the effects' parameters in this
    /// order, and the plausibility lists its reasons in the reverse order.
    fn file_position(&self) -> u8;

    /// Its continuous parameters the joint refinement moves, when the robot file declares it
    /// (none by default).
    fn parameters(&self, _effects: &Effects) -> Vec<Parameter> {
        Vec::new()
    }

    /// Whether its parameter `index` ([`Effect::parameters`]) means nothing where `effects`
    /// stand, so that a refinement holds it where it is and states no error for it (the
    /// joints' pre-sliding travel while the joints do not rub). None by default.
    fn holds(&self, _effects: &Effects, _index: usize) -> bool {
        false
    }

    /// Its part of the robot file `new` moved to a fraction `s` of the way from `old` (its
    /// continuous values interpolated with [`lerp`], absent from `old` counting as zero): the
    /// damping of a linearised step. Nothing by default.
    fn blend(&self, _old: &RobotConfig, _new: &mut RobotConfig, _s: f64) {}

    /// Takes its entry out of the robot file (`params`: the parameters it was added with, which
    /// name the term of an effect that holds several). Recalibrations cannot be taken out:
    /// nothing by default.
    fn remove(&self, _effects: &mut Effects, _params: &[Estimate]) {}

    /// Which independent parts of the training rows its consistency is checked on
    /// ([`crate::consistency`]): static against moving rows by default.
    fn consistency(&self) -> Parts {
        Parts::StaticMoving
    }

    /// Why the robot file's entry is not a physical explanation, if it is not; `max_change` is
    /// the largest change of the geometry a plausible explanation makes (mm or degrees).
    /// Nothing by default.
    fn unphysical(&self, _effects: &Effects, _max_change: f64) -> Option<String> {
        None
    }
}

/// Every effect, in the order the candidates are tried (the default of
/// [`crate::Options::candidates`]).
pub static ALL: [&dyn Effect; 11] = [
    &geometry::Geometry,
    &tendon_map::TendonMap,
    &frame::Frame,
    &latency::Latency,
    &backlash::Backlash,
    &creep::Creep,
    &drift::Drift,
    &joint_springs::JointSprings,
    &external_load::ExternalLoad,
    &periodic::Periodic,
    &friction::Friction,
];

/// The effect of a vocabulary name.
pub fn named(name: &str) -> Option<&'static dyn Effect> {
    ALL.iter().copied().find(|e| e.name() == name)
}

/// The vocabulary, in the order of [`ALL`].
pub fn names() -> Vec<&'static str> {
    ALL.iter().map(|e| e.name()).collect()
}

/// The reference of the scoring ([`Role::Reference`]).
pub fn reference() -> Option<&'static dyn Effect> {
    ALL.iter().copied().find(|e| e.role() == Role::Reference)
}

/// The effects in the order of their entries in the robot file ([`Effect::file_position`]).
pub fn in_file_order() -> Vec<&'static dyn Effect> {
    let mut v = ALL.to_vec();
    v.sort_by_key(|e| e.file_position());
    v
}

static CHAIN: LazyLock<Vec<&'static dyn Extension>> =
    LazyLock::new(|| ALL.iter().map(|&e| e as &'static dyn Extension).collect());

/// The effects' parts of the prediction, in the order of [`ALL`]: what an extended model runs
/// ([`crate::model::ExtendedModel::new`]).
pub fn chain() -> Chain {
    CHAIN.as_slice()
}

/// `a` moved a fraction `s` of the way to `b`: the interpolation of [`Effect::blend`].
pub fn lerp(a: f64, b: f64, s: f64) -> f64 {
    a + s * (b - a)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_registry_names_every_effect_once_with_one_reference() {
        let mut n = names();
        assert_eq!(n.first(), Some(&"geometry"), "the reference is tried first");
        n.sort_unstable();
        n.dedup();
        assert_eq!(n.len(), ALL.len());
        assert_eq!(
            ALL.iter().filter(|e| e.role() == Role::Reference).count(),
            1
        );
        assert_eq!(reference().map(|e| e.name()), Some("geometry"));
        assert!(named("backlash").is_some_and(|e| e.role() == Role::Physical));
        assert!(named("nonsense").is_none());
        assert_eq!(chain().len(), ALL.len());
    }
}
