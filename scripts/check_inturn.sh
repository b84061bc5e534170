#!/usr/bin/env bash
# The in-turn timing harness that BENCHMARKS.md's timings come from (scripts/inturn.py): run for
# real on tiny commands (scripts/test_inturn.py; `sleep` and `python3 -c`, a dozen seconds).
set -euo pipefail
cd "$(dirname "$0")/.."
exec python3 scripts/test_inturn.py -v
