#!/usr/bin/env bash
# The validation sweep's time rule (scripts/validate_residuals.py): a run over the budget is
# judged on the median of three timings alone (scripts/test_validate_timing.py; no analysis is
# run, a second or so).
set -euo pipefail
cd "$(dirname "$0")/.."
exec python3 scripts/test_validate_timing.py -v
