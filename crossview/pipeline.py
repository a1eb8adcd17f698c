"""The stages of the main job, each a function the CLI and the benchmarks call: generate, track, score.

Stages talk only through files (a recording, a tracks file) so that each can be run, inspected and
replaced on its own, and `run` is nothing more than the three in a row.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import logging
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from core.errors import CrossviewError
from sim import scenario as scenario_mod
from sim.types import BoxKind, PoseTruth

log = logging.getLogger(__name__)

METHODS = ("crossview", "baseline")


def camera_grid(count: int, width_m: float, depth_m: float) -> tuple[int, int]:
    """Rows and columns of a grid of exactly `count` cameras whose shape best fits the floor.

    Args:
        count: number of cameras, >= 1.
        width_m, depth_m: floor extents along x (columns) and y (rows).
    """
    if count < 1:
        raise CrossviewError(f"--cameras: {count} must be >= 1")
    aspect = width_m / depth_m
    rows = min(
        (r for r in range(1, count + 1) if count % r == 0),
        key=lambda r: abs(math.log((count // r) / r / aspect)),
    )
    return rows, count // rows


def load_scenario(path, *, seed=None, duration_s=None, people=None, cameras=None) -> scenario_mod.Scenario:
    """Loads a scenario with the command line's overrides applied (validated like the file)."""
    overrides = {}
    if duration_s is not None:
        overrides["duration_s"] = duration_s
    if seed is not None:
        overrides["seed"] = seed
    if people is not None:
        overrides["crowd.people"] = people
    scenario = scenario_mod.load(path, overrides)
    if cameras is not None:
        rows, cols = camera_grid(cameras, scenario.store.width_m, scenario.store.depth_m)
        scenario = scenario_mod.load(path, {**overrides, "cameras.rows": rows, "cameras.cols": cols})
    return scenario


def check_writable(path: Path, inputs: tuple = ()) -> None:
    """Fails early, before any work, when `path` cannot be created, or writing it would replace one of
    `inputs` (the same file under any name) or something that is not a regular file (a device, a pipe)."""
    path = Path(path)
    for given in inputs:
        if given is not None and os.path.realpath(given) == os.path.realpath(path):
            raise CrossviewError(f"{path}: is also an input ({given}); writing it would destroy the input, "
                                 "so choose another output")
    if path.exists() and not path.is_dir() and not path.is_file():
        raise CrossviewError(f"{path}: is not a regular file (a device or a pipe); choose a file name for the output")
    folder = path.parent if str(path.parent) else Path(".")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise CrossviewError(f"{folder}: output folder cannot be created ({e.strerror})") from None
    if not os.access(folder, os.W_OK):
        raise CrossviewError(f"{folder}: output folder is not writable; choose another with --out / -o")
    if path.is_dir():
        raise CrossviewError(f"{path}: is a folder; give a file name ending in .mcap")


@dataclass(frozen=True)
class GenerateResult:
    """What `generate` made and how long it took: `wall_s` in all, of which `startup_s` before the first
    event came to be written (building the world, loading the compiled kernels, the worker's first block)."""

    path: Path
    num_cameras: int
    num_frames: int
    wall_s: float
    startup_s: float = math.nan
    duration_s: float = math.nan

    @property
    def realtime_factor(self) -> float:
        """Simulated seconds per wall-clock second, everything included."""
        return self.duration_s / self.wall_s

    @property
    def running_realtime_factor(self) -> float:
        """The same once running: simulated seconds per wall-clock second after the start-up."""
        return self.duration_s / (self.wall_s - self.startup_s)


_WRITE_BATCH = 64  # events handed to the writer at once


