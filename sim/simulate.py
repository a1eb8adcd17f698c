"""The simulation driver: world, camera rig, clocks and detector merged into one time-ordered stream."""

from __future__ import annotations

import contextlib
import heapq
import itertools
from collections.abc import Iterator
from typing import NamedTuple

import cv2
import numpy as np

from core import jit, processes
from core.types import COCO17
from sim import cameras as cameras_mod
from sim import clock as clock_mod
from sim.poses import interpolate_ticks
from sim.rng import child_rng
from sim.sensing.detector import Detector
from sim.sensing.draws import large_enough
from sim.types import CameraFrame, Capture, DetectionRows, PoseTruth

TRUTH_RATE_HZ = 100.0
# Order of events that share a log time: the truth first, then frames by camera index.
_TRUTH_KIND, _FRAME_KIND = 0, 1
# The captures of this many truth ticks (0.3 s) are projected, ray cast and given their detector errors
# together, so that the per-call costs are shared by many frames (about 84 of store_layout2).
_DETECT_BLOCK_TICKS = 30


class Block(NamedTuple):
    """One block of `_DETECT_BLOCK_TICKS` truth ticks, as `Simulation._blocks` gives it.

    Attributes:
        t: the block's last tick time, seconds: every later event has a later log time.
        truths: the block's truth ticks (`PoseTruth`), in time order.
        requests: the captures taken during the block (`Capture`), by capture time.
        rows: their detections (`DetectionRows`); or, from a block left without the detector's draws, the
            captures' visibility (`Detector.block_visibility`).
        bounds: (R + 1,) capture i owns rows bounds[i]:bounds[i + 1] (None without the draws).
    """

    t: float
    truths: list
    requests: list
    rows: object
    bounds: np.ndarray | None


