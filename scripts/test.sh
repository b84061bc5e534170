#!/usr/bin/env bash
# The project's test command (README): installs what the tests need, then runs format and lint
# checks, every Rust test, and the comparison scripts.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export PATH="$PWD/.venv/bin:$PATH"

cargo fmt --all -- --check
cargo clippy --workspace --all-targets --locked -- -D warnings
cargo test --workspace --locked
for t in scripts/check_*.sh; do
  [ -e "$t" ] || continue
  echo "== $t"
  bash "$t"
done
