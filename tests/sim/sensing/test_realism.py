"""The detector's realism: its own joints (offsets from the truth), errors that persist, misses in runs."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from core.records import PoseTruth
from core.truth import TRUTH_RATE_HZ
from core.types import COCO17
from sim.cameras import CameraPlacement
from sim.sensing.detector import Detector
from sim.sensing.draws import TEMPLATE_COCO17
from sim.sensing.offsets import ANCHOR_TICKS, JointOffsets, fourier_sums
from sim.sensing.profiles import PROFILES, DetectorConfig, DetectorProfile
from tests.reference.detector import detect
from tests.sim.sensing.test_detector import BoxWorld, _cameras, _frames, _only

_IDEAL = PROFILES[DetectorProfile.IDEAL]


def _offsets(seed=0, **knobs) -> JointOffsets:
    return JointOffsets(_IDEAL._replace(**knobs), COCO17, seed)


def _crowd(n: int) -> np.ndarray:
    """(n, 17, 3) standing people spread over a floor, each turned its own way."""
    rng = np.random.default_rng(11)
    poses = []
    for _ in range(n):
        yaw = rng.uniform(0, 2 * np.pi)
        rot = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
        poses.append(TEMPLATE_COCO17 @ rot.T + [*rng.uniform(0, 10, 2), 0.0])
    return np.array(poses)


def test_offsets_have_the_profiles_std_lift_and_time_correlation():
    std_m, lift_m, time_s = 0.04, 0.02, 1.5
    offsets = _offsets(offset_m=(std_m,) * 7, lift_m=(lift_m,) * 7, offset_time_s=time_s)
    poses = _crowd(3000)
    ids = np.arange(3000)
    a = offsets.offsets(ids, np.full(3000, 1000), poses)  # (ticks: 10 s)
    b = offsets.offsets(ids, np.full(3000, 1000 + round(time_s * TRUTH_RATE_HZ)), poses)
    # Gaussian across people (offset_tail_dof inf): per axis std offset_m, the lift on the world's z.
    assert a[..., 0].std() == pytest.approx(std_m, rel=0.05)  # m
    assert a[..., 2].mean() == pytest.approx(lift_m, abs=0.002)  # m
    assert np.abs(a[..., :2].mean()) < 0.002  # m
    # Correlation exp(-|dt| / offset_time_s) between two times one time constant apart.
    corr = np.corrcoef(a[..., 0].ravel(), b[..., 0].ravel())[0, 1]
    assert corr == pytest.approx(math.exp(-1.0), abs=0.05)


def test_offsets_belong_to_the_person_not_to_who_asks_or_in_which_order():
    offsets, again = _offsets(offset_m=(0.05,) * 7), _offsets(offset_m=(0.05,) * 7)
    poses = _crowd(5)
    t = np.array([0, 75, 150, 225, 300])  # ticks
    first = offsets.offsets(np.arange(5), t, poses)
    # Another detector with the same seed, asked about the people in another order and among others.
    order = np.array([4, 2, 0, 3, 1])
    again.offsets(np.array([9, 7]), np.zeros(2, dtype=np.int64), _crowd(2))
    np.testing.assert_array_equal(again.offsets(order, t[order], poses[order]), first[order])
    # A detector of another seed gives other offsets.
    assert not np.allclose(_offsets(seed=1, offset_m=(0.05,) * 7).offsets(np.arange(5), t, poses), first)


def test_the_turned_phasors_are_the_cosines_and_a_tick_gives_the_same_bits_however_it_is_asked():
    """`fourier_sums` turns each feature's phasor from tick to tick: it agrees with the cosines evaluated at each
    tick's time, and a tick's value does not depend on the other rows of the call (which ticks were turned
    through on the way)."""
    rng = np.random.default_rng(3)
    fourier = np.empty((6, 17, 3, 4, 6))  # 6 people: ω (Cauchy, 0.5 s), φ, the turn per tick
    fourier[..., 0, :] = rng.standard_cauchy((6, 17, 3, 6)) / 0.5
    fourier[..., 1, :] = rng.uniform(0, 2 * np.pi, (6, 17, 3, 6))
    fourier[..., 2, :], fourier[..., 3, :] = (f(fourier[..., 0, :] / TRUTH_RATE_HZ) for f in (np.cos, np.sin))
    slots, ticks = rng.integers(0, 6, 4000), rng.integers(0, 3000, 4000)
    sums = np.empty((4000, 17, 3))
    fourier_sums(slots, ticks, np.lexsort((ticks, slots)), fourier, ANCHOR_TICKS, TRUTH_RATE_HZ, sums)
    omega, phase = fourier[slots, :, :, 0], fourier[slots, :, :, 1]
    direct = np.cos(omega * (ticks / TRUTH_RATE_HZ)[:, None, None, None] + phase).sum(axis=-1)
    np.testing.assert_allclose(sums, direct, rtol=0, atol=1e-9)
    for i in (0, 17, 3999):  # each row alone: the same bits
        alone = np.empty((1, 17, 3))
        fourier_sums(slots[i:i + 1], ticks[i:i + 1], np.zeros(1, dtype=np.int64), fourier, ANCHOR_TICKS,
                     TRUTH_RATE_HZ, alone)
        np.testing.assert_array_equal(alone[0], sums[i])


def test_offsets_turn_with_the_body():
    offsets = _offsets(offset_m=(0.05,) * 7, offset_time_s=2.0)
    pose = _crowd(1)
    yaw = 0.7
    rot = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
    here = offsets.offsets(np.array([3]), np.array([100]), pose)
    turned = offsets.offsets(np.array([3]), np.array([100]), pose @ rot.T)
    np.testing.assert_allclose(turned, here @ rot.T, atol=1e-12)  # m


def test_heavy_tailed_offsets_put_more_mass_far_out():
    poses, ids, t = _crowd(3000), np.arange(3000), np.zeros(3000, dtype=np.int64)
    gauss = np.abs(_offsets(offset_m=(0.03,) * 7).offsets(ids, t, poses)[..., 0]).ravel()
    heavy = np.abs(_offsets(offset_m=(0.03,) * 7, offset_tail_dof=3.0).offsets(ids, t, poses)[..., 0]).ravel()
    assert np.percentile(heavy, 99.5) / np.median(heavy) > 1.3 * np.percentile(gauss, 99.5) / np.median(gauss)


def test_every_camera_sees_the_same_offset_joint_so_it_survives_triangulation():
    # Two cameras either side of a person, a detector with offsets only: triangulating its two views gives the
    # detector's joint, not the truth's.
    world = BoxWorld([(3.0, 2.0)], shelf=((9.0, 9.0, 0.1), (0.1, 0.1, 0.1)))
    cams = _cameras(CameraPlacement((0.5, 0.2, 2.6), (3.0, 2.0, 1.0)),
                    CameraPlacement((5.5, 3.8, 2.6), (3.0, 2.0, 1.0)))
    detector = Detector(_only(offset_m=(0.05,) * 7, lift_m=(0.03,) * 7, occlusion=False), cams,
                        np.random.default_rng(4))
    truth = world.truth(0.5)
    frames = [detect(detector, c, None, truth, 0.5, 0.5, 0.5) for c in range(2)]
    P = [c.K @ np.hstack([c.R_cam_from_world, c.t_cam_from_world.reshape(3, 1)]) for c in cams]
    points = cv2.triangulatePoints(P[0], P[1], frames[0].frame.keypoints_px[0].T, frames[1].frame.keypoints_px[0].T)
    found = (points[:3] / points[3]).T
    want = truth.poses[0] + detector.offsets.offsets(np.array([0]), np.array([50]), truth.poses)[0]
    np.testing.assert_allclose(found, want, atol=1e-6)  # m
    assert np.linalg.norm(found - truth.poses[0], axis=1).mean() > 0.03  # m: not the truth's joints


def _lag1(frames, joint):
    """Lag-1 correlation of person 0's x error on `joint` over consecutive frames, and its std, px."""
    err = np.array([f.frame.keypoints_px[list(f.truth.person_ids).index(0), joint, 0]
                    - f.truth.keypoints_px[list(f.truth.person_ids).index(0), joint, 0] for f in frames])
    return np.corrcoef(err[:-1], err[1:])[0, 1], err.std()


