#!/usr/bin/env bash
# Conformance of the project's QTM simulator with the official Qualisys Python SDK (qtm-rt):
# `pcr qtm serve` on the simulated plant, qtm_rt connects, reads the parameters, streams 6DOF
# and 3D frames and compares them with the plant's truth (scripts/qtm_rt_conformance.py).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=.venv/bin/python
[ -x "$PY" ] || PY=python3
if [ -z "${PCR_BIN:-}" ]; then
  cargo build --release -q --bin pcr
  export PCR_BIN="$PWD/target/release/pcr"
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$PY" scripts/qtm_rt_conformance.py --pcr "$PCR_BIN" --workdir "$work"
