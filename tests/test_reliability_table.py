"""docs/reliability.md cannot drift: every test its table names exists (file, function and parameter id),
and the counts it states are the table's.

Run as a script, it prints the table's tests as pytest node ids: `pytest $(python tests/test_reliability_table.py)`.
"""

from __future__ import annotations

import importlib
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "reliability.md"
_NODE = re.compile(r"`(tests/[\w/]+\.py)::(\w+)(?:\[([\w-]+)\])?`")


def table_rows() -> list[tuple[str, str, str | None]]:
    """(file, test function, parameter id or None) of every row of the table, in order."""
    rows = []
    for line in DOC.read_text(encoding="utf-8").splitlines():
        if line.startswith("| ") and "`tests/" in line:
            cells = [c.strip() for c in line.strip("|").split("|")]
            found = _NODE.fullmatch(cells[-1])
            assert found, f"docs/reliability.md: the last cell of a row must name one test: {line}"
            rows.append(found.groups())
    return rows


def node_ids() -> list[str]:
    return sorted({f"{path}::{name}" + (f"[{param}]" if param else "") for path, name, param in table_rows()})


def _parameter_ids(function) -> set[str]:
    ids = set()
    for mark in getattr(function, "pytestmark", []):
        if mark.name == "parametrize":
            ids.update(str(i) for i in mark.kwargs.get("ids") or [])
    return ids


def test_every_test_the_reliability_table_names_exists():
    rows = table_rows()
    assert len(rows) > 50
    for path, name, param in rows:
        assert (ROOT / path).is_file(), path
        module = importlib.import_module(path[:-3].replace("/", "."))
        function = getattr(module, name, None)
        assert callable(function), f"{path}::{name} is not a test"
        if param:
            assert param in _parameter_ids(function), f"{path}::{name} has no parameter [{param}]"


def test_the_counts_the_reliability_page_states_are_the_tables():
    stated = re.search(r"\*\*(\d+) rows, (\d+) tests\.\*\*", DOC.read_text(encoding="utf-8"))
    assert stated, "docs/reliability.md: state the counts as **N rows, M tests.**"
    assert (int(stated[1]), int(stated[2])) == (len(table_rows()), len(node_ids()))


if __name__ == "__main__":
    print(" ".join(node_ids()))
    sys.exit(0)
