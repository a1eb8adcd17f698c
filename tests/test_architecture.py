"""The rules of docs/architecture.md, read off the source: no import cycles, `core/` imports no other part,
`tracker/` neither mujoco, mcap nor `sim/`, scoring and the file formats not `sim/`, only the recording package
imports mcap, only `sim/` imports mujoco, no private name crosses a module, no code reaches into a library's
private (name-mangled) attributes, no module imports its own package's face, and every document the code and
the docs cite is in the repository."""

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


SIM_FREE = ("crossview.scoring", "crossview.formats", "crossview.recording")
"""Scoring and the file formats (the dataset layout, OpenPose, result files, the JSON readers, the
recordings): they read and write what `core/` defines and never import `sim/`, so that a real dataset is
read and scored without the simulator."""


def test_scoring_and_the_formats_import_nothing_of_sim():
    offenders = {}
    for name, path in _modules().items():
        if any(name == m or name.startswith(m + ".") for m in SIM_FREE):
            sim = sorted(i for i in _imports(path) if i.split(".")[0] == "sim")
            if sim:
                offenders[name] = sim
    assert offenders == {}


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def private_crossings(modules: dict[str, Path]) -> list[str]:
    """Every private name (a leading underscore, dunders aside) one module of `modules` takes from another:
    `from a.b import _c`, and `m._c` where `m` is a module of the project bound by an import (`import a.b`,
    `import a.b as m`, `from a import b`). Each as "importer: module._name"."""
    found = []
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        bound = {}  # local name -> the project module it stands for
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.asname and alias.name in modules:
                        bound[alias.asname] = alias.name
                    elif not alias.asname and alias.name.split(".")[0] in PACKAGES:
                        bound[alias.name] = alias.name
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = package.split(".")[:len(package.split(".")) - node.level + 1]
                    base = ".".join(parts + ([base] if base else []))
                if base.split(".")[0] not in PACKAGES:
                    continue
                for alias in node.names:
                    full = f"{base}.{alias.name}"
                    if full in modules:
                        bound[alias.asname or alias.name] = full
                    elif _private(alias.name) and base != name:
                        found.append(f"{name}: {base}.{alias.name}")
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and _private(node.attr):
                owner = ast.unparse(node.value)
                if bound.get(owner, name) != name:
                    found.append(f"{name}: {bound[owner]}.{node.attr}")
    return sorted(set(found))


def test_no_private_name_crosses_a_module():
    assert private_crossings(_modules()) == []


def test_a_private_name_crossing_a_module_is_found(tmp_path):
    (tmp_path / "core").mkdir()
    (tmp_path / "core" / "a.py").write_text("_hidden = 1\nshown = 2\n", encoding="utf-8")
    (tmp_path / "core" / "b.py").write_text("from core.a import _hidden, shown\n", encoding="utf-8")
    (tmp_path / "core" / "c.py").write_text("import core.a\nfrom core import a as m\n\n"
                                            "x = core.a._hidden + m._hidden + m.shown\n", encoding="utf-8")
    (tmp_path / "core" / "d.py").write_text("class D:\n    _own = 1\n\n    def f(self):\n"
                                            "        return self._own + D._own\n", encoding="utf-8")
    modules = {f"core.{p.stem}": p for p in sorted((tmp_path / "core").glob("*.py"))}
    assert private_crossings(modules) == ["core.b: core.a._hidden", "core.c: core.a._hidden"]


def _face_holds_code(path: Path) -> bool:
    """Whether a package's `__init__.py` holds more than its docstring (and `from __future__`): a face with
    imports or definitions, which a module of the package importing it would loop through."""
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        docstring = isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)
        if not docstring and not (isinstance(node, ast.ImportFrom) and node.module == "__future__"):
            return True
    return False


def face_imports(modules: dict[str, Path]) -> list[str]:
    """Every import by a module inside a package of its own package's face (`from P import x` or `import P`,
    where P's `__init__.py` holds code), each as "module:line: P". A module of P imports P's submodules
    directly (`from P.sub import x`, `import P.sub as sub`); only the face gathers them."""
    faces = {name for name, path in modules.items() if path.name == "__init__.py" and _face_holds_code(path)}
    found = []
    for name, path in modules.items():
        inside = {face for face in faces if name.startswith(face + ".")}
        if not inside:
            continue
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                named = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = package.split(".")[:len(package.split(".")) - node.level + 1]
                    base = ".".join(parts + ([base] if base else []))
                named = [base]
            else:
                continue
            found += [f"{name}:{node.lineno}: {face}" for face in sorted(inside) if face in named]
    return sorted(found)


def test_no_package_imports_its_own_face():
    assert face_imports(_modules()) == []


