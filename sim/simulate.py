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
# The detector's error draws are made for the captures of this many truth ticks at once (0.1 s): the
# per-call cost of the draws is then shared by about 28 frames of store_layout2 instead of about 3.
_DETECT_BLOCK_TICKS = 10


class Simulation:
    """One scenario, ready to generate its recording.

    Args:
        scenario: a loaded `sim.scenario.Scenario`.
        seed: the seed of every random stream; None uses the scenario's seed.

    Attributes:
        cameras: the rig, in camera-index order.
        boxes: the store's boxes (floor, walls, shelves, ...).
        skeleton: the keypoint layout of the poses.
        detector: the `sim.detector.Detector` of the latest `events` pass (its `visibility_counts` give
            the joints in the image, occluded and self-occluded per camera, over every person-view).
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
        self.detector: Detector | None = None

    def events(self, duration_s: float | None = None) -> Iterator[PoseTruth | CameraFrame]:
        """Everything a recording holds, in log-time order.

        PoseTruth at 100 Hz (log time `t_s`) and CameraFrame (log time `truth.delivery_s`). Ties
        break by kind (truth first) then camera index then capture time. The world moves forward one
        truth tick at a time; the captures since the previous tick are projected and ray cast against
        the bodies interpolated to their capture time, and the detector's error draws are made once per
        block of ticks. A frame waits in a small heap until no later event can come before it, so memory
        stays bounded by the delivery delay (plus one block).

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
        # Truth ticks cover [0, duration] and the last capture.
        n_truth = int(np.ceil(duration * TRUTH_RATE_HZ - 1e-9)) + 1
        pending: list = []
        seq = itertools.count()
        next_capture = 0
        previous: PoseTruth | None = None
        requests: list = []
        visibilities: list = []
        for k in range(n_truth):
            t = k / TRUTH_RATE_HZ
            poses = world.advance(t)
            # Captures up to this tick see the poses interpolated between the two ticks (10 ms apart:
            # under a millimetre from the exact pose even for a swinging wrist) and the bodies of this tick.
            batch = []
            while next_capture < len(captures) and captures[next_capture].capture_s <= t:
                capture = captures[next_capture]
                next_capture += 1
                at_capture = interpolate_poses(previous, poses, capture.capture_s)
                batch.append((capture.camera_index, at_capture, capture.capture_s, capture.stamp_s,
                              capture.delivery_s))
            if batch:  # occlusion needs this tick's bodies; the error draws wait for the block
                requests += batch
                visibilities += detector.visibility_many(world, batch)
            heapq.heappush(pending, (t, _TRUTH_KIND, -1, t, next(seq), poses))
            previous = poses
            if (k + 1) % _DETECT_BLOCK_TICKS and k + 1 < n_truth:
                continue
            for request, event in zip(requests, detector.detect_visible(requests, visibilities)):
                heapq.heappush(pending, (request[4], _FRAME_KIND, request[0], request[2], next(seq), event))
            requests, visibilities = [], []
            # Everything later has a log time > t (a later capture is after t, and delivered after it).
            while pending and pending[0][0] <= t:
                yield heapq.heappop(pending)[-1]
        while pending:
            yield heapq.heappop(pending)[-1]


def interpolate_poses(before: PoseTruth | None, after: PoseTruth, t_s: float) -> PoseTruth:
    """Everybody's pose at `t_s` between two truth ticks, linear in time.

    People present at both ticks are interpolated; someone present at only one tick is taken from it
    when `t_s` lies in that tick's half of the interval.

    Args:
        before: the truth at the earlier tick (None: only `after` is known).
        after: the truth at the later tick, `after.t_s >= t_s`.
        t_s: the time wanted.
    """
    if before is None or after.t_s <= before.t_s:
        return PoseTruth(float(t_s), after.person_ids, after.poses)
    a = (t_s - before.t_s) / (after.t_s - before.t_s)
    if np.array_equal(before.person_ids, after.person_ids):
        return PoseTruth(float(t_s), after.person_ids, before.poses + (after.poses - before.poses) * a)
    ids = np.union1d(before.person_ids, after.person_ids)
    in_before = np.isin(ids, before.person_ids)
    in_after = np.isin(ids, after.person_ids)
    keep = (in_before & in_after) | (in_after & (a > 0.5)) | (in_before & (a <= 0.5))
    ids = ids[keep]
    poses = np.empty((ids.size, *after.poses.shape[1:]))
    for i, pid in enumerate(ids):
        b = before.poses[np.searchsorted(before.person_ids, pid)] if pid in before.person_ids else None
        f = after.poses[np.searchsorted(after.person_ids, pid)] if pid in after.person_ids else None
        poses[i] = b + (f - b) * a if b is not None and f is not None else (f if f is not None else b)
    return PoseTruth(float(t_s), ids, poses)
