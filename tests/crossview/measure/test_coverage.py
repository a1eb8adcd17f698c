"""`crossview coverage`: cameras per walkable floor cell against a closed-form footprint, the shares, the map, the
warning of generate, and bad input."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from core.types import Camera
from crossview.cli import EXIT_BAD_INPUT, main
from crossview.measure.coverage import HEIGHTS_M, WARN_TWO_VIEW_SHARE, coverage
from sim import scenario as scenario_mod
from tests.crossview.test_cli import _run_bad

CEILING_M = 3.0
_DOWN = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])  # camera x = world x, looking down -z


def _room(tmp_path, text: str = "") -> scenario_mod.Scenario:
    path = tmp_path / "room.toml"
    path.write_text("[store]\nwidth_m = 6.0\ndepth_m = 4.0\n[crowd]\npeople = 2\n" + text)
    return scenario_mod.load(path)


def _looking_down(name: str, x_m: float, y_m: float) -> Camera:
    """A pinhole 640 x 480 px camera at the ceiling above (x, y), looking straight down."""
    K = np.array([[400.0, 0.0, 319.5], [0.0, 400.0, 239.5], [0.0, 0.0, 1.0]])
    centre = np.array([x_m, y_m, CEILING_M])
    return Camera(name, K, np.zeros(5), _DOWN, -_DOWN @ centre, 640, 480)


def test_each_cell_is_counted_by_the_cameras_whose_footprint_holds_it(tmp_path):
    cameras = [_looking_down("a", 2.0, 2.0), _looking_down("b", 4.0, 2.0)]
    cov = coverage(_room(tmp_path), cameras)
    for h in cov.heights:
        # A pinhole looking down sees the rectangle |dx| <= (W/2) z / f, |dy| <= (H/2) z / f at depth z
        # (pixel centres at 0 .. W-1, the image's edges half a pixel beyond).
        z = CEILING_M - h.height_m
        expected = np.zeros(len(cov.cells_xy), int)
        for cam in cameras:
            c = cam.center_world
            dx, dy = np.abs(cov.cells_xy[:, 0] - c[0]), np.abs(cov.cells_xy[:, 1] - c[1])
            expected += (dx <= 320.0 * z / 400.0) & (dy <= 240.0 * z / 400.0)
        np.testing.assert_array_equal(h.counts, expected)
        assert 0 < h.share(2) < h.share(1) <= 1.0  # the two footprints overlap in the middle only
    assert [h.height_m for h in cov.heights] == [m for _, m in HEIGHTS_M]
    # Hip height is further from the ceiling than head height: each camera sees more of it.
    assert cov.heights[0].share(1) >= cov.heights[1].share(1)


def test_a_second_camera_in_the_same_place_doubles_every_count(tmp_path):
    room = _room(tmp_path)
    one = coverage(room, [_looking_down("a", 3.0, 2.0)])
    two = coverage(room, [_looking_down("a", 3.0, 2.0), _looking_down("b", 3.0, 2.0)])
    for h1, h2 in zip(one.heights, two.heights):
        np.testing.assert_array_equal(h2.counts, 2 * h1.counts)
        assert h2.share(2) == h1.share(1) and h1.share(2) == 0.0


def test_no_cameras_is_no_coverage_with_the_warning(tmp_path):
    cov = coverage(_room(tmp_path), [])
    assert all(h.share(1) == 0.0 for h in cov.heights)
    assert "only 0 % of the walkable floor is seen by two cameras or more" in cov.warning()
    assert len(cov.lines()) == 7 and "predicted PCP 0.000" in cov.lines()[1]


def test_the_scenario_rig_is_the_one_generate_builds_and_store_layout1_needs_no_warning():
    cov = coverage(scenario_mod.load("store_layout1"))
    assert len(cov.cameras) == 12
    assert min(h.share(2) for h in cov.heights) >= WARN_TWO_VIEW_SHARE and cov.warning() is None
    assert cov.floor_m2 == pytest.approx(12.8, abs=0.05)  # the walkable floor the crowd is checked against


def test_coverage_command_prints_the_shares_and_writes_both_maps(tmp_path, capsys):
    out = tmp_path / "maps" / "l1.png"
    assert main(["coverage", "store_layout1", "-o", str(out)]) == 0
    captured = capsys.readouterr()
    assert "store_layout1: 12 cameras" in captured.out and "head height 1.6 m" in captured.out
    assert captured.err == ""
    image = cv2.imread(str(out))
    assert image is not None and image.shape[1] > 2 * image.shape[0]  # hip and head maps side by side


def test_a_floor_no_camera_sees_is_a_one_line_warning_and_exit_0(tmp_path, capsys):
    # One camera in a corner looking out of the store: nothing of the floor is in its image.
    blind = tmp_path / "blind.toml"
    blind.write_text("[store]\nwidth_m = 4.0\ndepth_m = 4.0\n[crowd]\npeople = 2\n[[cameras.placements]]\n"
                     "position_m = [0.2, 0.2, 2.8]\nlook_at_m = [-5.0, -5.0, 2.0]\n")
    assert main(["coverage", str(blind)]) == 0
    captured = capsys.readouterr()
    assert ">= 1:   0.0 %" in captured.out
    assert len(captured.err.strip().splitlines()) == 1 and "only 0 %" in captured.err
    # generate warns in the same line, and still generates.
    rec = tmp_path / "blind.mcap"
    assert main(["--no-progress", "generate", str(blind), "--duration", "0.2", "-o", str(rec)]) == 0
    assert "only 0 % of the walkable floor" in capsys.readouterr().err and rec.exists()


def test_an_invalid_scenario_is_named_in_one_line_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("[store]\nwidth_m = -3\n")
    err = _run_bad(capsys, ["coverage", str(bad), "-o", str(tmp_path / "map.png")])
    assert "bad.toml" in err and "width_m" in err
    assert not (tmp_path / "map.png").exists()
    assert main(["coverage", str(tmp_path / "missing.toml")]) == EXIT_BAD_INPUT


# ---------------------------------------------------------------- the prediction (what the detector will detect)


def test_the_shelf_test_agrees_with_mujocos_ray_caster():
    """`blocked_by_boxes` against `mujoco.mj_ray` on the same yawed boxes: segments from ceiling points to
    points on the floor, blocked when the first hit comes before the segment's end."""
    import mujoco

    from crossview.measure.coverage import blocked_by_boxes
    from sim.store import Obstacle

    rng = np.random.default_rng(3)
    obstacles = [Obstacle(f"s{i}", rng.uniform(1.0, 7.0, 2), rng.uniform(0.2, 1.5, 2), rng.uniform(-np.pi, np.pi),
                          rng.uniform(0.5, 2.2)) for i in range(5)]
    geoms = "".join(
        f'<geom type="box" pos="{o.center[0]} {o.center[1]} {o.height / 2}" size="{o.half[0]} {o.half[1]} '
        f'{o.height / 2}" euler="0 0 {o.yaw}"/>' for o in obstacles)
    model = mujoco.MjModel.from_xml_string(f'<mujoco><compiler angle="radian"/><worldbody>{geoms}</worldbody>'
                                           "</mujoco>")
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    geomid = np.zeros(1, np.int32)
    origins = np.column_stack([rng.uniform(0.0, 8.0, (40, 2)), rng.uniform(2.5, 4.0, 40)])
    checked = hits = 0
    for origin in origins:
        points = np.column_stack([rng.uniform(0.0, 8.0, (50, 2)), rng.uniform(0.05, 1.9, 50)])
        ours = blocked_by_boxes(origin, points, obstacles)
        for point, blocked in zip(points, ours):
            x = mujoco.mj_ray(model, data, origin, point - origin, None, 1, -1, geomid)
            if 0.0 <= x < 1.0 and x > 1.0 - 1e-6:  # (a surface at the point itself: either answer is right)
                continue
            assert blocked == (0.0 <= x < 1.0), (origin, point, x)
            checked += 1
            hits += blocked
    assert checked > 1900 and 200 < hits < checked - 200  # both answers well represented


