//! What the attribution is doing, for a progress display: the library reports through
//! [`Progress`]; the binary draws it (or not).

use std::sync::Arc;

/// Receives the attribution's progress. Called from the analysing threads (hence `Sync`).
pub trait Progress: Send + Sync {
    /// A stage begins: `what` it is (e.g. "fitting candidates", "adding backlash"), the round
    /// (1-based; 0 before the first), the rows it works on, and the number of steps it takes
    /// (0: not known).
    fn stage(&self, round: usize, what: &str, rows: usize, steps: usize);
    /// One more step of the current stage is done.
    fn step(&self);
}

/// An optional progress receiver in the options (none by default; never serialised).
#[derive(Clone, Default)]
pub struct ProgressSink(pub Option<Arc<dyn Progress>>);

impl ProgressSink {
    /// A sink that reports to `p`.
    pub fn new(p: Arc<dyn Progress>) -> ProgressSink {
        ProgressSink(Some(p))
    }

    /// Reports the start of a stage.
    pub fn stage(&self, round: usize, what: &str, rows: usize, steps: usize) {
        tracing::debug!(round, rows, steps, "stage: {what}");
        if let Some(p) = &self.0 {
            p.stage(round, what, rows, steps);
        }
    }

    /// Reports a step done.
    pub fn step(&self) {
        if let Some(p) = &self.0 {
            p.step();
        }
    }
}

impl std::fmt::Debug for ProgressSink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(if self.0.is_some() {
            "ProgressSink(set)"
        } else {
            "ProgressSink(none)"
        })
    }
}
