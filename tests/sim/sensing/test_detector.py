"""The synthetic detector: visibility by ray casting, and every error effect following its knob."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from core.projection import in_image
from core.records import Capture, DetectionEffect, PoseTruth
from core.types import COCO17
from sim.cameras import CameraPlacement, CameraRigConfig, build_rig
from sim.scenario import Scenario
from sim.sensing.detector import Detector
from sim.sensing.draws import TEMPLATE_COCO17 as _TEMPLATE_COCO17
from sim.sensing.draws import person_size_px
from sim.sensing.profiles import DetectorConfig, DetectorProfile
from sim.store import StoreConfig
from tests.reference.detector import cast, detect, visibility, visibility_many
from tests.reference.rays import cast_visibility

# Bodies of the stand-in person (COCO-17 keypoint -> body): head, torso, arms, legs.
_PARTS = {"head": (0, 1, 2, 3, 4), "larm": (5, 7, 9), "rarm": (6, 8, 10), "lleg": (11, 13, 15),
          "rleg": (12, 14, 16)}


def _v(a) -> str:
    return " ".join(map(str, a))


def _cap(pose, a, b, r=0.06) -> str:
    return f'<geom type="capsule" size="{r}" fromto="{_v(pose[a])} {_v(pose[b])}"/>'


class BoxWorld:
    """A MuJoCo stand-in for sim.world.World: a shelf and capsule people at the template's joints."""

    def __init__(self, people_xy, shelf=((2.0, 1.5, 0.75), (0.25, 1.0, 0.75))):
        import mujoco

        self.poses = np.stack([_TEMPLATE_COCO17 + [x, y, 0.0] for x, y in people_xy])
        bodies = []
        for p, pose in enumerate(self.poses):
            torso_a, torso_b = (pose[11] + pose[12]) / 2, (pose[5] + pose[6]) / 2
            bodies.append(f"""
              <body name="p{p}_head"><geom type="sphere" size="0.11" pos="{_v(pose[0] - [0.06, 0, 0])}"/></body>
              <body name="p{p}_torso"><geom type="capsule" size="0.14" fromto="{_v(torso_a)} {_v(torso_b)}"/></body>
              <body name="p{p}_larm">{_cap(pose, 5, 7)}{_cap(pose, 7, 9)}</body>
              <body name="p{p}_rarm">{_cap(pose, 6, 8)}{_cap(pose, 8, 10)}</body>
              <body name="p{p}_lleg">{_cap(pose, 11, 13, 0.08)}{_cap(pose, 13, 15)}</body>
              <body name="p{p}_rleg">{_cap(pose, 12, 14, 0.08)}{_cap(pose, 14, 16)}</body>""")
        (cx, cy, cz), (hx, hy, hz) = shelf
        xml = f"""<mujoco><worldbody>
            <geom name="shelf" type="box" pos="{cx} {cy} {cz}" size="{hx} {hy} {hz}"/>
            {''.join(bodies)}</worldbody></mujoco>"""
        self.model = mujoco.MjModel.from_xml_string(xml)
        self.data = mujoco.MjData(self.model)
        mujoco.mj_forward(self.model, self.data)
        self.people = len(people_xy)

    def geom_person_ids(self):
        names = [self.model.body(self.model.geom_bodyid[g]).name for g in range(self.model.ngeom)]
        return np.array([int(n[1:n.index("_")]) if n.startswith("p") else -1 for n in names])

    def geom_body_ids(self):
        names = [self.model.body(self.model.geom_bodyid[g]).name for g in range(self.model.ngeom)]
        parts = list(_PARTS) + ["torso"]
        return np.array([parts.index(n[n.index("_") + 1:]) if n.startswith("p") else -1 for n in names])

    def keypoint_body_ids(self):
        table = np.zeros(17, dtype=np.int64)
        for i, joints in enumerate(_PARTS.values()):
            table[list(joints)] = i
        return table

    def keypoint_parent_body_ids(self):
        return self.keypoint_body_ids()  # (each keypoint lies in its own part's geoms only)

    def geom_groups(self):
        person = self.geom_person_ids()
        return np.concatenate([[0], np.nonzero(person[1:] != person[:-1])[0] + 1, [person.size]])

    def ray_geom_constants(self):
        return self.model.geom_size.copy(), self.model.geom_rbound.copy(), self.geom_person_ids()

    def truth(self, t=0.0):
        return PoseTruth(t, np.arange(self.people), self.poses.copy())


