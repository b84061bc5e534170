#!/usr/bin/env bash
# The Python package `pcr` (python/): builds it with maturin (release, in the workspace's
# target/) and installs it into the venv, runs its tests (python/tests, pytest: results equal
# the release `pcr` tool's on the same inputs; bad inputs raise) and executes the notebook
# docs/notebooks/calibration.ipynb with nbclient on a small calibration set, so that neither
# can rot.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=.venv/bin/python
[ -x "$PY" ] || { echo "check_python: $PY missing: run scripts/setup.sh" >&2; exit 1; }
# maturin (the build backend) is the venv's, pinned in scripts/requirements.txt.
export PATH="$PWD/.venv/bin:$PATH"
start=$(date +%s)
"$PY" -m pip install -q --no-build-isolation ./python
echo "check_python: pip install ./python in $(( $(date +%s) - start )) s"
if [ -z "${PCR_BIN:-}" ]; then
  cargo build --release -q --bin pcr
  export PCR_BIN="${CARGO_TARGET_DIR:-$PWD/target}/release/pcr"
fi
"$PY" -m pytest -q python/tests
start=$(date +%s)
PCR_NOTEBOOK_POINTS=5 "$PY" scripts/run_notebook.py docs/notebooks/calibration.ipynb
echo "check_python: notebook executed in $(( $(date +%s) - start )) s"
