"""The package import graph (docs/architecture.md#layers): no import cycle and the layer rules.

Imports are read from the source with `ast`, so every import counts: module level, inside functions (the
lazy ones a cycle likes to hide behind) and under `TYPE_CHECKING`.
"""

from __future__ import annotations

import ast
import sys
from collections.abc import Iterable, Mapping
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("controller", "vehicles", "server", "webui")

# Which of our packages each package may import (its own sub-modules always).
LAYERS: dict[str, frozenset[str]] = {
    "controller": frozenset(),
    "vehicles": frozenset({"controller"}),
    "webui": frozenset({"controller"}),
    "server": frozenset({"controller", "vehicles", "webui"}),
}
# Third-party libraries the pure core may use (plus the standard library): numba compiles its kernels,
# daqp is the exact QP's active-set solver (docs/fast-core.md).
CONTROLLER_LIBRARIES = frozenset({"numpy", "scipy", "osqp", "filterpy", "numba", "daqp"})
# Heavy libraries kept where they belong: the library -> the only modules (and their sub-modules) that may
# import it. Dask distributed runs an experiment sweep on a cluster, nothing else.
LIBRARY_HOMES: dict[str, tuple[str, ...]] = {
    "numba": ("controller",),
    "daqp": ("controller",),
    "distributed": ("server.lab",),
    "dask": ("server.lab",),
}


def module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _resolve(node: ast.ImportFrom, importer: str, is_package: bool) -> str:
    """The absolute module an ImportFrom names (relative imports resolved against the importer)."""
    if node.level == 0:
        return node.module or ""
    base = importer.split(".") if is_package else importer.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def imported_names(path: Path, importer: str) -> set[str]:
    """Every module name `path` imports anywhere in its body; `from a import b` yields a.b and a."""
    tree = ast.parse(path.read_text(), filename=str(path))
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = _resolve(node, importer, path.name == "__init__.py")
            out.add(base)
            out.update(f"{base}.{alias.name}" for alias in node.names if alias.name != "*")
    return out


def import_graph(root: Path, packages: Iterable[str]) -> dict[str, set[str]]:
    """module -> the modules of `packages` it imports (only names that are modules of ours)."""
    files = {module_name(p, root): p for pkg in packages for p in sorted((root / pkg).rglob("*.py"))}
    graph: dict[str, set[str]] = {}
    for name, path in files.items():
        graph[name] = {m for m in imported_names(path, name) if m in files and m != name}
    return graph


def external_imports(root: Path, package: str) -> dict[str, set[str]]:
    """module -> the top-level names it imports that are not ours."""
    ours = set(PACKAGES)
    out: dict[str, set[str]] = {}
    for path in sorted((root / package).rglob("*.py")):
        name = module_name(path, root)
        tops = {m.split(".")[0] for m in imported_names(path, name) if m}
        out[name] = {t for t in tops if t not in ours}
    return out


def cycles(graph: Mapping[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = 0

    def visit(v: str) -> None:
        nonlocal counter
        index[v] = low[v] = counter
        counter += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10 * len(graph) + 100))
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def layer_violations(graph: Mapping[str, set[str]], layers: Mapping[str, frozenset[str]]) -> list[str]:
    """'importer -> imported' for every import of a package the importer's layer may not use."""
    bad = []
    for importer, imported in sorted(graph.items()):
        own = importer.split(".")[0]
        for target in sorted(imported):
            top = target.split(".")[0]
            if top != own and top not in layers.get(own, frozenset()):
                bad.append(f"{importer} -> {target}")
    return bad


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    return import_graph(ROOT, PACKAGES)


def test_the_graph_covers_every_package(graph):
    for pkg in PACKAGES:
        assert any(m == pkg or m.startswith(pkg + ".") for m in graph), pkg
    assert "controller.formation" in graph["vehicles.agent"]


def test_no_import_cycle_between_modules(graph):
    assert cycles(graph) == []


def test_every_import_points_down_the_layers(graph):
    assert layer_violations(graph, LAYERS) == []


def test_controller_uses_only_the_standard_library_and_its_numeric_libraries():
    allowed = CONTROLLER_LIBRARIES | set(sys.stdlib_module_names) | {"__future__"}
    extra = {m: sorted(names - allowed) for m, names in external_imports(ROOT, "controller").items()}
    assert {m: names for m, names in extra.items() if names} == {}


def misplaced_libraries(
    root: Path, packages: Iterable[str], homes: Mapping[str, tuple[str, ...]]
) -> list[str]:
    """'module -> library' for every import of a library in `homes` outside the modules it is confined to."""
    bad = []
    for package in packages:
        for module, names in sorted(external_imports(root, package).items()):
            for lib in sorted(names & homes.keys()):
                if not any(module == home or module.startswith(home + ".") for home in homes[lib]):
                    bad.append(f"{module} -> {lib}")
    return bad


def test_heavy_libraries_are_imported_only_where_they_belong():
    assert misplaced_libraries(ROOT, PACKAGES, LIBRARY_HOMES) == []


def test_the_check_finds_a_library_outside_its_home(tmp_path):
    _write(
        tmp_path,
        {
            "app/__init__.py": "",
            "app/lab/__init__.py": "",
            "app/lab/sweep.py": "import distributed\n",
            "app/station/__init__.py": "",
            "app/station/api.py": "def late():\n    from distributed import Client\n",
        },
    )
    assert misplaced_libraries(tmp_path, ["app"], {"distributed": ("app.lab",)}) == [
        "app.station.api -> distributed"
    ]


def _write(root: Path, files: Mapping[str, str]) -> None:
    for rel, text in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


def test_the_check_finds_a_cycle_hidden_in_a_function(tmp_path):
    _write(
        tmp_path,
        {
            "pkg/__init__.py": "",
            "pkg/a.py": "from pkg import b\n",
            "pkg/b.py": "def late():\n    from pkg.a import thing\n    return thing\n",
            "pkg/c.py": "import pkg.a\n",
        },
    )
    assert cycles(import_graph(tmp_path, ["pkg"])) == [["pkg.a", "pkg.b"]]


def test_the_check_finds_an_upward_import(tmp_path):
    _write(
        tmp_path,
        {
            "low/__init__.py": "",
            "low/core.py": "import typing\nif typing.TYPE_CHECKING:\n    from high.app import App\n",
            "high/__init__.py": "",
            "high/app.py": "from low import core\n",
        },
    )
    graph = import_graph(tmp_path, ["low", "high"])
    rules = {"low": frozenset(), "high": frozenset({"low"})}
    assert layer_violations(graph, rules) == ["low.core -> high.app"]
