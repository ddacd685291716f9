#!/usr/bin/env bash
# Peer benchmark of issue 16: the paper's KR-270 iterative WLS (OLS start,
# eq. 14 weights per configuration and axis, WLS refits to 1e-3 σ, sandwich
# covariance) in robcal, numpy and statsmodels on exactly the same 810 × 9
# problem, interleaved A B C A B C … in one invocation, medians and ratios.
#
#   bench/peers/run.sh [--rounds R] [--quick] [--before BIN]
#
# Needs a Rust toolchain, python3 (with venv) and PyPI (numpy, statsmodels
# are installed into a venv under target/, once). Nothing else from the
# network. Environment: CARGO_TARGET_DIR as usual; PEERS_VENV to put the
# venv elsewhere.
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
cd "$root"
target=${CARGO_TARGET_DIR:-$root/target}
venv=${PEERS_VENV:-$root/target/peers-venv}
data=$root/target/peers-data

if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet --upgrade pip
  "$venv/bin/pip" install --quiet numpy statsmodels
fi

cargo build --release -p host-tests --example kr270_irls_timing
bin=$target/release/examples/kr270_irls_timing
"$bin" export "$data"
exec "$venv/bin/python" "$root/bench/peers/peers.py" --robcal "$bin" --data "$data" "$@"
