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
import time
from dataclasses import dataclass
from pathlib import Path

from core.errors import ConfigError, CrossviewError
from core.head import HeadPoints
from core.records import watched_floor
from core.types import COCO17
from crossview import outputs
from sim import scenario as scenario_mod
from sim.cameras import camera_grid
from sim.sensing.profiles import is_profile_file

log = logging.getLogger(__name__)

def load_scenario(path, *, seed=None, duration_s=None, people=None, cameras=None,
                  overrides: dict | None = None) -> scenario_mod.Scenario:
    """Loads a scenario with the command line's overrides applied (validated like the file).

    Args:
        overrides: any further dotted keys (`{"clock.fps": 5.0}`), applied under the named options.
    """
    overrides = dict(overrides or {})
    if duration_s is not None:
        overrides["duration_s"] = duration_s
    if seed is not None:
        overrides["seed"] = seed
    if people is not None:
        overrides["crowd.people"] = people
    scenario = scenario_mod.load(path, overrides)
    if cameras is not None and scenario.cameras.calibration:  # a real rig: that many of its cameras
        return scenario_mod.load(path, {**overrides, "cameras.calibration_count": cameras})
    if cameras is not None:
        rows, cols = camera_grid(cameras, scenario.store.width_m, scenario.store.depth_m)
        scenario = scenario_mod.load(path, {**overrides, "cameras.rows": rows, "cameras.cols": cols})
    return scenario


def scenario_files(name_or_path) -> tuple[Path, ...]:
    """The files a scenario's command reads: its file (a shipped name resolved as `sim.scenario.load` does)
    and the calibration file and detector profile file it names (relative to its folder), read from the TOML
    without validating it (the command does that, and names what is wrong); an unreadable file names none beyond
    itself."""
    from core import tomlfile
    from crossview.formats.json_input import check_input_file

    path = scenario_mod.resolve_path(name_or_path)
    check_input_file(path, scenario_mod.ScenarioError)
    try:
        with open(path, "rb") as f:
            tree = tomlfile.load(f)
    except (OSError, ValueError):
        return (path,)
    named = []
    for section, key in (("cameras", "calibration"), ("detector", "profile")):
        table = tree.get(section)
        value = table.get(key) if isinstance(table, dict) else None
        if isinstance(value, str) and value and (key != "profile" or is_profile_file(value)):
            named.append(path.parent / value)
    return (path, *named)


def check_writable(path: Path, inputs: tuple = ()) -> None:
    """Fails early, before any work, when `path` cannot be written: it is one of `inputs` (under any name),
    not a regular file, a folder, or its folder cannot be made (`crossview.outputs.check_output`). No
    folder is made here: that happens when the output is written, and is undone if writing fails."""
    outputs.check_output(path, inputs)


@dataclass(frozen=True)
class GenerateResult:
    """What `generate` made and how long it took: `wall_s` in all, of which `startup_s` before the first
    block came to be written (building the world, loading the compiled kernels, the worker's first block)."""

    path: Path
    num_cameras: int
    num_frames: int
    wall_s: float
    startup_s: float = math.nan
    duration_s: float = math.nan
    images: int = 0
    images_s: float = 0.0  # of `wall_s`, making the pictures (`--images`)

    @property
    def realtime_factor(self) -> float:
        """Simulated seconds per wall-clock second, everything included."""
        return self.duration_s / self.wall_s

    @property
    def running_realtime_factor(self) -> float:
        """The same once running: simulated seconds per wall-clock second after the start-up."""
        return self.duration_s / (self.wall_s - self.startup_s)


MAX_CAMERA_FRAMES = 5_000_000
"""Most camera frames one generation may schedule (duration x frame rate x cameras): store_layout2's 28
cameras for about 5 hours, the supermarket's 60 for 2.3 hours."""
_SCHEDULE_BYTES_PER_FRAME = 170  # the clock's schedule, as arrays and the lists made of them


