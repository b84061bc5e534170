//! The calibration pose set of the paper (Fig. 5): points evenly spaced along scaled workspace
//! boundaries, for several constant orientations, split into training and test poses.
//!
//! Decisions the paper leaves open (docs/experiments.md):
//! - the boundary is that of each orientation's own translational workspace (not phi = 0's
//!   for all three), of the robot model in use (the one that drives the robot);
//! - it is traced along rays from the origin ([`crate::boundary`]), scaled about the origin
//!   (0, 0), and the points start at polar angle 0 (+x) and go counter-clockwise, spaced by
//!   perimeter / n along the scaled polygon;
//! - pose ids run orientation-major in the order of `phis_deg`, then scale in the order of
//!   `scales`, then point along the boundary: `pose_id = (i_phi * n_scales + i_scale) * n + k`;
//!   positions are rounded to 0.1 um;
//! - the split is stratified by (orientation, scale) group: `test_per_group` of each group's
//!   points go to the test set, drawn by [`crate::split::stratified_test_indices`] with the seed;
//! - every pose must have IK in the working mode with a conditioning of at least
//!   `singularity_margin` times the robot's singularity threshold, and the straight approach
//!   from the origin must stay feasible (sampled every 0.5 mm); a design with any failing pose
//!   is refused with all failures listed, none is dropped.

use crate::boundary::{workspace_boundary, Boundary, BoundaryOptions};
use crate::error::{DesignError, InfeasiblePose};
use crate::split::stratified_test_indices;
use pcr_kinematics::{Pose, Robot};
use pcr_recording::Split;

/// Options of the calibration set (defaults: the paper's).
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationOptions {
    /// Constant orientations, deg (paper: 0, +10, -10).
    pub phis_deg: Vec<f64>,
    /// Scales of the boundary about the origin (paper: 0.75, 0.5, 0.2).
    pub scales: Vec<f64>,
    /// Points per scaled boundary (paper: 21).
    pub points: usize,
    /// Test poses per (orientation, scale) group (paper: 63 of 189, i.e. 7 of 21).
    pub test_per_group: usize,
    /// Seed of the split.
    pub seed: u64,
    /// Required conditioning at each pose, as a multiple of the singularity threshold (>= 1).
    pub singularity_margin: f64,
    /// How the boundaries are traced.
    pub boundary: BoundaryOptions,
}

impl Default for CalibrationOptions {
    fn default() -> Self {
        CalibrationOptions {
            phis_deg: vec![0.0, 10.0, -10.0],
            scales: vec![0.75, 0.5, 0.2],
            points: 21,
            test_per_group: 7,
            seed: 1,
            singularity_margin: 2.0,
            boundary: BoundaryOptions::default(),
        }
    }
}

impl CalibrationOptions {
    /// Checks the ranges; names the option.
    pub fn validate(&self) -> Result<(), DesignError> {
        let opt = |option, why: String| Err(DesignError::Option { option, why });
        if self.phis_deg.is_empty() {
            return opt("phis_deg", "no orientation".into());
        }
        if let Some(p) = self
            .phis_deg
            .iter()
            .find(|p| !(p.is_finite() && p.abs() < 90.0))
        {
            return opt("phis_deg", format!("{p} deg (|phi| < 90 deg)"));
        }
        if self.scales.is_empty() {
            return opt("scales", "no scale".into());
        }
        if let Some(s) = self
            .scales
            .iter()
            .find(|s| !(s.is_finite() && **s > 0.0 && **s <= 1.0))
        {
            return opt("scales", format!("{s} (0 < scale <= 1)"));
        }
        if self.points == 0 {
            return opt("points", "0 points per boundary".into());
        }
        if self.test_per_group > self.points {
            return opt(
                "test_per_group",
                format!(
                    "{} test poses of {} per group",
                    self.test_per_group, self.points
                ),
            );
        }
        if !(self.singularity_margin.is_finite() && self.singularity_margin >= 1.0) {
            return opt(
                "singularity_margin",
                format!("{} (>= 1)", self.singularity_margin),
            );
        }
        Ok(())
    }
}

/// One pose of the calibration set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationPose {
    /// Pose id (see the module documentation for the order).
    pub pose_id: u64,
    /// The pose (mm, rad).
    pub pose: Pose,
    /// Orientation, deg (exactly as given in the options).
    pub phi_deg: f64,
    /// Scale of its boundary.
    pub scale: f64,
    /// Index along the scaled boundary (0 at polar angle 0, counter-clockwise).
    pub point: usize,
    /// Training or test.
    pub set: Split,
    /// Conditioning of the model there (0 singular .. 1).
    pub conditioning: f64,
}

/// The calibration set: the traced boundaries (one per orientation) and the poses.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationSet {
    /// The options it was built with.
    pub options: CalibrationOptions,
    /// One boundary per orientation, in the order of `options.phis_deg`.
    pub boundaries: Vec<Boundary>,
    /// The poses in pose-id order.
    pub poses: Vec<CalibrationPose>,
}

/// Poses closer than this to the origin have no approach to check, mm.
const APPROACH_STEP_MM: f64 = 0.5;

