//! Task-space paths of the platform in (x, y, phi): mm, mm, rad.
//!
//! A path is parametrised by its length `s` in a combined metric
//! `ds^2 = dx^2 + dy^2 + (R dphi)^2`, where `R` (mm/rad, [`Path::rotation_radius`]) converts
//! rotation into an equivalent distance (so that a pure rotation has a length and the speed
//! limits along the path also bound the rotation rate). Every path is `Copy` with fixed-size
//! storage: evaluating it never allocates. No workspace or kinematic check is made here.

/// Maximal number of vertices of a polyline path (a rectangle uses 5).
pub const MAX_VERTICES: usize = 32;

/// Default rotation radius `R` in mm/rad.
pub const DEFAULT_ROTATION_RADIUS_MM: f64 = 50.0;

/// Platform pose: position in mm, orientation in rad. Also used for pose rates (mm/s, rad/s).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Pose {
    /// x in mm.
    pub x: f64,
    /// y in mm.
    pub y: f64,
    /// Orientation in rad.
    pub phi: f64,
}

impl Pose {
    /// A pose from its components (mm, mm, rad).
    pub const fn new(x: f64, y: f64, phi: f64) -> Self {
        Pose { x, y, phi }
    }

    fn lerp(&self, o: &Pose, u: f64) -> Pose {
        Pose::new(
            self.x + (o.x - self.x) * u,
            self.y + (o.y - self.y) * u,
            self.phi + (o.phi - self.phi) * u,
        )
    }

    fn scaled(&self, k: f64) -> Pose {
        Pose::new(self.x * k, self.y * k, self.phi * k)
    }

    /// Largest component-wise difference (mm or rad).
    pub fn max_diff(&self, o: &Pose) -> f64 {
        (self.x - o.x)
            .abs()
            .max((self.y - o.y).abs())
            .max((self.phi - o.phi).abs())
    }
}

/// Invalid path definition.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PathError {
    /// A number is NaN or infinite.
    #[error("path parameter {0} is not finite")]
    NotFinite(&'static str),
    /// Radius, width, height or rotation radius not strictly positive.
    #[error("path parameter {0} must be > 0 (got {1})")]
    NotPositive(&'static str, f64),
    /// Too few or too many polyline vertices.
    #[error("a polyline needs 2 ..= {MAX_VERTICES} vertices (got {0})")]
    Vertices(usize),
}

/// A line or an arc in (x, y, phi), the pieces both [`Path`] and the composite paths of
/// [`crate::composite`] are made of.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Primitive {
    /// Straight line, orientation interpolated linearly.
    Line {
        /// Start pose.
        a: Pose,
        /// End pose.
        b: Pose,
    },
    /// Circular arc, orientation interpolated linearly.
    Arc {
        /// Centre x, mm.
        cx: f64,
        /// Centre y, mm.
        cy: f64,
        /// Radius, mm.
        r: f64,
        /// Polar angle of the start point, rad.
        theta0: f64,
        /// Signed sweep, rad (positive: counter-clockwise).
        sweep: f64,
        /// Start orientation, rad.
        phi0: f64,
        /// End orientation, rad.
        phi1: f64,
    },
}

impl Primitive {
    /// Length in the combined metric with rotation radius `rot` (mm/rad), mm.
    pub fn length(&self, rot: f64) -> f64 {
        match *self {
            Primitive::Line { a, b } => seg_len(&a, &b, rot),
            Primitive::Arc {
                r,
                sweep,
                phi0,
                phi1,
                ..
            } => {
                let (l, p) = (r * sweep, rot * (phi1 - phi0));
                (l * l + p * p).sqrt()
            }
        }
    }

    /// Pose and d(pose)/ds at length `s` (clamped to [0, `len`]) of a primitive whose
    /// combined length is `len` mm; the end is reached exactly.
    pub fn sample(&self, len: f64, s: f64) -> (Pose, Pose) {
        let s = s.clamp(0.0, len);
        let (u, k) = if len > 0.0 {
            (s / len, 1.0 / len)
        } else {
            (0.0, 0.0)
        };
        match *self {
            Primitive::Line { a, b } => {
                let p = if s >= len { b } else { a.lerp(&b, u) };
                (
                    p,
                    Pose::new((b.x - a.x) * k, (b.y - a.y) * k, (b.phi - a.phi) * k),
                )
            }
            Primitive::Arc {
                cx,
                cy,
                r,
                theta0,
                sweep,
                phi0,
                phi1,
            } => {
                let (sn, c) = (theta0 + sweep * u).sin_cos();
                (
                    Pose::new(cx + r * c, cy + r * sn, phi0 + (phi1 - phi0) * u),
                    Pose::new(-r * sn * sweep * k, r * c * sweep * k, (phi1 - phi0) * k),
                )
            }
        }
    }
}

// Fixed size on purpose: paths are Copy and never allocate.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug, PartialEq)]
enum Geometry {
    Single(Primitive),
    Polyline {
        pts: [Pose; MAX_VERTICES],
        /// Cumulative length at each vertex.
        cum: [f64; MAX_VERTICES],
        n: usize,
    },
}

