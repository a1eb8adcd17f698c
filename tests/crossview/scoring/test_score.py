"""score() end to end: truth fed back as tracks, swapped identities, NaN joints, empty and foreign tracks."""

import json

import numpy as np
import pytest

from core.layouts import coco17_to_campus14
from core.records import PoseTruth
from core.types import CAMPUS14
from crossview.scoring import JSON_KEYS, ScoringError, TruthTimeline, score
from tracker.types import Target, TrackerOutput

TEMPLATE = np.random.default_rng(3).normal(0.0, 0.25, (17, 3)) + [0.0, 0.0, 1.0]
VELOCITY = {1: np.array([0.8, 0.1, 0.0]), 2: np.array([-0.5, 0.6, 0.0])}  # m/s, straight lines
START = {1: np.array([0.0, 0.0, 0.0]), 2: np.array([4.0, 0.0, 0.0])}
DURATION_S = 10.0


def _pose(pid, t):
    """COCO-17 pose of person pid at time t: constant velocity, so linear interpolation is exact."""
    return TEMPLATE + START[pid] + VELOCITY[pid] * t


def _truth(rate_hz=100.0):
    times = np.arange(int(DURATION_S * rate_hz) + 1) / rate_hz
    return [PoseTruth(t, np.array([1, 2]), np.stack([_pose(1, t), _pose(2, t)])) for t in times]


def _outputs(rate_hz=25.0, ids=lambda t: (10, 20), modify=lambda pose: pose):
    """Tracks that are the truth at their stamps, from one camera at rate_hz (ids may change with t)."""
    outs = []
    for k in range(int(DURATION_S * rate_hz) + 1):
        t = k / rate_hz
        a, b = ids(t)
        targets = [Target(a, modify(_pose(1, t)), t), Target(b, modify(_pose(2, t)), t)]
        outs.append(TrackerOutput(t, "cam0", targets, np.zeros(0, dtype=np.int64)))
    return outs


def test_truth_between_samples_follows_the_one_rule_arrivals_and_departures_included():
    """Between two samples, the truth is `core.truth`'s rule: linear for the people at both, and a person
    at only one sample is there in that sample's half of the interval; off the span, nobody beyond half a
    sampling period."""
    truth = [
        PoseTruth(0.0, np.array([1, 2]), np.stack([np.zeros((17, 3)), np.ones((17, 3))])),
        PoseTruth(0.01, np.array([2]), np.full((1, 17, 3), 2.0)),
    ]
    ids, poses = TruthTimeline(truth).at(0.0025)
    assert ids.tolist() == [1, 2]  # person 1 leaves after the first sample: still there a quarter of the way
    np.testing.assert_allclose(poses[0], 0.0)  # m
    np.testing.assert_allclose(poses[1], 1.25)  # m
    assert TruthTimeline(truth).at(0.0075)[0].tolist() == [2]
    assert TruthTimeline(truth).at(0.0)[0].tolist() == [1, 2]
    assert TruthTimeline(truth).at(0.014)[0].tolist() == [2]  # within half a period of the last sample
    assert len(TruthTimeline(truth).at(0.5)[0]) == 0  # beyond the recording: nobody


def test_the_scored_truth_at_a_capture_time_is_what_the_camera_saw():
    """Scoring and the simulator share the truth-at-t rule: at each frame's true capture time, the truth a
    score compares with is, bit for bit, the poses the frame was made from (`poses_at_capture`)."""
    from core.records import CameraFrame
    from sim.scenario import load
    from sim.simulate import Simulation

    scenario = load("store_layout1", {"crowd.people": 3, "cameras.rows": 2, "cameras.cols": 2})
    events = list(Simulation(scenario, seed=3, worker_process=False).events(1.0))
    timeline = TruthTimeline([e for e in events if isinstance(e, PoseTruth)])
    frames = [e for e in events if isinstance(e, CameraFrame)]
    assert len(frames) > 30
    for frame in frames:
        ids, poses = timeline.at(frame.truth.capture_s)
        assert ids.tolist() == frame.poses_at_capture.person_ids.tolist()
        assert poses.tobytes() == frame.poses_at_capture.poses.tobytes()


