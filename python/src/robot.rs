//! `pcr.Robot`: the constant-curvature model of a robot file, with batch IK, FK, Jacobians,
//! singularity measures and the workspace. Every row is what `pcr ik` / `pcr fk` compute for
//! it (`pcr_offline::kinematics_rows`).

use crate::arrays::{f64_n3, f64_n33, rows3, vec1};
use crate::errors::{err, invalid};
use numpy::{PyArray1, PyArray2, PyArray3, PyReadonlyArray2};
use pcr_kinematics::{workspace, Pose, Robot};
use pcr_offline::error::{ErrorKind, OfflineError};
use pcr_offline::kinematics_rows::{fk_row, ik_row, kappa_of_steps, status_code};
use pcr_robot::RobotConfig;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// The constant-curvature model of one robot (native part of `pcr.Robot`).
#[pyclass(name = "Robot", module = "pcr._pcr", frozen)]
pub struct PyRobot {
    /// The model.
    pub robot: Robot,
    /// The name it is reported by (file, or "nominal (built-in)").
    pub name: String,
}

impl PyRobot {
    /// The model of a configuration, or the CLI's `robot NAME: why` error.
    pub fn of_config(cfg: &RobotConfig, name: String) -> PyResult<PyRobot> {
        let robot = Robot::new(cfg)
            .map_err(|e| err(OfflineError::from(e).context(format!("robot {name}"))))?;
        Ok(PyRobot { robot, name })
    }

    /// The configuration.
    pub fn config(&self) -> &RobotConfig {
        self.robot.config()
    }
}

/// Rows of a batch and their status codes.
type WithStatus<'py, A> = (Bound<'py, A>, Bound<'py, PyArray1<u8>>);

type IkArrays<'py> = (
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<u8>>,
);

#[pymethods]
impl PyRobot {
    /// Loads a robot file (the shape of configs/robot.toml); a bad file names its key.
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<PyRobot> {
        let cfg = RobotConfig::load(&path).map_err(err)?;
        PyRobot::of_config(&cfg, path.display().to_string())
    }

    /// The built-in nominal robot (geometry.md; = configs/robot.toml).
    #[staticmethod]
    fn nominal() -> PyRobot {
        PyRobot {
            robot: Robot::nominal(),
            name: "nominal (built-in)".into(),
        }
    }

    /// A robot from the text of a robot file; `origin` names it in errors.
    #[staticmethod]
    #[pyo3(signature = (text, origin = "<string>"))]
    fn from_toml(text: &str, origin: &str) -> PyResult<PyRobot> {
        let cfg = RobotConfig::from_toml_str(text, origin).map_err(err)?;
        PyRobot::of_config(&cfg, origin.to_string())
    }

    /// The robot file's text.
    fn to_toml(&self) -> String {
        self.config().to_toml_string()
    }

    /// The name the robot is reported by.
    #[getter]
    fn name(&self) -> String {
        self.name.clone()
    }

    /// Motor steps per mm of tendon displacement are 1 / mm_per_step: per leg, mm.
    #[getter]
    fn mm_per_step(&self) -> [f64; 3] {
        std::array::from_fn(|i| self.robot.legs[i].mm_per_step)
    }

    /// The curvatures of the home pose (0, 0, 0), 1/mm.
    #[getter]
    fn home_kappa_per_mm(&self) -> [f64; 3] {
        self.robot.home_kappa
    }

