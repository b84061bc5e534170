//! A frame in the robot base frame: the platform pose and the labelled markers of the robot
//! (base points B_i, passive joints M_i), found by name in the server's parameters.

use crate::frame::Frame;
use crate::params::Parameters;
use crate::registration::{MarkerLabels, Registration};

/// The robot's view of one frame (robot base frame).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RobotSample {
    /// Platform pose: x mm, y mm, phi rad (`None` = not measured).
    pub pose: Option<[f64; 3]>,
    /// Base markers B_1..B_3: x, y, z mm.
    pub base: [Option<[f64; 3]>; 3],
    /// Joint markers M_1..M_3: x, y, z mm.
    pub joints: [Option<[f64; 3]>; 3],
}

/// A body or label the mapper cannot find.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MapperError {
    /// The named body is not declared.
    #[error("6DOF body {0:?} is not declared by the server (bodies: {1})")]
    UnknownBody(String, String),
}

/// Maps frames of one server (its parameters) into the robot frame.
#[derive(Debug, Clone)]
pub struct Mapper {
    body: Option<usize>,
    base: [Option<usize>; 3],
    joints: [Option<usize>; 3],
    reg: Registration,
}

impl Mapper {
    /// The platform is the body named `body` (or the first body); markers by label (labels
    /// the server does not declare are never measured).
    pub fn new(
        params: &Parameters,
        body: Option<&str>,
        labels: &MarkerLabels,
        reg: Registration,
    ) -> Result<Mapper, MapperError> {
        let body = match body {
            Some(n) => Some(
                params
                    .body_index(n)
                    .ok_or_else(|| MapperError::UnknownBody(n.into(), params.bodies.join(", ")))?,
            ),
            None => (!params.bodies.is_empty()).then_some(0),
        };
        Ok(Mapper {
            body,
            base: std::array::from_fn(|i| params.label_index(&labels.base[i])),
            joints: std::array::from_fn(|i| params.label_index(&labels.joints[i])),
            reg,
        })
    }

    /// The registration applied.
    pub fn registration(&self) -> &Registration {
        &self.reg
    }

    /// One frame in the robot frame.
    pub fn map(&self, f: &Frame) -> RobotSample {
        let marker = |i: Option<usize>| {
            i.and_then(|i| f.markers.get(i).copied().flatten())
                .map(|m| self.reg.point(m.position_mm))
        };
        RobotSample {
            pose: self
                .body
                .and_then(|i| f.bodies.get(i).copied().flatten())
                .map(|b| self.reg.pose(&b)),
            base: self.base.map(marker),
            joints: self.joints.map(marker),
        }
    }
}
