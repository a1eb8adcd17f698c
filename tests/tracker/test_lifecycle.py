"""Lifecycle transitions, timed in seconds."""

import numpy as np

from tracker import lifecycle as lc
from tracker.config import TrackerConfig

CFG = TrackerConfig(confirm_min_updates=3, confirm_min_age_s=0.1, tentative_timeout_s=0.5, lost_after_s=1.0,
                    remove_after_s=3.0)


def test_time_transitions():
    state = np.array([lc.TENTATIVE, lc.TENTATIVE, lc.CONFIRMED, lc.CONFIRMED, lc.LOST, lc.LOST])
    last = np.array([9.6, 9.4, 9.1, 8.9, 7.5, 6.9])
    new = lc.on_time(state, last, 10.0, CFG)
    # Tentative idle 0.4 s stays; 0.6 s is removed. Confirmed idle 0.9 s stays; 1.1 s is lost.
    # Lost idle 2.5 s stays lost; 3.1 s is removed.
    assert new.tolist() == [lc.TENTATIVE, lc.REMOVED, lc.CONFIRMED, lc.LOST, lc.LOST, lc.REMOVED]


def test_confirmed_long_idle_goes_straight_to_removed():
    assert lc.on_time(np.array([lc.CONFIRMED]), np.array([0.0]), 10.0, CFG).tolist() == [lc.REMOVED]


def test_match_transitions():
    state = np.array([lc.TENTATIVE, lc.TENTATIVE, lc.TENTATIVE, lc.LOST, lc.CONFIRMED])
    born = np.array([0.0, 0.0, 0.95, 0.0, 0.0])
    updates = np.array([2, 3, 5, 1, 9])
    new = lc.on_match(state, born, updates, 1.0, CFG)
    # Too few updates; enough; too young; lost found again; confirmed stays.
    assert new.tolist() == [lc.TENTATIVE, lc.CONFIRMED, lc.TENTATIVE, lc.CONFIRMED, lc.CONFIRMED]


def test_codes_map_to_the_shared_enum():
    assert [lc.to_state(c).value for c in (lc.TENTATIVE, lc.CONFIRMED, lc.LOST, lc.REMOVED)] == [
        "tentative", "confirmed", "lost", "removed"]
