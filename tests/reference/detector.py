"""One capture, or the captures of one tick, through the detector's public steps: the shortest way for a test
to get a frame or a capture's visibility (the simulation runs the same steps block by block), and the
compiled ray caster called on arbitrary points."""

from __future__ import annotations

import numpy as np

from core.records import CameraFrame, Capture, PoseTruth
from sim.sensing.detector import Detector
from sim.sensing.rays import KeypointRays, RayHits, Scenes, cast_keypoint_rays


def visibility_many(detector: Detector, world, requests: list[Capture]) -> list[tuple]:
    """Projection and occlusion of several captures whose bodies are all in `world`'s data (one truth tick;
    world None: no ray casting), through `Detector.block_visibility` as one block of one tick.

    Returns:
        Per request: px (P, J, 2) distorted true pixels, in_img, occluded, self_occluded (P, J), and found_px
        (P, J, 2) the detector's own joints' pixels (NaN for people it cannot detect).
    """
    if not requests:
        return []
    J = detector.skeleton.num_joints
    for r in requests:
        if np.shape(r.poses.poses)[1:] != (J, 3):
            raise ValueError(f"visibility: poses of shape {np.shape(r.poses.poses)}, expected (P, {J}, 3)")
    scenes = [detector.scene_now(world, copy=False)] if world is not None else None
    visible = detector.block_visibility(requests, scenes, [0] * len(requests))
    bounds = np.cumsum([0] + [len(r.poses.person_ids) for r in requests]).tolist()
    return [tuple(v[a:b] for v in visible) for a, b in zip(bounds[:-1], bounds[1:])]


def visibility(detector: Detector, camera_index: int, world, poses: PoseTruth) -> tuple:
    """`visibility_many` of one capture of `poses` (P, J, 3) by camera `camera_index` at the poses' time."""
    return visibility_many(detector, world, [Capture(camera_index, poses, poses.t_s, poses.t_s, poses.t_s)])[0]


def detect_visible(detector: Detector, requests: list[Capture], visibilities: list[tuple]) -> list[CameraFrame]:
    """The frames of captures whose visibility is already known (`visibility_many` of the same poses, or a
    dataset's true 2D joints: px, in_img, occluded, self_occluded and optionally found_px, without which the
    detector's joints are the true ones), with the detector's errors drawn for all of them at once."""
    if not requests:
        return []
    rows, bounds = detector.detection_rows_of(requests, *(np.concatenate([v[k] for v in visibilities])
                                                           for k in range(len(visibilities[0]))))
    return detector.frames_from_rows(requests, rows, bounds)


def detect_many(detector: Detector, world, requests: list[Capture]) -> list[CameraFrame]:
    """The frames of captures whose bodies are all in `world`'s data (one truth tick; None: no occlusion)."""
    return detect_visible(detector, requests, visibility_many(detector, world, requests))


def detect(detector: Detector, camera_index: int, world, poses: PoseTruth, capture_s: float, stamp_s: float,
           delivery_s: float) -> CameraFrame:
    """The frame camera `camera_index` delivers for one capture, with the truth behind each row."""
    return detect_many(detector, world, [Capture(camera_index, poses, capture_s, stamp_s, delivery_s)])[0]


def cast(detector: Detector, world, origins: np.ndarray, points: np.ndarray, mask: np.ndarray, person: np.ndarray):
    """The detector's compiled ray caster on `world`'s bodies now: occluded and self-occluded flags (R, N) of
    keypoints `points` (R, N, 3) seen from `origins` (R, 3), where `mask` (R, N); `person` (R, N // J) is the
    person id of each row of J keypoints. Also the nearest geom hit before each keypoint (R, N) (-1: none)
    and its distance."""
    model = detector._scene(world)
    xpos, xmat, size, rbound, owner = detector.scene_now(world, copy=False)[:5]
    shape = mask.shape
    hits = RayHits(np.empty(shape, dtype=bool), np.empty(shape, dtype=bool), np.empty(shape, dtype=np.int32),
                   np.empty(shape))
    rays = KeypointRays(np.ascontiguousarray(origins, dtype=np.float64),
                        np.ascontiguousarray(points, dtype=np.float64), np.ascontiguousarray(mask),
                        np.ascontiguousarray(person, dtype=np.int64), np.zeros(shape[0], dtype=np.int64),
                        np.zeros(shape[0], dtype=np.int64))
    scenes = Scenes(xpos[None], xmat[None], size[None], rbound[None], owner[None], np.zeros(1, dtype=np.int64))
    bounds = np.empty((1, len(model.geom_type) + len(model.groups) - 1, 6))
    cast_keypoint_rays(rays, model, scenes, float(detector.config.self_hit_margin_m), hits,
                       np.zeros((1, 3), dtype=np.int64), bounds)
    return hits.occluded, hits.self_occluded, hits.geomid, hits.dist
