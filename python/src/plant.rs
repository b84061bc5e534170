//! `pcr.Plant`: the simulated plant (`pcr-plant`): a plant file on a robot's drawing, static
//! equilibria for motor positions (`pcr plant pose`) and a setpoint series through the
//! time-stepped plant as a recording (`pcr plant run`, through `pcr_offline::plant_run`).

use crate::arrays::{f64_n3, rows3};
use crate::errors::{err, invalid};
use crate::recording::PyRecording;
use crate::robot::PyRobot;
use numpy::{PyReadonlyArray1, PyReadonlyArray2};
use pcr_offline::clock::utc_now;
use pcr_offline::plant_run::{self, PASS_THROUGH};
use pcr_offline::OfflineError;
use pcr_plant::{Plant, PlantConfig, TruthModel};
use pcr_recording::{Recording, RecordingWriter, Row};
use pcr_robot::RobotConfig;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// One static equilibrium: pose (x mm, y mm, phi deg), M_i (mm), axial link forces (N).
type PoseRow = ([f64; 3], [f64; 6], [f64; 3]);

/// A plant configuration on a robot's drawing (native part of `pcr.Plant`).
#[pyclass(name = "Plant", module = "pcr._pcr")]
pub struct PyPlant {
    robot: RobotConfig,
    robot_name: String,
    cfg: PlantConfig,
    name: String,
}

fn drawing(robot: Option<PyRef<'_, PyRobot>>) -> (RobotConfig, String) {
    match robot {
        Some(r) => (r.config().clone(), r.name.clone()),
        None => (RobotConfig::nominal(), "nominal (built-in)".into()),
    }
}

#[pymethods]
impl PyPlant {
    /// Loads a plant file (effects; the shape of configs/plant.toml) on `robot`'s drawing
    /// (default: the nominal robot); a bad file names its key.
    #[staticmethod]
    #[pyo3(signature = (path, robot = None))]
    fn load(path: PathBuf, robot: Option<PyRef<'_, PyRobot>>) -> PyResult<PyPlant> {
        let cfg = PlantConfig::load(&path).map_err(err)?;
        let (robot, robot_name) = drawing(robot);
        Ok(PyPlant {
            robot,
            robot_name,
            cfg,
            name: path.display().to_string(),
        })
    }

    /// The built-in prototype-like plant (= configs/plant.toml).
    #[staticmethod]
    #[pyo3(signature = (robot = None))]
    fn prototype(robot: Option<PyRef<'_, PyRobot>>) -> PyPlant {
        let (robot, robot_name) = drawing(robot);
        PyPlant {
            robot,
            robot_name,
            cfg: PlantConfig::prototype(),
            name: "prototype (built-in)".into(),
        }
    }

    /// The built-in ideal plant (no effects; = configs/plant-ideal.toml).
    #[staticmethod]
    #[pyo3(signature = (robot = None))]
    fn ideal(robot: Option<PyRef<'_, PyRobot>>) -> PyPlant {
        let (robot, robot_name) = drawing(robot);
        PyPlant {
            robot,
            robot_name,
            cfg: PlantConfig::ideal(),
            name: "ideal (built-in)".into(),
        }
    }

    /// Seed of the plant's random effects (capture noise, missed steps, dropouts).
    #[getter]
    fn get_seed(&self) -> u64 {
        self.cfg.seed
    }

    #[setter]
    fn set_seed(&mut self, seed: u64) {
        self.cfg.seed = seed;
    }

    /// The plant file's name.
    #[getter]
    fn name(&self) -> String {
        self.name.clone()
    }

    /// The plant file's text.
    fn to_toml(&self) -> String {
        self.cfg.to_toml_string()
    }