def test_a_package_importing_its_own_face_is_found(tmp_path):
    package = tmp_path / "crossview" / "rec"
    package.mkdir(parents=True)
    (tmp_path / "crossview" / "__init__.py").write_text('"""Only a docstring."""\n', encoding="utf-8")
    (package / "__init__.py").write_text('"""The face."""\n\nfrom crossview.rec.a import x\n', encoding="utf-8")
    (package / "a.py").write_text("x = 1\n", encoding="utf-8")
    (package / "b.py").write_text("from crossview.rec import a\n", encoding="utf-8")
    (package / "c.py").write_text("import crossview.rec.a as a\nfrom crossview.rec.a import x\n", encoding="utf-8")
    (package / "d.py").write_text("from . import a\n\n\ndef f():\n    import crossview.rec\n", encoding="utf-8")
    (package / "e.py").write_text("from crossview import rec\n", encoding="utf-8")  # (crossview's face: empty)
    modules = {"crossview": tmp_path / "crossview" / "__init__.py", "crossview.rec": package / "__init__.py"}
    modules |= {f"crossview.rec.{p.stem}": p for p in sorted(package.glob("[a-z].py"))}
    assert face_imports(modules) == ["crossview.rec.b:1: crossview.rec", "crossview.rec.d:1: crossview.rec",
                                     "crossview.rec.d:5: crossview.rec"]


def test_no_private_attribute_of_a_library_is_touched():
    mangled = re.compile(r"\._[A-Z][A-Za-z0-9]*__[a-z_]+")
    offenders = [f"{path.relative_to(ROOT)}:{i}" for path in _modules().values()
                 for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1) if mangled.search(line)]
    assert offenders == []


# Every file that may cite a document: the packages, the tests, the docs, the examples and tools, and the
# repository's own top-level files.
TEXT_FOLDERS = (*PACKAGES, "tests", "docs", "examples", "tools")
TEXT_SUFFIXES = (".py", ".md", ".toml")
CITED_DOCUMENT = re.compile(r"[A-Za-z0-9_/.-]+\.md\b")
OUTPUT_NAMES = {"report.md", "compare.md"}
"""Documents the commands write into their output folder (`crossview ablate`, `sweep`, `compare`), named
bare; a path to one in the repository (docs/sweeps/report.md) is still checked."""


def _text_files() -> list[Path]:
    files = [p for p in ROOT.iterdir() if p.is_file() and p.suffix in TEXT_SUFFIXES]
    for folder in TEXT_FOLDERS:
        files += [p for p in (ROOT / folder).rglob("*") if p.is_file() and p.suffix in TEXT_SUFFIXES]
    return sorted(files)


def _is_repository_document(name: str, citing: Path) -> bool:
    """Whether a cited `*.md` name means a document of this repository (and must exist) rather than a file a
    command writes or a path elsewhere (`out/report.md`, another project's `doc/02_output.md`).

    Upper-case names (README.md, CONTRIBUTING.md) and anything that climbs out of its folder always do;
    a bare lower-case name does unless a command writes it; a path does when it starts in a folder of the
    repository (at the root, under docs/, or beside the citing file)."""
    parts = name.split("/")
    if Path(name).stem.isupper() or ".." in parts:
        return True
    if len(parts) == 1:
        return name not in OUTPUT_NAMES
    first = parts[0] if parts[0] != "." else parts[1]
    return any((base / first).is_dir() for base in (ROOT, ROOT / "docs", citing.parent))


def _resolves(name: str, citing: Path) -> bool:
    """Whether `name` is a file of the repository, read from the root, from docs/ or from the citing file's
    folder."""
    for base in (ROOT, ROOT / "docs", citing.parent):
        path = (base / name).resolve()
        if path.is_file() and path.is_relative_to(ROOT):
            return True
    return False


def _dangling(files: list[Path]) -> list[str]:
    found = []
    for path in files:
        for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            for name in CITED_DOCUMENT.findall(line):
                if _is_repository_document(name, path) and not _resolves(name, path):
                    where = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path
                    found.append(f"{where}:{i}: {name}")
    return found


def test_every_cited_document_is_in_the_repository():
    assert _dangling(_text_files()) == []


def test_a_dangling_reference_is_found(tmp_path):
    md = ".md"  # (spelt apart, so that this file cites none of the missing names it tests with)
    citing = tmp_path / f"a{md}"
    citing.write_text(f"See ARCHITECTURE{md}, ../outside/STYLE{md}, docs/nowhere{md} and docs/metrics{md};\n"
                      f"the sweep writes report{md} into out/report{md}.\n", encoding="utf-8")
    assert _dangling([citing]) == [f"{citing}:1: ARCHITECTURE{md}", f"{citing}:1: ../outside/STYLE{md}",
                                   f"{citing}:1: docs/nowhere{md}"]
