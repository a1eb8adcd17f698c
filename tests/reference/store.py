"""Points pushed out of the store's obstacle footprints, as plain numpy: the rule `sim.crowd`'s compiled hard
constraint applies (the footprint grown by a clearance), checked here against the plain rectangle distance."""

from __future__ import annotations

import numpy as np

from sim.store import StoreGeometry


def push_out(store: StoreGeometry, points: np.ndarray, clearance_m: float) -> np.ndarray:
    """(n, 2) points moved the shortest way out of every footprint grown by `clearance_m`."""
    if not store.obstacles:
        return points
    center, half, c, s = store.obstacle_arrays()
    d = points[:, None, :] - center[None]  # (n, O, 2), then in every obstacle's own frame
    lx, ly = d[..., 0] * c + d[..., 1] * s, -d[..., 0] * s + d[..., 1] * c
    hx, hy = half[:, 0], half[:, 1]
    qx, qy = np.clip(lx, -hx, hx), np.clip(ly, -hy, hy)
    ox, oy = lx - qx, ly - qy
    dist = np.sqrt(ox * ox + oy * oy)
    hit = dist < clearance_m
    if not hit.any():
        return points
    # Outside the core rectangle: radially from its nearest point; inside: through the nearest face.
    scale = clearance_m / np.maximum(dist, 1e-12)
    nx, ny = qx + ox * scale, qy + oy * scale
    core = dist < 1e-12
    use_x = (hx - np.abs(lx)) < (hy - np.abs(ly))
    nx = np.where(core & use_x, np.where(lx >= 0, hx + clearance_m, -hx - clearance_m), np.where(core, lx, nx))
    ny = np.where(core & ~use_x, np.where(ly >= 0, hy + clearance_m, -hy - clearance_m), np.where(core, ly, ny))
    dx, dy = np.where(hit, nx - lx, 0.0), np.where(hit, ny - ly, 0.0)
    return points + np.stack([(dx * c - dy * s).sum(axis=1), (dx * s + dy * c).sum(axis=1)], axis=-1)
