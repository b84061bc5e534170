//! The robot drawn for Foxglove's 3D panel: each leg as the constant-curvature arc of the model
//! for the commanded steps (pcr-kinematics), the rigid links to the platform joints, the platform
//! at the model's pose of those steps (FK), the measured platform and markers M_i where the row
//! has them, and the planned platform. Frame `base`, metres.

use foxglove::messages::{
    line_primitive, Color, FrameTransform, FrameTransforms, LinePrimitive, Point3, Pose as FgPose,
    PoseInFrame, Quaternion, SceneEntity, SceneUpdate, SpherePrimitive, Timestamp, Vector3,
};
use pcr_kinematics::{Pose, Robot};
use pcr_recording::Row;

use crate::topics::{BASE_FRAME, PLANNED_FRAME, PLATFORM_FRAME};

/// Points per leg arc.
const ARC_POINTS: usize = 24;
/// mm -> m.
const M_PER_MM: f64 = 1e-3;

/// A Foxglove timestamp of a time in seconds (clamped to 0 and to the format's range).
pub fn timestamp(t_s: f64) -> Timestamp {
    let t = t_s.max(0.0);
    let sec = t.floor().min(u32::MAX as f64) as u32;
    let nsec = (((t - t.floor()) * 1e9) as u32).min(999_999_999);
    Timestamp::new(sec, nsec)
}

/// Nanoseconds of a time in seconds (log times of the channels).
pub fn nanos(t_s: f64) -> u64 {
    (t_s.max(0.0) * 1e9).round() as u64
}

fn point(p: [f64; 2]) -> Point3 {
    Point3 {
        x: p[0] * M_PER_MM,
        y: p[1] * M_PER_MM,
        z: 0.0,
    }
}

fn color(r: f64, g: f64, b: f64) -> Option<Color> {
    Some(Color { r, g, b, a: 1.0 })
}

fn yaw(phi_rad: f64) -> Quaternion {
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: (phi_rad * 0.5).sin(),
        w: (phi_rad * 0.5).cos(),
    }
}

/// A platform pose (x mm, y mm, phi rad) as a Foxglove pose in metres.
pub fn fg_pose(p: [f64; 3]) -> FgPose {
    FgPose {
        position: Some(Vector3 {
            x: p[0] * M_PER_MM,
            y: p[1] * M_PER_MM,
            z: 0.0,
        }),
        orientation: Some(yaw(p[2])),
    }
}

/// A `foxglove.PoseInFrame` in the base frame.
pub fn pose_in_frame(p: [f64; 3], t_s: f64) -> PoseInFrame {
    PoseInFrame {
        timestamp: Some(timestamp(t_s)),
        frame_id: BASE_FRAME.into(),
        pose: Some(fg_pose(p)),
    }
}

/// The transforms `base` -> `platform` (measured) and `base` -> `platform_planned` that a row
/// has (none when it has neither pose).
pub fn transforms(
    measured: Option<[f64; 3]>,
    planned: Option<[f64; 3]>,
    t_s: f64,
) -> FrameTransforms {
    let tf = |child: &str, p: [f64; 3]| FrameTransform {
        timestamp: Some(timestamp(t_s)),
        parent_frame_id: BASE_FRAME.into(),
        child_frame_id: child.into(),
        translation: Some(Vector3 {
            x: p[0] * M_PER_MM,
            y: p[1] * M_PER_MM,
            z: 0.0,
        }),
        rotation: Some(yaw(p[2])),
    };
    FrameTransforms {
        transforms: measured
            .map(|p| tf(PLATFORM_FRAME, p))
            .into_iter()
            .chain(planned.map(|p| tf(PLANNED_FRAME, p)))
            .collect(),
    }
}

fn line(
    points: Vec<Point3>,
    kind: line_primitive::Type,
    thickness_px: f64,
    c: Option<Color>,
) -> LinePrimitive {
    LinePrimitive {
        r#type: kind as i32,
        pose: Some(fg_pose([0.0; 3])),
        thickness: thickness_px,
        scale_invariant: true,
        points,
        color: c,
        colors: Vec::new(),
        indices: Vec::new(),
    }
}

