"""Parametric humanoids: MJCF generated in code, COCO-17 keypoint sites, and pose targets to joint angles.

Body frame: a person faces +x, +y is their left, +z up. Every length and size is proportional to the
body height (segment fractions after Winter, "Biomechanics and Motor Control of Human Movement"), so a
person of height H is the 1.75 m reference scaled by H / 1.75; `World` resizes a body slot that way
when a new person takes it.

Hinges, in qpos order after the free pelvis joint (angles in radians, positive as named):
spine flex/lateral/twist, neck flex/twist, head nod/tilt, per arm (left then right) shoulder
flex/abduction/rotation, elbow flex, wrist flex, per leg (left then right) hip abduction/flex/rotation,
knee flex, ankle plantarflex. Ranges are human active ranges of motion.
"""

from __future__ import annotations

import numpy as np

from core.head import HeadPoints

REFERENCE_HEIGHT_M = 1.75
# Heights a body can be built for; scenario heights outside are rejected.
SUPPORTED_HEIGHT_M = (1.40, 2.10)

# Bodies of one humanoid in MuJoCo's depth-first order (the index is what `keypoint_body_ids` returns).
BODIES = (
    "pelvis", "torso", "neck", "head",
    "left_upper_arm", "left_forearm", "left_hand",
    "right_upper_arm", "right_forearm", "right_hand",
    "left_thigh", "left_shin", "left_foot",
    "right_thigh", "right_shin", "right_foot",
)
B = {name: i for i, name in enumerate(BODIES)}

# (name, body, axis for the left side (right side mirrors x), (min, max) radians).
HINGES = (
    ("spine_flex", "torso", (0, 1, 0), (-0.4, 1.0)),
    ("spine_lateral", "torso", (1, 0, 0), (-0.4, 0.4)),
    ("spine_twist", "torso", (0, 0, 1), (-0.6, 0.6)),
    ("neck_flex", "neck", (0, 1, 0), (-0.6, 0.8)),
    ("neck_twist", "neck", (0, 0, 1), (-1.2, 1.2)),
    ("head_nod", "head", (0, 1, 0), (-0.4, 0.4)),
    ("head_tilt", "head", (1, 0, 0), (-0.4, 0.4)),
    *(
        item
        for side in ("left", "right")
        for item in (
            (f"{side}_shoulder_flex", f"{side}_upper_arm", (0, -1, 0), (-0.8, 3.0)),
            (f"{side}_shoulder_abd", f"{side}_upper_arm", (1, 0, 0), (-0.3, 2.5)),
            (f"{side}_shoulder_rot", f"{side}_upper_arm", (0, 0, 1), (-1.0, 1.0)),
            (f"{side}_elbow", f"{side}_forearm", (0, -1, 0), (0.0, 2.5)),
            (f"{side}_wrist", f"{side}_hand", (0, -1, 0), (-1.2, 1.2)),
        )
    ),
    *(
        item
        for side in ("left", "right")
        for item in (
            (f"{side}_hip_abd", f"{side}_thigh", (1, 0, 0), (-0.5, 0.8)),
            (f"{side}_hip_flex", f"{side}_thigh", (0, -1, 0), (-0.5, 2.0)),
            (f"{side}_hip_rot", f"{side}_thigh", (0, 0, 1), (-0.7, 0.7)),
            (f"{side}_knee", f"{side}_shin", (0, 1, 0), (0.0, 2.4)),
            (f"{side}_ankle", f"{side}_foot", (0, 1, 0), (-0.45, 0.85)),
        )
    ),
)
J = {name: i for i, (name, *_) in enumerate(HINGES)}
NUM_HINGES = len(HINGES)
HINGE_RANGES = np.array([h[3] for h in HINGES])  # (27, 2)
# qpos per humanoid: free joint (3 position + 4 quaternion) then the hinges.
NQ = 7 + NUM_HINGES

