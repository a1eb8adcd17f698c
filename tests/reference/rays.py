"""Occlusion of keypoints by one `mujoco.mj_multiRay` batch: the plain reference the detector's compiled ray
caster (`sim.sensing.rays.cast_keypoint_rays`) is tested against."""

from __future__ import annotations

import mujoco
import numpy as np


def cast_visibility(model, data, origin: np.ndarray, points: np.ndarray, point_person: np.ndarray,
                    point_bodies: np.ndarray, geom_person: np.ndarray, geom_body: np.ndarray,
                    self_hit_margin_m: float):
    """Occlusion of keypoints seen from one point, one `mj_multiRay` batch.

    Args:
        model, data: the MuJoCo model and data holding the bodies at the capture time.
        origin: (3,) camera centre, metres.
        points: (N, 3) keypoints, metres.
        point_person: (N,) person id of each keypoint.
        point_bodies: (N, 2) the body each keypoint hangs on and its parent body (a joint keypoint sits
            inside both segments' geoms), in the numbering of `geom_body`.
        geom_person: (ngeom,) person id of each geom, -1 for the store.
        geom_body: (ngeom,) body of each geom within its person.
        self_hit_margin_m: hits on the keypoint's own segments this close to the keypoint count as reaching it.

    Returns:
        (N,) bool occluded (first hit: store or another person) and (N,) bool self-occluded (first
        hit: another limb of the same person, or its own segments far from the keypoint).
    """
    n = points.shape[0]
    if n == 0:
        return np.zeros(0, dtype=bool), np.zeros(0, dtype=bool)
    vec = points - origin
    length = np.sqrt(np.einsum("ij,ij->i", vec, vec))
    unit = vec / length[:, None]
    geomid = np.empty(n, dtype=np.int32)
    dist = np.empty(n)
    mujoco.mj_multiRay(model, data, np.asarray(origin, dtype=np.float64), unit.ravel(), None, 1, -1,
                       geomid, dist, None, n, float(length.max()))
    return classify_hits(geomid, dist, length, point_person, point_bodies, geom_person, geom_body, self_hit_margin_m)


def classify_hits(geomid: np.ndarray, dist: np.ndarray, length: np.ndarray, point_person: np.ndarray,
                  point_bodies: np.ndarray, geom_person: np.ndarray, geom_body: np.ndarray,
                  self_hit_margin_m: float):
    """Occluded and self-occluded flags from the first hits of rays cast at keypoints.

    Args:
        geomid, dist: (N,) first geom hit by each ray (-1: none) and its distance.
        length: (N,) distance from the ray origin to the keypoint.
        point_person, point_bodies, geom_person, geom_body, self_hit_margin_m: as in `cast_visibility`.

    Returns:
        (N,) bool occluded and (N,) bool self-occluded, as `cast_visibility`.
    """
    hit = (geomid >= 0) & (dist >= 0) & (dist < length)
    g = np.maximum(geomid, 0)
    same_person = hit & (geom_person[g] == point_person)
    hit_body = geom_body[g][:, None]
    own_near = same_person & (hit_body == point_bodies).any(axis=1) & (length - dist <= self_hit_margin_m)
    return hit & ~same_person, same_person & ~own_near