/// Draws the robot of one model.
#[derive(Debug, Clone)]
pub struct RobotScene {
    robot: Robot,
    /// The last FK pose (warm start of the next).
    last: Pose,
}

impl RobotScene {
    /// A scene of this robot model.
    pub fn new(robot: Robot) -> Self {
        Self {
            robot,
            last: Pose::default(),
        }
    }

    fn platform(&self, p: [f64; 3]) -> Vec<Point3> {
        let pose = Pose::from_array(p);
        (0..3)
            .map(|i| point(self.robot.joint_p(i, &pose)))
            .collect()
    }

    /// The scene of one row: legs of its commanded steps, links and platform at their FK pose,
    /// the measured platform and markers, the planned platform (poses x mm, y mm, phi rad).
    pub fn update(
        &mut self,
        q: [i32; 3],
        measured: Option<[f64; 3]>,
        markers: [Option<[f64; 2]>; 3],
        planned: Option<[f64; 3]>,
        t_s: f64,
    ) -> SceneUpdate {
        let kappa: [f64; 3] = std::array::from_fn(|i| self.robot.steps_to_kappa(i, q[i] as f64));
        let mut lines = Vec::with_capacity(6);
        let mut spheres = Vec::new();
        for i in 0..3 {
            let pts = self.robot.legs[i].shape(kappa[i], ARC_POINTS);
            lines.push(line(
                pts.iter().map(|p| point(*p)).collect(),
                line_primitive::Type::LineStrip,
                4.0,
                color(0.15, 0.45, 0.95),
            ));
        }
        if let Ok(pose) = self.robot.fk_warm(&kappa, &self.last) {
            self.last = pose;
            let mut links = Vec::with_capacity(6);
            for i in 0..3 {
                links.push(point(self.robot.joint_m(i, kappa[i])));
                links.push(point(self.robot.joint_p(i, &pose)));
            }
            lines.push(line(
                links,
                line_primitive::Type::LineList,
                3.0,
                color(0.5, 0.5, 0.5),
            ));
            lines.push(line(
                self.platform(pose.to_array()),
                line_primitive::Type::LineLoop,
                3.0,
                color(0.2, 0.2, 0.2),
            ));
        }
        if let Some(p) = planned {
            lines.push(line(
                self.platform(p),
                line_primitive::Type::LineLoop,
                1.5,
                color(0.1, 0.7, 0.2),
            ));
        }
        if let Some(p) = measured {
            lines.push(line(
                self.platform(p),
                line_primitive::Type::LineLoop,
                2.0,
                color(0.9, 0.2, 0.1),
            ));
        }
        for m in markers.iter().flatten() {
            let c = point(*m);
            spheres.push(SpherePrimitive {
                pose: Some(fg_pose([c.x / M_PER_MM, c.y / M_PER_MM, 0.0])),
                size: Some(Vector3 {
                    x: 0.006,
                    y: 0.006,
                    z: 0.006,
                }),
                color: color(0.9, 0.2, 0.1),
            });
        }
        SceneUpdate {
            deletions: Vec::new(),
            entities: vec![SceneEntity {
                timestamp: Some(timestamp(t_s)),
                frame_id: BASE_FRAME.into(),
                id: "robot".into(),
                lifetime: None,
                frame_locked: false,
                metadata: Vec::new(),
                arrows: Vec::new(),
                cubes: Vec::new(),
                spheres,
                cylinders: Vec::new(),
                lines,
                triangles: Vec::new(),
                texts: Vec::new(),
                models: Vec::new(),
            }],
        }
    }

    /// The scene of a recording row (its poses in mm and degrees).
    pub fn of_row(&mut self, row: &Row, t_s: f64) -> SceneUpdate {
        let rad = |p: [f64; 3]| [p[0], p[1], p[2].to_radians()];
        let measured = row.measured_pose().map(rad);
        let planned = planned_pose(row).map(rad);
        let markers = std::array::from_fn(|i| Some([row.m[i][0]?, row.m[i][1]?]));
        self.update(row.q, measured, markers, planned, t_s)
    }
}

/// The planned pose of a row if all three cells are present (mm, mm, deg).
pub fn planned_pose(row: &Row) -> Option<[f64; 3]> {
    Some([row.planned[0]?, row.planned[1]?, row.planned[2]?])
}