# COCO-17 keypoint sites: (body, offset in the body frame at the reference height).
KEYPOINTS = (
    ("head", (0.105, 0.0, 0.07)),  # nose
    ("head", (0.085, 0.032, 0.10)),  # left eye
    ("head", (0.085, -0.032, 0.10)),  # right eye
    ("head", (0.0, 0.078, 0.085)),  # left ear
    ("head", (0.0, -0.078, 0.085)),  # right ear
    ("left_upper_arm", (0, 0, 0)),
    ("right_upper_arm", (0, 0, 0)),
    ("left_forearm", (0, 0, 0)),
    ("right_forearm", (0, 0, 0)),
    ("left_hand", (0, 0, 0)),
    ("right_hand", (0, 0, 0)),
    ("left_thigh", (0, 0, 0)),
    ("right_thigh", (0, 0, 0)),
    ("left_shin", (0, 0, 0)),
    ("right_shin", (0, 0, 0)),
    ("left_foot", (0, 0, 0)),
    ("right_foot", (0, 0, 0)),
)
KEYPOINT_NAMES = (
    "nose", "left_eye", "right_eye", "left_ear", "right_ear",
    "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
    "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle",
)
# (17,) index in BODIES of the body each keypoint site hangs on.
KEYPOINT_BODY = np.array([B[body] for body, _ in KEYPOINTS], dtype=np.int64)
# (17,) index in BODIES of the parent of that body (a joint keypoint is also inside the parent's geom).
PARENT = {"pelvis": -1, "torso": "pelvis", "neck": "torso", "head": "neck",
          "left_upper_arm": "torso", "left_forearm": "left_upper_arm", "left_hand": "left_forearm",
          "right_upper_arm": "torso", "right_forearm": "right_upper_arm", "right_hand": "right_forearm",
          "left_thigh": "pelvis", "left_shin": "left_thigh", "left_foot": "left_shin",
          "right_thigh": "pelvis", "right_shin": "right_thigh", "right_foot": "right_shin"}
KEYPOINT_PARENT_BODY = np.array([B[PARENT[body]] for body, _ in KEYPOINTS], dtype=np.int64)

# Segment lengths as fractions of the height (Winter's anthropometry).
ANKLE_HEIGHT = 0.039
SHIN = 0.246
THIGH = 0.245
HIP_HEIGHT = ANKLE_HEIGHT + SHIN + THIGH  # 0.530: hip joint centre above the floor, standing
HIP_HALF_WIDTH = 0.05
# Knee flex of a standing person, as a fraction of the straight-leg hip height.
STAND_HIP_FRACTION = 0.985
LUMBAR_ABOVE_HIP = 0.07
SHOULDER_ABOVE_LUMBAR = 0.218
SHOULDER_HALF_WIDTH = 0.105
NECK_ABOVE_LUMBAR = 0.23
NECK_LENGTH = 0.045
UPPER_ARM = 0.186
FOREARM = 0.146
# The skull: an ellipsoid in the head body's frame (origin at the top of the neck), metres at the reference height.
HEAD_CENTRE_M = (0.01, 0.0, 0.095)
HEAD_RADII_M = (0.1, 0.078, 0.115)
# Fraction of a leg's full reach the gait lets it stretch to (a knee is never locked straight).
MAX_LEG_STRETCH = 0.995


def _v(*xs: float) -> str:
    return " ".join(f"{x:.12g}" for x in xs)


def _annotated_head() -> HeadPoints:
    """The head joints of the Campus/Shelf annotations on this head: the bottom of the head at the head body's
    origin (where the neck ends and the head turns: the base of the skull, at the level of the chin), the top
    at the vertex of the skull (the top of its ellipsoid), both in the frame of the nose and ear sites."""
    sites = {name: np.array(offset) for name, (body, offset) in zip(KEYPOINT_NAMES, KEYPOINTS) if body == "head"}
    vertex = np.array(HEAD_CENTRE_M) + np.array([0.0, 0.0, HEAD_RADII_M[2]])
    return HeadPoints.of(np.zeros(3), vertex, sites["nose"], sites["left_ear"], sites["right_ear"])


