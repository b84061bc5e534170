#!/usr/bin/env bash
# No import circles between the modules of a crate (scripts/module_cycles.py; STYLE.md).
set -euo pipefail
cd "$(dirname "$0")/.."
python3 scripts/module_cycles.py .
