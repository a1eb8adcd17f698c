"""Pose accuracy: PCP by the Campus/Shelf protocol, MPJPE and PCK per joint group.

PCP (percentage of correctly estimated parts) follows the evaluation script published with Chen et al.
(CVPR 2020, `evaluate.py` of longcw/crossview_3d_pose_tracking), which follows Belagiannis et al.:
both poses are brought to the 14-joint Campus layout, ten bones are checked, a bone is correct when the
mean of its two end-point errors is at most alpha times the true bone length (alpha = 0.5), and every true
person is compared with the estimate nearest to it (no one-to-one assignment, identities ignored).

The estimate's head joints are always placed as evaluate.py places them; a COCO-17 truth's can instead be the
points of the true head that the datasets' annotators mark (`core.head.HeadPoints`, docs/metrics.md, "Joint
conventions"), so that a simulated truth is scored as a real one is.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np

from core.head import HeadPoints
from core.layouts import coco17_to_campus14
from core.types import CAMPUS14, COCO17, Skeleton

PCP_ALPHA = 0.5
"""Fraction of the true bone length the mean end-point error may reach for a bone to count as correct."""

PCK_THRESHOLDS_M = (0.05, 0.10, 0.15)
"""PCK distance thresholds, metres (50, 100 and 150 mm)."""

MPJPE_MATCH_MAX_M = 0.5
"""A true person enters MPJPE only when its nearest estimate lies within this mean joint error (metres),
so that a missed person does not add the distance to somebody else (the VoxelPose convention)."""

# The ten checked bones of the 14-joint layout; the last one (torso) runs from the mid-hip (joints 2, 3)
# to the bottom of the head (12) and is built in `pcp_bones`.
CAMPUS_LIMBS = ((0, 1), (1, 2), (3, 4), (4, 5), (6, 7), (7, 8), (9, 10), (10, 11), (12, 13))
NUM_PCP_BONES = len(CAMPUS_LIMBS) + 1
PCP_BONE_GROUPS: OrderedDict[str, tuple[int, ...]] = OrderedDict(
    [
        ("head", (8,)),
        ("torso", (9,)),
        ("upper_arms", (5, 6)),
        ("lower_arms", (4, 7)),
        ("upper_legs", (1, 2)),
        ("lower_legs", (0, 3)),
    ]
)
"""Bone groups as indices into the (10,) result of `pcp_bones`, as in evaluate.py's table."""



def pcp_bones(estimate14: np.ndarray, truth14: np.ndarray, alpha: float = PCP_ALPHA) -> np.ndarray:
    """Which of the ten Campus bones of one estimate are correct.

    A bone (s, e) is correct when (|s_est - s_true| + |e_est - e_true|) / 2 <= alpha |e_true - s_true|.
    A NaN end point makes the bone wrong.

    Args:
        estimate14: (14, 3) estimated pose, Campus order.
        truth14: (14, 3) true pose, Campus order.
        alpha: PCP threshold as a fraction of the true bone length.

    Returns:
        (10,) bool, bones in the order of `CAMPUS_LIMBS` followed by the torso.
    """
    starts = np.array([b[0] for b in CAMPUS_LIMBS])
    ends = np.array([b[1] for b in CAMPUS_LIMBS])
    est_s = np.vstack([estimate14[starts], (estimate14[2] + estimate14[3]) / 2])
    est_e = np.vstack([estimate14[ends], estimate14[12]])
    tru_s = np.vstack([truth14[starts], (truth14[2] + truth14[3]) / 2])
    tru_e = np.vstack([truth14[ends], truth14[12]])
    length = np.linalg.norm(tru_e - tru_s, axis=1)
    error = (np.linalg.norm(tru_s - est_s, axis=1) + np.linalg.norm(tru_e - est_e, axis=1)) / 2
    with np.errstate(invalid="ignore"):
        return error <= alpha * length  # NaN compares False: a missing joint makes its bones wrong


def pose_distance_matrix(truth: np.ndarray, estimates: np.ndarray) -> np.ndarray:
    """Frobenius distance between every true and every estimated pose, NaN joints left out.

    Over the joints finite in both poses, sqrt(J * mean squared joint error): equal to the Frobenius
    norm of the difference when nothing is missing (evaluate.py's matching distance), and not biased
    toward estimates with fewer known joints otherwise. Infinite when no joint is finite in both.

    Args:
        truth: (G, J, 3) true poses.
        estimates: (H, J, 3) estimated poses.

    Returns:
        (G, H) distances.
    """
    diff = truth[:, None] - estimates[None, :]
    sq = np.sum(diff**2, axis=-1)  # (G, H, J), NaN where a joint is missing
    finite = np.isfinite(sq)
    count = finite.sum(axis=-1)
    total = np.where(finite, sq, 0.0).sum(axis=-1)
    num_joints = truth.shape[1]
    with np.errstate(invalid="ignore", divide="ignore"):
        dist = np.sqrt(num_joints * total / count)
    dist[count == 0] = np.inf
    return dist


