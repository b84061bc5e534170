//! Gear backlash and base-plate friction (paper section III-D): the smallest motor step count
//! whose motion the measurement detects, per motor, and the worst-case end-effector error it
//! causes over the workspace (paper eq. 10, Fig. 7).
//!
//! The protocol moves one motor n steps forth and back, repeatedly, for n = 1, 2, ...; the
//! marker at the end of that leg (M_i) is recorded. For each block (one motor, one n):
//!
//! 1. The block is cut to a whole number of excitation periods (from the commanded signal).
//! 2. The measured M_i is projected on the direction the model's M_i moves when that tendon is
//!    pulled (dM/d dl of the robot file's leg at the block's rest position), missing samples
//!    interpolated.
//! 3. FFT (`rustfft`): the single-sided amplitude A_k = 2 |X_k| / N at the excitation bin (the
//!    commanded signal's strongest bin) against the noise floor of the other bins (harmonics of
//!    the excitation excluded). For white noise A_k is Rayleigh distributed with scale
//!    s = sqrt(mean(A^2) / 2); the motion is detected when the amplitude exceeds
//!    s sqrt(-2 ln p) (p = 1e-3 false alarms per block by default).
//!
//! n_S,i is the smallest n detected with every larger n detected too. Blocks come from the extra
//! columns `motor` and `amplitude_steps` when the recording has them, else from the commanded
//! motor positions (an excursion of one motor away from its rest value and back; consecutive
//! excursions of the same size form a block).

use crate::figures::FigureError;
use pcr_kinematics::workspace::{error_map, grid_workspace, Workspace};
use pcr_kinematics::{Leg, Robot};
use pcr_recording::{Recording, Row};
use pcr_robot::RobotConfig;
use rustfft::num_complex::Complex;
use rustfft::FftPlanner;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::Path;

/// Why a backlash recording cannot be analysed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BacklashError {
    /// No block found.
    #[error("{origin}: no forth-and-back blocks found: the recording needs one motor at a time moving n steps forth and back (columns `motor`, `amplitude_steps`, or the commanded q1..q3 alone)")]
    NoBlocks {
        /// The file.
        origin: String,
    },
    /// A column holds something else than expected.
    #[error("{origin}: line {line}: column `{column}`: {message}")]
    Cell {
        /// The file.
        origin: String,
        /// 1-based data row (header excluded).
        line: usize,
        /// Column.
        column: String,
        /// What is wrong.
        message: String,
    },
    /// The robot model is unusable.
    #[error("robot model: {0}")]
    Robot(String),
}

/// The analysis of one block.
#[derive(Debug, Clone, Serialize)]
pub struct Block {
    /// Motor 1..3.
    pub motor: usize,
    /// Steps forth and back.
    pub amplitude_steps: u32,
    /// Samples analysed.
    pub samples: usize,
    /// Excitation periods in the analysed window.
    pub periods: usize,
    /// Excitation frequency, Hz.
    pub frequency_hz: f64,
    /// Measured amplitude of M_i along the motion direction at that frequency, mm.
    pub amplitude_mm: f64,
    /// Rayleigh scale of the noise floor, mm.
    pub noise_mm: f64,
    /// Detection threshold, mm.
    pub threshold_mm: f64,
    /// Whether the motion was detected.
    pub detected: bool,
    /// Samples without a measured M_i (interpolated).
    pub missing: usize,
}

/// Per motor.
#[derive(Debug, Clone, Serialize)]
pub struct MotorBacklash {
    /// Motor 1..3.
    pub motor: usize,
    /// Smallest detected step count with every larger one detected (None: none detected).
    pub n_s: Option<u32>,
    /// Its blocks, by step count.
    pub blocks: Vec<Block>,
}

/// The worst-case error map of eq. 10 at phi = 0.
#[derive(Debug, Clone, Serialize)]
pub struct ErrorMap {
    /// Step counts used per motor.
    pub n_s: [f64; 3],
    /// Largest error over the workspace, mm.
    pub max_mm: f64,
    /// Where it is (x, y), mm.
    pub max_at: [f64; 2],
    /// Mean over the workspace, mm.
    pub mean_mm: f64,
    /// The same at the square's corner (50, -50) mm, if in the workspace.
    pub at_square_corner_mm: Option<f64>,
    /// Grid cells.
    #[serde(skip)]
    pub cells: Vec<([f64; 2], f64)>,
    /// Cell side, mm.
    #[serde(skip)]
    pub cell_mm: f64,
    /// Workspace outline.
    #[serde(skip)]
    pub outline: Vec<[[f64; 2]; 2]>,
}