/// A task-space path (line, arc, full circle, rectangle, polyline).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Path {
    geo: Geometry,
    rot_radius: f64,
    length: f64,
}

fn finite(name: &'static str, v: f64) -> Result<f64, PathError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(PathError::NotFinite(name))
    }
}

fn finite_pose(p: &Pose) -> Result<(), PathError> {
    finite("x", p.x)?;
    finite("y", p.y)?;
    finite("phi", p.phi)?;
    Ok(())
}

fn seg_len(a: &Pose, b: &Pose, r: f64) -> f64 {
    let (dx, dy, dp) = (b.x - a.x, b.y - a.y, r * (b.phi - a.phi));
    (dx * dx + dy * dy + dp * dp).sqrt()
}

impl Path {
    /// Straight line from `a` to `b` (orientation interpolated linearly).
    pub fn line(a: Pose, b: Pose) -> Result<Path, PathError> {
        finite_pose(&a)?;
        finite_pose(&b)?;
        let mut p = Path {
            geo: Geometry::Single(Primitive::Line { a, b }),
            rot_radius: DEFAULT_ROTATION_RADIUS_MM,
            length: 0.0,
        };
        p.update_length();
        Ok(p)
    }

    /// Circular arc around (`cx`, `cy`) mm of radius `r` mm, from polar angle `theta0` rad
    /// sweeping `sweep` rad (positive: counter-clockwise), orientation from `phi0` to `phi1` rad.
    pub fn arc(
        cx: f64,
        cy: f64,
        r: f64,
        theta0: f64,
        sweep: f64,
        phi0: f64,
        phi1: f64,
    ) -> Result<Path, PathError> {
        for (n, v) in [
            ("cx", cx),
            ("cy", cy),
            ("r", r),
            ("theta0", theta0),
            ("sweep", sweep),
            ("phi0", phi0),
            ("phi1", phi1),
        ] {
            finite(n, v)?;
        }
        if r <= 0.0 {
            return Err(PathError::NotPositive("radius", r));
        }
        let mut p = Path {
            geo: Geometry::Single(Primitive::Arc {
                cx,
                cy,
                r,
                theta0,
                sweep,
                phi0,
                phi1,
            }),
            rot_radius: DEFAULT_ROTATION_RADIUS_MM,
            length: 0.0,
        };
        p.update_length();
        Ok(p)
    }

    /// Full circle around (`cx`, `cy`) of radius `r` starting at polar angle `theta0`,
    /// counter-clockwise if `ccw`, at constant orientation `phi`.
    pub fn circle(
        cx: f64,
        cy: f64,
        r: f64,
        theta0: f64,
        ccw: bool,
        phi: f64,
    ) -> Result<Path, PathError> {
        let sweep = if ccw {
            std::f64::consts::TAU
        } else {
            -std::f64::consts::TAU
        };
        Path::arc(cx, cy, r, theta0, sweep, phi, phi)
    }

    /// Rectangle with one corner at `corner`, sides `width` (along the direction `angle` rad)
    /// and `height` (90 degrees counter-clockwise from it), traversed counter-clockwise back to
    /// the start corner at constant orientation `corner.phi`.
    pub fn rectangle(corner: Pose, width: f64, height: f64, angle: f64) -> Result<Path, PathError> {
        finite_pose(&corner)?;
        finite("angle", angle)?;
        if width.is_nan() || width <= 0.0 {
            return Err(PathError::NotPositive("width", width));
        }
        if height.is_nan() || height <= 0.0 {
            return Err(PathError::NotPositive("height", height));
        }
        let (c, s) = (angle.cos(), angle.sin());
        let p0 = corner;
        let p1 = Pose::new(p0.x + width * c, p0.y + width * s, p0.phi);
        let p2 = Pose::new(p1.x - height * s, p1.y + height * c, p0.phi);
        let p3 = Pose::new(p0.x - height * s, p0.y + height * c, p0.phi);
        Path::polyline(&[p0, p1, p2, p3, p0])
    }

    /// Polyline through 2 ..= [`MAX_VERTICES`] vertices.
    pub fn polyline(vertices: &[Pose]) -> Result<Path, PathError> {
        if vertices.len() < 2 || vertices.len() > MAX_VERTICES {
            return Err(PathError::Vertices(vertices.len()));
        }
        let mut pts = [Pose::default(); MAX_VERTICES];
        for (d, v) in pts.iter_mut().zip(vertices) {
            finite_pose(v)?;
            *d = *v;
        }
        let mut p = Path {
            geo: Geometry::Polyline {
                pts,
                cum: [0.0; MAX_VERTICES],
                n: vertices.len(),
            },
            rot_radius: DEFAULT_ROTATION_RADIUS_MM,
            length: 0.0,
        };
        p.update_length();
        Ok(p)
    }

    /// The same path with another rotation radius `R` (mm/rad, > 0).
    pub fn with_rotation_radius(mut self, r: f64) -> Result<Path, PathError> {
        if !(r > 0.0 && r.is_finite()) {
            return Err(PathError::NotPositive("rotation radius", r));
        }
        self.rot_radius = r;
        self.update_length();
        Ok(self)
    }

