#!/usr/bin/env bash
# The reduced validation sweep of `pcr residuals` with its rules (docs/residuals.md,
# "Validation"): every effect of the library at its test strength and 3x, a pair that mimics, a
# triple, drift at 0.002 mm/s over 712 s, cross-coupling 7 %, the temperature cycle, the clean
# plant, in both timing conventions; it fails when an effect at its test strength or more is not
# named or a parameter is off by more than 3 stated standard errors, when anything outside the
# vocabulary or not in the data is named, or when the held-out error stays above 1.5x the floor.
# The time rule is off here (--time-budget-s 0): times are measured by the full sweep and in
# BENCHMARKS.md, not gated on a shared CI machine. A few minutes on two cores, recordings
# included (cached in out/validate-residuals-reduced).
set -euo pipefail
cd "$(dirname "$0")/.."
exec bash scripts/validate_residuals.sh --reduced --check --jobs 2 --time-budget-s 0 "$@"
