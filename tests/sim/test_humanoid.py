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


def _quaternion(axis, angle_rad: float) -> np.ndarray:
    axis = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    return np.concatenate([[math.cos(angle_rad / 2)], math.sin(angle_rad / 2) * axis])


# Head poses: (root turn about z, root lean axis and angle, hinge angles in radians).
HEAD_POSES = [
    (0.0, (1, 0, 0), 0.0, {}),  # upright, facing +x
    (1.1, (1, 0, 0), 0.0, {"neck_twist": 0.9, "head_tilt": 0.35}),  # turned and tilted sideways
    (-2.4, (0, 1, 0), 0.3, {"neck_flex": 0.7, "head_nod": 0.4}),  # leaning, looking down
    (0.5, (1, 1, 0), -0.25, {"neck_flex": -0.5, "neck_twist": -1.1, "head_nod": -0.35, "head_tilt": -0.3,
                              "spine_flex": 0.6, "spine_twist": 0.4}),  # looking up over the shoulder, bent
]


@pytest.mark.parametrize("height", [1.45, 1.75, 2.05])
def test_the_annotated_head_joints_are_the_neck_top_and_the_skull_vertex_in_every_head_pose(height):
    """`ANNOTATED_HEAD` places the bottom of the head at the head body's origin (the top of the neck) and the
    top at the vertex of the skull geom, found by MuJoCo's kinematics, from the nose and ear sites alone."""
    model, data = _model(height)
    head = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "p_head")
    skull = next(g for g in range(model.ngeom) if model.geom_bodyid[g] == head)
    for turn_rad, lean_axis, lean_rad, hinges in HEAD_POSES:
        data.qpos[:] = model.qpos0
        q = np.zeros(4)
        mujoco.mju_mulQuat(q, _quaternion((0, 0, 1), turn_rad), _quaternion(lean_axis, lean_rad))
        data.qpos[3:7] = q
        for name, angle in hinges.items():
            data.qpos[7 + hm.J[name]] = angle
        mujoco.mj_forward(model, data)
        base = data.xpos[head]
        vertex = data.geom_xpos[skull] + data.geom_xmat[skull].reshape(3, 3) @ [0.0, 0.0, model.geom_size[skull, 2]]
        np.testing.assert_allclose(hm.ANNOTATED_HEAD.locate(_keypoints(model, data)), [base, vertex],
                                   atol=1e-3)  # m
        # The head bone of the annotations: about 0.21 m at the reference height, scaling with the body.
        assert np.linalg.norm(vertex - base) == pytest.approx(0.2102 * height / hm.REFERENCE_HEIGHT_M, abs=1e-3)
