"""Camera rigs: placement, intrinsics from resolution and field of view, lens distortion, calibration files.

Owns the camera side of the sensor model: building the rig a scenario asks for (a ceiling grid,
explicit placements or a real calibration file: the CMU Panoptic dome's, or the dataset layout's
calibration.json of Campus, Shelf and the Store datasets, which `crossview.datasets` reads with the same
parser), projecting world points to distorted pixels with OpenCV's camera model, and the one conversion
from the OpenCV camera frame (x right, y down, z forward) to MuJoCo's (looks down -z, y up).
"""

from __future__ import annotations

import enum
import functools
import json
import math
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np

from core.errors import ScenarioError
from core.jit import intrinsic, jit, llvm_ir, types
from core.types import MAX_IMAGE_PX as MAX_CALIBRATION_IMAGE_PX
from core.types import Camera
from sim.config import bounded, check_ranges
from sim.store import MAX_FLOOR_M

MAX_GRID = 100  # cameras along one side of a grid
MAX_IMAGE_PX = 16384
# Points closer than this in front of the camera plane count as behind it (their projection blows up).
MIN_DEPTH_M = 1e-6
# When a camera looks (almost) straight down, "up" in its image points along world +y.
_STRAIGHT_DOWN_COS = 0.999


@dataclass(frozen=True)
class CameraPlacement:
    """[[cameras.placements]]: one camera at an explicit position, looking at a point.

    Attributes:
        name: camera name; empty gives "cam{index:02d}".
        position_m: (x, y, z) of the camera centre in the world frame.
        look_at_m: (x, y, z) the optical axis passes through; must lie below the camera.
        roll_deg: rotation of the image about the optical axis.
    """

    position_m: tuple[float, float, float] = bounded((0.0, 0.0, 3.0), -MAX_FLOOR_M, MAX_FLOOR_M)
    look_at_m: tuple[float, float, float] = bounded((1.0, 1.0, 0.0), -MAX_FLOOR_M, MAX_FLOOR_M)
    name: str = ""
    roll_deg: float = bounded(0.0, -360.0, 360.0)

    def __post_init__(self):
        check_ranges(self)
        direction = np.subtract(self.look_at_m, self.position_m)
        norm = float(np.linalg.norm(direction))
        if norm == 0:
            raise ValueError(f"placements.look_at_m: {self.look_at_m} equals position_m; it must differ")
        if direction[2] / norm > -0.05:
            raise ValueError(
                f"placements.look_at_m: {self.look_at_m} is not below position_m {self.position_m}; "
                "ceiling cameras must look down (look_at z < position z)"
            )


class CalibrationFormat(enum.Enum):
    """What kind of file `cameras.calibration` names."""

    PANOPTIC = "panoptic"  # a CMU Panoptic calibration_*.json (`load_panoptic`)
    DATASET = "dataset"  # the dataset layout's calibration.json (`load_dataset_calibration`)