def _cameras(*placements):
    scenario = Scenario(name="t", store=StoreConfig(width_m=6.0, depth_m=4.0),
                        cameras=CameraRigConfig(placements=placements, k1=0.0, k2=0.0))
    return build_rig(scenario, np.random.default_rng(0))


def test_person_behind_a_shelf_has_its_hidden_joints_flagged():
    # A person just behind a 1.5 m shelf, seen over the shelf from a camera on the other side.
    world = BoxWorld([(2.6, 1.5)])
    cams = _cameras(CameraPlacement((0.3, 1.5, 2.8), (2.6, 1.5, 0.9)))
    detector = Detector(DetectorConfig(profile=DetectorProfile.IDEAL), cams, np.random.default_rng(1))
    frame = detect(detector, 0, world, world.truth(), 0.0, 0.0, 0.05)
    truth = frame.truth
    assert truth.person_ids.tolist() == [0]
    occluded = truth.occluded[0]
    legs = [COCO17.index(n) for n in ("left_knee", "right_knee", "left_ankle", "right_ankle")]
    head = [COCO17.index(n) for n in ("nose", "left_eye", "right_eye")]
    assert occluded[legs].all() and not occluded[head].any()
    assert truth.in_image[0].all()
    # The ideal detector reports exactly the visible joints, occluded ones too (drop prob 0).
    np.testing.assert_allclose(frame.frame.keypoints_px[0], truth.keypoints_px[0], atol=1e-9)  # px
    # Without the shelf nothing is occluded.
    open_world = BoxWorld([(2.6, 1.5)], shelf=((9.0, 9.0, 0.1), (0.1, 0.1, 0.1)))
    ideal = Detector(DetectorConfig(profile=DetectorProfile.IDEAL), cams, np.random.default_rng(1))
    assert not detect(ideal, 0, open_world, open_world.truth(), 0.0, 0.0, 0.05).truth.occluded.any()


def test_limbs_behind_the_body_are_self_occluded_and_other_people_occlude():
    # Camera low on the person's left (+y) side: the right arm is behind the torso.
    world = BoxWorld([(3.0, 1.5), (3.0, 2.5)], shelf=((9.0, 9.0, 0.1), (0.1, 0.1, 0.1)))
    cams = _cameras(CameraPlacement((3.0, 0.0, 1.6), (3.0, 1.5, 1.0)),
                    CameraPlacement((3.0, 3.9, 1.6), (3.0, 2.5, 1.0)))
    detector = Detector(DetectorConfig(profile=DetectorProfile.IDEAL), cams, np.random.default_rng(1))
    _, in_img, occluded, self_occluded, _ = visibility(detector, 0, world, world.truth())
    left_wrist, right_wrist = COCO17.index("left_wrist"), COCO17.index("right_wrist")
    # Camera 0 looks from -y: person 0's left (+y) wrist hides behind its torso, its right wrist is seen.
    assert self_occluded[0, left_wrist] and not occluded[0, left_wrist]
    assert not self_occluded[0, right_wrist] and not occluded[0, right_wrist]
    # Person 1 stands behind person 0 in camera 0: its hidden joints are occluded, not self-occluded.
    assert occluded[1].any() and not self_occluded[1][occluded[1]].any()
    # Visibility counts accumulate per camera.
    assert detector.visibility_counts[0].tolist() == [in_img.sum(), occluded.sum(), self_occluded.sum()]


