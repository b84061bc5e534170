//! The program file of `pcr plan program` and of the supervisor's `ctl run program`: a TOML list of segments (lines, arcs, dwells, joint
//! moves) with their limits. Unknown keys are rejected naming the file and the key; bad values
//! name the file and the segment index (`segment[i]`, 0-based, as in the file's array).
//!
//! ```toml
//! [limits]                 # path limits (combined metric)
//! speed = 40.0             # mm/s (required)
//! acceleration = 200.0     # mm/s^2 (default: --amax), also the centripetal limit on arcs
//! jerk = 2000.0            # mm/s^3 (default: --jmax)
//! blend_radius = 5.0       # mm, rounds every corner between two lines (default 0: stop)
//! rotation_radius = 50.0   # mm/rad of the combined metric (default 50)
//!
//! [joint_limits]           # joint moves, per motor (step rate from the robot config)
//! acceleration = 2000.0    # steps/s^2
//! jerk = 20000.0           # steps/s^3
//!
//! [[segment]]
//! type = "line"
//! to = [20.0, -15.0]       # x mm, y mm[, phi deg]; phi unchanged if omitted
//! speed = 20.0             # optional own speed limit, mm/s
//! blend_radius = 3.0       # optional, the corner at the end of this line
//!
//! [[segment]]
//! type = "arc"
//! center = [20.0, 0.0]     # mm; the radius is the distance from the current point
//! sweep_deg = 180.0        # positive: counter-clockwise
//! phi_deg = 0.0            # optional end orientation
//!
//! [[segment]]
//! type = "dwell"
//! seconds = 0.5
//!
//! [[segment]]
//! type = "joint"
//! steps = [250, 150, 176]  # target motor positions
//! ```

use toml::{Table, Value};

/// Why a program file cannot be used. The message names the file, and the key or segment
/// (`segment[i]`, 0-based) that is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProgramError {
    /// The file cannot be read.
    #[error("cannot read {file}: {why}")]
    Read {
        /// The file.
        file: String,
        /// The I/O error.
        why: String,
    },
    /// The file is not a valid program (the message names the file, key and segment).
    #[error("{0}")]
    Invalid(String),
}

type Result<T> = std::result::Result<T, ProgramError>;

macro_rules! invalid {
    ($($t:tt)*) => { ProgramError::Invalid(format!($($t)*)) };
}

macro_rules! bail {
    ($($t:tt)*) => { return Err(invalid!($($t)*)) };
}

/// Limits of the path segments.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathLimits {
    /// Speed, mm/s.
    pub speed: f64,
    /// Acceleration (tangential and centripetal), mm/s^2.
    pub acceleration: f64,
    /// Jerk, mm/s^3.
    pub jerk: f64,
    /// Default corner blend radius, mm (0: sharp corners).
    pub blend_radius: f64,
    /// Rotation radius of the combined metric, mm/rad.
    pub rotation_radius: f64,
}

/// Per-motor limits of the joint moves (the step rate comes from the robot configuration).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointSettings {
    /// Acceleration, steps/s^2.
    pub acceleration: f64,
    /// Jerk, steps/s^3.
    pub jerk: f64,
}

/// One segment of the program.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Step {
    /// Line to (x mm, y mm, phi rad; None keeps the orientation).
    Line {
        /// Target x, y in mm.
        to: [f64; 2],
        /// Target orientation in rad.
        phi: Option<f64>,
        /// Own speed limit, mm/s.
        speed: Option<f64>,
        /// Blend radius of the corner at the end, mm.
        blend_radius: Option<f64>,
    },
    /// Arc around a centre.
    Arc {
        /// Centre x, y in mm.
        center: [f64; 2],
        /// Signed sweep, rad.
        sweep: f64,
        /// End orientation, rad.
        phi: Option<f64>,
        /// Own speed limit, mm/s.
        speed: Option<f64>,
    },
    /// Hold the pose.
    Dwell {
        /// Duration, s.
        seconds: f64,
    },
    /// Joint-space move to motor steps.
    Joint {
        /// Target steps.
        steps: [i64; 3],
    },
}

impl Step {
    /// The segment type as written in the file.
    pub fn kind(&self) -> &'static str {
        match self {
            Step::Line { .. } => "line",
            Step::Arc { .. } => "arc",
            Step::Dwell { .. } => "dwell",
            Step::Joint { .. } => "joint",
        }
    }
}

