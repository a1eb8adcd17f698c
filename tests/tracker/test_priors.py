"""The body and joint priors beyond the paper (docs/tracker.md, "Body and joint priors"): the bone prior, the
temporal gate, the per-joint velocity windows and the constant-acceleration velocity fit."""

import cv2
import numpy as np
import pytest

from core.types import CAMPUS14, COCO17, Frame
from tests.tracker.synthetic import store_like
from tracker.body import prior_bones, velocity_windows
from tracker.config import BONE_SAMPLES, TrackerConfig
from tracker.kernels import _bound_bones, _fit_velocities, _gate_jumps, _resolve_bones
from tracker.tracker import Tracker
from tracker.triangulation import Observations, triangulate_point

CONFIG = TrackerConfig.preset("store")
ALL_ON = CONFIG.replace(limb_velocity_window_s=0.2, velocity_quadratic=True, joint_gate_m=0.3,
                        bone_prior_tolerance=0.15, bone_symmetry=True, head_bones=True, bone_prior_sample_s=0.0,
                        bone_prior_min_samples=1)


@pytest.fixture(scope="module")
def layout1():
    return store_like("layout1", 3.0, seed=0)


def _depths(skeleton, bones):
    """Each joint's number of bones from a hip over `bones` (breadth first), a reference of its own."""
    hips = [i for i, n in enumerate(skeleton.joints) if "hip" in n]
    depth = dict.fromkeys(hips, 0)
    changed = True
    while changed:
        changed = False
        for a, b in bones:
            for u, v in ((a, b), (b, a)):
                if u in depth and depth[u] + 1 < depth.get(v, 99):
                    depth[v] = depth[u] + 1
                    changed = True
    return depth


@pytest.mark.parametrize("head_bones", [False, True])
def test_the_prior_bones_point_away_from_the_hips_and_pair_left_with_right(head_bones):
    bones, mirror = prior_bones(COCO17, head_bones)
    names = COCO17.joints
    pairs = {frozenset(b) for b in COCO17.bones}
    if head_bones:
        pairs |= {frozenset((names.index(s), 0)) for s in ("left_shoulder", "right_shoulder")}
    assert {frozenset(b) for b in bones.tolist()} == pairs and len(bones) == len(pairs)
    depth = _depths(COCO17, bones.tolist())
    swap = {"left": "right", "right": "left"}
    mirrored = {n: "_".join(swap.get(w, w) for w in n.split("_")) for n in names}
    where = {frozenset((names[p], names[c])): i for i, (p, c) in enumerate(bones.tolist())}
    parents = []
    for i, ((p, c), m) in enumerate(zip(bones.tolist(), mirror.tolist())):
        if c in depth:
            assert depth[p] <= depth[c], (names[p], names[c])
            parents.append(depth[p])
        other = where.get(frozenset((mirrored[names[p]], mirrored[names[c]])))
        assert m == (other if other != i else -1), (names[p], names[c])
    assert parents == sorted(parents)  # ordered outward


def test_campus_arms_are_oriented_from_the_shoulders():
    bones, _ = prior_bones(CAMPUS14)
    names = CAMPUS14.joints
    oriented = {(names[p], names[c]) for p, c in bones.tolist()}
    assert ("right_shoulder", "right_elbow") in oriented and ("right_elbow", "right_wrist") in oriented
    assert ("left_hip", "left_knee") in oriented


def test_the_limb_window_reaches_only_the_wrists_and_ankles():
    windows = velocity_windows(COCO17, CONFIG.replace(limb_velocity_window_s=0.3))
    for name, w in zip(COCO17.joints, windows):
        limb = name.endswith("_wrist") or name.endswith("_ankle")
        assert w == (0.3 if limb else CONFIG.velocity_window_s), name
    paper = TrackerConfig.preset("store-paper")
    assert (velocity_windows(COCO17, paper) == paper.velocity_window_s).all()
    assert TrackerConfig.preset("store").limb_velocity_window_s == 0.2


