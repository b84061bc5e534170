#!/usr/bin/env bash
# Regenerates the measured reports quoted in the documentation (docs/calibration.md,
# docs/residuals.md, docs/loop-run/, BENCHMARKS.md): the paper's workflow and the measuring loop
# on the simulated plant. About a minute on one core. Recordings stay in out/.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -q --bin pcr
P=target/release/pcr
mkdir -p out/paper
$P experiment calibration --config configs/sim.toml --out out/paper/calibration.csv
$P calibrate --data out/paper/calibration.csv --out out/paper/calibrated.toml \
  --report out/paper/calibration --json out/paper/calibration.json
$P evaluate --config configs/sim.toml --calibrated out/paper/calibrated.toml \
  --report out/paper/evaluation --json out/paper/evaluation.json
cp out/paper/calibration/table1.svg docs/figures/calibration_table1.svg
rm -rf out/loop
$P loop --config configs/sim.toml --out out/loop
rm -rf docs/loop-run
mkdir -p docs/loop-run
cp -r out/loop/. docs/loop-run/
find docs/loop-run -name '*.csv' -delete
echo "docs/figures/calibration_table1.svg and docs/loop-run/ regenerated"
