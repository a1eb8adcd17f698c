"""View volumes: planes against projection, overlap of views, gating of targets, and that gating changes nothing."""

import numpy as np
import pytest

from core.types import COCO17
from tests.tracker.synthetic import Walkers, look_at_camera, make_frames
from tracker.config import TrackerConfig
from tracker.geometry import project
from tracker.target_rows import TargetRows
from tracker.tracker import Tracker
from tracker.visibility import (
    EvidenceParams,
    SightMap,
    count_sightings,
    overlapping_views,
    sight_map_grid,
    targets_in_view,
    view_planes,
)


def _corridor(num_cameras=8, spacing_m=2.0):
    """Cameras 3 m up along a corridor, each looking (nearly) straight down: each sees a few metres of it."""
    return [look_at_camera(f"c{k}", [1.0 + spacing_m * k, 2.0, 3.0], [1.0 + spacing_m * k, 2.3, 0.0], f_px=600.0)
            for k in range(num_cameras)]


def test_planes_agree_with_projection():
    cam = look_at_camera("a", [0.0, 0.0, 3.0], [1.0, 0.5, 0.0], dist=np.array([-0.2, 0.05, 0.0, 0.0, 0.0]))
    planes = view_planes(cam)
    rng = np.random.default_rng(0)
    X = rng.uniform([-8, -8, -1], [8, 8, 4], (4000, 3))
    inside = np.all(X @ planes[:, :3].T + planes[:, 3] >= 0, axis=1)
    px = project(cam.P, X)
    depth = X @ cam.R_cam_from_world[2] + cam.t_cam_from_world[2]
    # Everything the undistorted pinhole puts in the image (in front) is inside; nothing behind the camera is.
    in_image = (depth > 0.05) & (px[:, 0] >= 0) & (px[:, 0] <= cam.width_px) & (px[:, 1] >= 0) & \
        (px[:, 1] <= cam.height_px)
    assert inside[in_image].all()
    assert not inside[depth < 0].any()
    assert in_image.sum() > 100 and (~inside).sum() > 100


def test_overlap_links_neighbours_only():
    cams = _corridor()
    linked = overlapping_views(cams, -0.5, 2.6, 0.5)
    assert linked.shape == (8, 8) and np.array_equal(linked, linked.T) and linked.diagonal().all()
    assert linked[0, 1] and linked[3, 4]
    assert not linked[0, 7] and not linked[1, 6]
    assert overlapping_views(cams, -0.5, 2.6, 1e3).all()  # a huge margin links everything


@pytest.mark.parametrize("compiled", [True, False])
def test_targets_in_view_keeps_the_near_and_the_recent(compiled):
    kernel = targets_in_view if compiled else targets_in_view.py_func
    cam = _corridor()[0]  # sees x in about [-1.5, 3.5] at the floor
    planes = view_planes(cam)
    J = 17
    pos = np.full((4, J, 3), np.nan)
    for r, x in enumerate([1.0, 12.0, 3.9, 20.0]):
        pos[r, :, :] = [x, 2.0, 1.0]
        pos[r, :, 2] = np.linspace(0.1, 1.7, J)
    pos[3, :, :] = np.nan  # nothing known
    vel = np.zeros_like(pos)
    joint_s = np.zeros((4, J))
    obs_s = np.full((4, 2, J), np.nan)
    obs_s[1, 0, 3] = 0.9  # target 1 (far) was matched by this camera 0.1 s ago
    cam_s = np.nanmax(obs_s, axis=2, initial=-np.inf)
    out = np.empty(4, dtype=np.int64)
    n = kernel(planes, 0, pos, vel, joint_s, obs_s, cam_s, 1.0, 0.5, 0.5, 1.0, out)
    assert out[:n].tolist() == [0, 1, 2]
    n = kernel(planes, 0, pos, vel, joint_s, obs_s, cam_s, 3.0, 0.5, 0.5, 1.0, out)  # the match is now too old
    assert out[:n].tolist() == [0, 2]
    cam_s[1, 0] = 1.0  # a later frame of the camera matched the target with none of these joints: still recent
    n = kernel(planes, 0, pos, vel, joint_s, obs_s, cam_s, 1.0, 0.5, 0.5, 1.0, out)
    assert out[:n].tolist() == [0, 1, 2]


