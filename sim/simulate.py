"""The simulation driver: world, camera rig, clocks and detector, giving out blocks of truth ticks and
detected captures (`core.stream.Block`) in time order; `events` puts their contents in log-time order."""

from __future__ import annotations

from collections.abc import Iterator

import cv2
import numpy as np

from core import jit, processes
from core.poses import interpolate_ticks
from core.records import CameraFrame, Capture, DetectionRows, PoseTruth
from core.stream import CAPTURE, DELIVERY, STAMP, Block, LogTimeOrder, frame_times
from core.truth import TRUTH_RATE_HZ, tick_of
from core.types import COCO17
from sim import cameras as cameras_mod
from sim import clock as clock_mod
from sim.rng import child_rng
from sim.sensing.detector import Detector
from sim.sensing.draws import large_enough

# The captures of this many truth ticks (0.3 s) are projected, ray cast and given their detector errors
# together, so that the per-call costs are shared by many frames (about 84 of store_layout2).
_DETECT_BLOCK_TICKS = 30


class Simulation:
    """One scenario, ready to generate its recording.

    Args:
        scenario: a loaded `sim.scenario.Scenario`.
        seed: the seed of every random stream; None uses the scenario's.
        worker_process: simulate in a second process (forked; where the machine has more than one core),
            pipelined with whatever consumes the blocks here (writing the recording): the blocks are the same.

    Attributes:
        cameras: the rig, in camera-index order.
        boxes: the store's boxes (floor, walls, shelves, ...).
        skeleton: the keypoint layout of the poses.
        world: the `sim.world.World`, built on first use (advanced by a pass only when no worker process
            simulates: a worker builds its own, so that this process meanwhile loads what it needs).
        detector: the `sim.sensing.detector.Detector` of the latest pass (`blocks`, `events`; its
            `visibility_counts` give the joints in the image, occluded and self-occluded per camera, over every
            person-view).
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

    def blocks(self, duration_s: float | None = None, *, with_poses: bool = True) -> Blocks:
        """One pass of the simulation, a block of `_DETECT_BLOCK_TICKS` truth ticks (0.3 s) at a time, in
        time order: each block's truth ticks (100 Hz) and the captures taken during them, with their
        detections (`Block`). A block's frames are delivered after its time, some after later blocks' ticks:
        `core.stream.LogTimeOrder` puts the contents of the blocks in log-time order.

        The world moves forward one truth tick at a time; the captures since the previous tick are projected
        and ray cast against the bodies interpolated to their capture time, and the detector's error draws
        are made once per block. Use the pass as a context manager to start the simulation before the first
        block is wanted (a worker process then builds its world while the consumer gets ready, e.g. opens its
        output) and to stop it however the consumer ends.

        Args:
            duration_s: simulated duration; None uses the scenario's.
            with_poses: give each capture request its poses (False: None, which is all a recording writer
                needs: a recording stores the truth ticks, from which its reader derives them).
        """
        duration = self.scenario.duration_s if duration_s is None else float(duration_s)
        if not duration > 0:
            raise ValueError(f"duration_s: {duration} must be > 0")
        return Blocks(self, duration, with_poses)

    def events(self, duration_s: float | None = None, *, with_poses: bool = True) -> Iterator[PoseTruth | CameraFrame]:
        """Everything a recording holds, in log-time order (`core.stream.LogTimeOrder`): PoseTruth at 100 Hz
        (log time `t_s`) and CameraFrame (log time `truth.delivery_s`), from the blocks of one pass (`blocks`).

        Args:
            duration_s: simulated duration; None uses the scenario's.
            with_poses: give each CameraFrame its `poses_at_capture` (False: None).
        """
        order = LogTimeOrder()
        # (the simulation worker is stopped as soon as this stream ends, however it ends: a failure here must
        # not leave it running while something still holds the traceback)
        with self.blocks(duration_s, with_poses=with_poses) as blocks:
            for block in blocks:
                # A block can hold no capture at all (a short last block, a slow or dropping clock).
                frames = (self.detector.frames_from_rows(block.requests, block.rows, block.bounds)
                          if block.requests else ())
                yield from order.add(block, frames)
        yield from order.rest()

    def _start(self, duration: float) -> processes.Worker | None:
        """A pass's start: its detector, and where a worker process will simulate, that worker, made (not yet
        started)."""
        if self._used:  # a second pass starts again from the same initial state
            self._world = None
        self._used = True
        self.detector = Detector(self.scenario.detector, self.cameras, child_rng(self.seed, "detector"),
                                 self.skeleton)
        if not (self.worker_process and processes.can_fork_worker()):
            return None
        jit.prepare()  # (once here instead of once in each process)
        # OpenCV's worker threads do not survive a fork, and one caught holding its pool's lock at the fork
        # would hang the worker's first parallel OpenCV call (the store's distance transform) on that lock:
        # OpenCV runs on the calling thread alone from here on (its calls in this project are small).
        cv2.setNumThreads(0)
        return processes.Worker(self._work, (duration,), "crossview-simulation", _WORKER, _PIPE_BYTES)

    def _blocks_here(self, duration: float, with_poses: bool) -> Iterator[Block]:
        """`_blocks` in this process, the captures' poses left out unless `with_poses`."""
        for block in self._blocks(duration):
            yield block if with_poses else block._replace(requests=[r._replace(poses=None) for r in block.requests])

    def _blocks(self, duration: float, draws: bool = True) -> Iterator[Block]:
        """The simulation proper, one `Block` of `_DETECT_BLOCK_TICKS` truth ticks at a time.

        With `draws` False a block's rows are the requests' visibility (`Detector.block_visibility`) and its
        bounds None: the error draws are left to the consumer (`_blocks_from_worker`), with the same detector
        state.
        """
        world, detector = self.world, self.detector
        cams, _, capture_times, stamp_s, delivery_s = clock_mod.schedule(
            [c.name for c in self.cameras], self.scenario.clock, duration, child_rng(self.seed, "clock"))
        cams, capture_s, stamp_s, delivery_s = (c.tolist() for c in (cams, capture_times, stamp_s, delivery_s))
        # Truth ticks cover [0, duration] and the last capture.
        n_truth = int(np.ceil(duration * TRUTH_RATE_HZ - 1e-9)) + 1
        # Captures up to a tick see the poses interpolated between it and the tick before (10 ms apart: under
        # a millimetre from the exact pose even for a swinging wrist) and the bodies of that tick.
        taken_by = np.searchsorted(tick_of(capture_times), np.arange(n_truth), side="right").tolist()
        previous: PoseTruth | None = None  # the previous block's last tick
        first = 0  # the block's first capture
        truths: list = []
        scenes: list = []  # what rays need of the bodies at each tick with captures (None: no ray casting)
        scene_of: list = []  # per capture of the block, its tick in `scenes`
        truth_of: list = []  # per capture of the block, its tick in `truths`
        for k in range(n_truth):
            t = k / TRUTH_RATE_HZ
            truths.append(world.advance(t))
            n = taken_by[k] - first - len(truth_of)
            if n:  # occlusion needs this tick's bodies; the poses, rays and error draws wait for the block
                scene_of += [len(scenes)] * n
                truth_of += [len(truths) - 1] * n
                scenes.append(detector.scene_now(world))
            if (k + 1) % _DETECT_BLOCK_TICKS and k + 1 < n_truth:
                continue
            end = first + len(truth_of)
            at_capture = interpolate_ticks(previous, truths, truth_of, capture_times[first:end])
            requests = list(map(Capture, cams[first:end], at_capture, capture_s[first:end], stamp_s[first:end],
                                delivery_s[first:end]))
            rows, bounds = DetectionRows.empty(self.skeleton.num_joints), np.zeros(1, dtype=np.int64)
            if requests:
                visible = detector.block_visibility(requests, None if scenes[0] is None else scenes, scene_of)
                rows, bounds = detector.detection_rows_of(requests, *visible) if draws else (visible, None)
            yield Block(t, truths, requests, rows, bounds)
            previous, first = truths[-1], end
            truths, scenes, scene_of, truth_of = [], [], [], []

    def _blocks_from_worker(self, worker: processes.Worker, with_poses: bool) -> Iterator[Block]:
        """`_blocks` computed in the started `worker` process and received here, block by block. The captures'
        poses do not travel: they are derived here again from the truth ticks (`core.poses`, the same
        arithmetic), and only when `with_poses` (else None). The worker's failures are raised here.
        """
        previous = None  # the last truth tick of the previous block
        while True:
            kind, payload = worker.receive()  # (its error is raised here)
            if kind == "block":
                t, truths, requests, visible, people = _unpack_block(payload, previous, with_poses)
                previous = truths[-1] if truths else previous
                # The detector's draws are made here: the worker only does geometry (the two processes then
                # take about the same time per block). The same draws, in the same order.
                rows, bounds = DetectionRows.empty(self.skeleton.num_joints), np.zeros(1, dtype=np.int64)
                if requests:
                    rows, bounds = self.detector.detection_rows_of(requests, *visible, person_ids=people)
                yield Block(t, truths, requests, rows, bounds)
            else:  # "end": the counts of the detector that ran there
                self.detector.visibility_counts[:] = payload
                return

    def _work(self, duration: float, sender) -> None:
        """The worker process (`processes.Worker`): simulates and sends every block, then the detector's counts."""
        for block in self._blocks(duration, draws=False):
            sender.send(("block", _pack_block(block, self.detector.min_size_px)))
        sender.send(("end", self.detector.visibility_counts))