def test_a_capture_that_sees_nobody_does_not_break_the_batch():
    # Two cameras posed in one batch; the second looks away from everybody (its rays segment is empty).
    world = BoxWorld([(2.6, 1.5)])
    cams = _cameras(CameraPlacement((0.3, 1.5, 2.8), (2.6, 1.5, 0.9)),
                    CameraPlacement((5.8, 3.8, 2.8), (5.9, 3.9, 0.0)))
    detector = Detector(DetectorConfig(profile=DetectorProfile.IDEAL), cams, np.random.default_rng(1))
    for order in ((0, 1), (1, 0), (1, 1)):
        views = visibility_many(detector, world, [Capture(c, world.truth(), 0.0, 0.0, 0.0) for c in order])
        for c, (_, in_img, occluded, _, _) in zip(order, views):
            assert in_img.any() == (c == 0)
            if c == 0:
                _, in_single, occluded_single, _, _ = visibility(detector, 0, world, world.truth())
                assert (in_img == in_single).all() and (occluded == occluded_single).all()


def _open_scene(people=4):
    xy = [(1.0 + 0.8 * i, 1.5 + 0.3 * (i % 2)) for i in range(people)]
    world = BoxWorld(xy, shelf=((9.0, 9.0, 0.1), (0.1, 0.1, 0.1)))
    cams = _cameras(CameraPlacement((0.2, 0.2, 2.9), (2.0, 1.5, 1.0)))
    return world, cams


def _frames(config, n=300, world_rays=False, seed=2):
    world, cams = _open_scene()
    detector = Detector(config, cams, np.random.default_rng(seed))
    return [detect(detector, 0, world if world_rays else None, world.truth(k * 0.1), k * 0.1, k * 0.1, k * 0.1)
            for k in range(n)]


def test_ideal_profile_reports_every_person_exactly():
    frames = _frames(DetectorConfig(profile=DetectorProfile.IDEAL), n=5)
    for f in frames:
        assert sorted(f.truth.person_ids.tolist()) == [0, 1, 2, 3]
        assert (f.truth.effects == 0).all()
        ok = f.truth.in_image
        np.testing.assert_allclose(f.frame.keypoints_px[ok], f.truth.keypoints_px[ok], atol=1e-9)  # px
        assert np.isnan(f.frame.keypoints_px[~ok]).all() and (f.frame.scores[~ok] == 0).all()
        assert (f.frame.scores[ok] == 1).all()


def _only(**knobs):
    """The ideal detector with one effect turned on."""
    return DetectorConfig(profile=DetectorProfile.IDEAL, **knobs)


def test_noise_scales_with_the_person_size_and_its_knob():
    def median_norm_error(noise_frac):
        frames = _frames(_only(noise_frac=noise_frac, noise_tail_dof=1e9), n=100)
        errs = []
        for f in frames:
            size = person_size_px(f.truth.keypoints_px)
            errs.append((np.linalg.norm(f.frame.keypoints_px - f.truth.keypoints_px, axis=-1) / size[:, None]).ravel())
        e = np.concatenate(errs)
        return np.nanmedian(e)

    # Gaussian per-axis std s (times the per-joint factor ~1): the 2D error's median is s * sqrt(2 ln 2).
    assert median_norm_error(0.01) == pytest.approx(0.01 * np.sqrt(2 * np.log(2)), rel=0.15)
    assert median_norm_error(0.02) / median_norm_error(0.01) == pytest.approx(2.0, rel=0.1)


@pytest.mark.parametrize(
    ("knob", "effect"),
    [("fragment_prob", DetectionEffect.FRAGMENT), ("swap_prob", DetectionEffect.LEFT_RIGHT_SWAP),
     ("duplicate_prob", DetectionEffect.DUPLICATE)],
)
def test_each_detection_effect_follows_its_probability(knob, effect):
    frames = _frames(_only(**{knob: 0.3}), n=200)
    effects = np.concatenate([f.truth.effects for f in frames])
    flagged = (effects & effect) != 0
    real = np.concatenate([f.truth.person_ids for f in frames]) >= 0
    if effect == DetectionEffect.DUPLICATE:
        # Each of the 800 person views brings a duplicate with probability 0.3.
        assert flagged.sum() / 800 == pytest.approx(0.3, abs=0.05)
    else:
        assert flagged[real].mean() == pytest.approx(0.3, abs=0.05)