def generate(scenario: scenario_mod.Scenario, out: Path, *, progress: bool = True,
             worker_process: bool = True, images_per_s: float | None = None, gl: str | None = None,
             live=None, tracking=None) -> GenerateResult:
    """Simulates `scenario` for its duration and writes the recording to `out` atomically.

    Args:
        worker_process: simulate in a second process pipelined with the writer (`sim.simulate.Simulation`);
            False where the cores are already busy (a sweep's cells run side by side). The bytes are the same.
        images_per_s: store this many rendered JPEG pictures per second per camera, at most the cameras'
            frame rate (`sim.render.FrameImages`); None: none. Rendering needs an offscreen OpenGL
            backend chosen before MuJoCo is imported in this process (`sim.render.choose_backend`).
        gl: that backend ("egl", "osmesa"); None: MUJOCO_GL when it names one, else probed.
        live: where every message written is also published as it is written (`crossview.live.Paced`), or None.
        tracking: `live_run`'s maker of a `Tracking` from the recording's header and cameras, which is given each
            camera frame as soon as it is written (`RecordingWriter`'s `frames_to`); None: nothing tracked.
    """
    check_writable(out, inputs=(scenario.source_path or None,))
    if images_per_s is not None:
        from sim.render import check_image_rate, choose_backend

        check_image_rate(images_per_s, scenario.clock.fps, scenario.source_path or scenario.name)
        choose_backend(gl)
    from sim.simulate import Simulation  # MuJoCo is only needed for this stage

    start = time.perf_counter()
    sim = Simulation(scenario, scenario.seed, worker_process=worker_process)
    scheduled = scenario.duration_s * scenario.clock.fps * len(sim.cameras)
    if scheduled > MAX_CAMERA_FRAMES:
        raise CrossviewError(
            f"{scenario.source_path or scenario.name}: duration_s = {scenario.duration_s:g} with {len(sim.cameras)} "
            f"cameras at {scenario.clock.fps:g} fps schedules {scheduled:,.0f} camera frames, more than the "
            f"{MAX_CAMERA_FRAMES:,} one recording may hold (their schedule is made up front, about "
            f"{_SCHEDULE_BYTES_PER_FRAME * scheduled / 2**30:.1f} GiB); generate a shorter duration, or several")
    frames = 0
    started = math.nan
    with contextlib.ExitStack() as stack:
        # The simulation starts first: while its worker process builds the world, this process imports the
        # writer's modules, loads its encoders and opens the file. (Left in any way, the stack aborts the
        # file and stops the worker.)
        blocks = stack.enter_context(sim.blocks(scenario.duration_s, with_poses=False))
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
        writer = recording.RecordingWriter(out, header, sim.cameras, sim.boxes, inputs=(scenario.source_path or None,),
                                           live=live)
        if tracking is not None:  # (opened after the recording, whose channels come first live; entered before it,
            try:  # so that it closes after it: the writer's close delivers the last frames)
                writer.frames_to = stack.enter_context(tracking(header, sim.cameras)).update_from_bytes
            except BaseException:
                writer.abort()
                raise
        stack.enter_context(writer)
        bar = stack.enter_context(tqdm(total=scenario.duration_s, unit="sim s", desc="generate",
                                       disable=not progress, leave=False))
        images = None
        if images_per_s is not None:  # (made here, after the worker's fork: its OpenGL context stays here)
            from sim.render import FrameImages

            images = stack.enter_context(FrameImages(scenario, scenario.seed, sim.cameras, images_per_s,
                                                     scenario.clock.fps))
        for block in blocks:
            if math.isnan(started):  # the first block: the start-up ends
                started = time.perf_counter() - start
            pictures = None
            if images is not None and block.requests:  # (the requests come in capture order)
                pictures = images.pictures([r.camera for r in block.requests], [r.capture_s for r in block.requests])
            # The writer encodes the block's frames and writes what is due, in log-time order.
            frames += writer.write_block(block, pictures)
            bar.update(max(0.0, min(block.t, scenario.duration_s) - bar.n))
    return GenerateResult(out, len(sim.cameras), frames, time.perf_counter() - start, started, scenario.duration_s,
                          images.count if images else 0, images.render_s if images else 0.0)


