"""Scenario files: TOML read with the standard library into frozen, validated dataclasses, and written back
with every key resolved (`resolved_toml`, `crossview scenarios --show`).

Each section of a scenario is the config dataclass of the module that owns it (`[store]` is
`sim.store.StoreConfig`, `[crowd]` is `sim.crowd.CrowdConfig`, ...). This module finds the file, applies the
overrides and a detector profile file the scenario names (`sim.sensing.profiles.load_profile_file`), and has
`sim.config.from_dict` walk the TOML tree against those dataclasses: unknown keys, wrong types and values that
a config's `__post_init__` rejects all become a `ScenarioError` that names the file and the key. The reference
of every key (docs/scenarios.md) is written by `sim.scenario_reference`.
"""

from __future__ import annotations

import ast
import dataclasses
import hashlib
import tomllib
import typing
from dataclasses import dataclass, field
from pathlib import Path

import scenarios
from core import tomlfile
from core.errors import ScenarioError
from core.head import HeadConvention, HeadPoints
from sim.cameras import CameraRigConfig
from sim.clock import ClockConfig
from sim.config import bounded, check_ranges, convert, file_keys, from_dict, is_table, table_class, toml_value
from sim.crowd import CrowdConfig
from sim.humanoid import ANNOTATED_HEAD
from sim.sensing.profiles import DetectorConfig, is_profile_file, load_profile_file
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

    def head_points(self) -> HeadPoints | None:
        """Where PCP puts the true head joints of a COCO-17 truth (`crossview.scoring.score`'s `truth_head`):
        on the humanoid's head (`sim.humanoid.ANNOTATED_HEAD`) for "annotated"; None for "evaluate", mapped
        with evaluate.py's factors as the estimate's."""
        return ANNOTATED_HEAD if self.truth_head is HeadConvention.ANNOTATED else None


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
        fields = {f.name for f in file_keys(cls)}
        if name not in fields:
            raise ScenarioError(f"{file}: unknown key '{prefix}{name}' (valid keys: {', '.join(sorted(fields))})")
        hint = typing.get_type_hints(cls)[name]
        if depth < len(names) - 1:
            if table_class(hint) is None:
                raise ScenarioError(f"{file}: '{prefix}{name}' is not a table, so '{dotted}' is not a key")
            cls, prefix = table_class(hint), f"{prefix}{name}."
    if is_table(hint):
        raise ScenarioError(f"{file}: '{dotted}' is a table; name one of its keys")
    convert(hint, value, file, dotted)


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
        for f in file_keys(cls):
            value = getattr(obj, f.name)
            if is_table(hints[f.name]):
                nested.append((f, value))
            elif value is None and cls is DetectorConfig:
                effective = getattr(obj.params(), f.name)
                lines.append(f"# {f.name} = {toml_value(effective)}  # the {obj.profile.value} profile's")
            elif value is not None and (obj is not scenario or f.name != "name" or explicit_name):
                lines.append(f"{f.name} = {toml_value(value)}")
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
                    lines.extend(f"#   store.checkout_lanes[{k}]: {toml_value(c)}, {toml_value(size)}"
                                 for k, (c, size) in enumerate(value.counters(obj.width_m, obj.depth_m, obj.ceiling_m)))

    table(scenario, "", None)
    return "\n".join(lines) + "\n"
