//! The constant-orientation translational workspace, two ways.
//!
//! - [`grid_workspace`]: direct IK feasibility on a square grid (the reference): a cell is in the
//!   workspace when every leg has a valid root in the working mode and the configuration is not
//!   singular.
//! - [`alpha_workspace`]: the paper's method. Each leg is discretised over its joint space
//!   (bending angle in the bending range, passive joint angle gamma in the working mode's half of
//!   the joint range); every sample gives a platform centre for the fixed orientation, kept if
//!   the platform joint zeta is in range. The point cloud of each leg is triangulated (Delaunay,
//!   `spade`), triangles whose circumradius exceeds alpha form no part of the alpha shape, and the
//!   three legs' shapes are intersected on a raster.
//!
//! Both report the area in mm^2 and a contour; [`accuracy_map`] adds a local accuracy figure.

use crate::model::Robot;
use crate::pose::Pose;
use pcr_robot::{geometry as g, Vec2};
use spade::{DelaunayTriangulation, Point2, Triangulation};

/// A rectangular grid of cells of side `res` mm; cell (i, j) is centred at
/// (x0 + (i + 0.5) res, y0 + (j + 0.5) res).
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    /// Left edge, mm.
    pub x0: f64,
    /// Bottom edge, mm.
    pub y0: f64,
    /// Cell side, mm.
    pub res: f64,
    /// Cells along x.
    pub nx: usize,
    /// Cells along y.
    pub ny: usize,
}

impl Grid {
    /// A grid covering [xmin, xmax] x [ymin, ymax] with cells of `res` mm.
    pub fn covering(xmin: f64, xmax: f64, ymin: f64, ymax: f64, res: f64) -> Grid {
        let x0 = (xmin / res).floor() * res;
        let y0 = (ymin / res).floor() * res;
        Grid {
            x0,
            y0,
            res,
            nx: (((xmax - x0) / res).ceil() as usize).max(1),
            ny: (((ymax - y0) / res).ceil() as usize).max(1),
        }
    }

    /// Centre of cell (i, j), mm.
    #[inline]
    pub fn center(&self, i: usize, j: usize) -> Vec2 {
        [
            self.x0 + (i as f64 + 0.5) * self.res,
            self.y0 + (j as f64 + 0.5) * self.res,
        ]
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.nx * self.ny
    }

    /// Whether the grid has no cells.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A workspace as a set of grid cells.
#[derive(Debug, Clone)]
pub struct Workspace {
    /// Platform orientation, rad.
    pub phi: f64,
    /// The grid.
    pub grid: Grid,
    /// `inside[j * nx + i]` for cell (i, j).
    pub inside: Vec<bool>,
}

impl Workspace {
    /// Area, mm^2.
    pub fn area(&self) -> f64 {
        self.inside.iter().filter(|b| **b).count() as f64 * self.grid.res * self.grid.res
    }

