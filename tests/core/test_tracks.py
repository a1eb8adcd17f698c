"""The tracks at t (`core.tracks`) against a brute-force reading of the rule, and namespaced ids."""

from __future__ import annotations

import numpy as np
import pytest

from core import tracks


def _brute(stamps: list[float], ticks: np.ndarray, k: int):
    """The rule read literally: of the outputs stamped in [ticks[0], ticks[k]], the latest stamp, on equal stamps
    the later delivered (index); None when there is none."""
    best = None
    for i, s in enumerate(stamps):
        if ticks[0] <= s <= ticks[k] and (best is None or s >= stamps[best]):
            best = i
    return best


@pytest.mark.parametrize("seed", range(5))
def test_latest_per_tick_is_the_rule_read_literally(seed):
    rng = np.random.default_rng(seed)
    ticks = 1.0 + np.arange(40) / 10
    stamps = np.round(rng.uniform(0.5, 6.5, 120), 2).tolist()  # (rounded: equal stamps happen, some before t_0)
    stamps += [float(ticks[3])] * 3  # (stamps exactly on a tick)
    grid = tracks.LatestPerTick(ticks)
    for i, s in enumerate(stamps):
        grid.offer(s, i)
    for k in range(len(ticks)):
        want = _brute(stamps, ticks, k)
        got = grid.latest(k)
        assert got == want
        standing = grid.at(k)
        assert standing == (want if want is not None and ticks[k] - stamps[want] <= tracks.OUTPUT_MAX_AGE_S else None)


def test_an_output_older_than_the_age_limit_no_longer_stands():
    grid = tracks.LatestPerTick(np.array([0.0, 0.5, 1.0, 1.5, 2.0]))
    grid.offer(0.2, "a")
    assert [grid.at(k) for k in range(5)] == [None, "a", "a", None, None]
    assert tracks.stands(0.2, 1.2) and not tracks.stands(0.2, 1.21)


def test_namespaced_ids_keep_zone_and_local_id_and_leave_plain_ids_alone():
    local = np.array([0, 1, 7, 2 ** 40 - 1])
    for zone in (0, 1, 5, 1000):
        ids = tracks.namespaced(zone, local)
        assert ids.dtype == np.int64 and (ids > 0).all()
        assert (tracks.namespace_of(ids) == zone).all() and (tracks.local_of(ids) == local).all()
    assert len({tracks.namespaced(z, 3) for z in range(4)}) == 4  # (one local id, a distinct global id per zone)
    assert tracks.namespace_of(12) == -1 and tracks.local_of(12) == 12
    with pytest.raises(ValueError, match="local ids"):
        tracks.namespaced(0, [2 ** 40])
    with pytest.raises(ValueError, match="zone -1"):
        tracks.namespaced(-1, [0])
