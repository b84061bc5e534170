//! Simulated 3-FbRR plant: a kineto-static truth model (Kirchhoff elastica legs) with
//! switchable error effects, following `shared/spec/plant.md`.
//!
//! - [`segment`]: one elastica segment, RK4 shooting with sensitivities.
//! - [`statics`]: the equilibrium of the whole robot (Newton on 12 unknowns), continuation from
//!   home, typed errors.
//! - [`model`]: the true robot (nominal geometry + deviations, true tendon map, home steps).
//! - [`truth`]: the static truth model (stateless solves).
//! - [`sim`]: the time-stepped plant (implements `pcr_driver::Driver`), with [`actuator`]
//!   (stepper, gear) and [`capture`] (motion capture).
//! - [`config`]: the plant configuration file with every effect as a switch.
//!
//! Units: mm, rad (degrees only in files), N, N mm, s, motor steps.

pub mod actuator;
pub mod capture;
pub mod config;
pub mod model;
pub mod segment;
pub mod sim;
pub mod statics;
pub mod truth;

pub use capture::{Frame, Measurement};
pub use config::{PlantConfig, PlantConfigError};
pub use model::TrueRobot;
pub use sim::{Plant, PlantError, TrueState};
pub use statics::{Equilibrium, Joint, Loads, Statics, StaticsError};
pub use truth::TruthModel;