def test_fragments_keep_fewer_than_six_joints_and_swaps_swap_sides():
    for f in _frames(_only(fragment_prob=1.0), n=20):
        assert ((~np.isnan(f.frame.keypoints_px[..., 0])).sum(axis=1) < 6).all()
    for f in _frames(_only(swap_prob=1.0), n=5):
        lw, rw = COCO17.index("left_wrist"), COCO17.index("right_wrist")
        ok = f.truth.in_image[:, lw] & f.truth.in_image[:, rw]
        np.testing.assert_allclose(f.frame.keypoints_px[ok, lw], f.truth.keypoints_px[ok, rw], atol=1e-9)  # px


def test_phantoms_are_poisson_with_the_configured_rate_and_have_no_person():
    frames = _frames(_only(phantom_rate=0.5), n=400)
    phantoms = [int((f.truth.person_ids < 0).sum()) for f in frames]
    # Some phantoms land mostly outside the image and are dropped; most stay.
    assert 0.35 <= np.mean(phantoms) <= 0.5
    f = next(f for f, n in zip(frames, phantoms) if n)
    row = np.nonzero(f.truth.person_ids < 0)[0][0]
    assert f.truth.effects[row] == DetectionEffect.PHANTOM and np.isnan(f.truth.keypoints_px[row]).all()


def test_misses_grow_with_occlusion():
    world = BoxWorld([(2.6, 1.5)])
    cams = _cameras(CameraPlacement((0.3, 1.5, 2.8), (2.6, 1.5, 0.9)))
    config = _only(miss_prob=0.1, miss_occlusion_gain=0.8)
    detector = Detector(config, cams, np.random.default_rng(3))
    hidden = np.mean([len(detect(detector, 0, world, world.truth(), 0, 0, 0).truth.person_ids) == 0
                      for _ in range(400)])
    open_world = BoxWorld([(2.6, 1.5)], shelf=((9.0, 9.0, 0.1), (0.1, 0.1, 0.1)))
    seen = np.mean([len(detect(detector, 0, open_world, open_world.truth(), 0, 0, 0).truth.person_ids) == 0
                    for _ in range(400)])
    assert seen == pytest.approx(0.1, abs=0.04)
    assert hidden > seen + 0.15


def test_detections_are_deterministic_for_a_seed():
    a = _frames(DetectorConfig(profile=DetectorProfile.HARSH), n=20, seed=5)
    b = _frames(DetectorConfig(profile=DetectorProfile.HARSH), n=20, seed=5)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x.frame.keypoints_px, y.frame.keypoints_px)
        np.testing.assert_array_equal(x.truth.effects, y.truth.effects)


def test_knobs_override_the_profile_and_bad_knobs_name_the_key():
    assert DetectorConfig(profile=DetectorProfile.TYPICAL, swap_prob=0.5).params().swap_prob == 0.5
    assert DetectorConfig(profile=DetectorProfile.IDEAL).params().noise_frac == 0.0
    with pytest.raises(ValueError, match="miss_prob"):
        DetectorConfig(miss_prob=1.5)
    with pytest.raises(ValueError, match="noise_tail_dof"):
        DetectorConfig(noise_tail_dof=1.0)


def test_in_image_joints_of_far_away_people_are_not_reported():
    world, cams = _open_scene()
    truth = world.truth()
    far = PoseTruth(0.0, np.array([7]), truth.poses[:1] + [0.0, -40.0, 0.0])
    _, inside = in_image(cams[0], far.poses)
    detector = Detector(DetectorConfig(), cams, np.random.default_rng(0))
    assert not inside.any() and detect(detector, 0, None, far, 0, 0, 0).truth.person_ids.size == 0


