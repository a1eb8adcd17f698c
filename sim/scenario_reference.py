"""docs/scenarios.md's reference of every scenario key (`crossview scenarios --reference`), written from the
configuration classes themselves: each key's meaning from its class's docstring, its type, unit, default and
valid range from its declaration (`sim.config.bounded`), so the documented range is the enforced one."""

from __future__ import annotations

import dataclasses
import enum
import inspect
import types
import typing

from sim.config import field_range, field_unit, file_keys, is_table, table_class, toml_value
from sim.scenario import Scenario
from sim.sensing.profiles import PROFILES, DetectorConfig, DetectorParams, DetectorProfile

# Where a section's keys are explained when its class documents them elsewhere (the detector's knobs are the
# profile's parameters).
_MEANINGS_FROM = {DetectorConfig: (DetectorParams,)}


def attribute_docs(cls) -> dict[str, str]:
    """Each field's meaning from the `Attributes:` section of `cls`'s docstring (Google style; a line may
    document several fields, `a, b: text`), then from the classes in `_MEANINGS_FROM`."""
    docs: dict[str, str] = {}
    for source in (*_MEANINGS_FROM.get(cls, ()), cls):
        lines = inspect.getdoc(source).splitlines()
        if "Attributes:" not in lines:
            continue
        names: list[str] = []
        for line in lines[lines.index("Attributes:") + 1:]:
            if line and not line.startswith(" "):
                break
            head, sep, text = line.strip().partition(": ")
            if line.startswith("    ") and not line.startswith("     ") and sep:
                names = [n.strip() for n in head.split(",")]
                for name in names:
                    docs[name] = text.strip()
            elif line.strip():
                for name in names:
                    docs[name] += " " + line.strip()
    return docs


def _sections(cls=Scenario, prefix: str = ""):
    """(dotted section name, class, is an array of tables) of `cls` and every section below it."""
    yield prefix, cls, False
    hints = typing.get_type_hints(cls)
    for f in file_keys(cls):
        hint = hints[f.name]
        if table_class(hint) is not None:
            yield from _sections(table_class(hint), f"{prefix}{f.name}.")
        elif typing.get_origin(hint) is tuple and dataclasses.is_dataclass(typing.get_args(hint)[0]):
            yield from ((name, sub, True) for name, sub, _ in _sections(typing.get_args(hint)[0], f"{prefix}{f.name}."))


def _type_name(hint) -> str:
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return _type_name(next(a for a in args if a is not type(None)))
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"array of {_type_name(args[0])}"
        return f"array of {len(args)} {_type_name(args[0])}"
    if isinstance(hint, type) and issubclass(hint, enum.Enum):
        return "one of " + ", ".join(f'"{m.value}"' for m in hint)
    return {float: "number", int: "integer", bool: "true or false", str: "text"}.get(hint, str(hint))


def _default_text(cls, f: dataclasses.Field) -> str:
    if f.default is dataclasses.MISSING:
        value = f.default_factory() if f.default_factory is not dataclasses.MISSING else None
    else:
        value = f.default
    if cls is DetectorConfig and value is None:
        typical = getattr(PROFILES[DetectorProfile.TYPICAL], f.name)
        return f"the profile's (typical: {toml_value(typical)})"
    if cls is Scenario and f.name == "name":
        return "the file's name"
    if value is None:
        return "none"
    return f"`{toml_value(value)}`" if value != () else "none"


def reference_markdown() -> str:
    """docs/scenarios.md: every key of a scenario file with its meaning, type, unit, default and valid range,
    written from the configuration classes themselves (a test checks the committed file against it)."""
    out = [
        "# Scenario files: every key",
        "",
        "A scenario is a TOML file; every key is optional and takes the default below. `crossview scenarios` lists",
        "the shipped scenarios and `crossview scenarios --show NAME` prints one with every key resolved, as a file",
        "to start from. Unknown keys, wrong types and values outside the valid range are errors that name the",
        "file and the key. Relative paths (`cameras.calibration`) are taken from the scenario file's folder.",
        "",
        "This page is generated from the configuration classes (`crossview scenarios --reference`); a test fails",
        "when it is stale. The notes on the shipped scenarios at its end are written by hand.",
    ]
    for section, cls, array in _sections():
        title = section.rstrip(".")
        heading = "Top level" if not title else (f"[[{title}]]" if array else f"[{title}]")
        summary = inspect.getdoc(cls).split("\n\n")[0].replace("\n", " ")
        summary = summary.split(": ", 1)[1] if summary.startswith("[") else summary
        out += ["", f"## {heading}", "", summary[0].upper() + summary[1:], "",
                "| key | meaning | type | unit | default | valid |", "|---|---|---|---|---|---|"]
        docs = attribute_docs(cls)
        hints = typing.get_type_hints(cls)
        shown = "" if array else section  # keys of an array of tables are written under its [[header]]
        for f in file_keys(cls):
            if is_table(hints[f.name]):
                continue
            valid = field_range(f)
            kind = _type_name(hints[f.name])
            valid_text = str(valid) if valid is not None else ("see type" if kind.startswith("one of") else "any")
            meaning = docs.get(f.name, "").replace("|", "\\|")
            out.append(f"| `{shown}{f.name}` | {meaning} | {kind} | {field_unit(f) or '–'} | "
                       f"{_default_text(cls, f)} | {valid_text} |")
    return "\n".join(out) + "\n"
