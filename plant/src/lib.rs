//! Simulated 3-FbRR plant: a kineto-static truth model (Kirchhoff elastica legs) with
//! switchable error effects, following `shared/spec/plant.md`.
//!
//! - [`segment`]: one elastica segment, RK4 shooting with sensitivities.
//! - [`statics`]: the equilibrium of the whole robot (Newton on 12 unknowns), continuation from
//!   home, typed errors.
//! - [`model`]: the true robot (nominal geometry + deviations, true tendon map, home steps).
//! - [`truth`]: the static truth model (stateless solves).
//! - [`config`]: the plant configuration file with every effect as a switch.
//!
//! Units: mm, rad (degrees only in files), N, N mm, s, motor steps.

pub mod config;
pub mod model;
pub mod segment;
pub mod statics;
pub mod truth;

pub use config::{PlantConfig, PlantConfigError};
pub use model::TrueRobot;
pub use statics::{Equilibrium, Joint, Loads, Statics, StaticsError};
pub use truth::TruthModel;
