"""Crowd motion: config checks, hard constraints at every step, arrivals through the entrance, gait numbers."""

import dataclasses

import numpy as np
import pytest

from sim import crowd as cr
from sim import scenario as sc
from sim.crowd import Activity, Crowd, CrowdConfig
from sim.store import StoreGeometry
from tests.reference import store as store_reference


@pytest.mark.parametrize("kwargs,key", [
    (dict(people=-1), "people"),
    (dict(height_range_m=(1.3, 1.9)), "height_range_m"),
    (dict(heights_m=(1.7, 2.5)), r"heights_m\[1\]"),
    (dict(speed_range_m_s=(0.6, 3.0)), "speed_range_m_s"),
    (dict(browse_share=1.5), "browse_share"),
    (dict(stand_s=(5.0, 2.0)), "stand_s"),
    (dict(pace_range=(1.1, 0.9)), "pace_range"),
    (dict(pause_s=(1.0, 5.0)), r"pause_s\[1\]: 5.0 must be in \(0, 4\) s"),
    (dict(handling_hz=(0.0, 1.0)), r"handling_hz\[0\]"),
    (dict(look_rate_hz=float("nan")), "look_rate_hz"),
    (dict(hand_motion_scale=-1.0), "hand_motion_scale"),
    (dict(group_size=0), "group_size"),
])
def test_bad_crowd_settings_name_the_field(kwargs, key):
    with pytest.raises(ValueError, match=key):
        CrowdConfig(**kwargs)


def test_cadence_and_step_length_follow_speed():
    v = np.array([0.6, 1.0, 1.3, 1.6])
    cadence = cr.cadence_steps_s(v, np.full(4, 1.75))
    step = v / cadence
    assert np.all(np.diff(cadence) > 0) and np.all(np.diff(step) > 0)
    # Adult walking (e.g. Grieve 1968): about 1.5-2.2 steps/s and 0.35-0.8 m steps over 0.6-1.6 m/s.
    assert 1.4 < cadence[0] and cadence[-1] < 2.3
    assert 0.35 < step[0] and step[-1] < 0.8


@pytest.mark.parametrize("name", ["store_layout2", "supermarket"])
def test_hard_limits_hold_at_every_step(name):
    scenario = sc.load(name)
    store = StoreGeometry(scenario.store, name=name)
    crowd = Crowd(scenario.crowd, store, np.random.default_rng(2))
    W, D = scenario.store.width_m, scenario.store.depth_m
    for _ in range(300):
        crowd.step()
        p = crowd.pos[crowd.person_id >= 0]
        d = np.linalg.norm(p[:, None] - p[None], axis=-1)
        np.fill_diagonal(d, np.inf)
        assert d.min() >= cr.SEPARATION_M - 1e-9
        assert store_reference.obstacle_distance(store, p).min() >= cr.SHELF_CLEARANCE_M - 1e-9
        inside = [not (a.in_door or a.leaving) for a, pid in zip(crowd.agents, crowd.person_id) if pid >= 0]
        q = p[inside]
        assert np.all((q >= cr.WALL_CLEARANCE_M - 1e-9) & (q <= np.array([W, D]) - cr.WALL_CLEARANCE_M + 1e-9))


def test_people_arrive_through_the_entrance_one_by_one():
    scenario = sc.load("store_layout2")
    config = dataclasses.replace(scenario.crowd, start_inside=False, mean_arrival_gap_s=2.0)
    store = StoreGeometry(scenario.store)
    crowd = Crowd(config, store, np.random.default_rng(0))
    assert np.all(crowd.person_id < 0)
    first_seen = {}
    for _ in range(600):
        before = set(crowd.person_id[crowd.person_id >= 0].tolist())
        crowd.step()
        for s, pid in enumerate(crowd.person_id.tolist()):
            if pid >= 0 and pid not in before and pid not in first_seen:
                first_seen[pid] = crowd.pos[s].copy()
    assert len(first_seen) >= 12  # a newcomer waits while someone stands in the doorway
    for p in first_seen.values():
        assert np.linalg.norm(p - store.entrance.outside) < 0.2  # m, appeared at the door


def test_a_crowd_in_a_store_with_shelves_walks_stands_and_browses():
    scenario = sc.load("store_layout2")
    crowd = Crowd(scenario.crowd, StoreGeometry(scenario.store), np.random.default_rng(4))
    seen = np.zeros(len(Activity))
    for _ in range(600):
        crowd.step()
        acts = crowd.activities()[crowd.person_id >= 0]
        seen += np.bincount(acts, minlength=len(Activity))
    share = seen / seen.sum()
    assert share[Activity.WALK] > 0.1 and share[Activity.STAND] > 0.05 and share[Activity.BROWSE] > 0.1