ANNOTATED_HEAD = _annotated_head()
"""Bottom and top of the head as the datasets annotate them, in the nose-ear frame (`core.head`); the same for
every height, since the whole body scales."""


def humanoid_xml(prefix: str, height_m: float = REFERENCE_HEIGHT_M) -> str:
    """MJCF `<body>` of one humanoid with a free pelvis, standing at the origin facing +x.

    The enclosing model must use `<compiler angle="radian"/>` (joint ranges are in radians).

    Args:
        prefix: prepended to every body, joint, geom and site name (for example "p3_").
        height_m: body height; every length scales with it.
    """
    H = height_m
    s = H / REFERENCE_HEIGHT_M
    P = prefix

    def hinge(name: str) -> str:
        _, _, axis, rng = HINGES[J[name]]
        if name.startswith("right_") and axis[0]:
            axis = (-axis[0], axis[1], axis[2])
        return f'<joint name="{P}{name}" type="hinge" axis="{_v(*axis)}" range="{_v(*rng)}" limited="true"/>'

    def sites(body: str) -> str:
        out = []
        for name, (b, off) in zip(KEYPOINT_NAMES, KEYPOINTS):
            if b == body:
                out.append(f'<site name="{P}{name}" pos="{_v(*(np.array(off) * s))}" size="{0.01 * s:.12g}"/>')
        return "".join(out)

    def arm(side: str, sign: float) -> str:
        return (
            f'<body name="{P}{side}_upper_arm" '
            f'pos="{_v(0, sign * SHOULDER_HALF_WIDTH * H, SHOULDER_ABOVE_LUMBAR * H)}">'
            + hinge(f"{side}_shoulder_flex") + hinge(f"{side}_shoulder_abd") + hinge(f"{side}_shoulder_rot")
            + f'<geom type="capsule" fromto="{_v(0, 0, 0, 0, 0, -UPPER_ARM * H)}" size="{0.045 * s:.12g}"/>'
            + sites(f"{side}_upper_arm")
            + f'<body name="{P}{side}_forearm" pos="{_v(0, 0, -UPPER_ARM * H)}">' + hinge(f"{side}_elbow")
            + f'<geom type="capsule" fromto="{_v(0, 0, 0, 0, 0, -FOREARM * H)}" size="{0.037 * s:.12g}"/>'
            + sites(f"{side}_forearm")
            + f'<body name="{P}{side}_hand" pos="{_v(0, 0, -FOREARM * H)}">' + hinge(f"{side}_wrist")
            + f'<geom type="ellipsoid" pos="{_v(0, 0, -0.08 * s)}" size="{_v(0.045 * s, 0.02 * s, 0.085 * s)}"/>'
            + sites(f"{side}_hand")
            + "</body></body></body>"
        )

    def leg(side: str, sign: float) -> str:
        return (
            f'<body name="{P}{side}_thigh" pos="{_v(0, sign * HIP_HALF_WIDTH * H, 0)}">'
            + hinge(f"{side}_hip_abd") + hinge(f"{side}_hip_flex") + hinge(f"{side}_hip_rot")
            + f'<geom type="capsule" fromto="{_v(0, 0, -0.03 * s, 0, 0, -THIGH * H)}" size="{0.075 * s:.12g}"/>'
            + sites(f"{side}_thigh")
            + f'<body name="{P}{side}_shin" pos="{_v(0, 0, -THIGH * H)}">' + hinge(f"{side}_knee")
            + f'<geom type="capsule" fromto="{_v(0, 0, 0, 0, 0, -SHIN * H)}" size="{0.05 * s:.12g}"/>'
            + sites(f"{side}_shin")
            + f'<body name="{P}{side}_foot" pos="{_v(0, 0, -SHIN * H)}">' + hinge(f"{side}_ankle")
            + f'<geom type="ellipsoid" pos="{_v(0.08 * s, 0, -0.035 * s)}" '
            f'size="{_v(0.13 * s, 0.045 * s, 0.033 * s)}"/>'
            + sites(f"{side}_foot")
            + "</body></body></body>"
        )

    return (
        f'<body name="{P}pelvis" pos="{_v(0, 0, HIP_HEIGHT * H)}">'
        f'<freejoint name="{P}root"/>'
        f'<geom type="capsule" fromto="{_v(0, -0.085 * s, 0.03 * s, 0, 0.085 * s, 0.03 * s)}" size="{0.095 * s:.12g}"/>'
        f'<body name="{P}torso" pos="{_v(0, 0, LUMBAR_ABOVE_HIP * H)}">'
        + hinge("spine_flex") + hinge("spine_lateral") + hinge("spine_twist")
        + f'<geom type="ellipsoid" pos="{_v(0, 0, 0.21 * s)}" size="{_v(0.11 * s, 0.16 * s, 0.23 * s)}"/>'
        + f'<body name="{P}neck" pos="{_v(0, 0, NECK_ABOVE_LUMBAR * H)}">' + hinge("neck_flex") + hinge("neck_twist")
        + f'<geom type="capsule" fromto="{_v(0, 0, -0.02 * s, 0, 0, NECK_LENGTH * H)}" size="{0.05 * s:.12g}"/>'
        + f'<body name="{P}head" pos="{_v(0, 0, NECK_LENGTH * H)}">' + hinge("head_nod") + hinge("head_tilt")
        + f'<geom type="ellipsoid" pos="{_v(*np.multiply(HEAD_CENTRE_M, s))}" '
        f'size="{_v(*np.multiply(HEAD_RADII_M, s))}"/>'
        + sites("head")
        + "</body></body>"
        + arm("left", 1.0) + arm("right", -1.0)
        + "</body>"
        + leg("left", 1.0) + leg("right", -1.0)
        + "</body>"
    )