class Simulation:
    """One scenario, ready to generate its recording.

    Args:
        scenario: a loaded `sim.scenario.Scenario`.
        seed: the seed of every random stream; None uses the scenario's seed.
        worker_process: simulate in a second process (forked; where the machine has more than one core),
            pipelined with whatever consumes `events` here (writing the recording): the events are the same.

    Attributes:
        cameras: the rig, in camera-index order.
        boxes: the store's boxes (floor, walls, shelves, ...).
        skeleton: the keypoint layout of the poses.
        world: the `sim.world.World`, built on first use (advanced by `events` only when no worker process
            simulates: a worker builds its own, so that this process meanwhile loads what it needs).
        detector: the `sim.sensing.detector.Detector` of the latest `events` pass (its `visibility_counts` give
            the joints in the image, occluded and self-occluded per camera, over every person-view).
    """

    def __init__(self, scenario, seed: int | None = None, *, worker_process: bool = True):
        from sim.crowd import validate as validate_crowd
        from sim.store import StoreGeometry

        self.scenario = scenario
        self.seed = scenario.seed if seed is None else int(seed)
        self.cameras = cameras_mod.build_rig(scenario, child_rng(self.seed, "cameras"))
        store = StoreGeometry(scenario.store, name=scenario.where)  # (what World checks first, without MuJoCo)
        validate_crowd(scenario.crowd, store, scenario.where)
        self.boxes = tuple(store.boxes)
        self.skeleton = COCO17
        self._world = None
        self.worker_process = worker_process
        self._used = False
        self.detector: Detector | None = None

    @property
    def world(self):
        if self._world is None:
            from sim.world import World  # MuJoCo is only needed here and below

            self._world = World(self.scenario, child_rng(self.seed, "crowd"))
        return self._world

    def events(self, duration_s: float | None = None, *, with_poses: bool = True, while_starting=None,
               frames_of=None) -> Iterator[PoseTruth | CameraFrame]:
        """Everything a recording holds, in log-time order.

        PoseTruth at 100 Hz (log time `t_s`) and CameraFrame (log time `truth.delivery_s`). Ties
        break by kind (truth first) then camera index then capture time. The world moves forward one
        truth tick at a time; the captures since the previous tick are projected and ray cast against
        the bodies interpolated to their capture time, and the detector's error draws are made once per
        block of ticks. A frame waits in a small heap until no later event can come before it, so memory
        stays bounded by the delivery delay (plus one block).

        Args:
            duration_s: simulated duration; None uses the scenario's.
            with_poses: give each CameraFrame its `poses_at_capture` (False: None, which is all a recording
                writer needs: a recording stores the truth ticks, from which its reader derives them).
            while_starting: a function called once the worker process has started, while it builds its
                world (e.g. to load what the consumer will need); with no worker, at the start.
            frames_of: what stands for a block's frames, in their place in the order: a function of the
                block's capture requests, detection rows and bounds (`Detector.detection_rows`) that gives
                one item per request. None: the CameraFrames (`Detector.frames_from_rows`). A recording
                writer encodes them straight from the rows (`RecordingWriter.encode_frames`).
        """
        duration = self.scenario.duration_s if duration_s is None else float(duration_s)
        if not duration > 0:
            raise ValueError(f"duration_s: {duration} must be > 0")
        if self._used:  # a second pass starts again from the same initial state
            self._world = None
        self._used = True
        self.detector = Detector(self.scenario.detector, self.cameras, child_rng(self.seed, "detector"),
                                 self.skeleton)
        frames_of = frames_of or self.detector.frames_from_rows
        if self.worker_process and processes.can_fork_worker():
            blocks = self._blocks_from_worker(duration, with_poses, while_starting)
        else:
            if while_starting is not None:
                while_starting()
            blocks = self._blocks(duration)
            if not with_poses:
                blocks = (Block(b.t, b.truths, [r._replace(poses=None) for r in b.requests], b.rows, b.bounds)
                          for b in blocks)
        pending: list = []
        seq = itertools.count()
        # The blocks are closed (the worker stopped) as soon as this stream ends, however it ends: a failure
        # here must not leave the worker running while something still holds the traceback.
        with contextlib.closing(blocks):
            for t, truths, requests, rows, bounds in blocks:  # (a Block)
                for poses in truths:
                    heapq.heappush(pending, (poses.t_s, _TRUTH_KIND, -1, poses.t_s, next(seq), poses))
                # A block can hold no capture at all (a short last block, a slow or dropping clock).
                for request, event in zip(requests, frames_of(requests, rows, bounds) if requests else ()):
                    heapq.heappush(pending, (request.delivery_s, _FRAME_KIND, request.camera, request.capture_s,
                                             next(seq), event))
                # Everything later has a log time > t (a later capture is after t, and delivered after it).
                while pending and pending[0][0] <= t:
                    yield heapq.heappop(pending)[-1]
        while pending:
            yield heapq.heappop(pending)[-1]

    def _blocks(self, duration: float, draws: bool = True) -> Iterator[tuple]:
        """The simulation proper, one block of `_DETECT_BLOCK_TICKS` truth ticks at a time: (the block's
        last tick time, its truths, its capture requests, their `Detector.detection_rows` and bounds).

        With `draws` False the last two are the requests' visibility (`Detector.block_visibility`) and
        None: the error draws are left to the consumer (`_blocks_from_worker`), with the same detector state.
        """
        world, detector = self.world, self.detector
        cams, _, capture_times, stamp_s, delivery_s = clock_mod.schedule(
            [c.name for c in self.cameras], self.scenario.clock, duration, child_rng(self.seed, "clock"))
        cams, capture_s, stamp_s, delivery_s = (c.tolist() for c in (cams, capture_times, stamp_s, delivery_s))
        # Truth ticks cover [0, duration] and the last capture.
        n_truth = int(np.ceil(duration * TRUTH_RATE_HZ - 1e-9)) + 1
        # Captures up to a tick see the poses interpolated between it and the tick before (10 ms apart: under
        # a millimetre from the exact pose even for a swinging wrist) and the bodies of that tick.
        taken_by = np.searchsorted(capture_times, np.arange(n_truth) / TRUTH_RATE_HZ, side="right").tolist()
        previous: PoseTruth | None = None  # the previous block's last tick
        first = 0  # the block's first capture
        truths: list = []
        scenes: list = []  # what rays need of the bodies at each tick with captures (None: no ray casting)
        scene_of: list = []  # per capture of the block, its tick in `scenes`
        tick_of: list = []  # per capture of the block, its tick in `truths`
        for k in range(n_truth):
            t = k / TRUTH_RATE_HZ
            truths.append(world.advance(t))
            n = taken_by[k] - first - len(tick_of)
            if n:  # occlusion needs this tick's bodies; the poses, rays and error draws wait for the block
                scene_of += [len(scenes)] * n
                tick_of += [len(truths) - 1] * n
                scenes.append(detector.scene_now(world))
            if (k + 1) % _DETECT_BLOCK_TICKS and k + 1 < n_truth:
                continue
            end = first + len(tick_of)
            at_capture = interpolate_ticks(previous, truths, tick_of, capture_times[first:end])
            requests = list(map(Capture, cams[first:end], at_capture, capture_s[first:end], stamp_s[first:end],
                                delivery_s[first:end]))
            rows, bounds = DetectionRows.empty(self.skeleton.num_joints), np.zeros(1, dtype=np.int64)
            if requests:
                visible = detector.block_visibility(requests, None if scenes[0] is None else scenes, scene_of)
                rows, bounds = detector.detection_rows_of(requests, *visible) if draws else (visible, None)
            yield Block(t, truths, requests, rows, bounds)
            previous, first = truths[-1], end
            truths, scenes, scene_of, tick_of = [], [], [], []

    def _blocks_from_worker(self, duration: float, with_poses: bool, while_starting=None) -> Iterator[tuple]:
        """`_blocks` computed in a forked process and received here, block by block. The captures' poses
        do not travel: they are derived here again from the truth ticks (`sim.poses`, the same arithmetic),
        and only when `with_poses` (else None).

        The worker ignores Ctrl-C (the whole process group gets it; this side decides) and is stopped and
        reaped whenever this generator ends: done, failed, interrupted or dropped unfinished. Its
        failures are raised here.
        """
        jit.prepare()  # (once here instead of once in each process)
        # OpenCV's worker threads do not survive a fork, and one caught holding its pool's lock at the fork
        # would hang the worker's first parallel OpenCV call (the store's distance transform) on that lock:
        # OpenCV runs on the calling thread alone from here on (its calls in this project are small).
        cv2.setNumThreads(0)
        worker = processes.Worker(self._work, (duration,), "crossview-simulation", _WORKER, _PIPE_BYTES)
        previous = None  # the last truth tick of the previous block
        try:
            worker.start()
            _load_draw_kernels(self.detector)
            if while_starting is not None:
                while_starting()
            while True:
                kind, payload = worker.receive()  # (its error is raised here)
                if kind == "block":
                    t, truths, requests, visible, people = _unpack_block(payload, previous, with_poses)
                    previous = truths[-1] if truths else previous
                    # The detector's draws are made here: the worker only does geometry (the two processes
                    # then take about the same time per block). The same draws, in the same order.
                    rows, bounds = DetectionRows.empty(self.skeleton.num_joints), np.zeros(1, dtype=np.int64)
                    if requests:
                        rows, bounds = self.detector.detection_rows_of(requests, *visible, person_ids=people)
                    yield Block(t, truths, requests, rows, bounds)
                else:  # "end": the counts of the detector that ran there
                    self.detector.visibility_counts[:] = payload
                    return
        finally:
            worker.stop()

    def _work(self, duration: float, sender) -> None:
        """The worker process (`processes.Worker`): simulates and sends every block, then the detector's counts."""
        for block in self._blocks(duration, draws=False):
            sender.send(("block", _pack_block(block, self.detector.min_size_px)))
        sender.send(("end", self.detector.visibility_counts))


