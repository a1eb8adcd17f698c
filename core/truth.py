"""Everybody's true pose at a time between two truth ticks: the one rule for "the truth at t", which the
simulator uses for the poses at a camera's capture time, a recording's reader to derive them again from the
stored ticks, and scoring for the truth it compares a tracker's output with.

The rule: at a tick's own time, that tick's poses exactly; strictly between two ticks, linear in time for
the people present at both, and someone present at only one tick is taken from it when the time lies in
that tick's half of the interval; with only one tick known (before the first tick, after the last), that
tick's poses.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

TRUTH_RATE_HZ = 100.0
"""Truth ticks per second: the simulator writes everybody's pose at every tick (tick k at k / TRUTH_RATE_HZ)."""


def tick_of(times_s: np.ndarray) -> np.ndarray:
    """(N,) int64 the tick whose captures include a capture at each time: the first tick at or after it (a
    capture up to a tick's time sees that tick's bodies, `sim.simulate`)."""
    k = np.ceil(np.asarray(times_s, dtype=np.float64) * TRUTH_RATE_HZ)
    k -= (k - 1) / TRUTH_RATE_HZ >= times_s  # (the product rounded up past a tick's own time)
    k += k / TRUTH_RATE_HZ < times_s
    return k.astype(np.int64)


class Tick(Protocol):
    """A truth tick (`core.records.PoseTruth`): `t_s` seconds, `person_ids` (P,) int64, `poses` (P, J, 3) metres."""

    t_s: float
    person_ids: np.ndarray
    poses: np.ndarray


def truth_between(before: Tick | None, after: Tick | None, t_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Everybody's pose at `t_s`, with `before.t_s < t_s <= after.t_s` (see the module docstring): (ids (P,),
    poses (P, J, 3)); at a tick's time, or with one tick known, that tick's own arrays.

    Args:
        before: the truth at the earlier tick (None: only `after` is known).
        after: the truth at the later tick (None: only `before` is known).
        t_s: the time wanted.
    """
    if after is None:
        if before is None:
            raise ValueError("truth_between: no tick given")
        return before.person_ids, before.poses
    if before is None or after.t_s <= before.t_s or t_s >= after.t_s:
        return after.person_ids, after.poses
    a = (t_s - before.t_s) / (after.t_s - before.t_s)
    if np.array_equal(before.person_ids, after.person_ids):
        return after.person_ids, before.poses + (after.poses - before.poses) * a
    ids = np.union1d(before.person_ids, after.person_ids)
    in_before = np.isin(ids, before.person_ids)
    in_after = np.isin(ids, after.person_ids)
    keep = (in_before & in_after) | (in_after & (a > 0.5)) | (in_before & (a <= 0.5))
    ids = ids[keep]
    poses = np.empty((ids.size, *after.poses.shape[1:]))
    for i, pid in enumerate(ids):
        b = before.poses[np.searchsorted(before.person_ids, pid)] if pid in before.person_ids else None
        f = after.poses[np.searchsorted(after.person_ids, pid)] if pid in after.person_ids else None
        poses[i] = b + (f - b) * a if b is not None and f is not None else (f if f is not None else b)
    return ids, poses