def test_two_or_more_is_the_poisson_binomial_tail():
    import itertools

    from crossview.measure.coverage import _two_or_more

    rng = np.random.default_rng(0)
    p = rng.uniform(0.0, 1.0, (4, 6))
    p[0, :3] = 0.0
    p[1, 0] = 1.0
    for row, got in zip(p, _two_or_more(p, axis=1)):
        exact = sum(np.prod([q if bit else 1 - q for q, bit in zip(row, bits)])
                    for bits in itertools.product((0, 1), repeat=len(row)) if sum(bits) >= 2)
        assert got == pytest.approx(exact, abs=1e-9)


def test_people_hide_a_ray_as_often_as_a_scattered_crowd_does():
    """The closed form of `_people_hiding` against people scattered at random (Poisson, none within the personal
    space of the point), each an upright cylinder: the share of scatterings in which one stands in the ray."""
    from crossview.measure.coverage import OCCLUDER_HEIGHT_M, OCCLUDER_WIDTH_M, PERSONAL_SPACE_M, _people_hiding

    origin = np.array([0.0, 0.0, 3.0])
    points = np.array([[4.0, 0.0, 0.5], [4.0, 0.0, 1.2], [6.0, 0.0, 0.1], [1.0, 0.0, 1.0], [3.0, 0.0, 1.8]])
    density = 0.4
    predicted = _people_hiding(origin, points, density)
    rng = np.random.default_rng(1)
    trials = 4000
    hidden = np.zeros(len(points))
    for _ in range(trials):
        n = rng.poisson(density * 100.0)
        people = np.column_stack([rng.uniform(-1.0, 9.0, n), rng.uniform(-5.0, 5.0, n)])
        for k, point in enumerate(points):
            # The ray's height at each person's distance along it, and their distance across it.
            d = point[:2] - origin[:2]
            length = np.linalg.norm(d)
            along = (people - origin[:2]) @ d / length
            across = np.abs((people - origin[:2]) @ np.array([-d[1], d[0]]) / length)
            height = origin[2] + (point[2] - origin[2]) * along / length
            away = np.linalg.norm(people - point[:2], axis=1) >= PERSONAL_SPACE_M
            blocks = (along > 0) & (along < length) & (across <= OCCLUDER_WIDTH_M / 2) & (height < OCCLUDER_HEIGHT_M)
            hidden[k] += np.any(blocks & away & (length - along >= PERSONAL_SPACE_M))
    np.testing.assert_allclose(hidden / trials, predicted, atol=0.03)
    assert predicted[4] == 0.0 and predicted[0] > predicted[1]  # above the crowd's heads: never hidden


