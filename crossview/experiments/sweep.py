"""Grids of generate → track → score cells (`crossview sweep`): the plan, the cell's work, resuming, the result
files and `crossview verify`. The cells run on `crossview.parallel`'s executors (serial, a local process pool, Ray).

A cell is one resolved scenario (the base scenario with the cell's axis values), one seed, one tracker method
and preset. Its work (`run_cell`) runs anywhere and returns a plain dict; only the driver writes into the
output folder, each file atomically (a temporary name renamed at the end). A cell's result depends only on
the cell, so the serial, pool and Ray executors give the same `results.json`, byte for byte.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import hashlib
import io
import itertools
import json
import logging
import os
import random
import resource
import socket
import tempfile
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

from core import processes, tomlfile
from core.errors import ConfigError, CrossviewError, ScenarioError, one_line
from crossview import outputs, parallel, pipeline
from crossview.parallel import Executor, cluster
from sim import scenario as scenario_mod
from sim.sensing.profiles import is_profile_file, load_profile_file

log = logging.getLogger(__name__)

CAMERAS_AXIS = "cameras"
TRACKER_PREFIX = "tracker."
"""Axes named `tracker.FIELD` set a field of the tracker's configuration (`tracker.config.TrackerConfig`)
over its preset, not a scenario key."""
"""The axis of camera counts (`--cameras`): each count becomes a grid of cameras fitted to the floor."""
PEOPLE_AXIS = "crowd.people"

TIMING_FIELDS = ("tracker_fps", "camera_frames_per_s")
"""Fields of the score JSON that measure speed: they vary from run to run, so they go to timings.json."""

SWEEP_FORMAT = 1
"""Version of the layout of sweep.json, the cell files and results.json."""

# Modules a pool's fork server imports once, so that each worker it forks starts with them loaded.
_SETUP = parallel.Setup(preload=("crossview.experiments.sweep", "crossview.recording", "crossview.scoring",
                                 "sim.simulate", "tracker.tracker"))


@dataclass(frozen=True)
class Axis:
    """One dimension of the grid.

    Attributes:
        key: a scenario key by its dotted name (`crowd.people`), `cameras` for camera counts, or
            `tracker.FIELD` for a field of the tracker's configuration (`tracker.w_2d`).
        values: the values in the order given, each of the key's type.
    """

    key: str
    values: tuple


@dataclass(frozen=True)
class SweepSpec:
    """A grid: the product of the axes, the seeds, the methods and the presets.

    Attributes:
        scenario: the base scenario (a file or a shipped name).
        axes: the axes in the order given; the first is the x of the plots, the second the lines.
        seeds: seeds of the scenario's random generator.
        methods: tracker methods, each a `--method` of `crossview track` (built in, registered or a plug-in),
            or `LABEL=METHOD` to name it LABEL in the results and the report (`split_method`).
        presets: tracker presets (`tracker.config.PRESETS`).
        duration_s: simulated seconds per cell; None keeps the scenario's.
        warm_up_s: seconds at the start of each cell left out of its score (`crossview.scoring.score`'s
            `from_s`); None: the default rule, `crossview.scoring.default_from_s` of the cell's duration.
        zones: `--zones auto|N` of `crossview track`: each cell tracked as zones in its worker, one after another
            (`crossview.zoned`, 2 m overlap); None: one tracker.
    """

    scenario: str
    axes: tuple[Axis, ...] = ()
    seeds: tuple[int, ...] = (0,)
    methods: tuple[str, ...] = ("crossview",)
    presets: tuple[str, ...] = ("store",)
    duration_s: float | None = None
    warm_up_s: float | None = 0.0
    zones: str | None = None


@dataclass(frozen=True)
class Cell:
    """Everything a worker needs to run one cell, with nothing that depends on where it runs.

    Attributes:
        index: position in the grid (the order of the result rows).
        key: sha256 (hex, 16 digits) of the resolved scenario, seed, method, preset and package version.
        label: the cell in words, for the progress bar and the logs.
        values: (axis key, value) pairs.
        seed, method, preset: the rest of the cell (`method` is what runs: `LABEL=` taken off).
        scenario_name: the base scenario's name (its file's stem).
        scenario_text: the base scenario file's text (shipped, so that a worker on another machine needs no
            copy of the file).
        files: (path as the scenario writes it, text) of each file the scenario refers to by a relative path
            (its calibration), shipped with it so that the copy a worker loads resolves them.
        overrides: the dotted keys applied to the base scenario (the axis values, the seed, the duration,
            the camera grid's rows and columns).
        version: the package version the cell was planned with (workers must have the same).
        tracker_overrides: fields of the tracker's configuration set over its preset (the `tracker.*` axes).
        method_label: the LABEL of `--method LABEL=METHOD`, the method's name in the results and the report.
        error: why the cell's scenario is invalid (a failed cell that needs no worker); None if it is valid.
        keep_recording: return the recording's bytes.
        worker_process: simulate, and compute the per-camera 2D scores, in a second process
            (`crossview.pipeline.generate`, `crossview.pipeline.score`); False where cells already run side by
            side.
        from_s: the warm-up left out of the cell's score, seconds.
        zones: tracked as zones (`SweepSpec.zones`); None: one tracker.
    """

    index: int
    key: str
    label: str
    values: tuple
    seed: int
    method: str
    preset: str
    scenario_name: str
    scenario_text: str
    files: tuple
    overrides: dict
    version: str
    error: str | None = None
    keep_recording: bool = False
    worker_process: bool = False
    tracker_overrides: dict = field(default_factory=dict)
    method_label: str | None = None  # the method's name in the results (`--method LABEL=METHOD`); None: `method`
    from_s: float = 0.0
    zones: str | None = None

    def load_scenario(self, folder: Path) -> scenario_mod.Scenario:
        """The cell's resolved scenario, loaded from a copy of its file and the files it refers to in `folder`
        (the same on the driver and on a worker elsewhere; where it lies changes no byte of the recording)."""
        return load_copy(Path(folder), self.scenario_name, self.scenario_text, self.files, self.overrides)


def load_copy(folder: Path, name: str, text: str, files, overrides: dict) -> scenario_mod.Scenario:
    """A scenario loaded from a copy of its file's `text` written into `folder` with the `files` it refers to
    by relative paths ((path, text) pairs), each where that path leads from the copy.

    Raises:
        ScenarioError: the scenario is invalid with these overrides.
    """
    home = copy_home(folder, files)
    home.mkdir(parents=True, exist_ok=True)
    for relative, content in files:
        target = home / relative
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(content, encoding="utf-8")
    source = home / f"{name}.toml"
    source.write_text(text, encoding="utf-8")
    return scenario_mod.load(source, overrides)


def copy_home(folder: Path, files) -> Path:
    """Where `load_copy` writes the scenario's copy in `folder`: deep enough that `../x.json` stays inside."""
    ups = max((PurePosixPath(p).parts.count("..") for p, _ in files), default=0)
    return Path(folder).joinpath(*["s"] * ups)


def referenced_files(scenario: scenario_mod.Scenario) -> tuple[tuple[str, str], ...]:
    """(path as written, text) of each file `scenario` refers to by a path relative to its own file (its
    calibration); none where it names an absolute path (a worker needs that file at that path) or the file
    cannot be read (the cell fails as it runs, naming it)."""
    calibration = scenario.cameras.calibration
    if not calibration or Path(calibration).is_absolute() or not scenario.source_path:
        return ()
    try:
        text = (Path(scenario.source_path).parent / calibration).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return ()
    return ((calibration, text),)


def absolute_files(scenario: scenario_mod.Scenario) -> list[list[str]]:
    """[path, sha256 of its bytes] of each file `scenario` names by an absolute path (its calibration), which
    `referenced_files` does not ship: a cell's key covers its content (none where it cannot be read: the cell
    fails as it runs, naming it)."""
    calibration = scenario.cameras.calibration
    if not calibration or not Path(calibration).is_absolute():
        return []
    try:
        return [[calibration, hashlib.sha256(Path(calibration).read_bytes()).hexdigest()]]
    except OSError:
        return []


def plugin_sources(method: str) -> list[str]:
    """The sha256 of the bytes of each module file of a plug-in tracker (`crossview.plugins.Method.source_files`):
    a cell's key covers the plug-in's code, which the package version does not; none for a built-in tracker."""
    from crossview.plugins import resolve

    found = []
    for path in resolve(method).source_files:  # (by content alone: the same plug-in anywhere, the same key)
        try:
            found.append(hashlib.sha256(Path(path).read_bytes()).hexdigest())
        except OSError:
            found.append("")
    return found


def portable(message: str, folder) -> str:
    """`message` with paths under the scenario file's `folder` (the driver's, or a worker's copy) written
    relative to it (`supermarket.toml: crowd.people: ...`): the same on every machine and from every folder."""
    prefix = str(folder).rstrip(os.sep) + os.sep
    message = message.replace(prefix, "")
    resolved = str(Path(folder).resolve()).rstrip(os.sep) + os.sep
    return message.replace(resolved, "")


# ---------------------------------------------------------------- the command line's values


def parse_values(option: str, text: str) -> tuple:
    """The comma-separated values of an axis, each read as a TOML value (`10`, `2.5`, `true`, `[1, 2]`),
    or as text where it is not one (`typical`). Commas inside brackets do not split.

    Raises:
        CrossviewError: no values, or an empty one.
    """
    parts, depth, current = [], 0, ""
    for char in text:
        depth += {"[": 1, "]": -1}.get(char, 0)
        if char == "," and depth == 0:
            parts.append(current)
            current = ""
        else:
            current += char
    parts.append(current)
    parts = [p.strip() for p in parts]
    if not text.strip() or any(not p for p in parts):
        raise CrossviewError(f"{option}: {text!r} is an empty axis or has an empty value; give values like "
                             f"{option.split()[-1].split('=')[0]}=1,2,3")
    values = []
    for part in parts:
        try:
            values.append(tomlfile.loads(f"v = {part}")["v"])
        except tomllib.TOMLDecodeError:
            values.append(part)
    if len(set(map(repr, values))) != len(values):
        raise CrossviewError(f"{option}: {text!r} repeats a value")
    return tuple(values)


PROFILE_KEY = "detector.profile"
"""The key whose value may name a profile file (`sim.sensing.profiles.load_profile_file`), relative to the working
folder as an override's is."""


def parse_axis(key: str, text: str) -> Axis:
    """An axis from the command line: `--set KEY=V1,V2` (key given) or `--people` / `--cameras`.

    Raises:
        CrossviewError: an unknown key, a value of the wrong type, an empty axis or a repeated value.
    """
    option = "--cameras" if key == CAMERAS_AXIS else f"--set {key}"
    if key in ("seed", "name"):
        raise CrossviewError(f"{option}: '{key}' cannot be an axis" + ("; use --seeds" if key == "seed" else ""))
    values = parse_values(option, text)
    for value in values:
        if key == CAMERAS_AXIS:
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise CrossviewError(f"--cameras: {value!r} is not a camera count (an integer >= 1)")
        elif key == PROFILE_KEY and is_profile_file(value):  # a fitted profile, as in a scenario
            try:
                load_profile_file(Path(value))
            except ScenarioError as e:
                raise CrossviewError(f"{option}: {e}") from None
        elif not key.startswith(TRACKER_PREFIX):  # (tracker values are checked together, by `plan`)
            scenario_mod.check_override(key, value, option)
    return Axis(key, values)


def _check_tracker_axes(axes, presets) -> None:
    """Refuses a `tracker.*` axis value that no cell of the grid can take: with none of the presets and none
    of the other tracker axes' values is the configuration valid (a value valid only with some of them fails
    only the other cells, when planned; `alpha_3d_m` 0.6 is valid with `view_margin_m` 0.7, not alone).

    Raises:
        CrossviewError: an unknown field, or a value no cell takes, named with its option.
    """
    axes = [a for a in axes if a.key.startswith(TRACKER_PREFIX)]
    fine = [[False] * len(a.values) for a in axes]
    first_error: dict[tuple[int, int], CrossviewError] = {}
    for picks in itertools.product(*(range(len(a.values)) for a in axes)):
        fields = {a.key[len(TRACKER_PREFIX):]: a.values[i] for a, i in zip(axes, picks)}
        for preset in presets:
            try:
                pipeline.tracker_config(preset, None, fields)
            except ConfigError as e:
                for n, i in enumerate(picks):
                    first_error.setdefault((n, i), e)
                continue
            for n, i in enumerate(picks):
                fine[n][i] = True
            break
    for n, axis in enumerate(axes):
        for i, ok in enumerate(fine[n]):
            if not ok:
                raise CrossviewError(f"--set {axis.key}: {first_error[(n, i)]}")


def parse_seeds(text: str) -> tuple[int, ...]:
    """`0,1,2` as seeds.

    Raises:
        CrossviewError: not a comma-separated list of distinct integers >= 0.
    """
    try:
        seeds = tuple(int(part) for part in text.split(","))
    except ValueError:
        raise CrossviewError(f"--seeds: {text!r} is not a comma-separated list of integers (e.g. 0,1,2)") from None
    if any(not 0 <= s <= scenario_mod.MAX_SEED for s in seeds) or len(set(seeds)) != len(seeds):
        raise CrossviewError(f"--seeds: {text!r} must be distinct integers in [0, {scenario_mod.MAX_SEED}]")
    return seeds


def split_method(text: str) -> tuple[str, str]:
    """(label, method) of a sweep's method: `LABEL=METHOD` names METHOD (say a plug-in's long
    `pkg.module:Class`) LABEL in the results; a method alone is its own label."""
    label, sep, method = text.partition("=")
    if not sep:
        return text, text
    if not label.strip() or not method.strip():
        raise CrossviewError(f"--method: {text!r} is not LABEL=METHOD (for example greedy=pkg.module:Class)")
    return label.strip(), method.strip()


def parse_names(option: str, text: str, valid=None) -> tuple[str, ...]:
    """A comma-separated list of names, each one of `valid` (when given)."""
    names = tuple(part.strip() for part in text.split(","))
    for name in names:
        if valid is not None and name not in valid:
            raise CrossviewError(f"{option}: {name!r} is not one of {', '.join(sorted(valid))}")
    if len(set(names)) != len(names):
        raise CrossviewError(f"{option}: {text!r} repeats a name")
    return names


# ---------------------------------------------------------------- the plan


def resolved_digest(scenario: scenario_mod.Scenario) -> str:
    """sha256 of every resolved value of a scenario (not its file's text: comments do not change a cell)."""
    values = {f.name: getattr(scenario, f.name) for f in dataclasses.fields(scenario)
              if f.name not in ("source_text", "source_path")}
    values = {k: dataclasses.asdict(v) if dataclasses.is_dataclass(v) else v for k, v in values.items()}
    text = json.dumps(pipeline.jsonable(values), sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def content_digest(scenario: scenario_mod.Scenario) -> str:
    """sha256 of a scenario's resolved values (`resolved_digest`) and of the content of every file it names,
    by a relative path (`referenced_files`) or an absolute one (`absolute_files`)."""
    files = [[p, hashlib.sha256(t.encode()).hexdigest()] for p, t in referenced_files(scenario)]
    return _key(resolved_digest(scenario), files, absolute_files(scenario))


def _key(*parts) -> str:
    return hashlib.sha256(json.dumps(parts, sort_keys=True).encode()).hexdigest()[:16]


def _label(values, seed: int, method: str, preset: str) -> str:
    return " ".join([*(f"{k}={v}" for k, v in values), f"seed={seed}", f"{method}/{preset}"])


def plan(spec: SweepSpec, *, keep_recordings: bool = False, worker_process: bool = False) -> list[Cell]:
    """The cells of a grid in order (axes, then seeds, methods, presets; the last varies fastest).

    A cell whose scenario does not load (a value out of its range for that cell) is planned with its error:
    it fails without running. A cell whose scenario loads but cannot be simulated (more people than the
    floor holds) fails when it runs.

    Raises:
        CrossviewError: the base scenario cannot be loaded, a `tracker.*` value suits none of the presets, or the
            warm-up is longer than a cell.
    """
    from crossview.recording import software_version
    from crossview.scoring import default_from_s

    version = software_version()
    base = pipeline.load_scenario(spec.scenario, duration_s=spec.duration_s)
    _check_tracker_axes(spec.axes, spec.presets)
    path = str(Path(base.source_path).resolve())
    text = Path(path).read_text(encoding="utf-8")  # (the file's, without the overrides' notes)
    folder = Path(path).parent
    sources = {text: plugin_sources(split_method(text)[1]) for text in spec.methods}  # (by the method as given)
    cells = []
    grid = itertools.product(*(a.values for a in spec.axes), spec.seeds, spec.methods, spec.presets)
    for index, combo in enumerate(grid):
        *axis_values, seed, method_text, preset = combo
        label, method = split_method(method_text)
        values = tuple((a.key, v) for a, v in zip(spec.axes, axis_values))
        tracker = {k[len(TRACKER_PREFIX):]: v for k, v in values if k.startswith(TRACKER_PREFIX)}
        overrides = {k: v for k, v in values if k != CAMERAS_AXIS and not k.startswith(TRACKER_PREFIX)}
        cameras = dict(values).get(CAMERAS_AXIS)
        error = None
        from_s = spec.warm_up_s or 0.0
        try:
            scenario = pipeline.load_scenario(path, seed=seed, duration_s=spec.duration_s, cameras=cameras,
                                              overrides=overrides)
            from_s = default_from_s(scenario.duration_s) if spec.warm_up_s is None else spec.warm_up_s
            if from_s > scenario.duration_s:
                raise CrossviewError(f"--from {from_s:g}: the warm-up reaches past the end of the cells, which "
                                     f"simulate {scenario.duration_s:g} s; give at most {scenario.duration_s:g}")
            resolved = _applied_overrides(scenario, overrides, seed, spec.duration_s, cameras)
            files = referenced_files(scenario)
            identity = resolved_digest(scenario)
        except ScenarioError as e:
            error = portable(one_line(e), folder)
            resolved = {**overrides, "seed": seed}
            files = ()
            identity = _key(base.name, resolved, spec.duration_s, cameras)
        if files:  # (a calibration's content is part of the cell: the resolved values name only its path)
            identity = _key(identity, [[p, hashlib.sha256(t.encode()).hexdigest()] for p, t in files])
        elif error is None and absolute_files(scenario):  # (one named by an absolute path: its content too)
            identity = _key(identity, absolute_files(scenario))
        if tracker and error is None:
            try:
                pipeline.tracker_config(preset, None, tracker)
            except ConfigError as e:
                error = portable(one_line(e), folder)
        # (A cell without tracker axes or a plug-in keeps the key it had before they were keyed: finished cells
        # stay found. The method as given, label included: a method without a label keeps its key.)
        identity_parts = (identity, seed, method_text, preset, version) + ((tracker,) if tracker else ()) + (
            (sources[method_text],) if sources[method_text] else ()) + ((("from_s", from_s),) if from_s else ()) + (
            (("zones", spec.zones),) if spec.zones is not None else ())
        cells.append(Cell(
            index=index, key=_key(*identity_parts), label=_label(values, seed, label, preset),
            values=values, seed=seed, method=method, preset=preset, scenario_name=base.name, scenario_text=text,
            files=files, overrides=resolved, version=version, error=error, keep_recording=keep_recordings,
            worker_process=worker_process, tracker_overrides=tracker,
            method_label=label if label != method else None, from_s=from_s, zones=spec.zones,
        ))
    return cells


def _applied_overrides(scenario, overrides: dict, seed: int, duration_s, cameras) -> dict:
    """The dotted keys that turn the base file into `scenario`: what `pipeline.load_scenario` applied."""
    resolved = {**overrides, "seed": seed}
    if duration_s is not None:
        resolved["duration_s"] = duration_s
    if cameras is not None and scenario.cameras.calibration:
        resolved["cameras.calibration_count"] = cameras
    elif cameras is not None:
        resolved["cameras.rows"] = scenario.cameras.rows
        resolved["cameras.cols"] = scenario.cameras.cols
    return resolved


# ---------------------------------------------------------------- the work of one cell (runs in a worker)


def _reset_peak_memory() -> None:
    """Resets this process's peak resident memory (Linux: `/proc/self/clear_refs`), so that a reused worker
    reports the cell's peak, not an earlier one's."""
    with contextlib.suppress(OSError):
        Path("/proc/self/clear_refs").write_text("5")


def _peak_memory_mb() -> float:
    """Peak resident memory of this process since `_reset_peak_memory` (elsewhere: since it started), MiB."""
    with contextlib.suppress(OSError):
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def run_cell(cell: Cell) -> dict:
    """Generates, tracks and scores one cell in a temporary folder; returns what the driver records.

    Returns:
        {"key", "status": "ok" or the cell's one-line error, "score": the score JSON or None, "timings":
        {"wall_s", "generate_s", "generate_realtime_factor", "track_s", "score_s", "tracker_fps",
        "camera_frames_per_s", "peak_memory_mb", "host"}, "recording": the recording's bytes or None}.
        "transient": whether it failed for a reason of its environment (an OSError: a full disk, the
        file-size limit, a permission), which the next run retries. Errors of bad input (`CrossviewError`)
        and of the environment are the cell's status; anything else is raised.
    """
    from crossview.recording import software_version

    _reset_peak_memory()
    start = time.perf_counter()
    timings: dict = {"host": socket.gethostname()}
    score, recording, home = None, None, None
    try:
        if cell.error is not None:
            raise CrossviewError(cell.error)
        if software_version() != cell.version:
            raise CrossviewError(f"this worker has crossview-testbed {software_version()}, the sweep {cell.version}; "
                                 "install the same version on every machine")
        _remove_dead_cell_folders()
        with tempfile.TemporaryDirectory(prefix=f"{_CELL_FOLDER}{os.getpid()}-") as tmp:
            home = copy_home(Path(tmp), cell.files)
            scenario = cell.load_scenario(Path(tmp))
            rec, tracks = Path(tmp) / f"{scenario.name}.mcap", Path(tmp) / f"{scenario.name}.tracks.mcap"
            gen = pipeline.generate(scenario, rec, progress=False, worker_process=cell.worker_process)
            t0 = time.perf_counter()
            if cell.zones is None:
                trk = pipeline.track(rec, tracks, method=cell.method, preset=cell.preset,
                                     overrides=cell.tracker_overrides or None, progress=False)
                tracker_fps, camera_frames_per_s = trk.tracker_fps, trk.camera_frames_per_s
            else:  # (the zones one after another in this worker: the sweep runs its cells side by side)
                from crossview import parallel, zoned
                from tracker.zones import MIN_OVERLAP_M

                trk = zoned.track_zoned(rec, tracks, zones_text=cell.zones, overlap_m=MIN_OVERLAP_M,
                                        executor=parallel.Executor.SERIAL, workers=1, method=cell.method,
                                        preset=cell.preset, overrides=cell.tracker_overrides or None,
                                        progress=False)
                tracker_fps, camera_frames_per_s = trk.tracker_fps_wall, trk.camera_frames_per_s
            t1 = time.perf_counter()
            _, score = pipeline.score(rec, tracks, progress=False, worker_process=cell.worker_process,
                                      from_s=cell.from_s)
            timings.update(generate_s=gen.wall_s, generate_realtime_factor=gen.realtime_factor, track_s=t1 - t0,
                           score_s=time.perf_counter() - t1, tracker_fps=tracker_fps,
                           camera_frames_per_s=camera_frames_per_s)
            if cell.keep_recording:
                recording = rec.read_bytes()
        status = "ok"
    except CrossviewError as e:
        status = one_line(e) if home is None else portable(one_line(e), home)
        transient = getattr(e, "errno", None) is not None  # (an output that failed to be written: a full disk)
    except OSError as e:  # the environment's (a full disk, the file-size limit, a permission), not the cell's
        status = f"{type(e).__name__}: {e.strerror or e}"
        transient = True
    else:
        transient = False
    timings.update(wall_s=time.perf_counter() - start, peak_memory_mb=_peak_memory_mb())
    return {"key": cell.key, "status": status, "score": score, "timings": timings, "recording": recording,
            "transient": transient}


_CELL_FOLDER = "crossview-cell-"
"""A cell's temporary folder: `crossview-cell-PID-XXXXXXXX` in the system's temporary folder."""


def _remove_dead_cell_folders() -> None:
    """Removes the cell folders of processes that no longer exist (a sweep killed with SIGKILL, or the workers a
    signal to the sweep terminated: neither could remove its own); a live process's are left alone."""
    from crossview.parallel.pool import remove_dead_folders

    remove_dead_folders(_CELL_FOLDER)


def _crashed(cell: Cell, error: BaseException) -> dict:
    """The outcome of a cell whose work raised something other than bad input (a bug, a lost worker): failed,
    and not stored, so that a rerun tries it again."""
    log.error("cell %s (%s) raised %s: %s", cell.key, cell.label, type(error).__name__, error)
    return {"key": cell.key, "status": f"{type(error).__name__}: {one_line(error)}", "score": None,
            "timings": {}, "recording": None, "crashed": True}


# ---------------------------------------------------------------- executors


# ---------------------------------------------------------------- the driver


@dataclass(frozen=True)
class SweepSummary:
    """What a sweep did: cells in all, found finished, run now, failed (of all), its wall time (s), and each
    cell's stored outcome in the grid's order (its values, status, whole score JSON and timings)."""

    cells: int
    skipped: int
    ran: int
    failed: int
    wall_s: float
    out: Path
    rows: list[dict] = field(default_factory=list)


def definition(spec: SweepSpec, cells: list[Cell]) -> dict:
    """What identifies a sweep (sweep.json): a folder holding another one's is refused."""
    base = pipeline.load_scenario(spec.scenario, duration_s=spec.duration_s)
    return {
        "format": SWEEP_FORMAT,
        "scenario": base.name,
        "scenario_resolved_sha256": resolved_digest(base),
        "axes": [{"key": a.key, "values": list(a.values)} for a in spec.axes],
        "seeds": list(spec.seeds),
        "methods": list(spec.methods),
        "presets": list(spec.presets),
        "duration_s": base.duration_s,
        "warm_up_s": spec.warm_up_s,  # (None: the default rule, `crossview.scoring.default_from_s`)
        "zones": spec.zones,
        "version": cells[0].version if cells else None,
        "cells": len(cells),
    }


IDENTITY = ("format", "version", "scenario", "axis_keys", "duration_s", "warm_up_s", "scenario_resolved_sha256")
"""What must match between a sweep and the one whose results a folder holds: the base scenario, the axes'
keys, the duration, the warm-up and the version. The values of the axes, the seeds, methods and presets may differ (a
smaller or a larger grid of the same sweep): a cell's key says whether it is already there."""


def _identity(definition: dict) -> dict:
    identity = {k: definition.get(k) for k in IDENTITY if k != "axis_keys"}
    identity["warm_up_s"] = definition.get("warm_up_s", 0.0)  # (a folder from before warm-ups scored from 0)
    identity["axis_keys"] = [a.get("key") if isinstance(a, dict) else a for a in definition.get("axes") or []]
    return identity


def check_output(out: Path, wanted: dict) -> None:
    """Refuses, before any cell runs, a folder that holds another sweep's results (creates nothing). A folder
    holding the same sweep with other axis values, seeds, methods or presets is accepted: its finished cells
    that this grid has are reused."""
    out = Path(out)
    found = out / "sweep.json"
    if out.exists() and not out.is_dir():
        raise CrossviewError(f"--output {out}: is not a folder; choose a folder for the sweep's results")
    if found.is_file():
        try:
            held = json.loads(found.read_text(encoding="utf-8"))
            held_identity = _identity(held)
        except (OSError, ValueError, UnicodeDecodeError, AttributeError) as e:
            raise CrossviewError(f"{found}: unreadable ({one_line(e)}); choose another --output") from None
        identity = _identity(wanted)
        differing = [k for k in IDENTITY if held_identity[k] != identity[k]]
        if differing:
            name = differing[0]
            raise CrossviewError(
                f"--output {out}: holds another sweep's results (its {name} {json.dumps(held_identity[name])}, "
                f"this sweep's {json.dumps(identity[name])}); choose another --output or remove that folder")
    elif (out / "results.json").exists() or (out / "cells").exists():
        raise CrossviewError(f"--output {out}: holds results without a sweep.json; choose another --output")
    for name in RESULT_FILES:  # (none of them one of the sweep's inputs, under any name)
        outputs.check_output(out / name)


RETRY_KEY = "retry"
"""Key of a cell file whose cell failed for a reason of its environment (`run_cell`'s "transient"): not final."""

RESULT_FILES = ("sweep.json", "results.json", "timings.json", "results.csv", "report.md", "manifest.json")
"""The files a sweep writes at the top of its folder."""


def _cell_path(out: Path, key: str) -> Path:
    return Path(out) / "cells" / f"{key}.json"


def _recording_path(out: Path, key: str) -> Path:
    return Path(out) / "recordings" / f"{key}.mcap"


def _finished(out: Path, cell: Cell, keep_recordings: bool) -> dict | None:
    """The stored outcome of a cell that an earlier run finished (None: run it)."""
    path = _cell_path(out, cell.key)
    if not path.exists():
        return None
    try:
        stored = json.loads(path.read_text(encoding="utf-8"))
        malformed = _malformed_cell(stored)
    except (OSError, ValueError, UnicodeDecodeError) as e:
        malformed = one_line(e)
    if malformed:
        log.warning("%s: not a cell file of this sweep (%s): running the cell again", path, malformed)
        return None
    if stored.get("key") != cell.key:
        return None
    if stored.get(RETRY_KEY):
        log.warning("cell %s failed in an earlier run for a reason of its environment (%s): running it again",
                    cell.label, stored.get("status"))
        return None
    if keep_recordings and stored["status"] == "ok" and not _recording_path(out, cell.key).is_file():
        return None  # finished before recordings were kept
    return {**stored, "index": cell.index, "label": cell.label}  # (its place in this grid, which may be another)


_CELL_FIELDS = {"key": str, "label": str, "values": list, "seed": int, "method": str, "preset": str, "status": str,
                "overrides": dict, "score": (dict, type(None)), "timings": dict}
"""The fields of a cell file (`_record`) and their JSON types."""


def _malformed_cell(stored) -> str | None:
    """What is wrong with a cell file's document (None: nothing): an object with `_CELL_FIELDS` of their types."""
    if not isinstance(stored, dict):
        return f"an object expected, got {type(stored).__name__}"
    for name, kind in _CELL_FIELDS.items():
        if not isinstance(stored.get(name), kind):
            return f"key {name!r} missing or not of its type"
    if not all(isinstance(v, list) and len(v) == 2 and isinstance(v[0], str) for v in stored["values"]):
        return "key 'values' must hold [axis, value] pairs"
    return None


def _write_bytes(data: bytes, path: Path) -> str:
    """Writes `data` atomically; returns its sha256."""
    outputs.write_bytes(data, path)
    return hashlib.sha256(data).hexdigest()


def _record(out: Path, cell: Cell, outcome: dict) -> dict:
    """Stores one cell's outcome (its recording first, then its cell file, which marks it finished)."""
    stored = {"key": cell.key, "label": cell.label, "index": cell.index, "values": [list(v) for v in cell.values],
              "seed": cell.seed, "method": cell.method_label or cell.method, "preset": cell.preset,
              "status": outcome["status"],
              "overrides": cell.overrides, "score": outcome["score"], "timings": outcome["timings"]}
    if outcome.get("crashed"):
        return stored  # not stored: a rerun runs it again
    if outcome.get("transient"):  # stored as such: a rerun runs it again, and says why
        stored[RETRY_KEY] = True
        log.warning("cell %s failed for a reason of its environment (%s); not final: the next run retries it",
                    cell.label, outcome["status"])
    if outcome.get("recording") is not None:
        stored["recording_sha256"] = _write_bytes(outcome["recording"], _recording_path(out, cell.key))
    pipeline.write_json(stored, _cell_path(out, cell.key))
    return stored


def run_sweep(spec: SweepSpec, out: Path, *, executor: Executor = Executor.POOL, workers: int | None = None,
              ray_address: str | None = None, keep_recordings: bool = False, progress: bool = True) -> SweepSummary:
    """Runs the grid's unfinished cells and writes the results, the report and its plots into `out`.

    Args:
        executor: where the cells run.
        workers: processes of the pool (default: the usable cores).
        ray_address: the Ray cluster to join (`Executor.RAY`); None starts or joins a local instance.
        keep_recordings: keep each cell's recording (`out/recordings/`) and write `out/manifest.json`.

    Raises:
        CrossviewError: bad input, found before any cell runs.
    """
    from tqdm import tqdm

    from crossview.experiments import sweep_report

    start = time.perf_counter()
    out = Path(out)
    workers = workers or processes.usable_cores()
    in_process = executor is Executor.SERIAL
    cells = plan(spec, keep_recordings=keep_recordings, worker_process=in_process and processes.can_fork_worker())
    wanted = definition(spec, cells)
    check_output(out, wanted)
    stored: dict[str, dict] = {}
    for cell in cells:
        found = _finished(out, cell, keep_recordings)
        if found is not None:
            stored[cell.key] = found
    pending = [c for c in cells if c.key not in stored]
    if stored:  # (a resume, as asked: progress, not a problem)
        log.info("%d of %d cells already finished in %s: skipped", len(stored), len(cells), out)
    # Nothing to run starts nothing: no Ray, no pool. (Ray is joined before anything is written: a bad
    # address leaves no folder.)
    with cluster.session(ray_address, connect=executor is Executor.RAY and bool(pending)) as disconnect:
        pipeline.write_json(wanted, out / "sweep.json")  # (checks that the folder can be written)
        with tqdm(total=len(cells), initial=len(stored), unit="cell", desc="sweep", disable=not progress) as bar:
            def started(cell: Cell) -> None:
                bar.set_postfix_str(cell.label)

            runner = parallel.tasks(run_cell, pending, executor=executor, workers=workers, setup=_SETUP,
                                    started=started, cancel_left=not disconnect)
            try:
                with runner if pending else contextlib.nullcontext(iter(())) as outcomes:
                    for cell, outcome, error in outcomes:
                        if error is not None:
                            outcome = _crashed(cell, error)
                        stored[cell.key] = _record(out, cell, outcome)
                        if outcome["status"] != "ok":
                            log.warning("cell %s failed: %s", cell.label, outcome["status"])
                        bar.set_postfix_str(cell.label)
                        bar.update()
            finally:
                if executor is Executor.POOL and pending:  # (the pool's workers have ended, ended by a signal too)
                    _remove_dead_cell_folders()
    rows = [stored[c.key] for c in cells]
    write_results(out, wanted, rows)
    sweep_report.write_report(out, wanted, rows)
    if keep_recordings:
        write_manifest(out, cells, rows)
    failed = sum(r["status"] != "ok" for r in rows)
    return SweepSummary(len(cells), len(cells) - len(pending), len(pending), failed, time.perf_counter() - start, out,
                        rows)


# ---------------------------------------------------------------- the result files


def result_row(stored: dict) -> dict:
    """One row of results.json: the axis values, the cell, its status and every scalar of its score JSON
    except the speeds (which vary from run to run: timings.json)."""
    row = {"key": stored["key"], **{k: v for k, v in stored["values"]}, "seed": stored["seed"],
           "method": stored["method"], "preset": stored["preset"], "status": stored["status"]}
    for name, value in (stored["score"] or {}).items():
        if name not in TIMING_FIELDS and not isinstance(value, dict | list) and name not in row:
            row[name] = value
    return row


def write_results(out: Path, wanted: dict, rows: list[dict]) -> None:
    """results.json (deterministic: the same grid gives the same bytes anywhere; with "means", each grid point's
    means over seeds and 95 % intervals, `sweep_report.means`), timings.json (the speeds,
    wall times and peak memory of each cell) and results.csv (both, one row per cell, for spreadsheets)."""
    result_rows = [result_row(r) for r in rows]
    columns = list(dict.fromkeys(k for row in result_rows for k in row))
    result_rows = [{c: row.get(c) for c in columns} for row in result_rows]  # a failed cell's scores are null
    from crossview.experiments.sweep_report import means

    pipeline.write_json({"sweep": wanted, "cells": result_rows, "means": means(wanted, rows)},
                        Path(out) / "results.json")
    timings = [{"key": r["key"], **r["timings"]} for r in rows]
    pipeline.write_json({"cells": timings}, Path(out) / "timings.json")
    timing_columns = list(dict.fromkeys(k for t in timings for k in t if k != "key"))
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns + timing_columns)
    for row, timing in zip(result_rows, timings):
        writer.writerow([_csv(row.get(c)) for c in columns] + [_csv(timing.get(c)) for c in timing_columns])
    pipeline.write_text(buffer.getvalue(), Path(out) / "results.csv")


def _csv(value) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(value)
    return str(value) if not isinstance(value, list | dict) else json.dumps(value)


# ---------------------------------------------------------------- the kept recordings


def write_manifest(out: Path, cells: list[Cell], rows: list[dict]) -> None:
    """manifest.json: each kept recording with what regenerates it (the base scenario's text, the files it
    refers to and the overrides), its resolved scenario, seed, package version and sha256. Nothing in it
    depends on where the scenario or the output folder lie."""
    recordings, files = [], {}
    for cell, row in zip(cells, rows):
        if row["status"] != "ok" or "recording_sha256" not in row:
            continue
        path = _recording_path(out, cell.key)
        with tempfile.TemporaryDirectory(prefix="crossview-manifest-") as tmp:
            scenario = cell.load_scenario(Path(tmp))
            # (without its file's place, a relative calibration stays relative: the manifest carries it)
            resolved = scenario_mod.resolved_toml(dataclasses.replace(scenario, source_path=""))
        referenced = {}
        for relative, text in cell.files:
            digest = hashlib.sha256(text.encode()).hexdigest()
            files[digest] = text
            referenced[relative] = digest
        recordings.append({
            "file": str(path.relative_to(out)), "key": cell.key, "label": cell.label,
            "sha256": row["recording_sha256"], "bytes": path.stat().st_size, "seed": cell.seed,
            "version": cell.version, "scenario_name": cell.scenario_name, "scenario_text": cell.scenario_text,
            "files": referenced, "overrides": cell.overrides, "resolved_scenario": resolved,
        })
    pipeline.write_json({"format": SWEEP_FORMAT, "recordings": recordings, "files": files},
                        Path(out) / "manifest.json")


_MANIFEST_FIELDS = {"file": str, "sha256": str, "version": str, "scenario_name": str, "scenario_text": str,
                    "overrides": dict, "files": dict}
"""The fields of a manifest's recording that `verify` uses, and their JSON types."""


@dataclass(frozen=True)
class VerifiedRecording:
    """One checked recording: its file, the sha256 the manifest holds, that of the file in the folder (None
    where the file is missing) and that of the recording regenerated here."""

    file: str
    expected_sha256: str
    file_sha256: str | None
    regenerated_sha256: str

    @property
    def matches(self) -> bool:
        return self.file_sha256 == self.expected_sha256 == self.regenerated_sha256


def verify(folder: Path, *, cells: int | None = None, progress: bool = True) -> list[VerifiedRecording]:
    """Regenerates all (or a fixed random sample of `cells`) of a kept sweep's recordings and compares the
    sha256 of each, and of the file kept in `folder`, with the manifest's.

    Raises:
        CrossviewError: no readable manifest, or `cells` < 1.
    """
    from tqdm import tqdm

    from crossview.recording import software_version

    path = Path(folder) / "manifest.json"
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
        entries = manifest["recordings"]
        texts = manifest.get("files", {})
        if not isinstance(entries, list) or not isinstance(texts, dict):
            raise TypeError("'recordings' must be an array and 'files' an object")
        for k, entry in enumerate(entries):
            for name, kind in _MANIFEST_FIELDS.items():
                if not isinstance(entry.get(name), kind):
                    raise TypeError(f"recordings[{k}]: key {name!r} missing or not of its type")
            if PurePosixPath(entry["file"]).is_absolute() or ".." in PurePosixPath(entry["file"]).parts:
                raise ValueError(f"recordings[{k}]: file {entry['file']!r} must lie inside the folder")
            if any(PurePosixPath(p).is_absolute() for p in entry["files"]):
                raise ValueError(f"recordings[{k}]: the files it names must be relative to the scenario")
            entry["file_texts"] = tuple((p, texts[d]) for p, d in entry.get("files", {}).items())
    except FileNotFoundError:
        raise CrossviewError(f"{path}: no manifest; verify needs a sweep run with --keep-recordings") from None
    except (OSError, ValueError, KeyError, TypeError, AttributeError, UnicodeDecodeError) as e:
        raise CrossviewError(f"{path}: not a sweep manifest ({one_line(e)})") from None
    for digest, text in texts.items():
        if not isinstance(text, str) or hashlib.sha256(text.encode()).hexdigest() != digest:
            raise CrossviewError(f"{path}: a file it carries does not match its sha256 {digest[:16]}")
    if cells is not None:
        if cells < 1:
            raise CrossviewError(f"--cells: {cells} must be >= 1")
        # A fixed draw: the same sample on every machine.
        entries = random.Random(0).sample(entries, min(cells, len(entries)))
    mismatched_version = {e["version"] for e in entries} - {software_version()}
    if mismatched_version:
        log.warning("the manifest's recordings were made with crossview-testbed %s, this is %s: their bytes "
                    "differ in the version they record", ", ".join(sorted(mismatched_version)), software_version())
    results = []
    for entry in tqdm(entries, unit="recording", desc="verify", disable=not progress):
        with tempfile.TemporaryDirectory(prefix="crossview-verify-") as tmp:
            scenario = load_copy(Path(tmp), entry["scenario_name"], entry["scenario_text"], entry["file_texts"],
                                 entry["overrides"])
            rec = Path(tmp) / "again.mcap"
            pipeline.generate(scenario, rec, progress=False)
            regenerated = hashlib.sha256(rec.read_bytes()).hexdigest()
        kept = Path(folder) / entry["file"]
        held = hashlib.sha256(kept.read_bytes()).hexdigest() if kept.is_file() else None
        results.append(VerifiedRecording(entry["file"], entry["sha256"], held, regenerated))
    return results
