"""Everybody's true pose between two truth ticks: the one rule the simulator uses for the poses at a
camera's capture time and a recording's reader uses to derive them again from the stored ticks.

The rule: at a tick's own time, that tick's poses exactly; strictly between two ticks, linear in time
for the people present at both, and someone present at only one tick is taken from it when the time lies
in that tick's half of the interval; before the first tick or after the last, the nearest tick's poses.
"""

from __future__ import annotations

import numpy as np

from sim.types import PoseTruth
from tracker.jit import jit


def interpolate_poses(before: PoseTruth | None, after: PoseTruth | None, t_s: float) -> PoseTruth:
    """Everybody's pose at `t_s`, with `before.t_s < t_s <= after.t_s` (see the module docstring).

    Args:
        before: the truth at the earlier tick (None: only `after` is known).
        after: the truth at the later tick (None: only `before` is known).
        t_s: the time wanted.
    """
    if after is None:
        if before is None:
            raise ValueError("interpolate_poses: no tick given")
        return PoseTruth(float(t_s), before.person_ids, before.poses)
    if before is None or after.t_s <= before.t_s or t_s >= after.t_s:
        return PoseTruth(float(t_s), after.person_ids, after.poses)
    a = (t_s - before.t_s) / (after.t_s - before.t_s)
    if np.array_equal(before.person_ids, after.person_ids):
        return PoseTruth(float(t_s), after.person_ids, before.poses + (after.poses - before.poses) * a)
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
    return PoseTruth(float(t_s), ids, poses)


def interpolate_many(before: PoseTruth | None, after: PoseTruth, times_s: list[float]) -> list[PoseTruth]:
    """`interpolate_poses` at several times between the same two ticks (the same poses, bit for bit: the
    same arithmetic per element, with the difference of the two ticks taken once)."""
    if not times_s:
        return []
    if (before is None or after.t_s <= before.t_s or max(times_s) >= after.t_s
            or not (before.person_ids is after.person_ids or np.array_equal(before.person_ids, after.person_ids))):
        return [interpolate_poses(before, after, t_s) for t_s in times_s]
    t0, span = before.t_s, after.t_s - before.t_s
    a = np.array([(t_s - t0) / span for t_s in times_s]).reshape(-1, *(1,) * after.poses.ndim)
    poses = before.poses + (after.poses - before.poses) * a
    return [PoseTruth(float(t_s), after.person_ids, p) for t_s, p in zip(times_s, poses)]


def interpolate_ticks(previous: PoseTruth | None, ticks: list[PoseTruth], tick_of: np.ndarray,
                      times_s: np.ndarray) -> list[PoseTruth]:
    """`interpolate_poses` for the captures of several consecutive ticks at once: capture i at `times_s[i]`,
    between `ticks[tick_of[i]]` and the tick before it (`previous` for the first). The same poses, bit for
    bit: where the same people are present at both ticks, the same arithmetic per element in one compiled
    pass for all those captures together; every other capture is `interpolate_poses`'s own.

    Args:
        previous: the tick before `ticks[0]` (None: there is none).
        ticks: consecutive truth ticks, in time order.
        tick_of: (N,) int, per capture the index in `ticks` of the first tick at or after its time.
        times_s: (N,) the captures' times, seconds.

    Returns:
        N PoseTruth, in the captures' order (the linear ones' poses are views of one (sum P, J, 3) array).
    """
    chain = ticks if previous is None else [previous, *ticks]
    shift = len(chain) - len(ticks)  # the index in `chain` of ticks[k] is k + shift
    tick_list, time_list = np.asarray(tick_of).tolist(), np.asarray(times_s, dtype=np.float64).tolist()
    same: dict[int, bool] = {}  # per tick of `chain` asked for: the same people as at the tick before
    out: list = [None] * len(time_list)
    linear = []  # the captures strictly between two ticks with the same people
    for i, (k, t_s) in enumerate(zip(tick_list, time_list)):
        k += shift
        before, after = chain[k - 1] if k else None, chain[k]
        if k not in same:
            same[k] = before is not None and after.t_s > before.t_s and (
                before.person_ids is after.person_ids or np.array_equal(before.person_ids, after.person_ids))
        if same[k] and t_s < after.t_s:
            linear.append(i)
        else:
            out[i] = interpolate_poses(before, after, t_s)
    if not linear:
        return out
    # Every tick's people stacked, one row of J * 3 per person; per row of the output, the rows of its two
    # ticks and its weight, for one compiled pass (numpy took five over fresh temporaries, page faults and all).
    sizes = np.array([len(p.person_ids) for p in chain], dtype=np.int64)
    starts = np.cumsum(sizes) - sizes
    stacked = np.concatenate([p.poses for p in chain]).astype(np.float64, copy=False)
    rows = stacked.reshape(len(stacked), int(np.prod(stacked.shape[1:])))
    ka = np.array(tick_list)[linear] + shift
    counts = sizes[ka]
    local = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    t_chain = np.array([p.t_s for p in chain])
    a = (np.array(time_list)[linear] - t_chain[ka - 1]) / (t_chain[ka] - t_chain[ka - 1])
    poses = np.empty((len(local), rows.shape[1]))
    _lerp_rows(rows, np.repeat(starts[ka - 1], counts) + local, np.repeat(starts[ka], counts) + local,
               np.repeat(a, counts), poses)
    poses = poses.reshape(-1, *stacked.shape[1:])
    for i, end, n in zip(linear, np.cumsum(counts).tolist(), counts.tolist()):
        out[i] = PoseTruth(time_list[i], chain[tick_list[i] + shift].person_ids, poses[end - n:end])
    return out


@jit
def _lerp_rows(rows, before, after, a, out):
    """out[i] = rows[before[i]] + (rows[after[i]] - rows[before[i]]) * a[i] per row i of out (M, W): the
    arithmetic of `interpolate_poses`, element by element (no fused multiply-add: numba contracts none
    without fastmath)."""
    for i in range(out.shape[0]):
        b, f, w = before[i], after[i], a[i]
        for j in range(out.shape[1]):
            out[i, j] = rows[b, j] + (rows[f, j] - rows[b, j]) * w
