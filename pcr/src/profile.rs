//! `pcr profile`: solves jerk-limited profiling cases from a JSON file.
//!
//! Input `{"cases": [{"id", "dofs", "control_interface": "position"|"velocity",
//! "synchronization": "time"|"none"|"phase", "current": {"p","v","a"}, "target": {..},
//! "limits": {"vmax","vmin"?,"amax","amin"?,"jmax"}, "minimum_duration"?}]}`; output
//! `{"answers": [{"id", "duration", "p", "v", "a", "final": {"p","v","a"}} | {"id","error"}]}`
//! with samples every 20 ms (at most 500). Unknown fields are ignored.

use std::path::PathBuf;

use anyhow::{anyhow, bail, Context};
use pcr_planner::profiler::{
    calculate, ControlInterface, Input, Limits, State, Synchronization, MAX_DOFS,
};
use serde_json::{json, Map, Value};

/// Sampling period of the answers in s.
const DT: f64 = 0.02;
/// Maximal number of samples per answer.
const MAX_SAMPLES: usize = 500;

/// Arguments of `pcr profile`.
#[derive(clap::Args)]
pub struct Args {
    /// Input cases (JSON).
    #[arg(long)]
    pub cases: PathBuf,
    /// Output answers (JSON).
    #[arg(long)]
    pub out: PathBuf,
}

/// Runs `pcr profile`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(&args.cases)
        .with_context(|| format!("reading {}", args.cases.display()))?;
    let root: Value = serde_json::from_str(&text)
        .with_context(|| format!("{} is not valid JSON", args.cases.display()))?;
    let cases = root.get("cases").and_then(Value::as_array).ok_or_else(|| {
        anyhow!(
            "{}: expected an object with a \"cases\" array",
            args.cases.display()
        )
    })?;
    let mut answers = Vec::with_capacity(cases.len());
    let mut failed = 0usize;
    for (idx, case) in cases.iter().enumerate() {
        let (id, input) =
            parse_case(case).with_context(|| format!("case index {idx} is malformed"))?;
        match calculate(&input) {
            Ok(traj) => answers.push(answer(id, &traj)),
            Err(e) => {
                failed += 1;
                answers.push(json!({"id": id, "error": e.to_string()}));
            }
        }
    }
    let out = json!({ "answers": answers });
    std::fs::write(&args.out, serde_json::to_string(&out)?)
        .with_context(|| format!("writing {}", args.out.display()))?;
    eprintln!(
        "pcr profile: {} cases, {} solved, {} errors -> {}",
        cases.len(),
        cases.len() - failed,
        failed,
        args.out.display()
    );
    Ok(())
}

fn answer(id: Value, traj: &pcr_planner::profiler::Trajectory) -> Value {
    let n = traj.dofs();
    let d = traj.duration();
    let k_max = ((d / DT).floor() as usize).min(MAX_SAMPLES - 1);
    let mut ps = Vec::with_capacity(k_max + 1);
    let mut vs = Vec::with_capacity(k_max + 1);
    let mut as_ = Vec::with_capacity(k_max + 1);
    let mut buf = [State::default(); MAX_DOFS];
    for k in 0..=k_max {
        traj.at(k as f64 * DT, &mut buf[..n]);
        ps.push(buf[..n].iter().map(|s| s.p).collect::<Vec<_>>());
        vs.push(buf[..n].iter().map(|s| s.v).collect::<Vec<_>>());
        as_.push(buf[..n].iter().map(|s| s.a).collect::<Vec<_>>());
    }
    traj.at(d, &mut buf[..n]);
    json!({
        "id": id,
        "duration": d,
        "p": ps, "v": vs, "a": as_,
        "final": {
            "p": buf[..n].iter().map(|s| s.p).collect::<Vec<_>>(),
            "v": buf[..n].iter().map(|s| s.v).collect::<Vec<_>>(),
            "a": buf[..n].iter().map(|s| s.a).collect::<Vec<_>>(),
        }
    })
}

