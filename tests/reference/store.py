"""Plain numpy versions of the store's rules: points pushed out of the obstacle footprints (the rule
`sim.crowd`'s compiled hard constraint applies, the footprint grown by a clearance, checked against the plain
rectangle distance), each point's distance to the nearest footprint, and the navigation grid computed over every
cell."""

from __future__ import annotations

import numpy as np

from sim.store import StoreGeometry, rect_distance


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


def obstacle_distance(store: StoreGeometry, points: np.ndarray) -> np.ndarray:
    """(n,) distance from each point (n, 2) to the nearest shelf or counter footprint (inf without any)."""
    distance = np.full(len(points), np.inf)
    for ob in store.obstacles:
        distance = np.minimum(distance, rect_distance(points, ob.center, ob.half, ob.yaw))
    return distance


def free_grid(store: StoreGeometry, obstacles) -> np.ndarray:
    """(nx, ny) the navigation grid of `store`'s floor and doors with these obstacles, plainly: every cell's
    distance to every footprint (no windows), the wall clearance, the door corridors (`StoreGeometry.free`'s rule)."""
    from sim.store import INSIDE_DOOR_M

    P, W, D = store.cell_centers, store.config.width_m, store.config.depth_m
    c = store.wall_clearance_m
    free = (P[..., 0] >= c) & (P[..., 0] <= W - c) & (P[..., 1] >= c) & (P[..., 1] <= D - c)
    distance = np.full(P.shape[:2], np.inf)
    for ob in obstacles:
        distance = np.minimum(distance, rect_distance(P, ob.center, ob.half, ob.yaw))
    clear = distance >= store.nav_clearance_m
    free &= clear
    for door in (store.entrance, store.exit):
        rel = P - door.center
        along = np.abs(rel @ np.array([-door.inward[1], door.inward[0]]))
        depth = rel @ door.inward
        free |= (along <= door.width / 2 - 0.2) & (depth >= 0) & (depth <= INSIDE_DOOR_M + 0.1) & clear
    return free