/// The whole analysis.
#[derive(Debug, Clone, Serialize)]
pub struct Backlash {
    /// The file.
    pub file: String,
    /// How blocks were found (`columns` or `commanded motion`).
    pub blocks_from: String,
    /// False-alarm probability per block.
    pub false_alarm: f64,
    /// Per motor.
    pub motors: Vec<MotorBacklash>,
    /// Eq. 10 over the phi = 0 workspace.
    pub error_map: Option<ErrorMap>,
}

struct RawBlock {
    motor: usize,
    amplitude: u32,
    rows: std::ops::Range<usize>,
}

/// Blocks from the extra columns `motor` and `amplitude_steps`.
fn blocks_from_columns(
    rec: &Recording,
    origin: &str,
    mc: usize,
    ac: usize,
) -> Result<Vec<RawBlock>, BacklashError> {
    let mut out: Vec<RawBlock> = Vec::new();
    let parse = |k: usize, c: usize, name: &str| -> Result<Option<u32>, BacklashError> {
        match rec.rows[k].extra.get(c).and_then(|v| v.as_deref()) {
            None | Some("") => Ok(None),
            Some(v) => v
                .parse::<f64>()
                .ok()
                .filter(|x| x.fract() == 0.0 && *x >= 0.0 && *x < 1e6)
                .map(|x| Some(x as u32))
                .ok_or_else(|| BacklashError::Cell {
                    origin: origin.into(),
                    line: k + 1,
                    column: name.into(),
                    message: format!("{v:?} is not a whole non-negative number"),
                }),
        }
    };
    for k in 0..rec.rows.len() {
        let (Some(m), Some(a)) = (parse(k, mc, "motor")?, parse(k, ac, "amplitude_steps")?) else {
            continue;
        };
        if !(1..=3).contains(&m) {
            return Err(BacklashError::Cell {
                origin: origin.into(),
                line: k + 1,
                column: "motor".into(),
                message: format!("{m} is not a motor (1, 2 or 3)"),
            });
        }
        match out.last_mut() {
            Some(b) if b.motor == m as usize && b.amplitude == a && b.rows.end == k => {
                b.rows.end = k + 1
            }
            _ => out.push(RawBlock {
                motor: m as usize,
                amplitude: a,
                rows: k..k + 1,
            }),
        }
    }
    Ok(out)
}

/// Blocks from the commanded motion alone.
fn blocks_from_motion(rows: &[Row]) -> Vec<RawBlock> {
    // The rest position: the most frequent commanded vector.
    let mut counts: BTreeMap<[i32; 3], usize> = BTreeMap::new();
    for r in rows {
        *counts.entry(r.q).or_default() += 1;
    }
    let Some(rest) = counts.iter().max_by_key(|e| e.1).map(|e| *e.0) else {
        return Vec::new();
    };
    // Excursions: maximal runs where exactly one motor is off its rest value.
    let mut exc: Vec<(usize, usize, std::ops::Range<usize>)> = Vec::new(); // (motor, peak, rows)
    let mut k = 0;
    while k < rows.len() {
        let off: Vec<usize> = (0..3).filter(|&i| rows[k].q[i] != rest[i]).collect();
        if off.len() != 1 {
            k += 1;
            continue;
        }
        let i = off[0];
        let start = k;
        let mut peak = 0;
        while k < rows.len()
            && rows[k].q[i] != rest[i]
            && (0..3).all(|j| j == i || rows[k].q[j] == rest[j])
        {
            peak = peak.max((rows[k].q[i] - rest[i]).unsigned_abs() as usize);
            k += 1;
        }
        exc.push((i, peak, start..k));
    }
    // Consecutive excursions of the same motor and size: one block, extended by one spacing
    // after the last excursion's start.
    let mut out = Vec::new();
    let mut a = 0;
    while a < exc.len() {
        let mut b = a + 1;
        while b < exc.len() && exc[b].0 == exc[a].0 && exc[b].1 == exc[a].1 {
            b += 1;
        }
        if b - a >= 2 {
            let spacing = (exc[b - 1].2.start - exc[a].2.start) / (b - a - 1);
            out.push(RawBlock {
                motor: exc[a].0 + 1,
                amplitude: exc[a].1 as u32,
                rows: exc[a].2.start..(exc[b - 1].2.start + spacing).min(rows.len()),
            });
        }
        a = b;
    }
    out
}