# A block is about 640 kB on the wire (store_layout2; the visibility of its 84 captures is two thirds): the
# default 64 kB pipe makes the worker wait for ten reads of the consumer per block, so any hiccup on either
# side stalls both. A pipe of the system's usual limit, 1 MiB, holds a block and a half: the worker can
# finish the next block while the consumer is still reading one.
_PIPE_BYTES = 1 << 20
_WORKER = "simulation worker"  # (how errors and warnings name the worker process)


def _load_draw_kernels(detector: Detector) -> None:
    """Loads the compiled kernels of the detector's draws (while the worker builds its world) by drawing one
    made-up detection with a throwaway copy of `detector`: its own state is left as it is."""
    spare = Detector(detector.config, detector.cameras, np.random.default_rng(0), detector.skeleton)
    J = detector.skeleton.num_joints
    seen = np.ones((1, J), dtype=bool)
    spare.detection_rows_of([Capture(0, None, 0.0, 0.0, 0.0)], np.ones((1, J, 2)), seen, ~seen, ~seen,
                            person_ids=[np.zeros(1, np.int64)])


def _pack_block(block: Block, min_size_px: np.ndarray) -> tuple:
    """A block of `_blocks(draws=False)` as a few flat arrays (one pickle of a handful of arrays instead of
    dozens of small ones): the truths' poses concatenated, with their times and people counts; the
    captures' cameras, times, people and visibility (their poses are left out: `_unpack_block` derives
    them from the truths). Of the person-views, only those with a joint in the image and no smaller than
    the camera's `min_size_px` (`Detector.min_size_px`) travel: the others make no detection and take no draw
    (`sim.sensing.draws.draw_detections`), so the consumer draws the same rows."""
    t, truths, requests, visible, _ = block
    seen = [r.poses.person_ids for r in requests]
    viewed = np.concatenate(seen).astype(np.int64, copy=False) if seen else np.zeros(0, dtype=np.int64)
    people = (viewed, np.array([len(p) for p in seen], dtype=np.int64))
    if requests:  # (else `visible` stands for no rows at all)
        keep = visible[1].any(axis=1)
        if min_size_px.any():
            cams = np.array([r.camera for r in requests], dtype=np.int64)
            keep &= large_enough(visible[0], np.repeat(min_size_px[cams], people[1]))
        people = (viewed[keep], np.bincount(np.repeat(np.arange(len(seen)), people[1])[keep], minlength=len(seen)))
        visible = tuple(np.ascontiguousarray(v[keep]) for v in visible)
    times = np.array([p.t_s for p in truths])
    counts = np.array([len(p.person_ids) for p in truths], dtype=np.int64)
    ids = np.concatenate([p.person_ids for p in truths]).astype(np.int64, copy=False)
    poses = [p.poses for p in truths]
    joints = np.concatenate([p.reshape(-1, 3) for p in poses]).astype(np.float64, copy=False)
    shapes = [p.shape[1:] for p in poses]
    meta = (np.array([r.camera for r in requests], dtype=np.int64),
            np.array([(r.capture_s, r.stamp_s, r.delivery_s) for r in requests]).reshape(-1, 3))
    return t, times, counts, ids, joints, shapes, meta, visible, people


