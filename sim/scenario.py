"""Scenario files: TOML read with the standard library into frozen, validated dataclasses.

Each section of a scenario is the config dataclass of the module that owns it (`[store]` is
`sim.store.StoreConfig`, `[crowd]` is `sim.crowd.CrowdConfig`, ...). This module only walks the
TOML tree against those dataclasses: unknown keys, wrong types and values that a config's
`__post_init__` rejects all become a `ScenarioError` that names the file and the key.
"""

from __future__ import annotations

import dataclasses
import enum
import hashlib
import tomllib
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path

import scenarios
from sim.cameras import CameraRigConfig
from sim.clock import ClockConfig
from sim.config import bounded, check_ranges
from sim.crowd import CrowdConfig
from sim.detector import DetectorConfig
from sim.store import StoreConfig

MAX_DURATION_S = 86400.0  # a day of simulated time
MAX_SEED = 2**63 - 1
SCENARIO_DIR = Path(scenarios.__file__).resolve().parent  # the shipped files, installed as package data
DEFAULT_SCENARIO = "store_layout1"


class ScenarioError(ValueError):
    """A scenario file that cannot be used; the message names the file and the key."""


@dataclass(frozen=True)
class Scenario:
    """A whole scenario: the store, the people, the cameras, their clocks and the detector.

    Attributes:
        name: short name, used for output file names.
        description: one line for people.
        duration_s: default simulated duration.
        seed: default seed of the scenario's random generator.
        store, crowd, cameras, clock, detector: the sections, each owned by its module.
    """

    name: str
    description: str = ""
    duration_s: float = bounded(60.0, 0.0, MAX_DURATION_S, low_open=True)
    seed: int = bounded(0, 0, MAX_SEED)
    store: StoreConfig = field(default_factory=StoreConfig)
    crowd: CrowdConfig = field(default_factory=CrowdConfig)
    cameras: CameraRigConfig = field(default_factory=CameraRigConfig)
    clock: ClockConfig = field(default_factory=ClockConfig)
    detector: DetectorConfig = field(default_factory=DetectorConfig)
    source_text: str = field(default="", repr=False, compare=False)
    source_path: str = field(default="", repr=False, compare=False)

    def __post_init__(self):
        if not self.name or not self.name.replace("_", "").replace("-", "").isalnum():
            raise ValueError(f"name: {self.name!r} must be letters, digits, '_' or '-'")
        check_ranges(self)

    @property
    def where(self) -> str:
        """What error messages name: the scenario's file, or its name when it was built in code."""
        return self.source_path or self.name

    @property
    def digest(self) -> str:
        """sha256 of the scenario text, which ties recordings and tracks files together."""
        return hashlib.sha256(self.source_text.encode()).hexdigest()


def scenario_dirs() -> list[Path]:
    """Where shipped scenarios are looked up: `./scenarios`, then the installed `scenarios` package."""
    return [Path("scenarios"), SCENARIO_DIR]


def resolve_path(name_or_path: str | Path | None) -> Path:
    """Maps None to the default scenario and a bare name to `scenarios/NAME.toml`."""
    path = Path(name_or_path if name_or_path is not None else DEFAULT_SCENARIO)
    if path.suffix or path.exists():
        return path
    for folder in scenario_dirs():
        if (folder / f"{path.name}.toml").is_file():
            return folder / f"{path.name}.toml"
    return path


def load(name_or_path: str | Path | None = None, overrides: dict | None = None) -> Scenario:
    """Reads and validates a scenario file.

    Args:
        name_or_path: a path to a TOML file, the name of a shipped scenario, or None for the default.
        overrides: dotted keys to replace (for example `{"duration_s": 10, "crowd.people": 6}`),
            validated the same way as the file.

    Raises:
        ScenarioError: the file is missing or unreadable, or a key is unknown or invalid.
    """
    path = resolve_path(name_or_path)
    overrides = overrides or {}
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        shipped = ", ".join(sorted({p.stem for d in scenario_dirs() for p in d.glob("*.toml")}))
        raise ScenarioError(f"{path}: no such scenario file (shipped scenarios: {shipped})") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ScenarioError(f"{path}: cannot read scenario: {e}") from None
    try:
        tree = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError(f"{path}: malformed TOML: {e}") from None
    for dotted, value in overrides.items():
        *parents, leaf = dotted.split(".")
        table = tree
        for parent in parents:
            table = table.setdefault(parent, {})
        table[leaf] = value
    tree.setdefault("name", path.stem)
    scenario = from_dict(Scenario, tree, str(path), "")
    # Overrides are part of what was simulated, so they are part of the recorded description.
    note = "".join(f"\n# override: {k} = {v!r}" for k, v in sorted(overrides.items()))
    return dataclasses.replace(scenario, source_text=text + note, source_path=str(path))


def from_dict(cls, tree: dict, file: str, prefix: str):
    """Builds dataclass `cls` from a TOML table, naming `file` and the dotted key on any error."""
    if not isinstance(tree, dict):
        raise ScenarioError(f"{file}: [{prefix.rstrip('.')}] must be a table, got {type(tree).__name__}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init and f.name not in ("source_text", "source_path")}
    unknown = sorted(set(tree) - set(fields))
    if unknown:
        raise ScenarioError(
            f"{file}: unknown key '{prefix}{unknown[0]}' (valid keys: {', '.join(sorted(fields))})"
        )
    kwargs = {name: _convert(hints[name], value, file, f"{prefix}{name}") for name, value in tree.items()}
    try:
        return cls(**kwargs)
    except ScenarioError:
        raise
    except (ValueError, TypeError) as e:
        where = f"[{prefix.rstrip('.')}] " if prefix else ""
        raise ScenarioError(f"{file}: {where}{e}") from None


def _convert(hint, value, file: str, key: str):
    """Converts one TOML value to the annotated field type."""
    origin = typing.get_origin(hint)
    if dataclasses.is_dataclass(hint):
        return from_dict(hint, value, file, f"{key}.")
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        return None if value is None else _convert(args[0], value, file, key)
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
            return tuple(_convert(args[0], v, file, f"{key}[{i}]") for i, v in enumerate(value))
        if len(args) != len(value):
            raise ScenarioError(f"{file}: {key} must have {len(args)} elements, got {len(value)}")
        return tuple(_convert(a, v, file, f"{key}[{i}]") for i, (a, v) in enumerate(zip(args, value)))
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
