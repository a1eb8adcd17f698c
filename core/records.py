"""Plain data a recording holds beside the tracker's frames: store geometry, the ground truth, the detector's
rows and a delivered camera frame with the truth behind it.

The simulator makes them; the recording formats, scoring and the pictures read them. Everything here is
numpy only, so those parts use it without MuJoCo and without `sim/`.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from core.types import Frame


class BoxKind(enum.Enum):
    """What a box of the store is, for drawing and for occlusion bookkeeping."""

    FLOOR = "floor"
    WALL = "wall"
    SHELF = "shelf"
    CHECKOUT = "checkout"
    ENTRANCE = "entrance"
    EXIT = "exit"


@dataclass(frozen=True)
class Box:
    """An axis-aligned-in-yaw box of the store.

    Attributes:
        kind: what it is.
        center_m: (x, y, z) of the box centre in the world frame.
        size_m: full extents (x, y, z) before the yaw rotation.
        yaw_rad: rotation about the world z axis.
    """

    kind: BoxKind
    center_m: tuple[float, float, float]
    size_m: tuple[float, float, float]
    yaw_rad: float = 0.0


def watched_floor(boxes) -> tuple[float, float, float, float] | None:
    """(x_min, y_min, x_max, y_max) of the store's floor (the cameras' ground), metres; None without a floor."""
    floors = [b for b in boxes if b.kind is BoxKind.FLOOR]
    if not floors:
        return None
    corners = []
    for b in floors:
        c, s = np.cos(b.yaw_rad), np.sin(b.yaw_rad)
        for dx, dy in ((-1, -1), (-1, 1), (1, -1), (1, 1)):
            hx, hy = dx * b.size_m[0] / 2, dy * b.size_m[1] / 2
            corners.append((b.center_m[0] + c * hx - s * hy, b.center_m[1] + s * hx + c * hy))
    xy = np.array(corners)
    return (*xy.min(axis=0).tolist(), *xy.max(axis=0).tolist())


@dataclass(frozen=True, eq=False)
class PoseTruth:
    """The true 3D poses of everybody in the store at one instant.

    Attributes:
        t_s: true time, seconds since the scenario start.
        person_ids: (P,) int64 ids of the people present.
        poses: (P, J, 3) keypoints in the world frame, metres.
    """

    t_s: float
    person_ids: np.ndarray
    poses: np.ndarray


@dataclass(frozen=True, eq=False)
class DetectionTruth:
    """What really lies behind each detection of one camera frame (rows match `Frame` rows).

    Attributes:
        capture_s: the true capture time of the frame (the stamp is the camera's jittered clock).
        delivery_s: when the frame reached the tracker; frames are delivered in this order.
        person_ids: (D,) int64 person behind each detection, -1 for a false positive.
        keypoints_px: (D, J, 2) true distorted pixel position of each joint (NaN for a false positive).
        in_image: (D, J) bool, the joint is in front of the camera and inside the image.
        occluded: (D, J) bool, the ray to the joint first hits a shelf, a wall or another person.
        self_occluded: (D, J) bool, the ray first hits another limb of the same person.
        effects: (D,) int, bit mask of `DetectionEffect` values applied to the detection.
    """

    capture_s: float
    delivery_s: float
    person_ids: np.ndarray
    keypoints_px: np.ndarray
    in_image: np.ndarray
    occluded: np.ndarray
    self_occluded: np.ndarray
    effects: np.ndarray


class DetectionEffect(enum.IntFlag):
    """Detector effects recorded per detection, so that statistics can be measured from a recording."""

    NONE = 0
    FRAGMENT = 1
    DUPLICATE = 2
    PHANTOM = 4
    LEFT_RIGHT_SWAP = 8
    GROSS_ERROR = 16


class Capture(NamedTuple):
    """One frame a camera takes, as the simulation hands it to the detector.

    Attributes:
        camera: index of the camera in the rig.
        poses: everybody's true pose at the capture time; None where the poses were left out (a recording
            writer does not need them, and the detector then takes the people's ids separately).
        capture_s: true capture time, seconds since the scenario start.
        stamp_s: the time the camera stamped on the frame.
        delivery_s: when the frame reaches the tracker.
    """

    camera: int
    poses: PoseTruth | None
    capture_s: float
    stamp_s: float
    delivery_s: float


class DetectionRows(NamedTuple):
    """Every detection of a batch of captures as a struct of arrays, one row per detection (D rows, each
    frame's rows together and in the order the detector reports them).

    Attributes:
        person_ids: (D,) int64 true person of each detection, -1 for a phantom.
        keypoints_px: (D, J, 2) reported pixels, NaN for a joint not reported.
        scores: (D, J) reported scores, 0 for a joint not reported.
        true_px: (D, J, 2) the true joints' pixels (NaN behind the camera).
        in_image: (D, J) bool, the true joint is inside the image.
        occluded: (D, J) bool, hidden by the store or another person.
        self_occluded: (D, J) bool, hidden by the person's own body.
        effects: (D,) int64 `DetectionEffect` bits.
    """

    person_ids: np.ndarray
    keypoints_px: np.ndarray
    scores: np.ndarray
    true_px: np.ndarray
    in_image: np.ndarray
    occluded: np.ndarray
    self_occluded: np.ndarray
    effects: np.ndarray

    @classmethod
    def empty(cls, num_joints: int) -> DetectionRows:
        """No detection at all."""
        J = num_joints
        return cls(np.zeros(0, np.int64), np.zeros((0, J, 2)), np.zeros((0, J)), np.zeros((0, J, 2)),
                   *(np.zeros((0, J), dtype=bool) for _ in range(3)), np.zeros(0, np.int64))


@dataclass(frozen=True, eq=False)
class CameraFrame:
    """One delivered camera frame: what the tracker sees and the truth behind it.

    Attributes:
        frame: the detections as the tracker receives them.
        truth: per-detection truth, rows matching `frame`.
        poses_at_capture: everybody's true 3D pose at the true capture time (`core.poses.interpolate_poses`
            of the truth ticks around it); None where it was not asked for (a recording does not store it:
            its reader derives it from the stored truth ticks on request).
    """

    frame: Frame
    truth: DetectionTruth
    poses_at_capture: PoseTruth | None

    @classmethod
    def from_rows(cls, camera: str, stamp_s: float, capture_s: float, delivery_s: float, rows: DetectionRows,
                  start: int, end: int, poses_at_capture: PoseTruth | None = None) -> CameraFrame:
        """The frame whose detections are rows start:end of `rows`, as views."""
        ids, kp, scores, true_px, in_image, occluded, self_occluded, effects = (r[start:end] for r in rows)
        return cls(Frame(camera, float(stamp_s), kp, scores),
                   DetectionTruth(capture_s=float(capture_s), delivery_s=float(delivery_s), person_ids=ids,
                                  keypoints_px=true_px, in_image=in_image, occluded=occluded,
                                  self_occluded=self_occluded, effects=effects),
                   poses_at_capture)
