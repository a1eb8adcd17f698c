"""What the tracker produces: targets with an identity and a 3D pose, and its output after each frame.

Shapes follow the project convention (see STYLE): J joints, D detections, coordinates on the last axis,
float64, NaN for a missing joint. World frame: z up, metres.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np


class TargetState(enum.Enum):
    """Lifecycle of a tracked person; all transitions happen in `tracker.lifecycle`."""

    TENTATIVE = "tentative"
    CONFIRMED = "confirmed"
    LOST = "lost"
    REMOVED = "removed"


@dataclass(frozen=True, eq=False)
class Target:
    """One tracked person as the tracker reports it.

    Attributes:
        id: identity, never reused within a run.
        pose: (J, 3) joint positions in the world frame, metres; NaN for a joint not yet known.
        stamp_s: the time the pose refers to (the stamp of the frame that produced this output).
        state: lifecycle state.
    """

    id: int
    pose: np.ndarray
    stamp_s: float
    state: TargetState = TargetState.CONFIRMED


@dataclass(frozen=True, eq=False)
class TrackerOutput:
    """What the tracker reported after one frame: the targets and where each detection went.

    Attributes:
        stamp_s: stamp of the frame that was processed.
        camera: name of that frame's camera.
        targets: confirmed targets after the update, poses at `stamp_s`.
        detection_target_ids: (D,) int64 id of the target each detection of the frame was assigned
            to (including a target it helped start), -1 for a detection left unassigned.
    """

    stamp_s: float
    camera: str
    targets: list[Target]
    detection_target_ids: np.ndarray
