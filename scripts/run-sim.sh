#!/usr/bin/env bash
# The main job: the whole stack (planner, IK, driver, mocap processes over iceoryx2, started and
# watched by the supervisor) on the simulated plant; runs the paper's circle and square, prints
# the path accuracy and writes the recording and a figure (out/recordings/).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -q -p pcr-nodes -p pcr-supervisor
exec target/release/pcr-supervisor --config configs/sim.toml --run paper "$@"
