"""Arms, gaze and weight: the reach against MuJoCo's own kinematics, and the motion a crowd makes with them."""

import dataclasses

import mujoco
import numpy as np
import pytest

from sim import gestures as gs
from sim import humanoid as hm
from sim import scenario as sc
from sim.crowd import STEP_S
from sim.limb_speeds import LimbSpeeds
from sim.rng import child_rng
from sim.types import Activity
from sim.world import World


def _site(model, name):
    return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, f"p_{name}")


def _joint(model, name):
    return model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, f"p_{name}")]


@pytest.mark.parametrize("height", [1.55, 1.75, 1.95])
def test_a_reach_puts_the_wrist_on_the_target_in_mujoco(height):
    model = mujoco.MjModel.from_xml_string(hm.standalone_xml(height))
    data = mujoco.MjData(model)
    wrist = _site(model, "left_wrist")
    for target_m in np.linspace(0.35, 1.85, 11):
        for forward_m in (gs.REACH_FORWARD_M, gs.REACH_FORWARD_M + gs.REACH_DEPTH_M):
            arm, spine, neck = gs.reach_pose(height, float(target_m), forward_m)
            # A standing person facing +x, pelvis at the standing hip height, the left arm reaching.
            data.qpos[:] = 0.0
            data.qpos[2] = hm.HIP_HEIGHT * hm.STAND_HIP_FRACTION * height
            data.qpos[3] = 1.0
            data.qpos[_joint(model, "spine_flex")] = spine
            for name, angle in zip(("shoulder_flex", "shoulder_abd", "shoulder_rot", "elbow", "wrist"), arm):
                data.qpos[_joint(model, f"left_{name}")] = angle
            mujoco.mj_kinematics(model, data)
            a, b = hm.UPPER_ARM * height, hm.FOREARM * height
            shoulder = data.site_xpos[_site(model, "left_shoulder")]
            goal = np.array([forward_m, shoulder[1], target_m])
            if np.linalg.norm(goal - shoulder) < 0.98 * (a + b):
                np.testing.assert_allclose(data.site_xpos[wrist], goal, atol=1e-9)  # m
            else:  # out of reach: the arm points at the target
                reach = data.site_xpos[wrist] - shoulder
                cos = reach @ (goal - shoulder) / np.linalg.norm(reach) / np.linalg.norm(goal - shoulder)
                assert cos > 1 - 1e-9
            lo, hi = hm.HINGE_RANGES[hm.J["left_shoulder_flex"]]
            assert lo <= arm[0] <= hi and 0.0 <= arm[3] <= hm.HINGE_RANGES[hm.J["left_elbow"], 1]
            # The trunk bends only for what lies low.
            assert (spine > 0) == (target_m < gs.BEND_BELOW_M)


@pytest.fixture(scope="module")
def store_minute():
    """60 s of store_layout2 at 25 Hz: per tick the truth, the activities and the gesture channels by person."""
    scenario = sc.load("store_layout2")
    world = World(scenario, child_rng(3, "crowd"))
    ticks = []
    for k in range(60 * 25 + 1):
        truth = world.advance(k / 25)
        doing = world.activities()
        slots = [int(np.nonzero(world.crowd.person_id == p)[0][0]) for p in truth.person_ids.tolist()]
        ticks.append((truth, np.array([doing[p] for p in truth.person_ids.tolist()], dtype=np.int64),
                      world.crowd.gestures.value[slots].copy()))
    return world, ticks


def test_standing_people_move_their_hands_and_walkers_swing_them(store_minute):
    _, ticks = store_minute
    speeds = LimbSpeeds(25.0)
    for truth, acts, _ in ticks:
        speeds.add(truth, acts == Activity.WALK)
    out = speeds.summary()
    # Real actors at a shelf: 0.14 m/s over one second; the issue asks for at least 0.1 m/s frame to frame.
    assert out["wrist_speed_standing_frame_median_m_s"] >= 0.1
    assert 0.07 < out["wrist_speed_standing_1s_median_m_s"] < 0.3
    assert out["wrist_speed_walking_1s_median_m_s"] > 2 * out["wrist_speed_standing_1s_median_m_s"]
    # Standing people shift their weight and take small steps (real actors at Shelf's shelf: hips at a median
    # 0.087 m/s over one second, p95 0.32; the issue asks for a median of at least 0.05 and a p95 of at most
    # 0.4); walking moves hips and feet far more.
    assert out["hip_speed_standing_1s_median_m_s"] >= 0.05
    assert out["hip_speed_standing_1s_p95_m_s"] <= 0.4
    assert out["hip_speed_walking_1s_median_m_s"] > 0.4 > out["hip_speed_standing_1s_p95_m_s"] / 2
    assert out["ankle_speed_walking_1s_median_m_s"] > 2 * out["ankle_speed_standing_1s_median_m_s"]


