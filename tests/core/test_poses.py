"""Everybody's pose between truth ticks as PoseTruth, one capture or many (the rule: tests/core/test_truth.py)."""

from __future__ import annotations

import numpy as np

from core.poses import interpolate_poses, interpolate_ticks
from core.records import PoseTruth


def test_a_capture_at_a_tick_time_gets_that_ticks_poses_exactly():
    rng = np.random.default_rng(2)
    before = PoseTruth(0.07, np.array([1]), rng.normal(size=(1, 17, 3)))
    after = PoseTruth(0.08, np.array([1]), rng.normal(size=(1, 17, 3)))
    at_tick = interpolate_ticks(before, [after], np.array([0, 0]), np.array([0.075, 0.08]))
    assert at_tick[1].poses.tobytes() == after.poses.tobytes()
    assert interpolate_poses(before, after, 0.08).t_s == 0.08


def test_interpolating_the_captures_of_several_ticks_at_once_gives_each_one_bit_for_bit():
    rng = np.random.default_rng(11)
    ids = np.array([3, 5, 8])
    # Ticks 10 ms apart: person 9 arrives at the third, person 3 leaves at the fifth.
    people = [ids, ids.copy(), np.array([3, 5, 8, 9]), np.array([3, 5, 8, 9]), np.array([5, 8, 9])]
    ticks = [PoseTruth(0.01 * (k + 1), p, rng.normal(size=(len(p), 17, 3))) for k, p in enumerate(people)]
    previous = PoseTruth(0.0, ids, rng.normal(size=(3, 17, 3)))
    # Captures strictly between ticks, at a tick's own time, and around the arrival and the departure.
    tick_of = np.array([0, 0, 1, 2, 2, 3, 4, 4, 4])
    times = np.array([0.0013, 0.01, 0.0157, 0.0212, 0.0291, 0.035, 0.0401, 0.0466, 0.05])
    for first in (previous, None):
        chain = [first, *ticks]
        expected = [interpolate_poses(chain[k], chain[k + 1], t) for k, t in zip(tick_of.tolist(), times.tolist())]
        got = interpolate_ticks(first, ticks, tick_of, times)
        assert len(got) == len(expected)
        for one, many in zip(expected, got):
            assert one.t_s == many.t_s and one.person_ids.tolist() == many.person_ids.tolist()
            assert one.poses.tobytes() == many.poses.tobytes()
    assert interpolate_ticks(previous, ticks, np.zeros(0, dtype=np.int64), np.zeros(0)) == []
    # Nobody in the store: nobody at any time.
    empty = [PoseTruth(0.01 * k, np.zeros(0, dtype=np.int64), np.zeros((0, 17, 3))) for k in range(3)]
    nobody = interpolate_ticks(empty[0], empty[1:], np.array([0, 1]), np.array([0.005, 0.017]))
    assert [p.poses.shape for p in nobody] == [(0, 17, 3)] * 2 and [p.t_s for p in nobody] == [0.005, 0.017]
