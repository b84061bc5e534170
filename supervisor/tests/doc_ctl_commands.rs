//! Every `pcr-supervisor ... ctl ...` command shown in README.md and docs/*.md is one the
//! supervisor accepts: its configuration loads, the request parses as the supervisor parses it,
//! an experiment's options are valid and a program file exists. The commands are read from the
//! markdown, so a new one is checked as soon as it is written (scripts/check_doc_commands.sh
//! names this test for them). Running them on a live chain is the job of
//! tests/tests/chain_supervisor.rs and chain_program.rs.

use pcr_supervisor::ctl::{self, Request};
use pcr_supervisor::{experiment, SupervisorConfig};
use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn doc_files() -> Vec<PathBuf> {
    let mut v = vec![repo().join("README.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(repo().join("docs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
        .collect();
    docs.sort();
    v.extend(docs);
    v
}

/// A documented ctl command: where, the configuration argument and the request words.
#[derive(Debug)]
struct CtlCommand {
    at: String,
    config: String,
    words: String,
}

/// The ctl commands of one markdown text: `pcr-supervisor --config X ctl WORDS` up to the end
/// of the code span, the shell comment or the line (a trailing `\` continues it).
fn ctl_commands(file: &str, text: &str) -> Vec<CtlCommand> {
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::new();
    let mut k = 0;
    while k < lines.len() {
        let mut line = lines[k].to_string();
        let at = format!("{file}:{}", k + 1);
        while line.trim_end().ends_with('\\') && k + 1 < lines.len() {
            line = line.trim_end().trim_end_matches('\\').to_string() + " " + lines[k + 1];
            k += 1;
        }
        k += 1;
        let mut rest = line.as_str();
        while let Some(i) = rest.find("pcr-supervisor --config ") {
            let after = &rest[i + "pcr-supervisor --config ".len()..];
            let end = after.find(['`', '#']).unwrap_or(after.len());
            let cmd = &after[..end];
            rest = &after[end..];
            let Some((config, words)) = cmd.split_once(" ctl ") else {
                continue;
            };
            out.push(CtlCommand {
                at: at.clone(),
                config: config.trim().to_string(),
                words: words.split_whitespace().collect::<Vec<_>>().join(" "),
            });
        }
    }
    out
}

/// The requests a documented command stands for: `status|run paper|pause` is three; shell
/// quotes are the shell's (the client joins the words with spaces).
fn requests(words: &str) -> Vec<String> {
    if words.contains('"') {
        return vec![words.replace('"', "")];
    }
    words.split('|').map(|w| w.trim().to_string()).collect()
}

#[test]
fn every_documented_ctl_command_parses() {
    let mut checked = 0;
    let mut problems = Vec::new();
    for f in doc_files() {
        let text = std::fs::read_to_string(&f).unwrap();
        let name = f.strip_prefix(repo()).unwrap_or(&f).display().to_string();
        for c in ctl_commands(&name, &text) {
            let config = repo().join(&c.config);
            // `--config C` stands for any configuration.
            if c.config.ends_with(".toml") {
                if let Err(e) = SupervisorConfig::load(&config) {
                    problems.push(format!("{}: --config {}: {e}", c.at, c.config));
                }
            }
            for r in requests(&c.words) {
                checked += 1;
                match ctl::parse(&r) {
                    Ok(Request::RunExperiment { kind, options }) => {
                        if let Err(e) = experiment::spec(&kind, &options) {
                            problems.push(format!("{}: ctl {r}: {e}", c.at));
                        }
                    }
                    Ok(Request::RunProgram(file)) => {
                        if !repo().join(&file).is_file() {
                            problems.push(format!("{}: ctl {r}: no file {}", c.at, file.display()));
                        }
                    }
                    Ok(_) => {}
                    Err(e) => problems.push(format!("{}: ctl {r}: {e}", c.at)),
                }
            }
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
    // README and docs/chain.md, calibration.md, experiments.md show more than a dozen.
    assert!(
        checked >= 12,
        "only {checked} ctl requests found in the docs"
    );
}

#[test]
fn the_extractor_reads_spans_alternatives_quotes_and_continuations() {
    let text = "Run `pcr-supervisor --config configs/sim.toml ctl status|run paper` now.\n\
                \x20   pcr-supervisor --config C ctl run moves \"line 1 2 0 30; dwell 1\"  # comment\n\
                \x20   pcr-supervisor --config c.toml ctl run experiment calibration \\\n\
                \x20       points=6 seed=2\n\
                \x20   pcr-supervisor --config c.toml --run paper\n";
    let c = ctl_commands("x.md", text);
    assert_eq!(c.len(), 3, "{c:?}");
    assert_eq!(requests(&c[0].words), ["status", "run paper"]);
    assert_eq!(c[0].at, "x.md:1");
    assert_eq!(c[1].config, "C");
    assert_eq!(requests(&c[1].words), ["run moves line 1 2 0 30; dwell 1"]);
    assert_eq!(c[2].words, "run experiment calibration points=6 seed=2");
    assert_eq!(c[2].at, "x.md:3");
    // And a bad request is refused as the supervisor refuses it.
    assert!(ctl::parse("run everything").is_err());
}