def tracker_config(preset: str, config_path: Path | None = None, overrides: dict | None = None):
    """The tracker configuration of a preset, optionally overridden by a TOML file and then by `overrides`
    (field -> value, as a sweep's `tracker.*` axes give them); validated: a `ConfigError` names the file or
    the field."""
    from tracker.config import TrackerConfig

    config = TrackerConfig.from_toml(config_path, base=preset) if config_path else TrackerConfig.preset(preset)
    if overrides:
        names = {f.name for f in dataclasses.fields(TrackerConfig)}
        for key in overrides:
            if key not in names:
                raise ConfigError(f"tracker.{key}: unknown tracker setting; valid: {', '.join(sorted(names))}")
        # All at once: the rules between fields (view_margin_m >= alpha_3d_m, ...) hold for the result, not
        # for a half-applied set.
        try:
            config = config.replace(**overrides)
        except ConfigError as e:  # (TrackerConfig raises nothing else for a bad value)
            given = ", ".join(f"tracker.{k} = {v!r}" for k, v in overrides.items())
            raise ConfigError(f"{given}: {e}") from None
    return config


def make_tracker(method: str, cameras, preset: str, config_path: Path | None, skeleton,
                 overrides: dict | None = None):
    """The tracker `method` names (built in, registered or `package.module:Class`, see `crossview.plugins`),
    configured from a preset, optionally a TOML file and `overrides` (`tracker_config`); returns (tracker,
    config)."""
    from crossview.plugins import resolve

    resolved = resolve(method)
    config = tracker_config(preset, config_path, overrides)
    try:
        config.check_fits(len(cameras), skeleton.num_joints)
    except ConfigError as e:  # (the one error check_fits raises)
        raise ConfigError(f"{config_path or '--preset ' + preset}: {e}") from None
    return resolved.make(cameras, config, skeleton), config


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


class Tracking:
    """One tracker's run: a tracker fed camera frames one at a time in delivery order (`update`), its outputs
    written to a tracks file (`crossview.recording.TracksWriter`, published to `live` as written), and the
    tracker's own seconds counted. What `track` does over a recording's frames and what `run --live` does over the
    frames as the simulation makes them (`live_run`): the same tracker, frames and bytes.

    Use as a context manager: the tracks file appears when it exits cleanly; `result` then says what was done.

    Args:
        header_of: the recording's header (scenario name, digest, seed, skeleton name).
        cameras: the cameras as the recording's header holds them (`Recording.cameras`).
        warm_up_s: feed the frames stamped up to this also to a throwaway tracker first, untimed, so that the
            tracker's compiled kernels load (`warm_up_tracker`) outside the tracker's seconds; None: no warm-up
            here (`track` warms up on the recording before).
    """

    def __init__(self, header_of, cameras, out: Path, *, method: str = "crossview", preset: str = "store",
                 config_path: Path | None = None, overrides: dict | None = None, inputs: tuple = (), live=None,
                 warm_up_s: float | None = None):
        from core.types import SKELETONS
        from crossview import recording
        from crossview.plugins import resolve

        self._resolved = resolve(method)
        self._skeleton = skeleton = SKELETONS[header_of.skeleton_name]
        self._cameras = list(cameras)
        self._tracker, config = make_tracker(method, self._cameras, preset, config_path, skeleton, overrides)
        self._warm = None
        self._warm_up_s = warm_up_s
        if warm_up_s is not None:
            self._warm, _ = make_tracker(method, self._cameras, preset, config_path, skeleton, overrides)
        header = recording.TracksHeader(
            scenario_name=header_of.scenario_name,
            scenario_digest=header_of.scenario_digest,
            seed=header_of.seed,
            method=method,
            preset=preset,
            config=jsonable(dataclasses.asdict(config)),
            skeleton_name=skeleton.name,
            software_version=recording.software_version(),
            format_version=recording.TRACKS_FORMAT_VERSION,
        )
        self._writer = recording.TracksWriter(out, header, self._cameras, inputs=inputs, live=live)
        self.updates = 0
        self.tracker_s = 0.0
        self._out = out
        self.result: TrackResult | None = None

    def update(self, frame) -> None:
        """Tracks one camera frame (`core.types.Frame`), the next in delivery order, and writes the output."""
        if self._warm is not None:
            if frame.stamp_s <= self._warm_up_s:
                self._resolved.update(self._warm, frame, self.updates)
            else:
                self._warm = None
        start = time.perf_counter()
        targets = self._resolved.update(self._tracker, frame, self.updates)
        self.tracker_s += time.perf_counter() - start
        self._writer.write(self._resolved.output(self._tracker, targets, frame, self.updates, self._skeleton))
        self.updates += 1

    def update_from_bytes(self, data: bytes) -> None:
        """`update` of a frame given as the recording's `crossview.CameraFrame` bytes
        (`crossview.recording.RecordingWriter`'s `frames_to`)."""
        from crossview.recording import camera_frame_from_bytes

        self.update(camera_frame_from_bytes(data).frame)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self._writer.finish({"tracker_s": self.tracker_s, "updates": self.updates,
                                 "num_cameras": len(self._cameras),
                                 ASSIGNMENTS_KEY: self._resolved.reports_assignments(self._tracker)})
        self._writer.__exit__(exc_type, exc, tb)
        if exc_type is None:
            self.result = TrackResult(self._out, self.updates, self.tracker_s, len(self._cameras))


