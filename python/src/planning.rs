//! `pcr.plan`: the paper's paths, program files and joint moves as the chain's 20 ms
//! setpoints (`pcr plan`, through `pcr_offline::plan_request`), and `pcr.profile`: the
//! jerk-limited profiler on one multi-DoF case (`pcr profile`'s solver).

use crate::arrays::{f64_n3, i64_n3, vec1};
use crate::errors::{err, invalid};
use crate::robot::PyRobot;
use pcr_kinematics::Pose;
use pcr_offline::error::{ErrorKind, OfflineError};
use pcr_offline::plan_request::{self, PlanSettings, Shape};
use pcr_planner::profiler::{
    calculate, ControlInterface, Input, Limits, State, Synchronization, MAX_DOFS,
};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// A required value of the request dict.
fn get<'py, T: FromPyObjectOwned<'py>>(d: &Bound<'py, PyDict>, key: &str) -> PyResult<T> {
    match d.get_item(key)? {
        Some(v) => v.extract::<T>().map_err(|e| {
            let e: PyErr = e.into();
            invalid(format!("{key}: {e}"))
        }),
        None => Err(invalid(format!("missing argument `{key}`"))),
    }
}

/// A three-number value (pose or steps).
fn three(d: &Bound<'_, PyDict>, key: &str) -> PyResult<[f64; 3]> {
    let v: Vec<f64> = get(d, key)?;
    <[f64; 3]>::try_from(v.as_slice())
        .map_err(|_| invalid(format!("{key} must be three numbers, got {}", v.len())))
}

/// Plans a request (`kind`: circle, square, line, paper, program or joint; `args` holds the
/// shape's and the settings' keyword arguments, units in their names) with the robot's model
/// (the GIL is released). Returns a dict of arrays: t_s, pose (N, 3: xp_mm, yp_mm, phip_deg),
/// speed_mm_s, kappa_per_mm (N, 3), q (N, 3 steps), speed_limit_mm_s, and `moves`.
#[pyfunction]
pub fn plan<'py>(
    py: Python<'py>,
    robot: PyRef<'_, PyRobot>,
    kind: &str,
    args: &Bound<'py, PyDict>,
) -> PyResult<Bound<'py, PyDict>> {
    let shape = match kind {
        "circle" => Shape::Circle {
            radius_mm: get(args, "radius_mm")?,
            speed_mm_s: get(args, "speed_mm_s")?,
            centre_mm: get(args, "centre_mm")?,
            phi_deg: get(args, "phi_deg")?,
            start_deg: get(args, "start_deg")?,
            cw: get(args, "cw")?,
        },
        "square" => Shape::Square {
            side_mm: get(args, "side_mm")?,
            speed_mm_s: get(args, "speed_mm_s")?,
            centre_mm: get(args, "centre_mm")?,
            phi_deg: get(args, "phi_deg")?,
            blend_radius_mm: get(args, "blend_radius_mm")?,
        },
        "line" => {
            let to = three(args, "to")?;
            Shape::Line {
                to: Pose::from_mm_deg(to[0], to[1], to[2]),
                speed_mm_s: get(args, "speed_mm_s")?,
            }
        }
        "paper" => Shape::Paper {
            speed_mm_s: get(args, "speed_mm_s")?,
        },
        "program" => Shape::Program {
            file: get::<std::path::PathBuf>(args, "file")?
                .display()
                .to_string(),
            joint_amax: get(args, "joint_amax")?,
            joint_jmax: get(args, "joint_jmax")?,
        },
        "joint" => Shape::Joint {
            steps: three(args, "steps")?,
            from_steps: match args.get_item("from_steps")? {
                Some(v) if !v.is_none() => Some(three(args, "from_steps")?),
                _ => None,
            },
            joint_amax: get(args, "joint_amax")?,
            joint_jmax: get(args, "joint_jmax")?,
        },
        other => return Err(invalid(format!("unknown plan kind {other:?}"))),
    };
    let from = three(args, "start")?;
    if from.iter().any(|v| !v.is_finite()) {
        return Err(invalid(
            "start must be three finite numbers x_mm, y_mm, phi_deg",
        ));
    }
    let settings = PlanSettings {
        from: Pose::from_mm_deg(from[0], from[1], from[2]),
        amax: get(args, "amax")?,
        jmax: get(args, "jmax")?,
        pause_at: get(args, "pause_at")?,
        resume_at: get(args, "resume_at")?,
        stop_at: get(args, "stop_at")?,
        singularity_margin: get(args, "singularity_margin")?,
        rate_fraction: get(args, "rate_fraction")?,
    };
    let r = &robot.robot;
    let p = py
        .detach(|| plan_request::plan(r, &shape, &settings))
        .map_err(err)?;
    let d = PyDict::new(py);
    d.set_item("t_s", vec1(py, p.rows.iter().map(|r| r.t_s).collect()))?;
    d.set_item(
        "pose",
        f64_n3(
            py,
            p.rows
                .iter()
                .map(|r| [r.pose.x, r.pose.y, r.pose.phi.to_degrees()])
                .collect(),
        ),
    )?;
    d.set_item(
        "speed_mm_s",
        vec1(py, p.rows.iter().map(|r| r.speed_mm_s).collect()),
    )?;
    d.set_item(
        "kappa_per_mm",
        f64_n3(py, p.rows.iter().map(|r| r.kappa_per_mm).collect()),
    )?;
    d.set_item("q", i64_n3(py, p.rows.iter().map(|r| r.q).collect()))?;
    d.set_item("speed_limit_mm_s", vec1(py, p.speed_limits))?;
    d.set_item("moves", p.moves)?;
    Ok(d)
}

