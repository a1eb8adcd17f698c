"""One store tracked as zones, each zone's tracker in its own worker (`crossview track --zones`, issue 47).

The driver reads the recording's frames in delivery order and hands each frame to the tracker of every zone
that holds its camera (`tracker.zones`), a batch at a time, all zones at once (`crossview.parallel.actors`:
processes of this machine, or Ray actors); the zones' outputs go through the merger (`tracker.handover`) into
one ordinary tracks file, which `score`, `compare`, `render` and the exports read unchanged. Each zone's tracker
is the configured `Tracker`, fed its cameras' frames in delivery order, so its outputs, and the merged file's
outputs, are the same whatever the executor and the number of workers.

Speed: `camera_frames_per_s` is the recording's camera frames over the wall-clock time of the whole (the
driver's reading and merging, the transfers, the zones in parallel); `zone_tracker_s` is the sum of the zones'
own update times, the single tracker's measure.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path

from core.errors import ConfigError, CrossviewError
from core.records import watched_floor
from crossview import parallel, pipeline

BATCH_S = 0.5
"""Simulated seconds of frames handed to the zones per call: long enough that a call's transfer is small beside
its tracking, short enough that the driver's memory holds little."""


def zone_count(text: str) -> int | None:
    """`--zones auto|N` as a count, None for auto (`tracker.zones.cut` then picks it).

    Raises:
        ConfigError: neither auto nor a positive integer."""
    if text == "auto":
        return None
    if not text.isdigit() or int(text) < 1:
        raise ConfigError(f"--zones {text}: must be auto or a whole number of zones, at least 1")
    return int(text)


def cut(cameras, boxes, text: str, overlap_m: float):
    """The zones of a store (its cameras, its boxes' floor) for `--zones TEXT`."""
    from tracker import zones

    floor = watched_floor(boxes)
    if floor is None:
        raise CrossviewError("--zones: the recording keeps no store floor to cut into zones")
    return zones.cut(cameras, floor, zone_count(text), overlap_m)


class ZoneTracker:
    """A zone's tracker in its worker: the configured tracker over the zone's cameras."""

    def __init__(self, method: str, cameras, preset: str, config_path, skeleton, overrides):
        from crossview.plugins import resolve

        self.args = (method, cameras, preset, config_path, skeleton, overrides)
        self.resolved = resolve(method)
        self.skeleton = skeleton
        self.tracker, _ = pipeline.make_tracker(method, cameras, preset, config_path, skeleton, overrides)
        self.updates = 0

    def warm_up(self, frames) -> None:
        """A throwaway tracker over the first frames, untimed (numba's kernels loaded: `pipeline.warm_up_tracker`)."""
        method, cameras, preset, config_path, skeleton, overrides = self.args
        tracker, _ = pipeline.make_tracker(method, cameras, preset, config_path, skeleton, overrides)
        for index, frame in enumerate(frames):
            self.resolved.update(tracker, frame, index)

    def update(self, frames) -> tuple[list, float]:
        """The outputs of the frames (in their order) and the seconds spent in the tracker's update."""
        outputs, spent = [], 0.0
        for frame in frames:
            start = time.perf_counter()
            targets = self.resolved.update(self.tracker, frame, self.updates)
            spent += time.perf_counter() - start
            outputs.append(self.resolved.output(self.tracker, targets, frame, self.updates, self.skeleton))
            self.updates += 1
        return outputs, spent


class ZoneGroup:
    """A worker's zones (`assign`): one `ZoneTracker` each, called together."""

    def __init__(self, zone_args: list[tuple]):
        self.trackers = [ZoneTracker(*a) for a in zone_args]

    def warm_up(self, frames_per_zone: list) -> None:
        for tracker, frames in zip(self.trackers, frames_per_zone, strict=True):
            tracker.warm_up(frames)

    def update(self, frames_per_zone: list) -> list[tuple[list, float]]:
        return [tracker.update(frames) for tracker, frames in zip(self.trackers, frames_per_zone, strict=True)]

    def peak_memory(self) -> int:
        """Peak resident memory of the process holding these zones so far, bytes."""
        return peak_memory()