def track(
    rec_path: Path,
    out: Path,
    *,
    method: str = "crossview",
    preset: str = "store",
    config_path: Path | None = None,
    overrides: dict | None = None,
    progress: bool = True,
    live=None,
) -> TrackResult:
    """Runs a tracker over a recording's frames in delivery order and writes the tracks file (configured by
    `tracker_config(preset, config_path, overrides)`); with `live`, each message written is also published there
    (`crossview.live.Paced`)."""
    from tqdm import tqdm

    from core.types import SKELETONS
    from crossview import recording

    check_writable(out, inputs=(rec_path, config_path))
    rec = recording.open_recording(rec_path)
    skeleton = SKELETONS[rec.header.skeleton_name]
    warm_up_tracker(method, rec, preset, config_path, skeleton, overrides)
    with Tracking(rec.header, rec.cameras, out, method=method, preset=preset, config_path=config_path,
                  overrides=overrides, inputs=(rec_path, config_path), live=live) as tracking:
        for camera_frame in tqdm(rec.frames(), unit="frame", desc="track", disable=not progress, leave=False):
            tracking.update(camera_frame.frame)
    return tracking.result


def live_run(scenario: scenario_mod.Scenario, rec_path: Path, tracks_path: Path, *, method: str = "crossview",
             preset: str = "store", config_path: Path | None = None, progress: bool = True,
             live=None) -> tuple[GenerateResult, TrackResult]:
    """`run --live`'s generate and track in one pass: each camera frame is tracked as soon as the recording
    writer has written it (and published it to `live`), so the tracker's outputs are published on the tracks
    file's channels right after the frame's detections, paced to simulated time with them. The tracker sees the
    frames in delivery order, decoded from the bytes the recording holds (a frame delivered after a block's end
    waits for the next block, as in the file), so both files are the bytes `generate` then `track` write.
    Returns what each would."""
    from crossview import recording

    check_writable(tracks_path, inputs=(rec_path, config_path))
    tracking: list[Tracking] = []

    def tracking_of(header, cameras) -> Tracking:
        # The cameras as the recording's header holds them (its JSON read back), as `track` gets them.
        as_read = [recording.camera_from_json(json.loads(json.dumps(recording.camera_json(c)))) for c in cameras]
        tracking.append(Tracking(header, as_read, tracks_path, method=method, preset=preset, config_path=config_path,
                                 inputs=(rec_path, config_path), live=live, warm_up_s=WARM_UP_S))
        return tracking[0]

    gen = generate(scenario, rec_path, progress=progress, live=live, tracking=tracking_of)
    return gen, tracking[0].result


