"""The house in figures: what a review of the product's code counts, for a before/after comparison.

    python tools/house_stats.py [ROOT] [--json FILE]

ROOT is a checkout (default: this one). Counted over the product's packages (core, sim, tracker, crossview),
tests excluded:
- lines per package (physical lines of .py files);
- the 10 largest modules and the 10 longest functions (lines, arguments);
- compiled kernels (functions decorated with `jit` or numba's `njit`) and their lines;
- function-local imports (an `import` inside a function body);
- private names crossing modules: `from pkg.mod import _name` or `mod._name` where `mod` is an imported
  project module (each distinct module/name pair counted once);
- test-only lines in the product: functions and methods whose name the product never uses (no name, attribute
  or `__all__` entry anywhere in the product's code outside their own body, nor in examples/ and tools/, which
  use the product as its users do) but the tests do, with their lines.
  Dunder methods are left out (Python calls them); a name used by the product at all counts as used, so the
  figure can miss a test-only function that shares its name with a used one, never the other way round.
Only Python's `ast` is used, so an old checkout is read the same way as a new one.
"""

from __future__ import annotations

import argparse
import ast
import json
import sys
from pathlib import Path

PACKAGES = ("core", "sim", "tracker", "crossview")


def product_files(root: Path) -> list[Path]:
    return sorted(p for pkg in PACKAGES for p in (root / pkg).rglob("*.py"))


def module_name(root: Path, path: Path) -> str:
    parts = path.relative_to(root).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def is_kernel(node: ast.FunctionDef) -> bool:
    for d in node.decorator_list:
        target = d.func if isinstance(d, ast.Call) else d
        name = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")
        if name.lstrip("_") in ("jit", "njit"):
            return True
    return False