@pytest.mark.parametrize("quadratic", [False, True])
def test_the_velocity_is_the_slope_of_numpys_least_squares_fit(quadratic):
    rng = np.random.default_rng(3)
    H, J = 12, 2
    stamp = 10.0
    hist_s = np.full((1, H, J), np.nan)
    hist_pos = np.full((1, H, J, 3), np.nan)
    times = stamp - np.sort(rng.uniform(0.0, 0.35, H - 2))[::-1]
    hist_s[0, :H - 2, :] = times[:, None]
    for k in range(3):
        hist_pos[0, :H - 2, :, k] = (0.3 * k + 1.5 * (times - stamp) + 4.0 * (times - stamp) ** 2)[:, None] \
            + rng.normal(0, 0.002, (H - 2, J))
    vel = np.zeros((1, J, 3))
    windows = np.array([0.4, 0.2])
    _fit_velocities(hist_pos, hist_s, 0, np.ones(J, dtype=np.bool_), stamp, windows, 100.0, quadratic, vel)
    for j in range(J):
        inside = stamp - times <= windows[j]
        for k in range(3):
            expected = np.polyfit(times[inside] - stamp, hist_pos[0, :H - 2, j, k][inside], 2 if quadratic else 1)
            assert vel[0, j, k] == pytest.approx(expected[-2], rel=1e-7, abs=1e-9)


def _prior(**changes):
    cfg = ALL_ON.replace(**changes)
    return Tracker(store_like("layout1", 0.1, seed=0)[0], cfg)._update_params.prior


def test_the_gate_refuses_a_jump_from_the_prediction_and_takes_it_after_the_reset():
    prior = _prior(joint_gate_m=0.2, joint_gate_reset_s=0.3)
    J = COCO17.num_joints
    pos = np.zeros((1, J, 3))
    vel = np.zeros((1, J, 3))
    vel[0, :, 0] = 1.0  # 1 m/s along x
    joint_s = np.full((1, J), 5.0)
    seen_s = np.full((1, J), 5.0)
    X = np.zeros((J, 3))
    X[:, 0] = 0.1  # 0.1 s later: on the prediction
    X[3, 0] = 0.35  # 0.25 m ahead of it
    update = np.ones(J, dtype=np.bool_)
    _gate_jumps(pos, vel, joint_s, seen_s, 0, 5.1, 0.5, prior, X, update)
    assert not update[3] and update[np.arange(J) != 3].all()
    seen_s[0, 3] = 4.7  # refused since 0.4 s: the person did move
    update[:] = True
    _gate_jumps(pos, vel, joint_s, seen_s, 0, 5.1, 0.5, prior, X, update)
    assert update.all()


def test_a_bone_out_of_the_persons_length_is_bounded_along_its_direction():
    prior = _prior(bone_prior_tolerance=0.1)
    bones = prior.bones
    b = next(i for i, (p, c) in enumerate(bones.tolist()) if (COCO17.joints[p], COCO17.joints[c])
             == ("left_elbow", "left_wrist"))
    p, c = bones[b]
    J = COCO17.num_joints
    bone_len = np.full((1, len(bones)), np.nan)
    bone_len[0, b] = 0.25
    pos = np.zeros((1, J, 3))
    X = np.zeros((J, 3))
    X[p] = (1.0, 1.0, 1.0)
    X[c] = (1.0, 1.0, 0.5)  # 0.5 m below the elbow: twice the person's forearm
    samples = X.copy()
    update = np.zeros(J, dtype=np.bool_)
    update[[p, c]] = True
    _bound_bones(pos, bone_len, 0, X, samples, update, prior)
    np.testing.assert_allclose(X[c], (1.0, 1.0, 1.0 - 0.25 * 1.1), atol=1e-12)
    np.testing.assert_allclose(samples[c], X[c], atol=1e-12)
    X[c] = (1.0, 1.24, 1.0)  # within the tolerance: untouched
    _bound_bones(pos, bone_len, 0, X, samples, update, prior)
    np.testing.assert_array_equal(X[c], (1.0, 1.24, 1.0))


def test_a_target_without_a_confident_frame_keeps_the_papers_estimates_never_nan(layout1):
    cams, _, frames, _ = layout1
    # No frame is confident (1000 views per joint): no bone length is ever known, so the prior changes nothing.
    never = CONFIG.replace(bone_prior_tolerance=0.15, bone_symmetry=True, head_bones=True, bone_prior_min_views=1000)
    runs = []
    for cfg in (CONFIG, never):
        tracker = Tracker(cams, cfg)
        outs = []
        for frame in frames:
            tracker.update(frame)
            outs.append(tracker.last_output.targets)
        runs.append(outs)
        assert np.isnan(tracker._targets.bone_len).all()
    for a, b in zip(*runs):
        np.testing.assert_array_equal(a.ids, b.ids)
        np.testing.assert_array_equal(a.poses, b.poses)
        assert np.isfinite(b.poses).all()


