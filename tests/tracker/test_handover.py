"""The zones' merger (`tracker.handover`): a person walking from zone to zone keeps one global id, reported once
per output by the zone whose cell holds them; people apart are never merged; detections follow their targets."""

from __future__ import annotations

import numpy as np

from core import tracks
from core.types import COCO17
from tracker.handover import Merger
from tracker.types import TargetArrays, TrackerOutput
from tracker.zones import Zone

J = COCO17.num_joints
# Two zones side by side on a 10 x 4 m floor, cut at x = 5, each region 1 m into the other (a 2 m overlap).
ZONES = [Zone(0, (0.0, 0.0, 5.0, 4.0), (0.0, 0.0, 6.0, 4.0), (0,), (False, True)),
         Zone(1, (5.0, 0.0, 10.0, 4.0), (4.0, 0.0, 10.0, 4.0), (1,), (True, True))]


def _pose(x: float, y: float) -> np.ndarray:
    pose = np.zeros((J, 3))
    pose[:, 0], pose[:, 1] = x, y
    pose[:, 2] = np.linspace(0.1, 1.7, J)
    return pose


def _output(t: float, seen: dict[int, tuple[float, float]], noise: float, detections=()) -> TrackerOutput:
    ids = np.array(sorted(seen), dtype=np.int64)
    poses = np.array([_pose(*seen[i]) + noise for i in ids]).reshape(-1, J, 3)
    arrays = TargetArrays(ids, poses, np.zeros((len(ids), J), np.uint8), t)
    return TrackerOutput(t, "cam", arrays, np.array(detections, dtype=np.int64))


def test_a_walker_keeps_one_global_id_across_the_border_and_is_reported_once():
    merger = Merger(ZONES, COCO17, gate_m=0.25)
    reported = []
    for k in range(101):  # x from 1 to 9 m in 10 s, 10 frames a second; a bystander stands in zone 1
        t, x = k / 10, 1.0 + 0.08 * k
        outputs = {}
        if x <= 6.0:  # zone 0's region; its tracker calls the walker 3
            outputs[0] = _output(t, {3: (x, 2.0)}, 0.0, detections=[3])
        if x >= 4.3:  # zone 1's region (its tracker confirms the walker a little after they enter); calls them 0
            outputs[1] = _output(t, {0: (x, 2.0), 1: (8.0, 1.0)}, 0.05, detections=[0])
        else:
            outputs[1] = _output(t, {1: (8.0, 1.0)}, 0.0, detections=[-1])
        merged = merger.add(outputs, 1)
        walker = [i for i, p in zip(merged.targets.ids, merged.targets.poses, strict=True) if p[0, 1] == 2.0 or
                  abs(p[0, 1] - 2.05) < 1e-9]
        reported.append((x, walker, merged.detection_target_ids.tolist(), len(merged.targets)))
    ids = {i for _, walker, _, _ in reported for i in walker}
    assert ids == {tracks.namespaced(0, 3)}  # (one id, zone 0's own: the walker was first seen there)
    assert all(len(walker) == 1 for _, walker, _, _ in reported)  # (reported once, never twice, never missed)
    assert all(n == 2 for *_, n in reported)  # (the bystander reported all along, by zone 1)
    assert all(d == [tracks.namespaced(0, 3)] for _, _, d, _ in reported)  # (by whichever zone reports them)
    assert [h[1:] for h in merger.handovers] == [(0, 1, tracks.namespaced(0, 3))]


def test_people_farther_apart_than_the_gate_are_never_handed_over():
    merger = Merger(ZONES, COCO17, gate_m=0.25)
    merger.add({0: _output(0.0, {0: (4.8, 2.0)}, 0.0)}, 0)
    merged = merger.add({1: _output(0.1, {0: (5.2, 2.0)}, 0.0)}, 0)  # (0.4 m from zone 0's person)
    assert sorted(merged.targets.ids) == sorted([tracks.namespaced(0, 0), tracks.namespaced(1, 0)])
    assert merger.handovers == []


def test_an_output_older_than_the_age_limit_is_no_longer_reported():
    merger = Merger(ZONES, COCO17, gate_m=0.25)
    merger.add({0: _output(0.0, {0: (2.0, 2.0)}, 0.0)}, 0)
    assert list(merger.add({1: _output(1.0, {}, 0.0)}, 0).targets.ids) == [tracks.namespaced(0, 0)]
    assert list(merger.add({1: _output(1.01, {}, 0.0)}, 0).targets.ids) == []


def test_a_target_born_beyond_the_gate_is_handed_over_once_its_pose_settles():
    """Zone 1 confirms the walker at the far edge of the overlap, its first poses 0.5 m off along each axis (the
    few cameras that see that edge), beyond the 0.25 m gate; they settle before the walker reaches the border.
    Zone 1's id is provisional until it reports the walker, so the walker keeps zone 0's id: no switch there."""
    merger = Merger(ZONES, COCO17, gate_m=0.25)
    reported = []
    for k in range(101):
        t, x = k / 10, 1.0 + 0.08 * k
        outputs = {0: _output(t, {3: (x, 2.0)} if x <= 6.0 else {}, 0.0)}
        if x >= 4.3:
            outputs[1] = _output(t, {0: (x, 2.0)}, -0.5 if x < 4.7 else 0.05)
        merged = merger.add(outputs, 0)
        reported.append(merged.targets.ids.tolist())
    assert all(ids == [tracks.namespaced(0, 3)] for ids in reported)
    assert [h[1:] for h in merger.handovers] == [(0, 1, tracks.namespaced(0, 3))]
    assert merger.handovers[0][0] >= 0.45  # (handed over once the pose settled, at x >= 4.7 m)


def test_a_person_standing_on_the_border_keeps_one_id_though_two_zones_took_them_for_two():
    """Zone 1's tracker first places the person 0.6 m off (beyond the gate, inside its own cell: reported under its
    own id), then 3 cm beside zone 0's estimate, both wandering across the border line. While zone 1 does not
    report them (its estimate on zone 0's side) its target follows zone 0's id, so from then on the person is
    reported under zone 0's id alone, by either zone."""
    merger = Merger(ZONES, COCO17, gate_m=0.25)
    reported = []
    for k in range(60):
        t = k / 10
        x0 = 4.95 + 0.1 * np.sin(k)
        x1 = 5.6 if k < 3 else x0 + 0.03
        merged = merger.add({0: _output(t, {1: (x0, 2.0)}, 0.0), 1: _output(t, {7: (x1, 2.0)}, 0.0)}, 0)
        reported.append(sorted(set(merged.targets.ids.tolist())))
    assert reported[0] == sorted([tracks.namespaced(0, 1), tracks.namespaced(1, 7)])  # (two people, at first)
    settled = reported[10:]
    assert all(ids == [tracks.namespaced(0, 1)] for ids in settled), settled