def generate(scenario: scenario_mod.Scenario, out: Path, *, progress: bool = True) -> GenerateResult:
    """Simulates `scenario` for its duration and writes the recording to `out` atomically."""
    from sim.simulate import Simulation  # MuJoCo is only needed for this stage

    check_writable(out, inputs=(scenario.source_path or None,))
    start = time.perf_counter()
    sim = Simulation(scenario, scenario.seed)
    frames = 0
    with contextlib.ExitStack() as stack:
        opened: list = []  # the writer and the progress bar, made while the simulation worker starts

        def open_writer() -> None:
            # The writer's modules are imported here, not before: while the worker process builds its
            # world, this process imports them, opens the file and loads the encoders.
            from tqdm import tqdm

            from crossview import recording

            header = recording.RecordingHeader(
                scenario_name=scenario.name,
                scenario_text=scenario.source_text,
                scenario_digest=scenario.digest,
                seed=scenario.seed,
                duration_s=scenario.duration_s,
                skeleton_name=sim.skeleton.name,
                software_version=recording.software_version(),
                format_version=recording.FORMAT_VERSION,
            )
            opened.append(stack.enter_context(recording.RecordingWriter(out, header, sim.cameras, sim.boxes)))
            opened.append(stack.enter_context(tqdm(total=scenario.duration_s, unit="sim s", desc="generate",
                                                   disable=not progress, leave=False)))
            recording.warm_up(sim.skeleton)

        def encoded(requests, rows, bounds) -> list:
            """A block's frames encoded straight from the detector's rows, in one compiled call (no
            CameraFrame objects: the writer takes the encoded frames in their place in the order)."""
            cameras = [r.camera for r in requests]
            times = [(r.stamp_s, r.capture_s, r.delivery_s) for r in requests]
            return opened[0].encode_frames(cameras, np.array(times, dtype=np.float64).reshape(-1, 3), bounds, rows)

        batch: list = []  # written many at a time
        started = math.nan
        for event in sim.events(scenario.duration_s, with_poses=False, while_starting=open_writer,
                                frames_of=encoded):
            if math.isnan(started):  # the first event: the start-up ends
                started = time.perf_counter() - start
                writer, bar = opened
            batch.append(event)
            if not isinstance(event, PoseTruth):
                frames += 1
            elif len(batch) >= _WRITE_BATCH:
                writer.write_many(batch)
                batch = []
                bar.update(max(0.0, min(event.t_s, scenario.duration_s) - bar.n))
        opened[0].write_many(batch)  # (`events` calls open_writer before its first event)
    return GenerateResult(out, len(sim.cameras), frames, time.perf_counter() - start, started, scenario.duration_s)


def make_tracker(method: str, cameras, preset: str, config_path: Path | None, skeleton):
    """The tracker of `method` configured from a preset and optionally a TOML file."""
    from tracker.baseline import BaselineTracker
    from tracker.config import TrackerConfig
    from tracker.tracker import Tracker

    config = TrackerConfig.from_toml(config_path, base=preset) if config_path else TrackerConfig.preset(preset)
    if method == "crossview":
        return Tracker(cameras, config, skeleton), config
    if method == "baseline":
        return BaselineTracker(cameras, config, skeleton), config
    raise CrossviewError(f"--method: {method!r} is not one of {', '.join(METHODS)}")


@dataclass(frozen=True)
class TrackResult:
    path: Path
    updates: int
    tracker_s: float
    num_cameras: int

    @property
    def camera_frames_per_s(self) -> float:
        return self.updates / self.tracker_s if self.tracker_s > 0 else math.nan

    @property
    def tracker_fps(self) -> float:
        """Frames per second in the paper's sense: one frame is every camera updated once."""
        return self.camera_frames_per_s / self.num_cameras


def track(
    rec_path: Path,
    out: Path,
    *,
    method: str = "crossview",
    preset: str = "store",
    config_path: Path | None = None,
    progress: bool = True,
) -> TrackResult:
    """Runs a tracker over a recording's frames in delivery order and writes the tracks file."""
    from tqdm import tqdm

    from core.types import SKELETONS
    from crossview import recording

    check_writable(out, inputs=(rec_path, config_path))
    rec = recording.open_recording(rec_path)
    skeleton = SKELETONS[rec.header.skeleton_name]
    tracker, config = make_tracker(method, rec.cameras, preset, config_path, skeleton)
    header = recording.TracksHeader(
        scenario_name=rec.header.scenario_name,
        scenario_digest=rec.header.scenario_digest,
        seed=rec.header.seed,
        method=method,
        preset=preset,
        config=_jsonable(dataclasses.asdict(config)),
        skeleton_name=skeleton.name,
        software_version=recording.software_version(),
        format_version=recording.TRACKS_FORMAT_VERSION,
    )
    warm_up_tracker(method, rec, preset, config_path, skeleton)
    updates = 0
    tracker_s = 0.0
    with recording.TracksWriter(out, header, rec.cameras) as writer:
        for camera_frame in tqdm(rec.frames(), unit="frame", desc="track", disable=not progress, leave=False):
            start = time.perf_counter()
            tracker.update(camera_frame.frame)
            tracker_s += time.perf_counter() - start
            updates += 1
            writer.write(tracker.last_output)
        writer.finish({"tracker_s": tracker_s, "updates": updates, "num_cameras": len(rec.cameras)})
    return TrackResult(out, updates, tracker_s, len(rec.cameras))


