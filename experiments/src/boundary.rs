//! The boundary of a constant-orientation translational workspace as an ordered closed polygon.
//!
//! The workspace of the calibration set is the one of `pcr_kinematics::workspace`: the platform
//! positions at orientation phi whose IK has a valid root in the working mode (joint and bending
//! limits) and whose conditioning is at or above the singularity threshold
//! ([`pcr_kinematics::workspace::feasible`], the test behind the grid workspace). It contains
//! the origin. Its boundary is found along `rays` rays from the origin at evenly spaced polar
//! angles, the first at polar angle 0 (+x): each ray is walked outwards in steps of `step_mm`
//! until the test fails, then the crossing is bisected to `tol_mm`. The vertices are therefore
//! ordered counter-clockwise, vertex 0 on the +x axis, and the polygon is star-shaped from the
//! origin: every point between the origin and a vertex passed the test (to the walking step).
//!
//! The polygon is cross-checked against the grid workspace mask (`grid_res_mm` cells):
//! [`BoundaryCheck`] reports the mask's area, the polygon's and the area of mask cells that lie
//! beyond the polygon (non-zero if the workspace were not star-shaped from the origin or had a
//! second component).

use crate::error::DesignError;
use pcr_kinematics::workspace::{feasible, grid_workspace};
use pcr_kinematics::{Pose, Robot};
use pcr_robot::Vec2;
use std::f64::consts::TAU;

/// How a boundary is traced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoundaryOptions {
    /// Number of rays from the origin (evenly spaced polar angles, the first at 0).
    pub rays: usize,
    /// Walking step along a ray, mm.
    pub step_mm: f64,
    /// Bisection tolerance of the crossing, mm.
    pub tol_mm: f64,
    /// Largest radius searched, mm (a ray still feasible there is an error).
    pub max_radius_mm: f64,
    /// Cell side of the grid mask of the cross-check, mm.
    pub grid_res_mm: f64,
}

impl Default for BoundaryOptions {
    fn default() -> Self {
        BoundaryOptions {
            rays: 720,
            step_mm: 0.5,
            tol_mm: 0.01,
            max_radius_mm: 1000.0,
            grid_res_mm: 1.0,
        }
    }
}

/// The cross-check of a traced boundary against the grid workspace mask.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoundaryCheck {
    /// Area of the grid mask, mm^2.
    pub grid_area_mm2: f64,
    /// Area of the polygon, mm^2.
    pub polygon_area_mm2: f64,
    /// Area of mask cells whose centre lies more than one cell beyond the polygon, mm^2.
    pub outside_area_mm2: f64,
}

/// An ordered closed polygon around the origin (counter-clockwise, vertex 0 on the +x axis,
/// the last vertex joined to the first).
#[derive(Debug, Clone, PartialEq)]
pub struct Boundary {
    /// Platform orientation of the workspace, rad.
    pub phi: f64,
    /// Vertices, mm.
    pub vertices: Vec<Vec2>,
    /// The grid cross-check (None for polygons not traced from a robot).
    pub check: Option<BoundaryCheck>,
}

impl Boundary {
    /// A polygon from vertices (ordered, closed implicitly), orientation `phi` rad.
    pub fn from_vertices(phi: f64, vertices: Vec<Vec2>) -> Boundary {
        Boundary {
            phi,
            vertices,
            check: None,
        }
    }

    /// Perimeter, mm.
    pub fn perimeter(&self) -> f64 {
        let n = self.vertices.len();
        (0..n)
            .map(|k| dist(self.vertices[k], self.vertices[(k + 1) % n]))
            .sum()
    }

    /// Enclosed area (shoelace), mm^2; positive for counter-clockwise vertices.
    pub fn area(&self) -> f64 {
        let n = self.vertices.len();
        0.5 * (0..n)
            .map(|k| {
                let (a, b) = (self.vertices[k], self.vertices[(k + 1) % n]);
                a[0] * b[1] - a[1] * b[0]
            })
            .sum::<f64>()
    }

    /// The polygon scaled about the origin by `s`.
    pub fn scaled(&self, s: f64) -> Boundary {
        Boundary {
            phi: self.phi,
            vertices: self.vertices.iter().map(|v| [s * v[0], s * v[1]]).collect(),
            check: None,
        }
    }

