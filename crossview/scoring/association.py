"""Per-camera association accuracy (the paper's Figure 4) and per-camera 2D tracking quality (Table 5).

Association accuracy: over the run, each person's *carrier* is the target to which most of that
person's true detections (all cameras) were assigned. A true detection is correctly associated when the
tracker assigned it to its person's carrier; a detection left unassigned, or given to another target, is
wrong. Accuracy per camera = correct / true detections of that camera; the overall figure pools all
cameras. False-positive detections (person id -1) are not in the denominator; the share of them that the
tracker did assign to a target is reported beside. Camera frames with no tracker output of the same
camera and stamp (the tracker never processed them) are left out and counted.

2D tracking per camera (the paper scores Shelf this way, following MOTChallenge): for every tracker
output of a camera, the targets' 3D poses and the true poses at the output's stamp are projected into
that camera (OpenCV model with distortion); each becomes the bounding box of its projected joints. A
box counts when at least `MIN_VISIBLE_FRACTION` of it lies inside the image. Boxes match when their
IoU is at least `IOU_THRESHOLD`; py-motmetrics gives MOTA, IDF1, FP, FN and IDS per camera.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

import cv2
import motmetrics as mm
import numpy as np

from core.boxes import box_iou, keypoint_boxes
from core.types import Camera
from crossview.scoring.identity import identity_scores
from sim.types import CameraFrame
from tracker.types import TargetState, TrackerOutput

IOU_THRESHOLD = 0.5
"""Smallest IoU of a projected target box and a true box that counts as a match (MOTChallenge)."""
MIN_VISIBLE_FRACTION = 0.5
"""Fraction of a projected box that must lie inside the image for the box to count."""
SCORED_STATES = (TargetState.CONFIRMED, TargetState.LOST)
"""Target states that are scored (a tracker reports confirmed targets; tentative and removed ones never count)."""
_MIN_DEPTH_M = 0.1
_PROJECTION_MARGIN = 0.5  # fraction of the image size outside which undistorted points are not distorted


def _stamp_key(camera: str, stamp_s: float) -> tuple[str, int]:
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
    assigned = {_stamp_key(o.camera, o.stamp_s): np.asarray(o.detection_target_ids, dtype=np.int64) for o in outputs}
    pairs: list[tuple[str, np.ndarray, np.ndarray]] = []
    missing = 0
    for cf in camera_frames:
        key = _stamp_key(cf.frame.camera, cf.frame.stamp_s)
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


@dataclass
class Camera2DScores:
    """MOTChallenge-style scores of one camera's projected tracks (the paper's Table 5)."""

    mota: float | None
    idf1: float | None
    false_positives: int
    false_negatives: int
    id_switches: int
    num_truth: int
    num_frames: int


def projected_2d_scores(
    outputs: Sequence[TrackerOutput],
    cameras: Sequence[Camera],
    truth_at: Callable[[float], tuple[np.ndarray, np.ndarray]],
) -> dict[str, Camera2DScores]:
    """Per-camera 2D MOT scores of projected 3D tracks, see the module docstring.

    Args:
        outputs: tracker outputs; each is scored in the camera that produced it.
        cameras: the calibrated cameras.
        truth_at: t -> (ids (P,), poses (P, J, 3)) true poses at time t.

    Returns:
        camera name -> scores, for every camera given.
    """
    by_name = {c.name: c for c in cameras}
    accs = {name: mm.MOTAccumulator(auto_id=True) for name in by_name}
    frames: Counter = Counter()
    for out in outputs:
        camera = by_name.get(out.camera)
        if camera is None:
            raise ValueError(f"2D scores: tracker output from camera {out.camera!r}, not among {sorted(by_name)}")
        ids, poses = truth_at(out.stamp_s)
        t_boxes, t_vis = pose_boxes(camera, poses) if len(ids) else (np.zeros((0, 4)), np.zeros(0, bool))
        targets = [t for t in out.targets if t.state in SCORED_STATES]
        h_ids = np.array([t.id for t in targets], dtype=np.int64)
        h_poses = np.array([t.pose for t in targets], dtype=np.float64) if targets else np.zeros((0, 1, 3))
        h_boxes, h_vis = pose_boxes(camera, h_poses) if len(h_ids) else (np.zeros((0, 4)), np.zeros(0, bool))
        iou = box_iou(t_boxes[t_vis], h_boxes[h_vis])
        dist = np.where(iou >= IOU_THRESHOLD, 1.0 - iou, np.nan)
        accs[camera.name].update(np.asarray(ids)[t_vis].tolist(), h_ids[h_vis].tolist(), dist)
        frames[camera.name] += 1
    result = {}
    for name in by_name:  # the cameras' own order
        s = identity_scores(accs[name])
        result[name] = Camera2DScores(s.mota, s.idf1, s.false_positives, s.false_negatives, s.id_switches,
                                      s.num_truth, frames[name])
    return result