    /// Rotation radius `R` in mm/rad.
    pub fn rotation_radius(&self) -> f64 {
        self.rot_radius
    }

    fn update_length(&mut self) {
        let r = self.rot_radius;
        self.length = match &mut self.geo {
            Geometry::Single(p) => p.length(r),
            Geometry::Polyline { pts, cum, n } => {
                cum[0] = 0.0;
                for i in 1..*n {
                    cum[i] = cum[i - 1] + seg_len(&pts[i - 1], &pts[i], r);
                }
                cum[*n - 1]
            }
        };
    }

    /// Length in the combined metric, mm.
    pub fn length(&self) -> f64 {
        self.length
    }

    /// Start pose.
    pub fn start(&self) -> Pose {
        self.pose_at(0.0)
    }

    /// End pose.
    pub fn end(&self) -> Pose {
        self.pose_at(self.length)
    }

    /// Pose and derivative d(pose)/ds (1/1, 1/1, rad/mm) at path length `s` mm (clamped to
    /// `[0, length]`).
    pub fn sample(&self, s: f64) -> (Pose, Pose) {
        let s = s.clamp(0.0, self.length);
        match &self.geo {
            Geometry::Single(p) => p.sample(self.length, s),
            Geometry::Polyline { pts, cum, n } => {
                let mut i = 1;
                while i < *n - 1 && cum[i] < s {
                    i += 1;
                }
                let l = cum[i] - cum[i - 1];
                if l == 0.0 {
                    return (pts[i], Pose::default());
                }
                let u = ((s - cum[i - 1]) / l).clamp(0.0, 1.0);
                let (a, b) = (&pts[i - 1], &pts[i]);
                let d = Pose::new(b.x - a.x, b.y - a.y, b.phi - a.phi).scaled(1.0 / l);
                (a.lerp(b, u), d)
            }
        }
    }

    /// Pose at path length `s` mm (clamped).
    pub fn pose_at(&self, s: f64) -> Pose {
        self.sample(s).0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    #[test]
    fn line_endpoints_and_length() {
        let p = Path::line(Pose::new(0.0, 0.0, 0.0), Pose::new(3.0, 4.0, 0.0)).unwrap();
        assert!((p.length() - 5.0).abs() < 1e-12);
        assert!(p.end().max_diff(&Pose::new(3.0, 4.0, 0.0)) < 1e-12);
        let (m, d) = p.sample(2.5);
        assert!(m.max_diff(&Pose::new(1.5, 2.0, 0.0)) < 1e-12);
        assert!((d.x * d.x + d.y * d.y - 1.0).abs() < 1e-12);
    }

    #[test]
    fn pure_rotation_has_length() {
        let p = Path::line(Pose::new(1.0, 1.0, 0.0), Pose::new(1.0, 1.0, 0.5))
            .unwrap()
            .with_rotation_radius(10.0)
            .unwrap();
        assert!((p.length() - 5.0).abs() < 1e-12);
    }

    #[test]
    fn arc_stays_on_circle() {
        let p = Path::arc(1.0, 2.0, 10.0, 0.0, FRAC_PI_2, 0.0, 0.0).unwrap();
        assert!((p.length() - 10.0 * FRAC_PI_2).abs() < 1e-12);
        for k in 0..=10 {
            let q = p.pose_at(p.length() * k as f64 / 10.0);
            assert!((((q.x - 1.0).powi(2) + (q.y - 2.0).powi(2)).sqrt() - 10.0).abs() < 1e-12);
        }
        assert!(p.end().max_diff(&Pose::new(1.0, 12.0, 0.0)) < 1e-12);
    }

    #[test]
    fn full_circle_returns_to_start() {
        let p = Path::circle(0.0, 0.0, 5.0, PI, false, 0.2).unwrap();
        assert!((p.length() - 10.0 * PI).abs() < 1e-12);
        assert!(p.end().max_diff(&p.start()) < 1e-12);
        // Clockwise from (-5, 0): a quarter later at (0, 5).
        assert!(
            p.pose_at(p.length() / 4.0)
                .max_diff(&Pose::new(0.0, 5.0, 0.2))
                < 1e-12
        );
    }

    #[test]
    fn rectangle_perimeter_and_corners() {
        let p = Path::rectangle(Pose::new(1.0, 1.0, 0.1), 4.0, 2.0, 0.0).unwrap();
        assert!((p.length() - 12.0).abs() < 1e-12);
        assert!(p.pose_at(4.0).max_diff(&Pose::new(5.0, 1.0, 0.1)) < 1e-12);
        assert!(p.pose_at(6.0).max_diff(&Pose::new(5.0, 3.0, 0.1)) < 1e-12);
        assert!(p.end().max_diff(&p.start()) < 1e-12);
    }

    #[test]
    fn bad_paths_are_errors() {
        assert!(Path::arc(0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0).is_err());
        assert!(Path::line(Pose::new(f64::NAN, 0.0, 0.0), Pose::default()).is_err());
        assert!(Path::polyline(&[Pose::default()]).is_err());
        assert!(Path::rectangle(Pose::default(), -1.0, 1.0, 0.0).is_err());
    }
}
