"""What the tracker produces: targets with an identity and a 3D pose, and its output after each frame.

Shapes follow the project convention (CONTRIBUTING.md, "Names, units and shapes"): J joints, D detections,
coordinates on the last axis, float64, NaN for a missing joint. World frame: z up, metres.
"""

from __future__ import annotations

import enum
import operator
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np


class TargetState(enum.Enum):
    """Lifecycle of a tracked person; all transitions happen in `tracker.lifecycle`."""

    TENTATIVE = "tentative"
    CONFIRMED = "confirmed"
    LOST = "lost"
    REMOVED = "removed"


class JointState(enum.Enum):
    """Where an output joint comes from; its value is the per-joint code of `Target.joint_state`."""

    OBSERVED = 0  # triangulated from cameras' points within the last `stale_after_s`
    PREDICTED = 1  # triangulated earlier, carried with the body's motion since (eq. 5)
    INFERRED = 2  # never triangulated: from the target's own body (tracker.body.fill_unknown)


@dataclass(frozen=True, eq=False)
class Target:
    """One tracked person as the tracker reports it.

    Attributes:
        id: identity, never reused within a run.
        pose: (J, 3) joint positions in the world frame, metres; the tracker's outputs hold no NaN (a joint not
            yet triangulated is inferred, see `joint_state`); a target read from an old tracks file may.
        stamp_s: the time the pose refers to (the stamp of the frame that produced this output).
        state: lifecycle state.
        joint_state: (J,) uint8 `JointState` values per joint; None when unknown (tracks files of format 2).
    """

    id: int
    pose: np.ndarray
    stamp_s: float
    state: TargetState = TargetState.CONFIRMED
    joint_state: np.ndarray | None = None


class TargetArrays(Sequence):
    """Targets of one output held as arrays, all with one stamp and state: a sequence of `Target`, each made
    only when it is read. The built-in tracker emits these every frame; the tracks file's encoder takes the
    arrays as they are, so no per-target object is made on that path (in the hypermarket, making 200 per
    camera frame took longer than tracking).

    Attributes:
        ids: (T,) int64 identities.
        poses: (T, J, 3) joint positions, metres.
        joint_states: (T, J) uint8 `JointState` codes.
        stamp_s: the stamp of every target.
        state: the lifecycle state of every target.
    """

    __slots__ = ("ids", "poses", "joint_states", "stamp_s", "state")

    def __init__(self, ids: np.ndarray, poses: np.ndarray, joint_states: np.ndarray, stamp_s: float,
                 state: TargetState = TargetState.CONFIRMED):
        self.ids, self.poses, self.joint_states = ids, poses, joint_states
        self.stamp_s, self.state = stamp_s, state

    def __len__(self) -> int:
        return len(self.ids)

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        i = operator.index(index)
        if not -len(self) <= i < len(self):
            raise IndexError(f"target index {i} out of range for {len(self)} targets")
        i %= len(self)
        return Target(int(self.ids[i]), self.poses[i], self.stamp_s, self.state, self.joint_states[i])

    def __iter__(self) -> Iterator[Target]:
        for i, target_id in enumerate(self.ids.tolist()):
            yield Target(target_id, self.poses[i], self.stamp_s, self.state, self.joint_states[i])

    def __repr__(self) -> str:
        return f"TargetArrays({len(self)} targets at {self.stamp_s} s)"


@dataclass(frozen=True, eq=False)
class TrackerOutput:
    """What the tracker reported after one frame: the targets and where each detection went.

    Attributes:
        stamp_s: stamp of the frame that was processed.
        camera: name of that frame's camera.
        targets: confirmed targets after the update, poses at `stamp_s` (a list, or `TargetArrays`).
        detection_target_ids: (D,) int64 id of the target each detection of the frame was assigned
            to (including a target it helped start), -1 for a detection left unassigned.
    """

    stamp_s: float
    camera: str
    targets: Sequence[Target]
    detection_target_ids: np.ndarray


STANDING_STATES = (TargetState.CONFIRMED, TargetState.LOST)
"""Target states that stand for a person (a tracker reports confirmed targets; tentative and removed ones never
count): what scoring scores and the zones' merger hands over."""


def target_arrays(targets: Sequence[Target], num_joints: int) -> tuple[np.ndarray, np.ndarray]:
    """A tracker output's targets in the one shape every reader uses: ids (T,) int64 and poses (T, J, 3) float64
    of the targets in `STANDING_STATES`, in their order; a `TargetArrays` gives its own arrays without making a
    `Target` each. With none, poses is (0, num_joints, 3).

    Raises:
        ValueError: poses of different shapes.
    """
    if isinstance(targets, TargetArrays):
        if targets.state in STANDING_STATES:
            return np.asarray(targets.ids, dtype=np.int64), np.asarray(targets.poses, dtype=np.float64)
        return np.zeros(0, dtype=np.int64), np.zeros((0, num_joints, 3))
    kept = [t for t in targets if t.state in STANDING_STATES]
    if not kept:
        return np.zeros(0, dtype=np.int64), np.zeros((0, num_joints, 3))
    return (np.array([t.id for t in kept], dtype=np.int64),
            np.array([np.asarray(t.pose, dtype=np.float64) for t in kept]))
