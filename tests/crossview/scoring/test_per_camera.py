"""Per-camera 2D tracking scores: MOTA and IDF1 counted by hand on small stories, the per-detection protocol's
truth and tracks, and its distance against a plain loop."""

import logging

import numpy as np
import pytest

from core.errors import CrossviewError
from core.records import CameraFrame, DetectionTruth
from core.types import Camera, Frame
from crossview.scoring.association import pose_boxes, stamp_key
from crossview.scoring.per_camera import (
    JOINT_MATCH_FRACTION,
    Camera2DAccumulator,
    Projected2DAccumulator,
    detection_2d_scores,
    detection_tracks,
    detection_truth,
    iou_distances,
    joint_distances,
    projected_2d_scores,
)
from tracker.types import Target, TrackerOutput

J = 17


def _person_px(x: float, y: float = 100.0) -> np.ndarray:
    """(J, 2) joints of a person spread over a 40 x 160 px box whose top left corner is (x, y)."""
    rng = np.random.default_rng(int(x))
    px = np.column_stack([rng.uniform(0, 40, J), np.linspace(0, 160, J)])
    return px + [x, y]


def _camera_frame(camera, stamp, person_ids, reported, true):
    """A frame whose detections report `reported` (D, J, 2), with `true` (D, J, 2) behind them."""
    d = len(person_ids)
    frame = Frame(camera, stamp, np.asarray(reported, float).reshape(d, J, 2), np.ones((d, J)))
    truth = DetectionTruth(
        capture_s=stamp, delivery_s=stamp, person_ids=np.asarray(person_ids, dtype=np.int64),
        keypoints_px=np.asarray(true, float).reshape(d, J, 2), in_image=np.ones((d, J), bool),
        occluded=np.zeros((d, J), bool), self_occluded=np.zeros((d, J), bool), effects=np.zeros(d, dtype=np.int64),
    )
    return CameraFrame(frame, truth, None)


def test_accumulator_mota_and_idf1_by_hand():
    acc = Camera2DAccumulator(["A", "B"])
    near = np.array([[0.1]])
    # Person 1: track 10 in frames 0-1, then track 20 in frames 2-3 (one switch).
    # Person 2: missed in frame 0, then track 30. Frame 3 also has a track 40 matching nobody.
    acc.update("A", [1, 2], [10], np.array([[0.1], [np.nan]]))
    acc.update("A", [1, 2], [10, 30], np.array([[0.1, np.nan], [np.nan, 0.1]]))
    acc.update("A", [1, 2], [20, 30], np.array([[0.1, np.nan], [np.nan, 0.1]]))
    acc.update("A", [1, 2], [20, 30, 40], np.array([[0.1, np.nan, np.nan], [np.nan, 0.1, np.nan]]))
    acc.update("B", [7], [70], near)
    s = acc.result()
    a = s["A"]
    # 8 true instants; FN 1, FP 1, IDS 1: MOTA = 1 - 3 / 8.
    assert (a.num_truth, a.false_negatives, a.false_positives, a.id_switches, a.num_frames) == (8, 1, 1, 1, 4)
    assert a.mota == pytest.approx(1 - 3 / 8)
    # IDF1: person 1 keeps 2 of its 4 instants under one id, person 2 keeps 3: IDTP 5, IDFN 3, IDFP 8 - 5 = 3.
    assert a.idf1 == pytest.approx(2 * 5 / (2 * 5 + 3 + 3))
    assert (s["B"].mota, s["B"].idf1) == (1.0, 1.0)
    with pytest.raises(ValueError, match="camera 'C'"):
        acc.update("C", [1], [1], near)


def test_joint_distance_agrees_with_a_plain_loop():
    rng = np.random.default_rng(0)
    truth = rng.uniform(0, 200, (3, J, 2))
    valid = rng.random((3, J)) > 0.2
    tracks = truth[[1, 0, 2, 1]] + rng.normal(0, 15, (4, J, 2))
    tracks[rng.random((4, J)) < 0.3] = np.nan
    d = joint_distances(truth, valid, tracks, threshold=np.inf)
    for g in range(3):
        known = truth[g][valid[g]]
        diagonal = np.hypot(*(known.max(axis=0) - known.min(axis=0)))
        for h in range(4):
            errors = [np.hypot(*(tracks[h, j] - truth[g, j])) for j in range(J) if np.isfinite(tracks[h, j]).all()]
            assert d[g, h] == pytest.approx(np.mean(errors) / diagonal)
    # The threshold turns far pairs into no match.
    gated = joint_distances(truth, valid, tracks)
    assert np.array_equal(np.isnan(gated), ~(d <= JOINT_MATCH_FRACTION))


def test_truth_and_tracks_of_a_frame_take_each_id_once():
    p1, p2 = _person_px(0), _person_px(300)
    cf = _camera_frame("A", 0.0, [2, -1, 1, 2], [p2, p1, p1, p2 + 3], [p2, np.full((J, 2), np.nan), p1, p2])
    ids, px, valid = detection_truth(cf)
    assert ids.tolist() == [2, 1]  # order of the first detection, the false positive left out
    np.testing.assert_array_equal(px, [p2, p1])
    track_ids, track_px = detection_tracks(cf.frame, np.array([9, -1, 5, 9]))
    assert track_ids.tolist() == [9, 5]
    np.testing.assert_array_equal(track_px, [p2, p1])  # track 9 keeps its first detection