    /// Bounding box (xmin, xmax, ymin, ymax) of the cells inside, mm, or None if empty.
    pub fn bounds(&self) -> Option<[f64; 4]> {
        let mut b = [
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        let h = 0.5 * self.grid.res;
        for j in 0..self.grid.ny {
            for i in 0..self.grid.nx {
                if self.inside[j * self.grid.nx + i] {
                    let c = self.grid.center(i, j);
                    b = [
                        b[0].min(c[0] - h),
                        b[1].max(c[0] + h),
                        b[2].min(c[1] - h),
                        b[3].max(c[1] + h),
                    ];
                }
            }
        }
        b[0].is_finite().then_some(b)
    }

    /// Area centroid, mm.
    pub fn centroid(&self) -> Option<Vec2> {
        let (mut sx, mut sy, mut n) = (0.0, 0.0, 0usize);
        for j in 0..self.grid.ny {
            for i in 0..self.grid.nx {
                if self.inside[j * self.grid.nx + i] {
                    let c = self.grid.center(i, j);
                    sx += c[0];
                    sy += c[1];
                    n += 1;
                }
            }
        }
        (n > 0).then(|| [sx / n as f64, sy / n as f64])
    }

    /// The boundary as line segments between cell corners (marching squares on the cell mask:
    /// every edge between an inside and an outside cell).
    pub fn contour(&self) -> Vec<[Vec2; 2]> {
        let gd = &self.grid;
        let at = |i: isize, j: isize| -> bool {
            i >= 0
                && j >= 0
                && (i as usize) < gd.nx
                && (j as usize) < gd.ny
                && self.inside[j as usize * gd.nx + i as usize]
        };
        let corner = |i: isize, j: isize| [gd.x0 + i as f64 * gd.res, gd.y0 + j as f64 * gd.res];
        let mut segs = Vec::new();
        for j in -1..=gd.ny as isize {
            for i in -1..=gd.nx as isize {
                let c = at(i, j);
                if c != at(i + 1, j) {
                    segs.push([corner(i + 1, j), corner(i + 1, j + 1)]);
                }
                if c != at(i, j + 1) {
                    segs.push([corner(i, j + 1), corner(i + 1, j + 1)]);
                }
            }
        }
        segs
    }
}

/// Whether the pose is in the workspace: IK valid in the working mode and not singular.
pub fn feasible(robot: &Robot, pose: &Pose) -> bool {
    match robot.ik(pose) {
        Ok(s) => robot.conditioning(pose, &s.kappa).value() >= robot.limits.singularity_threshold,
        Err(_) => false,
    }
}

/// The curvature each leg needs over the robot's workspace (its travel): at each orientation of
/// `phis` (rad), the feasible poses (IK valid in the working mode, not singular) on a grid of
/// `step_mm` covering a square of 1.2 times the base radius about the origin; per leg the
/// smallest and largest curvature (1/mm) of those poses. `None` when no pose is feasible.
///
/// A tendon map must be invertible over this range, or the robot has poses it can reach with
/// no motor position for them.
pub fn leg_travel(robot: &Robot, phis: &[f64], step_mm: f64) -> Option<[[f64; 2]; 3]> {
    let r = 0.6 * robot.legs.iter().map(|l| g::norm(l.b)).sum::<f64>() / 3.0;
    let grid = Grid::covering(-r, r, -r, r, step_mm.max(0.1));
    let mut out = [[f64::INFINITY, f64::NEG_INFINITY]; 3];
    let mut any = false;
    for &phi in phis {
        for j in 0..grid.ny {
            for i in 0..grid.nx {
                let c = grid.center(i, j);
                let pose = Pose::new(c[0], c[1], phi);
                let Ok(s) = robot.ik(&pose) else {
                    continue;
                };
                if robot.conditioning(&pose, &s.kappa).value() < robot.limits.singularity_threshold
                {
                    continue;
                }
                any = true;
                for (o, k) in out.iter_mut().zip(s.kappa) {
                    o[0] = o[0].min(k);
                    o[1] = o[1].max(k);
                }
            }
        }
    }
    any.then_some(out)
}

/// Largest distance of the platform centre from the origin that any leg could reach, mm.
fn reach(robot: &Robot) -> f64 {
    robot
        .legs
        .iter()
        .map(|l| g::norm(l.b) + l.l_c + l.l_ce + l.l_st + g::norm(l.p_e))
        .fold(0.0, f64::max)
}

fn evaluate(robot: &Robot, phi: f64, grid: &Grid, progress: &(dyn Fn(usize) + Sync)) -> Vec<bool> {
    let mut inside = vec![false; grid.len()];
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .clamp(1, 8);
    let rows_per = grid.ny.div_ceil(threads);
    std::thread::scope(|s| {
        for (t, chunk) in inside.chunks_mut(rows_per * grid.nx).enumerate() {
            s.spawn(move || {
                for (k, cell) in chunk.iter_mut().enumerate() {
                    let (i, j) = (k % grid.nx, t * rows_per + k / grid.nx);
                    let c = grid.center(i, j);
                    *cell = feasible(robot, &Pose::new(c[0], c[1], phi));
                    if i + 1 == grid.nx {
                        progress(1);
                    }
                }
            });
        }
    });
    inside
}

/// The workspace for orientation `phi` (rad) by IK feasibility on a grid of `res` mm. A coarse
/// pass (8 `res`, at most 5 mm) finds the region; the fine pass covers it with a margin.
/// `progress` is called with the number of fine rows finished.
pub fn grid_workspace(
    robot: &Robot,
    phi: f64,
    res: f64,
    progress: &(dyn Fn(usize) + Sync),
) -> Workspace {
    let r = reach(robot);
    let coarse_res = (8.0 * res).min(5.0).max(res);
    let coarse = Grid::covering(-r, r, -r, r, coarse_res);
    let ws = Workspace {
        phi,
        inside: evaluate(robot, phi, &coarse, &|_| {}),
        grid: coarse,
    };
    let Some(b) = ws.bounds() else {
        return Workspace {
            phi,
            grid: Grid::covering(0.0, res, 0.0, res, res),
            inside: vec![false],
        };
    };
    let m = 2.0 * coarse_res;
    let grid = Grid::covering(b[0] - m, b[1] + m, b[2] - m, b[3] + m, res);
    Workspace {
        phi,
        inside: evaluate(robot, phi, &grid, progress),
        grid,
    }
}

/// One leg's alpha shape: the triangles of its point cloud kept for the alpha value.
#[derive(Debug, Clone)]
pub struct LegShape {
    /// Kept triangles, mm.
    pub triangles: Vec<[Vec2; 3]>,
    /// Number of joint-space samples that gave a point.
    pub points: usize,
    /// Area of the alpha shape, mm^2.
    pub area: f64,
}

/// The workspace by the paper's method.
#[derive(Debug, Clone)]
pub struct AlphaWorkspace {
    /// Each leg's alpha shape.
    pub legs: [LegShape; 3],
    /// The intersection, rasterised on a grid of the requested resolution.
    pub workspace: Workspace,
}

/// Samples leg `i`'s joint space for orientation `phi`: platform centres, mm.
pub fn leg_point_cloud(robot: &Robot, i: usize, phi: f64, step_deg: f64) -> Vec<Vec2> {
    let leg = &robot.legs[i];
    let lim = &robot.limits;
    let pe = g::rot(phi, leg.p_e);
    let sign = robot.mode[i].sign();
    let (glo, ghi) = if sign < 0.0 {
        (lim.joint_min, 0.0)
    } else {
        (0.0, lim.joint_max)
    };
    let step = step_deg.to_radians();
    let nt = (2.0 * lim.bending_max / step).ceil() as usize;
    let ng = ((ghi - glo) / step).ceil() as usize;
    let mut pts = Vec::with_capacity((nt + 1) * (ng + 1));
    for a in 0..=nt {
        let theta = -lim.bending_max + 2.0 * lim.bending_max * a as f64 / nt as f64;
        let kappa = theta / leg.l_c;
        let m = leg.joint_m(kappa);
        let t = leg.tangent(kappa);
        for b in 0..=ng {
            let gamma = glo + (ghi - glo) * b as f64 / ng as f64;
            let u = g::rot(gamma, t);
            let p = g::add(m, g::scale(leg.l_st, u));
            let zeta = g::signed_angle(pe, g::scale(-1.0, u));
            if zeta >= lim.joint_min && zeta <= lim.joint_max {
                pts.push(g::sub(p, pe));
            }
        }
    }
    pts
}

fn alpha_shape(points: &[Vec2], alpha: f64) -> LegShape {
    let verts: Vec<Point2<f64>> = points.iter().map(|p| Point2::new(p[0], p[1])).collect();
    let n = verts.len();
    let Ok(tri) = DelaunayTriangulation::<Point2<f64>>::bulk_load(verts) else {
        return LegShape {
            triangles: Vec::new(),
            points: n,
            area: 0.0,
        };
    };
    let a2 = alpha * alpha;
    let mut triangles = Vec::new();
    let mut area = 0.0;
    for f in tri.inner_faces() {
        let (_, r2) = f.circumcircle();
        if r2 <= a2 {
            let p = f.positions();
            let t = [[p[0].x, p[0].y], [p[1].x, p[1].y], [p[2].x, p[2].y]];
            area += 0.5 * g::cross(g::sub(t[1], t[0]), g::sub(t[2], t[0])).abs();
            triangles.push(t);
        }
    }
    LegShape {
        triangles,
        points: n,
        area,
    }
}

fn rasterise(shape: &LegShape, grid: &Grid, mask: &mut [bool]) {
    for t in &shape.triangles {
        let xmin = t.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min);
        let xmax = t.iter().map(|p| p[0]).fold(f64::NEG_INFINITY, f64::max);
        let ymin = t.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min);
        let ymax = t.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max);
        let i0 = (((xmin - grid.x0) / grid.res - 0.5).ceil().max(0.0)) as usize;
        let j0 = (((ymin - grid.y0) / grid.res - 0.5).ceil().max(0.0)) as usize;
        let i1 = ((((xmax - grid.x0) / grid.res - 0.5).floor()) as isize).min(grid.nx as isize - 1);
        let j1 = ((((ymax - grid.y0) / grid.res - 0.5).floor()) as isize).min(grid.ny as isize - 1);
        let d = g::cross(g::sub(t[1], t[0]), g::sub(t[2], t[0]));
        if d == 0.0 || i1 < i0 as isize || j1 < j0 as isize {
            continue;
        }
        for j in j0..=j1 as usize {
            for i in i0..=i1 as usize {
                let c = grid.center(i, j);
                let w0 = g::cross(g::sub(t[1], c), g::sub(t[2], c)) / d;
                let w1 = g::cross(g::sub(t[2], c), g::sub(t[0], c)) / d;
                let w2 = 1.0 - w0 - w1;
                if w0 >= -1e-12 && w1 >= -1e-12 && w2 >= -1e-12 {
                    mask[j * grid.nx + i] = true;
                }
            }
        }
    }
}