def test_person_size_is_the_larger_side_of_the_box_of_the_known_joints():
    """`person_size_px` (the detector's compiled loop) against the box computed with numpy, any leading shape."""
    rng = np.random.default_rng(6)
    kp = rng.uniform(0, 1280, (4, 5, 17, 2))
    kp[rng.random(kp.shape) < 0.3] = np.nan  # single coordinates unknown too
    kp[0, 0] = np.nan  # nobody known: NaN
    known = ~np.isnan(kp)
    extent = (np.where(known, kp, -np.inf).max(axis=-2, initial=-np.inf)
              - np.where(known, kp, np.inf).min(axis=-2, initial=np.inf))
    size = np.max(extent, axis=-1, initial=-np.inf)
    np.testing.assert_array_equal(person_size_px(kp), np.where(np.isfinite(size), size, np.nan))
    assert np.isnan(person_size_px(kp)[0, 0]) and person_size_px(kp[1, 2]).shape == ()
    assert person_size_px(np.array([[0.0, 0.0], [3.0, np.nan], [np.nan, 5.0]])) == 5.0
    assert person_size_px(np.zeros((0, 17, 2))).shape == (0,)


def test_people_smaller_than_min_person_frac_of_the_image_are_never_detected_and_cast_no_rays():
    # One person 6 m from the camera, one 30 m away along the same line of sight (a hypermarket's far aisle),
    # and a shelf in front of the far one's legs.
    world = BoxWorld([(6.0, 0.0), (30.0, 0.0)], shelf=((28.0, 0.0, 0.4), (0.2, 1.0, 0.4)))
    cams = _cameras(CameraPlacement((0.0, 0.0, 2.9), (30.0, 0.0, 0.5)))
    truth = world.truth()
    sizes = person_size_px(visibility(Detector(DetectorConfig(), cams, np.random.default_rng(0)), 0, world,
                                      truth)[0])
    assert sizes[0] > 100 and 20 < sizes[1] < 48  # px, in 720 px high images

    def seen(**knobs):
        detector = Detector(_only(**knobs), cams, np.random.default_rng(0))
        px, in_img, occluded, _, _ = visibility(detector, 0, world, truth)
        frame = detect(detector, 0, world, truth, 0.0, 0.0, 0.0)
        return sorted(frame.truth.person_ids.tolist()), in_img, occluded, detector.visibility_counts[0]

    ids, in_img, occluded, counts = seen()
    assert ids == [0, 1] and in_img[1].all() and occluded[1].any()  # the ideal detector reports both
    assert counts[0] == 2 * in_img.sum()  # (both calls cast every joint in the image)
    for knobs in ({"min_person_frac": 0.1}, {"min_person_frac": (sizes[1] + 1e-6) / 720}):
        ids, small_in_img, small_occluded, counts = seen(**knobs)
        assert ids == [0]
        # The far person is still in the image, but no ray is cast for it: no occlusion flag, not counted.
        assert (small_in_img == in_img).all() and not small_occluded[1].any()
        assert (small_occluded[0] == occluded[0]).all() and counts[0] == 2 * in_img[0].sum()
    assert seen(min_person_frac=(sizes[1] - 1e-6) / 720)[0] == [0, 1]
    typical = Detector(DetectorConfig(), cams, np.random.default_rng(0))
    assert typical.min_size_px.tolist() == [72.0]  # a tenth of the image height
    with pytest.raises(ValueError, match="min_person_frac"):
        DetectorConfig(min_person_frac=-0.1)


def test_profiles_order_from_ideal_to_harsh():
    def figures(profile):
        frames = _frames(DetectorConfig(profile=profile), n=150, seed=4)
        real = [(f.frame.keypoints_px[f.truth.person_ids >= 0], f.truth.keypoints_px[f.truth.person_ids >= 0])
                for f in frames]
        errors = np.concatenate([(np.linalg.norm(kp - t, axis=-1) / person_size_px(t)[:, None]).ravel()
                                 for kp, t in real])
        detections = sum(len(kp) for kp, _ in real)
        return np.nanmedian(errors), detections

    ideal, typical, harsh = (figures(p) for p in DetectorProfile)
    assert ideal[0] == 0 and 0 < typical[0] < harsh[0]
    # 150 frames x 4 people; harsh misses and drops more.
    assert ideal[1] == 600 and harsh[1] < typical[1] <= 600 * 1.05


