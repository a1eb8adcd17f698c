"""Camera rigs: placement, intrinsics from resolution and field of view, lens distortion, calibration files.

Owns the camera side of the sensor model: building the rig a scenario asks for (a ceiling grid,
explicit placements or a real calibration file: the CMU Panoptic dome's, or the dataset layout's
calibration.json of Campus, Shelf and the Store datasets, parsed by `core.calibration` as
`crossview.formats.datasets` reads it), and the one conversion from the OpenCV camera frame (x right, y down,
z forward) to MuJoCo's (looks down -z, y up). Projecting world points to distorted pixels is
`core.projection`'s, which the formats and scoring share.
"""

from __future__ import annotations

import enum
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from core.calibration import M_PER_CM, calibration_image_wh, dataset_cameras, dataset_entries, orthonormalise
from core.errors import CrossviewError, ScenarioError
from core.projection import in_image
from core.types import Camera
from sim.config import bounded, check_ranges
from sim.store import MAX_FLOOR_M

MAX_GRID = 100  # cameras along one side of a grid
MAX_IMAGE_PX = 16384
# When a camera looks (almost) straight down, "up" in its image points along world +y.
_STRAIGHT_DOWN_COS = 0.999


def camera_grid(count: int, width_m: float, depth_m: float) -> tuple[int, int]:
    """Rows and columns of a grid of exactly `count` cameras whose shape best fits the floor, of those with at
    most `MAX_GRID` rows and columns (`crossview generate --cameras N` on a scenario without a calibration).

    Args:
        count: number of cameras, >= 1.
        width_m, depth_m: floor extents along x (columns) and y (rows).
    """
    if count < 1:
        raise CrossviewError(f"--cameras: {count} must be >= 1")
    if count > MAX_GRID * MAX_GRID:  # (before the divisor search, which would take as long as the count is large)
        raise CrossviewError(f"--cameras: {count} is more than the {MAX_GRID * MAX_GRID} cameras a grid may hold "
                             f"(cameras.rows and cameras.cols at most {MAX_GRID} each)")
    aspect = width_m / depth_m
    shapes = [r for r in range(1, count + 1) if count % r == 0 and max(r, count // r) <= MAX_GRID]
    if not shapes:  # (else the scenario's check would blame the file for a shape the option made)
        raise CrossviewError(f"--cameras: {count} cameras make no grid of at most {MAX_GRID} rows and {MAX_GRID} "
                             "columns; give a count that does (a product of two numbers up to "
                             f"{MAX_GRID})")
    rows = min(shapes, key=lambda r: abs(math.log((count // r) / r / aspect)))
    return rows, count // rows


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
            t_m = np.asarray(entry["t"], dtype=np.float64).ravel() * M_PER_CM
            # X_pan = world_from_pan.T (X - origin)  =>  R_cam = R_pan world_from_pan.T, t = t - R_cam origin.
            R = R_pan @ world_from_pan.T
            R = orthonormalise(R)
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


def load_dataset_calibration(path, *, origin_m=(0.0, 0.0, 0.0)) -> list[Camera]:
    """The cameras of a dataset layout calibration.json that holds its image size as `image_wh` (as this
    project's exports write it), with their listed distortion (`dataset_cameras`).

    Raises:
        OSError: the file cannot be read.
        ValueError: the file is not JSON or not of this shape; the message names the key.
    """
    with open(path, encoding="utf-8") as f:
        calibration = json.load(f)
    dataset_entries(calibration)
    if "image_wh" not in calibration:
        raise ValueError("key 'image_wh' missing: K is normalised by the image size, so the file must give it "
                         "as \"image_wh\": [width, height] (the published files keep it in detection.json)")
    width, height = calibration_image_wh(calibration["image_wh"])
    return dataset_cameras(calibration, width, height, use_distortion=True, origin_m=origin_m)
