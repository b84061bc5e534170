//! What an effect adds to the prediction of the extended model ([`crate::model`]): its part of
//! the chain that turns a recording's commands into predicted poses, stage by stage in the
//! order the physics runs. The model runs every stage for the effects it is given
//! ([`crate::effects::chain`]), in the registry's order within a stage; a stage an effect does
//! not act in, or an effect the robot file does not declare, changes nothing.
//!
//! This is the part of [`crate::effects::Effect`] the model needs; it is a trait of its own so
//! that the model knows the effects' predictions and not their fits (which need the model).

use crate::series::Series;
use pcr_kinematics::friction::Friction;
use pcr_kinematics::statics::Loads;
use pcr_robot::effects::Effects;
use std::fmt::Debug;

/// An effect's part of the extended model. `effects` is the robot file's `[effects]`, whose
/// entry for this effect (if any) holds its parameters.
pub trait Extension: Debug + Sync {
    /// Stage 1, timing: how much later than the recording's command delay the motors are where
    /// the command was, s.
    fn delay_s(&self, _effects: &Effects) -> f64 {
        0.0
    }

    /// Stage 2, transmission: the motor outputs (steps, one entry per row of the series) as
    /// functions of the motor positions, changed in place.
    fn transmission(&self, _effects: &Effects, _q: &mut [[f64; 3]]) {}

    /// Stage 3, play: the motor outputs (steps, one entry per row) through a play that depends
    /// on the path the motors took, changed in place.
    fn play(&self, _effects: &Effects, _q: &mut [[f64; 3]]) {}

    /// Whether [`Extension::play`] changes anything under `effects` (an effect that overrides
    /// it says so): without a play, a row's motor outputs depend on the commands about it
    /// alone, and some rows' can be computed without the whole series'
    /// ([`crate::model::ExtendedModel::effective_steps_at`]).
    fn plays(&self, _effects: &Effects) -> bool {
        false
    }

    /// Stage 4, tendons: the tendon displacements the segments see (mm, one entry per row of
    /// `series`), changed in place.
    fn tendons(&self, _effects: &Effects, _series: &Series, _dl: &mut [[f64; 3]]) {}

    /// Stage 5, loads: the loads of the kineto-static model, if the effect loads the robot
    /// (the model takes the first effect's; without any, the rigid constant-curvature model).
    fn loads(&self, _effects: &Effects) -> Option<Loads> {
        None
    }

    /// Stage 5b, friction: the friction of the joints and their supports, if the effect rubs
    /// (the model takes the first effect's): its deflection of the pose along the path of the
    /// whole series ([`pcr_kinematics::friction`]).
    fn friction(&self, _effects: &Effects) -> Option<Friction> {
        None
    }

    /// Stage 6, measurement: a measured pose (x mm, y mm, phi rad) corrected before it is
    /// compared with the prediction.
    fn corrected(&self, _effects: &Effects, m: [f64; 3]) -> [f64; 3] {
        m
    }
}

/// The extensions a model runs, in the registry's order ([`crate::effects::chain`]).
pub type Chain = &'static [&'static dyn Extension];
