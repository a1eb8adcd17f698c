"""Pose metrics: the COCO-17 to Campus-14 mapping, PCP bones, MPJPE and PCK with NaN joints."""

import numpy as np
import pytest

from core.head import HeadPoints
from core.layouts import coco17_to_campus14
from core.types import CAMPUS14, COCO17
from crossview.scoring.pose import (
    PCP_BONE_GROUPS,
    PoseAccumulator,
    match_nearest,
    pcp_bones,
)

# A head convention as the simulator's humanoid gives one: the base of the head below the ears and the vertex
# above them, in the nose-ear frame (coefficients of the ear-to-ear distance).
HEAD = HeadPoints(bottom_head=(0.08, 0.0, -0.54), top_head=(-0.05, 0.0, 0.8))


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


def _person(rng, offset=(0.0, 0.0)):
    """A random COCO-17 pose (17, 3) around (offset, 1 m), metres."""
    return rng.normal(0.0, 0.3, (17, 3)) + np.array([offset[0], offset[1], 1.0])


def test_bone_is_correct_up_to_half_its_length_of_mean_endpoint_error():
    truth = np.zeros((14, 3))
    truth[:, 2] = np.arange(14) * 1.0  # every consecutive pair 1 m apart along z
    est = truth.copy()
    # Bone 0 (joints 0-1, length 1 m): mean end-point error exactly 0.5 m is still correct ...
    est[0] += [0.4, 0, 0]
    est[1] += [0.6, 0, 0]
    # ... bone 2 (joints 3-4): 0.51 m is not.
    est[3] += [0.51, 0, 0]
    est[4] += [0.51, 0, 0]
    ok = pcp_bones(est, truth)
    assert ok[0] and not ok[2]
    # Joint 1 also ends bone 1 (1-2), mean error 0.3 m: correct; joint 3 starts nothing else but the torso
    # uses the mid-hip (2, 3), moved 0.255 m, against a 10 m torso: correct.
    assert ok[1] and ok[9]
    assert ok.sum() == 9


def test_nan_joint_makes_its_bones_wrong():
    truth = np.random.default_rng(0).normal(size=(14, 3))
    est = truth.copy()
    est[7] = np.nan  # right elbow: ends the right lower arm (6, 7) and starts the right upper arm (7, 8)
    ok = pcp_bones(est, truth)
    assert not ok[4] and not ok[5] and ok.sum() == 8


def test_match_nearest_ignores_identities_and_may_reuse_an_estimate(rng):
    a, b = _person(rng), _person(rng, (5, 0))
    idx = match_nearest(np.stack([a, b]), np.stack([b + 0.01, a + 0.01]))
    assert idx.tolist() == [1, 0]
    # evaluate.py does not assign one-to-one: both true persons may take the same estimate.
    assert match_nearest(np.stack([a, a + 0.1]), np.stack([a])).tolist() == [0, 0]
    assert match_nearest(np.stack([a]), np.zeros((0, 17, 3))).tolist() == [-1]


def test_pck_and_mpjpe_by_hand(rng):
    truth = _person(rng)
    est = truth.copy()
    # Offsets along x: joint 0 by 40 mm, joint 1 by 90 mm, joint 2 by 140 mm, joint 3 by 200 mm, joint 4 NaN.
    for j, off in enumerate([0.04, 0.09, 0.14, 0.2]):
        est[j, 0] += off
    est[4] = np.nan
    acc = PoseAccumulator()
    acc.update(np.array([1]), truth[None], est[None])
    s = acc.result()
    # PCK counts all 17 true joints; the NaN joint is wrong.
    assert s.pck[50] == pytest.approx(13 / 17)
    assert s.pck[100] == pytest.approx(14 / 17)
    assert s.pck[150] == pytest.approx(15 / 17)
    # MPJPE over the 16 known joints; the NaN joint is counted apart.
    assert s.mpjpe_mm == pytest.approx((40 + 90 + 140 + 200) / 16, abs=1e-9)  # mm
    assert s.num_nan_joints == 1
    assert s.mpjpe_per_group_mm["head"] == pytest.approx((40 + 90 + 140 + 200) / 4, abs=1e-9)
    assert s.pck_per_group[100]["head"] == pytest.approx(2 / 5)
    assert s.pck_per_group[100]["ankles"] == 1.0