ASSIGNMENTS_KEY = "detection_assignments"
"""Key of a tracks file's summary: false when the tracker did not say where each detection went (a plug-in
without `last_output`); its score then leaves association accuracy out."""


WARM_UP_S = 2.0
"""Stamps of the frames a throwaway tracker sees before timing starts (see `warm_up_tracker`), seconds."""


def warm_up_tracker(method: str, rec, preset: str, config_path: Path | None, skeleton,
                    overrides: dict | None = None, until_s: float = WARM_UP_S) -> None:
    """Runs a throwaway tracker over the first `WARM_UP_S` of frames, untimed.

    The tracker's numba kernels compile on first use (tens of seconds on a fresh install, then loaded from
    the on-disk cache in under a second); that is not tracking time and must not enter the FPS figure.
    """
    from crossview.plugins import resolve

    resolved = resolve(method)
    tracker, _ = make_tracker(method, rec.cameras, preset, config_path, skeleton, overrides)
    for index, camera_frame in enumerate(rec.frames()):
        if camera_frame.frame.stamp_s > until_s:
            break
        resolved.update(tracker, camera_frame.frame, index)


def jsonable(value):
    """Config dicts as JSON-safe values (Enums by value, tuples as lists, anything else as its text)."""
    return json.loads(json.dumps(value, default=lambda v: getattr(v, "value", str(v))))


def truth_head(rec) -> HeadPoints | None:
    """Where PCP puts the true head joints of an opened recording (`crossview.scoring.score`'s `truth_head`):
    what the `[scoring] truth_head` of the scenario it keeps says (`sim.scenario.ScoringConfig.head_points`)
    when its truth is COCO-17; else None, evaluate.py's mapping. A recording converted from a dataset keeps no
    scenario, and its 14-joint truth already holds the annotated head joints.

    Raises:
        ScenarioError: the scenario text the recording keeps is not a valid scenario.
    """
    if rec.skeleton.name != COCO17.name or not rec.header.scenario_text:
        return None
    return scenario_mod.from_source_text(rec.header.scenario_text, rec.header.scenario_name,
                                         str(rec.path)).scoring.head_points()


def open_run(rec_path: Path, tracks_path: Path):
    """Opens a recording and a tracks file made from it; (Recording, Tracks). CrossviewError when the tracks
    were made from another scenario or seed."""
    from crossview import recording

    rec = recording.open_recording(rec_path)
    tracks = recording.open_tracks(tracks_path)
    check_tracks_match(rec, tracks)
    return rec, tracks