@dataclass(frozen=True)
class CameraRigConfig:
    """[cameras]: where the cameras hang and what lenses they have.

    Without `placements` or `calibration`, a `rows` x `cols` grid hangs `ceiling_gap_m` below the
    ceiling, inset `margin_m` from the walls; each camera looks at a point `aim_height_m` above the
    floor, pulled from below itself toward the store centre by `aim_inward` (0 looks straight down,
    1 at the centre), so that it tilts toward its part of the floor and the views overlap.

    Attributes:
        rows: cameras of the grid along y.
        cols: cameras of the grid along x.
        width_px: image width.
        height_px: image height.
        hfov_deg: horizontal field of view of the undistorted pinhole.
        k1: OpenCV radial distortion, r² term.
        k2: OpenCV radial distortion, r⁴ term.
        p1: OpenCV tangential distortion, first term.
        p2: OpenCV tangential distortion, second term.
        k3: OpenCV radial distortion, r⁶ term.
        margin_m: inset of the outer grid cameras from the walls.
        ceiling_gap_m: distance of the cameras below the ceiling.
        aim_height_m: height of the aim points above the floor.
        aim_inward: fraction of the way from below the camera to the store centre.
        position_jitter_m: std of a random displacement of each grid camera (x and y).
        placements: explicit cameras ([[cameras.placements]] tables); when given they replace the grid.
        calibration: path of a real calibration file (see `calibration_format`); replaces the grid and
            `width_px` ... `k3`. A relative path is taken from the scenario file's folder (from the working
            directory for a scenario built in code). Its cameras stand where the real rig has them, over the
            floor or around it (outside the walls), above the ground and below the ceiling; each must see
            some of the floor.
        calibration_format: "panoptic" (a CMU Panoptic calibration file) or "dataset" (the calibration.json
            of the dataset layout of Campus, Shelf and the Store datasets; its normalised K needs the
            image size, which the file's `image_wh` = [width, height] gives).
        calibration_kind: camera type to take from a Panoptic calibration file ("hd": its 1920x1080 cameras).
        calibration_origin_m: where the calibration's world origin lies in the store frame.
        calibration_count: how many of the calibration's cameras to use, spread evenly over the file's
            order (the first, the last and evenly between); 0 uses them all.
    """

    rows: int = bounded(3, 1, MAX_GRID, unit="cameras")
    cols: int = bounded(4, 1, MAX_GRID, unit="cameras")
    width_px: int = bounded(1280, 1, MAX_IMAGE_PX)
    height_px: int = bounded(720, 1, MAX_IMAGE_PX)
    hfov_deg: float = bounded(90.0, 0.0, 180.0, low_open=True, high_open=True)
    k1: float = bounded(-0.05, -10.0, 10.0, unit="")
    k2: float = bounded(0.01, -10.0, 10.0, unit="")
    p1: float = bounded(0.0, -1.0, 1.0, unit="")
    p2: float = bounded(0.0, -1.0, 1.0, unit="")
    k3: float = bounded(0.0, -10.0, 10.0, unit="")
    margin_m: float = bounded(0.3, 0.0, MAX_FLOOR_M)
    ceiling_gap_m: float = bounded(0.1, 0.0, 20.0)
    aim_height_m: float = bounded(1.0, 0.0, 20.0)
    aim_inward: float = bounded(0.3, 0.0, 1.0, unit="fraction")
    position_jitter_m: float = bounded(0.0, 0.0, MAX_FLOOR_M)
    placements: tuple[CameraPlacement, ...] = ()
    calibration: str = ""
    calibration_format: CalibrationFormat = CalibrationFormat.PANOPTIC
    calibration_kind: str = "hd"
    calibration_origin_m: tuple[float, float, float] = bounded((0.0, 0.0, 0.0), -MAX_FLOOR_M, MAX_FLOOR_M)
    calibration_count: int = bounded(0, 0, MAX_GRID * MAX_GRID, unit="cameras")

    def __post_init__(self):
        check_ranges(self)
        names = [p.name for p in self.placements if p.name]
        if len(set(names)) != len(names):
            raise ValueError(f"placements.name: names {names} must be unique")

    @property
    def dist(self) -> np.ndarray:
        """(5,) OpenCV distortion (k1, k2, p1, p2, k3)."""
        return np.array([self.k1, self.k2, self.p1, self.p2, self.k3])


def intrinsics(width_px: int, height_px: int, hfov_deg: float) -> np.ndarray:
    """(3, 3) K of a pinhole with square pixels and the principal point at the image centre.

    Pixel centres sit at integer coordinates (OpenCV), so the centre of a W-pixel row is (W - 1) / 2.
    """
    f = 0.5 * width_px / math.tan(math.radians(hfov_deg) / 2)
    return np.array([[f, 0.0, (width_px - 1) / 2], [0.0, f, (height_px - 1) / 2], [0.0, 0.0, 1.0]])


