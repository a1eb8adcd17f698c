"""The single-view SORT tracker: its Kalman filter against independent formulas, its matching against brute
force, and its lifecycle (birth after min hits, death after max age in seconds) on stories of moving people."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.integrate import quad_vec

from core.boxes import box_iou
from core.types import Frame
from tests.tracker.synthetic import look_at_camera
from tracker.single_view import (
    Affinity2D,
    SingleViewConfig,
    SingleViewTracker,
    keypoint_distances,
    kf_predict,
    kf_update,
    match,
)

# A 2D person template: 17 joints in a unit box (x right, y down), the box's corners among them.
_TEMPLATE = np.array([
    [0.5, 0.0], [0.45, 0.05], [0.55, 0.05], [0.4, 0.07], [0.6, 0.07], [0.2, 0.2], [0.8, 0.2], [0.0, 0.4],
    [1.0, 0.4], [0.05, 0.55], [0.95, 0.55], [0.35, 0.55], [0.65, 0.55], [0.35, 0.78], [0.65, 0.78],
    [0.33, 1.0], [0.67, 1.0],
])


def person(box) -> np.ndarray:
    """(17, 2) joints filling box (x0, y0, x1, y1)."""
    x0, y0, x1, y1 = box
    return np.array([x0, y0]) + _TEMPLATE * np.array([x1 - x0, y1 - y0])


def frame(camera: str, stamp_s: float, boxes) -> Frame:
    kp = np.array([person(b) for b in boxes]).reshape(-1, 17, 2)
    return Frame(camera, stamp_s, kp, np.ones(kp.shape[:2]))


@pytest.fixture
def cameras():
    return [look_at_camera(name, (0.0, 0.0, 3.0), (1.0, 0.0, 0.0)) for name in ("a", "b")]


def walking_box(t_s: float, start_x: float, speed_px_per_s: float, y: float = 200.0) -> tuple:
    x = start_x + speed_px_per_s * t_s
    return (x, y, x + 80.0, y + 200.0)


# ---------------------------------------------------------------- the Kalman filter and the matching


def test_process_noise_is_the_integral_of_white_acceleration():
    # Reference: Q = ∫_0^dt F(s) G G^T F(s)^T ds q^2 with G = [0, 1] (acceleration drives the velocity).
    dt, q = 0.137, 3.0
    G = np.array([[0.0], [1.0]])

    def F(s):
        return np.array([[1.0, s], [0.0, 1.0]])

    reference, _ = quad_vec(lambda s: F(s) @ G @ G.T @ F(s).T * q**2, 0.0, dt)
    _, _, Q = kf_predict(np.zeros((1, 2)), np.zeros((1, 2)), np.zeros((1, 2, 2)), dt, q)
    np.testing.assert_allclose(Q[0], reference, rtol=1e-9, atol=1e-12)


def test_kalman_update_agrees_with_the_information_form():
    # Reference, per image axis with x = (position, velocity), H = [1, 0]:
    # P+^-1 = P^-1 + H^T R^-1 H, x+ = P+ (P^-1 x + H^T R^-1 z).
    rng = np.random.default_rng(0)
    A = rng.normal(size=(3, 2, 2))
    P = A @ A.transpose(0, 2, 1) + np.eye(2)
    pos, vel, z, std = rng.normal(size=(3, 2)), rng.normal(size=(3, 2)), rng.normal(size=(3, 2)), 0.7
    new_pos, new_vel, new_P = kf_update(pos, vel, P, z, std)
    H = np.array([[1.0, 0.0]])
    for n in range(3):
        P_ref = np.linalg.inv(np.linalg.inv(P[n]) + H.T @ H / std**2)
        np.testing.assert_allclose(new_P[n], P_ref, atol=1e-12)
        for axis in range(2):
            x = np.array([pos[n, axis], vel[n, axis]])
            x_ref = P_ref @ (np.linalg.solve(P[n], x) + H.T[:, 0] * z[n, axis] / std**2)
            np.testing.assert_allclose([new_pos[n, axis], new_vel[n, axis]], x_ref, atol=1e-12)


def test_kalman_filter_learns_a_constant_velocity_from_uneven_intervals():
    # Noise-free joints moving at (120, -40) px/s, measured at jittered intervals.
    rng = np.random.default_rng(1)
    velocity = np.array([120.0, -40.0])
    start = np.array([[300.0, 200.0], [320.0, 380.0]])
    pos, vel, P = start.copy(), np.zeros((2, 2)), np.tile(np.diag([4.0, 1e4]), (2, 1, 1))
    t = 0.0
    for _ in range(40):
        dt = 0.1 + rng.uniform(-0.03, 0.03)
        t += dt
        pos, vel, P = kf_predict(pos, vel, P, dt, accel_std=5.0)
        pos, vel, P = kf_update(pos, vel, P, start + velocity * t, measurement_std=2.0)
    np.testing.assert_allclose(vel, np.tile(velocity, (2, 1)), atol=1.0)  # px/s
    ahead, _, _ = kf_predict(pos, vel, P, 0.5, accel_std=5.0)
    np.testing.assert_allclose(ahead, start + velocity * (t + 0.5), atol=1.0)  # px


def test_keypoint_distance_by_hand_uses_the_joints_both_know():
    predicted = np.array([[[0.0, 0.0], [10.0, 0.0], [np.nan, np.nan]]])  # (T=1, J=3, 2)
    detected = np.array([[[3.0, 4.0], [np.nan, np.nan], [50.0, 50.0]], [[np.nan] * 2, [np.nan] * 2, [1.0, 1.0]]])
    d = keypoint_distances(predicted, np.array([10.0]), detected)
    assert d[0, 0] == pytest.approx(5.0 / 10.0)  # only joint 0 in common: 5 px over a 10 px track
    assert np.isnan(d[0, 1])  # nothing in common


def test_match_agrees_with_brute_force():
    rng = np.random.default_rng(2)
    for _ in range(30):
        T, D = (int(n) for n in rng.integers(0, 5, size=2))
        lo = rng.uniform(0, 100, size=(T + D, 2))
        boxes = np.hstack([lo, lo + rng.uniform(20, 60, size=(T + D, 2))])
        iou = box_iou(boxes[:T], boxes[T:])
        allowed = iou >= 0.1
        # Reference: the one-to-one assignment of allowed pairs with the largest total IoU, over every
        # permutation of every subset.
        best, best_pairs = -1.0, set()
        for k in range(min(T, D) + 1):
            for rs in itertools.combinations(range(T), k):
                for cs in itertools.permutations(range(D), k):
                    if all(allowed[r, c] for r, c in zip(rs, cs)):
                        total = sum(iou[r, c] for r, c in zip(rs, cs))
                        if total > best + 1e-12:
                            best, best_pairs = total, set(zip(rs, cs))
        rows, cols = match(1.0 - iou, allowed)
        assert set(zip(rows.tolist(), cols.tolist())) == best_pairs


# ---------------------------------------------------------------- the tracker


@pytest.mark.parametrize("affinity", list(Affinity2D))
def test_ids_follow_people_through_reordered_detections_and_uneven_stamps(cameras, affinity):
    rng = np.random.default_rng(3)
    tracker = SingleViewTracker(cameras, SingleViewConfig(affinity=affinity, min_hits=3))
    t, history = 0.0, []
    for _ in range(30):
        t += 0.1 + rng.normal(0, 0.01)
        boxes = [walking_box(t, 100, 150.0), walking_box(t, 700, -60.0, y=260.0)]
        order = rng.permutation(2)
        tracker.update(frame("a", t, [boxes[i] for i in order]))
        ids = tracker.last_output.detection_track_ids
        history.append(ids[np.argsort(order)])  # back to person order
    history = np.array(history)
    # Birth: tentative (-1) for the first two frames, confirmed on the third.
    assert (history[:2] == -1).all()
    assert (history[2:] >= 0).all()
    # One id per person for the whole walk, two different ids.
    assert len(set(history[2:, 0])) == 1 and len(set(history[2:, 1])) == 1
    assert history[2, 0] != history[2, 1]
    # The reported tracks are the confirmed, matched ones with their filtered boxes.
    out = tracker.last_output
    assert sorted(tr.id for tr in out.tracks) == sorted(history[-1])
    expected = {history[-1][i]: walking_box(t, *args) for i, args in enumerate([(100, 150.0), (700, -60.0, 260.0)])}
    for tr in out.tracks:
        np.testing.assert_allclose(tr.box_px, expected[tr.id], atol=2.0)  # px


@pytest.mark.parametrize("affinity", list(Affinity2D))
def test_two_people_crossing_keep_their_ids(cameras, affinity):
    # Two people walk past each other at the same height; the velocity carries each through the overlap.
    tracker = SingleViewTracker(cameras, SingleViewConfig(affinity=affinity))
    ids = []
    for k in range(1, 41):
        t = 0.1 * k
        boxes = [walking_box(t, 100, 200.0), walking_box(t, 900, -200.0, y=210.0)]
        tracker.update(frame("a", t, boxes))
        ids.append(tracker.last_output.detection_track_ids)
    ids = np.array(ids[2:])
    assert len(set(ids[:, 0])) == 1 and len(set(ids[:, 1])) == 1 and ids[0, 0] != ids[0, 1]


def test_joints_dropping_out_break_the_box_but_not_the_keypoint_track(cameras):
    # Every other frame only the head and shoulders are reported (the rest occluded): the box shrinks to a
    # fifth of its height, under SORT's IoU gate, while the joints that are reported stay where they were.
    def run(affinity):
        tracker = SingleViewTracker(cameras, SingleViewConfig(affinity=affinity, min_hits=1))
        ids = []
        for k in range(10):
            f = frame("a", 0.1 * k, [walking_box(0.1 * k, 100, 30.0)])
            if k % 2:
                f.keypoints_px[0, 7:] = np.nan
            tracker.update(f)
            ids.append(int(tracker.last_output.detection_track_ids[0]))
        return ids

    assert len(set(run(Affinity2D.KEYPOINTS))) == 1
    assert len(set(run(Affinity2D.IOU))) > 1


def test_death_is_measured_in_seconds_not_frames(cameras):
    config = SingleViewConfig(max_age_s=0.5, min_hits=1)

    def id_after_gap(fps: float, missed_frames: int) -> tuple[int, int]:
        tracker = SingleViewTracker(cameras, config)
        stamps = np.arange(20) / fps
        seen = [k for k in range(20) if not 5 <= k < 5 + missed_frames]
        ids = {}
        for k in seen:
            tracker.update(frame("a", stamps[k], [walking_box(stamps[k], 100, 50.0)]))
            ids[k] = int(tracker.last_output.detection_track_ids[0])
        return ids[4], ids[5 + missed_frames]

    # Four missed frames: 0.5 s at 10 fps (kept), 0.16 s at 30 fps (kept), 1.33 s at 3 fps (a new track).
    before, after = id_after_gap(10.0, 4)
    assert before == after
    before, after = id_after_gap(30.0, 4)
    assert before == after
    before, after = id_after_gap(3.0, 4)
    assert before != after


def test_cameras_are_tracked_apart_and_ids_are_unique_over_cameras(cameras):
    tracker = SingleViewTracker(cameras, SingleViewConfig(min_hits=1))
    # The same pixels in two cameras are two different people.
    tracker.update(frame("a", 0.0, [walking_box(0.0, 100, 0.0)]))
    tracker.update(frame("b", 0.01, [walking_box(0.0, 100, 0.0)]))
    id_a = tracker.update(frame("a", 0.1, [walking_box(0.0, 100, 0.0)]))[0].id
    id_b = tracker.update(frame("b", 0.11, [walking_box(0.0, 100, 0.0)]))[0].id
    assert id_a != id_b
    # A long silence of camera b does not age camera a's tracks.
    assert tracker.update(frame("a", 0.2, [walking_box(0.0, 100, 0.0)]))[0].id == id_a


def test_detections_without_a_box_and_empty_frames_are_left_unassigned(cameras):
    tracker = SingleViewTracker(cameras, SingleViewConfig(min_hits=1))
    f = frame("a", 0.0, [walking_box(0.0, 100, 0.0), walking_box(0.0, 600, 0.0)])
    f.keypoints_px[1, 1:] = np.nan  # one joint: no box
    tracker.update(f)
    ids = tracker.last_output.detection_track_ids
    assert ids[0] >= 0 and ids[1] == -1
    assert tracker.update(Frame("a", 0.1, np.zeros((0, 17, 2)), np.zeros((0, 17)))) == []
    assert tracker.last_output.detection_track_ids.shape == (0,)
    # An empty first frame of a camera, even one that names no joints, does not fix its joint count.
    assert tracker.update(Frame("b", 0.1, np.zeros((0, 0, 2)), np.zeros((0, 0)))) == []
    assert len(tracker.update(frame("b", 0.2, [walking_box(0.0, 100, 0.0)]))) == 1


def test_low_scored_joints_are_left_out_of_the_box(cameras):
    tracker = SingleViewTracker(cameras, SingleViewConfig(min_hits=1, score_threshold=0.5))
    f = frame("a", 0.0, [walking_box(0.0, 100, 0.0)])
    f.scores[0, 15:] = 0.1  # the ankles: the box ends at the knees
    box = tracker.update(f)[0].box_px
    np.testing.assert_allclose(box[3], 200 + 0.78 * 200, atol=1e-6)  # px


def test_bad_frames_are_dropped_with_a_warning_and_bad_config_names_the_field(cameras, caplog):
    tracker = SingleViewTracker(cameras, SingleViewConfig(min_hits=1))
    for bad in (frame("zz", 0.0, [walking_box(0.0, 100, 0.0)]), frame("a", float("nan"), [walking_box(0.0, 100, 0.0)])):
        assert tracker.update(bad) == []
        assert tracker.last_output.detection_track_ids.tolist() == [-1]
    assert "unknown camera" in caplog.text and "not finite" in caplog.text
    # Nothing was started by them: the next good frame starts track 0.
    assert tracker.update(frame("a", 0.1, [walking_box(0.0, 100, 0.0)]))[0].id == 0
    # A frame of another joint layout than the camera's earlier ones is dropped too.
    assert tracker.update(Frame("a", 0.2, np.ones((1, 5, 2)), np.ones((1, 5)))) == []
    assert "5 joints where the camera's earlier frames had 17" in caplog.text
    for bad in ({"affinity": "iou"}, {"max_joint_distance": 0.0}, {"min_iou": 0.0}, {"min_hits": 0},
                {"max_age_s": -1.0}, {"score_threshold": 2.0}, {"measurement_std_frac": 0.0}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            SingleViewConfig(**bad)
