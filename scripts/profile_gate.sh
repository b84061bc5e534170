#!/usr/bin/env bash
# Pre-commit gate of the planner work: format (own files), lint and tests of pcr-planner / pcr.
set -euo pipefail
cd "$(dirname "$0")/.."
rustfmt --edition 2021 --check planner/src/lib.rs planner/src/*/*.rs planner/tests/*.rs \
  planner/benches/*.rs pcr/src/profile.rs
cargo clippy -q -p pcr-planner -p pcr --all-targets -- -D warnings
out=$(cargo test -q -p pcr-planner 2>&1) || { echo "$out"; exit 1; }
echo "$out" | grep -E "^test result"
echo "gate: ok"
