"""Configuration dataclasses: the declared ranges and units of their fields, and their reading from a TOML tree.

A config dataclass declares a numeric field with `bounded(default, low, high, ...)`; its `__post_init__`
calls `check_ranges(self)`, and `docs/scenarios.md` is written from the same declarations (`sim.scenario_reference
.reference_markdown`), so the documented range is the enforced one. Checks that tie two fields together
(a minimum below a maximum, jitter under a quarter period) stay in the class, stated in its docstring.

`from_dict` builds a config (sections nested as dataclasses) from a TOML table: unknown keys, wrong types and
values that a config's `__post_init__` rejects all become a `ScenarioError` that names the file and the key.
The scenario file (`sim.scenario`) and the detector profile file (`sim.sensing.profiles`) are both read by it.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import math
import types
import typing
from dataclasses import dataclass

from core.errors import ScenarioError

# Units read off a field's name when it does not declare one: the longest matching suffix wins.
_UNIT_SUFFIXES = {"_m_s": "m/s", "_m2": "m²", "_m": "m", "_s": "s", "_deg": "degrees", "_px": "pixels",
                  "_prob": "probability", "_frac": "fraction of the person's size in the image"}


@dataclass(frozen=True)
class Range:
    """Valid values of a number (or of each number of a tuple): finite, and within the bounds given."""

    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    finite: bool = True

    def contains(self, value) -> bool:
        if value is None:
            return True
        if isinstance(value, float) and math.isnan(value) or self.finite and not math.isfinite(value):
            return False
        if self.low is not None and not (value > self.low if self.low_open else value >= self.low):
            return False
        return self.high is None or (value < self.high if self.high_open else value <= self.high)

    def __str__(self) -> str:
        low, high = _number(self.low), _number(self.high)
        if self.low is not None and self.high is not None:
            return f"in {'(' if self.low_open else '['}{low}, {high}{')' if self.high_open else ']'}"
        if self.low is not None:
            return f"{'>' if self.low_open else '>='} {low}{'' if self.finite else ' (inf allowed)'}"
        if self.high is not None:
            return f"{'<' if self.high_open else '<='} {high}"
        return "finite"


def _number(value: float | None) -> str:
    if value is None:
        return ""
    return str(value) if isinstance(value, int) else f"{value:g}"


def bounded(default, low: float | None = None, high: float | None = None, *, low_open: bool = False,
            high_open: bool = False, finite: bool = True, unit: str | None = None):
    """A dataclass field whose value (each element, for a tuple) must lie in the given range.

    Args:
        default: the field's default.
        low, high: inclusive bounds (None: unbounded on that side); `low_open`/`high_open` exclude them.
        finite: False lets the value be infinite (NaN never is valid).
        unit: the unit for people (None: read off the field's name, e.g. `_m` metres, `_s` seconds).
    """
    return dataclasses.field(default=default, metadata={"range": Range(low, high, low_open, high_open, finite),
                                                        "unit": unit})


def field_range(f: dataclasses.Field) -> Range | None:
    return f.metadata.get("range")


def field_unit(f: dataclasses.Field) -> str:
    """The declared unit of a field, else the one its name's suffix says, else ''."""
    unit = f.metadata.get("unit")
    if unit is not None:
        return unit
    for suffix in sorted(_UNIT_SUFFIXES, key=len, reverse=True):
        if f.name.endswith(suffix):
            return _UNIT_SUFFIXES[suffix]
    return ""


def check_ranges(config) -> None:
    """Raises ValueError naming the first field of `config` outside its declared range, with the range."""
    for f in dataclasses.fields(config):
        valid = field_range(f)
        if valid is None:
            continue
        value = getattr(config, f.name)
        named = [(f"{f.name}[{i}]", v) for i, v in enumerate(value)] if isinstance(value, tuple) else [(f.name, value)]
        for name, v in named:
            if not valid.contains(v):
                unit = field_unit(f)
                shown = f" {unit}" if unit and unit != "probability" and not unit.startswith("fraction") else ""
                raise ValueError(f"{name}: {v!r} must be {valid}{shown}")


# ---------------------------------------------------------------- reading a config from a TOML tree

NOT_KEYS = ("source_text", "source_path")  # a Scenario's record of the file it was read from, not keys of it


def from_dict(cls, tree: dict, file: str, prefix: str):
    """Builds dataclass `cls` from a TOML table, naming `file` and the dotted key on any error."""
    if not isinstance(tree, dict):
        raise ScenarioError(f"{file}: [{prefix.rstrip('.')}] must be a table, got {type(tree).__name__}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in file_keys(cls)}
    unknown = sorted(set(tree) - set(fields))
    if unknown:
        raise ScenarioError(
            f"{file}: unknown key '{prefix}{unknown[0]}' (valid keys: {', '.join(sorted(fields))})"
        )
    kwargs = {name: convert(hints[name], value, file, f"{prefix}{name}") for name, value in tree.items()}
    try:
        return cls(**kwargs)
    except ScenarioError:
        raise
    except (ValueError, TypeError) as e:
        where = f"[{prefix.rstrip('.')}] " if prefix else ""
        raise ScenarioError(f"{file}: {where}{e}") from None


def convert(hint, value, file: str, key: str):
    """Converts one TOML value to the annotated field type."""
    origin = typing.get_origin(hint)
    if dataclasses.is_dataclass(hint):
        return from_dict(hint, value, file, f"{key}.")
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        return None if value is None else convert(args[0], value, file, key)
    if isinstance(hint, type) and issubclass(hint, enum.Enum):
        valid = [m.value for m in hint]
        if value not in valid:
            raise ScenarioError(f"{file}: {key} = {value!r} is not one of {valid}")
        return hint(value)
    if origin is tuple:
        args = typing.get_args(hint)
        if not isinstance(value, list):
            raise ScenarioError(f"{file}: {key} must be an array, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(convert(args[0], v, file, f"{key}[{i}]") for i, v in enumerate(value))
        if len(args) != len(value):
            raise ScenarioError(f"{file}: {key} must have {len(args)} elements, got {len(value)}")
        return tuple(convert(a, v, file, f"{key}[{i}]") for i, (a, v) in enumerate(zip(args, value)))
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ScenarioError(f"{file}: {key} = {value!r} must be a number")
        return float(value)
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ScenarioError(f"{file}: {key} = {value!r} must be an integer")
        return value
    if hint is bool:
        if not isinstance(value, bool):
            raise ScenarioError(f"{file}: {key} = {value!r} must be true or false")
        return value
    if hint is str:
        if not isinstance(value, str):
            raise ScenarioError(f"{file}: {key} = {value!r} must be a string")
        return value
    raise TypeError(f"scenario field {key} has unsupported type {hint}")


def file_keys(cls) -> list[dataclasses.Field]:
    """The fields of config `cls` that are keys of its file."""
    return [f for f in dataclasses.fields(cls) if f.init and f.name not in NOT_KEYS]


def table_class(hint):
    """The dataclass of a table-valued field (`Section` or `Section | None`), else None."""
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        hint = args[0] if len(args) == 1 else None
    return hint if dataclasses.is_dataclass(hint) else None


def is_table(hint) -> bool:
    return table_class(hint) is not None or (
        typing.get_origin(hint) is tuple and dataclasses.is_dataclass(typing.get_args(hint)[0]))


def toml_value(value) -> str:
    """A config value as TOML writes it (an enum as its value, an infinite number as `inf`)."""
    if isinstance(value, enum.Enum):
        value = value.value
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, tuple):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    return str(value)