def argument_count(node: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    a = node.args
    return len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + (a.vararg is not None) + (a.kwarg is not None)


def local_imports(tree: ast.AST) -> int:
    """Imports inside a function body (not counting nested functions twice)."""
    count = 0
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            stack = list(node.body)
            while stack:
                child = stack.pop()
                if isinstance(child, (ast.Import, ast.ImportFrom)):
                    count += 1
                elif not isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                    stack.extend(ast.iter_child_nodes(child))
    return count


def private_crossings(tree: ast.AST, modules: set[str], own: str, is_package: bool) -> set[tuple[str, str]]:
    """(module, name) pairs of a private name of another project module used here."""
    found: set[tuple[str, str]] = set()
    aliases: dict[str, str] = {}
    package = own.split(".") if is_package else own.split(".")[:-1]
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package[: len(package) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            for alias in node.names:
                full = f"{base}.{alias.name}"
                if full in modules:
                    aliases[alias.asname or alias.name] = full
                elif base in modules and base != own and alias.name.startswith("_") and not alias.name.startswith("__"):
                    found.add((base, alias.name))
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name in modules:
                    bound = alias.asname or alias.name.split(".")[0]
                    aliases[bound] = alias.name if alias.asname else bound
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__"):
            chain = []
            value = node.value
            while isinstance(value, ast.Attribute):
                chain.append(value.attr)
                value = value.value
            if isinstance(value, ast.Name) and value.id in aliases:
                target = ".".join([aliases[value.id], *reversed(chain)])
                if target in modules and target != own:
                    found.add((target, node.attr))
    return found


def used_names(tree: ast.AST, skip: set[int] = frozenset()) -> set[str]:
    """Names, attribute names and string constants (`__all__`, `getattr`) used in `tree`, outside the nodes
    whose id is in `skip` (a function's own body does not make it used)."""
    names: set[str] = set()
    stack = [tree]
    while stack:
        node = stack.pop()
        if id(node) in skip:
            continue
        if isinstance(node, ast.Name):
            names.add(node.id)
        elif isinstance(node, ast.Attribute):
            names.add(node.attr)
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value.isidentifier():
            names.add(node.value)
        elif isinstance(node, ast.alias):
            names.add((node.asname or node.name).split(".")[0])
            names.add(node.name.split(".")[-1])
        stack.extend(ast.iter_child_nodes(node))
    return names


def test_only_functions(root: Path, trees: dict[str, ast.AST]) -> list[tuple[int, str]]:
    """(lines, "file:name") of the product's functions that only the tests use (see the module's docstring)."""
    definitions = []
    for rel, tree in trees.items():
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and not (
                node.name.startswith("__") and node.name.endswith("__")
            ):
                definitions.append((rel, node))
    bodies = {id(node): name for name, node in ((f"{r}:{n.name}", n) for r, n in definitions)}
    product = set()
    for tree in trees.values():
        product |= used_names(tree, set(bodies))
    # A function whose name appears only inside its own body (recursion) or other unused bodies is checked
    # against the uses outside every function body, plus the bodies of functions that are themselves used.
    used_bodies = set()
    changed = True
    while changed:
        changed = False
        for _, node in definitions:
            if node.name in product and id(node) not in used_bodies:
                used_bodies.add(id(node))
                product |= used_names(node, {id(n) for _, n in definitions if n is not node})
                changed = True
    for path in sorted(p for folder in ("examples", "tools") for p in (root / folder).rglob("*.py")):
        product |= used_names(ast.parse(path.read_text()))
    tests = set()
    for path in sorted((root / "tests").rglob("*.py")):
        tests |= used_names(ast.parse(path.read_text()))
    return sorted(
        ((node.end_lineno - node.lineno + 1, f"{rel}:{node.name}") for rel, node in definitions
         if node.name not in product and node.name in tests),
        reverse=True,
    )


def house_stats(root: Path) -> dict:
    files = product_files(root)
    modules = {module_name(root, p) for p in files}
    per_package = {pkg: 0 for pkg in PACKAGES}
    sizes, functions = [], []
    kernels = kernel_lines = local = 0
    crossings: set[tuple[str, str, str]] = set()
    trees: dict[str, ast.AST] = {}
    for path in files:
        text = path.read_text()
        lines = text.count("\n")
        rel = str(path.relative_to(root))
        per_package[rel.split("/")[0]] += lines
        sizes.append((lines, rel))
        tree = trees[rel] = ast.parse(text)
        own = module_name(root, path)
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                length = node.end_lineno - node.lineno + 1
                functions.append((length, argument_count(node), f"{rel}:{node.name}"))
                if is_kernel(node):
                    kernels += 1
                    kernel_lines += length
        local += local_imports(tree)
        found = private_crossings(tree, modules, own, path.name == "__init__.py")
        crossings |= {(own, m, n) for m, n in found}
    sizes.sort(reverse=True)
    functions.sort(reverse=True)
    test_only = test_only_functions(root, trees)
    return {
        "lines_per_package": per_package,
        "lines_total": sum(per_package.values()),
        "modules": len(files),
        "largest_modules": [{"module": m, "lines": n} for n, m in sizes[:10]],
        "longest_functions": [{"function": f, "lines": n, "arguments": a} for n, a, f in functions[:10]],
        "most_arguments": [
            {"function": f, "arguments": a, "lines": n}
            for a, n, f in sorted(((a, n, f) for n, a, f in functions), reverse=True)[:10]
        ],
        "kernels": kernels,
        "kernel_lines": kernel_lines,
        "function_local_imports": local,
        "private_names_crossing_modules": len({(m, n) for _, m, n in crossings}),
        "private_crossings": sorted(f"{user} uses {m}.{n}" for user, m, n in crossings),
        "test_only_lines": sum(n for n, _ in test_only),
        "test_only_functions": [{"function": f, "lines": n} for n, f in test_only],
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("root", nargs="?", default=str(Path(__file__).resolve().parents[1]), help="a checkout")
    parser.add_argument("--json", help="also write the figures to this JSON file")
    args = parser.parse_args(argv)
    stats = house_stats(Path(args.root))
    if args.json:
        Path(args.json).write_text(json.dumps(stats, indent=1) + "\n")
    print(
        f"lines: {stats['lines_total']} in {stats['modules']} modules; "
        + ", ".join(f"{k} {v}" for k, v in stats["lines_per_package"].items())
    )
    print("largest modules:", "; ".join(f"{m['module']} {m['lines']}" for m in stats["largest_modules"]))
    print(
        "longest functions:",
        "; ".join(f"{f['function']} {f['lines']} lines/{f['arguments']} args" for f in stats["longest_functions"]),
    )
    print("most arguments:", "; ".join(f"{f['function']} {f['arguments']}" for f in stats["most_arguments"]))
    print(
        f"kernels: {stats['kernels']} ({stats['kernel_lines']} lines); function-local imports: "
        f"{stats['function_local_imports']}; private names crossing modules: "
        f"{stats['private_names_crossing_modules']}"
    )
    print(
        f"test-only lines in the product: {stats['test_only_lines']} in {len(stats['test_only_functions'])} "
        "functions" + "".join(f"; {f['function']} {f['lines']}" for f in stats["test_only_functions"])
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
