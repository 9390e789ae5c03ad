"""Execute the tutorials and store each with its outputs: docs/tutorials/NAME.py -> docs/tutorials/NAME.ipynb.

    python tools/tutorials.py                                     # every tutorial, about 2 minutes on 2 cores
    python tools/tutorials.py docs/tutorials/02_committed_runs.py # one

The .py files (jupytext percent scripts) are the sources, edited and reviewed as code. Each .ipynb is made from its
source and the outputs of one execution here, from the repository's root, in a fresh kernel; the site shows it as
it is (mkdocs-jupyter, `execute: false`), and tests/test_tutorials.py holds it equal to its source cell for cell and
executes each source again. Run this after editing a source and commit both files.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import jupytext
import nbclient
import nbformat

ROOT = Path(__file__).resolve().parent.parent
TUTORIALS = ROOT / "docs" / "tutorials"
CELL_TIMEOUT = 600  # [s] a cell that runs longer is stuck (tutorial 1's longest, a training, takes under a minute)
KERNEL = "python3"  # ipykernel's kernel, run by the Python that runs this


def sources(folder: Path = TUTORIALS) -> list[Path]:
    """The tutorials' sources, in their order (NN_name.py)."""
    return sorted(folder.glob("[0-9][0-9]_*.py"))


def execute(source: Path, cwd: Path = ROOT) -> nbformat.NotebookNode:
    """A tutorial's notebook from its source, executed in a fresh kernel from `cwd`; raises CellExecutionError."""
    notebook = jupytext.read(source)
    # No timing metadata: a stored notebook then changes only where a source or an output does.
    client = nbclient.NotebookClient(
        notebook, timeout=CELL_TIMEOUT, kernel_name=KERNEL, record_timing=False, resources={"metadata": {"path": cwd}}
    )
    client.execute()
    return notebook


def main(argv: list[str] | None = None) -> int:
    """Execute the given tutorials' sources (default: all) and write their notebooks beside them."""
    paths = [Path(a) for a in (sys.argv[1:] if argv is None else argv)] or sources()
    for source in paths:
        start = time.perf_counter()
        notebook = execute(source)
        target = source.with_suffix(".ipynb")
        jupytext.write(notebook, target)
        print(f"{target}: executed in {time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