def look_at(position_m, target_m, roll_rad: float = 0.0) -> np.ndarray:
    """(3, 3) R_cam_from_world of an OpenCV camera at `position_m` whose optical axis passes `target_m`.

    Image "down" is the world's down projected onto the image plane; a camera looking straight down
    has image "up" along world +y.
    """
    forward = np.asarray(target_m, dtype=np.float64) - np.asarray(position_m, dtype=np.float64)
    forward /= np.linalg.norm(forward)
    down = np.array([0.0, 0.0, -1.0])
    if abs(forward @ down) > _STRAIGHT_DOWN_COS:
        down = np.array([0.0, -1.0, 0.0])
    x = np.cross(down, forward)
    x /= np.linalg.norm(x)
    y = np.cross(forward, x)
    c, s = math.cos(roll_rad), math.sin(roll_rad)
    x, y = c * x + s * y, -s * x + c * y
    return np.stack([x, y, forward])


def build_rig(scenario, rng: np.random.Generator) -> list[Camera]:
    """The cameras a scenario asks for: explicit placements, a calibration file, or a ceiling grid.

    Args:
        scenario: a `sim.scenario.Scenario`.
        rng: the "cameras" generator (used for `position_jitter_m`).

    Raises:
        ScenarioError: a placed or grid camera lies outside the store, a calibrated camera below the floor,
            above the ceiling or seeing none of the floor, or the calibration file cannot be used.
    """

    config: CameraRigConfig = scenario.cameras
    store = scenario.store
    K = intrinsics(config.width_px, config.height_px, config.hfov_deg)
    if config.calibration:
        path = Path(config.calibration)
        if not path.is_absolute() and scenario.source_path:  # relative to the scenario file
            path = Path(scenario.source_path).parent / path
        try:
            if config.calibration_format is CalibrationFormat.DATASET:
                cameras = load_dataset_calibration(path, origin_m=config.calibration_origin_m)
            else:
                cameras = load_panoptic(path, config.calibration_kind, origin_m=config.calibration_origin_m)
        except FileNotFoundError:
            raise ScenarioError(f"{scenario.where}: cameras.calibration: {config.calibration!r}: no such file "
                                f"({path})") from None
        except (OSError, ValueError) as e:  # (json's and UTF-8's decode errors are ValueErrors)
            raise ScenarioError(f"{scenario.where}: cameras.calibration: cannot use {config.calibration!r} "
                                f"as a {config.calibration_format.value} calibration: {e}") from None
        cameras = spread_subset(cameras, config.calibration_count, f"{scenario.where}: cameras.calibration_count")
        key = "cameras.calibration"
    elif config.placements:
        cameras = []
        for i, p in enumerate(config.placements):
            R = look_at(p.position_m, p.look_at_m, math.radians(p.roll_deg))
            cameras.append(
                Camera(p.name or f"cam{i:02d}", K, config.dist, R, -R @ np.asarray(p.position_m, float),
                       config.width_px, config.height_px)
            )
        key = "cameras.placements"
    else:
        cameras = _grid(config, store, K, rng)
        key = "cameras.rows/cols"
    for i, cam in enumerate(cameras):
        c = cam.center_world
        if key == "cameras.calibration":
            _check_calibrated(scenario.where, f"{key}[{i}]", cam, store)
            continue
        inside = (
            0 <= c[0] <= store.width_m
            and 0 <= c[1] <= store.depth_m
            and 0 <= c[2] <= store.ceiling_m
        )
        if not inside:
            where = f"{key}[{i}]" if key != "cameras.rows/cols" else key
            raise ScenarioError(
                f"{scenario.where}: {where}: camera {cam.name} at ({c[0]:.2f}, {c[1]:.2f}, {c[2]:.2f}) m "
                f"is outside the store [0, {store.width_m}] x [0, {store.depth_m}] x [0, {store.ceiling_m}] m"
            )
    return cameras


# The floor points (FLOOR_PROBES x FLOOR_PROBES, at FLOOR_PROBE_HEIGHT_M) of which a calibrated camera must see one.
FLOOR_PROBES = 41
FLOOR_PROBE_HEIGHT_M = 1.0