def test_standing_people_reach_look_and_shift_their_weight(store_minute):
    _, ticks = store_minute
    rows = np.concatenate([g[acts != Activity.WALK] for _, acts, g in ticks])
    # Someone reached up (a shoulder raised above the horizontal) and someone bent to a low shelf.
    assert np.max(rows[:, [gs.LEFT_ARM, gs.RIGHT_ARM]]) > np.pi / 2
    assert np.max(rows[:, gs.SPINE_FLEX]) > 0.2
    # Elbows bent to hold something in front of the chest.
    assert np.mean(rows[:, [gs.LEFT_ARM + 3, gs.RIGHT_ARM + 3]] > 1.2) > 0.1
    # Glances to both sides; weight shifts within their range, to both feet.
    assert rows[:, gs.NECK_TWIST].min() < -0.3 and rows[:, gs.NECK_TWIST].max() > 0.3
    assert np.abs(rows[:, gs.SHIFT]).max() <= gs.SHIFT_M[1] + 1e-12
    assert rows[:, gs.SHIFT].min() < -0.01 and rows[:, gs.SHIFT].max() > 0.01


def test_joint_angles_change_smoothly(store_minute):
    # No joint jumps: from one crowd step to the next (the channels change at steps, 2.5 ticks apart) no
    # channel moves faster than a fast human joint, about 10 rad/s.
    _, ticks = store_minute
    for (a, _, ga), (b, _, gb) in zip(ticks[:-1], ticks[1:]):
        if np.array_equal(a.person_ids, b.person_ids):
            jump = np.abs(gb - ga).max(axis=0)
            assert jump.max() < 10.0 * STEP_S, f"channel {jump.argmax()}"


def test_walkers_stop_on_the_way_and_vary_their_pace():
    def walking_speeds(**crowd):
        """Per step the speed of a lone walker (nobody to steer around) with more than 1.5 m of path left
        (no slowing for the goal), for 300 s, as a fraction of their preferred speed."""
        scenario = sc.load("store_layout2")
        scenario = dataclasses.replace(scenario, crowd=dataclasses.replace(scenario.crowd, people=1, **crowd))
        crowd = World(scenario, child_rng(1, "crowd")).crowd
        speeds = []
        for _ in range(3000):
            crowd.step()
            agent = crowd.agents[0]
            if agent.activity == Activity.WALK and agent.path:
                left = agent.rest[0] + np.hypot(*(np.array(agent.path[0]) - crowd.pos[0]))
                if left > 1.5 and not agent.in_door and not agent.leaving:
                    speeds.append(float(np.hypot(*crowd.vel[0]) / crowd.speed_pref[0]))
        return np.array(speeds)

    def stops(speeds):
        """Stops on the way: below 5 % of the preferred speed after cruising above half of it, for 0.5 s."""
        count, cruised, still = 0, False, 0
        for speed in speeds:
            cruised |= speed > 0.5
            still = still + 1 if speed < 0.05 else 0
            if cruised and still == 5:
                count, cruised = count + 1, False
        return count

    default = walking_speeds()
    steady = walking_speeds(pause_rate_hz=0.0, pace_range=(1.0, 1.0))
    assert stops(default) >= 3 and stops(steady) == 0
    # Cruising (not speeding up or slowing down), the steady walker keeps their preferred speed; the default
    # one's pace varies within `pace_range`.
    def cruising(speeds):
        keep = np.abs(np.diff(speeds)) < 0.005
        return speeds[1:][keep & (speeds[1:] > 0.5)]

    assert np.percentile(cruising(steady), [5, 95]) == pytest.approx([1.0, 1.0], abs=0.02)
    lo, hi = np.percentile(cruising(default), [5, 95])
    assert lo < 0.9 and hi > 1.03


def test_same_seed_same_gestures_other_seed_other():
    def channels(seed):
        world = World(sc.load("store_layout1"), child_rng(seed, "crowd"))
        world.advance(12.0)
        return world.crowd.gestures.value.copy()

    np.testing.assert_array_equal(channels(4), channels(4))
    assert not np.array_equal(channels(4), channels(5))


def test_limb_speeds_are_distances_over_the_span_and_split_by_activity():
    from core.records import PoseTruth

    speeds = LimbSpeeds(50.0)
    velocity = np.array([0.3, -0.4, 0.0])  # 0.5 m/s
    rest = np.zeros((17, 3))
    for k in range(151):
        t = k / 50
        # Person 1 walks at 0.5 m/s for 1.5 s then stands; person 2 stands still throughout.
        moving = rest + velocity * min(t, 1.5)
        truth = PoseTruth(t, np.array([1, 2]), np.stack([moving, rest]))
        speeds.add(truth, np.array([t <= 1.5, False]))
    out = speeds.summary()
    assert out["limb_speed_frame_s"] == 0.04 and out["limb_speed_window_s"] == 1.0
    for limb in ("wrist", "ankle", "hip"):
        for span in ("frame", "1s"):
            assert out[f"{limb}_speed_walking_{span}_median_m_s"] == pytest.approx(0.5, abs=1e-9)
            assert out[f"{limb}_speed_walking_{span}_p95_m_s"] == pytest.approx(0.5, abs=1e-9)
            # Spans across the change count as neither; standing after it is still.
            assert out[f"{limb}_speed_standing_{span}_p95_m_s"] == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(ValueError, match="rate_hz"):
        LimbSpeeds(30.0)