def test_truth_fed_back_as_tracks_scores_perfectly():
    r = score(_truth(), _outputs())
    assert r.eval_instants == 101 and r.truth_person_instants == 202
    assert r.pcp == 1.0 and r.pck_50mm == 1.0
    assert r.mpjpe_mm == pytest.approx(0.0, abs=1e-9)  # mm
    assert r.idf1 == 1.0 and r.mota == 1.0 and r.id_switches == 0
    assert r.hota == pytest.approx(1.0, abs=1e-12)


def test_swapping_two_identities_lowers_idf1_by_the_share_after_the_swap():
    # Targets 10 and 20 trade persons at 3 s: 30 ticks before (0.0 .. 2.9 s), 71 from 3.0 s to 10.0 s.
    r = score(_truth(), _outputs(ids=lambda t: (10, 20) if t < 3.0 else (20, 10)))
    # Best identity map keeps the longer part of each person: IDF1 = 71 / 101.
    assert r.idf1 == pytest.approx(71 / 101, abs=1e-12)
    assert r.id_switches == 2
    assert r.mota == pytest.approx(1 - 2 / 202, abs=1e-12)
    assert r.pcp == 1.0  # pose metrics ignore identities
    # Halfway (5 s): 50 ticks before, 51 after.
    assert score(_truth(), _outputs(ids=lambda t: (10, 20) if t < 5.0 else (20, 10))).idf1 == pytest.approx(51 / 101)


def test_nan_joint_counts_wrong_for_pcp_and_pck_and_is_left_out_of_mpjpe():
    def drop_left_wrist(pose):
        pose = pose.copy()
        pose[9] = np.nan
        return pose

    r = score(_truth(), _outputs(modify=drop_left_wrist))
    # One of ten bones (left lower arm) is wrong at every instant; one of 17 joints is never within reach.
    assert r.pcp == pytest.approx(0.9)
    assert r.pcp_per_group["lower_arms"] == pytest.approx(0.5)
    assert r.pck_100mm == pytest.approx(16 / 17)
    assert r.mpjpe_mm == pytest.approx(0.0, abs=1e-9)
    assert r.nan_joints == 202
    assert r.idf1 == 1.0  # the root (hips) is intact


def test_empty_tracks_give_documented_scores():
    r = score(_truth(), [])
    assert (r.pcp, r.mota, r.idf1, r.hota, r.id_switches, r.false_negatives) == (0.0, 0.0, 0.0, 0.0, 0, 202)
    assert r.mpjpe_mm is None and r.association_accuracy is None
    assert "MOTA" in r.table()


def test_json_has_the_architecture_keys_first_and_no_nan():
    r = score(_truth(), [])
    d = r.to_json(scenario="store", seed=1, num_cameras=4, num_people=2, duration_s=DURATION_S,
                  tracker_fps=None, camera_frames_per_s=None)
    assert tuple(d)[: len(JSON_KEYS)] == JSON_KEYS
    assert d["mpjpe_mm"] is None and d["pcp"] == 0.0 and d["tracker_fps"] is None
    json.dumps(d, allow_nan=False)
    for key in ("pcp", "pck_100mm", "idf1", "hota"):
        assert 0.0 <= d[key] <= 1.0


def test_tracks_of_another_recording_are_refused():
    foreign = [TrackerOutput(500.0, "cam0", [], np.zeros(0, dtype=np.int64))]
    with pytest.raises(ScoringError, match="another recording"):
        score(_truth(), foreign)


def test_tracks_in_another_joint_layout_are_refused():
    bad = [TrackerOutput(0.0, "cam0", [Target(1, np.zeros((14, 3)), 0.0)], np.zeros(0, dtype=np.int64))]
    with pytest.raises(ScoringError, match=r"target poses have shape \(14, 3\), expected \(17, 3\) coco17"):
        score(_truth(), bad)
    with pytest.raises(ScoringError, match=r"truth poses have 17 joints, expected 14 \(campus14\)"):
        score(_truth(), [], skeleton=CAMPUS14)


