#!/usr/bin/env bash
# Every command shown in README.md and docs/*.md works: scripts/doc_commands.py reads them from
# the markdown and runs each one (or the smaller or concrete form, the test that covers it, or
# the reason it is not run, that scripts/doc_commands.toml gives) in a scratch directory with the
# release `pcr`. A new command in the docs is run as written; one that fails fails the check.
# About two minutes on two cores. Options go to doc_commands.py (--only TEXT, --keep, --list).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=.venv/bin/python
[ -x "$PY" ] || PY=python3
if [ -z "${PCR_BIN:-}" ]; then
  cargo build --release -q --bin pcr
  PCR_BIN="${CARGO_TARGET_DIR:-$PWD/target}/release/pcr"
fi
"$PY" scripts/doc_commands.py --self-test
exec "$PY" scripts/doc_commands.py --pcr "$PCR_BIN" "$@"
