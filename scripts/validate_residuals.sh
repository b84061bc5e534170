#!/usr/bin/env bash
# Validation sweep of `pcr residuals` (docs/residuals.md, "Validation"): the residual analysis
# run like a measuring instrument on recordings of the simulated plant with known effects at
# known strengths, in both timing conventions, and how well it finds them.
#
# For each case (every effect of the library at four strengths, from below detection to 10x
# today's test value or the largest the plant holds; drift at 0.002 mm/s over the ~880 s
# calibration recording; pairs that mimic each other and others; triples; effects outside the
# library: cross-coupling at 3, 7, 15 % and the lab's temperature cycle; the clean plant) and
# plant seed it writes the plant file, records a calibration recording, a holdout and the
# holdout's noise-free twin with `pcr experiment calibration` (cached in OUT: a re-run only
# re-analyses), writes the position-reached convention of both recordings, runs `pcr residuals`
# on both conventions pinned to one core (`taskset`), and compares what was named with the truth.
# Writes OUT/validation.md (detection limits, the aggregate per case, every run), OUT/runs.csv
# (one row per run and parameter) and OUT/validation.json.
#
# Usage: scripts/validate_residuals.sh [--reduced] [--check] [--jobs N] [--seeds 1,2,3]
#            [--only REGEX] [--out DIR] [--pcr PATH] [--recorder PATH] [--reuse] [--list]
#            [--no-two-cores] [--max-z 3] [--max-after-floor 1.5] [--time-budget-s 10]
#   --reduced   the CI subset: every effect at its test strength and 3x, one pair that mimics
#               (backlash + latency), one triple, joint springs at 10x and with a load at 3x,
#               cross-coupling 7 %, the temperature cycle at
#               0.03 mm, drift 0.002 mm/s (full-size recordings), the clean plant; seed 1; small
#               recordings (calibration --points 6, holdout --points 4); default OUT
#               out/validate-residuals-reduced (full: out/validate-residuals, seeds 1,2,3)
#   --check     exit 1 when a rule fails, printing every failure by rule: an effect of the
#               library at >= its test strength not named, or a parameter of it off by more than
#               --max-z stated standard errors; anything named outside the vocabulary; an effect
#               named that is not in the data; held-out after/floor above --max-after-floor
#               (cases with library effects only, at >= test strength, and the clean plant); a
#               full-size analysis above --time-budget-s of cpu on one core (pinned; 0: no time rule;
#               a run over it is timed again alone, pinned, the other cores idle, three times, and
#               the rule reads the median of those; the table shows both)
#   --jobs N    cases in parallel, each pinned to its own core (default 1: core 1)
#   --reuse     report again from the analyses of an earlier run (no new analysis)
# Environment: PCR_VALIDATION_TIME_BUDGET_S (default 10); PCR_BIN, the pcr to run (default: the
# release build, made first, as the other scripts/check_*.sh do; --pcr overrides both). Takes long: the full sweep records about 150
# calibration recordings (hours on one core); the reduced one about 5 minutes on two cores.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=.venv/bin/python
[ -x "$PY" ] || PY=python3
case " $* " in
  *" --pcr "*|*" --list "*) exec "$PY" scripts/validate_residuals.py "$@" ;;
esac
if [ -z "${PCR_BIN:-}" ]; then
  cargo build --release -q -p pcr
  PCR_BIN="${CARGO_TARGET_DIR:-$PWD/target}/release/pcr"
fi
exec "$PY" scripts/validate_residuals.py --pcr "$PCR_BIN" "$@"