@pytest.mark.parametrize("noise_time_s", [0.0, 0.2, 1.0])
def test_a_cameras_noise_on_a_joint_persists_with_its_time_constant(noise_time_s):
    # Frames 0.1 s apart: the lag-1 correlation is exp(-0.1 / noise_time_s), the std stays noise_frac x size.
    frames = _frames(_only(noise_frac=0.01, noise_tail_dof=1e9, noise_time_s=noise_time_s), n=1500)
    corr, _ = _lag1(frames, COCO17.index("left_wrist"))
    want = math.exp(-0.1 / noise_time_s) if noise_time_s else 0.0
    assert corr == pytest.approx(want, abs=0.07)
    white = _lag1(_frames(_only(noise_frac=0.01, noise_tail_dof=1e9), n=1500), COCO17.index("left_wrist"))[1]
    assert _lag1(frames, COCO17.index("left_wrist"))[1] == pytest.approx(white, rel=0.15)


def test_joint_misses_come_in_runs_at_their_rate():
    rate, time_s = 0.2, 0.3
    frames = _frames(_only(joint_miss_prob=(rate,) * 7, miss_time_s=time_s), n=1500)
    missed = np.array([np.isnan(f.frame.keypoints_px[np.argsort(f.truth.person_ids), :, 0]) for f in frames])
    assert missed.mean() == pytest.approx(rate, abs=0.02)
    # P(missed at the next frame | missed now) = rate + (1 - rate) exp(-0.1 / time).
    again = (missed[1:] & missed[:-1]).sum() / missed[:-1].sum()
    assert again == pytest.approx(rate + (1 - rate) * math.exp(-0.1 / time_s), abs=0.04)
    # Without memory the misses are independent frame to frame.
    frames = _frames(_only(joint_miss_prob=(rate,) * 7), n=800)
    missed = np.array([np.isnan(f.frame.keypoints_px[np.argsort(f.truth.person_ids), :, 0]) for f in frames])
    assert (missed[1:] & missed[:-1]).sum() / missed[:-1].sum() == pytest.approx(rate, abs=0.04)


