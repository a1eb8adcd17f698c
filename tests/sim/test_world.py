"""The store world: the advance contract, body properties over a simulated minute, ray casts and errors."""

import dataclasses

import mujoco
import numpy as np
import pytest

from core.errors import ScenarioError
from core.types import COCO17
from sim import humanoid as hm
from sim import scenario as sc
from sim.crowd import CrowdConfig
from sim.rng import child_rng
from sim.store import ShelfConfig, rect_distance
from sim.world import World

RATE_HZ = 50.0
# The rigid COCO bones: limb segments and the shoulder and hip girdles (the torso diagonals bend with the spine).
RIGID_BONES = ((5, 7), (7, 9), (6, 8), (8, 10), (11, 13), (13, 15), (12, 14), (14, 16), (5, 6), (11, 12),
               (0, 1), (0, 2), (1, 3), (2, 4))


def _world(name="store_layout2", seed=0, **crowd) -> World:
    scenario = sc.load(name)
    if crowd:
        scenario = dataclasses.replace(scenario, crowd=dataclasses.replace(scenario.crowd, **crowd))
    return World(scenario, child_rng(seed, "crowd"))


@pytest.fixture(scope="module")
def minute():
    """60 s of store_layout2 at 50 Hz: per tick the truth, the hinge angles and the geom owners."""
    world = _world(mean_visit_s=30.0, mean_arrival_gap_s=3.0)
    ticks = []
    for k in range(int(60 * RATE_HZ) + 1):
        truth = world.advance(k / RATE_HZ)
        ticks.append((truth, world.data.qpos.copy()))
    return world, ticks


def test_advance_returns_coco_keypoints_of_everybody_present(minute):
    world, ticks = minute
    assert world.skeleton is COCO17
    for truth, _ in ticks[::50]:
        assert truth.poses.shape == (len(truth.person_ids), 17, 3)
        assert np.all(np.diff(truth.person_ids) > 0)  # unique, ascending
        assert np.isfinite(truth.poses).all()


def test_people_come_and_go_and_ids_are_never_reused(minute):
    world, ticks = minute
    assert world.crowd.arrivals > 0 and world.crowd.departures > 0
    seen_last = {}
    for k, (truth, _) in enumerate(ticks):
        for pid in truth.person_ids.tolist():
            if pid in seen_last:
                assert seen_last[pid] == k - 1, f"person {pid} came back after leaving"
            seen_last[pid] = k


def test_nobody_walks_through_anybody_or_any_shelf(minute):
    world, ticks = minute
    lh, rh = COCO17.index("left_hip"), COCO17.index("right_hip")
    for truth, _ in ticks:
        pelvis = (truth.poses[:, lh, :2] + truth.poses[:, rh, :2]) / 2
        d = np.linalg.norm(pelvis[:, None] - pelvis[None], axis=-1)
        np.fill_diagonal(d, np.inf)
        assert d.min() >= 0.4  # m
        for ob in world.store.obstacles:
            assert rect_distance(pelvis, ob.center, ob.half, ob.yaw).min() >= 0.25  # m


def test_bone_lengths_stay_constant_to_a_millimetre(minute):
    _, ticks = minute
    a, b = np.array(RIGID_BONES).T
    lengths: dict[int, list[np.ndarray]] = {}
    for truth, _ in ticks:
        bones = np.linalg.norm(truth.poses[:, a] - truth.poses[:, b], axis=-1)  # (P, bones)
        for pid, row in zip(truth.person_ids.tolist(), bones):
            lengths.setdefault(pid, []).append(row)
    for pid, rows in lengths.items():
        assert np.ptp(np.array(rows), axis=0).max() < 1e-3, f"person {pid}"  # m


def test_every_joint_angle_stays_in_its_range(minute):
    world, ticks = minute
    m = world.model
    hinge = m.jnt_type == mujoco.mjtJoint.mjJNT_HINGE
    adr = m.jnt_qposadr[hinge]
    lo, hi = m.jnt_range[hinge, 0], m.jnt_range[hinge, 1]
    for _, qpos in ticks:
        angles = qpos[adr]
        assert np.all(angles >= lo - 1e-9) and np.all(angles <= hi + 1e-9)


def test_feet_in_stance_stay_planted(minute):
    world, ticks = minute
    la, ra = COCO17.index("left_ankle"), COCO17.index("right_ankle")
    speeds = []
    for (a, _), (b, _) in zip(ticks[:-1], ticks[1:]):
        common, ia, ib = np.intersect1d(a.person_ids, b.person_ids, return_indices=True)
        for pid, i, j in zip(common.tolist(), ia, ib):
            rest = hm.ANKLE_HEIGHT * world.height_m(pid)
            for k in (la, ra):
                # A foot is in stance when its ankle is within 1 cm of its standing height.
                if a.poses[i, k, 2] < rest + 0.01 and b.poses[j, k, 2] < rest + 0.01:
                    speeds.append(np.linalg.norm(b.poses[j, k, :2] - a.poses[i, k, :2]) * RATE_HZ)
    assert len(speeds) > 1000
    assert np.mean(speeds) <= 0.15  # m/s


