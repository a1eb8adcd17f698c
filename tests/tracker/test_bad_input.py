"""Bad input never crashes the tracker and never puts NaN or inf into a joint it has once estimated."""

import copy
import functools

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from core.types import Frame
from tests.fuzz import FUZZ
from tests.tracker.synthetic import store_like
from tracker.baseline import BaselineTracker
from tracker.config import TrackerConfig
from tracker.tracker import Tracker

CAMS, _, FRAMES, _ = store_like("layout1", 1.5, seed=3)
CONFIG = TrackerConfig.preset("store")
J = 17

values = st.one_of(st.floats(-1e4, 1e4), st.just(float("nan")), st.just(float("inf")), st.just(-float("inf")),
                   st.floats(0, 1280))
scores = st.one_of(st.floats(-1, 2), st.just(float("nan")), st.just(0.0), st.just(1.0))


@st.composite
def bad_frames(draw):
    camera = draw(st.sampled_from([c.name for c in CAMS] + ["ghost"]))
    stamp = draw(st.one_of(st.floats(-5, 5), st.just(float("nan")), st.just(1.5 + draw(st.floats(0, 0.3)))))
    D = draw(st.integers(0, 3))
    kp = np.array(draw(st.lists(values, min_size=D * J * 2, max_size=D * J * 2)), dtype=float).reshape(D, J, 2)
    sc = np.array(draw(st.lists(scores, min_size=D * J, max_size=D * J)), dtype=float).reshape(D, J)
    if D and draw(st.booleans()):
        # A real detection of a real camera, perturbed: it may well be associated.
        source = FRAMES[-1 - draw(st.integers(0, 11))]
        if source.num_detections:
            camera, kp[0], sc[0] = source.camera, source.keypoints_px[0], source.scores[0]
            kp[0, draw(st.integers(0, J - 1))] = draw(values)
    return Frame(camera, stamp, kp, sc)


@functools.cache
def _warmed(tracker_type, config):
    tracker = tracker_type(CAMS, config)
    for frame in FRAMES:
        tracker.update(frame)
    return tracker


def _warm(tracker_type, config=CONFIG):
    """A tracker that has seen the synthetic frames (a copy, so that examples do not share state)."""
    return copy.deepcopy(_warmed(tracker_type, config))


def _check(tracker, frames, complete=False):
    """Runs the frames; with `complete`, every output joint must be finite (the crossview tracker infers the
    joints it has not triangulated) and none may sit at the world origin."""
    known: dict[int, np.ndarray] = {}
    for frame in frames:
        targets = tracker.update(frame)
        out = tracker.last_output
        assert out.detection_target_ids.shape == (frame.num_detections,)
        assert out.detection_target_ids.dtype == np.int64
        for target in targets:
            assert target.pose.shape == (J, 3)
            assert not np.isinf(target.pose).any()
            if complete:
                assert np.isfinite(target.pose).all()
                assert not np.any(np.linalg.norm(target.pose, axis=-1) < 1e-6)
            finite = np.isfinite(target.pose).all(axis=-1)
            before = known.get(target.id, np.zeros(J, dtype=bool))
            assert not (before & ~finite).any(), "a joint once estimated became NaN"
            known[target.id] = before | finite


@FUZZ
@given(st.lists(bad_frames(), min_size=1, max_size=6))
def test_fuzz_tracker_survives_bad_frames(frames):
    _check(_warm(Tracker), frames, complete=True)


# The baseline re-partitions every camera's latest frame on each update; the greedy partition keeps the
# property test fast (the exact milp path is tested in test_initialization).
BASELINE_CONFIG = CONFIG.replace(milp_max_nodes=2)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(bad_frames(), min_size=1, max_size=4))
def test_baseline_survives_bad_frames(frames):
    _check(_warm(BaselineTracker, BASELINE_CONFIG), frames)


def test_all_zero_scores_and_empty_frames_only_age_the_targets():
    tracker = _warm(Tracker)
    before = {t.id for t in tracker.last_output.targets}
    t = FRAMES[-1].stamp_s
    for i, cam in enumerate(CAMS):
        frame = Frame(cam.name, t + 0.01 * (i + 1), np.full((2, J, 2), 300.0), np.zeros((2, J)))
        tracker.update(frame)
        assert (tracker.last_output.detection_target_ids == -1).all()
    empty = Frame(CAMS[0].name, t + 0.2, np.zeros((0, J, 2)), np.zeros((0, J)))
    assert {target.id for target in tracker.update(empty)} == before