    /// `n` points evenly spaced by arc length along the polygon, the first at vertex 0, going
    /// in vertex order (counter-clockwise), spacing perimeter / n.
    pub fn points_by_arc_length(&self, n: usize) -> Vec<Vec2> {
        let nv = self.vertices.len();
        if n == 0 || nv == 0 {
            return Vec::new();
        }
        let spacing = self.perimeter() / n as f64;
        let mut out = Vec::with_capacity(n);
        // Walk the edges, placing point k at arc length k * spacing.
        let mut walked = 0.0;
        let mut edge = 0;
        for k in 0..n {
            let target = k as f64 * spacing;
            loop {
                let (a, b) = (self.vertices[edge % nv], self.vertices[(edge + 1) % nv]);
                let len = dist(a, b);
                if target <= walked + len || edge + 1 >= nv {
                    let u = if len > 0.0 {
                        ((target - walked) / len).clamp(0.0, 1.0)
                    } else {
                        0.0
                    };
                    out.push([a[0] + u * (b[0] - a[0]), a[1] + u * (b[1] - a[1])]);
                    break;
                }
                walked += len;
                edge += 1;
            }
        }
        out
    }

    /// Arc length from vertex 0 (counter-clockwise) of the point of the polygon nearest to
    /// `p`, mm.
    pub fn arc_length_of(&self, p: Vec2) -> f64 {
        let nv = self.vertices.len();
        let mut best = (f64::INFINITY, 0.0);
        let mut walked = 0.0;
        for k in 0..nv {
            let (a, b) = (self.vertices[k], self.vertices[(k + 1) % nv]);
            let ab = [b[0] - a[0], b[1] - a[1]];
            let len2 = ab[0] * ab[0] + ab[1] * ab[1];
            let u = if len2 > 0.0 {
                (((p[0] - a[0]) * ab[0] + (p[1] - a[1]) * ab[1]) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let q = [a[0] + u * ab[0], a[1] + u * ab[1]];
            let d = dist(p, q);
            if d < best.0 {
                best = (d, walked + u * len2.sqrt());
            }
            walked += len2.sqrt();
        }
        best.1
    }
}

fn dist(a: Vec2, b: Vec2) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// Traces the boundary of the translational workspace of `robot` at orientation `phi` (rad)
/// and cross-checks it with the grid mask (see the module documentation).
pub fn workspace_boundary(
    robot: &Robot,
    phi: f64,
    opt: &BoundaryOptions,
) -> Result<Boundary, DesignError> {
    let phi_deg = phi.to_degrees();
    let bad_option = |what: &'static str| DesignError::Option {
        option: what,
        why: "must be a positive finite number".into(),
    };
    if opt.rays < 3 {
        return Err(DesignError::Option {
            option: "boundary rays",
            why: format!("{} rays (at least 3)", opt.rays),
        });
    }
    for (what, v) in [
        ("boundary step_mm", opt.step_mm),
        ("boundary tol_mm", opt.tol_mm),
        ("boundary max_radius_mm", opt.max_radius_mm),
        ("boundary grid_res_mm", opt.grid_res_mm),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(bad_option(what));
        }
    }
    let ok = |r: f64, a: f64| feasible(robot, &Pose::new(r * a.cos(), r * a.sin(), phi));
    if !ok(0.0, 0.0) {
        return Err(DesignError::OriginOutside { phi_deg });
    }
    let mut vertices = Vec::with_capacity(opt.rays);
    for k in 0..opt.rays {
        let a = TAU * k as f64 / opt.rays as f64;
        let mut r_in = 0.0;
        let mut r_out = None;
        while r_in < opt.max_radius_mm {
            let r = r_in + opt.step_mm;
            if ok(r, a) {
                r_in = r;
            } else {
                r_out = Some(r);
                break;
            }
        }
        let Some(mut r_out) = r_out else {
            return Err(DesignError::Unbounded {
                phi_deg,
                angle_deg: a.to_degrees(),
                radius_mm: opt.max_radius_mm,
            });
        };
        while r_out - r_in > opt.tol_mm {
            let m = 0.5 * (r_in + r_out);
            if ok(m, a) {
                r_in = m;
            } else {
                r_out = m;
            }
        }
        // The last radius that passed: the vertex is inside (or on) the workspace.
        vertices.push([r_in * a.cos(), r_in * a.sin()]);
    }
    let mut b = Boundary::from_vertices(phi, vertices);
    b.check = Some(grid_check(robot, &b, opt));
    Ok(b)
}

