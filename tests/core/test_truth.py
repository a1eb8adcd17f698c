"""The one truth-at-t rule: linear between ticks, arrivals and departures at the half, a tick's own time exact."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pytest

from core.truth import truth_between


class PoseTruth(NamedTuple):  # (what `core.truth.Tick` asks of a tick: sim's PoseTruth has these fields)
    t_s: float
    person_ids: np.ndarray
    poses: np.ndarray


def test_the_truth_is_linear_between_ticks_and_people_at_one_tick_are_there_in_its_half():
    before = PoseTruth(0.0, np.array([1, 2]), np.zeros((2, 17, 3)))
    after = PoseTruth(0.01, np.array([2, 3]), np.ones((2, 17, 3)))
    ids, poses = truth_between(before, after, 0.002)
    assert ids.tolist() == [1, 2]  # person 3 arrives at the second tick: not yet
    np.testing.assert_allclose(poses[1], 0.2)  # m: person 2 moved a fifth of the way
    ids, poses = truth_between(before, after, 0.008)
    assert ids.tolist() == [2, 3]  # person 1 left after the first tick: gone
    np.testing.assert_allclose(poses[0], 0.8)  # m


def test_a_tick_time_gives_that_ticks_poses_exactly_and_one_tick_known_gives_it():
    rng = np.random.default_rng(2)
    before = PoseTruth(0.07, np.array([1]), rng.normal(size=(1, 17, 3)))
    after = PoseTruth(0.08, np.array([1]), rng.normal(size=(1, 17, 3)))
    # Not before + (after - before) * 1.0, which can differ from `after` in the last bit.
    assert truth_between(before, after, 0.08)[1].tobytes() == after.poses.tobytes()
    assert truth_between(None, after, 0.01)[1].tobytes() == after.poses.tobytes()
    assert truth_between(before, None, 0.09)[1].tobytes() == before.poses.tobytes()
    with pytest.raises(ValueError, match="no tick"):
        truth_between(None, None, 0.0)
