"""One capture, or the captures of one tick, through the detector's public steps: the shortest way for a test
to get a frame (the simulation runs the same steps block by block)."""

from __future__ import annotations

from core.records import CameraFrame, Capture, PoseTruth
from sim.sensing.detector import Detector


def detect_many(detector: Detector, world, requests: list[Capture]) -> list[CameraFrame]:
    """The frames of captures whose bodies are all in `world`'s data (one truth tick; None: no occlusion)."""
    return detector.detect_visible(requests, detector.visibility_many(world, requests))


def detect(detector: Detector, camera_index: int, world, poses: PoseTruth, capture_s: float, stamp_s: float,
           delivery_s: float) -> CameraFrame:
    """The frame camera `camera_index` delivers for one capture, with the truth behind each row."""
    return detect_many(detector, world, [Capture(camera_index, poses, capture_s, stamp_s, delivery_s)])[0]
