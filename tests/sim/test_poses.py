"""Everybody's pose between truth ticks: the simulator's rule, which a recording's reader applies again."""

from __future__ import annotations

import numpy as np
import pytest

from sim.poses import interpolate_many, interpolate_poses
from sim.types import PoseTruth


def test_interpolated_poses_are_linear_between_ticks_and_handle_arrivals():
    before = PoseTruth(0.0, np.array([1, 2]), np.zeros((2, 17, 3)))
    after = PoseTruth(0.01, np.array([2, 3]), np.ones((2, 17, 3)))
    early = interpolate_poses(before, after, 0.002)
    assert early.person_ids.tolist() == [1, 2]
    np.testing.assert_allclose(early.poses[1], 0.2)  # person 2 moved a fifth of the way
    late = interpolate_poses(before, after, 0.008)
    assert late.person_ids.tolist() == [2, 3]
    np.testing.assert_allclose(late.poses[0], 0.8)


def test_interpolating_several_captures_at_once_gives_each_one_bit_for_bit():
    rng = np.random.default_rng(5)
    before = PoseTruth(0.03, np.array([4, 7]), rng.normal(size=(2, 17, 3)))
    after = PoseTruth(0.04, np.array([4, 7]), rng.normal(size=(2, 17, 3)))
    arrival = PoseTruth(0.04, np.array([4, 7, 9]), rng.normal(size=(3, 17, 3)))
    times = [0.0312, 0.0371, 0.04]
    for b, a in ((before, after), (before, arrival), (None, after)):
        for one, many in zip([interpolate_poses(b, a, t) for t in times], interpolate_many(b, a, times)):
            assert one.t_s == many.t_s and one.person_ids.tolist() == many.person_ids.tolist()
            assert one.poses.tobytes() == many.poses.tobytes()


def test_a_tick_time_gives_that_ticks_poses_exactly_and_the_ends_the_nearest_tick():
    rng = np.random.default_rng(2)
    before = PoseTruth(0.07, np.array([1]), rng.normal(size=(1, 17, 3)))
    after = PoseTruth(0.08, np.array([1]), rng.normal(size=(1, 17, 3)))
    # Not before + (after - before) * 1.0, which can differ from `after` in the last bit.
    assert interpolate_poses(before, after, 0.08).poses.tobytes() == after.poses.tobytes()
    assert [p.poses.tobytes() for p in interpolate_many(before, after, [0.075, 0.08])][1] == after.poses.tobytes()
    assert interpolate_poses(None, after, 0.01).poses.tobytes() == after.poses.tobytes()
    assert interpolate_poses(before, None, 0.09).poses.tobytes() == before.poses.tobytes()
    with pytest.raises(ValueError, match="no tick"):
        interpolate_poses(None, None, 0.0)
