"""What each camera can see: view volumes from the calibration, which targets lie in them, which views overlap.

A camera's view volume is the pyramid through its centre and the edges of its undistorted image (the
bounding box of the undistorted image border, widened by a pixel margin), cut by a near plane. It is held as
five planes n·X + d >= 0 (unit n, world frame, metres), so the signed distance of a point to each plane is
one dot product.

Why gating by it is exact where it matters: a detection's ray lies inside its camera's volume, so a joint
farther than m outside the volume is farther than m from every ray of the frame, and with m >= α3D its
3D term of eq. (4) is not positive. A target whose whole predicted body (a sphere around its known joints)
lies farther than `margin_m` outside therefore has no positive 3D term with any detection of the frame;
targets that this camera matched recently (which could still win on the 2D term of eq. 2) are kept
regardless (`targets_in_view`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from core.jit import jit
from core.types import Camera
from tracker.geometry import undistort_points

NEAR_M = 0.05
"""Distance of the near plane in front of the camera centre, metres."""


def undistorted_bounds_px(camera: Camera, samples: int = 33) -> tuple[float, float, float, float]:
    """(u_min, v_min, u_max, v_max) of the image border mapped to undistorted pixels.

    Lens distortion moves the border, so the undistorted image is not the (0, 0)-(W, H) rectangle; its
    bounding box holds every undistorted detection.
    """
    W, H = float(camera.width_px), float(camera.height_px)
    s = np.linspace(0.0, 1.0, samples)
    border = np.concatenate([
        np.stack([s * W, np.zeros_like(s)], axis=-1), np.stack([s * W, np.full_like(s, H)], axis=-1),
        np.stack([np.zeros_like(s), s * H], axis=-1), np.stack([np.full_like(s, W), s * H], axis=-1),
    ])
    und = undistort_points(camera, border)
    und = und[np.all(np.isfinite(und), axis=-1)]
    if not und.size:
        return 0.0, 0.0, W, H
    lo, hi = np.minimum(und.min(axis=0), 0.0), np.maximum(und.max(axis=0), [W, H])
    return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


def view_planes(camera: Camera, margin_px: float = 0.0, bounds_px: tuple[float, float, float, float] | None = None,
                near_m: float = NEAR_M) -> np.ndarray:
    """(5, 4) planes (n_x, n_y, n_z, d) bounding the camera's view volume: n·X + d >= 0 inside, |n| = 1.

    Rows: the near plane `near_m` in front of the centre, then the left, right, top and bottom edge of
    `bounds_px` (u_min, v_min, u_max, v_max) in undistorted pixels, by default the undistorted image
    (`undistorted_bounds_px`), widened by `margin_px`.
    """
    K, R, t = camera.K, camera.R_cam_from_world, camera.t_cam_from_world
    u0, v0, u1, v1 = undistorted_bounds_px(camera) if bounds_px is None else bounds_px
    u0, v0, u1, v1 = u0 - margin_px, v0 - margin_px, u1 + margin_px, v1 + margin_px
    # In camera coordinates a point is right of the column u when (K X)_0 - u (K X)_2 >= 0 (z > 0), etc.
    rows_cam = [np.array([0.0, 0.0, 1.0]), K[0] - u0 * K[2], u1 * K[2] - K[0], K[1] - v0 * K[2], v1 * K[2] - K[1]]
    offsets = [-near_m, 0.0, 0.0, 0.0, 0.0]
    planes = np.empty((5, 4))
    for i, (n_cam, off) in enumerate(zip(rows_cam, offsets)):
        norm = np.linalg.norm(n_cam)
        n_cam = n_cam / norm
        # n_cam·(R X + t) + off = (R^T n_cam)·X + n_cam·t + off
        planes[i, :3] = R.T @ n_cam
        planes[i, 3] = n_cam @ t + off
    return planes


def all_view_planes(cameras: Sequence[Camera], margin_px: float = 0.0) -> np.ndarray:
    """(C, 5, 4) `view_planes` of every camera."""
    return np.stack([view_planes(c, margin_px) for c in cameras]) if cameras else np.zeros((0, 5, 4))


def overlapping_views(cameras: Sequence[Camera], min_z_m: float, max_z_m: float, margin_m: float,
                      grid: int = 12, max_depth_m: float = 40.0) -> np.ndarray:
    """(C, C) bool: whether two cameras' views share a point of the band min_z_m <= z <= max_z_m (where
    people's joints are), within `margin_m`; the diagonal is True.

    Each camera's part of the band is sampled along the rays of a grid x grid of pixels over its
    undistorted image, at depths up to `max_depth_m`; a pair overlaps when a sample of one lies inside
    the other's view volume widened by `margin_m` (and the same the other way round is not needed: a
    shared point is a sample of either camera's rays within the sampling step, which the margin covers).
    """
    C = len(cameras)
    planes = all_view_planes(cameras)
    overlap = np.eye(C, dtype=bool)
    for a in range(C):
        pts = _band_samples(cameras[a], min_z_m, max_z_m, grid, max_depth_m)
        if pts.shape[0]:
            _samples_inside(planes, np.ascontiguousarray(pts), float(margin_m), overlap[a])
    return overlap | overlap.T


@jit
def inside_volume(planes, x, y, z, margin_m):
    """Whether the point (x, y, z) lies inside the volume of planes (P, 4) widened by margin_m (False for a
    NaN coordinate); the test stops at the first plane the point lies outside."""
    for p in range(planes.shape[0]):
        if not planes[p, 0] * x + planes[p, 1] * y + planes[p, 2] * z + planes[p, 3] >= -margin_m:
            return False
    return True


@jit
def poses_in_volume(planes, poses, margin_m, out):
    """out[n] = whether some joint of poses[n] (N, J, 3) lies inside the volume of planes (P, 4) widened by
    margin_m (`inside_volume`); a pose's search stops at its first such joint."""
    for n in range(poses.shape[0]):
        out[n] = False
        for j in range(poses.shape[1]):
            if inside_volume(planes, poses[n, j, 0], poses[n, j, 1], poses[n, j, 2], margin_m):
                out[n] = True
                break


