"""Scenario files: TOML read with the standard library into frozen, validated dataclasses.

Each section of a scenario is the config dataclass of the module that owns it (`[store]` is
`sim.store.StoreConfig`, `[crowd]` is `sim.crowd.CrowdConfig`, ...). This module only walks the
TOML tree against those dataclasses: unknown keys, wrong types and values that a config's
`__post_init__` rejects all become a `ScenarioError` that names the file and the key.
"""

from __future__ import annotations

import ast
import dataclasses
import enum
import hashlib
import inspect
import json
import math
import tomllib
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path

import scenarios
from core import tomlfile
from core.errors import ScenarioError
from core.head import HeadConvention
from sim.cameras import CameraRigConfig
from sim.clock import ClockConfig
from sim.config import bounded, check_ranges, field_range, field_unit
from sim.crowd import CrowdConfig
from sim.sensing.profiles import PROFILES, DetectorConfig, DetectorParams, DetectorProfile
from sim.store import StoreConfig, StoreGeometry

MAX_DURATION_S = 86400.0  # a day of simulated time
MAX_SEED = 2**63 - 1
SCENARIO_DIR = Path(scenarios.__file__).resolve().parent  # the shipped files, installed as package data
DEFAULT_SCENARIO = "store_layout1"


@dataclass(frozen=True)
class ScoringConfig:
    """[scoring]: how `crossview score` compares the tracker's poses with this scenario's truth.

    Attributes:
        truth_head: where PCP's true head joints (bottom and top of the head) lie. "evaluate": mapped from the
            true shoulders and nose with evaluate.py's factors, as the estimate is. "annotated": where the
            Campus and Shelf annotators mark them, on the simulated head: the base of the head at the top of the
            neck, and the vertex of the skull. The estimate is always mapped with evaluate.py's factors
            (docs/metrics.md, "Joint conventions").
    """

    truth_head: HeadConvention = HeadConvention.EVALUATE


