"""The simulation driver: world, camera rig, clocks and detector merged into one time-ordered stream."""

from __future__ import annotations

import heapq
import itertools
import logging
from collections.abc import Iterator

import numpy as np

from sim import cameras as cameras_mod
from sim import clock as clock_mod
from sim.detector import Detector
from sim.rng import child_rng
from sim.types import CameraFrame, PoseTruth

log = logging.getLogger(__name__)

TRUTH_RATE_HZ = 100.0
# Order of events that share a log time: the truth first, then frames by camera index.
_TRUTH_KIND, _FRAME_KIND = 0, 1


class Simulation:
    """One scenario, ready to generate its recording.

    Args:
        scenario: a loaded `sim.scenario.Scenario`.
        seed: the seed of every random stream; None uses the scenario's seed.

    Attributes:
        cameras: the rig, in camera-index order.
        boxes: the store's boxes (floor, walls, shelves, ...).
        skeleton: the keypoint layout of the poses.
    """

    def __init__(self, scenario, seed: int | None = None):
        from sim.world import World  # MuJoCo is only needed here and below

        self.scenario = scenario
        self.seed = scenario.seed if seed is None else int(seed)
        self.cameras = cameras_mod.build_rig(scenario, child_rng(self.seed, "cameras"))
        self._world_factory = lambda: World(scenario, child_rng(self.seed, "crowd"))
        self.world = self._world_factory()
        self.boxes = tuple(self.world.boxes)
        self.skeleton = self.world.skeleton
        self._used = False

    def events(self, duration_s: float | None = None) -> Iterator[PoseTruth | CameraFrame]:
        """Everything a recording holds, in log-time order.

        PoseTruth at 100 Hz (log time `t_s`) and CameraFrame (log time `truth.delivery_s`). Ties
        break by kind (truth first) then camera index then capture time. Capture and truth times are
        processed in true-time order (the world only moves forward); a frame waits in a small heap
        until no later-processed event can come before it, so memory stays bounded by the delivery
        delay.

        Args:
            duration_s: simulated duration; None uses the scenario's.
        """
        duration = self.scenario.duration_s if duration_s is None else float(duration_s)
        if not duration > 0:
            raise ValueError(f"duration_s: {duration} must be > 0")
        if self._used:  # a second pass starts again from the same initial state
            self.world = self._world_factory()
        self._used = True
        world = self.world
        detector = Detector(self.scenario.detector, self.cameras, child_rng(self.seed, "detector"), self.skeleton)
        self.detector = detector
        captures = clock_mod.schedule([c.name for c in self.cameras], self.scenario.clock, duration,
                                      child_rng(self.seed, "clock"))
        n_truth = int(np.floor(duration * TRUTH_RATE_HZ + 1e-9)) + 1
        truth_times = (k / TRUTH_RATE_HZ for k in range(n_truth))
        # (true time, kind, camera index, payload) in true-time order.
        work = heapq.merge(
            ((t, _TRUTH_KIND, -1, None) for t in truth_times),
            ((c.capture_s, _FRAME_KIND, c.camera_index, c) for c in captures),
        )
        pending: list = []
        seq = itertools.count()
        for t, kind, cam, capture in work:
            while pending and pending[0][0] < t:
                yield heapq.heappop(pending)[-1]
            poses = world.advance(t)
            if kind == _TRUTH_KIND:
                heapq.heappush(pending, (t, kind, cam, t, next(seq), poses))
            else:
                event = detector.detect(cam, world, poses, capture.capture_s, capture.stamp_s, capture.delivery_s)
                heapq.heappush(pending, (capture.delivery_s, kind, cam, capture.capture_s, next(seq), event))
        while pending:
            yield heapq.heappop(pending)[-1]