    /// Static equilibria for (N, 3) motor positions (steps), effects without history only
    /// (`pcr plant pose`): a dict with `pose` (N, 3: x_mm, y_mm, phi_deg), `m_mm` (N, 6: m1x,
    /// m1y, .., m3y) and `link_force_n` (N, 3, axial, compression positive). The GIL is
    /// released.
    fn pose<'py>(
        &self,
        py: Python<'py>,
        steps: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let rows = rows3(&steps, "steps")?;
        let (robot, cfg) = (&self.robot, &self.cfg);
        let out = py
            .detach(|| -> Result<Vec<PoseRow>, OfflineError> {
                let truth = TruthModel::new(robot, cfg).map_err(|e| {
                    OfflineError::from(e).context("the plant has no home equilibrium")
                })?;
                rows.iter()
                    .enumerate()
                    .map(|(k, q)| {
                        let eq = truth.solve_steps(q).map_err(|e| {
                            OfflineError::from(e)
                                .context(format!("row {k}: no static equilibrium for q = {q:?}"))
                        })?;
                        Ok((
                            [eq.pose[0], eq.pose[1], eq.pose[2].to_degrees()],
                            [
                                eq.m[0][0], eq.m[0][1], eq.m[1][0], eq.m[1][1], eq.m[2][0],
                                eq.m[2][1],
                            ],
                            eq.lambda,
                        ))
                    })
                    .collect()
            })
            .map_err(err)?;
        let d = PyDict::new(py);
        d.set_item("pose", f64_n3(py, out.iter().map(|o| o.0).collect()))?;
        let m: Vec<f64> = out.iter().flat_map(|o| o.1).collect();
        d.set_item(
            "m_mm",
            numpy::IntoPyArray::into_pyarray(
                numpy::ndarray::Array2::from_shape_vec((out.len(), 6), m).expect("n rows of 6"),
                py,
            ),
        )?;
        d.set_item(
            "link_force_n",
            f64_n3(py, out.iter().map(|o| o.2).collect()),
        )?;
        Ok(d)
    }

    /// Runs setpoints through the time-stepped plant (`pcr plant run`): `t_s` (N,) strictly
    /// increasing, `q` (N, 3) whole steps, `columns` optional pass-through columns (xp_mm,
    /// yp_mm, phip_deg, pose_id, rep, settled; NaN = empty). Returns the recording with the
    /// measured pose and the true state in extra columns. The GIL is released.
    #[pyo3(signature = (t_s, q, columns = Vec::new(), capture_frame = false, stop_on_fault = false))]
    fn run(
        &self,
        py: Python<'_>,
        t_s: PyReadonlyArray1<'_, f64>,
        q: PyReadonlyArray2<'_, f64>,
        columns: Vec<(String, PyReadonlyArray1<'_, f64>)>,
        capture_frame: bool,
        stop_on_fault: bool,
    ) -> PyResult<PyRecording> {
        let t = t_s.as_array().to_vec();
        let q = rows3(&q, "q")?;
        if q.len() != t.len() {
            return Err(invalid(format!(
                "t_s has {} rows and q {}: they must match",
                t.len(),
                q.len()
            )));
        }
        let mut setpoints: Vec<Row> = Vec::with_capacity(t.len());
        for (k, (t, q)) in t.iter().zip(&q).enumerate() {
            let mut qi = [0i32; 3];
            for i in 0..3 {
                if q[i].fract() != 0.0 || q[i].abs() > 1e9 {
                    return Err(invalid(format!(
                        "setpoint {k}, column `q{}`: {} is not a whole number of steps",
                        i + 1,
                        q[i]
                    )));
                }
                qi[i] = q[i] as i32;
            }
            setpoints.push(Row::new(*t, qi));
        }
        for (name, a) in &columns {
            let Some(k) = PASS_THROUGH.iter().position(|c| c == name) else {
                return Err(invalid(format!(
                    "column `{name}` is not passed through (known: {})",
                    PASS_THROUGH.join(", ")
                )));
            };
            let a = a.as_array();
            if a.len() != setpoints.len() {
                return Err(invalid(format!(
                    "column `{name}` has {} rows, t_s {}",
                    a.len(),
                    setpoints.len()
                )));
            }
            for (i, v) in a.iter().enumerate() {
                if v.is_nan() {
                    continue;
                }
                let whole = || -> PyResult<u64> {
                    if v.fract() != 0.0 || *v < 0.0 || (k == 5 && *v > 1.0) {
                        return Err(invalid(format!(
                            "setpoint {i}, column `{name}`: {v} is not a valid value"
                        )));
                    }
                    Ok(*v as u64)
                };
                let row = &mut setpoints[i];
                match k {
                    0..=2 => row.planned[k] = Some(*v),
                    3 => row.pose_id = Some(whole()?),
                    4 => row.rep = Some(whole()?),
                    _ => row.settled = Some(whole()? == 1),
                }
            }
        }
        let names: Vec<String> = columns.iter().map(|c| c.0.clone()).collect();
        let (robot, cfg) = (&self.robot, &self.cfg);
        let opts = plant_run::RunOptions {
            capture_frame,
            stop_on_fault,
        };
        let meta = plant_run::metadata(
            &self.robot_name,
            &self.name,
            cfg.seed,
            opts,
            "<array>",
            plant_run::command_delay_s(setpoints.iter().map(|s| s.t_s), cfg.simulation.cycle_s),
            &utc_now(),
        );
        let rec = py
            .detach(|| -> Result<Recording, OfflineError> {
                let at = |k: usize| format!("setpoint {k}");
                plant_run::check_setpoints(&setpoints, &at)?;
                let mut plant = Plant::new(robot, cfg)
                    .map_err(|e| OfflineError::from(e).context("cannot build the plant"))?;
                let known = plant_run::known_columns(&|c| names.iter().any(|n| n == c));
                let mut w = RecordingWriter::new(Vec::new(), &meta, &known, &plant_run::RUN_EXTRA)?;
                plant_run::run_setpoints(
                    &mut plant,
                    &setpoints,
                    opts,
                    &at,
                    &mut |c: plant_run::Cycle<'_>| {
                        w.write_row(c.row, c.extra).map_err(OfflineError::from)
                    },
                )?;
                let buf = w.into_inner()?;
                Ok(Recording::read(&buf[..], "<plant run>")?)
            })
            .map_err(err)?;
        Ok(PyRecording {
            rec,
            origin: "<plant run>".into(),
        })
    }

    fn __repr__(&self) -> String {
        format!("pcr.Plant({:?}, robot={:?})", self.name, self.robot_name)
    }
}