fn num_array(obj: &Map<String, Value>, key: &str, ctx: &str, n: usize) -> anyhow::Result<Vec<f64>> {
    let v = obj
        .get(key)
        .ok_or_else(|| anyhow!("missing field `{ctx}.{key}`"))?;
    let arr = v
        .as_array()
        .ok_or_else(|| anyhow!("field `{ctx}.{key}` must be an array of {n} numbers"))?;
    if arr.len() != n {
        bail!(
            "field `{ctx}.{key}` has {} entries, expected {n} (dofs)",
            arr.len()
        );
    }
    arr.iter()
        .enumerate()
        .map(|(i, x)| {
            x.as_f64()
                .ok_or_else(|| anyhow!("field `{ctx}.{key}[{i}]` must be a number, got {x}"))
        })
        .collect()
}

fn parse_state(case: &Map<String, Value>, key: &str, n: usize) -> anyhow::Result<Vec<State>> {
    let obj = case
        .get(key)
        .and_then(Value::as_object)
        .ok_or_else(|| anyhow!("missing or non-object field `{key}`"))?;
    let p = num_array(obj, "p", key, n)?;
    let v = num_array(obj, "v", key, n)?;
    let a = num_array(obj, "a", key, n)?;
    Ok((0..n).map(|i| State::new(p[i], v[i], a[i])).collect())
}

fn parse_case(case: &Value) -> anyhow::Result<(Value, Input)> {
    let obj = case
        .as_object()
        .ok_or_else(|| anyhow!("a case must be a JSON object"))?;
    let id = obj.get("id").cloned().unwrap_or(Value::Null);
    let dofs = obj
        .get("dofs")
        .and_then(Value::as_u64)
        .ok_or_else(|| anyhow!("missing or non-integer field `dofs`"))? as usize;
    if dofs == 0 || dofs > MAX_DOFS {
        bail!("field `dofs` = {dofs} must be within 1..={MAX_DOFS}");
    }
    let mut input = Input::new(dofs);
    input.control_interface = match obj.get("control_interface").map(|v| v.as_str()) {
        None | Some(Some("position")) => ControlInterface::Position,
        Some(Some("velocity")) => ControlInterface::Velocity,
        Some(other) => bail!(
            "field `control_interface` must be \"position\" or \"velocity\", got {}",
            other.map_or_else(
                || obj["control_interface"].to_string(),
                |s| format!("{s:?}")
            )
        ),
    };
    input.synchronization = match obj.get("synchronization").map(|v| v.as_str()) {
        None | Some(Some("time")) => Synchronization::Time,
        Some(Some("none")) => Synchronization::None,
        Some(Some("phase")) => Synchronization::Phase,
        Some(other) => bail!(
            "field `synchronization` must be \"time\", \"none\" or \"phase\", got {}",
            other.map_or_else(|| obj["synchronization"].to_string(), |s| format!("{s:?}"))
        ),
    };
    let cur = parse_state(obj, "current", dofs)?;
    let tgt = parse_state(obj, "target", dofs)?;
    let lim = obj
        .get("limits")
        .and_then(Value::as_object)
        .ok_or_else(|| anyhow!("missing or non-object field `limits`"))?;
    let vmax = num_array(lim, "vmax", "limits", dofs)?;
    let amax = num_array(lim, "amax", "limits", dofs)?;
    let jmax = num_array(lim, "jmax", "limits", dofs)?;
    let vmin = match lim.get("vmin") {
        None | Some(Value::Null) => vmax.iter().map(|v| -v).collect(),
        Some(_) => num_array(lim, "vmin", "limits", dofs)?,
    };
    let amin = match lim.get("amin") {
        None | Some(Value::Null) => amax.iter().map(|v| -v).collect(),
        Some(_) => num_array(lim, "amin", "limits", dofs)?,
    };
    for i in 0..dofs {
        input.current[i] = cur[i];
        input.target[i] = tgt[i];
        input.limits[i] = Limits {
            vmax: vmax[i],
            vmin: vmin[i],
            amax: amax[i],
            amin: amin[i],
            jmax: jmax[i],
        };
    }
    input.minimum_duration = match obj.get("minimum_duration") {
        None | Some(Value::Null) => None,
        Some(v) => Some(
            v.as_f64()
                .ok_or_else(|| anyhow!("field `minimum_duration` must be a number, got {v}"))?,
        ),
    };
    Ok((id, input))
}