/// Single-sided amplitude spectrum 2|X_k|/N, k = 0..=N/2.
fn amplitude_spectrum(x: &[f64], planner: &mut FftPlanner<f64>) -> Vec<f64> {
    let n = x.len();
    let mut buf: Vec<Complex<f64>> = x.iter().map(|v| Complex::new(*v, 0.0)).collect();
    planner.plan_fft_forward(n).process(&mut buf);
    buf.iter()
        .take(n / 2 + 1)
        .map(|c| 2.0 * c.norm() / n as f64)
        .collect()
}

fn analyse_block(
    raw: &RawBlock,
    rows: &[Row],
    leg: &Leg,
    mm_per_step: f64,
    p_fa: f64,
    planner: &mut FftPlanner<f64>,
) -> Option<Block> {
    let i = raw.motor - 1;
    let rs = &rows[raw.rows.clone()];
    if rs.len() < 8 {
        return None;
    }
    // Whole periods: excursion starts of the commanded signal.
    let rest = rs[0].q[i];
    let starts: Vec<usize> = (1..rs.len())
        .filter(|&k| rs[k].q[i] != rest && rs[k - 1].q[i] == rest)
        .collect();
    let (first, len) = if starts.len() >= 2 {
        let period = (starts[starts.len() - 1] - starts[0]) as f64 / (starts.len() - 1) as f64;
        let m = (((rs.len() - starts[0]) as f64) / period).floor().max(1.0);
        (
            starts[0],
            ((m * period).round() as usize).min(rs.len() - starts[0]),
        )
    } else {
        (0, rs.len())
    };
    let w = &rs[first..first + len];
    if w.len() < 8 {
        return None;
    }
    // Motion direction of M_i when the tendon is pulled, at the rest position.
    let dl = rest as f64 * mm_per_step;
    let h = 1e-3;
    let (a, b) = (
        leg.joint_m(leg.map.kappa(dl + h)),
        leg.joint_m(leg.map.kappa(dl - h)),
    );
    let (ux, uy) = (a[0] - b[0], a[1] - b[1]);
    let un = ux.hypot(uy);
    if un == 0.0 {
        return None;
    }
    let (ux, uy) = (ux / un, uy / un);
    // Projected measurement with gaps filled linearly.
    let mut s: Vec<Option<f64>> = w
        .iter()
        .map(|r| match r.m[i] {
            [Some(x), Some(y)] => Some(x * ux + y * uy),
            _ => None,
        })
        .collect();
    let missing = s.iter().filter(|v| v.is_none()).count();
    if missing * 5 > s.len() {
        return None;
    }
    fill_gaps(&mut s);
    let mut x: Vec<f64> = s.into_iter().map(|v| v.unwrap_or(0.0)).collect();
    let mean = x.iter().sum::<f64>() / x.len() as f64;
    for v in &mut x {
        *v -= mean;
    }
    let cmd: Vec<f64> = {
        let c: Vec<f64> = w.iter().map(|r| r.q[i] as f64).collect();
        let m = c.iter().sum::<f64>() / c.len() as f64;
        c.into_iter().map(|v| v - m).collect()
    };
    let spec_cmd = amplitude_spectrum(&cmd, planner);
    let k_e = (1..spec_cmd.len()).max_by(|a, b| spec_cmd[*a].total_cmp(&spec_cmd[*b]))?;
    let spec = amplitude_spectrum(&x, planner);
    let amplitude = spec[k_e];
    let noise: Vec<f64> = (1..spec.len())
        .filter(|k| {
            let r = k % k_e;
            !(r <= 1 || r + 1 >= k_e)
        })
        .map(|k| spec[k])
        .collect();
    if noise.is_empty() {
        return None;
    }
    let scale = (noise.iter().map(|a| a * a).sum::<f64>() / noise.len() as f64 / 2.0).sqrt();
    let threshold = scale * (-2.0 * p_fa.ln()).sqrt();
    let dt = (w[w.len() - 1].t_s - w[0].t_s) / (w.len() - 1) as f64;
    Some(Block {
        motor: raw.motor,
        amplitude_steps: raw.amplitude,
        samples: w.len(),
        periods: k_e,
        frequency_hz: k_e as f64 / (w.len() as f64 * dt),
        amplitude_mm: amplitude,
        noise_mm: scale,
        threshold_mm: threshold,
        detected: amplitude > threshold,
        missing,
    })
}

