//! Constant-curvature kinematic model of the 3-FbRR (work in progress).