def _check_calibrated(where: str, key: str, camera: Camera, store) -> None:
    """A calibrated camera stands where the real rig has it, over the floor or around it (Campus's stand on the
    edges of an open square), but above the ground, below the ceiling and seeing some of the floor: a camera
    that sees none of it is a wrong `calibration_origin_m` or a file in other units.

    Raises:
        ScenarioError: naming the scenario, the camera's key and where it stands.
    """
    c = camera.center_world
    at = f"camera {camera.name} at ({c[0]:.2f}, {c[1]:.2f}, {c[2]:.2f}) m"
    if not 0 < c[2] <= store.ceiling_m:
        raise ScenarioError(f"{where}: {key}: {at} must stand above the floor and at most at the ceiling "
                            f"(0 < z <= {store.ceiling_m} m); check cameras.calibration_origin_m")
    u, v = np.meshgrid(np.linspace(0.0, store.width_m, FLOOR_PROBES), np.linspace(0.0, store.depth_m, FLOOR_PROBES))
    probes = np.stack([u, v, np.full(u.shape, FLOOR_PROBE_HEIGHT_M)], axis=-1)
    if not in_image(camera, probes)[1].any():
        raise ScenarioError(f"{where}: {key}: {at} sees none of the floor [0, {store.width_m}] x "
                            f"[0, {store.depth_m}] m; check cameras.calibration_origin_m and the file's units")


def _grid(config: CameraRigConfig, store, K: np.ndarray, rng: np.random.Generator) -> list[Camera]:
    """A rows x cols ceiling grid, each camera tilted toward its part of the floor."""

    def axis(n: int, length: float) -> np.ndarray:
        if n == 1:
            return np.array([length / 2])
        return np.linspace(min(config.margin_m, length / 2), max(length - config.margin_m, length / 2), n)

    xs, ys = axis(config.cols, store.width_m), axis(config.rows, store.depth_m)
    z = max(store.ceiling_m - config.ceiling_gap_m, 0.0)
    centre = np.array([store.width_m / 2, store.depth_m / 2])
    cameras = []
    for r, y in enumerate(ys):
        for c, x in enumerate(xs):
            xy = np.array([x, y])
            if config.position_jitter_m > 0:
                xy = xy + rng.normal(0.0, config.position_jitter_m, 2)
                xy = np.clip(xy, 0.0, [store.width_m, store.depth_m])
            aim_xy = xy + config.aim_inward * (centre - xy)
            position = np.array([xy[0], xy[1], z])
            aim = np.array([aim_xy[0], aim_xy[1], min(config.aim_height_m, z - 0.5)])
            R = look_at(position, aim)
            cameras.append(
                Camera(f"cam{r * config.cols + c:02d}", K, config.dist, R, -R @ position, config.width_px,
                       config.height_px)
            )
    return cameras


def monotonic_radius(dist: np.ndarray) -> float:
    """Largest undistorted normalised radius up to which the radial distortion keeps growing.

    Beyond it a strong barrel lens folds far-away points back into the image, so projections there
    are not where a real lens would put them.
    """
    return _monotonic_radius(tuple(float(d) for d in dist))


@functools.lru_cache(maxsize=256)
def _monotonic_radius(dist: tuple[float, ...]) -> float:
    k1, k2, _, _, k3 = dist
    r = np.linspace(0.0, 10.0, 20001)
    r2 = r * r
    derivative = 1 + 3 * k1 * r2 + 5 * k2 * r2 * r2 + 7 * k3 * r2 * r2 * r2
    bad = np.nonzero(derivative <= 0)[0]
    return float(r[bad[0] - 1]) if bad.size else math.inf


