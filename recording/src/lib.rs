//! Recording format reader/writer (work in progress).
