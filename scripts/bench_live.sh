#!/usr/bin/env bash
# What the live view costs the chain (BENCHMARKS.md, "Live view"): the paper program under the
# supervisor (release, configs/sim.toml with its real-time settings: SCHED_FIFO, chain on CPU 1)
# three times: no viewer, a viewer reading every channel, a viewer subscribed to every channel
# that stops reading. Prints each process's deadline misses, cycle and wake-up latency
# percentiles (its heartbeat, `ctl status` after the run) and the supervisor's CPU time.
# Usage: bash scripts/bench_live.sh [target/release]
set -euo pipefail
cd "$(dirname "$0")/.."
BIN="${1:-target/release}"
PY=.venv/bin/python
[ -x "$PY" ] || { echo "bench_live: $PY missing: run scripts/setup.sh" >&2; exit 1; }
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
for case in none reading stalled; do
  prefix="pcrbl$$${case}_"
  sed -e "s/^iceoryx2_prefix = .*/iceoryx2_prefix = \"$prefix\"/" \
      -e "s|^recording_dir = .*|recording_dir = \"$TMP/rec-$case\"|" \
      -e "s/^port = 8765 .*/port = 0/" configs/sim.toml > "$TMP/$case.toml"
  "$BIN/pcr-supervisor" --config "$TMP/$case.toml" > "$TMP/$case.out" 2> "$TMP/$case.err" &
  sup=$!
  url=""
  for _ in $(seq 1 100); do
    url=$(grep -o 'ws://[0-9.:]*' "$TMP/$case.err" | head -1 || true)
    [ -n "$url" ] && "$BIN/pcr-supervisor" --config "$TMP/$case.toml" ctl status 2>/dev/null \
      | grep -q '^state: ready' && break
    sleep 0.2
  done
  client=""
  case $case in
    reading) "$PY" tests/py/live_client.py "$url" --all --seconds 40 > "$TMP/client.json" & client=$! ;;
    stalled) "$PY" tests/py/live_client.py "$url" --all --stall --seconds 40 > "$TMP/client.json" & client=$! ;;
  esac
  sleep 1
  "$BIN/pcr-supervisor" --config "$TMP/$case.toml" ctl run paper > /dev/null
  for _ in $(seq 1 600); do
    status=$("$BIN/pcr-supervisor" --config "$TMP/$case.toml" ctl status)
    echo "$status" | grep -q '^last run: 1 (paper)' && break
    sleep 0.2
  done
  cpu=$(awk '{printf "%.2f", ($14+$15)/100}' /proc/$sup/stat)
  echo "== $case: supervisor CPU ${cpu} s (whole life); $(date -u +%H:%M) UTC; load $(cut -d' ' -f1-3 /proc/loadavg)"
  echo "$status" | grep -E '^(process|last run|live)'
  "$BIN/pcr-supervisor" --config "$TMP/$case.toml" ctl shutdown > /dev/null
  wait "$sup" || true
  [ -n "$client" ] && { kill "$client" 2>/dev/null || true; wait "$client" 2>/dev/null || true; }
  grep -h 'outbox' "$TMP/$case.err" || true
done
