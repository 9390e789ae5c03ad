"""The README and the documentation site: their result tables are the committed files (tools/sync_docs.py), the
site's API reference covers every public module (tools/mkdocs_hooks.py), and the Python API page's example runs."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from PIL import Image

from reach_jax import env
from reach_jax.evaluate import animation
from reach_jax.store import run_dir

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "docs" / "examples" / "python_api.py"


@pytest.fixture
def tool(load_tool):
    return load_tool("tools/sync_docs")


def test_readme_blocks_match_the_committed_files(tool):
    readme = (ROOT / "README.md").read_text()
    assert tool.BLOCK.search(readme), "the README includes no generated block"
    assert tool.stale_blocks(readme) == []


def test_every_docs_page_block_matches_its_file(tool):
    pages = tool.pages()
    assert ROOT / "README.md" in pages and ROOT / "docs" / "results.md" in pages
    with_blocks = [p for p in pages if tool.BLOCK.search(p.read_text())]
    assert ROOT / "docs" / "results.md" in with_blocks and ROOT / "docs" / "research-log.md" in with_blocks
    assert {str(p.relative_to(ROOT)): tool.stale_blocks(p.read_text()) for p in with_blocks} == {
        str(p.relative_to(ROOT)): [] for p in with_blocks
    }


def test_a_changed_file_is_caught(tool, tmp_path, monkeypatch):
    (tmp_path / "r.md").write_text("# Title\n\n## Part\n\n| a |\n")
    monkeypatch.setattr(tool, "ROOT", tmp_path)
    text = "x\n<!-- include: r.md -->\nold\n<!-- end include -->\ny\n"
    assert tool.stale_blocks(text) == ["r.md"]
    fixed = tool.synced(text)
    assert fixed == "x\n<!-- include: r.md -->\n**Title**\n\n#### Part\n\n| a |\n<!-- end include -->\ny\n"
    assert tool.stale_blocks(fixed) == []


def test_the_check_names_a_stale_docs_page(tool, tmp_path, monkeypatch, capsys):
    (tmp_path / "docs").mkdir()
    (tmp_path / "r.md").write_text("# Title\n")
    (tmp_path / "README.md").write_text("<!-- include: r.md -->\n**Title**\n<!-- end include -->\n")
    (tmp_path / "docs" / "page.md").write_text("<!-- include: r.md -->\nold\n<!-- end include -->\n")
    monkeypatch.setattr(tool, "ROOT", tmp_path)
    assert tool.main(["--check"]) == 1
    assert capsys.readouterr().out.startswith("docs/page.md: the block of r.md differs")
    assert tool.main([]) == 0 and tool.main(["--check"]) == 0


def test_the_api_reference_lists_every_public_module_and_nothing_else(load_tool):
    hooks = load_tool("tools/mkdocs_hooks")
    names = hooks.public_modules()
    on_disk = {
        ".".join(p.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
        for p in (ROOT / "reach_jax").rglob("*.py")
    }
    public = {n for n in on_disk if "__main__" not in n and not n.startswith("reach_jax.testing")}
    assert set(names) == public and len(names) == len(public)
    assert {"reach_jax.config", "reach_jax.evaluate", "reach_jax.evaluate.lattice", "reach_jax.train"} <= set(names)


def test_the_hook_follows_a_new_subpackage(load_tool, tmp_path):
    hooks = load_tool("tools/mkdocs_hooks")
    for path in ("pkg/__init__.py", "pkg/__main__.py", "pkg/_private.py", "pkg/env/__init__.py", "pkg/env/step.py"):
        (tmp_path / path).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / path).write_text('"""Doc."""\n')
    (tmp_path / "pkg/testing").mkdir()
    (tmp_path / "pkg/testing/__init__.py").write_text("")
    assert hooks.public_modules(tmp_path, "pkg") == ["pkg", "pkg.env", "pkg.env.step", "pkg.testing"]
    nav = hooks._nav(["pkg", "pkg.config", "pkg.env", "pkg.env.step"])
    assert nav[1:] == [
        {"pkg": "api/pkg.md"},
        {"pkg.config": "api/pkg.config.md"},
        {"pkg.env": [{"pkg.env": "api/pkg.env.md"}, {"pkg.env.step": "api/pkg.env.step.md"}]},
    ]


@pytest.fixture(scope="module")
def api_run(tmp_path_factory):
    """The Python API page's example, run as a user runs it: its stdout and the run directory it wrote."""
    out = tmp_path_factory.mktemp("api") / "run"
    done = subprocess.run([sys.executable, str(EXAMPLE), str(out)], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    return done.stdout, out


@pytest.mark.slow
def test_the_python_api_example_trains_evaluates_and_loads(api_run):
    stdout, out = api_run
    assert "none -> viscous_mirror: success" in stdout and "claim 1:" in stdout
    assert "learners (condition, seed): [('none', 0), ('viscous_mirror', 0)]" in stdout
    for name in ("table2.md", "claims.json", "fig4.png"):
        assert (out / "eval" / name).is_file()
    assert '--8<-- "docs/examples/python_api.py"' in (ROOT / "docs" / "python-api.md").read_text()


@pytest.mark.slow
def test_the_animation_shows_both_test_conditions(api_run, tmp_path):
    _, out = api_run
    run = run_dir.load(out)
    assert animation.pick_network(run, "none", "none") == 0
    ep, traj = animation.movements(run, [0], ("none", "viscous_mirror"))
    assert ep.outcome.shape == (1, 2, 4) and set(ep.outcome.ravel()) <= set(range(len(env.OUTCOME_NAMES)))
    # The links end at the hand the episode recorded.
    hand = animation.arm_points(traj.arm[0, 0, :, :, :2], run.cfg)[..., 2, :]
    assert abs(hand - ep.hand[0, 0]).max() < 1e-5
    gif = animation.animate(out, tmp_path / "a.gif", stride=25, dpi=30)
    with Image.open(gif) as im:
        assert im.n_frames > 4 and im.size[0] > im.size[1]
