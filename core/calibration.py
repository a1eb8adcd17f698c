"""The dataset layout's calibration.json (Chen et al.: Campus, Shelf, the Store datasets) as cameras: one
parser, which the dataset reader and a scenario's calibrated rig (`sim.cameras`) both use.
"""

from __future__ import annotations

import numpy as np

from core.types import MAX_IMAGE_PX as MAX_CALIBRATION_IMAGE_PX
from core.types import Camera

M_PER_CM = 0.01
"""Metres in a centimetre: the calibration files (the dataset layout's, CMU Panoptic's) give positions in cm."""

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


MAX_ABS_CM = 1e9  # the largest number a dataset layout camera pose may hold, centimetres (10,000 km)


MAX_CAMERAS = 10_000
"""Most cameras of one calibration: a scenario's largest grid (100 x 100, `sim.cameras.camera_grid`); a
recording numbers its channels in 16 bits, a few per camera."""


def dataset_entries(calibration) -> dict:
    """The `cameras` object (camera name -> {K, Tw, dist_coeffs}) of a dataset layout calibration.json."""
    if not isinstance(calibration, dict):
        raise ValueError(f"the file must be an object, got {type(calibration).__name__}")
    entries = calibration.get("cameras")
    if not isinstance(entries, dict):
        raise ValueError(f"key 'cameras' (camera name -> {{K, Tw}}) must be an object, got {type(entries).__name__}")
    if len(entries) > MAX_CAMERAS:
        raise ValueError(f"key 'cameras' holds {len(entries):,} cameras, more than the {MAX_CAMERAS:,} one recording "
                         "may hold")
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
    entries = dataset_entries(calibration)
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
        with np.errstate(over="ignore"):  # (an overflowing K is refused just below, by name)
            K = K * np.array([[width_px], [height_px], [1.0]])
        if not (np.isfinite(K).all() and np.isfinite(Tw).all() and np.abs(Tw).max() <= MAX_ABS_CM):
            raise ValueError(f"camera {name!r}: K and Tw must hold numbers (no null), Tw's within {MAX_ABS_CM:g} cm")
        # Tw's rotation is orthonormal only to the precision the file was written with.
        try:
            R = orthonormalise(Tw[:3, :3].T)
        except ValueError as exc:
            raise ValueError(f"camera {name!r}: Tw: {exc}") from None
        center_m = Tw[:3, 3] * M_PER_CM + origin
        try:
            cameras.append(Camera(name=str(name), K=K, dist=dist, R_cam_from_world=R, t_cam_from_world=-R @ center_m,
                                  width_px=width_px, height_px=height_px))
        except ValueError as exc:
            raise ValueError(f"camera {name!r}: {exc}") from None
    return cameras


ROTATION_TOLERANCE = 1e-3
"""How far from a rotation (largest element of R^T R - I) a calibration's rotation may be; files store them to
about 1e-9, so anything further is not a rotation (an all-zero pose, a scaled or mirrored matrix)."""


def orthonormalise(R: np.ndarray) -> np.ndarray:
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