WARM_UP_S = 2.0
"""Stamps of the frames a throwaway tracker sees before timing starts (see `warm_up_tracker`), seconds."""


def warm_up_tracker(method: str, rec, preset: str, config_path: Path | None, skeleton) -> None:
    """Runs a throwaway tracker over the first `WARM_UP_S` of frames, untimed.

    The tracker's numba kernels compile on first use (tens of seconds on a fresh install, then loaded from
    the on-disk cache in under a second); that is not tracking time and must not enter the FPS figure.
    """
    tracker, _ = make_tracker(method, rec.cameras, preset, config_path, skeleton)
    for camera_frame in rec.frames():
        if camera_frame.frame.stamp_s > WARM_UP_S:
            break
        tracker.update(camera_frame.frame)


def _jsonable(value):
    """Config dicts as JSON-safe values (Enums by value, tuples as lists)."""
    return json.loads(json.dumps(value, default=lambda v: getattr(v, "value", str(v))))


def watched_floor(boxes) -> tuple[float, float, float, float] | None:
    """(x_min, y_min, x_max, y_max) of the store's floor (the cameras' ground), metres; None without a floor."""
    floors = [b for b in boxes if b.kind is BoxKind.FLOOR]
    if not floors:
        return None
    corners = []
    for b in floors:
        c, s = np.cos(b.yaw_rad), np.sin(b.yaw_rad)
        for dx, dy in ((-1, -1), (-1, 1), (1, -1), (1, 1)):
            hx, hy = dx * b.size_m[0] / 2, dy * b.size_m[1] / 2
            corners.append((b.center_m[0] + c * hx - s * hy, b.center_m[1] + s * hx + c * hy))
    xy = np.array(corners)
    return (*xy.min(axis=0).tolist(), *xy.max(axis=0).tolist())


def score(rec_path: Path, tracks_path: Path, *, progress: bool = True):
    """Scores a tracks file against the recording it was made from; returns (report, json dict)."""
    from tqdm import tqdm

    from crossview import recording
    from crossview.scoring import score as score_outputs

    rec = recording.open_recording(rec_path)
    tracks = recording.open_tracks(tracks_path)
    if tracks.header.scenario_digest != rec.header.scenario_digest or tracks.header.seed != rec.header.seed:
        raise CrossviewError(
            f"{tracks_path}: tracks were made from scenario {tracks.header.scenario_name!r} seed {tracks.header.seed} "
            f"(digest {tracks.header.scenario_digest[:12]}), not from {rec_path} "
            f"({rec.header.scenario_name!r} seed {rec.header.seed}, digest {rec.header.scenario_digest[:12]})"
        )
    truth = list(rec.truth())
    outputs = list(tqdm(tracks.outputs(), unit="output", desc="score", disable=not progress, leave=False))
    report = score_outputs(truth, outputs, rec.frames(), rec.cameras, scored_area=watched_floor(rec.boxes),
                           skeleton=rec.skeleton)
    summary = tracks.summary or {}
    tracker_s = summary.get("tracker_s") or 0.0
    updates = summary.get("updates") or len(outputs)
    cams = len(rec.cameras)
    frames_per_s = updates / tracker_s if tracker_s > 0 else None
    people = {int(i) for p in truth for i in p.person_ids}
    result = report.to_json(
        scenario=rec.header.scenario_name,
        seed=rec.header.seed,
        num_cameras=cams,
        num_people=len(people),
        duration_s=rec.header.duration_s,
        tracker_fps=frames_per_s / cams if frames_per_s else None,
        camera_frames_per_s=frames_per_s,
    )
    return report, result


def write_json(result: dict, path: Path) -> None:
    """Writes a JSON document (the score JSON, the bench's figures) atomically."""
    write_text(json.dumps(result, indent=2, sort_keys=False) + "\n", path)


def write_text(text: str, path: Path) -> None:
    """Writes `text` to `path` atomically (a temporary file in the same folder, renamed at the end)."""
    check_writable(path)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
