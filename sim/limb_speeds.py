"""How fast wrists, ankles and hips move, over one camera frame and over one second, for standing and walking
people: the figures `crossview world-stats` compares with real actors (Shelf, 25 fps: standing people's wrists
at a median 0.33 m/s frame to frame and 0.14 m/s over one second)."""

from __future__ import annotations

from collections import deque

import numpy as np

from core.records import PoseTruth
from core.types import COCO17

# The frame interval of the real figures (Shelf and Campus run at 25 fps), and the longer window, seconds.
FRAME_S = 0.04
WINDOW_S = 1.0
# The joints measured, both sides pooled.
LIMBS = {"wrist": ("left_wrist", "right_wrist"), "ankle": ("left_ankle", "right_ankle"),
         "hip": ("left_hip", "right_hip")}
_JOINTS = np.array([COCO17.index(j) for pair in LIMBS.values() for j in pair])


class LimbSpeeds:
    """Collects speeds |p(t) - p(t - span)| / span of each limb joint of everybody present at both ends.

    A span counts as standing when the person was not walking (`Activity.WALK`) at either end, as walking
    when they were walking at both; a span across a change counts as neither.
    """

    def __init__(self, rate_hz: float):
        """Args: rate_hz: the rate `add` is called at; FRAME_S and WINDOW_S must be whole numbers of its ticks.

        Raises:
            ValueError: rate_hz does not divide FRAME_S or WINDOW_S into whole ticks.
        """
        self.rate_hz = rate_hz
        self.lags = {}
        for span, seconds in (("frame", FRAME_S), ("1s", WINDOW_S)):
            lag = round(seconds * rate_hz)
            if lag < 1 or abs(lag - seconds * rate_hz) > 1e-9:
                raise ValueError(f"rate_hz: {rate_hz} must make {seconds} s a whole number of ticks")
            self.lags[span] = lag
        self._ring: deque = deque(maxlen=max(self.lags.values()) + 1)
        self._speeds = {(state, span): [] for state in ("standing", "walking") for span in self.lags}

    def add(self, truth: PoseTruth, walking: np.ndarray):
        """One tick (1 / rate_hz after the previous one).

        Args:
            truth: everybody's keypoints at the tick.
            walking: (P,) bool, whether each person of `truth.person_ids` is walking.
        """
        points = truth.poses[:, _JOINTS]
        self._ring.append((truth.person_ids, points, np.asarray(walking, dtype=bool)))
        for span, lag in self.lags.items():
            if len(self._ring) <= lag:
                continue
            ids0, points0, walking0 = self._ring[-1 - lag]
            _, i0, i1 = np.intersect1d(ids0, truth.person_ids, assume_unique=True, return_indices=True)
            if not len(i0):
                continue
            speed = np.linalg.norm(points[i1] - points0[i0], axis=-1) * (self.rate_hz / lag)  # (n, 6)
            w0, w1 = walking0[i0], walking[i1]
            self._speeds["standing", span].append(speed[~w0 & ~w1])
            self._speeds["walking", span].append(speed[w0 & w1])

    def summary(self) -> dict:
        """Flat dict: per limb, state and span the median and 95th percentile speed in m/s (None without
        samples), keyed like `wrist_speed_standing_frame_median_m_s`, plus the spans in seconds."""
        out: dict = {"limb_speed_frame_s": FRAME_S, "limb_speed_window_s": WINDOW_S}
        for (state, span), rows in self._speeds.items():
            speeds = np.concatenate(rows) if rows else np.zeros((0, len(_JOINTS)))
            for k, limb in enumerate(LIMBS):
                values = speeds[:, 2 * k:2 * k + 2].ravel()
                for stat, q in (("median", 50), ("p95", 95)):
                    out[f"{limb}_speed_{state}_{span}_{stat}_m_s"] = (
                        float(np.percentile(values, q)) if values.size else None)
        return out
