//! The control interface: one text line per request over a Unix stream socket, one text reply
//! (`pcr-supervisor ctl --config <file> status`).
//!
//! Requests: `status`, `run paper|circle|square`, `run moves <move>; <move>; ...` with moves
//! `line X Y PHI_DEG SPEED`, `circle CX CY R SPEED`, `dwell S` (mm, deg, mm/s, s),
//! `run program <file>` (a TOML program file of lines, arcs, dwells and joint moves; the client
//! sends the path made absolute),
//! `pause`, `resume`, `stop`, `reset` (re-arm after a safe stop), `shutdown`.

use pcr_control::Move;
use pcr_kinematics::Pose;
use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// A parsed request.
#[derive(Debug, Clone, PartialEq)]
pub enum Request {
    /// Report the state.
    Status,
    /// Run a built-in program (`paper`, `circle`, `square`).
    RunBuiltin(String),
    /// Run a list of moves.
    RunMoves(Vec<Move>),
    /// Run a program file (TOML; the path as the supervisor sees it).
    RunProgram(PathBuf),
    /// Run one of the paper's experiments (`crate::experiment`): its kind and `key=value`
    /// options.
    RunExperiment {
        /// calibration, repeatability, paths or backlash.
        kind: String,
        /// The options, in order.
        options: Vec<(String, String)>,
    },
    /// The planner's verdict on run N: `planning`, `running`, `refused: <reason>`, or how it
    /// ended (`ctl run` waits for it).
    Verdict(u32),
    /// Pause the motion.
    Pause,
    /// Resume it.
    Resume,
    /// Stop it (hold).
    Stop,
    /// Re-arm after a safe stop.
    Reset,
    /// Shut the chain down.
    Shutdown,
}

fn nums(parts: &[&str], n: usize, what: &str) -> Result<Vec<f64>, String> {
    if parts.len() != n {
        return Err(format!("{what}: expected {n} numbers, got {}", parts.len()));
    }
    parts
        .iter()
        .map(|p| {
            p.parse::<f64>()
                .map_err(|_| format!("{what}: {p:?} is not a number"))
        })
        .collect()
}

/// Parses `line X Y PHI_DEG SPEED; circle CX CY R SPEED; dwell S`.
pub fn parse_moves(text: &str) -> Result<Vec<Move>, String> {
    let mut v = Vec::new();
    for m in text.split(';').map(str::trim).filter(|s| !s.is_empty()) {
        let w: Vec<&str> = m.split_whitespace().collect();
        match w[0] {
            "line" => {
                let a = nums(&w[1..], 4, "line")?;
                v.push(Move::Line {
                    to: Pose::from_mm_deg(a[0], a[1], a[2]),
                    speed_mm_s: a[3],
                });
            }
            "circle" => {
                let a = nums(&w[1..], 4, "circle")?;
                v.push(Move::Circle {
                    centre: [a[0], a[1]],
                    radius_mm: a[2],
                    speed_mm_s: a[3],
                    phi: 0.0,
                });
            }
            "dwell" => {
                let a = nums(&w[1..], 1, "dwell")?;
                v.push(Move::Dwell { duration_s: a[0] });
            }
            o => return Err(format!("unknown move {o:?} (line, circle, dwell)")),
        }
    }
    if v.is_empty() {
        return Err("no moves".into());
    }
    Ok(v)
}

/// Parses one request line.
pub fn parse(line: &str) -> Result<Request, String> {
    let line = line.trim();
    let (head, rest) = line.split_once(' ').unwrap_or((line, ""));
    Ok(match head {
        "status" => Request::Status,
        "pause" => Request::Pause,
        "resume" => Request::Resume,
        "stop" => Request::Stop,
        "reset" => Request::Reset,
        "shutdown" => Request::Shutdown,
        "verdict" => Request::Verdict(
            rest.trim()
                .parse()
                .map_err(|_| format!("verdict needs a run number, got {rest:?}"))?,
        ),
        "run" => {
            let rest = rest.trim();
            match rest.split_once(' ') {
                Some(("moves", m)) => Request::RunMoves(parse_moves(m)?),
                Some(("experiment", e)) => {
                    let mut words = e.split_whitespace();
                    let kind = words.next().unwrap_or_default().to_string();
                    let options = words
                        .map(|w| {
                            w.split_once('=')
                                .map(|(k, v)| (k.to_string(), v.to_string()))
                                .ok_or_else(|| format!("experiment option {w:?}: write key=value"))
                        })
                        .collect::<Result<_, _>>()?;
                    Request::RunExperiment { kind, options }
                }
                Some(("program", f)) if !f.trim().is_empty() => {
                    Request::RunProgram(PathBuf::from(f.trim()))
                }
                _ if matches!(rest, "paper" | "circle" | "square") => {
                    Request::RunBuiltin(rest.into())
                }
                _ => {
                    return Err(format!(
                        "run what? {rest:?} (paper, circle, square, moves ..., program <file>, \
                         experiment <kind> [key=value ...])"
                    ))
                }
            }
        }
        o => return Err(format!("unknown command {o:?}")),
    })
}

/// The run number of a `run` request's reply (`run N (name) started; ...`).
pub fn started_run(reply: &str) -> Option<u32> {
    let rest = reply.strip_prefix("run ")?;
    let (n, tail) = rest.split_once(' ')?;
    tail.contains("started").then(|| n.parse().ok()).flatten()
}

/// Sends one request and returns the reply (client side).
pub fn request(socket: &Path, line: &str) -> std::io::Result<String> {
    let mut s = UnixStream::connect(socket)?;
    s.set_read_timeout(Some(Duration::from_secs(5)))?;
    writeln!(s, "{line}")?;
    s.shutdown(std::net::Shutdown::Write)?;
    let mut out = String::new();
    for l in BufReader::new(s).lines() {
        out.push_str(&l?);
        out.push('\n');
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_requests() {
        assert_eq!(parse("status").unwrap(), Request::Status);
        assert_eq!(parse("verdict 12").unwrap(), Request::Verdict(12));
        assert_eq!(
            parse("run experiment calibration points=3 phis-deg=0,10").unwrap(),
            Request::RunExperiment {
                kind: "calibration".into(),
                options: vec![
                    ("points".into(), "3".into()),
                    ("phis-deg".into(), "0,10".into())
                ]
            }
        );
        assert!(parse("run experiment calibration points").is_err());
        assert!(parse("verdict x").is_err());
        assert_eq!(
            started_run("run 3 (moves) started; recording out/x.csv\n"),
            Some(3)
        );
        assert_eq!(started_run("error: a run is in progress"), None);
        assert_eq!(
            parse("run paper").unwrap(),
            Request::RunBuiltin("paper".into())
        );
        let Request::RunMoves(m) =
            parse("run moves line 10 0 0 20; dwell 1; circle 0 0 30 40").unwrap()
        else {
            panic!()
        };
        assert_eq!(m.len(), 3);
        assert!(parse("run moves line 1 2").is_err());
        assert_eq!(
            parse("run program configs/programs/slot.toml").unwrap(),
            Request::RunProgram("configs/programs/slot.toml".into())
        );
        assert!(parse("run program").is_err());
        assert!(parse("fly").is_err());
    }
}