def test_people_walk_at_human_speeds(minute):
    world, ticks = minute
    lh, rh = COCO17.index("left_hip"), COCO17.index("right_hip")
    step = int(RATE_HZ)  # 1 s apart
    fastest = 0.0
    for (a, _), (b, _) in zip(ticks[:-step:step], ticks[step::step]):
        common, ia, ib = np.intersect1d(a.person_ids, b.person_ids, return_indices=True)
        pa = (a.poses[ia, lh, :2] + a.poses[ia, rh, :2]) / 2
        pb = (b.poses[ib, lh, :2] + b.poses[ib, rh, :2]) / 2
        if len(common):
            fastest = max(fastest, np.linalg.norm(pb - pa, axis=1).max())
    assert 0.6 < fastest < 1.8  # m/s


def test_same_seed_same_poses_whatever_the_call_pattern():
    # One world asked at 100 Hz, another at irregular times in between: poses agree bit for bit.
    a, b = _world(), _world()
    rng = np.random.default_rng(5)
    times_b = np.sort(rng.uniform(0, 5, 120))
    poses_a = {k: a.advance(k / 100) for k in range(501)}
    for t in times_b:
        b.advance(float(t))
    c = _world()
    for t in np.concatenate([times_b[:60], [2.5]]):
        last = c.advance(float(t))
    np.testing.assert_array_equal(last.poses, poses_a[250].poses)
    np.testing.assert_array_equal(last.person_ids, poses_a[250].person_ids)


def test_other_seed_other_motion():
    a = _world(seed=0).advance(3.0)
    b = _world(seed=1).advance(3.0)
    assert not np.array_equal(a.poses, b.poses)


def test_time_must_not_go_back():
    world = _world()
    world.advance(1.0)
    with pytest.raises(ValueError, match="t_s"):
        world.advance(0.5)


def test_geom_owners_match_what_a_ray_hits():
    world = _world()
    truth = world.advance(7.3)
    owners = world.geom_person_ids()
    bodies = world.geom_body_ids()
    nose = COCO17.index("nose")
    geomid = np.array([-1], dtype=np.int32)
    hits = 0
    for pid, pose in zip(truth.person_ids, truth.poses):
        # A ray straight down onto the top of the head hits that person's head.
        start = pose[nose] + np.array([0.0, 0.0, 0.6])
        mujoco.mj_ray(world.model, world.data, start, np.array([0.0, 0.0, -1.0]), None, 1, -1, geomid)
        if owners[geomid[0]] == pid:
            hits += 1
            assert bodies[geomid[0]] == hm.B["head"]
    assert hits >= len(truth.person_ids) - 2  # a reaching arm above someone else's head may come first
    assert np.all(owners[bodies < 0] == -1)


def test_absent_people_are_parked_where_no_ray_reaches():
    world = _world("store_layout1", start_inside=False)
    truth = world.advance(0.0)
    assert len(truth.person_ids) == 0
    assert np.all(world.geom_person_ids() == -1)
    geomid = np.array([-1], dtype=np.int32)
    for x in np.linspace(0.2, 4.4, 8):
        for y in np.linspace(0.2, 3.6, 8):
            mujoco.mj_ray(world.model, world.data, np.array([x, y, 2.9]), np.array([0.1, -0.05, -1.0]),
                          None, 1, -1, geomid)
            assert world.geom_body_ids()[geomid[0]] == -1  # store geometry only


def test_keypoint_body_ids_name_the_bodies_the_sites_hang_on():
    world = _world("store_layout1")
    kb = world.keypoint_body_ids()
    sites = world._kp_sites[0]
    body_of_site = world.model.site_bodyid[sites]
    np.testing.assert_array_equal(world._body_local[body_of_site], kb)
    # The parent is the body one level up the kinematic tree.
    parents = world.model.body_parentid[body_of_site]
    np.testing.assert_array_equal(world._body_local[parents], world.keypoint_parent_body_ids())


def test_heights_are_those_of_the_scenario_or_drawn_in_range():
    world = _world("store_layout1", heights_m=(1.52, 1.93))
    world.advance(0.0)
    assert world.height_m(0) == 1.52 and world.height_m(1) == 1.93
    assert 1.50 <= world.height_m(2) <= 1.95
    truth = world.advance(0.0)
    nose_z = truth.poses[:2, 0, 2]
    assert nose_z[1] / nose_z[0] == pytest.approx(1.93 / 1.52, rel=0.05)


