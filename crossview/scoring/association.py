"""Per-camera association accuracy (the paper's Figure 4), and the projection of 3D poses into a camera as boxes.

Association accuracy: over the run, each person's *carrier* is the target to which most of that
person's true detections (all cameras) were assigned. A true detection is correctly associated when the
tracker assigned it to its person's carrier; a detection left unassigned, or given to another target, is
wrong. Accuracy per camera = correct / true detections of that camera; the overall figure pools all
cameras. False-positive detections (person id -1) are not in the denominator; the share of them that the
tracker did assign to a target is reported beside. Camera frames with no tracker output of the same
camera and stamp (the tracker never processed them) are left out and counted.

A 3D pose seen by a camera (`pose_boxes`) is the bounding box of its joints projected with the camera's
distortion; it counts when at least `MIN_VISIBLE_FRACTION` of it lies inside the image. The per-camera 2D
tracking scores that use it (the paper's Table 5) are in `crossview.scoring.per_camera`.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from core.boxes import keypoint_boxes
from core.types import Camera
from sim.types import CameraFrame
from tracker.types import TargetState, TrackerOutput

MIN_VISIBLE_FRACTION = 0.5
"""Fraction of a projected box that must lie inside the image for the box to count."""
SCORED_STATES = (TargetState.CONFIRMED, TargetState.LOST)
"""Target states that are scored (a tracker reports confirmed targets; tentative and removed ones never count)."""
_MIN_DEPTH_M = 0.1
_PROJECTION_MARGIN = 0.5  # fraction of the image size outside which undistorted points are not distorted


def stamp_key(camera: str, stamp_s: float) -> tuple[str, int]:
    """The key that pairs a camera frame with the tracker output made from it: camera and stamp in ns."""
    return camera, int(round(stamp_s * 1e9))


@dataclass
class AssociationScores:
    """Association accuracy (fractions in [0, 1], None with no true detection).

    Attributes:
        overall: correct / true detections over all cameras.
        per_camera: camera -> accuracy.
        true_detections: camera -> number of true detections scored.
        false_positive_assigned: share of false-positive detections assigned to a target.
        frames_without_output: camera frames for which no tracker output was found.
        frames_scored: camera frames matched with a tracker output.
    """

    overall: float | None = None
    per_camera: dict[str, float | None] = field(default_factory=dict)
    true_detections: dict[str, int] = field(default_factory=dict)
    false_positive_assigned: float | None = None
    frames_without_output: int = 0
    frames_scored: int = 0


def association_accuracy(camera_frames: Iterable[CameraFrame], outputs: Sequence[TrackerOutput]) -> AssociationScores:
    """The paper's association accuracy per camera (Figure 4), see the module docstring.

    Args:
        camera_frames: delivered frames with per-detection truth.
        outputs: tracker outputs; `detection_target_ids` rows match the frame's detections.
    """
    assigned = {stamp_key(o.camera, o.stamp_s): np.asarray(o.detection_target_ids, dtype=np.int64) for o in outputs}
    pairs: list[tuple[str, np.ndarray, np.ndarray]] = []
    missing = 0
    for cf in camera_frames:
        key = stamp_key(cf.frame.camera, cf.frame.stamp_s)
        persons = np.asarray(cf.truth.person_ids, dtype=np.int64)
        if key not in assigned:
            missing += 1
            continue
        targets = assigned[key]
        if targets.shape != persons.shape:
            raise ValueError(
                f"association: camera {key[0]} at {cf.frame.stamp_s} s has {len(persons)} detections but the tracker "
                f"output assigns {len(targets)}; the tracks do not belong to this recording"
            )
        pairs.append((key[0], persons, targets))
    # Each person's carrier: the target most of its detections went to (ties: the smaller id).
    votes: dict[int, Counter] = defaultdict(Counter)
    for _, persons, targets in pairs:
        for p, t in zip(persons.tolist(), targets.tolist(), strict=True):
            if p >= 0 and t >= 0:
                votes[p][t] += 1
    carrier = {p: min(c.items(), key=lambda kv: (-kv[1], kv[0]))[0] for p, c in votes.items()}
    correct: Counter = Counter()
    total: Counter = Counter()
    fp_total = fp_assigned = 0
    for camera, persons, targets in pairs:
        total[camera] += 0
        for p, t in zip(persons.tolist(), targets.tolist(), strict=True):
            if p < 0:
                fp_total += 1
                fp_assigned += t >= 0
                continue
            total[camera] += 1
            correct[camera] += t >= 0 and carrier.get(p) == t
    scores = AssociationScores(frames_without_output=missing, frames_scored=len(pairs))
    for camera in total:  # order of first appearance
        scores.true_detections[camera] = total[camera]
        scores.per_camera[camera] = correct[camera] / total[camera] if total[camera] else None
    n = sum(total.values())
    scores.overall = sum(correct.values()) / n if n else None
    scores.false_positive_assigned = fp_assigned / fp_total if fp_total else None
    return scores


def project_points(camera: Camera, points: np.ndarray) -> np.ndarray:
    """Projects world points into a camera with its distortion; NaN for points behind it or far outside.

    Args:
        camera: calibrated camera.
        points: (N, 3) world points, metres (NaN allowed).

    Returns:
        (N, 2) distorted pixel coordinates.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    out = np.full((len(points), 2), np.nan)
    cam = points @ camera.R_cam_from_world.T + camera.t_cam_from_world
    with np.errstate(invalid="ignore"):
        front = np.isfinite(cam).all(axis=1) & (cam[:, 2] > _MIN_DEPTH_M)
    if not front.any():
        return out
    pin = cam[front] @ camera.K.T
    pin = pin[:, :2] / pin[:, 2:]
    w, h = camera.width_px, camera.height_px
    # The distortion polynomial folds back far outside the image: only distort points near it.
    near = ((pin[:, 0] > -_PROJECTION_MARGIN * w) & (pin[:, 0] < (1 + _PROJECTION_MARGIN) * w)
            & (pin[:, 1] > -_PROJECTION_MARGIN * h) & (pin[:, 1] < (1 + _PROJECTION_MARGIN) * h))
    if not near.any():
        return out
    px, _ = cv2.projectPoints(cam[front][near].reshape(-1, 1, 3), np.zeros(3), np.zeros(3), camera.K, camera.dist)
    idx = np.flatnonzero(front)[near]
    out[idx] = px.reshape(-1, 2)
    return out


def pose_boxes(camera: Camera, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bounding boxes of projected poses and whether each counts as visible.

    Args:
        camera: calibrated camera.
        poses: (N, J, 3) poses, metres.

    Returns:
        boxes (N, 4) as (x0, y0, x1, y1) pixels, and (N,) bool visible (at least two joints projected and
        at least `MIN_VISIBLE_FRACTION` of the box area inside the image).
    """
    poses = np.asarray(poses, dtype=np.float64)
    n, j = poses.shape[:2]
    boxes = keypoint_boxes(project_points(camera, poses.reshape(-1, 3)).reshape(n, j, 2))
    lo, hi = boxes[:, :2], boxes[:, 2:]
    size = np.prod(hi - lo, axis=1)
    inside = np.prod(np.clip(np.minimum(hi, (camera.width_px, camera.height_px)) - np.maximum(lo, 0), 0, None), axis=1)
    with np.errstate(invalid="ignore"):
        visible = np.isfinite(size) & (size > 0) & (inside >= MIN_VISIBLE_FRACTION * size)
    return boxes, visible
