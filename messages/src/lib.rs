//! Message types and service names of the process chain (work in progress).