def match_nearest(truth: np.ndarray, estimates: np.ndarray) -> np.ndarray:
    """For each true pose the index of the nearest estimate (evaluate.py's `_match_gts`), -1 if none.

    Args:
        truth: (G, J, 3) true poses.
        estimates: (H, J, 3) estimated poses.

    Returns:
        (G,) int64 indices into `estimates`.
    """
    if len(truth) == 0 or len(estimates) == 0:
        return np.full(len(truth), -1, dtype=np.int64)
    dist = pose_distance_matrix(truth, estimates)
    idx = np.argmin(dist, axis=1).astype(np.int64)
    idx[~np.isfinite(dist[np.arange(len(truth)), idx])] = -1
    return idx


def _ratio(num: float, den: float) -> float | None:
    return float(num) / float(den) if den > 0 else None


@dataclass
class PoseScores:
    """Pose accuracy of a run (fractions in [0, 1]; None where nothing was there to score).

    Attributes:
        pcp: mean over actors of each actor's PCP (evaluate.py's "Total / Average").
        pcp_per_actor: person id -> PCP over all bones of all evaluated instants.
        pcp_per_group: bone group -> mean over actors of the actor's PCP on that group.
        mpjpe_mm: mean joint error of true persons matched within `MPJPE_MATCH_MAX_M`, millimetres,
            over the joints finite in the estimate.
        mpjpe_per_group_mm: joint group -> MPJPE on that group.
        pck: threshold in mm -> fraction of all true joints within it (missed person or NaN joint: wrong).
        pck_per_group: threshold in mm -> joint group -> PCK on that group.
        num_person_instants: true persons evaluated (instants x persons).
        num_matched_instants: of those, matched within `MPJPE_MATCH_MAX_M` (enter MPJPE).
        num_nan_joints: joints of matched estimates that were NaN (left out of MPJPE, wrong for PCP/PCK).
    """

    pcp: float | None = None
    pcp_per_actor: dict[int, float] = field(default_factory=dict)
    pcp_per_group: dict[str, float | None] = field(default_factory=dict)
    mpjpe_mm: float | None = None
    mpjpe_per_group_mm: dict[str, float | None] = field(default_factory=dict)
    pck: dict[int, float | None] = field(default_factory=dict)
    pck_per_group: dict[int, dict[str, float | None]] = field(default_factory=dict)
    num_person_instants: int = 0
    num_matched_instants: int = 0
    num_nan_joints: int = 0


def to_campus14(poses: np.ndarray, skeleton: Skeleton, head: HeadPoints | None = None) -> np.ndarray:
    """(..., 14, 3) poses in the layout the PCP protocol checks, from COCO-17 (`coco17_to_campus14`, with
    `head` when given) or Campus-14 (as they are, `head` or not: a dataset's annotated truth already has its
    head joints, and they are never mapped again)."""
    if skeleton.name == CAMPUS14.name:
        return np.asarray(poses, dtype=np.float64)
    if skeleton.name == COCO17.name:
        return coco17_to_campus14(poses, head)
    raise ValueError(f"PCP: no mapping of the {skeleton.name} layout to the protocol's 14 joints "
                     f"(known: {COCO17.name}, {CAMPUS14.name})")


