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
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from core.boxes import keypoint_boxes
from core.projection import in_image
from core.records import CameraFrame
from core.types import Camera
from tracker.types import TrackerOutput
from tracker.visibility import poses_in_volume, view_planes

MIN_VISIBLE_FRACTION = 0.5
"""Fraction of a projected box that must lie inside the image for the box to count."""
_MIN_DEPTH_M = 0.1
_PROJECTION_MARGIN = 0.5  # fraction of the image size outside which undistorted points are not distorted
_VOLUME_SLACK_M = 1e-6  # how much wider `projection_volume` is than what `project_points` projects


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


class AssociationAccumulator:
    """Association accuracy fed one camera frame and one tracker output at a time, in any interleaving.

    A frame and the output made from it (same `stamp_key`) are paired as soon as both have been added;
    only the unpaired ones wait, so memory is bounded by how far the two streams drift apart, and the
    counts are kept per (camera, person, target): bounded by cameras x people x targets, not by frames.
    """

    def __init__(self):
        self._outputs: dict[tuple[str, int], np.ndarray] = {}  # unpaired outputs' detection target ids
        self._frames: dict[tuple[str, int], tuple[int, float, np.ndarray]] = {}  # unpaired frames: index, stamp, ids
        self._num_frames = 0
        self._first: dict[str, int] = {}  # camera -> index of its first paired frame (the result's order)
        self._counts: Counter = Counter()  # (camera, person, target) -> detections
        self._paired = 0

    def add_output(self, output: TrackerOutput) -> None:
        """Adds a tracker output; `detection_target_ids` rows match its frame's detections."""
        key = stamp_key(output.camera, output.stamp_s)
        targets = np.asarray(output.detection_target_ids, dtype=np.int64)
        frame = self._frames.pop(key, None)
        if frame is None:
            self._outputs[key] = targets
        else:
            self._pair(key, *frame, targets)

    def add_frame(self, camera_frame: CameraFrame) -> None:
        """Adds a delivered frame with its per-detection truth."""
        key = stamp_key(camera_frame.frame.camera, camera_frame.frame.stamp_s)
        persons = np.asarray(camera_frame.truth.person_ids, dtype=np.int64)
        index, self._num_frames = self._num_frames, self._num_frames + 1
        targets = self._outputs.pop(key, None)
        if targets is None:
            self._frames[key] = (index, camera_frame.frame.stamp_s, persons)
        else:
            self._pair(key, index, camera_frame.frame.stamp_s, persons, targets)

    @property
    def waiting_outputs(self) -> int:
        """Outputs added whose frame has not been added yet."""
        return len(self._outputs)

    def _pair(self, key, index: int, stamp_s: float, persons: np.ndarray, targets: np.ndarray) -> None:
        if targets.shape != persons.shape:
            raise ValueError(
                f"association: camera {key[0]} at {stamp_s} s has {len(persons)} detections but the tracker "
                f"output assigns {len(targets)}; the tracks do not belong to this recording"
            )
        camera = key[0]
        self._first[camera] = min(self._first.get(camera, index), index)
        self._counts.update(zip([camera] * len(persons), persons.tolist(), targets.tolist(), strict=True))
        self._paired += 1

    def result(self) -> AssociationScores:
        """Scores over the frames and outputs added so far (unpaired frames count as without output)."""
        # Each person's carrier: the target most of its detections went to (ties: the smaller id).
        votes: dict[int, Counter] = defaultdict(Counter)
        for (_, p, t), n in self._counts.items():
            if p >= 0 and t >= 0:
                votes[p][t] += n
        carrier = {p: min(c.items(), key=lambda kv: (-kv[1], kv[0]))[0] for p, c in votes.items()}
        correct: Counter = Counter()
        total: Counter = Counter({camera: 0 for camera in sorted(self._first, key=self._first.get)})
        fp_total = fp_assigned = 0
        for (camera, p, t), n in self._counts.items():
            if p < 0:
                fp_total += n
                fp_assigned += n if t >= 0 else 0
                continue
            total[camera] += n
            correct[camera] += n if t >= 0 and carrier.get(p) == t else 0
        scores = AssociationScores(frames_without_output=len(self._frames), frames_scored=self._paired)
        for camera in total:  # order of the first paired frame of each camera
            scores.true_detections[camera] = total[camera]
            scores.per_camera[camera] = correct[camera] / total[camera] if total[camera] else None
        n = sum(total.values())
        scores.overall = sum(correct.values()) / n if n else None
        scores.false_positive_assigned = fp_assigned / fp_total if fp_total else None
        return scores


def association_accuracy(camera_frames: Iterable[CameraFrame], outputs: Iterable[TrackerOutput]) -> AssociationScores:
    """The paper's association accuracy per camera (Figure 4), see the module docstring.

    Args:
        camera_frames: delivered frames with per-detection truth.
        outputs: tracker outputs; `detection_target_ids` rows match the frame's detections.
    """
    acc = AssociationAccumulator()
    for o in outputs:
        acc.add_output(o)
    for cf in camera_frames:
        acc.add_frame(cf)
    return acc.result()


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
    idx = np.flatnonzero(front)[near]
    out[idx] = in_image(camera, points[idx])[0]  # the simulator's projection, which drew the detections
    return out


def projection_volume(camera: Camera) -> np.ndarray:
    """(5, 4) planes (`tracker.visibility.view_planes`) around the points that `project_points` projects: in
    front of the camera and inside the undistorted image widened by its margin, both by a micrometre more so
    that rounding can only keep a point that the projection leaves out, never the other way round."""
    w, h, m = float(camera.width_px), float(camera.height_px), _PROJECTION_MARGIN
    return view_planes(camera, margin_px=0.0, bounds_px=(-m * w, -m * h, (1 + m) * w, (1 + m) * h),
                       near_m=_MIN_DEPTH_M) + np.array([0.0, 0.0, 0.0, _VOLUME_SLACK_M])


def may_project(volume: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """(N,) bool: whether a pose of poses (N, J, 3) has a joint inside `volume` (`projection_volume`).

    A pose without one has no joint that `project_points` projects, so no box and no part in the camera's
    2D scores: leaving it out changes nothing, and in a large store it is nearly everybody.
    """
    poses = np.ascontiguousarray(poses, dtype=np.float64)
    out = np.empty(poses.shape[0], dtype=np.bool_)
    poses_in_volume(np.ascontiguousarray(volume, dtype=np.float64), poses, 0.0, out)
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
    return projected_boxes(camera, project_points(camera, poses.reshape(-1, 3)).reshape(n, j, 2))


def projected_boxes(camera: Camera, poses_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`pose_boxes` of poses already projected by `project_points`.

    Args:
        camera: the camera they were projected into.
        poses_px: (N, J, 2) projected joints, pixels (NaN: not projected).

    Returns:
        boxes (N, 4) and (N,) bool visible, as `pose_boxes`.
    """
    boxes = keypoint_boxes(poses_px)
    lo, hi = boxes[:, :2], boxes[:, 2:]
    size = np.prod(hi - lo, axis=1)
    inside = np.prod(np.clip(np.minimum(hi, (camera.width_px, camera.height_px)) - np.maximum(lo, 0), 0, None), axis=1)
    with np.errstate(invalid="ignore"):
        visible = np.isfinite(size) & (size > 0) & (inside >= MIN_VISIBLE_FRACTION * size)
    return boxes, visible
