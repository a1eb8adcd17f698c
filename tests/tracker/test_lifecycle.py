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


def test_body_and_ghost_rules():
    state = np.array([lc.TENTATIVE, lc.TENTATIVE, lc.LOST])
    # Without a body a tentative target waits; a lost one is found again whatever it has.
    assert lc.on_match(state, np.zeros(3), np.full(3, 5), 1.0, CFG, np.array([False, True, False])).tolist() == [
        lc.TENTATIVE, lc.CONFIRMED, lc.CONFIRMED]
    cfg = TrackerConfig(ghost_min_expected=5.0, ghost_min_seen_ratio=0.3, implausible_after_s=2.0)
    state = np.array([lc.CONFIRMED, lc.CONFIRMED, lc.LOST, lc.CONFIRMED, lc.CONFIRMED, lc.TENTATIVE])
    expected = np.array([6.0, 4.0, 6.0, 6.0, 6.0, 0.0])
    sighted = np.array([1.0, 0.0, 0.0, 2.0, 2.0, 0.0])
    implausible = np.array([np.nan, np.nan, np.nan, np.nan, 8.0, 7.9])
    # Seen in 1/6 of 6 frames: a ghost; too few expected; lost (goes by time); seen 1/3; implausible since 2 s;
    # implausible for 2.1 s.
    ghost = lc.ghosts(expected, sighted, state, implausible, 10.0, cfg)
    assert ghost.tolist() == [True, False, False, False, True, True]
    # A ghost is removed, unless it has been idle long enough to be lost first (then the lost rule removes it).
    last = np.array([10.0, 10.0, 10.0, 10.0, 8.5, 10.0])
    assert lc.on_time(state, last, 10.0, cfg, ghost).tolist() == [
        lc.REMOVED, lc.CONFIRMED, lc.LOST, lc.CONFIRMED, lc.LOST, lc.REMOVED]


def test_codes_map_to_the_shared_enum():
    assert [lc.to_state(c).value for c in (lc.TENTATIVE, lc.CONFIRMED, lc.LOST, lc.REMOVED)] == [
        "tentative", "confirmed", "lost", "removed"]
