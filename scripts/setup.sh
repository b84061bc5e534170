#!/usr/bin/env bash
# Installs everything the stack and its tests need on a fresh Debian machine:
# the AVR toolchain and simavr (firmware tests), and a Python venv with the reference
# implementations used by the comparison tests (ruckig) and what the Python package needs to be
# built, tested and its notebook executed (maturin, pandas, pytest, nbclient, ...;
# scripts/check_python.sh installs the package itself). Safe to run repeatedly.
set -euo pipefail
cd "$(dirname "$0")/.."

APT_PKGS=(gcc-avr avr-libc simavr libsimavr-dev libelf-dev pkg-config)
missing=()
for p in "${APT_PKGS[@]}"; do
  dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  SUDO=""
  [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  echo "setup: installing ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

if [ ! -x .venv/bin/python ]; then
  python3 -m venv .venv
fi
.venv/bin/pip install -q -r scripts/requirements.txt