@jit
def _samples_inside(planes, pts, margin_m, out):
    """out[c] |= some point of pts (N, 3) lies inside camera c's view volume (planes (C, 5, 4)) widened by
    margin_m; each camera's search stops at its first such point (in the hypermarket most pairs share none,
    and a point fails on its first plane or two)."""
    for c in range(planes.shape[0]):
        if out[c]:
            continue
        for n in range(pts.shape[0]):
            if inside_volume(planes[c], pts[n, 0], pts[n, 1], pts[n, 2], margin_m):
                out[c] = True
                break


def _band_samples(camera: Camera, min_z_m: float, max_z_m: float, grid: int, max_depth_m: float) -> np.ndarray:
    """(N, 3) points on the rays of a pixel grid of the camera, spaced about 0.25 m, inside the z band."""
    u0, v0, u1, v1 = undistorted_bounds_px(camera)
    u, v = np.meshgrid(np.linspace(u0, u1, grid), np.linspace(v0, v1, grid))
    pix = np.stack([u.ravel(), v.ravel(), np.ones(u.size)], axis=-1)
    dirs = pix @ (camera.R_cam_from_world.T @ np.linalg.inv(camera.K)).T  # unnormalised: depth along the axis
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    depths = np.arange(NEAR_M, max_depth_m, 0.25)
    pts = camera.center_world + depths[:, None, None] * dirs[None, :, :]
    pts = pts.reshape(-1, 3)
    return pts[(pts[:, 2] >= min_z_m) & (pts[:, 2] <= max_z_m)]