/// Radius of the polygon along polar angle `a` (linear between the two neighbouring rays).
fn radius_at(b: &Boundary, a: f64) -> f64 {
    let n = b.vertices.len();
    let u = a.rem_euclid(TAU) / TAU * n as f64;
    let k = (u.floor() as usize).min(n - 1);
    let w = u - k as f64;
    let r = |v: Vec2| v[0].hypot(v[1]);
    (1.0 - w) * r(b.vertices[k]) + w * r(b.vertices[(k + 1) % n])
}

fn grid_check(robot: &Robot, b: &Boundary, opt: &BoundaryOptions) -> BoundaryCheck {
    let ws = grid_workspace(robot, b.phi, opt.grid_res_mm, &|_| {});
    let g = &ws.grid;
    let cell = g.res * g.res;
    let mut outside = 0.0;
    for j in 0..g.ny {
        for i in 0..g.nx {
            if ws.inside[j * g.nx + i] {
                let c = g.center(i, j);
                if c[0].hypot(c[1]) > radius_at(b, c[1].atan2(c[0])) + g.res {
                    outside += cell;
                }
            }
        }
    }
    BoundaryCheck {
        grid_area_mm2: ws.area(),
        polygon_area_mm2: b.area(),
        outside_area_mm2: outside,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> Boundary {
        Boundary::from_vertices(
            0.0,
            vec![
                [1.0, 0.0],
                [1.0, 1.0],
                [-1.0, 1.0],
                [-1.0, -1.0],
                [1.0, -1.0],
            ],
        )
    }

    #[test]
    fn a_square_has_its_perimeter_area_and_arc_length_points() {
        let b = square();
        assert!((b.perimeter() - 8.0).abs() < 1e-12);
        assert!((b.area() - 4.0).abs() < 1e-12);
        let p = b.points_by_arc_length(8);
        let want = [
            [1.0, 0.0],
            [1.0, 1.0],
            [0.0, 1.0],
            [-1.0, 1.0],
            [-1.0, 0.0],
            [-1.0, -1.0],
            [0.0, -1.0],
            [1.0, -1.0],
        ];
        for (a, w) in p.iter().zip(want) {
            assert!(dist(*a, w) < 1e-12, "{a:?} vs {w:?}");
        }
        for (k, q) in p.iter().enumerate() {
            assert!((b.arc_length_of(*q) - k as f64).abs() < 1e-12);
        }
        let s = b.scaled(0.5);
        assert!((s.perimeter() - 4.0).abs() < 1e-12);
    }

    #[test]
    fn the_nominal_workspace_boundary_matches_the_grid_mask() {
        let robot = Robot::nominal();
        let b = workspace_boundary(&robot, 0.0, &BoundaryOptions::default()).unwrap();
        let c = b.check.unwrap();
        // The polygon is within a few cells' worth of the 1 mm mask and nothing lies beyond it.
        assert!(
            (c.polygon_area_mm2 - c.grid_area_mm2).abs() < 0.01 * c.grid_area_mm2,
            "{c:?}"
        );
        assert!(c.outside_area_mm2 < 1e-9, "{c:?}");
        // geometry.md: x in [-86, 84], y in [-78, 90] mm
        let xmin = b
            .vertices
            .iter()
            .map(|v| v[0])
            .fold(f64::INFINITY, f64::min);
        let ymax = b
            .vertices
            .iter()
            .map(|v| v[1])
            .fold(f64::NEG_INFINITY, f64::max);
        assert!(
            (xmin + 86.0).abs() < 2.0 && (ymax - 90.0).abs() < 2.0,
            "{xmin} {ymax}"
        );
        assert!(b.vertices[0][1] == 0.0 && b.vertices[0][0] > 0.0);
    }
}