@pytest.mark.parametrize("name, times_s, min_hits", [("store_layout2", np.arange(0.0, 12.0, 0.6), 1000),
                                                     ("supermarket", (0.0, 7.3), 20000)])
def test_compiled_ray_caster_agrees_with_mj_multiray_in_the_store(name, times_s, min_hits):
    """The detector's ray caster finds the same first hit (geom and distance, bit for bit) as
    `mujoco.mj_multiRay` for every ray that hits something before its keypoint, and so the same flags,
    in store_layout2 through arrivals and departures, and in the crowded supermarket (its floor grid
    holds many people per cell), from every camera of the rig."""
    import mujoco

    from sim import scenario as scenario_mod
    from sim.rng import child_rng
    from sim.world import World

    scenario = scenario_mod.load(name)
    world = World(scenario, child_rng(0, "crowd"))
    cams = build_rig(scenario, child_rng(0, "cameras"))
    detector = Detector(DetectorConfig(), cams, np.random.default_rng(0))
    rng = np.random.default_rng(3)
    hits = flagged = 0
    floor = [scenario.store.width_m, scenario.store.depth_m, 2.5]
    for t in times_s:
        truth = world.advance(float(t))
        # The keypoints and random points of the store (nobody's), as seen from every camera.
        points = np.concatenate([truth.poses.reshape(-1, 3), rng.uniform([0, 0, 0], floor, (17, 3))])
        person = np.append(truth.person_ids, -1)
        for camera in cams:
            _, seen = in_image(camera, points)
            if not seen.any():
                continue
            occ, self_occ, geomid, dist = cast(detector, world, camera.center_world[None], points[None], seen[None],
                                               person[None])
            # Reference: one mj_multiRay batch over the points in view, and the flags cast_visibility gives.
            origin = np.asarray(camera.center_world, dtype=np.float64)
            vec = points[seen] - origin
            length = np.linalg.norm(vec, axis=1)
            ref_id, ref_dist = np.empty(len(vec), np.int32), np.empty(len(vec))
            mujoco.mj_multiRay(world.model, world.data, origin, (vec / length[:, None]).ravel(), None, 1, -1,
                               ref_id, ref_dist, None, len(vec), float(length.max()))
            before = (ref_id >= 0) & (ref_dist < length)
            np.testing.assert_array_equal(np.where(before, ref_id, -1), geomid[0, seen])
            np.testing.assert_array_equal(ref_dist[before], dist[0, seen][before])
            point_person = np.repeat(person, 17)[seen]
            joint = np.arange(len(points))[seen] % 17
            ref_occ, ref_self = cast_visibility(world.model, world.data, origin, points[seen], point_person,
                                                detector._scene(world)[0][joint], world.geom_person_ids(),
                                                world.geom_body_ids(), detector.config.self_hit_margin_m)
            np.testing.assert_array_equal(ref_occ, occ[0, seen])
            np.testing.assert_array_equal(ref_self, self_occ[0, seen])
            hits += int(before.sum())
            flagged += int(ref_occ.sum() + ref_self.sum())
    assert hits > min_hits and flagged > min_hits / 2  # the comparison saw plenty of occlusion