/// One jerk-limited profiling case of n <= 8 degrees of freedom (the solver of
/// `pcr profile`): current and target position, velocity and acceleration, limits (vmin and
/// amin default to -vmax and -amax), synchronisation (time, phase or none), control interface
/// (position or velocity), an optional minimum duration (s), sampled every `dt_s`. Returns a
/// dict: duration_s, t_s (K,), p, v, a (K, n) and the final state. A case the profiler cannot
/// solve raises `pcr.PlanningError`.
#[pyfunction]
#[pyo3(signature = (current, target, vmax, amax, jmax, vmin = None, amin = None, synchronization = "time", control_interface = "position", minimum_duration_s = None, dt_s = 0.02))]
#[allow(clippy::too_many_arguments)]
pub fn profile<'py>(
    py: Python<'py>,
    current: [Vec<f64>; 3],
    target: [Vec<f64>; 3],
    vmax: Vec<f64>,
    amax: Vec<f64>,
    jmax: Vec<f64>,
    vmin: Option<Vec<f64>>,
    amin: Option<Vec<f64>>,
    synchronization: &str,
    control_interface: &str,
    minimum_duration_s: Option<f64>,
    dt_s: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let n = vmax.len();
    if n == 0 || n > MAX_DOFS {
        return Err(invalid(format!(
            "{n} degrees of freedom: must be 1..={MAX_DOFS}"
        )));
    }
    let vmin = vmin.unwrap_or_else(|| vmax.iter().map(|v| -v).collect());
    let amin = amin.unwrap_or_else(|| amax.iter().map(|v| -v).collect());
    for (name, v) in [
        ("current p", &current[0]),
        ("current v", &current[1]),
        ("current a", &current[2]),
        ("target p", &target[0]),
        ("target v", &target[1]),
        ("target a", &target[2]),
        ("vmax", &vmax),
        ("vmin", &vmin),
        ("amax", &amax),
        ("amin", &amin),
        ("jmax", &jmax),
    ] {
        if v.len() != n {
            return Err(invalid(format!(
                "{name} has {} entries, expected {n} (the degrees of freedom of vmax)",
                v.len()
            )));
        }
    }
    if !(dt_s.is_finite() && dt_s > 0.0) {
        return Err(invalid(format!("dt_s = {dt_s}: must be > 0")));
    }
    let mut input = Input::new(n);
    input.synchronization = match synchronization {
        "time" => Synchronization::Time,
        "phase" => Synchronization::Phase,
        "none" => Synchronization::None,
        other => {
            return Err(invalid(format!(
                "synchronization = {other:?}: must be \"time\", \"phase\" or \"none\""
            )))
        }
    };
    input.control_interface = match control_interface {
        "position" => ControlInterface::Position,
        "velocity" => ControlInterface::Velocity,
        other => {
            return Err(invalid(format!(
                "control_interface = {other:?}: must be \"position\" or \"velocity\""
            )))
        }
    };
    for i in 0..n {
        input.current[i] = State::new(current[0][i], current[1][i], current[2][i]);
        input.target[i] = State::new(target[0][i], target[1][i], target[2][i]);
        input.limits[i] = Limits {
            vmax: vmax[i],
            vmin: vmin[i],
            amax: amax[i],
            amin: amin[i],
            jmax: jmax[i],
        };
    }
    input.minimum_duration = minimum_duration_s;
    let traj = py
        .detach(|| calculate(&input))
        .map_err(|e| err(OfflineError::new(ErrorKind::Planning, e.to_string())))?;
    let d = traj.duration();
    let k_max = (d / dt_s).floor() as usize;
    if k_max > 10_000_000 {
        return Err(invalid(format!(
            "{} samples of {dt_s} s: too many",
            k_max + 1
        )));
    }
    let mut buf = [State::default(); MAX_DOFS];
    let (mut t, mut p, mut v, mut a) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for k in 0..=k_max {
        let tk = k as f64 * dt_s;
        traj.at(tk, &mut buf[..n]);
        t.push(tk);
        p.extend(buf[..n].iter().map(|s| s.p));
        v.extend(buf[..n].iter().map(|s| s.v));
        a.extend(buf[..n].iter().map(|s| s.a));
    }
    traj.at(d, &mut buf[..n]);
    let shape = |x: Vec<f64>| {
        numpy::IntoPyArray::into_pyarray(
            numpy::ndarray::Array2::from_shape_vec((k_max + 1, n), x).expect("k rows of n"),
            py,
        )
    };
    let out = PyDict::new(py);
    out.set_item("duration_s", d)?;
    out.set_item("t_s", vec1(py, t))?;
    out.set_item("p", shape(p))?;
    out.set_item("v", shape(v))?;
    out.set_item("a", shape(a))?;
    out.set_item("final_p", buf[..n].iter().map(|s| s.p).collect::<Vec<_>>())?;
    out.set_item("final_v", buf[..n].iter().map(|s| s.v).collect::<Vec<_>>())?;
    out.set_item("final_a", buf[..n].iter().map(|s| s.a).collect::<Vec<_>>())?;
    Ok(out)
}
