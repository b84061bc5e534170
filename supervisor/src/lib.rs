//! Supervisor of the process chain (not started yet; see the issues).