def standalone_xml(height_m: float = REFERENCE_HEIGHT_M, prefix: str = "p_") -> str:
    """A complete MJCF model with one humanoid (angles in radians, as `humanoid_xml` assumes)."""
    return (f'<mujoco><compiler angle="radian"/><default><geom contype="0" conaffinity="0"/></default>'
            f"<worldbody>{humanoid_xml(prefix, height_m)}</worldbody></mujoco>")


def standing_keypoints(height_m: float = REFERENCE_HEIGHT_M) -> np.ndarray:
    """(17, 3) COCO-17 keypoints (`KEYPOINT_NAMES` order) of a person of `height_m` standing upright with the
    arms hanging (every hinge at zero), the pelvis above the origin, facing +x, feet on the floor: the body
    itself, placed by MuJoCo's forward kinematics, for what asks where a person's joints are without a crowd
    (`crossview.measure.coverage`)."""
    import mujoco

    prefix = "p_"
    model = mujoco.MjModel.from_xml_string(standalone_xml(height_m, prefix))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    points = np.array([data.site(prefix + name).xpos for name in KEYPOINT_NAMES])
    points[:, :2] -= data.body(prefix + "pelvis").xpos[:2]
    points[:, 2] -= points[:, 2].min() - ANKLE_HEIGHT * height_m
    return points


def sample_heights(rng: np.random.Generator, n: int, low_m: float, high_m: float) -> np.ndarray:
    """(n,) adult heights: an even mix of women N(1.63, 0.065) and men N(1.76, 0.07) m, redrawn outside [low, high]."""
    out = np.empty(n)
    for k in range(n):
        mean, std = (1.63, 0.065) if rng.random() < 0.5 else (1.76, 0.07)
        h = rng.normal(mean, std)
        while not low_m <= h <= high_m:
            h = rng.normal(mean, std)
        out[k] = h
    return out