def test_per_detection_scores_of_a_short_story(caplog):
    p1, p2, far = _person_px(0), _person_px(300), _person_px(600)
    nan = np.full((J, 2), np.nan)
    frames = [
        # A phantom given track 7 (FP); person 2 left unassigned (FN); person 1 on track 5.
        _camera_frame("A", 0.0, [1, 2, -1], [p1, p2, far], [p1, p2, nan]),
        # Person 1 and its duplicate both on track 5 (one place per track); person 2 on track 6.
        _camera_frame("A", 0.1, [1, 1, 2], [p1, p1 + 2, p2], [p1, p1, p2]),
        # Person 1's detection lies on nobody (a gross error) and is given track 5: FP and FN.
        _camera_frame("A", 0.2, [1, 2], [far, p2], [p1, p2]),
        # A frame the tracker never processed: left out.
        _camera_frame("A", 0.3, [1], [p1], [p1]),
    ]
    ids = {stamp_key("A", 0.0): np.array([5, -1, 7]), stamp_key("A", 0.1): np.array([5, 5, 6]),
           stamp_key("A", 0.2): np.array([5, 6])}
    with caplog.at_level(logging.WARNING):
        s = detection_2d_scores(frames, ids, ["A", "B"])
    a = s["A"]
    # 6 true instants, FP 2, FN 2, no switch.
    assert (a.num_truth, a.false_positives, a.false_negatives, a.id_switches, a.num_frames) == (6, 2, 2, 0, 3)
    assert a.mota == pytest.approx(1 - 4 / 6)
    # IDF1: person 1 on track 5 twice, person 2 on track 6 twice: IDTP 4; IDFN 2; IDFP 6 tracks - 4 = 2.
    assert a.idf1 == pytest.approx(8 / 12)
    assert s["B"].num_frames == 0 and s["B"].mota is None
    assert "1 camera frames had no track ids" in caplog.text


def test_ids_of_another_recording_are_refused():
    p1 = _person_px(0)
    frames = [_camera_frame("A", 0.0, [1], [p1], [p1])]
    with pytest.raises(CrossviewError, match="has 1 detections but the tracks assign 2"):
        detection_2d_scores(frames, {stamp_key("A", 0.0): np.array([1, 2])}, ["A"])
    with pytest.raises(CrossviewError, match="none of the recording's 1 camera frames"):
        detection_2d_scores(frames, {stamp_key("A", 0.5): np.array([1])}, ["A"])


def _walk_outputs(camera, rng):
    """Tracker outputs of one camera: two noisy, partly swapped tracks of the truth, a ghost and a target
    behind the camera, with the true poses (t -> ids, poses) they are scored against."""
    template = np.column_stack([rng.uniform(-0.25, 0.25, J), rng.uniform(-0.1, 0.1, J), np.linspace(0.1, 1.7, J)])

    def truth_at(t):
        return np.array([1, 2]), np.stack([template + [0.3 * t - 1.5, 0, 0], template + [1.2 - 0.4 * t, 0.5, 0]])

    outputs = []
    for k in range(60):
        t = 0.05 * k
        _, poses = truth_at(t)
        noisy = poses + rng.normal(0, 0.03, poses.shape)
        ids = (10, 20) if k < 30 else (20, 10)
        targets = [Target(ids[0], noisy[0], t), Target(ids[1], noisy[1], t),
                   Target(30, template + [rng.uniform(-3, 3), 0, 0], t), Target(40, template + [0, 0, 9.0], t)]
        outputs.append(TrackerOutput(t, camera.name, targets[: k % 5], np.zeros(0, dtype=np.int64)))
    return outputs, truth_at


def test_projected_scores_in_blocks_equal_one_projection_per_pose(monkeypatch):
    rng = np.random.default_rng(4)
    R = np.diag([1.0, -1.0, -1.0])
    camera = Camera("top", np.array([[400.0, 0, 320], [0, 400.0, 240], [0, 0, 1]]),
                    np.array([-0.2, 0.05, 0.001, -0.001, 0.0]), R, -R @ np.array([0.0, 0.0, 4.0]), 640, 480)
    outputs, truth_at = _walk_outputs(camera, rng)
    # Reference: each output's true and tracked poses projected on their own (`pose_boxes`).
    reference = Camera2DAccumulator(["top"])
    for out in outputs:
        ids, poses = truth_at(out.stamp_s)
        t_boxes, t_vis = pose_boxes(camera, poses)
        h_ids = np.array([t.id for t in out.targets], dtype=np.int64)
        h_poses = np.array([t.pose for t in out.targets]) if out.targets else np.zeros((0, J, 3))
        h_boxes, h_vis = pose_boxes(camera, h_poses)
        reference.update("top", ids[t_vis], h_ids[h_vis], iou_distances(t_boxes[t_vis], h_boxes[h_vis]))
    expected = reference.result()
    assert 0 < expected["top"].id_switches and expected["top"].false_positives > 0  # a story worth comparing
    for block_points in (1, 100, Projected2DAccumulator.BLOCK_POINTS):
        monkeypatch.setattr(Projected2DAccumulator, "BLOCK_POINTS", block_points)
        assert projected_2d_scores(iter(outputs), [camera], truth_at) == expected, block_points
