"""The `border` scenario does what it claims (scenarios/border.toml): with the store cut into 2 zones, people
spend much of their time inside the zones' overlap, most cross the border, and they cross it in groups.

Measured on the crowd's own truth (the pelvis positions the simulation poses the bodies from, drawn from the
simulation's own random stream), 60 s of seeds 0 and 1; the thresholds are the scenario's promises, each well
above what the hypermarket gives (seed 0, 20 s: 2.6 % of person-time in an overlap, 17 % of people crossing).
"""

import dataclasses

import numpy as np
import pytest

from crossview import zoned
from sim import scenario as sc
from sim.cameras import build_rig
from sim.crowd import STEP_S, Crowd
from sim.rng import child_rng
from sim.store import StoreGeometry

OVERLAP_M = 2.0
GROUP = 3  # the border scenario's group size: body slots 3k..3k+2 (the measure is the same without groups)
GROUP_NEAR_M = 2.0  # a crossing is made together when another of the group is this close at that moment
TOGETHER = 0.62  # the least share of crossings made together that the scenario promises


def _measure(scenario, seed: int, duration_s: float = 60.0) -> tuple[float, float, float, float]:
    """(share of person-time inside an overlap of 2 zones, share of people who cross the border, crossings per
    person, share of crossings made with another of the person's group (`GROUP` consecutive body slots)
    within `GROUP_NEAR_M`)."""
    store = StoreGeometry(scenario.store, name=scenario.name)
    zones = zoned.cut(build_rig(scenario, child_rng(seed, "cameras")), store.boxes, "2", OVERLAP_M)
    crowd = Crowd(scenario.crowd, store, child_rng(seed, "crowd"))
    in_overlap = person_steps = together = 0
    last: dict[int, int] = {}
    crossings: dict[int, list[tuple[float, int]]] = {}
    for _ in range(round(duration_s / STEP_S)):
        crowd.step()
        here = np.flatnonzero(crowd.person_id >= 0)
        ids, pos = crowd.person_id[here].tolist(), crowd.pos[here]
        regions = np.stack([(pos[:, 0] >= z.region[0]) & (pos[:, 0] <= z.region[2]) & (pos[:, 1] >= z.region[1])
                            & (pos[:, 1] <= z.region[3]) for z in zones])
        in_overlap += int(np.count_nonzero(regions.sum(axis=0) >= 2))
        person_steps += len(ids)
        owner = np.argmax(np.stack([z.owns(pos) for z in zones]), axis=0).tolist()
        for pid, zone in zip(ids, owner):
            crossings.setdefault(pid, [])
            if pid in last and last[pid] != zone:
                crossings[pid].append((crowd.time_s, zone))
                k = ids.index(pid)
                mates = [j for j in range(len(ids)) if j != k and here[j] // GROUP == here[k] // GROUP]
                near = np.linalg.norm(pos[mates] - pos[k], axis=1)
                together += bool(np.any(near <= GROUP_NEAR_M))
            last[pid] = zone
    counts = [len(c) for c in crossings.values()]
    return (in_overlap / person_steps, float(np.mean([c > 0 for c in counts])), float(np.mean(counts)),
            together / max(1, sum(counts)))


@pytest.mark.parametrize("seed", [0, 1])
def test_border_people_stand_in_the_overlap_and_cross_in_groups(seed):
    scenario = sc.load("border")
    assert scenario.crowd.group_size == 3
    share, crossed, per_person, together = _measure(scenario, seed)
    # The 2 m band is 12.5 % of the 16 m floor: people are in it far more often than the floor's share.
    assert share > 0.2, share
    assert crossed >= 0.85 and per_person >= 1.5, (crossed, per_person)
    assert together >= TOGETHER, together


def test_the_group_measure_can_fail():
    """The same store with everybody going alone: fewer crossings are made beside a body-slot neighbour (seeds
    0 to 3 measured 0.35, 0.58, 0.30, 0.40 alone; 0.72, 0.66, 0.85, 0.70 in groups of three)."""
    scenario = sc.load("border")
    alone = dataclasses.replace(scenario, crowd=dataclasses.replace(scenario.crowd, group_size=1))
    assert _measure(alone, 0)[3] < TOGETHER