def peak_memory() -> int:
    """Peak resident memory of this process so far, bytes (`resource.getrusage`; Linux counts kilobytes)."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def assign(loads: list[int], workers: int) -> list[list[int]]:
    """Zones to workers: the zone with the most cameras first, each to the worker with the fewest cameras so far
    (ties: the lower index); each worker's zones in index order. Fixed by the loads alone."""
    if workers < 1:
        raise ConfigError(f"--workers {workers}: must be at least 1")
    groups: list[list[int]] = [[] for _ in range(min(workers, len(loads)))]
    totals = [0] * len(groups)
    for z in sorted(range(len(loads)), key=lambda z: (-loads[z], z)):
        w = min(range(len(groups)), key=lambda w: (totals[w], w))
        groups[w].append(z)
        totals[w] += loads[z]
    return [sorted(g) for g in groups]


@dataclass(frozen=True)
class ZonedResult:
    """What `track_zoned` did: the tracks file, camera frames, wall-clock seconds of the whole, the zones' update
    seconds (each, and so their sum), the zones' camera counts, the camera frames each zone tracked, the
    hand-overs, and the peak resident memory (bytes) of the command's process and of each worker's (the workers'
    are the command's own when it holds the zones itself)."""

    path: Path
    updates: int
    workers: int
    wall_s: float
    zone_tracker_s: tuple[float, ...]
    zone_cameras: tuple[int, ...]
    handovers: int
    num_cameras: int
    zone_frames: tuple[int, ...] = ()
    peak_memory: int = 0
    worker_peak_memory: tuple[int, ...] = ()

    @property
    def camera_frames_per_s(self) -> float:
        return self.updates / self.wall_s if self.wall_s > 0 else float("nan")

    @property
    def tracker_fps_wall(self) -> float:
        """Frames per second in the paper's sense (every camera once), wall-clock."""
        return self.camera_frames_per_s / self.num_cameras

    @property
    def summed_frames_per_s(self) -> float:
        """Camera frames per second of the zones' update time summed (one core doing all zones' work)."""
        total = sum(self.zone_tracker_s)
        return self.updates / total if total > 0 else float("nan")


def batches(frames):
    """The camera frames in delivery order, `BATCH_S` of stamps at a time."""
    batch: list = []
    for cf in frames:
        if batch and cf.frame.stamp_s - batch[0].frame.stamp_s > BATCH_S:
            yield batch
            batch = []
        batch.append(cf)
    if batch:
        yield batch


