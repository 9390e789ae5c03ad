"""MkDocs hooks: the API reference generated from the package's modules, and the committed figures it links to.

mkdocs.yml names this file under `hooks:`. At every build it

- walks reach_jax/ and writes one reference page per public module (`api/reach_jax.NAME.md`, holding only
  mkdocstrings' `::: reach_jax.NAME`), with an index, and adds them to the navigation under "API reference".
  The list is the package as it stands, never a hand-kept one: `__main__` modules, private modules (a leading
  underscore) and reach_jax.testing are left out;
- serves the files under runs/ and studies/ that a page links to, written as GitHub reads them
  (`![...](../runs/x/fig4.png)` in docs/): MkDocs only serves files under docs/, so each linked file joins
  the site as `runs/x/fig4.png` and the link is pointed there, so it works on the site and on GitHub alike. Only
  linked files are copied, not the whole of runs/.
"""

from __future__ import annotations

import ast
import posixpath
import re
from pathlib import Path

from mkdocs.structure.files import File, Files

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = "reach_jax"
SKIP = ("reach_jax.testing",)
API = "api"
SERVED = ("runs/", "studies/")  # folders whose linked files the site serves
# Markdown images and links, and HTML src/href attributes, whose target lies under runs/.
LINK = re.compile(r"""(?:\]\(|(?:src|href)=["'])(?P<target>[^)"'\s#]+)""")


def public_modules(root: Path = ROOT, package: str = PACKAGE) -> list[str]:
    """Dotted names of the package's public modules and subpackages, sorted (a package before its modules)."""
    names = []
    for path in sorted((root / package).rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        if any(p.startswith("_") for p in parts):  # __main__, private modules
            continue
        name = ".".join(parts)
        if any(name == s or name.startswith(s + ".") for s in SKIP):
            continue
        names.append(name)
    return sorted(names, key=lambda n: n.split("."))


def _summary(name: str, root: Path = ROOT) -> str:
    """The first line of a module's docstring, read without importing it."""
    path = root / Path(*name.split("."))
    path = path / "__init__.py" if path.is_dir() else path.with_suffix(".py")
    doc = ast.get_docstring(ast.parse(path.read_text())) or ""
    return doc.strip().splitlines()[0] if doc.strip() else ""


def _page(name: str) -> str:
    return f"{API}/{name}.md"


def _nav(names: list[str]) -> list:
    """Navigation entries: top-level modules flat, each subpackage a section holding its own page first."""
    tree: dict = {}
    for name in names:
        node = tree
        for part in name.split(".")[1:]:
            node = node.setdefault(part, {})

    def entries(node: dict, prefix: str) -> list:
        out = []
        for part, child in sorted(node.items()):
            name = f"{prefix}.{part}"
            if child:
                out.append({name: [{name: _page(name)}, *entries(child, name)]})
            else:
                out.append({name: _page(name)})
        return out

    package = names[0].split(".")[0] if names else PACKAGE
    top = [{package: _page(package)}] if package in names else []  # the package's own page: its map of the layers
    return [{"Overview": f"{API}/index.md"}, *top, *entries(tree, package)]


def _index(names: list[str]) -> str:
    lines = [
        "# API reference",
        "",
        "One page per public module of `reach_jax`, generated from the docstrings when the site is built",
        "(`tools/mkdocs_hooks.py` walks the package, so this list follows the code). The entry points are",
        "`reach_jax.config` (`from_partial`), `reach_jax.train` (`run`) and `reach_jax.evaluate` (`evaluate`);",
        "the [Python API](../python-api.md) page shows them at work.",
        "",
        "| module | what it holds |",
        "|---|---|",
    ]
    for name in names:
        summary = _summary(name).replace("|", "\\|")
        lines.append(f"| [`{name}`]({name}.md) | {summary} |")
    return "\n".join(lines) + "\n"


def on_config(config):
    """Append the generated reference to the navigation."""
    nav = config.get("nav")
    if nav is not None and not any(isinstance(e, dict) and "API reference" in e for e in nav):
        nav.append({"API reference": _nav(public_modules())})
    return config


def _repo_path(page_uri: str, target: str, docs: str) -> str | None:
    """The repository path under runs/ or studies/ that a page's link points to, read as GitHub reads it, else None."""
    if "://" in target or target.startswith(("/", "mailto:")):
        return None
    path = posixpath.normpath(posixpath.join(docs, posixpath.dirname(page_uri), target))
    return path if path.startswith(SERVED) and (ROOT / path).is_file() else None


def _docs(config) -> str:
    return Path(config["docs_dir"]).resolve().relative_to(ROOT).as_posix()


def on_files(files: Files, config) -> Files:
    """Add the reference pages and the files of runs/ that pages link to."""
    names = public_modules()
    files.append(File.generated(config, f"{API}/index.md", content=_index(names)))
    for name in names:
        files.append(File.generated(config, _page(name), content=f"# `{name}`\n\n::: {name}\n"))
    docs, linked = _docs(config), set()
    for f in files.documentation_pages():
        if f.abs_src_path:
            text = Path(f.abs_src_path).read_text()
            linked |= {_repo_path(f.src_uri, m.group("target"), docs) for m in LINK.finditer(text)} - {None}
    for path in sorted(linked):
        if files.get_file_from_path(path) is None:
            files.append(File.generated(config, path, abs_src_path=str(ROOT / path)))
    return files


def on_page_markdown(markdown: str, page, config, files) -> str:
    """Point a page's links into runs/ (as `../runs/...` from docs/) at the copies the site serves."""
    docs, here = _docs(config), posixpath.dirname(page.file.src_uri) or "."

    def relink(m: re.Match) -> str:
        path = _repo_path(page.file.src_uri, m.group("target"), docs)
        if path is None:
            return m.group(0)
        start, end = m.span("target")
        return m.group(0)[: start - m.start()] + posixpath.relpath(path, here) + m.group(0)[end - m.start() :]

    return LINK.sub(relink, markdown)
