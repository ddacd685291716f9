"""docs/python.md runs as written: its Python blocks, in order, in one
namespace, from the repository's root (matplotlib without a display)."""

import re

import matplotlib
import pytest

matplotlib.use("Agg")


def test_the_python_page_runs_as_written(repo, shared, monkeypatch):
    text = (repo / "docs" / "python.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert len(blocks) >= 6
    monkeypatch.chdir(repo)
    namespace: dict = {}
    for i, code in enumerate(blocks):
        try:
            exec(compile(code, f"docs/python.md block {i + 1}", "exec"), namespace)
        except Exception as e:  # the block that failed, named
            pytest.fail(f"docs/python.md block {i + 1}: {type(e).__name__}: {e}")
    # What the page says it shows.
    assert namespace["c"].error_um.max() < 0.1
    assert namespace["v"]["rms_mm"] < 4.0
    assert list(namespace["small"].names) == ["k_a2", "k_a3"]
    assert namespace["p"].q.shape == (12, 6)


def test_the_readmes_python_block_runs_as_written(repo, monkeypatch):
    blocks = re.findall(r"```python\n(.*?)```", (repo / "README.md").read_text(), flags=re.S)
    assert len(blocks) == 1
    monkeypatch.chdir(repo)
    namespace: dict = {}
    exec(compile(blocks[0], "README.md's Python block", "exec"), namespace)
    assert namespace["result"].failure is None
