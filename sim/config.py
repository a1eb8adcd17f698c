"""Declared ranges and units of configuration fields: what validation enforces and the reference documents.

A config dataclass declares a numeric field with `bounded(default, low, high, ...)`; its `__post_init__`
calls `check_ranges(self)`, and `docs/scenarios.md` is written from the same declarations (`sim.scenario
.reference_markdown`), so the documented range is the enforced one. Checks that tie two fields together
(a minimum below a maximum, jitter under a quarter period) stay in the class, stated in its docstring.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

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
