#!/usr/bin/env bash
# The project's test command (README): installs what the tests need, then runs format and lint
# checks, every Rust test, and the comparison scripts.
set -euo pipefail
cd "$(dirname "$0")/.."
# Each stage's wall time is printed, so a slow CI run says where its time went.
stage() {
  local t0=$SECONDS
  echo "== $*"
  "$@"
  echo "== $* took $((SECONDS - t0)) s (total $SECONDS s)"
}
stage bash scripts/setup.sh
export PATH="$PWD/.venv/bin:$PATH"

stage cargo fmt --all -- --check
stage cargo clippy --workspace --all-targets --locked -- -D warnings
stage cargo test --workspace --locked
for t in scripts/check_*.sh; do
  [ -e "$t" ] || continue
  stage bash "$t"
done
