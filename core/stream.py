"""What a simulation gives out, one block of truth ticks at a time (`Block`), and the one rule that puts its
contents in log-time order (`LogTimeOrder`): the order of a recording, and of `Simulation.events`.

A block holds the truth ticks of a stretch of time and the camera frames captured during it; those frames
are delivered later, some after the next blocks' ticks. Whoever turns the blocks into a stream (the
recording writer, `Simulation.events`) makes each block's frames (encoded, or as CameraFrames) and hands
them with their block to a `LogTimeOrder`, which gives back everything whose log time has come.
"""

from __future__ import annotations

import heapq
import itertools
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from core.records import Capture, DetectionRows, PoseTruth

# Order of events that share a log time: the truth first, then frames by camera index (then capture time).
_TRUTH_KIND, _FRAME_KIND = 0, 1

STAMP, CAPTURE, DELIVERY = range(3)
"""The columns of a frame's three times (stamp, true capture, delivery; seconds) wherever they travel as one
array (`frame_times`): the simulation worker's blocks, the recording's encoder."""


class Block(NamedTuple):
    """One block of truth ticks and the captures taken during it (`Simulation.blocks`).

    Attributes:
        t: the block's last tick time, seconds: everything of later blocks has a later log time.
        truths: the block's truth ticks (`PoseTruth`, log time `t_s`), in time order.
        requests: the captures taken during the block (`Capture`; a frame's log time is its `delivery_s`),
            by capture time. Their poses are None where the simulation was asked for none.
        rows: their detections (`DetectionRows`), or where the detector's draws are still to be made (the
            simulation worker's blocks), the captures' visibility (`Detector.block_visibility`).
        bounds: (R + 1,) capture i owns rows bounds[i]:bounds[i + 1] (None before the draws).
    """

    t: float
    truths: list[PoseTruth]
    requests: list[Capture]
    rows: DetectionRows | tuple
    bounds: np.ndarray | None


def frame_times(requests: Sequence[Capture]) -> np.ndarray:
    """(R, 3) float64 the captures' three times, in the columns `STAMP`, `CAPTURE`, `DELIVERY`."""
    return np.array([(r.stamp_s, r.capture_s, r.delivery_s) for r in requests], dtype=np.float64).reshape(-1, 3)


class LogTimeOrder:
    """The truth ticks and frames of consecutive blocks, put in log-time order: a truth tick at its `t_s`, a
    frame at its delivery time; ties put the truth first, then frames by camera index, then by capture time.

    A frame waits here until no later block can bring anything before it, so what is held stays bounded by
    the delivery delay (plus one block).
    """

    def __init__(self):
        self._pending: list = []
        self._seq = itertools.count()  # (ties that remain: first come, first out)

    def add(self, block: Block, frames: Sequence) -> list:
        """Takes the next block and what stands for its frames; returns, in log-time order, everything (of
        this and the earlier blocks) whose log time is up to `block.t`.

        Args:
            block: the block after the previous one given.
            frames: one item per capture request of the block, in their order (a CameraFrame, an encoded
                frame): what is given back in the frame's place.
        """
        pending, seq = self._pending, self._seq
        for poses in block.truths:
            heapq.heappush(pending, (poses.t_s, _TRUTH_KIND, -1, poses.t_s, next(seq), poses))
        for request, frame in zip(block.requests, frames, strict=True):
            heapq.heappush(pending, (request.delivery_s, _FRAME_KIND, request.camera, request.capture_s, next(seq),
                                     frame))
        # Everything later has a log time > t (a later capture is after t, and delivered after it).
        due = []
        while pending and pending[0][0] <= block.t:
            due.append(heapq.heappop(pending)[-1])
        return due

    def rest(self) -> list:
        """Everything still held, in log-time order (after the last block)."""
        pending = self._pending
        return [heapq.heappop(pending)[-1] for _ in range(len(pending))]
