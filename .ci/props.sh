#!/usr/bin/env bash
# Bounded property run (issue 8): the stable equivalents of the fuzz targets
# and the batch-equality properties, with more cases than the default
# `cargo test`. Bounded by PROPTEST_CASES and by `timeout` (≤ 2 minutes
# after the build). Usage: bash .ci/props.sh [cases]  (default 20000)
set -euo pipefail
cd "$(dirname "$0")/.."
cases="${1:-20000}"
# The README test command's packages and features: its build, reused (the
# features of shared dependencies are resolved over the packages a command
# builds: `-p host-tests` alone would build the library again).
features=(--workspace --features cli)
cargo test "${features[@]}" --no-run --quiet
PROPTEST_CASES="$cases" timeout 60 cargo test "${features[@]}" --quiet --test host -- fuzz_props:: fuzz_regressions::
# The parser fuzz findings and a replay of the kept parser corpora
# (fuzz/corpus/{csv_measurements,setup_toml,urdf}) on stable: a few seconds.
timeout 30 cargo test "${features[@]}" --quiet --test host -- fuzz_io_regressions::
# The batch-equality properties: a tenth of the cases (each solves an SVD).
PROPTEST_CASES="$((cases / 10))" timeout 60 cargo test "${features[@]}" --quiet --test host -- accumulator_props::
