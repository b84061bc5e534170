//! Why a design cannot be built.

/// One pose of a design that the model cannot reach safely.
#[derive(Debug, Clone, PartialEq)]
pub struct InfeasiblePose {
    /// Its pose id.
    pub pose_id: u64,
    /// Orientation, deg.
    pub phi_deg: f64,
    /// Scale of its boundary.
    pub scale: f64,
    /// Index of the point along the scaled boundary (0 at polar angle 0).
    pub point: usize,
    /// Position, mm.
    pub xy: [f64; 2],
    /// What failed.
    pub why: String,
}

impl std::fmt::Display for InfeasiblePose {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "pose_id {} (phi {:+} deg, scale {}, point {}: x {:.2} mm, y {:.2} mm): {}",
            self.pose_id, self.phi_deg, self.scale, self.point, self.xy[0], self.xy[1], self.why
        )
    }
}

/// Why a design cannot be built. Every variant names the option or the pose.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DesignError {
    /// A design option is out of range.
    #[error("design option {option}: {why}")]
    Option {
        /// The option.
        option: &'static str,
        /// What is wrong.
        why: String,
    },
    /// The origin is not in the workspace of an orientation.
    #[error(
        "the origin (0, 0) is not in the workspace at phi = {phi_deg} deg: the boundary is traced \
         from it"
    )]
    OriginOutside {
        /// Orientation, deg.
        phi_deg: f64,
    },
    /// A ray from the origin never left the workspace.
    #[error(
        "the workspace at phi = {phi_deg} deg does not end along polar angle {angle_deg:.1} deg \
         within {radius_mm} mm"
    )]
    Unbounded {
        /// Orientation, deg.
        phi_deg: f64,
        /// Polar angle of the ray, deg.
        angle_deg: f64,
        /// Largest radius searched, mm.
        radius_mm: f64,
    },
    /// Poses of the design are not feasible with the margin (all of them are listed).
    #[error("{} of the design's poses are not feasible:\n  {}", .0.len(),
        .0.iter().map(ToString::to_string).collect::<Vec<_>>().join("\n  "))]
    Infeasible(Vec<InfeasiblePose>),
    /// The robot model could not be built or used.
    #[error("robot model: {0}")]
    Robot(String),
}