class PoseAccumulator:
    """Collects per-instant comparisons of true and estimated poses (py-motmetrics style).

    Args:
        alpha: PCP threshold as a fraction of the bone length.
        pck_thresholds_m: PCK thresholds, metres.
        mpjpe_match_max_m: largest mean joint error at which a true person enters MPJPE, metres.
        skeleton: the joint layout of the poses (COCO-17 or Campus-14; MPJPE and PCK by its body parts).
        truth_head: with a COCO-17 truth, where PCP's true head joints lie (`coco17_to_campus14`'s `head`);
            None: evaluate.py's mapping, as for the estimate. MPJPE and PCK compare the COCO-17 joints as
            they are.
    """

    def __init__(
        self,
        alpha: float = PCP_ALPHA,
        pck_thresholds_m: tuple[float, ...] = PCK_THRESHOLDS_M,
        mpjpe_match_max_m: float = MPJPE_MATCH_MAX_M,
        skeleton: Skeleton = COCO17,
        truth_head: HeadPoints | None = None,
    ):
        if not 0 < alpha:
            raise ValueError(f"alpha={alpha}: must be > 0 (the protocol uses 0.5)")
        if mpjpe_match_max_m <= 0:
            raise ValueError(f"mpjpe_match_max_m={mpjpe_match_max_m}: must be > 0 metres")
        self.alpha = alpha
        self.pck_thresholds_m = tuple(pck_thresholds_m)
        self.mpjpe_match_max_m = mpjpe_match_max_m
        self.skeleton = skeleton
        self.truth_head = truth_head
        self.joint_groups = skeleton.joint_groups()
        J = skeleton.num_joints
        self._bones: dict[int, list[np.ndarray]] = {}
        self._joint_err_sum = np.zeros(J)
        self._joint_err_count = np.zeros(J)
        self._pck_hits = np.zeros((len(self.pck_thresholds_m), J))
        self._pck_total = np.zeros(J)
        self._instants = 0
        self._matched = 0
        self._nan_joints = 0

    def update(self, truth_ids: np.ndarray, truth_poses: np.ndarray, estimates: np.ndarray) -> np.ndarray:
        """Scores one instant.

        Args:
            truth_ids: (G,) int ids of the true persons.
            truth_poses: (G, J, 3) true poses, metres.
            estimates: (H, J, 3) estimated poses, metres, NaN for unknown joints.

        Returns:
            (G,) each true person's share of correct PCP bones at this instant (0 when missed).
        """
        J = self.skeleton.num_joints
        truth_poses = np.asarray(truth_poses, dtype=np.float64).reshape(-1, J, 3)
        estimates = np.asarray(estimates, dtype=np.float64).reshape(-1, J, 3)
        if len(truth_ids) != len(truth_poses):
            raise ValueError(f"truth_ids has {len(truth_ids)} rows, truth_poses {len(truth_poses)}")
        # The protocol matches in the 14-joint layout (evaluate.py maps results before `_match_gts`).
        truth14 = to_campus14(truth_poses, self.skeleton, self.truth_head)
        est14 = to_campus14(estimates, self.skeleton)
        idx = match_nearest(truth14, est14)
        shares = np.zeros(len(truth_ids))
        for g, pid in enumerate(np.asarray(truth_ids).tolist()):
            self._instants += 1
            self._pck_total += 1
            if idx[g] < 0:
                self._bones.setdefault(int(pid), []).append(np.zeros(NUM_PCP_BONES, dtype=bool))
                continue
            bones = pcp_bones(est14[idx[g]], truth14[g], self.alpha)
            self._bones.setdefault(int(pid), []).append(bones)
            shares[g] = bones.mean()
            err = np.linalg.norm(estimates[idx[g]] - truth_poses[g], axis=1)  # (J,), NaN for unknown
            known = np.isfinite(err)
            for k, thr in enumerate(self.pck_thresholds_m):
                self._pck_hits[k] += known & (np.where(known, err, np.inf) <= thr)
            if known.any() and np.mean(err[known]) <= self.mpjpe_match_max_m:
                self._matched += 1
                self._nan_joints += int((~known).sum())
                self._joint_err_sum += np.where(known, err, 0.0)
                self._joint_err_count += known
        return shares

    def result(self) -> PoseScores:
        """The scores over everything accumulated so far."""
        scores = PoseScores(num_person_instants=self._instants, num_matched_instants=self._matched,
                            num_nan_joints=self._nan_joints)
        per_actor = {pid: np.asarray(rows) for pid, rows in sorted(self._bones.items())}
        scores.pcp_per_actor = {pid: float(rows.mean()) for pid, rows in per_actor.items()}
        if per_actor:
            scores.pcp = float(np.mean(list(scores.pcp_per_actor.values())))
            for name, bones in PCP_BONE_GROUPS.items():
                scores.pcp_per_group[name] = float(np.mean([rows[:, bones].mean() for rows in per_actor.values()]))
        else:
            scores.pcp_per_group = {name: None for name in PCP_BONE_GROUPS}
        scores.mpjpe_mm = _mm(_ratio(self._joint_err_sum.sum(), self._joint_err_count.sum()))
        for name, joints in self.joint_groups.items():
            j = list(joints)
            scores.mpjpe_per_group_mm[name] = _mm(
                _ratio(self._joint_err_sum[j].sum(), self._joint_err_count[j].sum())
            )
        for k, thr in enumerate(self.pck_thresholds_m):
            key = int(round(thr * 1000))
            scores.pck[key] = _ratio(self._pck_hits[k].sum(), self._pck_total.sum())
            scores.pck_per_group[key] = {
                name: _ratio(self._pck_hits[k][list(j)].sum(), self._pck_total[list(j)].sum())
                for name, j in self.joint_groups.items()
            }
        return scores


def _mm(value_m: float | None) -> float | None:
    return None if value_m is None else 1000.0 * value_m