def test_campus14_truth_and_tracks_score_by_their_own_layout():
    # The same two people in the Campus-14 layout (hips, limbs and head joints of their own).
    def campus(pose):
        return coco17_to_campus14(pose)

    truth = [PoseTruth(p.t_s, p.person_ids, campus(p.poses)) for p in _truth()]
    perfect = score(truth, _outputs(modify=campus), skeleton=CAMPUS14)
    assert perfect.pcp == pytest.approx(1.0) and perfect.idf1 == pytest.approx(1.0)
    assert perfect.mpjpe_mm == pytest.approx(0.0, abs=1e-9)
    assert set(perfect.mpjpe_per_group_mm) == {"head", "shoulders", "elbows", "wrists", "hips", "knees", "ankles"}
    # Everybody 3 m off (no target comes within 1 m of anybody): every target is a false positive.
    off = score(truth, _outputs(modify=lambda pose: campus(pose) + [0.0, -3.0, 0.0]), skeleton=CAMPUS14)
    assert off.idf1 == 0.0 and off.pcp == 0.0


def test_stale_outputs_stop_counting_after_a_second():
    # The tracker reports only during the first 2 s: ticks after 3.0 s see no output at all.
    outs = [o for o in _outputs() if o.stamp_s <= 2.0]
    r = score(_truth(), outs)
    # Ticks 0.0 .. 3.0 s (31) compare with an output no older than 1 s; the other 70 ticks are all misses.
    assert r.false_negatives == 2 * 70
    assert r.mota == pytest.approx(31 / 101, abs=1e-12)


def test_nobody_in_the_store_leaves_pose_and_mota_undefined_and_targets_are_false_positives():
    empty_store = [PoseTruth(t, np.zeros(0, dtype=np.int64), np.zeros((0, 17, 3))) for t in np.arange(0, 1, 0.01)]
    r = score(empty_store, [])
    assert (r.pcp, r.mota, r.idf1, r.hota) == (None, None, None, None)
    ghost = [TrackerOutput(0.5, "cam0", [Target(1, np.zeros((17, 3)), 0.5)], np.zeros(0, dtype=np.int64))]
    r = score(empty_store, ghost)
    # Ticks 0.5 .. 0.9 s see the ghost: five false positives, IDF1 and HOTA 0, MOTA still undefined.
    assert (r.false_positives, r.idf1, r.hota, r.mota) == (5, 0.0, 0.0, None)
    assert score([], []).eval_instants == 0


def test_speed_set_on_the_report_reaches_table_and_json():
    r = score(_truth(), _outputs())
    r.tracker_fps, r.camera_frames_per_s = 120.0, 1440.0
    assert "120.0 / 1440" in r.table()
    d = r.to_json(scenario="s", seed=0, num_cameras=12, num_people=2, duration_s=DURATION_S)
    assert (d["tracker_fps"], d["camera_frames_per_s"]) == (120.0, 1440.0)
    d = r.to_json(scenario="s", seed=0, num_cameras=12, num_people=2, duration_s=1.0, tracker_fps=5.0)
    assert d["tracker_fps"] == 5.0  # an explicit argument wins


def test_ticks_before_the_first_output_are_not_scored():
    # No camera frame before 1 s: ticks 0.0 .. 0.9 s are left out, not counted as misses.
    late = [o for o in _outputs() if o.stamp_s >= 1.0]
    r = score(_truth(), late)
    assert r.eval_instants == 91 and r.truth_person_instants == 182
    assert r.false_negatives == 0 and r.mota == 1.0 and r.pcp == 1.0


def test_outputs_stamped_before_the_people_were_created_are_not_scored():
    # A camera whose clock reads behind stamps the first frame before t_0 = 0, when the people of the first
    # truth sample are created; the tracker has no target yet. The first tick waits for an output stamped at or
    # after t_0 (here 0.04 s, scored at tick 0.1 s) instead of counting both people missed.
    early = TrackerOutput(-0.004, "cam0", [], np.zeros(0, dtype=np.int64))
    r = score(_truth(), [early, *_outputs()[1:]])
    assert r.eval_instants == 100 and r.truth_person_instants == 200
    assert r.false_negatives == 0 and r.mota == 1.0 and r.pcp == 1.0
    # The same output stamped at t_0 speaks of the people there: both missed at tick 0.
    at_start = TrackerOutput(0.0, "cam0", [], np.zeros(0, dtype=np.int64))
    r = score(_truth(), [at_start, *_outputs()[1:]])
    assert r.eval_instants == 101 and r.false_negatives == 2