/// Linear interpolation over missing samples (ends held).
fn fill_gaps(s: &mut [Option<f64>]) {
    let known: Vec<usize> = (0..s.len()).filter(|&k| s[k].is_some()).collect();
    if known.is_empty() {
        return;
    }
    for k in 0..s.len() {
        if s[k].is_some() {
            continue;
        }
        let after = known.partition_point(|&j| j < k);
        let v = match (after.checked_sub(1).map(|a| known[a]), known.get(after)) {
            (Some(a), Some(&b)) => {
                let (va, vb) = (s[a].unwrap_or(0.0), s[b].unwrap_or(0.0));
                va + (vb - va) * (k - a) as f64 / (b - a) as f64
            }
            (Some(a), None) => s[a].unwrap_or(0.0),
            (None, Some(&b)) => s[b].unwrap_or(0.0),
            (None, None) => 0.0,
        };
        s[k] = Some(v);
    }
}

/// Analyses a backlash recording; `robot` gives the motion directions and the eq. 10 map.
pub fn analyse(
    rec: &Recording,
    origin: &str,
    robot: &RobotConfig,
    false_alarm: f64,
    map_resolution_mm: f64,
) -> Result<Backlash, BacklashError> {
    let (raw, blocks_from) = match (rec.extra_index("motor"), rec.extra_index("amplitude_steps")) {
        (Some(m), Some(a)) => (blocks_from_columns(rec, origin, m, a)?, "columns"),
        _ => (blocks_from_motion(&rec.rows), "commanded motion"),
    };
    let mut planner = FftPlanner::new();
    let mut motors: Vec<MotorBacklash> = (1..=3)
        .map(|m| MotorBacklash {
            motor: m,
            n_s: None,
            blocks: Vec::new(),
        })
        .collect();
    for b in &raw {
        let leg = Leg::from_config(&robot.legs[b.motor - 1]);
        let mmps = robot.legs[b.motor - 1].actuation.mm_per_step();
        if let Some(r) = analyse_block(b, &rec.rows, &leg, mmps, false_alarm, &mut planner) {
            motors[b.motor - 1].blocks.push(r);
        }
    }
    if motors.iter().all(|m| m.blocks.is_empty()) {
        return Err(BacklashError::NoBlocks {
            origin: origin.into(),
        });
    }
    for m in &mut motors {
        m.blocks.sort_by_key(|b| b.amplitude_steps);
        // Smallest n detected with every larger n detected.
        let mut n_s = None;
        for b in m.blocks.iter().rev() {
            if b.detected {
                n_s = Some(b.amplitude_steps);
            } else {
                break;
            }
        }
        m.n_s = n_s;
    }
    let n_s: [Option<u32>; 3] = std::array::from_fn(|i| motors[i].n_s);
    let error_map = if n_s.iter().all(Option::is_some) {
        Some(eq10_map(
            robot,
            n_s.map(|n| n.unwrap_or(0) as f64),
            map_resolution_mm,
        )?)
    } else {
        None
    };
    Ok(Backlash {
        file: origin.into(),
        blocks_from: blocks_from.into(),
        false_alarm,
        motors,
        error_map,
    })
}

/// Eq. 10 over the phi = 0 workspace for `n_s` steps per motor.
pub fn eq10_map(robot: &RobotConfig, n_s: [f64; 3], res: f64) -> Result<ErrorMap, BacklashError> {
    let model = Robot::new(robot).map_err(|e| BacklashError::Robot(e.to_string()))?;
    let ws: Workspace = grid_workspace(&model, 0.0, res, &|_| {});
    let vals = error_map(&model, &ws, n_s);
    let g = &ws.grid;
    let mut cells = Vec::new();
    for j in 0..g.ny {
        for i in 0..g.nx {
            if let Some(v) = vals[j * g.nx + i] {
                cells.push((g.center(i, j), v));
            }
        }
    }
    let (max_at, max_mm) =
        cells.iter().fold(
            ([0.0, 0.0], 0.0f64),
            |a, c| if c.1 > a.1 { (c.0, c.1) } else { a },
        );
    let mean_mm = cells.iter().map(|c| c.1).sum::<f64>() / cells.len().max(1) as f64;
    let corner = pcr_kinematics::workspace::position_error_for_steps(
        &model,
        &pcr_kinematics::Pose::new(50.0, -50.0, 0.0),
        n_s,
    );
    Ok(ErrorMap {
        n_s,
        max_mm,
        max_at,
        mean_mm,
        at_square_corner_mm: corner,
        cells,
        cell_mm: res,
        outline: ws.contour(),
    })
}

