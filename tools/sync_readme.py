"""Copy generated result files into the README, so its tables are the committed files, never retyped.

A block in README.md looks like

    <!-- include: runs/heldout/eval/claims.md -->
    ...the file's text...
    <!-- end include -->

`python tools/sync_readme.py` rewrites every block with the current text of its file; `--check` exits 1 when a
block differs (tests/test_readme.py runs the same check).
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BLOCK = re.compile(r"(<!-- include: (?P<path>\S+) -->\n)(?P<body>.*?)(<!-- end include -->)", re.S)


def _body(path: str) -> str:
    text = (ROOT / path).read_text()
    # The files start with a level-1 title; inside the README it becomes a paragraph in bold, and their other
    # headings sink two levels so that they nest under the README's section.
    lines = text.splitlines()
    if lines and lines[0].startswith("# "):
        lines[0] = f"**{lines[0][2:]}**"
    lines = [f"##{line}" if line.startswith("#") else line for line in lines]
    return "\n".join(lines).rstrip("\n") + "\n"


def synced(readme: str) -> str:
    """README text with every include block replaced by its file's current text."""
    return BLOCK.sub(lambda m: m.group(1) + _body(m.group("path")) + m.group(4), readme)


def stale_blocks(readme: str) -> list[str]:
    """Paths of the include blocks whose text differs from their file."""
    return [m.group("path") for m in BLOCK.finditer(readme) if m.group("body") != _body(m.group("path"))]


def main(argv: list[str]) -> int:
    path = ROOT / "README.md"
    text = path.read_text()
    if "--check" in argv:
        stale = stale_blocks(text)
        for p in stale:
            print(f"README.md: the block of {p} differs from the file; run python tools/sync_readme.py")
        return 1 if stale else 0
    path.write_text(synced(text))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
