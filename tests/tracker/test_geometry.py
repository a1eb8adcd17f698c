"""Geometry: projection against OpenCV, undistortion round trip, rays (eq. 3), fundamental matrix (eq. S1)."""

import cv2
import numpy as np
import pytest

from tests.reference.cameras import distort_pixels
from tests.reference.cameras import project as project_distorted_px
from tests.reference.geometry import point_to_ray_distance
from tests.reference.plain import plain_python
from tests.tracker.synthetic import look_at_camera
from tracker.geometry import (
    fundamental_matrix,
    point_line_distance_px,
    project,
    ray_directions,
    undistort_detections,
    undistort_points,
    world_from_pixel_matrix,
)

DIST = np.array([-0.2, 0.05, 0.001, -0.001, 0.0])


@pytest.fixture
def camera():
    return look_at_camera("a", [0.0, -4.0, 3.0], [0.5, 0.5, 1.0], dist=DIST)


@pytest.fixture
def points():
    return np.random.default_rng(0).uniform([-1, -1, 0], [2, 2, 2], (50, 3))


def test_undistort_inverts_distortion_onto_the_pinhole_projection(camera, points):
    # Reference: OpenCV's lens model in numpy (tests/reference/cameras.py, itself checked against cv2.projectPoints).
    rvec, _ = cv2.Rodrigues(camera.R_cam_from_world)
    opencv, _ = cv2.projectPoints(points, rvec, camera.t_cam_from_world, camera.K, camera.dist)
    distorted = project_distorted_px(camera, points)[0]
    np.testing.assert_allclose(distorted, opencv.reshape(-1, 2), atol=1e-6)  # px
    np.testing.assert_allclose(undistort_points(camera, distorted), project(camera.P, points), atol=1e-3)  # px
    np.testing.assert_allclose(distort_pixels(camera, project(camera.P, points)), distorted, atol=1e-3)  # px


def test_undistort_keeps_nan_and_rejects_infinity(camera):
    out = undistort_points(camera, np.array([[np.nan, 1.0], [np.inf, 2.0], [640.0, 360.0]]))
    assert np.isnan(out[:2]).all() and np.isfinite(out[2]).all()


def test_project_gives_nan_behind_the_camera(camera):
    behind = camera.center_world - 2.0 * camera.R_cam_from_world[2]
    assert np.isnan(project(camera.P, behind)).all()


def test_ray_through_a_projection_passes_through_the_point(camera, points):
    # Eq. (3): the back-projected ray of x = P X contains X.
    rays = ray_directions(camera, project(camera.P, points))
    np.testing.assert_allclose(point_to_ray_distance(points, camera.center_world, rays), 0.0, atol=1e-9)  # m
    np.testing.assert_allclose(np.linalg.norm(rays, axis=-1), 1.0)


def test_rays_of_several_cameras_at_once_equal_each_cameras(camera, points):
    # One (3, 3) matrix per leading row: the same directions as one call per camera.
    other = look_at_camera("other", [3.0, -2.0, 3.0], [0.0, 0.0, 1.0])
    cams = [camera, other, camera]
    px = np.stack([project(c.P, points) for c in cams])  # (3, N, 2)
    M = np.stack([world_from_pixel_matrix(c) for c in cams])[:, None]  # (3, 1, 3, 3)
    np.testing.assert_allclose(ray_directions(None, px, M),
                               np.stack([ray_directions(c, p) for c, p in zip(cams, px)]), rtol=0, atol=1e-15)


def test_point_to_ray_distance_by_hand():
    # A point 3 m along the z axis and 0.4 m to the side is 0.4 m from the z axis.
    d = point_to_ray_distance(np.array([0.4, 0.0, 3.0]), np.zeros(3), np.array([0.0, 0.0, 1.0]))
    assert d == pytest.approx(0.4)


def test_fundamental_matrix_satisfies_the_epipolar_constraint(points):
    a = look_at_camera("a", [0.0, -4.0, 3.0], [0.5, 0.5, 1.0])
    b = look_at_camera("b", [4.0, 1.0, 2.5], [0.5, 0.5, 1.0])
    F = fundamental_matrix(a, b)
    xa, xb = project(a.P, points), project(b.P, points)
    lines = np.concatenate([xa, np.ones((len(xa), 1))], axis=1) @ F.T  # eq. (S1): l_b = F x_a
    np.testing.assert_allclose(point_line_distance_px(xb, lines), 0.0, atol=1e-6)  # px


@pytest.mark.parametrize("dist", [DIST, np.zeros(5)])
def test_compiled_frame_undistortion_agrees_with_opencv_and_masks_unusable_joints(dist):
    cam = look_at_camera("a", [0.0, -4.0, 3.0], [0.5, 0.5, 1.0], dist=dist)
    rng = np.random.default_rng(4)
    kp = rng.uniform([-100.0, -100.0], [1380.0, 820.0], (6, 5, 2))
    scores = rng.uniform(0.0, 1.0, (6, 5))
    kp[0, 0] = np.nan
    kp[0, 1, 1] = np.inf
    scores[1, :3] = [np.nan, 0.0, np.inf]
    scores[2, 0] = 0.1  # below the threshold
    scores[2, 1] = -np.inf
    # Reference: the tracker's rule (score NaN -> 0, clipped to [0, 1], positive and >= 0.2) and cv2.
    clean = np.clip(np.nan_to_num(scores, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    usable = np.all(np.isfinite(kp), axis=-1) & (clean >= 0.2) & (clean > 0)
    expected = undistort_points(cam, np.where(usable[..., None], kp, np.nan))
    for kernel in (undistort_detections, plain_python(undistort_detections)):
        out = np.zeros(kp.shape)
        counts = kernel(kp, scores, 0.2, cam.K, cam.dist, out)
        np.testing.assert_array_equal(counts, usable.sum(axis=1))
        np.testing.assert_array_equal(np.isnan(out), np.isnan(expected))
        np.testing.assert_allclose(out, expected, atol=1e-9)  # px
