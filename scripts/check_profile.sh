#!/usr/bin/env bash
# Compares the in-house profiler (`pcr profile`) against ruckig on seeded random case sets.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=.venv/bin/python
[ -x "$PY" ] || PY=python3
if [ -z "${PCR_BIN:-}" ]; then
  cargo build --release -q --bin pcr
  export PCR_BIN="$PWD/target/release/pcr"
fi
"$PY" scripts/profile_compare.py "$@"
