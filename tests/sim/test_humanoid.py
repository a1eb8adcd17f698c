"""Parametric humanoid: model structure, proportions, and the leg inverse kinematics against MuJoCo's own FK."""

import math

import mujoco
import numpy as np
import pytest

from core.types import COCO17
from sim import humanoid as hm
from tests.reference.humanoid import leg_ik


def _model(height_m: float) -> tuple[mujoco.MjModel, mujoco.MjData]:
    model = mujoco.MjModel.from_xml_string(hm.standalone_xml(height_m))
    return model, mujoco.MjData(model)


def _keypoints(model, data) -> np.ndarray:
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, f"p_{n}") for n in hm.KEYPOINT_NAMES]
    return data.site_xpos[ids].copy()


def test_structure_free_pelvis_hinges_with_ranges_and_coco_sites():
    model, _ = _model(1.75)
    assert model.nbody - 1 == len(hm.BODIES)
    assert model.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE
    assert model.nq == hm.NQ
    assert all(model.jnt_type[1:] == mujoco.mjtJoint.mjJNT_HINGE)
    assert model.jnt_limited[1:].all()
    np.testing.assert_array_equal(model.jnt_range[1:], hm.HINGE_RANGES)
    assert hm.KEYPOINT_NAMES == COCO17.joints
    geom_types = {int(g) for g in model.geom_type}
    assert geom_types == {int(mujoco.mjtGeom.mjGEOM_CAPSULE), int(mujoco.mjtGeom.mjGEOM_ELLIPSOID)}


@pytest.mark.parametrize("height", [1.50, 1.75, 1.95])
def test_standing_pose_has_human_proportions(height):
    model, data = _model(height)
    mujoco.mj_kinematics(model, data)
    kp = _keypoints(model, data)
    z = kp[:, 2] / height
    j = COCO17.index
    assert 0.90 < z[j("nose")] < 0.95  # nose at ~0.92 H
    assert 0.80 < z[j("left_shoulder")] < 0.84  # shoulders at ~0.82 H (Winter)
    assert 0.50 < z[j("left_hip")] < 0.55  # hip joints at ~0.53 H
    assert 0.27 < z[j("left_knee")] < 0.30  # knees at ~0.285 H
    assert 0.03 < z[j("left_ankle")] < 0.05  # ankles at ~0.039 H
    # The top of the head (the highest geom point) is the body height within 2 cm.
    top = max(data.geom_xpos[g, 2] + model.geom_size[g, 2] for g in range(model.ngeom)
              if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_ELLIPSOID and model.body(model.geom_bodyid[g]).name
              == "p_head")
    assert abs(top - height) < 0.02
    # The feet stand on the floor.
    foot = [g for g in range(model.ngeom) if model.body(model.geom_bodyid[g]).name.endswith("_foot")]
    bottoms = [data.geom_xpos[g, 2] - model.geom_size[g, 2] for g in foot]
    np.testing.assert_allclose(bottoms, 0.0, atol=0.005)  # m


def test_every_length_scales_with_height():
    kp_a = _keypoints(*_fk(_model(1.6)))
    kp_b = _keypoints(*_fk(_model(1.9)))
    np.testing.assert_allclose(kp_b, kp_a * (1.9 / 1.6), atol=1e-9)


def _fk(md):
    mujoco.mj_kinematics(*md)
    return md


def test_keypoint_body_table_matches_the_model():
    model, _ = _model(1.75)
    for k, name in enumerate(hm.KEYPOINT_NAMES):
        site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, f"p_{name}")
        assert model.body(model.site_bodyid[site]).name == f"p_{hm.BODIES[hm.KEYPOINT_BODY[k]]}"
        assert model.site_bodyid[site] - 1 == hm.KEYPOINT_BODY[k]  # body index within the humanoid


@pytest.mark.parametrize("side,sign", [("left", 1.0), ("right", -1.0)])
def test_leg_ik_puts_the_ankle_on_target_in_mujoco(side, sign):
    height = 1.8
    model, data = _model(height)
    rng = np.random.default_rng(3)
    hip_site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, f"p_{side}_hip")
    ankle_site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, f"p_{side}_ankle")
    adr = {n: model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, f"p_{side}_{n}")]
           for n in ("hip_abd", "hip_flex", "knee")}
    thigh, shin = hm.THIGH * height, hm.SHIN * height
    for _ in range(50):
        # Targets a walking foot could have: below the hip, some forward/back, some sideways.
        d = np.array([rng.uniform(-0.35, 0.35), sign * rng.uniform(-0.05, 0.15), -rng.uniform(0.6, 0.85)])
        abd, flex, knee = leg_ik(d, np.float64(thigh), np.float64(shin), sign)
        data.qpos[:] = 0
        data.qpos[3] = 1.0
        data.qpos[2] = 1.0
        data.qpos[adr["hip_abd"]], data.qpos[adr["hip_flex"]], data.qpos[adr["knee"]] = abd, flex, knee
        mujoco.mj_kinematics(model, data)
        if np.linalg.norm(d) < (thigh + shin) * hm.MAX_LEG_STRETCH:
            np.testing.assert_allclose(data.site_xpos[ankle_site] - data.site_xpos[hip_site], d, atol=1e-9)
            assert 0 <= knee <= math.pi


def test_heights_come_from_an_adult_distribution_within_bounds():
    h = hm.sample_heights(np.random.default_rng(0), 4000, 1.50, 1.95)
    assert h.min() >= 1.50 and h.max() <= 1.95
    assert 1.66 < h.mean() < 1.73  # mix of women (1.63) and men (1.76)
    assert 0.07 < h.std() < 0.11