    /// Batch IK of (N, 3) poses (x_mm, y_mm, phi_deg): curvatures (1/mm), tendon displacements
    /// (mm), motor steps, gamma and zeta (deg), each (N, 3) with NaN where the pose has no
    /// solution, and the status codes (index in `STATUSES`). The GIL is released.
    fn ik<'py>(
        &self,
        py: Python<'py>,
        poses: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<IkArrays<'py>> {
        let rows = rows3(&poses, "poses")?;
        let n = rows.len();
        let robot = &self.robot;
        let (kappa, dl, steps, gamma, zeta, status) = py.detach(|| {
            let nan = [f64::NAN; 3];
            let mut kappa = Vec::with_capacity(n);
            let mut dl = Vec::with_capacity(n);
            let mut steps = Vec::with_capacity(n);
            let mut gamma = Vec::with_capacity(n);
            let mut zeta = Vec::with_capacity(n);
            let mut status = Vec::with_capacity(n);
            for p in &rows {
                let r = ik_row(robot, &Pose::from_mm_deg(p[0], p[1], p[2]));
                match r.values {
                    Some(v) => {
                        kappa.push(v.kappa_per_mm);
                        dl.push(v.dl_mm);
                        steps.push(v.steps.map(|q| q as f64));
                        gamma.push(v.gamma_rad.map(f64::to_degrees));
                        zeta.push(v.zeta_rad.map(f64::to_degrees));
                    }
                    None => {
                        kappa.push(nan);
                        dl.push(nan);
                        steps.push(nan);
                        gamma.push(nan);
                        zeta.push(nan);
                    }
                }
                status.push(status_code(r.status));
            }
            (kappa, dl, steps, gamma, zeta, status)
        });
        Ok((
            f64_n3(py, kappa),
            f64_n3(py, dl),
            f64_n3(py, steps),
            f64_n3(py, gamma),
            f64_n3(py, zeta),
            vec1(py, status),
        ))
    }

    /// Batch FK of (N, 3) curvatures (1/mm), or of motor positions (steps) with
    /// `steps=True`: poses (N, 3: x_mm, y_mm, phi_deg; NaN where no pose closes the loops)
    /// and status codes. The GIL is released.
    #[pyo3(signature = (values, steps = false))]
    fn fk<'py>(
        &self,
        py: Python<'py>,
        values: PyReadonlyArray2<'py, f64>,
        steps: bool,
    ) -> PyResult<WithStatus<'py, PyArray2<f64>>> {
        let rows = rows3(&values, if steps { "steps" } else { "kappa_per_mm" })?;
        let robot = &self.robot;
        let (poses, status) = py.detach(|| {
            rows.iter()
                .map(|v| {
                    let kappa = if steps { kappa_of_steps(robot, v) } else { *v };
                    let r = fk_row(robot, &kappa);
                    (
                        r.pose.map_or([f64::NAN; 3], |p| [p.x, p.y, p.phi_deg()]),
                        status_code(r.status),
                    )
                })
                .unzip::<_, _, Vec<_>, Vec<_>>()
        });
        Ok((f64_n3(py, poses), vec1(py, status)))
    }

    /// Batch Jacobians at (N, 3) poses: d(x_mm, y_mm, phi_deg)/d(kappa_i, 1/mm), or with
    /// `wrt="steps"` d(x_mm, y_mm, phi_deg)/d(q_i, steps), (N, 3, 3) with NaN where the pose
    /// has no IK solution or A is singular; and status codes of the poses' IK.
    #[pyo3(signature = (poses, wrt = "kappa"))]
    fn jacobian<'py>(
        &self,
        py: Python<'py>,
        poses: PyReadonlyArray2<'py, f64>,
        wrt: &str,
    ) -> PyResult<WithStatus<'py, PyArray3<f64>>> {
        let by_steps = match wrt {
            "kappa" => false,
            "steps" => true,
            other => {
                return Err(invalid(format!(
                    "wrt = {other:?}: must be \"kappa\" or \"steps\""
                )))
            }
        };
        let rows = rows3(&poses, "poses")?;
        let robot = &self.robot;
        let (jac, status) = py.detach(|| {
            rows.iter()
                .map(|p| {
                    let pose = Pose::from_mm_deg(p[0], p[1], p[2]);
                    let r = ik_row(robot, &pose);
                    let j = r.values.and_then(|v| {
                        let k = v.kappa_per_mm;
                        if by_steps {
                            let q: [f64; 3] = std::array::from_fn(|i| {
                                robot.kappa_to_steps(i, k[i]).unwrap_or(f64::NAN)
                            });
                            robot.jacobian_steps(&pose, &k, &q)
                        } else {
                            robot.jacobian(&pose, &k)
                        }
                    });
                    let m = match j {
                        Some(j) => std::array::from_fn(|r| {
                            std::array::from_fn(|c| {
                                if r == 2 {
                                    j[(r, c)].to_degrees()
                                } else {
                                    j[(r, c)]
                                }
                            })
                        }),
                        None => [[f64::NAN; 3]; 3],
                    };
                    (m, status_code(r.status))
                })
                .unzip::<_, _, Vec<_>, Vec<_>>()
        });
        Ok((f64_n33(py, jac), vec1(py, status)))
    }

    /// Singularity measures at (N, 3) poses: the inverse condition number of the scaled A
    /// (parallel singularity), the smallest normalised |B_ii| (serial singularity) and their
    /// minimum (the measure compared with `limits.singularity_threshold`), each (N,), NaN
    /// where the pose has no IK solution; and the status codes.
    #[allow(clippy::type_complexity)]
    fn singularity<'py>(
        &self,
        py: Python<'py>,
        poses: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<(
        Bound<'py, PyArray1<f64>>,
        Bound<'py, PyArray1<f64>>,
        Bound<'py, PyArray1<f64>>,
        Bound<'py, PyArray1<u8>>,
    )> {
        let rows = rows3(&poses, "poses")?;
        let robot = &self.robot;
        let out: Vec<([f64; 3], u8)> = py.detach(|| {
            rows.iter()
                .map(|p| {
                    let pose = Pose::from_mm_deg(p[0], p[1], p[2]);
                    let r = ik_row(robot, &pose);
                    let c = r.values.map_or([f64::NAN; 3], |v| {
                        let c = robot.conditioning(&pose, &v.kappa_per_mm);
                        [c.a, c.b, c.value()]
                    });
                    (c, status_code(r.status))
                })
                .collect()
        });
        let col = |k: usize| vec1(py, out.iter().map(|o| o.0[k]).collect());
        Ok((
            col(0),
            col(1),
            col(2),
            vec1(py, out.iter().map(|o| o.1).collect()),
        ))
    }

    /// The singularity threshold of the robot file (dimensionless).
    #[getter]
    fn singularity_threshold(&self) -> f64 {
        self.robot.limits.singularity_threshold
    }

    /// The constant-orientation workspace at `phi_deg` by IK feasibility on a grid of `res_mm`
    /// (the reference method of `pcr workspace`): a dict with `area_mm2`, `bounds_mm` (xmin,
    /// xmax, ymin, ymax or None), `centroid_mm`, `x0_mm`, `y0_mm`, `res_mm`, `inside` (ny, nx
    /// booleans, row j at y0 + (j + 0.5) res) and `contour_mm` (segments, (M, 2, 2)). The GIL
    /// is released.
    #[pyo3(signature = (phi_deg = 0.0, res_mm = 1.0))]
    fn workspace<'py>(
        &self,
        py: Python<'py>,
        phi_deg: f64,
        res_mm: f64,
    ) -> PyResult<Bound<'py, PyDict>> {
        if !(0.05..=50.0).contains(&res_mm) {
            return Err(invalid(format!(
                "res_mm must be between 0.05 and 50 mm, got {res_mm}"
            )));
        }
        if !phi_deg.is_finite() {
            return Err(invalid(format!("phi_deg must be finite, got {phi_deg}")));
        }
        let robot = &self.robot;
        let ws =
            py.detach(|| workspace::grid_workspace(robot, phi_deg.to_radians(), res_mm, &|_| {}));
        let d = PyDict::new(py);
        d.set_item("phi_deg", phi_deg)?;
        d.set_item("area_mm2", ws.area())?;
        d.set_item("bounds_mm", ws.bounds())?;
        d.set_item("centroid_mm", ws.centroid())?;
        d.set_item("x0_mm", ws.grid.x0)?;
        d.set_item("y0_mm", ws.grid.y0)?;
        d.set_item("res_mm", ws.grid.res)?;
        let inside =
            numpy::ndarray::Array2::from_shape_vec((ws.grid.ny, ws.grid.nx), ws.inside.clone())
                .map_err(|e| err(OfflineError::new(ErrorKind::Kinematics, e.to_string())))?;
        d.set_item("inside", numpy::IntoPyArray::into_pyarray(inside, py))?;
        let segs: Vec<f64> = ws.contour().into_iter().flatten().flatten().collect();
        let m = segs.len() / 4;
        let contour = numpy::ndarray::Array3::from_shape_vec((m, 2, 2), segs)
            .map_err(|e| err(OfflineError::new(ErrorKind::Kinematics, e.to_string())))?;
        d.set_item("contour_mm", numpy::IntoPyArray::into_pyarray(contour, py))?;
        Ok(d)
    }

    fn __repr__(&self) -> String {
        format!("pcr.Robot({:?})", self.name)
    }
}
