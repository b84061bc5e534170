//! Qualisys real-time protocol bridge (not started yet; see the issues).