def track_zoned(rec_path: Path, out: Path, *, zones_text: str, overlap_m: float, executor: parallel.Executor,
                workers: int, method: str = "crossview", preset: str = "store", config_path: Path | None = None,
                overrides: dict | None = None, progress: bool = True) -> ZonedResult:
    """Tracks a recording as zones (module docstring) and writes one tracks file; the caller has joined Ray for
    `Executor.RAY` (`crossview.parallel.cluster.session`). `workers`: processes or actors, each holding some
    zones (`assign`); the outputs do not depend on it."""
    from tqdm import tqdm

    from core.types import SKELETONS
    from crossview import recording
    from crossview.plugins import resolve
    from tracker.handover import Merger

    pipeline.check_writable(out, inputs=(rec_path, config_path))
    rec = recording.open_recording(rec_path)
    skeleton = SKELETONS[rec.header.skeleton_name]
    cameras = list(rec.cameras)
    zones = cut(cameras, rec.boxes, zones_text, overlap_m)
    config = pipeline.tracker_config(preset, config_path, overrides)
    resolved = resolve(method)
    header = recording.TracksHeader(
        scenario_name=rec.header.scenario_name, scenario_digest=rec.header.scenario_digest, seed=rec.header.seed,
        method=method, preset=preset, config=pipeline.jsonable(dataclasses.asdict(config)),
        skeleton_name=skeleton.name, software_version=recording.software_version(),
        format_version=recording.TRACKS_FORMAT_VERSION)
    zones_of = {c.name: [z.index for z in zones if i in z.cameras] for i, c in enumerate(cameras)}
    args = [(method, [cameras[i] for i in z.cameras], preset, config_path, skeleton, overrides) for z in zones]
    merger = Merger(zones, skeleton, gate_m=config.alpha_3d_m)
    spent = [0.0] * len(zones)
    tracked = [0] * len(zones)
    updates = 0
    groups = assign([len(z.cameras) for z in zones], workers)
    setup = parallel.Setup(preload=("crossview.zoned", "crossview.recording", "tracker.tracker"))
    with parallel.actors(ZoneGroup, [([args[z] for z in g],) for g in groups], executor=executor, setup=setup,
                         what="zone worker") as group:
        warm = [[] for _ in zones]
        for cf in rec.frames():
            if cf.frame.stamp_s > pipeline.WARM_UP_S:
                break
            for z in zones_of[cf.frame.camera]:
                warm[z].append(cf.frame)
        group.call("warm_up", [([warm[z] for z in g],) for g in groups])
        start = time.perf_counter()
        with recording.TracksWriter(out, header, rec.cameras, inputs=(rec_path, config_path)) as writer:
            bar = tqdm(unit="frame", desc="track", disable=not progress, leave=False)

            def submit(batch: list) -> list:
                per_zone = [[cf.frame for cf in batch if z.index in zones_of[cf.frame.camera]] for z in zones]
                return group.submit("update", [([per_zone[z] for z in g],) for g in groups])

            def merge(batch: list, answers: list) -> None:
                nonlocal updates
                results: list = [None] * len(zones)
                for g, answer in zip(groups, answers, strict=True):
                    for z, result in zip(g, answer, strict=True):
                        results[z] = result
                cursor = [0] * len(zones)
                for z, (frames, s) in enumerate(results):
                    spent[z] += s
                    tracked[z] += len(frames)
                for cf in batch:
                    outputs = {}
                    for z in zones_of[cf.frame.camera]:
                        outputs[z] = results[z][0][cursor[z]]
                        cursor[z] += 1
                    if outputs:
                        writer.write(merger.add(outputs, len(cf.frame.scores)))
                        updates += 1
                bar.update(len(batch))

            # Pipelined: while the zones track one batch, the driver merges the one before and reads the next.
            pending = None
            for batch in batches(rec.frames()):
                answers = group.gather(pending[1]) if pending else None
                handles = submit(batch)
                if pending:
                    merge(pending[0], answers)
                pending = (batch, handles)
            if pending:
                merge(pending[0], group.gather(pending[1]))
            bar.close()
            writer.finish({"tracker_s": sum(spent), "updates": updates, "num_cameras": len(cameras),
                           pipeline.ASSIGNMENTS_KEY: resolved.builtin,
                           "zones": [{"cell": list(z.cell), "region": list(z.region), "cameras": len(z.cameras)}
                                     for z in zones],
                           "handovers": len(merger.handovers)})
        wall_s = time.perf_counter() - start
        worker_peaks = tuple(group.call("peak_memory", [() for _ in groups]))
    return ZonedResult(out, updates, len(groups), wall_s, tuple(spent), tuple(len(z.cameras) for z in zones),
                       len(merger.handovers), len(cameras), tuple(tracked), peak_memory(), worker_peaks)


def write_map(name: str, boxes, cameras, zones, overlap_m: float, path: Path) -> Path:
    """The zones drawn on the store from above (`crossview.pictures.layout.draw_layout`): each zone's cell
    outlined in its colour and labelled with its camera count, its widened region dashed."""
    from crossview.pictures import layout as pictures

    image = pictures.draw_layout(boxes, list(cameras), title=f"{name}: {len(zones)} zones, overlap {overlap_m:g} m",
                                 px_per_m=pictures.layout_scale(watched_floor(boxes)[2]
                                                                - watched_floor(boxes)[0]),
                                 zones=[(z.cell, z.region, f"zone {z.index}: {len(z.cameras)} cameras")
                                        for z in zones])
    return pictures.write_png(image, path)
