"""The README's result tables are the committed evaluation files, copied by tools/sync_readme.py."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture
def tool(load_tool):
    return load_tool("tools/sync_readme")


def test_readme_blocks_match_the_committed_files(tool):
    readme = (ROOT / "README.md").read_text()
    assert tool.BLOCK.search(readme), "the README includes no generated block"
    assert tool.stale_blocks(readme) == []


def test_a_changed_file_is_caught(tool, tmp_path, monkeypatch):
    (tmp_path / "r.md").write_text("# Title\n\n## Part\n\n| a |\n")
    monkeypatch.setattr(tool, "ROOT", tmp_path)
    text = "x\n<!-- include: r.md -->\nold\n<!-- end include -->\ny\n"
    assert tool.stale_blocks(text) == ["r.md"]
    fixed = tool.synced(text)
    assert fixed == "x\n<!-- include: r.md -->\n**Title**\n\n#### Part\n\n| a |\n<!-- end include -->\ny\n"
    assert tool.stale_blocks(fixed) == []
