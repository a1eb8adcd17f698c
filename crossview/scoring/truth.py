"""The ground truth at any time t (`TruthTimeline`): what `crossview.scoring.score` compares a tracker output
stamped at t with, and what the per-camera 2D scores project."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from core.records import PoseTruth
from core.truth import truth_between


class TruthTimeline:
    """The ground-truth stream at any time t: between two samples, the project's one rule for the truth at t
    (`core.truth.truth_between`, the rule the simulator made the camera frames with); outside the sampled
    span, the nearest end sample up to half a sampling period away, beyond that nobody.

    Args:
        truth: PoseTruth samples (any order), poses (P, J, 3).
    """

    def __init__(self, truth: Sequence[PoseTruth]):
        order = np.argsort([s.t_s for s in truth], kind="stable")
        self.samples = [truth[i] for i in order]
        self.times = np.array([s.t_s for s in self.samples], dtype=np.float64)
        period = float(np.median(np.diff(self.times))) if len(self.times) > 1 else 0.0
        self._edge_s = period / 2 + 1e-9
        self.num_joints = next((np.asarray(s.poses).shape[1] for s in self.samples if len(s.person_ids)), None)

    def _sample(self, i: int) -> PoseTruth:
        s = self.samples[i]
        ids = np.asarray(s.person_ids, dtype=np.int64).reshape(-1)
        return PoseTruth(s.t_s, ids, np.asarray(s.poses, dtype=np.float64).reshape(len(ids), self.num_joints, 3))

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(ids (P,), poses (P, J, 3)) of the people present at time t."""
        n = len(self.times)
        if n == 0:
            return np.zeros(0, dtype=np.int64), np.zeros((0, self.num_joints, 3))
        i = int(np.searchsorted(self.times, t, side="right")) - 1  # times[i] <= t < times[i + 1]
        if i < 0 or i >= n - 1:
            edge = 0 if i < 0 else n - 1
            if abs(self.times[edge] - t) <= self._edge_s:
                return truth_between(None, self._sample(edge), t)
            return np.zeros(0, dtype=np.int64), np.zeros((0, self.num_joints, 3))
        before = self._sample(i)
        if t == self.times[i]:
            return before.person_ids, before.poses
        return truth_between(before, self._sample(i + 1), t)

    @property
    def span(self) -> tuple[float, float]:
        return (float(self.times[0]), float(self.times[-1])) if len(self.times) else (0.0, 0.0)
