"""The switch list of a zoned run by place and cause (`crossview.scoring.switches`): on tracks made by hand
whose every switch has a known cause, the list holds exactly py-motmetrics' own SWITCH events (computed here on
its own from the same roots), each placed and explained as made."""

import motmetrics as mm
import numpy as np

from core import tracks
from core.records import PoseTruth
from crossview.scoring import score
from crossview.scoring import switches as sw
from tracker.types import Target, TrackerOutput
from tracker.zones import Zone

ZONES = [Zone(0, (0.0, 0.0, 8.0, 8.0), (0.0, 0.0, 9.0, 8.0), (), (False, True)),
         Zone(1, (8.0, 0.0, 16.0, 8.0), (7.0, 0.0, 16.0, 8.0), (), (True, True))]
TIMES = np.round(np.arange(0.0, 10.0, 0.1), 10)


def _where(pid: int, t: float) -> tuple[float, float]:
    """Floor position of person pid at t: 1 walks right across the border (crossing it at t = 5), 2 stands in
    zone 0, 3 walks left across it (at t = 5), 4 goes right across it and back (at t = 2.5 and 7.5)."""
    if pid == 1:
        return 2.0 + 1.2 * t, 2.0
    if pid == 2:
        return 3.0, 6.0
    if pid == 3:
        return 14.0 - 1.2 * t, 4.0
    return (6.0 + 0.8 * t if t < 5 else 10.0 - 0.8 * (t - 5)), 7.0


def _target_id(pid: int, t: float) -> int:
    """The global ids a merger could have given: a new id on each crossing (1; 4 the first time), a zone tracker's
    own switch (2, at t = 5), a person handed the id another person had (3 takes 2's first id), and back to the
    earlier id (4's second crossing)."""
    x, _ = _where(pid, t)
    if pid == 1:
        return tracks.namespaced(0, 0) if x < 8 else tracks.namespaced(1, 0)
    if pid == 2:
        return tracks.namespaced(0, 1) if t < 5 else tracks.namespaced(0, 2)
    if pid == 3:
        return tracks.namespaced(1, 1) if x >= 8 else tracks.namespaced(0, 1)
    return tracks.namespaced(0, 3) if x < 8 else tracks.namespaced(1, 2)


def _pose(x: float, y: float) -> np.ndarray:
    pose = np.zeros((17, 3))
    pose[:, :2] = x, y
    pose[:, 2] = np.linspace(1.7, 0.05, 17)
    return pose


def _made():
    people = (1, 2, 3, 4)
    truth = [PoseTruth(float(t), np.array(people), np.stack([_pose(*_where(p, t)) for p in people]))
             for t in np.round(np.arange(0.0, 10.0, 0.01), 10)]
    outputs = [TrackerOutput(float(t), "c", [Target(_target_id(p, t), _pose(*_where(p, t)), float(t))
                                             for p in people], np.zeros(0, np.int64)) for t in TIMES]
    return truth, outputs


def test_every_switch_is_py_motmetrics_own_placed_and_explained():
    truth, outputs = _made()
    report = score(truth, outputs, zones=ZONES)
    listed = report.switches_by_place
    # py-motmetrics on its own, at the scorer's instants: the same switches, person and new target.
    acc = mm.MOTAccumulator(auto_id=True)
    for t in TIMES:
        people = [1, 2, 3, 4]
        xy = np.array([_where(p, t) for p in people])
        acc.update(people, [_target_id(p, t) for p in people], mm.distances.norm2squared_matrix(xy, xy, max_d2=1.0))
    events = acc.mot_events
    own = events[events["Type"] == "SWITCH"]
    assert sorted(zip(own["OId"].astype(int), own["HId"].astype(int))) == sorted(
        (s.person_id, s.to_target) for s in listed)
    assert len(listed) == report.id_switches == 5
    by = {(s.person_id, round(s.t_s, 1)): s for s in listed}
    crossing = by[(1, 5.0)]
    assert crossing.why == sw.NEW_ID and (crossing.from_zone, crossing.to_zone) == (0, 1)
    assert crossing.in_overlap and crossing.border_m < 0.01 and crossing.from_target == tracks.namespaced(0, 0)
    own_switch = by[(2, 5.0)]
    assert own_switch.why == sw.TRACKER and own_switch.from_zone == own_switch.to_zone == 0
    assert not own_switch.in_overlap and own_switch.border_m == 5.0
    assert [s.why for s in listed if s.person_id == 3] == [sw.ANOTHERS_ID]
    assert [s.why for s in listed if s.person_id == 4] == [sw.NEW_ID, sw.EARLIER_ID]
    assert [(s.from_zone, s.to_zone) for s in listed if s.person_id == 4] == [(0, 1), (1, 0)]
    # The JSON and the terminal carry the list; a run that is not zoned has none.
    assert report.to_json(scenario=None, seed=None, num_cameras=None, num_people=None,
                          duration_s=None)["switches_by_place"][0]["why"] in sw.WHYS
    assert "Switches by place (5; zoned run)" in report.table() and f"{sw.TRACKER}: 1 (0 in an overlap)" in (
        report.table())
    assert score(truth, outputs).switches_by_place is None


def test_the_zones_are_read_from_a_tracks_summary():
    summary = [{"cell": list(z.cell), "region": list(z.region), "cameras": 3} for z in ZONES]
    assert sw.zones_of(summary) == ZONES
    assert sw.zones_of([{"cell": [0, 0, 8, 8], "cameras": 3}]) is None and sw.zones_of([]) is None
