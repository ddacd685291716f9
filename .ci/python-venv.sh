#!/usr/bin/env bash
# The venv .ci/python.sh builds and tests the Python package in, with
# python/requirements-ci.txt's packages (from PyPI; no byte-code compiled
# ahead: it runs beside the builds, and the tests import little of them).
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m venv --clear target/python-venv
target/python-venv/bin/pip install --quiet --disable-pip-version-check --no-compile -r python/requirements-ci.txt