@jit
def targets_in_view(planes, camera, pos, vel, joint_s, obs_s, cam_s, stamp_s, max_predict_s, margin_m, recent_s, out):
    """The rows of the targets a camera's frame is scored against; returns how many were written to `out`.

    A target is in when its predicted body (eq. 5), the sphere around the mean of its known joints through
    the farthest one, comes within `margin_m` of the camera's view volume, or when the camera saw one of its
    joints within `recent_s` (its 2D term of eq. 2 may still count). Targets without a known joint are out
    (their affinity is 0 with every detection).

    Args:
        planes: (5, 4) `view_planes` of the camera; camera: its index in obs_s.
        pos, vel: (T, J, 3) X_t' and V_t'; joint_s: (T, J) t', s; obs_s: (T, C, J) stamps of the last matched
            point per camera (NaN none); cam_s: (T, C) the stamp of the camera's last frame matched to the
            target, >= its every obs_s (NaN none): only a target with a recent one has its points looked at.
        stamp_s: t, s; max_predict_s: the horizon of eq. (5), s.
        out: (T,) int64, the rows written first.
    """
    T, J = pos.shape[0], pos.shape[1]
    pred = np.empty((J, 3))
    n = 0
    for t in range(T):
        recent = False
        if stamp_s - cam_s[t, camera] <= recent_s:  # False for NaN
            for j in range(J):
                if stamp_s - obs_s[t, camera, j] <= recent_s:  # False for NaN
                    recent = True
                    break
        if recent:
            out[n] = t
            n += 1
            continue
        count = 0
        c0 = c1 = c2 = 0.0
        for j in range(J):
            horizon = min(max(stamp_s - joint_s[t, j], 0.0), max_predict_s)
            for k in range(3):
                pred[j, k] = pos[t, j, k] + vel[t, j, k] * horizon
            if np.isfinite(pred[j, 0] + pred[j, 1] + pred[j, 2]):
                c0 += pred[j, 0]
                c1 += pred[j, 1]
                c2 += pred[j, 2]
                count += 1
        if count == 0:
            continue
        c0, c1, c2 = c0 / count, c1 / count, c2 / count
        radius_sq = 0.0
        for j in range(J):
            if np.isfinite(pred[j, 0] + pred[j, 1] + pred[j, 2]):
                dx, dy, dz = pred[j, 0] - c0, pred[j, 1] - c1, pred[j, 2] - c2
                radius_sq = max(radius_sq, dx * dx + dy * dy + dz * dz)
        if inside_volume(planes, c0, c1, c2, np.sqrt(radius_sq) + margin_m):
            out[n] = t
            n += 1
    return n


def sight_map_grid(cameras: Sequence[Camera], cell_m: float, pad_m: float = 10.0) -> tuple[np.ndarray, int, int]:
    """The floor grid of the cameras' sight maps: (x0, y0, cell_m) and its cell counts (nx, ny).

    It covers the cameras' centres on the floor widened by `pad_m`; a point beyond it falls in the nearest
    edge cell. cell_m <= 0: a single cell (the map is off).
    """
    if cell_m <= 0 or not cameras:
        return np.array([0.0, 0.0, 0.0]), 1, 1
    xy = np.stack([c.center_world[:2] for c in cameras])
    lo, hi = xy.min(axis=0) - pad_m, xy.max(axis=0) + pad_m
    n = np.maximum(np.ceil((hi - lo) / cell_m).astype(np.int64), 1)
    return np.array([lo[0], lo[1], cell_m]), int(n[0]), int(n[1])


class SightMap(NamedTuple):
    """One camera's sight map (docs/tracker.md, "No ghosts"): how often it matched the confirmed targets it
    should have seen, per floor cell.

    Attributes:
        grid: (3,) the cells' corner x0, y0 and side, m (`sight_map_grid`; side 0: no map).
        nx, ny: the cell counts along x and y.
        expected: (nx * ny + 1,) decayed count of the confirmed targets the camera should have seen per cell,
            then over all cells.
        matched: (nx * ny + 1,) of those, the ones it matched.
    """

    grid: np.ndarray
    nx: int
    ny: int
    expected: np.ndarray
    matched: np.ndarray


class EvidenceParams(NamedTuple):
    """The `TrackerConfig` fields of the sightings count (`count_sightings`).

    Attributes:
        max_predict_s: the horizon of eq. (5), s.
        inside_m: how far inside the view volume a hip centre is seen, m.
        window_s: the time constant of the decayed counts, s.
        prior_count: the pseudo-sightings of a map cell (see `count_sightings`).
    """

    max_predict_s: float
    inside_m: float
    window_s: float
    prior_count: float


