"""The README's result tables are the committed evaluation files, copied by tools/sync_readme.py."""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _tool():
    spec = importlib.util.spec_from_file_location("sync_readme", ROOT / "tools" / "sync_readme.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_readme_blocks_match_the_committed_files():
    tool = _tool()
    readme = (ROOT / "README.md").read_text()
    assert tool.BLOCK.search(readme), "the README includes no generated block"
    assert tool.stale_blocks(readme) == []


def test_a_changed_file_is_caught(tmp_path, monkeypatch):
    tool = _tool()
    (tmp_path / "r.md").write_text("# Title\n\n## Part\n\n| a |\n")
    monkeypatch.setattr(tool, "ROOT", tmp_path)
    text = "x\n<!-- include: r.md -->\nold\n<!-- end include -->\ny\n"
    assert tool.stale_blocks(text) == ["r.md"]
    fixed = tool.synced(text)
    assert fixed == "x\n<!-- include: r.md -->\n**Title**\n\n#### Part\n\n| a |\n<!-- end include -->\ny\n"
    assert tool.stale_blocks(fixed) == []
