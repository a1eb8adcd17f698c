"""TOML as every file of the project is read (scenarios, detector profiles, tracker configs, override values).

`tomllib` recurses once per level of nested arrays or inline tables, so a file nested a thousand deep ends
in a RecursionError, and a tree a few hundred deep parses but breaks the code that walks it. Here nesting is
bounded: deeper is a `tomllib.TOMLDecodeError`, which every reader already turns into one line naming its file.
"""

from __future__ import annotations

import tomllib

MAX_NESTING = 32
"""Most levels of tables and arrays within each other (the project's files use 4)."""


def loads(text: str) -> dict:
    """`tomllib.loads`, with nesting deeper than `MAX_NESTING` a `tomllib.TOMLDecodeError`."""
    try:
        tree = tomllib.loads(text)
    except RecursionError:
        raise tomllib.TOMLDecodeError(_too_deep()) from None
    stack = [(tree, 1)]
    while stack:  # (a loop, not recursion: the tree may be as deep as the parser allowed)
        node, depth = stack.pop()
        if depth > MAX_NESTING:
            raise tomllib.TOMLDecodeError(_too_deep())
        children = node.values() if isinstance(node, dict) else node
        stack.extend((c, depth + 1) for c in children if isinstance(c, dict | list))
    return tree


def load(fp) -> dict:
    """`tomllib.load` of a binary file, bounded as `loads` (a UnicodeDecodeError where the bytes are not UTF-8)."""
    return loads(fp.read().decode())


def _too_deep() -> str:
    return f"tables or arrays nested more than {MAX_NESTING} deep"
