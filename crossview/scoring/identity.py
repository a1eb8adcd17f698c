"""Identity metrics on the ground plane: MOTA, MOTP, IDF1, switches, FP and FN, with py-motmetrics.

Every person and every target is reduced to its body root, the midpoint of the hips, and compared by
the (x, y) distance on the floor. A pair farther apart than `ROOT_MATCH_THRESHOLD_M` cannot match.
py-motmetrics does the CLEAR-MOT bookkeeping (Bernardin and Stiefelhagen 2008) and the IDF1
identity assignment (Ristani et al. 2016).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import motmetrics as mm
import numpy as np

from core.types import COCO17, Skeleton

ROOT_MATCH_THRESHOLD_M = 1.0
"""Largest ground-plane distance between body roots at which a target can match a person, metres."""


MOT_METRICS = ("mota", "motp", "idf1", "num_switches", "num_false_positives", "num_misses", "num_objects",
               "num_predictions", "num_matches", "idp", "idr")


def body_roots(poses: np.ndarray, skeleton: Skeleton = COCO17) -> np.ndarray:
    """Ground-plane body roots: the (x, y) midpoint of the hips (one hip if the other is NaN).

    Args:
        poses: (N, J, 3) poses in `skeleton`'s layout, metres.
        skeleton: the joint layout (its `hips`).

    Returns:
        (N, 2) roots, metres; NaN where both hips are unknown.
    """
    hips = np.asarray(poses, dtype=np.float64).reshape(-1, skeleton.num_joints, 3)[:, list(skeleton.hips), :2]
    known = np.isfinite(hips).all(axis=-1, keepdims=True)
    count = known.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        roots = np.where(known, hips, 0.0).sum(axis=1) / count
    roots[count[:, 0] == 0] = np.nan
    return roots


def ground_distances(truth_roots: np.ndarray, target_roots: np.ndarray, threshold_m: float) -> np.ndarray:
    """(G, H) ground-plane distances, NaN beyond the threshold or for an unknown root (py-motmetrics: no match)."""
    d = np.linalg.norm(truth_roots[:, None, :] - target_roots[None, :, :], axis=-1)
    d[~(d <= threshold_m)] = np.nan
    return d.reshape(len(truth_roots), len(target_roots))


@dataclass
class IdentityScores:
    """CLEAR-MOT and identity scores (None where undefined, e.g. MOTA with no true person).

    Attributes:
        mota: 1 - (FN + FP + IDS) / number of true person instants; can be negative.
        motp_m: mean ground-plane root distance of the matched pairs, metres.
        idf1, idp, idr: identity F1, precision and recall.
        id_switches, false_positives, false_negatives, matches: counts over the evaluation grid.
        num_truth, num_predictions: true person instants and target instants.
    """

    mota: float | None = None
    motp_m: float | None = None
    idf1: float | None = None
    idp: float | None = None
    idr: float | None = None
    id_switches: int = 0
    false_positives: int = 0
    false_negatives: int = 0
    matches: int = 0
    num_truth: int = 0
    num_predictions: int = 0


def _finite(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


class IdSwitch(NamedTuple):
    """An identity switch as py-motmetrics counts it: at `update` (0-based count of `IdentityAccumulator.update`
    calls), person `person_id` became matched to `target_id`, another target than at its previous match."""

    update: int
    person_id: int
    target_id: int


class IdEvent(NamedTuple):
    """One py-motmetrics event: at `update`, `kind` "MATCH", "SWITCH" (a match to another target than before),
    "MISS" (person `person_id` unmatched) or "FP" (target `target_id` unmatched); the other id None."""

    update: int
    kind: str
    person_id: int | None
    target_id: int | None


class IdentityAccumulator:
    """Feeds ground-plane comparisons into a py-motmetrics accumulator.

    Args:
        threshold_m: largest root distance for a match, metres.
        skeleton: the joint layout of the poses.
    """

    def __init__(self, threshold_m: float = ROOT_MATCH_THRESHOLD_M, skeleton: Skeleton = COCO17):
        if not threshold_m > 0:
            raise ValueError(f"threshold_m={threshold_m}: must be > 0 metres")
        self.threshold_m = threshold_m
        self.skeleton = skeleton
        self.acc = mm.MOTAccumulator(auto_id=True)

    def update(self, truth_ids, truth_poses: np.ndarray, target_ids, target_poses: np.ndarray) -> None:
        """Adds one instant.

        Args:
            truth_ids: (G,) person ids.
            truth_poses: (G, J, 3) true poses, metres.
            target_ids: (H,) target ids.
            target_poses: (H, J, 3) estimated poses, metres (NaN hips: the target cannot match).
        """
        roots = body_roots(truth_poses, self.skeleton), body_roots(target_poses, self.skeleton)
        d = ground_distances(*roots, self.threshold_m)
        self.acc.update([int(i) for i in truth_ids], [int(i) for i in target_ids], d)

    def switches(self) -> list[IdSwitch]:
        """The identity switches counted so far, in update order (py-motmetrics' SWITCH events)."""
        events = self.acc.mot_events
        rows = events[events["Type"] == "SWITCH"]
        frames = rows.index.get_level_values("FrameId")
        # (auto_id numbers the updates from 0.)
        return [IdSwitch(int(f), int(o), int(h)) for f, o, h in zip(frames, rows["OId"], rows["HId"])]

    def events(self) -> list[IdEvent]:
        """Every match, switch, miss and false positive counted so far, in update order (the rows of
        py-motmetrics' `mot_events` that its counts are made of)."""
        events = self.acc.mot_events
        rows = events[events["Type"].isin(("MATCH", "SWITCH", "MISS", "FP"))]
        frames = rows.index.get_level_values("FrameId")

        def as_id(value):
            return None if value is None or value != value else int(value)  # (NaN: no such side)

        return [IdEvent(int(f), str(k), as_id(o), as_id(h))
                for f, k, o, h in zip(frames, rows["Type"], rows["OId"], rows["HId"])]

    def result(self) -> IdentityScores:
        """Scores over everything added so far."""
        return identity_scores(self.acc)


def identity_scores(acc: mm.MOTAccumulator) -> IdentityScores:
    """Computes the scores of a py-motmetrics accumulator."""
    summary = mm.metrics.create().compute(acc, metrics=list(MOT_METRICS), name="run")
    row = summary.loc["run"]
    num_truth = int(row["num_objects"])
    return IdentityScores(
        mota=_finite(row["mota"]) if num_truth > 0 else None,
        motp_m=_finite(row["motp"]),
        idf1=_finite(row["idf1"]),
        idp=_finite(row["idp"]),
        idr=_finite(row["idr"]),
        id_switches=int(row["num_switches"]),
        false_positives=int(row["num_false_positives"]),
        false_negatives=int(row["num_misses"]),
        matches=int(row["num_matches"]),
        num_truth=num_truth,
        num_predictions=int(row["num_predictions"]),
    )