def score(rec_path: Path, tracks_path: Path, *, progress: bool = True, worker_process: bool | None = None,
          from_s: float = 0.0):
    """Scores a tracks file, or a result file (result_3d.json or JSON lines, `crossview.formats.results`), against
    the recording it was made from; returns (report, json dict).

    A result file holds no detection assignments, cameras or timings: association accuracy, the per-camera
    table and the FPS figures are then left out (null).

    worker_process: compute most of the per-camera 2D scores of a tracks file in a second process (forked),
    which reads the tracks file on its own while this one computes the rest (`SCORED_HERE` of the cameras'
    2D scores, and everything else): the same figures, sooner at 240 cameras (docs/metrics.md, "Speed").
    None: where the machine has more than one core; True: wherever fork exists.

    from_s: the warm-up left out, seconds after the recording's first truth sample (`crossview.scoring.score`).
    """
    from tqdm import tqdm

    from core import processes
    from crossview import recording
    from crossview.formats.results import is_result_file, read_results
    from crossview.scoring import TruthTimeline
    from crossview.scoring import score as score_outputs
    from crossview.scoring.orchestrate import SCORE_WORKER, SCORED_HERE, camera_2d_worker
    from crossview.scoring.switches import zones_of

    rec = recording.open_recording(rec_path)
    truth = list(rec.truth())
    summary: dict = {}
    if is_result_file(tracks_path):
        outputs = counted = read_results(tracks_path, rec.skeleton, TruthTimeline(truth).span)
        frames, cameras = None, None
    else:
        tracks = recording.open_tracks(tracks_path)
        check_tracks_match(rec, tracks)
        counted = _Counted(tracks.outputs())  # streamed: scoring holds one output per grid tick, not all
        outputs = tqdm(counted, unit="output", desc="score", disable=not progress, leave=False)
        summary = tracks.summary or {}
        frames = rec.frames() if summary.get(ASSIGNMENTS_KEY, True) else None
        cameras = rec.cameras
    if worker_process is None:
        worker_process = processes.can_fork_worker()
    beside = None
    here: bool | set[str] = True
    if cameras is not None and len(cameras) > 1 and worker_process and processes.can_fork():
        # Every SCORED_HERE-th camera here, the others in the worker, forked after the truth is read: it
        # shares its pages instead of reading it again.
        here = {c.name for c in cameras[::SCORED_HERE]}
        beside = processes.Worker(camera_2d_worker, (truth, rec.skeleton.num_joints,
                                                      [c for c in cameras if c.name not in here],
                                                      Path(tracks_path), from_s), "crossview-score-2d",
                                   SCORE_WORKER)
    try:
        if beside is not None:
            beside.start()
        report = score_outputs(truth, outputs, frames, cameras, scored_area=watched_floor(rec.boxes),
                               skeleton=rec.skeleton, projected=here, truth_head=truth_head(rec), from_s=from_s,
                               zones=zones_of(summary.get("zones") or []))
        if beside is not None:
            there = beside.receive()[1]
            report.camera_2d = {c.name: report.camera_2d[c.name] if c.name in here else there[c.name]
                                for c in cameras}
    finally:
        if beside is not None:
            beside.stop()
    tracker_s = summary.get("tracker_s") or 0.0
    updates = summary.get("updates") or len(counted)
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


class _Counted:
    """An iterable that counts the items it has yielded (`len`)."""

    def __init__(self, items):
        self._items, self._n = items, 0

    def __iter__(self):
        for item in self._items:
            self._n += 1
            yield item

    def __len__(self) -> int:
        return self._n


def check_tracks_match(rec, tracks) -> None:
    """Raises CrossviewError unless the opened tracks file was made from the opened recording (the same
    scenario text and seed)."""
    if tracks.header.scenario_digest != rec.header.scenario_digest or tracks.header.seed != rec.header.seed:
        raise CrossviewError(
            f"{tracks.path}: tracks were made from scenario {tracks.header.scenario_name!r} seed {tracks.header.seed} "
            f"(digest {tracks.header.scenario_digest[:12]}), not from {rec.path} "
            f"({rec.header.scenario_name!r} seed {rec.header.seed}, digest {rec.header.scenario_digest[:12]})"
        )


def write_score_map(result: dict, rec_path: Path, path: Path, inputs: tuple = ()) -> None:
    """Draws a score JSON's floor grid and time line over its recording's store (`crossview score --map`) and
    writes the PNG atomically."""
    from crossview import recording
    from crossview.pictures.score_map import score_map_png

    rec = recording.open_recording(rec_path)
    title = (f"{rec.header.scenario_name} seed {rec.header.seed}, {len(rec.cameras)} cameras: PCP "
             f"{_figure(result.get('pcp'))}, IDF1 {_figure(result.get('idf1'))}, {result.get('id_switches')} "
             f"ID switches, {result.get('false_positives')} false positives, scored from {result['from_s']:g} s")
    outputs.write_bytes(score_map_png(result, rec.boxes, title), path, inputs)


def _figure(value) -> str:
    return "-" if value is None else f"{value:.3f}"


def write_json(result: dict, path: Path, inputs: tuple = ()) -> None:
    """Writes a JSON document (the score JSON, the bench's figures) atomically."""
    write_text(json.dumps(result, indent=2, sort_keys=False) + "\n", path, inputs)


def write_text(text: str, path: Path, inputs: tuple = ()) -> None:
    """Writes `text` (UTF-8) to `path` atomically (`crossview.outputs.AtomicOutput`)."""
    outputs.write_bytes(text.encode("utf-8"), path, inputs)
