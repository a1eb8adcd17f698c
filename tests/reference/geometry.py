"""The distance of a point to a ray (d_l of eq. (4)) written out plainly, for the tests of the rays of eq. (3)."""

from __future__ import annotations

import numpy as np


def point_to_ray_distance(X: np.ndarray, origin: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """d_l of eq. (4): distance from points X (..., 3) to lines through `origin` (3,) with unit `direction` (..., 3)."""
    return np.linalg.norm(np.cross(X - origin, direction), axis=-1)

