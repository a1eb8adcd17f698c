"""What every reader of a tracker's output shares: the rule for "the tracks at time t", and target ids that carry
a namespace (the zone whose tracker made them).

The tracks at t: the latest output stamped at or before t (on equal stamps the later one delivered), as long as
it is at most `OUTPUT_MAX_AGE_S` old; else no target. Scoring reads a tracks file on its grid by this rule
(`crossview.scoring.score`), and the zones' merger (`tracker.handover`) reads each zone's outputs by it. (The
arrays of one output, in one shape whatever the tracker emitted: `tracker.types.target_arrays`.)

Ids: a tracker numbers its targets from 0. A zone's tracker is one of several in a store, so its ids go out
namespaced: `namespaced(zone, local)` keeps the local id in the low `LOCAL_ID_BITS` bits and zone + 1 above them
(namespace 0 is a tracker that is not a zone's: its ids are unchanged). The ids stay int64, as a tracks file holds.
"""

from __future__ import annotations

import numpy as np

OUTPUT_MAX_AGE_S = 1.0
"""A tracker output older than this at time t no longer stands for the tracker's belief at t, seconds."""

LOCAL_ID_BITS = 40
"""Bits of a namespaced id that hold the local id (2**40 targets per zone; 2**23 - 1 zones fit in an int64)."""


def stands(stamp_s: float, t: float) -> bool:
    """Whether an output stamped `stamp_s` (at or before t) still gives the tracks at t."""
    return t - stamp_s <= OUTPUT_MAX_AGE_S


class LatestPerTick:
    """The rule on a grid of times, in one pass over outputs in delivery order: `offer` each output, then
    `at(k)` for k = 0, 1, ... in order gives the output that stands for the tracks at ticks[k] (None: none).

    An output belongs to the first tick at or after its stamp; of those of one tick the latest stamp wins, on
    equal stamps the later one offered (delivered). Outputs stamped before `ticks[0]` are not kept."""

    def __init__(self, ticks: np.ndarray):
        self.ticks = np.asarray(ticks, dtype=np.float64)
        self._latest: dict[int, tuple[float, object]] = {}
        self._chosen: tuple[float, object] | None = None

    def offer(self, stamp_s: float, output) -> None:
        k = int(np.searchsorted(self.ticks, stamp_s, side="left"))
        if k < len(self.ticks) and stamp_s >= self.ticks[0] and (k not in self._latest
                                                                 or stamp_s >= self._latest[k][0]):
            self._latest[k] = (stamp_s, output)

    def latest(self, k: int):
        """The latest output stamped at or before ticks[k], however old (None before the first); call with k
        increasing."""
        self._chosen = self._latest.pop(k, self._chosen)
        return None if self._chosen is None else self._chosen[1]

    def at(self, k: int):
        """The output that gives the tracks at ticks[k]: `latest(k)` if it `stands`, else None."""
        chosen = self.latest(k)
        return chosen if chosen is not None and stands(self._chosen[0], float(self.ticks[k])) else None


def namespaced(zone: int, local_ids):
    """Ids of zone `zone`'s tracker (0, 1, ...) as store-wide ids (int or int64 array, as given)."""
    if not 0 <= zone < 2 ** (63 - LOCAL_ID_BITS) - 1:
        raise ValueError(f"zone {zone} out of range")
    ids = np.asarray(local_ids, dtype=np.int64)
    if np.any(ids < 0) or np.any(ids >= 2 ** LOCAL_ID_BITS):
        raise ValueError(f"local ids must lie in [0, 2**{LOCAL_ID_BITS})")
    out = ((zone + 1) << LOCAL_ID_BITS) | ids
    return int(out) if out.ndim == 0 else out


def namespace_of(ids):
    """The zone of namespaced ids (-1: an id of a tracker that is not a zone's)."""
    out = (np.asarray(ids, dtype=np.int64) >> LOCAL_ID_BITS) - 1
    return int(out) if out.ndim == 0 else out


def local_of(ids):
    """The local id of namespaced ids (the id itself for one that is not a zone's)."""
    out = np.asarray(ids, dtype=np.int64) & ((1 << LOCAL_ID_BITS) - 1)
    return int(out) if out.ndim == 0 else out