/// A parsed program.
#[derive(Clone, Debug, PartialEq)]
pub struct Program {
    /// Path limits.
    pub limits: PathLimits,
    /// Joint-move limits.
    pub joint: JointSettings,
    /// The segments in order.
    pub segments: Vec<Step>,
}

/// Defaults for keys the file may omit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Defaults {
    /// Path acceleration, mm/s^2.
    pub acceleration: f64,
    /// Path jerk, mm/s^3.
    pub jerk: f64,
    /// Joint acceleration, steps/s^2.
    pub joint_acceleration: f64,
    /// Joint jerk, steps/s^3.
    pub joint_jerk: f64,
}

impl Default for Defaults {
    /// The chain's defaults: 200 mm/s^2, 2000 mm/s^3, 2000 steps/s^2, 20000 steps/s^3.
    fn default() -> Self {
        Defaults {
            acceleration: 200.0,
            jerk: 2000.0,
            joint_acceleration: 2000.0,
            joint_jerk: 20000.0,
        }
    }
}

fn number(v: &Value) -> Option<f64> {
    match v {
        Value::Float(f) => Some(*f),
        Value::Integer(i) => Some(*i as f64),
        _ => None,
    }
}

fn check_keys(file: &str, prefix: &str, t: &Table, allowed: &[&str]) -> Result<()> {
    for k in t.keys() {
        if !allowed.contains(&k.as_str()) {
            bail!(
                "{file}: unknown key `{prefix}{k}` (expected one of: {})",
                allowed.join(", ")
            );
        }
    }
    Ok(())
}

/// A positive (or, with `zero_ok`, non-negative) finite number; `what` names where it is.
fn positive(v: &Value, what: &str, zero_ok: bool) -> Result<f64> {
    let x = number(v).ok_or_else(|| invalid!("{what} must be a number (got {v})"))?;
    if !x.is_finite() || x < 0.0 || (x == 0.0 && !zero_ok) {
        bail!(
            "{what} must be a finite number {} (got {x})",
            if zero_ok { ">= 0" } else { "> 0" }
        );
    }
    Ok(x)
}

fn finite_array(v: &Value, what: &str, lens: &[usize]) -> Result<Vec<f64>> {
    let a = v
        .as_array()
        .ok_or_else(|| invalid!("{what} must be an array of numbers (got {v})"))?;
    let out: Vec<f64> = a
        .iter()
        .map(|x| number(x).filter(|f| f.is_finite()))
        .collect::<Option<_>>()
        .ok_or_else(|| invalid!("{what} must hold finite numbers (got {v})"))?;
    if !lens.contains(&out.len()) {
        bail!(
            "{what} must have {} entries (got {})",
            lens.iter()
                .map(|l| l.to_string())
                .collect::<Vec<_>>()
                .join(" or "),
            out.len()
        );
    }
    Ok(out)
}

/// Reads and validates a program file.
pub fn load(file: &str, d: &Defaults) -> Result<Program> {
    let text = std::fs::read_to_string(file).map_err(|e| ProgramError::Read {
        file: file.to_string(),
        why: e.to_string(),
    })?;
    parse(&text, file, d)
}

