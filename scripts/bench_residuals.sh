#!/usr/bin/env bash
# Per-effect benchmark of `pcr residuals` (BENCHMARKS.md "Residual analysis per effect").
#
# For each effect of the plant (and clean data) it derives a plant file from
# configs/plant-ideal.toml (capture noise on, one effect on), records a calibration recording
# (`pcr experiment calibration`, about 37-44k rows) and a holdout (about 16k rows, `--points 8
# --test-per-group 3 --plant-seed 7 --seed 2`) once, then times
# `pcr residuals --data cal.csv --holdout holdout.csv` with scripts/inturn.py on one core (`--pin 1`)
# and on two (no pin), and prints a table: median wall and cpu, s; peak memory, MiB; what the analysis found.
#
# Usage: scripts/bench_residuals.sh [PCR_BINARY] [OUT_DIR] [EFFECT ...]
#   PCR_BINARY  the pcr to time (default target/release/pcr; also records the data)
#   OUT_DIR     where plant files, recordings and results go (default out/bench-residuals)
#   EFFECT      a subset of: clean backlash latency creep drift springs load frame
# Environment: RUNS (scripts/inturn.py runs, default 3), WARMUP (runs not counted, default 1), TIMEOUT (scripts/inturn.py bound, s, default 900),
# RECORDER (the pcr that records the data, default PCR_BINARY).
# Not a check (CI does not run it): it takes minutes and its numbers depend on the machine.
set -euo pipefail
cd "$(dirname "$0")/.."
PCR=$(realpath "${1:-target/release/pcr}")
OUT=${2:-out/bench-residuals}
shift $(( $# > 2 ? 2 : $# )) || true
EFFECTS=("$@")
[ ${#EFFECTS[@]} -gt 0 ] || EFFECTS=(clean backlash latency creep drift springs load frame)
RUNS=${RUNS:-3}
WARMUP=${WARMUP:-1}
TIMEOUT=${TIMEOUT:-900}
RECORDER=$(realpath "${RECORDER:-$PCR}")
mkdir -p "$OUT"
OUT=$(realpath "$OUT")
ROOT=$(pwd)

# set_key FILE SECTION KEY VALUE: sets `KEY = VALUE` in `[SECTION]` of a TOML file.
set_key() {
    awk -v sec="[$2]" -v key="$3" -v val="$4" '
        /^\[/ { cur = $1 }
        cur == sec && $1 == key && $2 == "=" { sub(/=[^#]*/, "= " val " ") }
        { print }' "$1" >"$1.tmp" && mv "$1.tmp" "$1"
}

plant_file() {
    local e=$1 f="$OUT/plant-$1.toml"
    cp "$ROOT/configs/plant-ideal.toml" "$f"
    set_key "$f" capture noise true
    # configs/sim.toml declares a 10 ms capture latency (its recordings align each measurement
    # with its capture time): the plant has it, so that only the effect is left to find.
    set_key "$f" capture latency_s 0.01
    case $e in
        clean) ;;
        backlash)
            set_key "$f" stepper backlash true
            set_key "$f" stepper backlash_steps "[3.0, 4.0, 3.0]" ;;
        latency) set_key "$f" capture latency_s 0.05 ;;  # 40 ms beyond the declared 10
        creep)
            set_key "$f" creep enabled true
            set_key "$f" creep compliance_mm_per_n 2.0e-3
            set_key "$f" creep time_constant_s 20.0 ;;
        drift)
            set_key "$f" drift enabled true
            set_key "$f" drift rate_mm_per_s "[0.0, 3.0e-4, 0.0]" ;;
        springs)
            set_key "$f" mechanics k_m_n_mm_per_rad 300.0
            set_key "$f" mechanics k_p_n_mm_per_rad 200.0 ;;
        load)
            set_key "$f" external_wrench fx_n 0.4
            set_key "$f" external_wrench fy_n -0.3 ;;
        frame)
            set_key "$f" capture registration_error_dx_mm 0.8
            set_key "$f" capture registration_error_dphi_deg 0.3 ;;
        *) echo "unknown effect $e" >&2; exit 2 ;;
    esac
    echo "$f"
}

# median WHAT <scripts/inturn.py output: the median of its "A wall s", "A cpu s" or "A peak MiB"
# line (who, figure, unit, min, median, max: the fifth field).
median() {
    awk -v what="$1" '$1 == "A" && $2 == what { print $5; exit }'
}

# found JSON: the verdict and the effects named, with their first parameters.
found() {
    python3 -c '
import json, sys
r = json.load(open(sys.argv[1]))
e = ", ".join(x["name"] + " " + " / ".join("%.4g" % p["value"] for p in x["params"][:3]) for x in r["effects"])
print("%s: %s" % (r["verdict"], e or "nothing"))' "$1" 2>/dev/null || echo "?"
}

printf '| effect | rows (cal + holdout) | wall 1 core (s) | cpu 1 core (s) | wall 2 cores (s) | cpu 2 cores (s) | peak (MiB) | found |\n'
printf '|---|---:|---:|---:|---:|---:|---:|---|\n'
for e in "${EFFECTS[@]}"; do
    d="$OUT/$e"
    mkdir -p "$d"
    if [ ! -s "$d/cal.csv" ] || [ ! -s "$d/holdout.csv" ]; then
        plant=$(plant_file "$e")
        "$RECORDER" experiment calibration --config configs/sim.toml --plant "$plant" \
            --out "$d/cal.csv" >"$d/record.log" 2>&1
        "$RECORDER" experiment calibration --config configs/sim.toml --plant "$plant" \
            --points 8 --test-per-group 3 --plant-seed 7 --seed 2 \
            --out "$d/holdout.csv" >>"$d/record.log" 2>&1
    fi
    rows=$(( $(grep -vc '^#' "$d/cal.csv") - 1 ))
    hrows=$(( $(grep -vc '^#' "$d/holdout.csv") - 1 ))
    tag=$(basename "$PCR")
    cmd=("$PCR" residuals --robot "$ROOT/configs/robot.toml" --data "$d/cal.csv"
         --holdout "$d/holdout.csv" --json "$d/res-$tag.json")
    (cd "$d" && "$ROOT/scripts/inturn.py" -n "$RUNS" --warmup "$WARMUP" --timeout "$TIMEOUT" --pin 1 -- "${cmd[@]}") >"$d/bench1-$tag.txt" 2>&1 || true
    (cd "$d" && "$ROOT/scripts/inturn.py" -n "$RUNS" --warmup "$WARMUP" --timeout "$TIMEOUT" -- "${cmd[@]}") >"$d/bench2-$tag.txt" 2>&1 || true
    w1=$(median wall <"$d/bench1-$tag.txt"); c1=$(median cpu <"$d/bench1-$tag.txt")
    w2=$(median wall <"$d/bench2-$tag.txt"); c2=$(median cpu <"$d/bench2-$tag.txt")
    pk=$(median peak <"$d/bench1-$tag.txt")
    printf '| %s | %s + %s | %s | %s | %s | %s | %s | %s |\n' "$e" "$rows" "$hrows" "$w1" "$c1" "$w2" "$c2" "$pk" "$(found "$d/res-$tag.json")"
done
