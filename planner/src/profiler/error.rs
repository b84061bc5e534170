//! Errors of the profiler.

/// Why a profiling request was rejected or could not be solved.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProfileError {
    /// A number in the request is NaN or infinite.
    #[error("{what} of DoF {dof} is not a finite number ({value})")]
    NotFinite {
        /// Which quantity.
        what: &'static str,
        /// Degree of freedom index.
        dof: usize,
        /// The offending value.
        value: f64,
    },
    /// A limit has the wrong sign (vmax, amax, jmax must be > 0; vmin, amin < 0).
    #[error("limit {what} of DoF {dof} must be {must} (got {value})")]
    BadLimit {
        /// Which limit.
        what: &'static str,
        /// Degree of freedom index.
        dof: usize,
        /// Human-readable requirement.
        must: &'static str,
        /// The offending value.
        value: f64,
    },
    /// The target state lies outside the limits (it cannot be held or reached).
    #[error("target {what} {value} of DoF {dof} is outside its limits [{min}, {max}]")]
    TargetOutsideLimits {
        /// Which quantity.
        what: &'static str,
        /// Degree of freedom index.
        dof: usize,
        /// Target value.
        value: f64,
        /// Lower limit.
        min: f64,
        /// Upper limit.
        max: f64,
    },
    /// The target state can only be reached through a velocity outside the limits: with a
    /// negative target acceleration the velocity just before was at least
    /// `v + a^2 / (2 jmax)`, with a positive one at most `v - a^2 / (2 jmax)`.
    #[error(
        "target state of DoF {dof} (v = {v}, a = {a}) can only be reached through velocity \
         {reached}, outside its limits [{min}, {max}]"
    )]
    TargetUnreachable {
        /// Degree of freedom index.
        dof: usize,
        /// Target velocity.
        v: f64,
        /// Target acceleration.
        a: f64,
        /// Velocity inevitably passed just before reaching the target.
        reached: f64,
        /// Lower velocity limit.
        min: f64,
        /// Upper velocity limit.
        max: f64,
    },
    /// Wrong number of degrees of freedom in one of the input vectors.
    #[error("{what} has {got} entries, expected {expected} (one per DoF, at most {max})")]
    DofMismatch {
        /// Which vector.
        what: &'static str,
        /// Its length.
        got: usize,
        /// The expected number of DoFs.
        expected: usize,
        /// Maximal number of DoFs supported.
        max: usize,
    },
    /// The minimum duration is negative or not finite.
    #[error("minimum duration {0} s must be a finite number >= 0")]
    BadMinimumDuration(f64),
    /// No profile was found (numerical failure; should not happen for valid input).
    #[error("no time-optimal profile found for DoF {dof}")]
    NoSolution {
        /// Degree of freedom index.
        dof: usize,
    },
    /// No common duration could be found for the synchronisation.
    #[error("no common duration found for synchronising the DoFs")]
    NoSynchronization,
}
