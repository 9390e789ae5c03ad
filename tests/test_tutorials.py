"""The tutorials (docs/tutorials): each source executes without an error, and its committed notebook is that source
with the outputs of an execution (tools/tutorials.py), which the site shows."""

from __future__ import annotations

import time

import jupytext
import nbformat
import pytest
from conftest import ROOT

SOURCES = sorted((ROOT / "docs" / "tutorials").glob("*.py"))


def cells(notebook) -> list[tuple[str, str]]:
    """(type, source) of each cell."""
    return [(c.cell_type, c.source) for c in notebook.cells]


def figures(notebook) -> int:
    """The PNG figures among a notebook's outputs."""
    return sum("image/png" in o.get("data", {}) for c in notebook.cells for o in c.get("outputs", []))


def test_both_tutorials_are_there(load_tool):
    assert [p.name for p in SOURCES] == ["01_first_run.py", "02_committed_runs.py"]
    assert load_tool("tools/tutorials").sources() == SOURCES


@pytest.mark.parametrize("source", SOURCES, ids=lambda p: p.stem)
def test_the_committed_notebook_is_its_source_executed(source):
    stored = nbformat.read(source.with_suffix(".ipynb"), as_version=4)
    assert cells(stored) == cells(jupytext.read(source)), "run python tools/tutorials.py and commit both"
    code = [c for c in stored.cells if c.cell_type == "code"]
    assert all(c.execution_count is not None for c in code), "stored without being executed"
    assert not [o for c in code for o in c.outputs if o.output_type == "error"]
    assert figures(stored) > 0


@pytest.mark.slow
@pytest.mark.parametrize("source", SOURCES, ids=lambda p: p.stem)
def test_the_tutorial_runs(source, load_tool):
    runs = sorted(p.name for p in (ROOT / "runs").iterdir())
    start = time.perf_counter()
    executed = load_tool("tools/tutorials").execute(source)  # raises at the first cell that does
    print(f"{source.name}: {time.perf_counter() - start:.0f} s")
    # Every figure the committed notebook shows is drawn again, and nothing was trained into the repository.
    assert figures(executed) == figures(nbformat.read(source.with_suffix(".ipynb"), as_version=4))
    assert sorted(p.name for p in (ROOT / "runs").iterdir()) == runs