def in_image(camera: Camera, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distorted pixels (OpenCV's camera model) and whether each point is in front of the camera, within the
    lens's monotonic radius (`monotonic_radius`) and inside its image.

    Args:
        camera: the camera.
        points_world: (..., 3) world points, metres.

    Returns:
        (..., 2) distorted pixels (NaN behind the camera) and (...,) bool visible-in-image mask.
    """
    points = np.asarray(points_world, dtype=np.float64)
    if points.shape[-1:] != (3,):
        raise ValueError(f"points_world: expected shape (..., 3), got {points.shape}")
    px, inside = in_image_many(camera.R_cam_from_world[None], camera.t_cam_from_world[None], camera.K[None],
                               camera.dist[None], np.array([[camera.width_px, camera.height_px]], dtype=float),
                               np.array([monotonic_radius(camera.dist)]), points.reshape(1, -1, 3),
                               np.zeros(1, dtype=np.int64))
    return px.reshape(points.shape[:-1] + (2,)), inside.reshape(points.shape[:-1])


def in_image_many(R: np.ndarray, t: np.ndarray, K: np.ndarray, dist: np.ndarray, size: np.ndarray,
                  max_radius: np.ndarray, points_world: np.ndarray, cameras: np.ndarray):
    """`in_image` of several point sets, each seen by its own camera of a rig, in one compiled pass.

    Args:
        R (C, 3, 3), t (C, 3), K (C, 3, 3), dist (C, 5): the rig's extrinsics, intrinsics and distortion.
        size (C, 2): width and height in pixels; max_radius (C,): `monotonic_radius` of each camera.
        points_world: (S, N, 3) world points, metres (NaN rows are never in the image).
        cameras: (S,) index of the camera of each point set.

    Returns:
        (S, N, 2) distorted pixels (NaN behind the camera) and (S, N) bool visible-in-image mask.
    """
    points = np.ascontiguousarray(points_world, dtype=np.float64)
    cameras = np.ascontiguousarray(cameras, dtype=np.int64)
    px = np.empty(points.shape[:2] + (2,))
    inside = np.empty(points.shape[:2], dtype=bool)
    # The tangential and skew terms are added only when some camera of the batch has them (adding exact
    # zeros could only turn a -0.0 into +0.0, but the results stay those of the vectorised formula).
    tangential = np.full(len(cameras), dist[cameras][:, 2:4].any())
    skew = np.full(len(cameras), K[cameras][:, 0, 1].any())
    in_image_many_kernel(np.ascontiguousarray(R, dtype=np.float64), np.ascontiguousarray(t, dtype=np.float64),
                     np.ascontiguousarray(K, dtype=np.float64), np.ascontiguousarray(dist, dtype=np.float64),
                     np.ascontiguousarray(size, dtype=np.float64), np.ascontiguousarray(max_radius, dtype=np.float64),
                     points, cameras, tangential, skew, px, inside)
    return px, inside


def _plain_fma(a, b, c):
    """a * b + c rounded once, in Python: exact rational arithmetic, then one rounding."""
    if not (math.isfinite(a) and math.isfinite(b) and math.isfinite(c)):
        return a * b + c
    return float(Fraction(a) * Fraction(b) + Fraction(c))


@intrinsic(plain=_plain_fma)
def _fma(typingctx, a, b, c):
    """a * b + c rounded once (LLVM's fma intrinsic), as the BLAS kernels behind numpy's matmul compute."""
    signature = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, sig, args):
        double = llvm_ir.DoubleType()
        fma = builder.module.declare_intrinsic("llvm.fma", [double], llvm_ir.FunctionType(double, [double] * 3))
        return builder.call(fma, args)

    return signature, codegen


@jit
def in_image_many_kernel(R, t, K, dist, size, max_radius, points, cameras, tangential, skew, px, inside):
    """The loops of `in_image_many` (its arguments, C-contiguous, then `tangential` and `skew` (S,): whether
    a camera of each set's batch has those terms, and the outputs px (S, N, 2) and inside (S, N)), for
    callers that keep the rig's arrays ready. Written out in the order of the vectorised numpy formula of
    `tests/reference/cameras.py`, so that every pixel is the same bit for bit (which keeps the recordings'
    bytes): numpy's matmul (OpenBLAS) rotates as fma(z, R2, fma(y, R1, x R0)), fused multiply-adds rounded
    once, and so does this loop."""
    for s in range(points.shape[0]):
        c = cameras[s]
        k1, k2, p1, p2, k3 = dist[c, 0], dist[c, 1], dist[c, 2], dist[c, 3], dist[c, 4]
        r2_max = max_radius[c] * max_radius[c]
        w, h = size[c, 0] - 0.5, size[c, 1] - 0.5
        for n in range(points.shape[1]):
            x, y, z = points[s, n, 0], points[s, n, 1], points[s, n, 2]
            cx = _fma(z, R[c, 0, 2], _fma(y, R[c, 0, 1], x * R[c, 0, 0])) + t[c, 0]
            cy = _fma(z, R[c, 1, 2], _fma(y, R[c, 1, 1], x * R[c, 1, 0])) + t[c, 1]
            cz = _fma(z, R[c, 2, 2], _fma(y, R[c, 2, 1], x * R[c, 2, 0])) + t[c, 2]
            in_front = cz > MIN_DEPTH_M
            inv_z = 1.0 / cz if in_front else np.nan
            xn, yn = cx * inv_z, cy * inv_z
            r2 = xn * xn + yn * yn
            radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
            xd, yd = xn * radial, yn * radial
            if tangential[s]:
                xd, yd = (xd + 2 * p1 * xn * yn + p2 * (r2 + 2 * xn * xn),
                          yd + p1 * (r2 + 2 * yn * yn) + 2 * p2 * xn * yn)
            u = K[c, 0, 0] * xd
            if skew[s]:
                u += K[c, 0, 1] * yd
            u += K[c, 0, 2]
            v = K[c, 1, 1] * yd + K[c, 1, 2]
            px[s, n, 0], px[s, n, 1] = u, v
            inside[s, n] = in_front and r2 <= r2_max and u >= -0.5 and u <= w and v >= -0.5 and v <= h


def mujoco_camera_pose(camera: Camera) -> tuple[np.ndarray, np.ndarray, float]:
    """The MuJoCo camera that sees what `camera` sees (without distortion).

    The one place that converts the OpenCV camera frame (x right, y down, z forward) to MuJoCo's
    (x right, y up, looking down -z): the MuJoCo axes are (x, -y, -z) of the OpenCV camera.

    Returns:
        pos (3,) camera centre in the world, quat (4,) world-from-camera rotation (w, x, y, z) for
        `<camera quat=...>` / `MjvCamera`-free rendering, and fovy_deg, the vertical field of view
        of the pinhole with focal length K[1, 1].
    """
    world_from_cv = camera.R_cam_from_world.T
    world_from_mj = world_from_cv @ np.diag([1.0, -1.0, -1.0])
    quat = _mat_to_quat(world_from_mj)
    fovy_deg = math.degrees(2 * math.atan(0.5 * camera.height_px / camera.K[1, 1]))
    return camera.center_world, quat, fovy_deg


def _mat_to_quat(R: np.ndarray) -> np.ndarray:
    """(4,) unit quaternion (w, x, y, z) of a (3, 3) rotation matrix, w >= 0."""
    m = R
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0:
        s = 2 * math.sqrt(1 + trace)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2 * math.sqrt(1 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2 * math.sqrt(1 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2 * math.sqrt(1 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return q if q[0] >= 0 else -q


# Panoptic's world has y pointing down; ours has z up: (x, y, z)_ours = (x, z, -y)_panoptic.
_Z_UP_FROM_PANOPTIC = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
_CM = 0.01


def spread_subset(cameras: list, count: int, where: str) -> list:
    """`count` of `cameras` spread evenly over their order (the first and the last among them); 0 keeps all.

    Raises:
        ScenarioError: `count` exceeds the cameras there are (`where` names the key).
    """
    if count == 0:
        return list(cameras)
    if count > len(cameras):
        raise ScenarioError(f"{where}: {count} is more than the {len(cameras)} cameras of the calibration")
    picked = np.unique(np.round(np.linspace(0, len(cameras) - 1, count)).astype(int))
    return [cameras[i] for i in picked]


def load_panoptic(path, kind: str = "hd", *, origin_m=(0.0, 0.0, 0.0), z_up: bool = True) -> list[Camera]:
    """Cameras of a CMU Panoptic calibration file (`x = K (R X + t)` then distortion, X in cm).

    Args:
        path: the calibration JSON.
        kind: camera type to keep ("hd": the 31 1920x1080 cameras, "vga", "kinect-color").
        origin_m: where Panoptic's origin lies in our world frame, metres.
        z_up: convert Panoptic's y-down world to ours (z up); False keeps Panoptic's axes (in metres).

    Raises:
        OSError: the file cannot be read.
        ValueError: the file is not JSON or not of this format (the message names the key), or holds no
            camera of that kind.
    """
    with open(path, encoding="utf-8") as f:
        calibration = json.load(f)
    entries = calibration.get("cameras") if isinstance(calibration, dict) else None
    if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
        raise ValueError("key 'cameras' must be an array of camera objects (the Panoptic format; a dataset "
                         "layout's calibration.json, whose 'cameras' is an object, takes calibration_format = "
                         "\"dataset\")")
    world_from_pan = _Z_UP_FROM_PANOPTIC if z_up else np.eye(3)
    origin = np.asarray(origin_m, dtype=np.float64)
    cameras = []
    for i, entry in enumerate(entries):
        if entry.get("type") != kind:
            continue
        try:
            R_pan = np.asarray(entry["R"], dtype=np.float64)
            t_m = np.asarray(entry["t"], dtype=np.float64).ravel() * _CM
            # X_pan = world_from_pan.T (X - origin)  =>  R_cam = R_pan world_from_pan.T, t = t - R_cam origin.
            R = R_pan @ world_from_pan.T
            R = _orthonormalise(R)
            width, height = entry["resolution"]
            cameras.append(Camera(f"{kind}_{entry['name']}", np.asarray(entry["K"], dtype=np.float64),
                                  np.asarray(entry["distCoef"], dtype=np.float64), R, t_m - R @ origin, int(width),
                                  int(height)))
        except KeyError as e:
            raise ValueError(f"cameras[{i}]: key {e} missing (expected name, type, resolution, K, distCoef, R, t)") \
                from None
        except (TypeError, ValueError) as e:
            raise ValueError(f"cameras[{i}]: {e}") from None
    if not cameras:
        kinds = sorted({str(e.get("type")) for e in entries})
        raise ValueError(f"no cameras of type {kind!r} (types in file: {kinds})")
    return cameras


def calibration_image_wh(value) -> tuple[int, int]:
    """(width, height) of an `image_wh` of the dataset layout: [width, height], integers in [1, MAX_IMAGE_PX].

    Raises:
        ValueError: naming the key and what is valid.
    """
    if not (isinstance(value, list) and len(value) == 2 and all(
            isinstance(v, int) and not isinstance(v, bool) and 0 < v <= MAX_CALIBRATION_IMAGE_PX for v in value)):
        raise ValueError(f"key 'image_wh' = {value!r} must be [width, height], integers in "
                         f"[1, {MAX_CALIBRATION_IMAGE_PX}]")
    return value[0], value[1]


_MAX_ABS_CM = 1e9  # the largest number a dataset layout camera pose may hold, centimetres (10,000 km)


def _dataset_entries(calibration) -> dict:
    """The `cameras` object (camera name -> {K, Tw, dist_coeffs}) of a dataset layout calibration.json."""
    if not isinstance(calibration, dict):
        raise ValueError(f"the file must be an object, got {type(calibration).__name__}")
    entries = calibration.get("cameras")
    if not isinstance(entries, dict):
        raise ValueError(f"key 'cameras' (camera name -> {{K, Tw}}) must be an object, got {type(entries).__name__}")
    return entries


def dataset_cameras(calibration, width_px: int, height_px: int, *, use_distortion: bool = True,
                    origin_m=(0.0, 0.0, 0.0)) -> list[Camera]:
    """The cameras of a calibration.json of the dataset layout of Chen et al. (Campus, Shelf, the Store
    datasets), sorted by name: per camera `K` normalised by the image size (row 0 divided by the width, row 1
    by the height), `Tw` the 4x4 camera-to-world pose in centimetres, and `dist_coeffs` (k1 k2 p1 p2 [k3]).
    Its world has z up, as ours.

    Args:
        calibration: the file's parsed JSON.
        width_px, height_px: the image size K was normalised by.
        use_distortion: keep the listed `dist_coeffs` (else none).
        origin_m: where the calibration's world origin lies in our world frame, metres.

    Raises:
        ValueError: the document is not of this shape; the message names the camera and the key.
    """
    entries = _dataset_entries(calibration)
    origin = np.asarray(origin_m, dtype=np.float64)
    cameras = []
    for name in sorted(entries):
        entry = entries[name]
        if not isinstance(entry, dict):
            raise ValueError(f"camera {name!r} must be an object, got {type(entry).__name__}")
        try:
            K = np.asarray(entry["K"], dtype=np.float64)
            Tw = np.asarray(entry["Tw"], dtype=np.float64)
            dist = np.asarray(entry.get("dist_coeffs", []), dtype=np.float64) if use_distortion else np.zeros(5)
        except KeyError as exc:
            raise ValueError(f"camera {name!r}: key {exc} missing or not numeric") from None
        except (TypeError, ValueError) as exc:
            raise ValueError(f"camera {name!r}: K, Tw and dist_coeffs must be arrays of numbers ({exc})") from None
        if K.shape != (3, 3) or Tw.shape != (4, 4):
            raise ValueError(f"camera {name!r}: K must be 3x3 and Tw 4x4, got {K.shape} and {Tw.shape}")
        K = K * np.array([[width_px], [height_px], [1.0]])
        if not (np.isfinite(K).all() and np.isfinite(Tw).all() and np.abs(Tw).max() <= _MAX_ABS_CM):
            raise ValueError(f"camera {name!r}: K and Tw must hold numbers (no null), Tw's within {_MAX_ABS_CM:g} cm")
        # Tw's rotation is orthonormal only to the precision the file was written with.
        try:
            R = _orthonormalise(Tw[:3, :3].T)
        except ValueError as exc:
            raise ValueError(f"camera {name!r}: Tw: {exc}") from None
        center_m = Tw[:3, 3] * _CM + origin
        try:
            cameras.append(Camera(name=str(name), K=K, dist=dist, R_cam_from_world=R, t_cam_from_world=-R @ center_m,
                                  width_px=width_px, height_px=height_px))
        except ValueError as exc:
            raise ValueError(f"camera {name!r}: {exc}") from None
    return cameras


def load_dataset_calibration(path, *, origin_m=(0.0, 0.0, 0.0)) -> list[Camera]:
    """The cameras of a dataset layout calibration.json that holds its image size as `image_wh` (as this
    project's exports write it), with their listed distortion (`dataset_cameras`).

    Raises:
        OSError: the file cannot be read.
        ValueError: the file is not JSON or not of this shape; the message names the key.
    """
    with open(path, encoding="utf-8") as f:
        calibration = json.load(f)
    _dataset_entries(calibration)
    if "image_wh" not in calibration:
        raise ValueError("key 'image_wh' missing: K is normalised by the image size, so the file must give it "
                         "as \"image_wh\": [width, height] (the published files keep it in detection.json)")
    width, height = calibration_image_wh(calibration["image_wh"])
    return dataset_cameras(calibration, width, height, use_distortion=True, origin_m=origin_m)


ROTATION_TOLERANCE = 1e-3
"""How far from a rotation (largest element of R^T R - I) a calibration's rotation may be; files store them to
about 1e-9, so anything further is not a rotation (an all-zero pose, a scaled or mirrored matrix)."""


def _orthonormalise(R: np.ndarray) -> np.ndarray:
    """Nearest rotation matrix (calibration files store rotations to about 1e-9).

    Raises:
        ValueError: `R` is not a rotation to `ROTATION_TOLERANCE` (orthonormal, determinant +1).
    """
    error = np.abs(R.T @ R - np.eye(3)).max()
    if not (error <= ROTATION_TOLERANCE and np.linalg.det(R) > 0):
        raise ValueError(f"the rotation {np.round(R, 6).tolist()} is not a rotation matrix (R^T R differs from "
                         f"the identity by {error:.3g}, det {np.linalg.det(R):.3g}; expected orthonormal, det +1)")
    u, _, vt = np.linalg.svd(R)
    return u @ vt