def test_overlapping_shelves_stop_the_world_with_the_key():
    scenario = sc.load("store_layout2")
    shelves = scenario.store.shelves + (ShelfConfig((4.6, 1.9), (1.0, 0.5, 1.5)),)
    bad = dataclasses.replace(scenario, store=dataclasses.replace(scenario.store, shelves=shelves))
    with pytest.raises(ScenarioError, match=r"store.shelves\[3\]: overlaps store.shelves\[0\]"):
        World(bad, child_rng(0, "crowd"))


def test_more_people_than_the_floor_holds_is_an_error():
    with pytest.raises(ScenarioError, match=r"crowd.people: 40 people need"):
        _world("store_layout1", people=40)


def test_a_body_height_outside_the_supported_range_is_an_error():
    with pytest.raises(ValueError, match=r"heights_m\[1\]: 2.3 must be in \[1\.4, 2\.1\] m"):
        CrowdConfig(people=3, heights_m=(1.7, 2.3))
    with pytest.raises(ScenarioError, match=r"crowd\] heights_m\[0\]"):
        sc.load("store_layout1", overrides={"crowd.heights_m": [1.2]})


def test_a_store_without_people_poses_nobody():
    world = _world("store_layout1", people=0)
    truth = world.advance(2.0)
    assert truth.poses.shape == (0, 17, 3)
    assert np.all(world.geom_person_ids() == -1)


def test_keypoints_are_mujocos_sites_after_its_own_kinematics():
    """advance computes the keypoints by its own forward kinematics and leaves MuJoCo's for when `data`
    is read: both must agree, through arrivals (resized slots) and interpolated ticks."""
    world = _world(mean_visit_s=20.0, mean_arrival_gap_s=2.0)
    worst = 0.0
    for k in range(0, 1500, 7):
        truth = world.advance(k / 25)
        data = world.data  # runs mj_kinematics for the pose just set
        slots = [int(np.nonzero(world.crowd.person_id == pid)[0][0]) for pid in truth.person_ids]
        reference = data.site_xpos[world._kp_sites[slots]].reshape(-1, 17, 3)
        worst = max(worst, float(np.abs(reference - truth.poses).max()) if slots else 0.0)
    assert worst < 1e-12


def test_ray_geom_constants_are_snapshots_shared_until_they_change():
    """`ray_geom_constants` equals the model's sizes, radii and the geom owners at every tick, cannot be
    written, and stays the same objects until a slot is resized or who is present changes."""
    world = _world("store_layout1", mean_visit_s=4.0, mean_arrival_gap_s=0.5)
    seen = []
    changes = 0
    for k in range(400):
        world.advance(k / 20.0)
        size, rbound, owner = world.ray_geom_constants()
        np.testing.assert_array_equal(size, world.model.geom_size)
        np.testing.assert_array_equal(rbound, world.model.geom_rbound)
        np.testing.assert_array_equal(owner, world.geom_person_ids())
        assert owner.dtype == np.int64 and not (size.flags.writeable or rbound.flags.writeable or owner.flags.writeable)
        if seen:
            same = np.array_equal(seen[-1][0], size) and np.array_equal(seen[-1][2], owner)
            assert same == all(a is b for a, b in zip(seen[-1], (size, rbound, owner)))
            changes += not same
        seen.append((size, rbound, owner))
    # Earlier snapshots keep their values through later resizes.
    assert changes >= 5 and len({id(s[0]) for s in seen}) > 1
    first = seen[0]
    world2 = _world("store_layout1", mean_visit_s=4.0, mean_arrival_gap_s=0.5)
    world2.advance(0.0)
    np.testing.assert_array_equal(first[0], world2.model.geom_size)
    np.testing.assert_array_equal(first[2], world2.geom_person_ids())


def test_person_ids_are_one_array_while_the_same_people_are_present():
    """`advance` hands out the same person-id array, unchanged, for as long as nobody arrives or leaves (so a
    consumer tells two ticks with the same people by identity), and another one when someone does."""
    world = _world("store_layout1", mean_visit_s=4.0, mean_arrival_gap_s=0.5)
    seen = []
    for k in range(600):
        truth = world.advance(k / 20.0)
        seen.append((truth.person_ids, truth.person_ids.tolist()))
    changes = 0
    for (ids, values), (next_ids, next_values) in zip(seen, seen[1:]):
        assert (ids is next_ids) == (values == next_values)
        changes += values != next_values
    assert changes >= 5
    assert all(ids.tolist() == values for ids, values in seen)  # nobody wrote into a shared one