@pytest.mark.parametrize("compiled", [True, False])
def test_sight_map_expects_as_often_as_the_camera_sees_people_there(compiled):
    kernel = count_sightings if compiled else count_sightings.py_func
    cam = _corridor()[0]  # sees x in about [-1.5, 3.5] at the floor
    grid, nx, ny = sight_map_grid([cam], 1.0)
    assert grid.tolist() == [-9.0, -8.0, 1.0] and (nx, ny) == (20, 20)  # the camera's centre widened by 10 m
    J = 17
    pos = np.zeros((3, J, 3))
    pos[:, :, 2] = 1.0
    pos[0, :, :2] = [0.5, 2.2]  # in the cell (9, 10): the camera matched 1 in 4 confirmed targets there
    pos[1, :, :2] = [2.5, 2.2]  # in (11, 10): no sightings there yet
    pos[2, :, :2] = [30.0, 2.2]  # outside the view
    cell_a, cell_b, total = 10 * nx + 9, 10 * nx + 11, nx * ny
    map_expected, map_matched = np.zeros(nx * ny + 1), np.zeros(nx * ny + 1)
    map_expected[cell_a], map_matched[cell_a] = 40.0, 10.0
    map_expected[total], map_matched[total] = 40.0, 10.0

    sight_map = SightMap(grid, nx, ny, map_expected, map_matched)

    def step(matched, confirmed, prior, sight=sight_map):
        targets = TargetRows.empty(3, 1, J, 1)._replace(pos=pos, joint_s=np.zeros((3, J)))
        kernel(view_planes(cam), np.array([11, 12]), targets, 0.0, np.array(matched), np.array(confirmed), sight,
               EvidenceParams(max_predict_s=0.5, inside_m=0.3, window_s=1.0, prior_count=prior))
        return targets.expected, targets.sighted, targets.evidence_s

    expected, sighted, _ = step([True, False, False], [False, False, False], 10.0)
    camera_rate = (10 + 10) / (40 + 10)  # the camera over all cells, with 10 pseudo-sightings at 1
    np.testing.assert_allclose(expected, [(10 + 10 * camera_rate) / (40 + 10), camera_rate, 0.0])
    np.testing.assert_allclose(sighted, [1.0, 0.0, 0.0])
    assert map_expected[total] == 40.0  # only confirmed targets teach the map
    step([True, False, False], [True, True, True], 10.0)
    assert (map_expected[cell_a], map_matched[cell_a], map_expected[cell_b], map_matched[cell_b]) == (41, 11, 1, 0)
    assert (map_expected[total], map_matched[total]) == (42, 11)
    expected, _, _ = step([False, False, False], [False, False, False], 0.0)  # no prior: the cells' own shares
    np.testing.assert_allclose(expected[:2], [11 / 41, 0.0])
    # No map: every frame whose view holds the target counts 1.
    expected, _, _ = step([False, False, False], [True, True, True], 10.0,
                          SightMap(*sight_map_grid([cam], 0.0), np.zeros(2), np.zeros(2)))
    np.testing.assert_allclose(expected, [1.0, 1.0, 0.0])


@pytest.mark.parametrize("compiled", [True, False])
def test_a_target_without_hips_is_expected_by_no_camera(compiled):
    kernel = count_sightings if compiled else count_sightings.py_func
    cams = _corridor()
    J = 17
    pos = np.zeros((2, J, 3))
    pos[:, :, :2] = [1.0, 2.2]  # both in the first camera's view, with every joint
    pos[:, :, 2] = 1.0
    pos[1, 12] = np.nan  # target 1 has no right hip: where it stands is not known
    for cam in cams:  # the cameras that see the place and those that do not
        grid, nx, ny = sight_map_grid([cam], 1.0)
        targets = TargetRows.empty(2, 1, J, 1)._replace(pos=pos, joint_s=np.zeros((2, J)))
        kernel(view_planes(cam), np.array([11, 12]), targets, 0.0, np.zeros(2, dtype=bool), np.zeros(2, dtype=bool),
               SightMap(grid, nx, ny, np.zeros(nx * ny + 1), np.zeros(nx * ny + 1)),
               EvidenceParams(max_predict_s=0.5, inside_m=0.3, window_s=1.0, prior_count=10.0))
        assert targets.expected[1] == 0.0 and targets.sighted[1] == 0.0
        assert targets.expected[0] == (1.0 if cam is cams[0] else 0.0)


def test_sight_maps_too_large_for_memory_are_refused():
    from core.errors import ConfigError

    far = [look_at_camera("a", [0.0, 0.0, 3.0], [0.0, 1.0, 0.0]),
           look_at_camera("b", [3e3, 3e3, 3.0], [3e3, 3e3 + 1, 0.0])]
    with pytest.raises(ConfigError, match=r"ghost_cell_m: 0.5 m makes 2 sight maps of 36,481,600 cells"):
        Tracker(far, TrackerConfig(ghost_cell_m=0.5))
    Tracker(far, TrackerConfig(ghost_cell_m=0.0))  # no map
    Tracker(far, TrackerConfig(ghost_cell_m=5.0))


def test_gating_changes_no_output():
    """Within the cameras' views nothing changes: the same run with a margin that lets every target and camera
    pair in (association without gating) gives the same targets and poses at every frame. Both trackers link
    the same camera pairs in initialisation: there the gate is meant to change things, by keeping chance
    epipolar matches of cameras that cannot see one person out of a new detection's neighbours."""
    cams = _corridor()
    rng = np.random.default_rng(4)
    walkers = Walkers.random(5, 16.0, 4.0, rng)
    frames, _ = make_frames(cams, walkers, 4.0, 10.0, rng)
    config = TrackerConfig.preset("store")
    gated, open_ = Tracker(cams, config, COCO17), Tracker(cams, config.replace(view_margin_m=1e3), COCO17)
    assert not gated._linked.all() and open_._linked.all()
    open_._linked = gated._linked.copy()
    outputs = 0
    for frame in frames:
        a, b = gated.update(frame), open_.update(frame)
        assert [t.id for t in a] == [t.id for t in b]
        for ta, tb in zip(a, b):
            np.testing.assert_allclose(ta.pose, tb.pose, rtol=0, atol=1e-9)
        outputs += len(a)
    assert outputs > 100