class Blocks:
    """One pass of a `Simulation` (`Simulation.blocks`): its `Block`s in time order, iterated once.

    As a context manager the pass starts on entering, before the first block is wanted: where a worker
    process simulates, it is forked then and builds its world while the consumer gets ready, and this
    process loads the kernels of the detector's draws meanwhile. Leaving stops the worker, however the
    block is left. Iterated without one, the pass starts at the first block and the worker is stopped at
    the last, or when the iterator is closed.

    The worker ignores Ctrl-C (the whole process group gets it; this side decides); its failures are raised
    here, with its traceback as a note.
    """

    def __init__(self, sim: Simulation, duration_s: float, with_poses: bool):
        self._sim = sim
        self.duration_s = duration_s
        self.with_poses = with_poses
        self._worker: processes.Worker | None = None
        self._started = self._iterated = False

    def start(self) -> None:
        """Starts the pass (once; iterating starts it too)."""
        if self._started:
            return
        self._started = True
        self._worker = self._sim._start(self.duration_s)
        if self._worker is None:
            return
        try:  # (made first, started then: a signal right after the fork still finds the worker to stop)
            self._worker.start()
            _load_draw_kernels(self._sim.detector)
        except BaseException:
            self.close()
            raise

    def __iter__(self) -> Iterator[Block]:
        if self._iterated:
            raise RuntimeError("a pass of Simulation.blocks is iterated once: call blocks() again for another")
        self.start()
        self._iterated = True
        return self._received()

    def _received(self) -> Iterator[Block]:
        try:
            if self._worker is None:
                yield from self._sim._blocks_here(self.duration_s, self.with_poses)
            else:
                yield from self._sim._blocks_from_worker(self._worker, self.with_poses)
        finally:
            self.close()

    def close(self) -> None:
        """Stops and reaps the worker process, if one was started; closing again does nothing."""
        if self._worker is not None:
            self._worker.stop()

    def __enter__(self) -> Blocks:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()


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
    meta = (np.array([r.camera for r in requests], dtype=np.int64), frame_times(requests))
    return t, times, counts, ids, joints, shapes, meta, visible, people