def _one_person_room(tmp_path, text: str = "") -> scenario_mod.Scenario:
    path = tmp_path / "room1.toml"
    path.write_text("[store]\nwidth_m = 6.0\ndepth_m = 4.0\n[crowd]\npeople = 1\n" + text)
    return scenario_mod.load(path)


def test_a_person_in_plain_view_is_detected_at_the_profiles_rate(tmp_path):
    from crossview.measure.coverage import PCP_BONE_JOINTS

    scenario = _one_person_room(tmp_path)
    params = scenario.detector.params()
    cameras = [_looking_down("a", 3.0, 2.0), _looking_down("b", 3.0, 2.0)]
    pred = coverage(scenario, cameras).prediction
    whole = np.all(np.abs(pred.cells_xy - [3.0, 2.0]) < [0.5, 0.4], axis=1)  # well inside both images
    assert whole.any()
    # Alone (no crowd), under no shelf: each camera detects the person unless the detector misses them.
    np.testing.assert_allclose(pred.detecting[whole], 2 * (1 - params.miss_prob), rtol=1e-9)
    np.testing.assert_allclose(pred.two_view[whole], (1 - params.miss_prob) ** 2, rtol=1e-9)
    # A bone is usable when both cameras report both of its ends: each camera's joint rates, per group.
    wrist, elbow = params.joint_miss_prob[3], params.joint_miss_prob[2]
    lower_arm = [k for k, (g, _) in enumerate(PCP_BONE_JOINTS) if g == "lower_arms"][0]
    one = (1 - params.miss_prob)
    expected = (one * (1 - wrist)) ** 2 * (one * (1 - elbow)) ** 2
    np.testing.assert_allclose(pred.bones[whole, lower_arm], expected, rtol=1e-9)
    assert pred.people == 1 and pred.density_per_m2 > 0  # (one person: nobody else to hide them)