def _unpack_block(packed: tuple, previous: PoseTruth | None, with_poses: bool) -> tuple:
    """`_pack_block` undone; each capture's poses interpolated between the tick it was taken at (the
    first at or after its capture time) and the tick before (`previous`: the previous block's last)."""
    t, times, counts, ids, joints, shapes, (cams, capture_times), visible, (seen, sizes) = packed
    ends = np.cumsum(sizes).tolist()
    seen = [seen[end - size:end] for end, size in zip(ends, sizes.tolist())]
    people = np.concatenate([[0], np.cumsum(counts)]).tolist()
    rows_of = [0]
    for n, shape in zip(counts.tolist(), shapes):
        rows_of.append(rows_of[-1] + n * (shape[0] if shape else 0))
    truths = [PoseTruth(t_s, ids[people[i]:people[i + 1]], joints[rows_of[i]:rows_of[i + 1]].reshape(-1, *shapes[i]))
              for i, t_s in enumerate(times.tolist())]
    capture_list = capture_times.tolist()
    poses: list = [None] * len(capture_list)
    if with_poses and capture_list:
        tick_of = np.searchsorted(times, capture_times[:, 0], side="left")
        poses = interpolate_ticks(previous, truths, tick_of, capture_times[:, 0])
    requests = [Capture(c, p, *times_i) for c, p, times_i in zip(cams.tolist(), poses, capture_list)]
    return t, truths, requests, visible, seen