/// The paper's method: per-leg joint-space sampling every `step_deg` degrees, alpha shapes
/// with `alpha` mm, intersection on a grid of `res` mm.
pub fn alpha_workspace(
    robot: &Robot,
    phi: f64,
    step_deg: f64,
    alpha: f64,
    res: f64,
) -> AlphaWorkspace {
    let legs: [LegShape; 3] = std::thread::scope(|s| {
        let h: Vec<_> = (0..3)
            .map(|i| s.spawn(move || alpha_shape(&leg_point_cloud(robot, i, phi, step_deg), alpha)))
            .collect();
        let v: Vec<LegShape> = h
            .into_iter()
            .map(|h| h.join().expect("alpha shape thread"))
            .collect();
        [v[0].clone(), v[1].clone(), v[2].clone()]
    });
    let mut b = [
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    for t in legs.iter().flat_map(|l| l.triangles.iter()).flatten() {
        b = [
            b[0].min(t[0]),
            b[1].max(t[0]),
            b[2].min(t[1]),
            b[3].max(t[1]),
        ];
    }
    if !b[0].is_finite() {
        b = [0.0, res, 0.0, res];
    }
    let grid = Grid::covering(b[0], b[1], b[2], b[3], res);
    let mut inside = vec![true; grid.len()];
    for leg in &legs {
        let mut m = vec![false; grid.len()];
        rasterise(leg, &grid, &mut m);
        for (a, b) in inside.iter_mut().zip(m) {
            *a &= b;
        }
    }
    AlphaWorkspace {
        legs,
        workspace: Workspace { phi, grid, inside },
    }
}

/// Local accuracy over a workspace: the largest platform position change (mm) that one motor
/// step on any combination of motors causes, max over dq in {-1, 0, 1}^3 of |J_q,xy dq|
/// (the paper's eq. 10 figure of merit). `None` for cells outside the workspace.
pub fn accuracy_map(robot: &Robot, ws: &Workspace) -> Vec<Option<f64>> {
    error_map(robot, ws, [1.0; 3])
}

/// The paper's eq. 10 over a workspace: the largest platform position error (mm) that
/// undetected motor motions of up to `steps[i]` steps per motor can cause,
/// max over |dq_i| <= steps_i of |J_q,xy dq|. `None` for cells outside the workspace.
pub fn error_map(robot: &Robot, ws: &Workspace, steps: [f64; 3]) -> Vec<Option<f64>> {
    let gd = &ws.grid;
    let mut out = vec![None; gd.len()];
    for j in 0..gd.ny {
        for i in 0..gd.nx {
            if !ws.inside[j * gd.nx + i] {
                continue;
            }
            let c = gd.center(i, j);
            let pose = Pose::new(c[0], c[1], ws.phi);
            out[j * gd.nx + i] = position_error_for_steps(robot, &pose, steps);
        }
    }
    out
}

/// The accuracy figure of [`accuracy_map`] at one pose, mm per step.
pub fn position_error_per_step(robot: &Robot, pose: &Pose) -> Option<f64> {
    position_error_for_steps(robot, pose, [1.0; 3])
}

/// The figure of [`error_map`] at one pose, mm.
pub fn position_error_for_steps(robot: &Robot, pose: &Pose, steps: [f64; 3]) -> Option<f64> {
    let s = robot.ik(pose).ok()?;
    let q: [f64; 3] = std::array::from_fn(|k| robot.kappa_to_steps(k, s.kappa[k]).unwrap_or(0.0));
    let j = robot.jacobian_steps(pose, &s.kappa, &q)?;
    // |J dq| is convex in dq: its maximum over the box is at a vertex (a sign pattern).
    let mut best = 0.0f64;
    for sx in [-1.0, 1.0] {
        for sy in [-1.0, 1.0] {
            for sz in [-1.0, 1.0] {
                let d = [sx * steps[0], sy * steps[1], sz * steps[2]];
                let dx = j[(0, 0)] * d[0] + j[(0, 1)] * d[1] + j[(0, 2)] * d[2];
                let dy = j[(1, 0)] * d[0] + j[(1, 1)] * d[1] + j[(1, 2)] * d[2];
                best = best.max(dx.hypot(dy));
            }
        }
    }
    Some(best)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn leg_travel_covers_the_workspace_poses() {
        let r = Robot::nominal();
        let phis = [-10f64.to_radians(), 0.0, 10f64.to_radians()];
        let t = leg_travel(&r, &phis, 4.0).unwrap();
        // The nominal legs bend from about -34 to +94 degrees over the workspace at these
        // orientations (an IK scan at 3 mm).
        for k in t {
            let (lo, hi) = ((k[0] * 125.0).to_degrees(), (k[1] * 125.0).to_degrees());
            assert!(
                lo < -25.0 && lo > -40.0 && hi > 80.0 && hi < 100.0,
                "{lo} {hi}"
            );
        }
        // Every check pose of geometry.md lies within it.
        for (x, y, phi) in [(0.0, 0.0, 0.0), (20.0, -10.0, 5.0), (-40.0, 30.0, -10.0)] {
            let s = r.ik(&Pose::from_mm_deg(x, y, phi)).unwrap();
            for (k, range) in s.kappa.iter().zip(t) {
                assert!(*k >= range[0] && *k <= range[1]);
            }
        }
    }

    #[test]
    fn grid_and_alpha_agree_on_the_nominal_robot() {
        let r = Robot::nominal();
        let ws = grid_workspace(&r, 0.0, 2.0, &|_| {});
        let b = ws.bounds().unwrap();
        // geometry.md: x in [-86, 84], y in [-78, 90] roughly
        assert!(
            (b[0] + 86.0).abs() < 4.0 && (b[1] - 84.0).abs() < 4.0,
            "{b:?}"
        );
        assert!(
            (b[2] + 78.0).abs() < 4.0 && (b[3] - 90.0).abs() < 4.0,
            "{b:?}"
        );
        let aw = alpha_workspace(&r, 0.0, 1.0, 5.0, 2.0);
        let (a1, a2) = (ws.area(), aw.workspace.area());
        assert!((a1 - a2).abs() < 0.03 * a1, "grid {a1} vs alpha {a2}");
    }
}