def _unpack_block(packed: tuple, previous: PoseTruth | None, with_poses: bool) -> tuple:
    """`_pack_block` undone; each capture's poses interpolated between the tick it was taken at (the
    first at or after its capture time) and the tick before (`previous`: the previous block's last)."""
    t, times, counts, ids, joints, shapes, (cams, frame_times_s), visible, (seen, sizes) = packed
    ends = np.cumsum(sizes).tolist()
    seen = [seen[end - size:end] for end, size in zip(ends, sizes.tolist())]
    people = np.concatenate([[0], np.cumsum(counts)]).tolist()
    rows_of = [0]
    for n, shape in zip(counts.tolist(), shapes):
        rows_of.append(rows_of[-1] + n * (shape[0] if shape else 0))
    truths = [PoseTruth(t_s, ids[people[i]:people[i + 1]], joints[rows_of[i]:rows_of[i + 1]].reshape(-1, *shapes[i]))
              for i, t_s in enumerate(times.tolist())]
    capture_s = frame_times_s[:, CAPTURE]
    poses: list = [None] * len(capture_s)
    if with_poses and len(capture_s):
        truth_of = np.searchsorted(times, capture_s, side="left")
        poses = interpolate_ticks(previous, truths, truth_of, capture_s)
    requests = list(map(Capture, cams.tolist(), poses, capture_s.tolist(), frame_times_s[:, STAMP].tolist(),
                        frame_times_s[:, DELIVERY].tolist()))
    return t, truths, requests, visible, seen
