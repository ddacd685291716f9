#!/usr/bin/env bash
# robcal from Python (python/): builds the package with maturin into a
# venv of its own (target/python-venv), then runs its pytest suite, which
# compares it with the command built by the test step (target/debug/robcal)
# and runs docs/python.md's code as written.
#
# .ci/run makes the venv beside the builds (.ci/python-venv.sh); run alone,
# this makes it when it is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

venv=target/python-venv
if [ ! -x "$venv/bin/maturin" ]; then
    bash .ci/python-venv.sh
fi
# shellcheck disable=SC1091
source "$venv/bin/activate"
# The command the tests compare with: the test step's build (the README
# test command's packages and features).
cargo test --workspace --features cli --no-run --quiet
maturin develop --quiet --manifest-path python/Cargo.toml
export ROBCAL_CLI="$PWD/target/debug/robcal" MPLBACKEND=Agg
python -m pytest -q python/tests
