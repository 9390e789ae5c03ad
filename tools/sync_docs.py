"""Copy generated result files into README.md and the docs pages: their tables are the committed files, never retyped.

A block in README.md or in a page under docs/ looks like

    <!-- include: runs/heldout/eval/claims.md -->
    ...the file's text...
    <!-- end include -->

The path is relative to the repository's root, whichever page holds the block. `python tools/sync_docs.py`
rewrites every block with the current text of its file; `--check` exits 1 when a block differs
(tests/test_readme.py runs the same check).
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BLOCK = re.compile(r"(<!-- include: (?P<path>\S+) -->\n)(?P<body>.*?)(<!-- end include -->)", re.S)


def pages(root: Path | None = None) -> list[Path]:
    """The pages that may hold blocks: README.md and every Markdown file under docs/."""
    root = ROOT if root is None else root
    return [root / "README.md", *sorted((root / "docs").rglob("*.md"))]


def _body(path: str) -> str:
    text = (ROOT / path).read_text()
    # The files start with a level-1 title; inside a page it becomes a paragraph in bold, and their other
    # headings sink two levels so that they nest under the page's section.
    lines = text.splitlines()
    if lines and lines[0].startswith("# "):
        lines[0] = f"**{lines[0][2:]}**"
    lines = [f"##{line}" if line.startswith("#") else line for line in lines]
    return "\n".join(lines).rstrip("\n") + "\n"


def synced(readme: str) -> str:
    """A page's text with every include block replaced by its file's current text."""
    return BLOCK.sub(lambda m: m.group(1) + _body(m.group("path")) + m.group(4), readme)


def stale_blocks(readme: str) -> list[str]:
    """Paths of a page's include blocks whose text differs from their file."""
    return [m.group("path") for m in BLOCK.finditer(readme) if m.group("body") != _body(m.group("path"))]


def main(argv: list[str]) -> int:
    stale = []
    for path in pages():
        text = path.read_text()
        if "--check" in argv:
            for p in stale_blocks(text):
                stale.append(p)
                name = path.relative_to(ROOT)
                print(f"{name}: the block of {p} differs from the file; run python tools/sync_docs.py")
        elif synced(text) != text:
            path.write_text(synced(text))
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
