"""The head as a rigid body seen through its COCO-17 keypoints: any point of it from the nose and the ears.

The nose and the two ears are three points of one rigid head, so they fix its pose, and every other point of
it (the top of the skull, the base of the head) is a fixed combination of them. The frame they define:

- origin c: the midpoint of the ears; scale w: the ear-to-ear distance |l|, with l = left_ear - right_ear;
- lateral axis l^ = l / w (towards the person's left);
- forward axis f^: the nose - c direction with its lateral part removed (towards the face);
- up axis u^ = f^ x l^ (towards the top of the head).

A point with coefficients (a, b, u) lies at c + w (a f^ + b l^ + u u^). Scaling by w makes the coefficients
the same for every body height when the whole body scales, as the simulator's humanoids do. Scoring uses
this to place the Campus/Shelf head joints (bottom and top of the head) on the true head
(docs/metrics.md, "Joint conventions").
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

NOSE, LEFT_EAR, RIGHT_EAR = 0, 3, 4
"""Indices of the nose and the ears in the COCO-17 layout (`core.types.COCO17`)."""


class HeadConvention(enum.Enum):
    """Where the true head joints of the 14-joint Campus/Shelf layout lie when the truth is COCO-17."""

    EVALUATE = "evaluate"  # mapped from the truth's shoulders and nose as evaluate.py maps an estimate
    ANNOTATED = "annotated"  # on the true head, where the datasets' annotators mark them (`HeadPoints`)


def head_frame(nose: np.ndarray, left_ear: np.ndarray, right_ear: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The head frame of nose and ears (see the module docstring).

    Args:
        nose, left_ear, right_ear: (..., 3) points, metres.

    Returns:
        origin (..., 3) the ears' midpoint; axes (..., 3, 3) whose columns are f^, l^, u^; scale (...,) the
        ear-to-ear distance, metres. NaN where a point is NaN or the three are collinear.
    """
    nose, left_ear, right_ear = (np.asarray(p, dtype=np.float64) for p in (nose, left_ear, right_ear))
    origin = (left_ear + right_ear) / 2
    lateral = left_ear - right_ear
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.linalg.norm(lateral, axis=-1)
        lateral = lateral / scale[..., None]
        forward = nose - origin
        forward = forward - np.sum(forward * lateral, axis=-1, keepdims=True) * lateral
        forward = forward / np.linalg.norm(forward, axis=-1, keepdims=True)
    up = np.cross(forward, lateral)
    return origin, np.stack([forward, lateral, up], axis=-1), scale


@dataclass(frozen=True)
class HeadPoints:
    """The bottom and the top of the head (joints 12 and 13 of the Campus/Shelf layout) as points of a rigid
    head, in the head frame of its nose and ears (coefficients (a, b, u), see the module docstring).

    Attributes:
        bottom_head: coefficients of the bottom of the head (the base of the head, on top of the neck).
        top_head: coefficients of the top of the head (the vertex of the skull).
    """

    bottom_head: tuple[float, float, float]
    top_head: tuple[float, float, float]

    def __post_init__(self):
        for name in ("bottom_head", "top_head"):
            value = np.asarray(getattr(self, name), dtype=np.float64)
            if value.shape != (3,) or not np.all(np.isfinite(value)):
                raise ValueError(f"HeadPoints.{name}: expected 3 finite coefficients, got {getattr(self, name)!r}")

    @classmethod
    def of(cls, bottom_head: np.ndarray, top_head: np.ndarray, nose: np.ndarray, left_ear: np.ndarray,
           right_ear: np.ndarray) -> HeadPoints:
        """The coefficients of two points of a head, given with its nose and ears in any one frame.

        Args:
            bottom_head, top_head, nose, left_ear, right_ear: (3,) points, metres.
        """
        origin, axes, scale = head_frame(nose, left_ear, right_ear)

        def coefficients(point) -> tuple[float, float, float]:
            return tuple(float(v) for v in axes.T @ (np.asarray(point, dtype=np.float64) - origin) / scale)

        return cls(coefficients(bottom_head), coefficients(top_head))

    def locate(self, poses: np.ndarray) -> np.ndarray:
        """The bottom and the top of the head of COCO-17 poses.

        Args:
            poses: (..., 17, 3) COCO-17 joints, metres.

        Returns:
            (..., 2, 3) bottom of the head, top of the head; NaN where the nose or an ear is.
        """
        poses = np.asarray(poses, dtype=np.float64)
        origin, axes, scale = head_frame(poses[..., NOSE, :], poses[..., LEFT_EAR, :], poses[..., RIGHT_EAR, :])
        coefficients = np.array([self.bottom_head, self.top_head])  # (2, 3)
        offsets = np.einsum("...ij,kj->...ki", axes, coefficients)  # (..., 2, 3): axes @ each coefficient row
        return origin[..., None, :] + scale[..., None, None] * offsets
