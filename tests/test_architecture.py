"""The dependency rules of ARCHITECTURE.md and STYLE.md, read off the source: no import cycles, `core/`
imports no other part, `tracker/` neither mujoco, mcap nor `sim/`, only the recording package imports mcap,
only `sim/` imports mujoco, and no code reaches into a library's private (name-mangled) attributes."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("core", "sim", "tracker", "crossview", "scenarios")


def _modules() -> dict[str, Path]:
    modules = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            name = ".".join(path.relative_to(ROOT).with_suffix("").parts)
            modules[name.removesuffix(".__init__")] = path
    return modules


def _imports(path: Path) -> set[str]:
    """Every module named by an import anywhere in the file, inside functions too."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    """Project module -> the project modules it imports."""
    modules = _modules()

    def owner(name: str) -> str | None:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    edges = {}
    for name, path in modules.items():
        targets = {owner(imported) for imported in _imports(path)} - {None, name}
        edges[name] = {t for t in targets if not name.startswith(t + ".")}  # a package's own __init__
    return edges


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    return found


def test_no_import_cycles(graph):
    assert _cycles(graph) == []


def test_the_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_core_imports_no_other_part_of_the_project(graph):
    for name, targets in graph.items():
        if name.split(".")[0] == "core":
            assert {t.split(".")[0] for t in targets} <= {"core"}, (name, targets)


def test_tracker_imports_neither_mujoco_mcap_sim_nor_the_glue():
    for name, path in _modules().items():
        if name.split(".")[0] == "tracker":
            roots = {imported.split(".")[0] for imported in _imports(path)}
            assert not roots & {"mujoco", "mcap", "sim", "crossview"}, (name, roots)


def test_only_the_recording_imports_mcap_and_only_sim_imports_mujoco():
    for name, path in _modules().items():
        roots = {imported.split(".")[0] for imported in _imports(path)}
        if "mcap" in roots:
            assert name.startswith("crossview.recording"), name
        if "mujoco" in roots:
            assert name.split(".")[0] == "sim", name


def test_no_private_attribute_of_a_library_is_touched():
    mangled = re.compile(r"\._[A-Z][A-Za-z0-9]*__[a-z_]+")
    offenders = [f"{path.relative_to(ROOT)}:{i}" for path in _modules().values()
                 for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1) if mangled.search(line)]
    assert offenders == []
