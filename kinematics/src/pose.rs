//! The platform pose x_E = (x_E, y_E, phi_E).

/// Platform pose in the base frame: position in mm, orientation in radians.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose {
    /// x_E, mm.
    pub x: f64,
    /// y_E, mm.
    pub y: f64,
    /// phi_E, rad.
    pub phi: f64,
}

impl Pose {
    /// A pose from millimetres and radians.
    pub const fn new(x: f64, y: f64, phi: f64) -> Pose {
        Pose { x, y, phi }
    }

    /// A pose from millimetres and degrees (the unit of every file and CLI).
    pub fn from_mm_deg(x: f64, y: f64, phi_deg: f64) -> Pose {
        Pose::new(x, y, phi_deg.to_radians())
    }

    /// Orientation in degrees.
    pub fn phi_deg(&self) -> f64 {
        self.phi.to_degrees()
    }

    /// As an array (x, y, phi).
    pub fn to_array(self) -> [f64; 3] {
        [self.x, self.y, self.phi]
    }

    /// From an array (x, y, phi).
    pub fn from_array(a: [f64; 3]) -> Pose {
        Pose::new(a[0], a[1], a[2])
    }

    /// Euclidean distance of the positions, mm.
    pub fn position_distance(&self, o: &Pose) -> f64 {
        (self.x - o.x).hypot(self.y - o.y)
    }
}
