#!/bin/bash
# robcal on robots it was not built on (tools/unseen/unseen.py): numpy and
# the pybullet 3.2.7 wheel's URDFs (PyPI) in a venv under target/unseen,
# the release build, 20 data sets per case. About two minutes.
set -euo pipefail
cd "$(dirname "$0")/../.."
V=target/unseen
if [ ! -x "$V/venv/bin/python" ]; then
  python3 -m venv "$V/venv"
  "$V/venv/bin/pip" -q install numpy==2.4.6
fi
if [ ! -d "$V/pybullet_data" ]; then
  "$V/venv/bin/pip" -q download pybullet==3.2.7 --no-deps -d "$V/wheel"
  (cd "$V" && unzip -q -o wheel/pybullet-3.2.7-*.whl 'pybullet_data/*')
fi
cargo build -q --release --features cli
"$V/venv/bin/python" tools/unseen/unseen.py "$PWD/target/release/robcal" "$PWD/$V/pybullet_data" "${1:-20}"