def test_pcp_is_the_mean_over_actors(rng):
    acc = PoseAccumulator()
    a, b = _person(rng), _person(rng, (5, 0))
    # Actor 1 perfect on two instants, actor 2 missed on one of its two instants.
    acc.update(np.array([1, 2]), np.stack([a, b]), np.stack([a, b]))
    acc.update(np.array([1, 2]), np.stack([a, b]), np.stack([a]))
    s = acc.result()
    assert s.pcp_per_actor[1] == 1.0
    # On the second instant actor 2 is compared with actor 1's estimate, 5 m away: every bone wrong.
    assert s.pcp_per_actor[2] == pytest.approx(0.5)
    assert s.pcp == pytest.approx(0.75)
    # MPJPE leaves out the far match (mean error above 0.5 m).
    assert s.num_matched_instants == 3 and s.mpjpe_mm == pytest.approx(0.0)


def test_no_estimates_score_zero_not_a_crash(rng):
    acc = PoseAccumulator()
    acc.update(np.array([1]), _person(rng)[None], np.zeros((0, 17, 3)))
    s = acc.result()
    assert s.pcp == 0.0 and s.pck[100] == 0.0 and s.mpjpe_mm is None
    assert PoseAccumulator().result().pcp is None


def test_a_head_convention_places_only_the_head_joints_on_the_head(rng):
    coco = _person(rng)
    evaluated, annotated = coco17_to_campus14(coco), coco17_to_campus14(coco, HEAD)
    # The limb joints are the same; the head joints are the convention's points of the nose-ear frame.
    np.testing.assert_array_equal(annotated[:12], evaluated[:12])
    np.testing.assert_array_equal(annotated[12:], HEAD.locate(coco))
    assert not np.allclose(annotated[12:], evaluated[12:])


def _upright(rng, offset):
    """A COCO-17 pose facing +x whose nose and ears make an upright head 1.6 m high, metres."""
    pose = _person(rng, offset) * [1, 1, 0.2]
    ears = np.array([offset[0], offset[1], 1.6])
    pose[COCO17.index("left_ear")], pose[COCO17.index("right_ear")] = ears + [0, 0.078, 0], ears - [0, 0.078, 0]
    pose[COCO17.index("nose")] = ears + [0.105, 0, -0.015]
    pose[COCO17.index("left_shoulder")], pose[COCO17.index("right_shoulder")] = ears + [0, 0.18, -0.27], \
        ears - [0, 0.18, 0.27]
    return pose


def test_the_truth_head_convention_applies_to_the_truth_only_and_pcp_alone(rng):
    truth = np.stack([_upright(rng, (0, 0)), _upright(rng, (3, 0))])
    estimate = truth.copy()
    estimate[:, COCO17.index("nose")] += [0.1, 0.0, 0.0]  # each estimate's nose 10 cm ahead of the true one
    evaluate, annotated = PoseAccumulator(), PoseAccumulator(truth_head=HEAD)
    for acc in (evaluate, annotated):
        acc.update(np.array([1, 2]), truth, estimate)
    a, e = annotated.result(), evaluate.result()
    # The estimate is mapped by evaluate.py's factors against a truth on the head: PCP is that comparison ...
    expected = [pcp_bones(coco17_to_campus14(estimate[g]), coco17_to_campus14(truth[g], HEAD)) for g in range(2)]
    assert a.pcp == pytest.approx(np.mean(expected))
    head = PCP_BONE_GROUPS["head"][0]
    assert a.pcp_per_group["head"] == pytest.approx(np.mean([bones[head] for bones in expected]))
    # ... in which evaluate.py's head, low and forward of the true one, misses where the same mapping on both
    # sides would have forgiven the nose's error ...
    assert e.pcp_per_group["head"] == 1.0 and a.pcp_per_group["head"] == 0.0
    assert a.pcp_per_group["torso"] == e.pcp_per_group["torso"] == 1.0
    # ... while MPJPE and PCK compare the COCO-17 joints as they are.
    assert (a.mpjpe_mm, a.pck) == (e.mpjpe_mm, e.pck)


def test_a_14_joint_truth_is_never_mapped_again(rng):
    """A dataset's annotated truth (CAMPUS14) already has its head joints: a head convention leaves it alone."""
    truth = np.stack([coco17_to_campus14(_upright(rng, (0, 0)))])
    estimate = truth + rng.normal(0.0, 0.02, truth.shape)
    plain, with_head = PoseAccumulator(skeleton=CAMPUS14), PoseAccumulator(skeleton=CAMPUS14, truth_head=HEAD)
    for acc in (plain, with_head):
        acc.update(np.array([1]), truth, estimate)
    assert with_head.result() == plain.result()
    assert plain.result().pcp == pytest.approx(pcp_bones(estimate[0], truth[0]).mean())