def test_a_late_frame_of_a_camera_is_dropped_and_logged(caplog):
    tracker = _warm(Tracker)
    last = FRAMES[-1]
    again = Frame(last.camera, last.stamp_s - 0.05, last.keypoints_px, last.scores)
    tracker.update(again)
    assert (tracker.last_output.detection_target_ids == -1).all()
    assert "dropping frame" in caplog.text


def test_wrong_joint_count_is_a_value_error():
    import pytest

    tracker = Tracker(CAMS, CONFIG)
    with pytest.raises(ValueError, match="14 joints"):
        tracker.update(Frame(CAMS[0].name, 0.0, np.zeros((1, 14, 2)), np.ones((1, 14))))


def test_a_burst_of_500_detections_in_a_frame():
    """500 person-shaped detections (random bodies projected) in each of three cameras' frames at once, and a
    frame whose every detection is a false positive: no crash, no NaN, no joint at the origin."""
    tracker = _warm(Tracker)
    _check(tracker, _burst_frames(np.random.default_rng(9), FRAMES[-1].stamp_s), complete=True)


def _burst_frames(rng, t):
    """500 person-shaped detections (random bodies projected) in each of three cameras' frames, then a frame of
    a fourth camera whose every detection is a false positive (random pixels)."""
    from tests.reference.cameras import project as project_distorted_px
    from tests.tracker.synthetic import _REST

    bodies = _REST[None] + np.concatenate([rng.uniform([-1, -1], [5.5, 5.0], (500, 2)), np.zeros((500, 1))],
                                          axis=1)[:, None, :]
    frames = []
    for i, cam in enumerate(CAMS[:3]):
        kp = project_distorted_px(cam, bodies)[0] + rng.normal(0, 2.0, (500, J, 2))
        frames.append(Frame(cam.name, t + 0.01 * (i + 1), kp, np.full((500, J), 0.9)))
    frames.append(Frame(CAMS[3].name, t + 0.05, rng.uniform(0, 1280, (40, J, 2)), np.full((40, J), 0.9)))
    return frames


def test_the_baseline_survives_a_burst_and_a_frame_of_false_positives_without_unknown_joints():
    tracker = _warm(BaselineTracker, BASELINE_CONFIG)
    _check(tracker, _burst_frames(np.random.default_rng(9), FRAMES[-1].stamp_s), complete=True)
    # ... and goes on tracking the real people afterwards.
    _check(tracker, [Frame(f.camera, f.stamp_s + 1.0, f.keypoints_px, f.scores) for f in FRAMES[-24:]], complete=True)
    assert tracker.last_output.targets


@pytest.mark.parametrize("tracker_type", [Tracker, BaselineTracker])
def test_a_camera_whose_view_holds_nothing(tracker_type):
    """A camera that looks at empty floor far from the store (its view overlaps no other camera's): its
    empty frames and its frames of false positives change nothing, and the other cameras track as before."""
    from tests.tracker.synthetic import look_at_camera

    void = look_at_camera("void", (60.0, 60.0, 3.0), (60.0, 61.0, 0.0))
    config = CONFIG if tracker_type is Tracker else BASELINE_CONFIG
    tracker = tracker_type([*CAMS, void], config)
    rng = np.random.default_rng(4)
    frames = []
    for k, frame in enumerate(FRAMES):
        frames.append(frame)
        if k % 12 == 0:  # the void camera at about 10 fps: empty, or false positives only
            D = int(rng.integers(0, 3))
            frames.append(Frame("void", frame.stamp_s + 1e-4, rng.uniform(0, 1280, (D, J, 2)), np.full((D, J), 0.9)))
    _check(tracker, frames, complete=True)
    reference = tracker_type(CAMS, config)
    for frame in FRAMES:
        reference.update(frame)
    assert len(tracker.last_output.targets) == len(reference.last_output.targets) > 0
    for a, b in zip(sorted(tracker.last_output.targets, key=lambda t: t.id),
                    sorted(reference.last_output.targets, key=lambda t: t.id)):
        np.testing.assert_allclose(a.pose, b.pose, atol=1e-9)