def test_people_outside_the_scored_area_are_neither_missed_nor_matched():
    area = (-2.0, -1.0, 4.0, 10.0)
    roots = {pid: _pose(pid, 0.0)[[11, 12], :2].mean(axis=0) for pid in (1, 2)}
    # Person 1 walks out of the area (x > 4 m) at t_out; person 2 stays in for the whole run.
    t_out = (4.0 - roots[1][0]) / VELOCITY[1][0]
    end_2 = roots[2] + VELOCITY[2][:2] * DURATION_S
    assert 3.0 < t_out < 7.0 and -2.0 < end_2[0] < roots[2][0] < 4.0 and -1.0 < roots[2][1] < end_2[1] < 10.0
    r = score(_truth(), _outputs(), scored_area=area)
    inside_ticks = int(np.floor(t_out * 10.0)) + 1
    assert r.truth_person_instants == 101 + inside_ticks
    # Its target, still reported outside, is no false positive: everything scored is perfect.
    assert (r.false_positives, r.false_negatives, r.mota, r.pcp) == (0, 0, 1.0, 1.0)
    # A tracker that drops person 1 once outside the area loses nothing either.
    def drop_outside(out):
        kept = [t for t in out.targets if t.id != 10 or out.stamp_s <= t_out]
        return TrackerOutput(out.stamp_s, out.camera, kept, out.detection_target_ids)

    r2 = score(_truth(), [drop_outside(o) for o in _outputs()], scored_area=area)
    assert (r2.false_negatives, r2.mota, r2.idf1) == (0, 1.0, 1.0)


def test_ghosts_off_the_floor_are_ignored_and_on_the_floor_are_false_positives():
    area = (-2.0, -1.0, 10.0, 10.0)  # both people stay inside
    off, on = np.zeros((17, 3)) + [20.0, 0.0, 1.0], np.zeros((17, 3)) + [9.0, 9.0, 1.0]
    outs = [TrackerOutput(o.stamp_s, o.camera, o.targets + [Target(98, off, o.stamp_s), Target(99, on, o.stamp_s)],
                          o.detection_target_ids) for o in _outputs()]
    r = score(_truth(), outs, scored_area=area)
    assert r.false_positives == 101 and r.false_negatives == 0


def test_outputs_are_read_once_as_a_stream_and_equal_stamps_take_the_later_delivered():
    outs = _outputs(ids=lambda t: (10, 20) if t < 5.0 else (20, 10))
    # Delivery order is not stamp order: every pair of neighbours swapped.
    shuffled = [o for pair in zip(outs[1::2], outs[0::2], strict=False) for o in pair] + outs[len(outs) // 2 * 2:]
    once = score(_truth(), iter(shuffled))
    assert once.to_json(scenario="s", seed=0, num_cameras=1, num_people=2, duration_s=DURATION_S, tracker_fps=None,
                        camera_frames_per_s=None) == score(_truth(), outs).to_json(
        scenario="s", seed=0, num_cameras=1, num_people=2, duration_s=DURATION_S, tracker_fps=None,
        camera_frames_per_s=None)
    # A second output with the stamp of one already delivered replaces it: its targets are the ones scored.
    late_ghosts = [TrackerOutput(o.stamp_s, "cam0", [Target(99, _pose(1, o.stamp_s) + [0.0, 5.0, 0.0], o.stamp_s)],
                                 np.zeros(0, dtype=np.int64)) for o in outs]
    r = score(_truth(), iter([o for pair in zip(outs, late_ghosts, strict=True) for o in pair]))
    assert r.false_negatives == r.truth_person_instants and r.false_positives == r.eval_instants
