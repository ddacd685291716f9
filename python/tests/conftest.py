"""Shared fixtures: the repository, the command built beside the package
(for the tests that compare the two), and the data sets beside it."""

import os
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def repo() -> Path:
    """The repository's root."""
    return REPO


@pytest.fixture(scope="session")
def cli() -> Path:
    """The `robcal` command: $ROBCAL_CLI, else target/debug/robcal (built
    by `cargo test --features cli`). CI sets ROBCAL_CLI: missing there, the
    comparisons fail instead of skipping."""
    path = os.environ.get("ROBCAL_CLI")
    if path:
        return Path(path)
    path = REPO / "target" / "debug" / "robcal"
    if not path.is_file():
        pytest.skip("no robcal command: build it (cargo build --features cli) or set ROBCAL_CLI")
    return path


@pytest.fixture(scope="session")
def shared() -> Path:
    """../shared (the real data sets); skipped without it unless
    ROBCAL_REQUIRE_SHARED is set (CI)."""
    path = REPO.parent / "shared"
    if not (path / "datasets").is_dir():
        if os.environ.get("ROBCAL_REQUIRE_SHARED"):
            pytest.fail("ROBCAL_REQUIRE_SHARED is set but ../shared/datasets is missing")
        pytest.skip("../shared/datasets is not beside the repository")
    return path


def run(cli: Path, *args: str, cwd: Path = REPO) -> str:
    """The command's stdout; its failure fails the test."""
    r = subprocess.run([str(cli), *args], cwd=cwd, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return r.stdout
