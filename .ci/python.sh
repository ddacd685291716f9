#!/usr/bin/env bash
# robcal from Python (python/): the extension module built by cargo beside
# the package's Python files (target/python-pkg), in a venv of its own
# (target/python-venv), then its pytest suite, which compares it with the
# command built by the test step (target/debug/robcal) and runs
# docs/python.md's code as written.
#
# The module is the one `maturin develop` builds (the same crate, profile
# and flags; PYO3_BUILD_EXTENSION_MODULE is what maturin sets), built with
# the test step's packages and features: `--all-targets` resolves the
# shared dependencies' features as `cargo test` does, so the library is not
# built a second time (maturin builds the package alone: its features
# differ, and so did its build of the library, ~90 s of a CI run). Users
# install with pip (docs/python.md), which runs maturin.
#
# .ci/run makes the venv beside the builds (.ci/python-venv.sh); run alone,
# this makes it when it is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

venv=target/python-venv
if [ ! -x "$venv/bin/python" ]; then
    bash .ci/python-venv.sh
fi
# shellcheck disable=SC1091
source "$venv/bin/activate"
# The command the tests compare with: the test step's build (the README
# test command's packages and features); then the module.
cargo test --workspace --features cli --no-run --quiet
PYO3_BUILD_EXTENSION_MODULE=1 cargo build --workspace --features cli --all-targets --quiet
pkg=target/python-pkg
rm -rf "$pkg"
mkdir -p "$pkg/robcal"
cp python/robcal/*.py python/robcal/*.pyi python/robcal/py.typed "$pkg/robcal/"
cp target/debug/lib_robcal.so "$pkg/robcal/_robcal.abi3.so"
export PYTHONPATH="$PWD/$pkg" ROBCAL_CLI="$PWD/target/debug/robcal" MPLBACKEND=Agg
python -m pytest -q -p no:cacheprovider python/tests
