"""The plain data every part shares: skeletons (joint layouts), calibrated cameras and 2D frames.

Shapes follow the project convention (CONTRIBUTING.md, "Names, units and shapes"): C cameras, J joints,
D detections, T targets, coordinates on the last axis, float64, NaN for a missing joint. World frame: z up,
metres. Camera frame: OpenCV (x right, y down, z forward).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


def _as_array(name: str, value, shape: tuple[int | None, ...]) -> np.ndarray:
    """Returns `value` as a float64 array, checking its shape (None matches any size)."""
    array = np.asarray(value, dtype=np.float64)
    if array.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, array.shape)):
        expected = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name}: expected shape {expected}, got {array.shape}")
    return array


# Body parts for per-part errors, and the words a joint's name holds to belong to one.
JOINT_GROUPS = {
    "head": ("nose", "eye", "ear", "head"), "shoulders": ("shoulder",), "elbows": ("elbow",), "wrists": ("wrist",),
    "hips": ("hip",), "knees": ("knee",), "ankles": ("ankle",),
}


@dataclass(frozen=True)
class Skeleton:
    """A joint layout: joint names in order and the bones between them (index pairs)."""

    name: str
    joints: tuple[str, ...]
    bones: tuple[tuple[int, int], ...]

    def __post_init__(self):
        for a, b in self.bones:
            if not (0 <= a < len(self.joints) and 0 <= b < len(self.joints)):
                raise ValueError(f"Skeleton {self.name}: bone ({a}, {b}) outside 0..{len(self.joints) - 1}")

    @property
    def num_joints(self) -> int:
        return len(self.joints)

    def index(self, joint: str) -> int:
        return self.joints.index(joint)

    @property
    def hips(self) -> tuple[int, int]:
        """Indices of the left and right hips: the body root (their midpoint) that identity metrics use."""
        return self.index("left_hip"), self.index("right_hip")

    def joint_groups(self) -> dict[str, tuple[int, ...]]:
        """The joints of each body part that has any in this layout, in `JOINT_GROUPS` order, by joint name."""
        groups = {}
        for group, words in JOINT_GROUPS.items():
            members = tuple(i for i, joint in enumerate(self.joints) if any(w in joint for w in words))
            if members:
                groups[group] = members
        return groups


COCO17 = Skeleton(
    name="coco17",
    joints=(
        "nose", "left_eye", "right_eye", "left_ear", "right_ear",
        "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
        "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle",
    ),
    bones=(
        (0, 1), (0, 2), (1, 3), (2, 4),
        (5, 6), (5, 7), (7, 9), (6, 8), (8, 10),
        (5, 11), (6, 12), (11, 12),
        (11, 13), (13, 15), (12, 14), (14, 16),
    ),
)

# The 14 joints of the Campus and Shelf annotations (Belagiannis et al.), in their order.
CAMPUS14 = Skeleton(
    name="campus14",
    joints=(
        "right_ankle", "right_knee", "right_hip", "left_hip", "left_knee", "left_ankle",
        "right_wrist", "right_elbow", "right_shoulder", "left_shoulder", "left_elbow", "left_wrist",
        "bottom_head", "top_head",
    ),
    bones=(
        (0, 1), (1, 2), (3, 4), (4, 5), (6, 7), (7, 8), (9, 10), (10, 11),
        (2, 3), (8, 9), (12, 13), (8, 12), (9, 12),
    ),
)

SKELETONS = {s.name: s for s in (COCO17, CAMPUS14)}


MAX_IMAGE_PX = 100_000
"""Largest image width or height a camera may have, pixels."""


@dataclass(frozen=True, eq=False)
class Camera:
    """A calibrated camera: OpenCV pinhole model with k1, k2, p1, p2, k3 distortion.

    A world point X (metres) maps to camera coordinates `R_cam_from_world @ X + t_cam_from_world`,
    then through `K` and the distortion to pixels.

    Attributes:
        name: unique camera name.
        K: (3, 3) intrinsic matrix, pixels.
        dist: (5,) OpenCV distortion (k1, k2, p1, p2, k3).
        R_cam_from_world: (3, 3) rotation.
        t_cam_from_world: (3,) translation, metres.
        width_px, height_px: image size.
    """

    name: str
    K: np.ndarray
    dist: np.ndarray
    R_cam_from_world: np.ndarray
    t_cam_from_world: np.ndarray
    width_px: int
    height_px: int
    P: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        set_ = object.__setattr__
        set_(self, "K", _as_array(f"Camera {self.name}: K", self.K, (3, 3)))
        dist = np.zeros(5)
        given = np.asarray(self.dist, dtype=np.float64).ravel()
        if given.size > 5:
            raise ValueError(f"Camera {self.name}: dist has {given.size} coefficients, at most 5 (k1 k2 p1 p2 k3)")
        dist[: given.size] = given
        set_(self, "dist", dist)
        R = _as_array(f"Camera {self.name}: R_cam_from_world", self.R_cam_from_world, (3, 3))
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise ValueError(f"Camera {self.name}: R_cam_from_world is not a rotation matrix")
        set_(self, "R_cam_from_world", R)
        set_(self, "t_cam_from_world", _as_array(f"Camera {self.name}: t_cam_from_world", self.t_cam_from_world, (3,)))
        if not (0 < self.width_px <= MAX_IMAGE_PX and 0 < self.height_px <= MAX_IMAGE_PX):
            raise ValueError(f"Camera {self.name}: image size {self.width_px}x{self.height_px} must be positive and "
                             f"at most {MAX_IMAGE_PX} pixels a side")
        for a in (self.K, self.dist, self.R_cam_from_world, self.t_cam_from_world):
            if not np.all(np.isfinite(a)):
                raise ValueError(f"Camera {self.name}: calibration holds NaN or infinite values")
        K = self.K
        if not (K[0, 0] > 0 and K[1, 1] > 0 and K[1, 0] == K[2, 0] == K[2, 1] == 0 and K[2, 2] == 1):
            raise ValueError(f"Camera {self.name}: K = {K.tolist()} is not a pinhole intrinsic matrix (focal lengths "
                             "fx, fy > 0 pixels on the diagonal, zeros below it, K[2, 2] = 1)")
        # Eq. (7): the projection matrix of the undistorted pinhole model, P = K [R | t].
        set_(self, "P", self.K @ np.hstack([R, self.t_cam_from_world[:, None]]))

    @property
    def center_world(self) -> np.ndarray:
        """(3,) camera centre in the world frame, metres."""
        return -self.R_cam_from_world.T @ self.t_cam_from_world


def camera_index(cameras, owner: str) -> dict[str, int]:
    """Camera name -> position in `cameras`; ValueError naming `owner` when two cameras share a name."""
    names = [c.name for c in cameras]
    if len(set(names)) != len(names):
        raise ValueError(f"{owner}: camera names must be unique, got {names}")
    return {name: i for i, name in enumerate(names)}


@dataclass(frozen=True, eq=False)
class Frame:
    """One camera's 2D detections at one stamp, as a live detector would deliver them.

    Attributes:
        camera: name of the camera that took it.
        stamp_s: the time the camera stamped on the frame, seconds since the scenario start.
        keypoints_px: (D, J, 2) distorted pixel coordinates; NaN for a joint not detected.
        scores: (D, J) detector confidences in [0, 1]; 0 for a joint not detected.
    """

    camera: str
    stamp_s: float
    keypoints_px: np.ndarray
    scores: np.ndarray

    def __post_init__(self):
        kp = np.asarray(self.keypoints_px, dtype=np.float64)
        if kp.ndim != 3 or kp.shape[2] != 2:
            raise ValueError(f"Frame {self.camera}@{self.stamp_s}: keypoints_px expected (D, J, 2), got {kp.shape}")
        scores = np.asarray(self.scores, dtype=np.float64)
        if scores.shape != kp.shape[:2]:
            raise ValueError(f"Frame {self.camera}@{self.stamp_s}: scores expected {kp.shape[:2]}, got {scores.shape}")
        object.__setattr__(self, "keypoints_px", kp)
        object.__setattr__(self, "scores", scores)

    @property
    def num_detections(self) -> int:
        return self.keypoints_px.shape[0]