def test_each_joint_group_misses_at_its_own_rate():
    rates = (0.0, 0.05, 0.1, 0.3, 0.0, 0.15, 0.2)
    frames = _frames(_only(joint_miss_prob=rates), n=800)
    missed = np.concatenate([np.isnan(f.frame.keypoints_px[..., 0]) for f in frames])
    for group, joints in enumerate(((0, 1, 2, 3, 4), (5, 6), (7, 8), (9, 10), (11, 12), (13, 14), (15, 16))):
        assert missed[:, joints].mean() == pytest.approx(rates[group], abs=0.025), group


def test_phantoms_report_their_joints_with_the_keep_probability():
    frames = _frames(_only(phantom_rate=2.0, phantom_keep_prob=0.5), n=300)
    counts = []
    for f in frames:
        phantom = f.truth.person_ids < 0
        counts.extend((~np.isnan(f.frame.keypoints_px[phantom, :, 0])).sum(axis=1).tolist())
    # Of the template's joints in the image (most of the 17), about half, and never fewer than 3.
    assert 6.5 < np.mean(counts) < 9.0 and min(counts) >= 3


def test_the_ideal_detector_finds_the_true_joints():
    detector = Detector(DetectorConfig(profile=DetectorProfile.IDEAL), _cameras(
        CameraPlacement((0.2, 0.2, 2.9), (2.0, 1.5, 1.0))), np.random.default_rng(0))
    assert not detector.offsets.active
    truth = PoseTruth(0.0, np.array([0]), TEMPLATE_COCO17[None] + [2.0, 1.5, 0.0])
    assert not detector.offsets.offsets(truth.person_ids, np.zeros(1), truth.poses).any()