/// Parses a program from TOML text; `file` names it in errors.
pub fn parse(text: &str, file: &str, d: &Defaults) -> Result<Program> {
    let root: Table = text
        .parse()
        .map_err(|e| invalid!("{file}: not a valid TOML file: {e}"))?;
    check_keys(file, "", &root, &["limits", "joint_limits", "segment"])?;
    let table = |k: &str| -> Result<Table> {
        match root.get(k) {
            None => Ok(Table::new()),
            Some(Value::Table(t)) => Ok(t.clone()),
            Some(v) => bail!("{file}: `{k}` must be a table (got {v})"),
        }
    };
    let lt = table("limits")?;
    check_keys(
        file,
        "limits.",
        &lt,
        &[
            "speed",
            "acceleration",
            "jerk",
            "blend_radius",
            "rotation_radius",
        ],
    )?;
    let lim = |k: &str, default: Option<f64>, zero_ok: bool| -> Result<f64> {
        match lt.get(k) {
            Some(v) => {
                positive(v, &format!("limits.{k}"), zero_ok).map_err(|e| invalid!("{file}: {e}"))
            }
            None => default.ok_or_else(|| invalid!("{file}: missing key `limits.{k}`")),
        }
    };
    let limits = PathLimits {
        speed: lim("speed", None, false)?,
        acceleration: lim("acceleration", Some(d.acceleration), false)?,
        jerk: lim("jerk", Some(d.jerk), false)?,
        blend_radius: lim("blend_radius", Some(0.0), true)?,
        rotation_radius: lim(
            "rotation_radius",
            Some(crate::path::DEFAULT_ROTATION_RADIUS_MM),
            false,
        )?,
    };
    let jt = table("joint_limits")?;
    check_keys(file, "joint_limits.", &jt, &["acceleration", "jerk"])?;
    let jl = |k: &str, default: f64| -> Result<f64> {
        match jt.get(k) {
            Some(v) => positive(v, &format!("joint_limits.{k}"), false)
                .map_err(|e| invalid!("{file}: {e}")),
            None => Ok(default),
        }
    };
    let joint = JointSettings {
        acceleration: jl("acceleration", d.joint_acceleration)?,
        jerk: jl("jerk", d.joint_jerk)?,
    };
    let segs = match root.get("segment") {
        Some(Value::Array(a)) => a.clone(),
        Some(v) => bail!("{file}: `segment` must be an array of tables ([[segment]]), got {v}"),
        None => bail!("{file}: no [[segment]] in the program"),
    };
    if segs.is_empty() {
        bail!("{file}: no [[segment]] in the program");
    }
    let mut segments = Vec::with_capacity(segs.len());
    for (i, v) in segs.iter().enumerate() {
        let t = v
            .as_table()
            .ok_or_else(|| invalid!("{file}: segment[{i}] must be a table (got {v})"))?;
        let kind = match t.get("type") {
            Some(Value::String(s)) => s.as_str(),
            Some(v) => bail!("{file}: segment[{i}]: `type` must be a string (got {v})"),
            None => bail!(
                "{file}: segment[{i}]: missing key `type` (\"line\", \"arc\", \"dwell\" or \"joint\")"
            ),
        };
        let allowed: &[&str] = match kind {
            "line" => &["type", "to", "speed", "blend_radius"],
            "arc" => &["type", "center", "sweep_deg", "phi_deg", "speed"],
            "dwell" => &["type", "seconds"],
            "joint" => &["type", "steps"],
            other => bail!(
                "{file}: segment[{i}]: unknown type `{other}` (expected \"line\", \"arc\", \"dwell\" or \"joint\")"
            ),
        };
        check_keys(file, &format!("segment[{i}]."), t, allowed)?;
        let ctx = |e: ProgramError| invalid!("{file}: segment[{i}] ({kind}): {e}");
        let req = |k: &str| -> Result<&Value> {
            t.get(k)
                .ok_or_else(|| invalid!("{file}: segment[{i}] ({kind}): missing key `{k}`"))
        };
        let opt_pos = |k: &str, zero_ok: bool| -> Result<Option<f64>> {
            t.get(k)
                .map(|v| positive(v, &format!("`{k}`"), zero_ok))
                .transpose()
                .map_err(ctx)
        };
        let step = match kind {
            "line" => {
                let to = finite_array(req("to")?, "`to` (x_mm, y_mm[, phi_deg])", &[2, 3])
                    .map_err(ctx)?;
                Step::Line {
                    to: [to[0], to[1]],
                    phi: to.get(2).map(|p| p.to_radians()),
                    speed: opt_pos("speed", false)?,
                    blend_radius: opt_pos("blend_radius", true)?,
                }
            }
            "arc" => {
                let c = finite_array(req("center")?, "`center` (x_mm, y_mm)", &[2]).map_err(ctx)?;
                let sweep = number(req("sweep_deg")?)
                    .filter(|s| s.is_finite() && *s != 0.0)
                    .ok_or_else(|| invalid!("`sweep_deg` must be a finite number other than 0"))
                    .map_err(ctx)?;
                let phi = match t.get("phi_deg") {
                    None => None,
                    Some(v) => Some(
                        number(v)
                            .filter(|p| p.is_finite())
                            .ok_or_else(|| invalid!("`phi_deg` must be a finite number"))
                            .map_err(ctx)?
                            .to_radians(),
                    ),
                };
                Step::Arc {
                    center: [c[0], c[1]],
                    sweep: sweep.to_radians(),
                    phi,
                    speed: opt_pos("speed", false)?,
                }
            }
            "dwell" => Step::Dwell {
                seconds: positive(req("seconds")?, "`seconds`", false).map_err(ctx)?,
            },
            _ => {
                let v = req("steps")?;
                let a = v
                    .as_array()
                    .filter(|a| a.len() == 3)
                    .and_then(|a| a.iter().map(|x| x.as_integer()).collect::<Option<Vec<_>>>())
                    .ok_or_else(|| {
                        invalid!("`steps` must be three integers (motor steps), got {v}")
                    })
                    .map_err(ctx)?;
                Step::Joint {
                    steps: [a[0], a[1], a[2]],
                }
            }
        };
        segments.push(step);
    }
    Ok(Program {
        limits,
        joint,
        segments,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const D: Defaults = Defaults {
        acceleration: 200.0,
        jerk: 2000.0,
        joint_acceleration: 1000.0,
        joint_jerk: 10000.0,
    };

    #[test]
    fn parses_every_segment_type() {
        let p = parse(
            r#"
            [limits]
            speed = 30
            blend_radius = 2.5
            [[segment]]
            type = "line"
            to = [10, 0]
            [[segment]]
            type = "arc"
            center = [10, 5]
            sweep_deg = 90
            speed = 10
            [[segment]]
            type = "dwell"
            seconds = 0.25
            [[segment]]
            type = "joint"
            steps = [1, -2, 3]
            "#,
            "p.toml",
            &D,
        )
        .unwrap();
        assert_eq!(p.limits.speed, 30.0);
        assert_eq!(p.limits.acceleration, 200.0);
        assert_eq!(p.limits.blend_radius, 2.5);
        assert_eq!(p.joint.jerk, 10000.0);
        assert_eq!(p.segments.len(), 4);
        assert_eq!(p.segments[3], Step::Joint { steps: [1, -2, 3] });
        let Step::Arc { sweep, speed, .. } = p.segments[1] else {
            panic!()
        };
        assert!((sweep - std::f64::consts::FRAC_PI_2).abs() < 1e-15);
        assert_eq!(speed, Some(10.0));
    }

    #[test]
    fn errors_name_the_file_key_and_segment() {
        let e = |s: &str| parse(s, "prog.toml", &D).unwrap_err().to_string();
        let m = e("[limits]\nspeed = 1\nsped = 2\n[[segment]]\ntype = \"dwell\"\nseconds = 1");
        assert!(
            m.contains("prog.toml") && m.contains("`limits.sped`"),
            "{m}"
        );
        let m = e("[limits]\nspeed = 1\n[[segment]]\ntype = \"dwell\"\nseconds = 1\n[[segment]]\ntype = \"line\"\nto = [1, 2]\nradius = 3");
        assert!(
            m.contains("prog.toml") && m.contains("`segment[1].radius`"),
            "{m}"
        );
        let m = e("[limits]\nspeed = 1\n[[segment]]\ntype = \"dwell\"\nseconds = -1");
        assert!(
            m.contains("segment[0] (dwell)") && m.contains("seconds"),
            "{m}"
        );
        let m = e("[limits]\nspeed = 1\n[[segment]]\ntype = \"line\"\nto = [1]");
        assert!(m.contains("segment[0] (line)") && m.contains("`to`"), "{m}");
        let m = e("[limits]\nspeed = 0\n[[segment]]\ntype = \"dwell\"\nseconds = 1");
        assert!(m.contains("limits.speed"), "{m}");
        let m = e("[[segment]]\ntype = \"dwell\"\nseconds = 1");
        assert!(m.contains("missing key `limits.speed`"), "{m}");
        let m = e("[limits]\nspeed = 1\n[[segment]]\ntype = \"spline\"");
        assert!(m.contains("segment[0]") && m.contains("spline"), "{m}");
        let m = e("[limits]\nspeed = 1\n[[segment]]\ntype = \"joint\"\nsteps = [1, 2.5, 3]");
        assert!(
            m.contains("segment[0] (joint)") && m.contains("three integers"),
            "{m}"
        );
        let m = e("[limits]\nspeed = 1\nextra = 2\n");
        assert!(m.contains("`limits.extra`"), "{m}");
        let m = e("bogus = 1");
        assert!(m.contains("unknown key `bogus`"), "{m}");
    }
}