@jit
def count_sightings(planes, hips, targets, stamp_s, matched, confirmed, sight_map, params):
    """Counts what one camera frame says about each target (in place).

    A target (`TargetRows`) whose predicted hip centre (eq. 5, hips (2,) known) lies at least `inside_m` inside
    the camera's view volume (planes (5, 4)) was expected to be seen, as often as this camera matches the
    confirmed targets standing in the same floor cell (its `SightMap`: shelves and crowds hide people from some
    cameras in some places). That rate is the cell's share of matched sightings with `prior_count`
    pseudo-sightings at the camera's share over all cells, itself with `prior_count` at 1: a new map trusts the
    camera everywhere, a cell learns from the camera as a whole until it has its own sightings.
    The targets' expected (T,) and sighted (T,) are counts decayed with time constant `window_s` since their
    evidence_s (T,): the first adds that rate (1 for a matched target outside the volume), the second 1 for
    each frame that matched the target (matched (T,) bool). The confirmed targets (confirmed (T,) bool) inside
    the volume teach the camera's map; a map without cells (side 0) makes every rate 1. The scalars are
    `EvidenceParams` params.
    """
    pos, vel, joint_s = targets.pos, targets.vel, targets.joint_s
    expected, sighted, evidence_s = targets.expected, targets.sighted, targets.evidence_s
    grid, nx, ny = sight_map.grid, sight_map.nx, sight_map.ny
    map_expected, map_matched = sight_map.expected, sight_map.matched
    max_predict_s, inside_m, window_s, prior_count = params.max_predict_s, params.inside_m, params.window_s, \
        params.prior_count
    T = pos.shape[0]
    total = nx * ny
    c = np.empty(3)  # the predicted hip centre, one buffer for every target
    for r in range(T):
        c[:] = 0.0
        for h in range(hips.size):
            j = hips[h]
            horizon = min(max(stamp_s - joint_s[r, j], 0.0), max_predict_s)
            for k in range(3):
                c[k] += (pos[r, j, k] + vel[r, j, k] * horizon) / hips.size
        seen = inside_volume(planes, c[0], c[1], c[2], -inside_m)  # False for NaN (a hip unknown)
        if not (seen or matched[r]):
            continue
        rate = 1.0
        if seen and grid[2] > 0:
            ix = min(max(int(np.floor((c[0] - grid[0]) / grid[2])), 0), nx - 1)
            iy = min(max(int(np.floor((c[1] - grid[1]) / grid[2])), 0), ny - 1)
            cell = iy * nx + ix
            camera_rate = (map_matched[total] + prior_count) / (map_expected[total] + prior_count)
            rate = (map_matched[cell] + prior_count * camera_rate) / (map_expected[cell] + prior_count)
            if confirmed[r]:
                hit = 1.0 if matched[r] else 0.0
                map_expected[cell] += 1.0
                map_matched[cell] += hit
                map_expected[total] += 1.0
                map_matched[total] += hit
        decay = np.exp(-max(stamp_s - evidence_s[r], 0.0) / window_s)
        expected[r] = expected[r] * decay + rate
        sighted[r] = sighted[r] * decay + (1.0 if matched[r] else 0.0)
        evidence_s[r] = stamp_s


HIP_HEIGHT_M = 0.9
"""Height of a standing adult's hips, metres: where a camera's view of the floor is measured (zones, coverage)."""


def floor_sight(cameras: Sequence[Camera], xy: np.ndarray, height_m: float = HIP_HEIGHT_M) -> np.ndarray:
    """(C, N) bool: whether camera c sees the point above floor position xy[n] (N, 2) at `height_m`: in front
    of it and inside its image (`core.projection.in_image`, the lens's model). The one geometry of camera
    overlap on the floor: a point's camera count is its column's sum (coverage), and a camera's cells its row's
    (`tracker.zones`)."""
    from core.projection import in_image

    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    points = np.column_stack([xy, np.full(len(xy), float(height_m))])
    if not len(cameras):
        return np.zeros((0, len(xy)), dtype=bool)
    return np.stack([in_image(camera, points)[1] for camera in cameras])