/// Checks one pose: IK in the working mode, conditioning >= margin x threshold, and the
/// straight approach from the origin (IK and conditioning >= threshold every 0.5 mm). Returns
/// the conditioning at the pose.
pub fn check_pose(robot: &Robot, pose: &Pose, margin: f64) -> Result<f64, String> {
    let thr = robot.limits.singularity_threshold;
    let sol = robot.ik(pose).map_err(|e| format!("no IK: {e}"))?;
    let c = robot.conditioning(pose, &sol.kappa).value();
    if c < margin * thr {
        return Err(format!(
            "conditioning {c:.2e} below {margin} x the singularity threshold {thr:.1e}"
        ));
    }
    let n = (pose.x.hypot(pose.y) / APPROACH_STEP_MM).ceil() as usize;
    for k in 1..n {
        let u = k as f64 / n as f64;
        let p = Pose::new(u * pose.x, u * pose.y, u * pose.phi);
        let bad = |why: String| {
            format!(
                "the approach from the origin fails at ({:.2} mm, {:.2} mm, {:.2} deg): {why}",
                p.x,
                p.y,
                p.phi.to_degrees()
            )
        };
        let s = robot.ik(&p).map_err(|e| bad(format!("no IK: {e}")))?;
        let cp = robot.conditioning(&p, &s.kappa).value();
        if cp < thr {
            return Err(bad(format!("conditioning {cp:.2e} below {thr:.1e}")));
        }
    }
    Ok(c)
}

impl CalibrationSet {
    /// Builds the set for the model `robot` (see the module documentation). Refuses a design in
    /// which any pose is not feasible, listing every such pose.
    pub fn design(robot: &Robot, options: &CalibrationOptions) -> Result<Self, DesignError> {
        options.validate()?;
        let o = options;
        let boundaries = o
            .phis_deg
            .iter()
            .map(|p| workspace_boundary(robot, p.to_radians(), &o.boundary))
            .collect::<Result<Vec<_>, _>>()?;
        for b in &boundaries {
            if let Some(c) = b.check {
                tracing::info!(
                    phi_deg = b.phi.to_degrees(),
                    polygon_mm2 = c.polygon_area_mm2,
                    grid_mm2 = c.grid_area_mm2,
                    beyond_mm2 = c.outside_area_mm2,
                    "workspace boundary"
                );
                if c.outside_area_mm2 > 0.01 * c.grid_area_mm2 {
                    tracing::warn!(
                        phi_deg = b.phi.to_degrees(),
                        "{:.0} mm^2 of the grid workspace lie beyond the boundary traced from \
                         the origin (not star-shaped from the origin, or a second component)",
                        c.outside_area_mm2
                    );
                }
            }
        }
        let groups = o.phis_deg.len() * o.scales.len();
        let test = stratified_test_indices(o.seed, groups, o.points, o.test_per_group);
        let mut poses = Vec::with_capacity(groups * o.points);
        let mut failed = Vec::new();
        for (ip, (&phi_deg, b)) in o.phis_deg.iter().zip(&boundaries).enumerate() {
            let unit = b.points_by_arc_length(o.points);
            for (is, &scale) in o.scales.iter().enumerate() {
                let g = ip * o.scales.len() + is;
                for (k, u) in unit.iter().enumerate() {
                    let pose_id = (g * o.points + k) as u64;
                    // Positions to 0.1 um, so that the file, the metadata and the program hold
                    // the same numbers.
                    let pose = Pose::new(
                        round_dec(scale * u[0], 4),
                        round_dec(scale * u[1], 4),
                        phi_deg.to_radians(),
                    );
                    let set = if test[g].binary_search(&k).is_ok() {
                        Split::Test
                    } else {
                        Split::Train
                    };
                    let conditioning = match check_pose(robot, &pose, o.singularity_margin) {
                        Ok(c) => c,
                        Err(why) => {
                            failed.push(InfeasiblePose {
                                pose_id,
                                phi_deg,
                                scale,
                                point: k,
                                xy: [pose.x, pose.y],
                                why,
                            });
                            0.0
                        }
                    };
                    poses.push(CalibrationPose {
                        pose_id,
                        pose,
                        phi_deg,
                        scale,
                        point: k,
                        set,
                        conditioning,
                    });
                }
            }
        }
        if !failed.is_empty() {
            return Err(DesignError::Infeasible(failed));
        }
        Ok(CalibrationSet {
            options: o.clone(),
            boundaries,
            poses,
        })
    }

    /// The poses of orientation `phi_deg` (as given in the options).
    pub fn at_phi(&self, phi_deg: f64) -> impl Iterator<Item = &CalibrationPose> {
        self.poses.iter().filter(move |p| p.phi_deg == phi_deg)
    }

    /// The pose set as CSV text: `pose_id,x_mm,y_mm,phi_deg,scale,point,set`.
    pub fn to_csv(&self) -> String {
        let mut s = String::from("pose_id,x_mm,y_mm,phi_deg,scale,point,set\n");
        for p in &self.poses {
            s.push_str(&format!(
                "{},{},{},{},{},{},{}\n",
                p.pose_id,
                pcr_recording::number(p.pose.x),
                pcr_recording::number(p.pose.y),
                pcr_recording::number(p.phi_deg),
                pcr_recording::number(p.scale),
                p.point,
                p.set.as_str()
            ));
        }
        s
    }
}

/// `v` rounded to `decimals` decimal places (the nearest double of the decimal, which prints
/// as that decimal).
pub(crate) fn round_dec(v: f64, decimals: i32) -> f64 {
    let f = 10f64.powi(decimals);
    let r = (v * f).round() / f;
    // (-0.0 would print as "-0")
    if r == 0.0 {
        0.0
    } else {
        r
    }
}