def _bad_arm(offsets: JointOffsets, ids: np.ndarray, ticks: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """(N, 2) the offsets' length at each pose's left and right wrist (metres)."""
    wrists = [COCO17.index("left_wrist"), COCO17.index("right_wrist")]
    return np.linalg.norm(offsets.offsets(ids, ticks, poses)[:, wrists], axis=-1)


@pytest.mark.parametrize("seed", range(10))
def test_a_crowd_holds_rate_times_n_difficult_people_whatever_the_seed(seed):
    # Offsets of the difficult people's bad arm only, always in a bad episode: who has one is who is difficult.
    offsets = _offsets(seed=seed, difficult_rate=0.25, difficult_error_m=0.4, difficult_share=1.0,
                       offset_time_s=2.0)
    n = 40
    lengths = _bad_arm(offsets, np.arange(n), np.zeros(n, dtype=np.int64), _crowd(n))
    difficult = (lengths > 0).any(axis=1)
    assert difficult.sum() == 10  # 0.25 x 40, not a binomial's 10 +- 3
    assert difficult[:4].sum() == 1 and difficult[:8].sum() == 2  # any 4 in a row hold one
    # One arm each, its wrist difficult_error_m off (the elbow half that); everybody else's joints untouched.
    np.testing.assert_allclose(np.sort(lengths[difficult], axis=1)[:, 1], 0.4)
    assert (np.sort(lengths[difficult], axis=1)[:, 0] == 0).all()
    assert (lengths[~difficult] == 0).all()


def test_which_people_are_difficult_changes_with_the_seed_and_an_arm_is_bad_for_the_whole_visit():
    n, poses = 40, _crowd(40)
    who = [(_bad_arm(_offsets(seed=s, difficult_rate=0.25, difficult_error_m=0.4, difficult_share=1.0),
                     np.arange(n), np.zeros(n, dtype=np.int64), poses) > 0).any(axis=1) for s in range(6)]
    assert len({w.tobytes() for w in who}) > 1
    # The share of the time the chosen arm is in a bad episode, and it is always the same arm.
    offsets = _offsets(difficult_rate=1.0, difficult_error_m=0.4, difficult_share=0.3, offset_time_s=1.0)
    ticks = np.arange(0, 400 * int(TRUTH_RATE_HZ), 7)  # 400 s
    bad_share, arms = [], []
    for pid in range(8):
        lengths = _bad_arm(offsets, np.full(len(ticks), pid), ticks, np.repeat(_crowd(1), len(ticks), axis=0))
        bad = (lengths > 0).any(axis=1)
        bad_share.append(bad.mean())
        arms.append(set(np.argmax(lengths[bad], axis=1).tolist()))
    assert np.mean(bad_share) == pytest.approx(0.3, abs=0.06)
    assert all(len(a) == 1 for a in arms)


def test_a_difficult_persons_offsets_are_scaled_and_nobody_elses():
    poses, ids, t = _crowd(12), np.arange(12), np.zeros(12, dtype=np.int64)
    plain = _offsets(offset_m=(0.03,) * 7, offset_tail_dof=1.5).offsets(ids, t, poses)
    scaled = _offsets(offset_m=(0.03,) * 7, offset_tail_dof=1.5, difficult_rate=0.25,
                      difficult_offset_scale=3.0).offsets(ids, t, poses)
    ratio = np.linalg.norm(scaled, axis=(1, 2)) / np.linalg.norm(plain, axis=(1, 2))
    np.testing.assert_allclose(np.sort(ratio), [1.0] * 9 + [3.0] * 3, rtol=1e-9)


@pytest.mark.parametrize(("knob", "value", "message"), [
    ("difficult_rate", 1.5, r"difficult_rate: 1\.5 must be in \[0, 1\]"),
    ("difficult_rate", -0.1, r"difficult_rate: -0\.1 must be in \[0, 1\]"),
    ("offset_tail_dof", 0.5, r"offset_tail_dof: 0\.5 must be"),
])
def test_a_difficulty_rate_outside_0_1_and_a_tail_below_a_cauchys_are_refused(knob, value, message):
    with pytest.raises(ValueError, match=message):
        DetectorConfig(**{knob: value})
    assert DetectorConfig(offset_tail_dof=1.0).params().offset_tail_dof == 1.0  # a Cauchy's tail is allowed