def test_with_every_prior_on_the_bones_keep_the_persons_lengths_and_no_joint_is_nan(layout1):
    cams, walkers, frames, _ = layout1
    tracker = Tracker(cams, ALL_ON)
    for frame in frames[:200]:
        tracker.update(frame)
    tg = tracker._targets
    assert len(tg) and np.isfinite(tg.bone_len).all()
    # Every learnt length is the median of its kept samples (pooled with the mirror's): within the samples.
    assert tg.bone_samples.shape[1] == BONE_SAMPLES
    # A gross error on every wrist of one frame: the forearms stay within the tolerance of the learnt lengths.
    frame = frames[200]
    kp = frame.keypoints_px.copy()
    kp[:, 9:11] += 150.0
    tracker.update(Frame(frame.camera, frame.stamp_s, kp, frame.scores))
    bones = tracker._update_params.prior.bones
    for r in range(len(tg)):
        for b, (p, c) in enumerate(bones.tolist()):
            if c in (9, 10) and tg.seen_s[r, c] == frame.stamp_s:
                length = np.linalg.norm(tg.pos[r, c] - tg.pos[r, p])
                assert abs(length - tg.bone_len[r, b]) <= 0.15 * tg.bone_len[r, b] + 1e-9
    assert all(np.isfinite(t.pose).all() for t in tracker.last_output.targets)



def test_resolve_drops_the_one_view_that_breaks_the_bone_and_leaves_two_views_to_the_bound():
    tracker = Tracker(store_like("layout1", 0.1, seed=0)[0], ALL_ON.replace(bone_prior_resolve=True,
                                                                            reject_factor=0.0))
    params, P = tracker._update_params, tracker._P
    prior = params.prior
    b = next(i for i, (p, c) in enumerate(prior.bones.tolist()) if (COCO17.joints[p], COCO17.joints[c])
             == ("left_elbow", "left_wrist"))
    p, c = prior.bones[b]
    J, C = COCO17.num_joints, len(P)
    elbow, wrist = np.array([2.0, 2.0, 1.1]), np.array([2.1, 2.05, 0.87])  # a forearm of 0.256 m
    views = [0, 3, 5, 8]

    def pixels(point, k):
        x = P[k] @ np.append(point, 1.0)
        return x[:2] / x[2]

    kept = Observations(np.zeros((J, C), dtype=np.int64), np.zeros((J, C, 2)), np.zeros((J, C)), np.ones((J, C)))
    for i, k in enumerate(views):
        kept.cam[c, i] = k
        kept.points_px[c, i] = pixels(wrist, k)
    kept.points_px[c, 2] += (0.0, 90.0)  # one view's wrist 90 px off
    # Independent reference: OpenCV's DLT of two of the good views is the true wrist, noise-free.
    ref = cv2.triangulatePoints(P[0], P[8], pixels(wrist, 0).reshape(2, 1), pixels(wrist, 8).reshape(2, 1))
    np.testing.assert_allclose(ref[:3, 0] / ref[3, 0], wrist, atol=1e-6)
    X = np.zeros((J, 3))
    X[p] = elbow
    plain, compensated = np.empty(3), np.empty(3)
    work, scratch = np.empty((3, 4, 4)), np.empty((4, 8))
    subset = Observations(np.empty(C, dtype=np.int64), np.empty((C, 2)), np.empty(C), np.empty(C))
    triangulate_point(P, Observations(kept.cam[c], kept.points_px[c], kept.dts[c], kept.decays[c]), 4, np.zeros(3),
                      params.triangulation, plain, compensated, work, scratch)
    X[c] = compensated  # the estimate from all four views: the forearm broken
    assert abs(np.linalg.norm(X[c] - elbow) / np.linalg.norm(wrist - elbow) - 1.0) > 0.15
    samples = X.copy()
    pos, vel = np.full((1, J, 3), np.nan), np.zeros((1, J, 3))
    bone_len = np.full((1, len(prior.bones)), np.nan)
    bone_len[0, b] = np.linalg.norm(wrist - elbow)
    update = np.zeros(J, dtype=np.bool_)
    update[[p, c]] = True
    num_views = np.zeros(J, dtype=np.int64)
    num_views[c] = 4
    _resolve_bones(pos, vel, bone_len, 0, X, samples, update, prior, P, kept, num_views, subset, params.triangulation,
                   work, scratch)
    np.testing.assert_allclose(X[c], ref[:3, 0] / ref[3, 0], atol=1e-6)
    np.testing.assert_allclose(samples[c], X[c], atol=1e-6)
    # With two views, leaving one out leaves too few to solve: the estimate goes on to the bound unchanged.
    X[c] = compensated
    num_views[c] = 2
    _resolve_bones(pos, vel, bone_len, 0, X, samples, update, prior, P, kept, num_views, subset, params.triangulation,
                   work, scratch)
    np.testing.assert_array_equal(X[c], compensated)