/// Draws Fig. 7 (the eq. 10 map) as SVG.
pub fn draw_error_map(path: &Path, m: &ErrorMap) -> Result<(), FigureError> {
    let title = format!(
        "Worst-case position error from undetected steps (eq. 10), n_S = {:?}, phi = 0",
        m.n_s.map(|v| v as u32)
    );
    pcr_figures::draw_heat_map(
        path,
        &pcr_figures::HeatMap {
            title: &title,
            cells: &m.cells,
            cell_mm: m.cell_mm,
            outline: &m.outline,
            marks: &[(m.max_at, format!("max {:.2} mm", m.max_mm))],
            value_label: "mm",
        },
    )
    .map_err(|message| FigureError {
        file: path.display().to_string(),
        message,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A synthetic backlash recording: motor `m` moves n steps forth and back for n = 1..=6,
    /// the leg's M follows with a dead band of `b` steps, plus deterministic pseudo-noise.
    fn synthetic(b: i32, noise: f64, labelled: bool) -> Recording {
        let robot = RobotConfig::nominal();
        let leg = Leg::from_config(&robot.legs[1]);
        let mmps = robot.legs[1].actuation.mm_per_step();
        let rest = [176, 176, 176];
        let mut text = String::from("t_s,q1,q2,q3,m2x_mm,m2y_mm");
        if labelled {
            text += ",motor,amplitude_steps";
        }
        text += "\n";
        let mut t = 0.0;
        let mut out_pos = 176.0f64; // gear output position (play model)
        let mut seed = 12345u64;
        for n in 1..=6 {
            for k in 0..(8 * 100) {
                // 0.5 Hz: forth for 1 s (50 rows), back for 1 s
                let forth = (k / 50) % 2 == 0 && k < 8 * 100 - 50;
                let q2 = if forth { rest[1] + n } else { rest[1] };
                let q = q2 as f64;
                let half = b as f64 / 2.0;
                if q - out_pos > half {
                    out_pos = q - half;
                } else if out_pos - q > half {
                    out_pos = q + half;
                }
                let m = leg.joint_m(leg.map.kappa(out_pos * mmps));
                seed = seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let e1 = noise * (((seed >> 33) % 1000) as f64 / 500.0 - 1.0);
                seed = seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let e2 = noise * (((seed >> 33) % 1000) as f64 / 500.0 - 1.0);
                t += 0.02;
                text += &format!(
                    "{t:.2},{},{q2},{},{},{}",
                    rest[0],
                    rest[2],
                    m[0] + e1,
                    m[1] + e2
                );
                if labelled {
                    text += &format!(",2,{n}");
                }
                text += "\n";
            }
        }
        Recording::read(text.as_bytes(), "b.csv").unwrap()
    }

    #[test]
    fn finds_the_dead_band_with_and_without_labels() {
        for labelled in [true, false] {
            let rec = synthetic(3, 0.05, labelled);
            let r = analyse(&rec, "b.csv", &RobotConfig::nominal(), 1e-3, 4.0).unwrap();
            let m = &r.motors[1];
            assert_eq!(m.blocks.len(), 6, "labelled {labelled}: {:?}", m.blocks);
            // A dead band of 3 steps swallows n <= 3; n = 4 moves the output by one step.
            assert_eq!(m.n_s, Some(4), "labelled {labelled}: {:#?}", m.blocks);
            assert!((m.blocks[0].frequency_hz - 0.5).abs() < 0.01);
            assert!(r.motors[0].blocks.is_empty() && r.motors[2].blocks.is_empty());
            assert!(r.error_map.is_none(), "n_S of motors 1 and 3 unknown");
        }
    }

    #[test]
    fn eq10_grows_with_the_step_count_and_peaks_low_in_the_workspace() {
        let robot = RobotConfig::nominal();
        let a = eq10_map(&robot, [1.0; 3], 4.0).unwrap();
        let b = eq10_map(&robot, [4.0; 3], 4.0).unwrap();
        assert!((b.max_mm - 4.0 * a.max_mm).abs() < 1e-9 * b.max_mm);
        assert!(a.max_mm > a.mean_mm);
        // the paper's Fig. 7: largest in the lower part of the workspace
        assert!(a.max_at[1] < 0.0, "{:?}", a.max_at);
        assert!(a.at_square_corner_mm.is_some());
    }

    #[test]
    fn no_blocks_is_an_error() {
        let rec =
            Recording::read("t_s,q1,q2,q3\n0,1,1,1\n0.1,1,1,1\n".as_bytes(), "b.csv").unwrap();
        let e = analyse(&rec, "b.csv", &RobotConfig::nominal(), 1e-3, 4.0).unwrap_err();
        assert!(e.to_string().contains("b.csv"));
    }
}