@dataclass(frozen=True)
class Scenario:
    """A whole scenario: the store, the people, the cameras, their clocks and the detector.

    Attributes:
        name: short name, used for output file names.
        description: one line for people.
        duration_s: default simulated duration.
        seed: default seed of the scenario's random generator.
        store, crowd, cameras, clock, detector: the sections, each owned by its module.
        scoring: how the truth is scored (read by `crossview score`, not by the simulator).
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
    scoring: ScoringConfig = field(default_factory=ScoringConfig)
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


def shipped() -> list[Path]:
    """The shipped scenario files, by name."""
    return sorted(SCENARIO_DIR.glob("*.toml"))


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
    return dataclasses.replace(_from_text(text, overrides, str(path), path.stem, path.parent), source_path=str(path))


_OVERRIDE_NOTE = "\n# override: "


def _from_text(text: str, overrides: dict, where: str, name: str, folder: Path | None = None) -> Scenario:
    """The scenario of a file's text with `overrides` applied; its `source_text` is the text with the
    overrides noted under it. A detector profile file the text names is resolved against `folder` (the
    scenario file's; one an override names, against the working folder), and its parameters become overrides
    too, so that the recorded text simulates the same without the file."""
    try:
        tree = tomlfile.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError(f"{where}: malformed TOML: {e}") from None
    overrides = _with_profile_file(tree, overrides, folder)
    for dotted, value in overrides.items():
        *parents, leaf = dotted.split(".")
        table = tree
        for parent in parents:
            table = table.setdefault(parent, {})
            if not isinstance(table, dict):
                raise ScenarioError(f"{where}: {parent} must be a table ([{parent}]), got {table!r}")
        table[leaf] = value
    tree.setdefault("name", name)
    scenario = from_dict(Scenario, tree, where, "")
    StoreGeometry(scenario.store, name=where)  # the layout checked at load: fixtures apart, doors free, all reachable
    # Overrides are part of what was simulated, so they are part of the recorded description.
    note = "".join(f"{_OVERRIDE_NOTE}{k} = {v!r}" for k, v in sorted(overrides.items()))
    return dataclasses.replace(scenario, source_text=text + note)


PROFILE_FILE_SUFFIX = ".toml"


def is_profile_file(profile) -> bool:
    """Whether a `detector.profile` value names a profile file rather than a shipped profile."""
    return isinstance(profile, str) and profile.endswith(PROFILE_FILE_SUFFIX)


def load_profile_file(path: Path) -> dict:
    """A detector profile file (what `crossview fit-detector` writes): `base`, the shipped profile it starts
    from (default typical), and any parameters of `DetectorParams`, each checked as a [detector] key is.

    Returns:
        {"profile": base, parameter: value, ...} as TOML values.

    Raises:
        ScenarioError: the file is missing, unreadable or malformed, or a key is unknown or invalid; the
            message names the file and the key.
    """
    try:
        tree = tomlfile.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ScenarioError(f"{path}: no such detector profile file (detector.profile names a shipped profile, "
                            f"{', '.join(p.value for p in DetectorProfile)}, or a profile file)") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ScenarioError(f"{path}: cannot read the detector profile: {e}") from None
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError(f"{path}: malformed TOML: {e}") from None
    base = tree.pop("base", DetectorProfile.TYPICAL.value)
    valid = [p.value for p in DetectorProfile]
    if base not in valid:
        raise ScenarioError(f"{path}: base = {base!r} is not one of {valid}")
    unknown = sorted(set(tree) - set(DetectorParams._fields))
    if unknown:
        raise ScenarioError(f"{path}: unknown key '{unknown[0]}' (valid keys: base, "
                            f"{', '.join(DetectorParams._fields)})")
    from_dict(DetectorConfig, {**tree, "profile": base}, str(path), "")  # every value checked, naming the file
    return {"profile": base, **tree}


def profile_params(profile: str) -> DetectorParams:
    """The parameters of a shipped profile (by name) or of a profile file (a path ending in .toml)."""
    if is_profile_file(profile):
        return from_dict(DetectorConfig, load_profile_file(Path(profile)), profile, "").params()
    valid = [p.value for p in DetectorProfile]
    if profile not in valid:
        raise ScenarioError(f"profile {profile!r}: not one of {valid} nor a profile file (.toml)")
    return PROFILES[DetectorProfile(profile)]


def _with_profile_file(tree: dict, overrides: dict, folder: Path | None) -> dict:
    """`overrides` with the parameters of the profile file that `detector.profile` names, if it names one: the
    file's base profile as the profile, and each of its parameters that neither the scenario's [detector] nor
    an override sets."""
    table = tree.get("detector") if isinstance(tree.get("detector"), dict) else {}
    profile = overrides.get("detector.profile", table.get("profile"))
    if not is_profile_file(profile):
        return overrides
    path = Path(profile)
    if not path.is_absolute() and "detector.profile" not in overrides and folder is not None:
        path = folder / path
    inline = load_profile_file(path)
    explicit = set(table) | {k.split(".", 1)[1] for k in overrides if k.startswith("detector.")}
    merged = dict(overrides)
    merged["detector.profile"] = inline.pop("profile")
    merged.update({f"detector.{k}": v for k, v in inline.items() if k not in explicit})
    return merged


def profile_file_text(params: DetectorParams, base: DetectorProfile, comment: str) -> str:
    """A profile file holding every parameter of `params` (what `load_profile_file` reads back)."""
    lines = [f"# {line}" if line else "#" for line in comment.splitlines()]
    lines += ["", f"base = {_toml_value(base.value)}"]
    lines += [f"{name} = {_toml_value(getattr(params, name))}" for name in DetectorParams._fields]
    return "\n".join(lines) + "\n"


def from_source_text(source_text: str, name: str, where: str) -> Scenario:
    """The scenario whose `source_text` (what a recording keeps) is `source_text`: the file's TOML with the
    overrides `load` noted under it applied again, so that it simulates what was recorded.

    Args:
        source_text: a `Scenario.source_text`.
        name: the scenario's name when the text sets none (the file's stem it was loaded from).
        where: what error messages name (the recording).

    Raises:
        ScenarioError: the text is not a valid scenario.
    """
    text, *notes = source_text.split(_OVERRIDE_NOTE)
    overrides = {}
    for note in notes:
        key, _, value = note.partition(" = ")
        try:
            overrides[key] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            try:  # an infinite number (a profile's Gaussian tails): repr wrote TOML's `inf`
                overrides[key] = tomlfile.loads(f"v = {value}")["v"]
            except tomllib.TOMLDecodeError:
                raise ScenarioError(f"{where}: unreadable override note {note!r} in the scenario text") from None
    scenario = _from_text(text, overrides, where, name)
    if scenario.source_text != source_text:
        raise ScenarioError(f"{where}: the scenario text's override notes do not read back as written")
    return scenario


def check_override(dotted: str, value, file: str = "override") -> None:
    """Checks that `dotted` names a key of a scenario file and that `value` has its type, as `load` would
    (its range is left to `load`: whether a value is valid can depend on the rest of the scenario).

    Raises:
        ScenarioError: an unknown key, a key that is a table, or a value of the wrong type; the message
            starts with `file` and names the key.
    """
    cls, prefix = Scenario, ""
    names = dotted.split(".")
    for depth, name in enumerate(names):
        fields = {f.name for f in _keys(cls)}
        if name not in fields:
            raise ScenarioError(f"{file}: unknown key '{prefix}{name}' (valid keys: {', '.join(sorted(fields))})")
        hint = typing.get_type_hints(cls)[name]
        if depth < len(names) - 1:
            if _table_class(hint) is None:
                raise ScenarioError(f"{file}: '{prefix}{name}' is not a table, so '{dotted}' is not a key")
            cls, prefix = _table_class(hint), f"{prefix}{name}."
    if _is_table(hint):
        raise ScenarioError(f"{file}: '{dotted}' is a table; name one of its keys")
    _convert(hint, value, file, dotted)


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


# ---------------------------------------------------------------- the reference of every key, and resolved files

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
    for f in _keys(cls):
        hint = hints[f.name]
        if _table_class(hint) is not None:
            yield from _sections(_table_class(hint), f"{prefix}{f.name}.")
        elif typing.get_origin(hint) is tuple and dataclasses.is_dataclass(typing.get_args(hint)[0]):
            yield from ((name, sub, True) for name, sub, _ in _sections(typing.get_args(hint)[0], f"{prefix}{f.name}."))


def _keys(cls) -> list[dataclasses.Field]:
    return [f for f in dataclasses.fields(cls) if f.init and f.name not in ("source_text", "source_path")]


def _table_class(hint):
    """The dataclass of a table-valued field (`Section` or `Section | None`), else None."""
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        hint = args[0] if len(args) == 1 else None
    return hint if dataclasses.is_dataclass(hint) else None


def _is_table(hint) -> bool:
    return _table_class(hint) is not None or (
        typing.get_origin(hint) is tuple and dataclasses.is_dataclass(typing.get_args(hint)[0]))


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
        return f"the profile's (typical: {_toml_value(typical)})"
    if cls is Scenario and f.name == "name":
        return "the file's name"
    if value is None:
        return "none"
    return f"`{_toml_value(value)}`" if value != () else "none"


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
        for f in _keys(cls):
            if _is_table(hints[f.name]):
                continue
            valid = field_range(f)
            kind = _type_name(hints[f.name])
            valid_text = str(valid) if valid is not None else ("see type" if kind.startswith("one of") else "any")
            meaning = docs.get(f.name, "").replace("|", "\\|")
            out.append(f"| `{shown}{f.name}` | {meaning} | {kind} | {field_unit(f) or '–'} | "
                       f"{_default_text(cls, f)} | {valid_text} |")
    return "\n".join(out) + "\n"


def _toml_value(value) -> str:
    if isinstance(value, enum.Enum):
        value = value.value
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return str(value)


def resolved_toml(scenario: Scenario) -> str:
    """`scenario` as a TOML file with every key written out (the profile's detector parameters as comments,
    since a key set in the file overrides the profile); loading it gives the same scenario. A name the file
    took from its file name is left to the new file's name; one set explicitly (`name = ...`, another than
    the file's) is kept. A relative calibration path is made absolute so that the file can move."""
    lines = [f"# {scenario.name}, every key resolved ({scenario.where}).", ""]
    explicit_name = bool(scenario.source_path) and scenario.name != Path(scenario.source_path).stem
    calibration = scenario.cameras.calibration
    if calibration and scenario.source_path and not Path(calibration).is_absolute():
        calibration = str((Path(scenario.source_path).parent / calibration).resolve())
        scenario = dataclasses.replace(scenario, cameras=dataclasses.replace(scenario.cameras, calibration=calibration))

    def table(obj, section: str, header: str | None) -> None:
        cls = type(obj)
        hints = typing.get_type_hints(cls)
        if header is not None:
            lines.extend(["", header])
        nested = []
        for f in _keys(cls):
            value = getattr(obj, f.name)
            if _is_table(hints[f.name]):
                nested.append((f, value))
            elif value is None and cls is DetectorConfig:
                effective = getattr(obj.params(), f.name)
                lines.append(f"# {f.name} = {_toml_value(effective)}  # the {obj.profile.value} profile's")
            elif value is not None and (obj is not scenario or f.name != "name" or explicit_name):
                lines.append(f"{f.name} = {_toml_value(value)}")
        for f, value in nested:
            if value is None:  # an optional table left out ([store.aisles], expanded into the shelves at load)
                continue
            if isinstance(value, tuple):
                for i, item in enumerate(value):
                    if isinstance(obj, StoreConfig) and f.name == "shelves" and i == obj.first_expanded:
                        lines.extend(["", f"# store.shelves[{i}] on: the file's [store.aisles], expanded"])
                    table(item, f"{section}{f.name}.", f"[[{section}{f.name}]]")
            else:
                table(value, f"{section}{f.name}.", f"[{section}{f.name}]")
                if isinstance(obj, StoreConfig) and f.name == "checkout_lanes":
                    lines.append("# its counters, (x, y) centre and (x, y, height) size:")
                    lines.extend(f"#   store.checkout_lanes[{k}]: {_toml_value(c)}, {_toml_value(size)}"
                                 for k, (c, size) in enumerate(value.counters(obj.width_m, obj.depth_m, obj.ceiling_m)))

    table(scenario, "", None)
    return "\n".join(lines) + "\n"
