"""The package's folders are its layers: imports point down only, no module cycle, modules of one readable size."""

from __future__ import annotations

import ast
import pathlib

import pytest

PACKAGE = pathlib.Path(__file__).resolve().parents[1] / "reach_jax"
# Lowest first, as the reach_jax docstring maps them; a module may import its own layer and the ones before it.
LAYERS = ("errors", "config", "physics", "env", "agent", "engine", "store", "train", "evaluate", "testing")
FACES = ("__init__.py", "__main__.py")  # a package's face may be short
MOST_LINES, FEWEST_LINES = 300, 40
MOST_FUNCTION_LINES = 50  # a library function, from its `def` to its last line, docstring included


def _modules(root: pathlib.Path) -> dict[str, pathlib.Path]:
    """Dotted module name -> file, for every module under root."""
    found = {}
    for path in sorted(root.rglob("*.py")):
        parts = path.relative_to(root.parent).with_suffix("").parts
        found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return found


def _imports(path: pathlib.Path, modules: dict[str, pathlib.Path]) -> set[str]:
    """The package's modules that `path` imports, anywhere in its body (`from a import b` names a.b if a module)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            inner = {f"{node.module}.{a.name}" for a in node.names} & modules.keys()
            names |= inner or {node.module}
    return {n for n in names if n in modules}


def _rank(name: str) -> int:
    """A module's place in LAYERS; the package's face comes above them all."""
    return LAYERS.index(name.split(".")[1]) if "." in name else len(LAYERS)


def _graph(root: pathlib.Path) -> dict[str, set[str]]:
    modules = _modules(root)
    return {name: _imports(path, modules) - {name} for name, path in modules.items()}


def _upward(graph: dict[str, set[str]]) -> list[str]:
    """Every import from a layer up to a later one (the package's own face may import any layer)."""
    return [
        f"{src} imports {dst}" for src, dsts in graph.items() for dst in dsts if "." in src and _rank(dst) > _rank(src)
    ]


def _cycle(graph: dict[str, set[str]]) -> list[str]:
    """One import cycle among the modules, or [] (a package importing its own modules is not one)."""
    edges = {s: {d for d in ds if not s.startswith(d + ".") and not d.startswith(s + ".")} for s, ds in graph.items()}
    state, path = {}, []

    def visit(node):
        state[node] = "open"
        path.append(node)
        for nxt in sorted(edges[node]):
            if state.get(nxt) == "open":
                return path[path.index(nxt) :] + [nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        state[node] = "done"
        path.pop()
        return []

    for node in sorted(edges):
        if node not in state and (found := visit(node)):
            return found
    return []


def test_every_folder_of_the_package_is_a_known_layer():
    top = {p.stem if p.is_file() else p.name for p in PACKAGE.iterdir() if p.suffix == ".py" or p.is_dir()}
    assert top - {"__init__", "__pycache__"} == set(LAYERS)


def test_imports_point_down_the_layers_and_form_no_cycle():
    graph = _graph(PACKAGE)
    assert _upward(graph) == []
    assert _cycle(graph) == []


def test_no_module_is_long_or_a_stub():
    sizes = {p: len(p.read_text().splitlines()) for p in PACKAGE.rglob("*.py")}
    assert [str(p) for p, n in sizes.items() if n > MOST_LINES and p.parent.name != "testing"] == []
    assert [str(p) for p, n in sizes.items() if n < FEWEST_LINES and p.name not in FACES] == []


def _long_functions(root: pathlib.Path) -> list[str]:
    """Every function or method under root longer than MOST_FUNCTION_LINES, as "path:line name (lines)"."""
    found = []
    for path in sorted(root.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                lines = node.end_lineno - (node.decorator_list[0].lineno if node.decorator_list else node.lineno) + 1
                if lines > MOST_FUNCTION_LINES:
                    found.append(f"{path}:{node.lineno} {node.name} ({lines})")
    return found


def test_no_library_function_is_over_50_lines():
    assert _long_functions(PACKAGE) == []


def test_the_length_check_sees_a_long_function_and_counts_its_decorator(tmp_path):
    body = "".join(f"    x{i} = {i}\n" for i in range(MOST_FUNCTION_LINES - 2))
    (tmp_path / "a.py").write_text(
        f"def fits():\n{body}    return 0\n\n\n@staticmethod\ndef over():\n{body}    return 0\n"
    )
    assert [f.split(" ", 1)[1] for f in _long_functions(tmp_path)] == [f"over ({MOST_FUNCTION_LINES + 1})"]


@pytest.fixture
def toy(tmp_path):
    """A package of three layers whose modules a test wires by hand."""

    def write(files: dict[str, str]) -> dict[str, set[str]]:
        for name, text in files.items():
            (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
            (tmp_path / name).write_text(text)
        return _graph(tmp_path / "reach_jax")

    return write


def test_the_checks_see_an_upward_import_and_a_cycle(toy):
    graph = toy(
        {
            "reach_jax/__init__.py": "from reach_jax import evaluate\n",
            "reach_jax/config/__init__.py": "",
            "reach_jax/config/schema.py": "from reach_jax.evaluate import claims\n",
            "reach_jax/evaluate/__init__.py": "from reach_jax.evaluate import claims\n",
            "reach_jax/evaluate/claims.py": "import reach_jax.evaluate.stats\n",
            "reach_jax/evaluate/stats.py": "from reach_jax.evaluate import claims\n",
        }
    )
    assert _upward(graph) == ["reach_jax.config.schema imports reach_jax.evaluate.claims"]
    assert _cycle(graph) == ["reach_jax.evaluate.claims", "reach_jax.evaluate.stats", "reach_jax.evaluate.claims"]
