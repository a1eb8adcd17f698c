"""Everybody's true pose between truth ticks as `PoseTruth`: the rule of `core.truth` for one capture time
(`interpolate_poses`), and for the captures of many ticks at once (`interpolate_ticks`, the same bits).
"""

from __future__ import annotations

import math

import numpy as np

from core.jit import jit
from core.records import PoseTruth
from core.truth import truth_between


def interpolate_poses(before: PoseTruth | None, after: PoseTruth | None, t_s: float) -> PoseTruth:
    """Everybody's pose at `t_s`, with `before.t_s < t_s <= after.t_s` (`core.truth.truth_between`).

    Args:
        before: the truth at the earlier tick (None: only `after` is known).
        after: the truth at the later tick (None: only `before` is known).
        t_s: the time wanted.
    """
    return PoseTruth(float(t_s), *truth_between(before, after, t_s))


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
    tick = np.asarray(tick_of, dtype=np.int64) + (len(chain) - len(ticks))  # (N,) index in `chain`
    times = np.asarray(times_s, dtype=np.float64)
    time_list = times.tolist()
    t_chain = np.array([p.t_s for p in chain])
    sizes = np.array([len(p.person_ids) for p in chain], dtype=np.int64)
    # The ticks asked for with the same people as the tick before (and later than it): linear in between.
    same = np.zeros(len(chain), dtype=bool)
    for k in set(tick.tolist()) - {0}:
        before, after = chain[k - 1], chain[k]
        same[k] = after.t_s > before.t_s and (
            before.person_ids is after.person_ids or np.array_equal(before.person_ids, after.person_ids))
    linear = same[tick] & (times < t_chain[tick])
    out: list = [None] * len(time_list)
    for i in np.nonzero(~linear)[0].tolist():
        k = int(tick[i])
        out[i] = interpolate_poses(chain[k - 1] if k else None, chain[k], time_list[i])
    if not linear.any():
        return out
    # The linear captures in one compiled pass over the stack of every tick's people (rows of J * 3).
    index = np.nonzero(linear)[0]
    k = tick[index]
    a = (times[index] - t_chain[k - 1]) / (t_chain[k] - t_chain[k - 1])  # `interpolate_poses`'s weight
    counts = sizes[k]
    starts = np.cumsum(sizes) - sizes
    stacked = np.concatenate([p.poses for p in chain]).astype(np.float64, copy=False)
    poses = np.empty((int(counts.sum()), *stacked.shape[1:]))
    width = math.prod(stacked.shape[1:])  # (not -1, which fails for nobody)
    _lerp_rows(stacked.reshape(len(stacked), width), starts[k - 1], starts[k], counts, a,
               poses.reshape(len(poses), width))
    end = 0
    for i, k_i, n in zip(index.tolist(), k.tolist(), counts.tolist()):
        out[i] = PoseTruth(time_list[i], chain[k_i].person_ids, poses[end:end + n])
        end += n
    return out


@jit
def _lerp_rows(rows, before, after, counts, a, out):
    """Per capture i, the next counts[i] rows of out (M, W): rows[before[i] + r] + (rows[after[i] + r] -
    rows[before[i] + r]) * a[i] for r < counts[i]. The arithmetic of `interpolate_poses`, element by element
    (no fused multiply-add: numba contracts none without fastmath)."""
    o = 0
    for i in range(counts.shape[0]):
        w = a[i]
        for r in range(counts[i]):
            b, f = before[i] + r, after[i] + r
            for j in range(out.shape[1]):
                out[o, j] = rows[b, j] + (rows[f, j] - rows[b, j]) * w
            o += 1
