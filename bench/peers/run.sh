#!/usr/bin/env bash
# Peer benchmark of issue 16: the paper's KR-270 iterative WLS (OLS start,
# eq. 14 weights per configuration and axis, WLS refits to 1e-3 σ, sandwich
# covariance) in robcal, numpy and statsmodels on exactly the same 810 × 9
# problem, interleaved A B C A B C … in one invocation, medians and ratios.
#
#   bench/peers/run.sh [--rounds R] [--quick] [--before BIN]
#
# With --stream, the streaming update instead (issue 16, item 3): 10^6
# weighted blocks at N = 9, 30, 60 into robcal's scalar core accumulator,
# its SIMD WideAccumulator and numpy's normal equations, with the machine's
# FMA peak through robcal's run-time dispatch, interleaved:
#
#   bench/peers/run.sh --stream [--sizes 9,30,60] [--stream-rounds R] [--quick]
#
# numpy runs on one BLAS thread (robcal's update is one thread), unless
# PEERS_BLAS_THREADS says otherwise.
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

if [ "${1:-}" = "--stream" ]; then
  cargo build --release -p host-tests --example stream_timing
  bin=$target/release/examples/stream_timing
  sizes=9,30,60
  args=("$@")
  for ((i = 0; i < ${#args[@]}; i++)); do
    [ "${args[i]}" = "--sizes" ] && sizes=${args[i + 1]}
  done
  for n in ${sizes//,/ }; do
    "$bin" export "$data" "$n"
  done
  export OPENBLAS_NUM_THREADS=${PEERS_BLAS_THREADS:-1}
  exec "$venv/bin/python" "$root/bench/peers/peers.py" --data "$data" --stream "$bin" "${@:2}"
fi

cargo build --release -p host-tests --example kr270_irls_timing
bin=$target/release/examples/kr270_irls_timing
"$bin" export "$data"
exec "$venv/bin/python" "$root/bench/peers/peers.py" --robcal "$bin" --data "$data" "$@"