def test_a_shelf_between_hides_and_a_small_person_is_never_detected(tmp_path):
    # (The shelf leaves a passage at each end: a layout whose right half no one reaches is refused at load.)
    scenario = _one_person_room(tmp_path, "[[store.shelves]]\ncenter_m = [3.0, 2.0]\nsize_m = [0.4, 2.2, 2.5]\n")
    # A camera low on the left wall looking right, across the shelf: it sees the floor behind it only over the shelf.
    cam = Camera("side", np.array([[400.0, 0.0, 319.5], [0.0, 400.0, 239.5], [0.0, 0.0, 1.0]]), np.zeros(5),
                 *_look(np.array([0.1, 2.0, 1.2]), np.array([6.0, 2.0, 1.0])), 640, 480)
    pred = coverage(scenario, [cam]).prediction
    left = pred.cells_xy[:, 0] < 3.0
    right = (pred.cells_xy[:, 0] > 3.0) & (np.abs(pred.cells_xy[:, 1] - 2.0) < 1.1)  # behind the shelf
    assert pred.detecting[right].max() == 0.0 and pred.detecting[left].max() > 0.9
    assert pred.losses.hidden > 0.2
    # The same rig with a detector that needs people half the image tall: those far away are too small.
    small = _one_person_room(tmp_path, "[detector]\nmin_person_frac = 0.5\n")
    pred = coverage(small, [cam]).prediction
    assert pred.losses.too_small > 0.3 and pred.detecting[pred.cells_xy[:, 0] > 4.0].max() == 0.0


def _look(position, target):
    from sim.cameras import look_at

    R = look_at(position, target)
    return R, -R @ position


def test_more_cameras_predict_better_on_the_convenience_store_sizes():
    """The prediction on store_layout2's floor rises with the grid, where the geometric upper bound is already
    saturated (the Why of the planner: 4 and 12 cameras looked the same)."""
    from crossview import pipeline

    low = coverage(pipeline.load_scenario("store_layout2", cameras=4))
    high = coverage(pipeline.load_scenario("store_layout2", cameras=28))
    assert high.prediction.predicted_pcp > low.prediction.predicted_pcp + 0.05
    assert high.prediction.usable_two_view_share >= low.prediction.usable_two_view_share
    assert set(high.as_dict()) >= {"predicted_pcp", "usable_two_view_share", "risk_share", "upper_bound"}


def test_the_predicted_detections_are_the_simulated_detectors(store_recording):
    """The model against the simulator it stands for: over a recording of store_layout1 (12 cameras, 4 people
    walking, browsing, gesturing), each camera's predicted chance of detecting each person where they stand,
    summed over the frames, against the detections the simulated detector made of them."""
    from crossview import pipeline
    from crossview.recording.reader import open_recording

    cov = coverage(pipeline.load_scenario("store_layout1"))
    pred = cov.prediction
    names = [c.name for c in cov.cameras]
    expected = found = 0.0
    rec = open_recording(store_recording)
    hips = list(rec.skeleton.hips)
    for cf in rec.frames(with_poses=True):
        c = names.index(cf.frame.camera)
        truth = cf.poses_at_capture
        pelvis = truth.poses[:, hips, :2].mean(axis=1)
        distance = np.linalg.norm(pelvis[:, None] - pred.cells_xy[None], axis=2)
        cell, near = distance.argmin(axis=1), distance.min(axis=1) < pred.cell_m
        detected = set(cf.truth.person_ids[(cf.truth.effects & 2) == 0].tolist())  # (duplicates aside)
        for pid, k, on_floor in zip(truth.person_ids, cell, near):
            if on_floor:
                expected += pred.camera_detect[c, k]
                found += int(pid) in detected
    assert found > 500
    assert expected == pytest.approx(found, rel=0.12)


def test_the_people_stood_on_a_cell_are_the_crowds_height_quantiles():
    """`crowd_heights` against the mixture's own distribution function (scipy: truncated normals for women and
    men, as `sim.humanoid.sample_heights` draws them), and against a crowd whose heights are all fixed."""
    from scipy import stats

    from crossview.measure.coverage import HEIGHT_QUANTILES, crowd_heights
    from sim.crowd import CrowdConfig

    low, high = 1.5, 1.95
    parts = [stats.truncnorm((low - m) / s, (high - m) / s, loc=m, scale=s) for m, s in ((1.63, 0.065), (1.76, 0.07))]
    x = np.linspace(low, high, 4501)
    exact = np.interp(HEIGHT_QUANTILES, 0.5 * (parts[0].cdf(x) + parts[1].cdf(x)), x)
    np.testing.assert_allclose(crowd_heights(CrowdConfig(people=30, height_range_m=(low, high))), exact, atol=0.01)
    fixed = CrowdConfig(people=3, heights_m=(1.6, 1.7, 1.9))
    assert crowd_heights(fixed) == pytest.approx(np.quantile([1.6, 1.7, 1.9], HEIGHT_QUANTILES))