def test_block_visibility_of_snapshots_equals_visibility_at_each_tick():
    """Rays cast later from `scene_now` snapshots (a buffer of rows shared by the ticks, sizes and owners
    shared until they change) flag the joints exactly as casting at each tick does: blocks that fill the
    buffer, straddle two buffers, take ticks out of order, and span arrivals and departures."""
    from sim import scenario as scenario_mod
    from sim.rng import child_rng
    from sim.sensing.detector import _SCENE_ROWS
    from sim.world import World

    scenario = scenario_mod.load("store_layout1")
    scenario = dataclasses.replace(scenario, crowd=dataclasses.replace(scenario.crowd, mean_visit_s=3.0,
                                                                       mean_arrival_gap_s=0.4))
    world = World(scenario, child_rng(0, "crowd"))
    cams = build_rig(scenario, child_rng(0, "cameras"))
    later, now = (Detector(DetectorConfig(), cams, np.random.default_rng(0)) for _ in range(2))
    ticks = []
    for k in range(2 * _SCENE_ROWS + 30):
        truth = world.advance(k * 0.05)
        requests = [Capture(c, truth, k * 0.05, k * 0.05, k * 0.05) for c in range(len(cams))]
        ticks.append((requests, later.scene_now(world), [visibility(now, c, world, truth) for c in range(len(cams))]))
    assert len({id(scene[2]) for _, scene, _ in ticks}) > 1 and len({id(scene[4]) for _, scene, _ in ticks}) > 1
    blocks = [list(range(a, min(a + n, len(ticks)))) for a, n in ((0, 7), (7, 50), (57, 10), (67, 70))]
    blocks += [[len(ticks) - 1, 70, 90], list(range(137, len(ticks)))]
    flagged = 0
    for block in blocks:
        requests = [r for i in block for r in ticks[i][0]]
        scene_of = [n for n, i in enumerate(block) for _ in ticks[i][0]]
        got = later.block_visibility(requests, [ticks[i][1] for i in block], scene_of)
        want = [np.concatenate([view[k] for i in block for view in ticks[i][2]]) for k in range(4)]
        for a, b in zip(got, want):
            assert a.tobytes() == b.tobytes()
        flagged += int(got[2].sum() + got[3].sum())
    assert flagged > 100


def test_scene_now_reuses_a_buffer_only_when_no_snapshot_of_it_is_alive():
    """`scene_now` writes into recycled buffers, but never into one a kept snapshot (or a view of it) still
    points into: every kept snapshot keeps the values it was taken with."""
    from sim import scenario as scenario_mod
    from sim.rng import child_rng
    from sim.sensing.detector import _SCENE_ROWS
    from sim.world import World

    scenario = scenario_mod.load("store_layout1")
    world = World(scenario, child_rng(0, "crowd"))
    detector = Detector(DetectorConfig(), build_rig(scenario, child_rng(0, "cameras")), np.random.default_rng(0))
    kept, buffers = [], set()
    block = []
    for k in range(6 * _SCENE_ROWS):
        world.advance(k * 0.01)
        scene = detector.scene_now(world)
        buffers.add(id(scene.buffer.pos))
        block.append(scene)
        if k % 37 == 0:  # a snapshot kept, one through a view of a view
            kept.append((scene[0][1:], scene[1], world.data.geom_xpos[1:].copy(), world.data.geom_xmat.copy()))
        if len(block) == 10:
            detector._scene_arrays(block)
            block = []
    for pos, mat, want_pos, want_mat in kept:
        assert pos.tobytes() == want_pos.tobytes() and mat.tobytes() == want_mat.tobytes()
    # Kept snapshots pin their buffers; the others are reused.
    assert len(buffers) <= len({id(pos.base) for pos, *_ in kept}) + 3


def test_frame_order_is_lexsort_by_frame_then_key():
    from sim.sensing.draws import frame_order as _frame_order

    rng = np.random.default_rng(4)
    for n_rows, n_frames in ((0, 3), (1, 1), (40, 7), (300, 28), (50, 60)):
        frame = rng.integers(n_frames, size=n_rows)
        key = rng.random(n_rows)
        key[rng.random(n_rows) < 0.2] = 0.5  # ties keep the input order, as lexsort's
        order = np.empty(n_rows, dtype=np.int64)
        _frame_order(frame, key, n_frames, order)
        np.testing.assert_array_equal(order, np.lexsort((key, frame)))
