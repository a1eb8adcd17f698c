"""Occlusion of keypoints by ray casting: which joints a camera sees, which a shelf, another person or the
person's own body hides."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from core.jit import jit

# -- ray casting ---------------------------------------------------------------------------------------
# Keypoint rays are cast by compiled loops that evaluate MuJoCo's own ray-primitive formulas (the
# quadratic of `mj_ray` for spheres, capsules, ellipsoids and cylinders, the slab faces for boxes) term
# by term in the same order, so every hit distance is the one `mujoco.mj_multiRay` returns, and the
# nearest hit is chosen as MuJoCo chooses it (geoms in model order, a later geom only when strictly
# nearer). What differs is the culling, which never drops a geom that has a hit nearer than the keypoint
# (the only hits the flags depend on), so the nearest hit and its ties come out the same. Per instant the
# geoms are binned by the floor cells (`_GRID_CELL_M`) their boxes overlap, each cell keeping its highest
# box top; a ray walks the cells its segment crosses from the camera on, skips a cell whose top is below
# the segment there, and stops at the first cell boundary past its nearest hit (a hit lies in the cell of
# its point, and its geom's box overlaps that cell). In a cell, a geom is skipped when the segment from the
# camera to the keypoint (to the nearest hit so far) misses its bounding sphere, a box geom also when the
# box around the segment misses its box; ties go to the geom first in model order. tests/sim checks the
# flags and the hits against `mj_multiRay` in the store. This replaced one `mj_multiRay` call per capture,
# whose per-call set-up (the bounding angles of every geom) cost more than its rays, and then per-person
# candidate lists, whose boxes (camera to person) held most of a crowded store.

_MJ_MINVAL = 1e-15  # mjMINVAL: MuJoCo's smallest denominator
_GEOM_SPHERE, _GEOM_CAPSULE, _GEOM_ELLIPSOID, _GEOM_CYLINDER, _GEOM_BOX = 2, 3, 4, 5, 6  # mjtGeom
RAY_GEOM_TYPES = (_GEOM_SPHERE, _GEOM_CAPSULE, _GEOM_ELLIPSOID, _GEOM_CYLINDER, _GEOM_BOX)
# Slack on the bounding spheres of the culling, far above the rounding of the hit distances.
_CULL_SLACK_M = 1e-6
# The floor grid of the ray casting: cell side, most cells along a side, and the slack of its bounds (far
# above the rounding of the cell walk, far below anything a cell's contents depend on).
_GRID_CELL_M = 0.5
_GRID_MAX_CELLS = 256
_GRID_SLACK_M = 1e-6


@jit
def _quadratic_roots(a, b, c):
    """Roots of a x² + 2 b x + c = 0 (both -1 when the discriminant is below mjMINVAL) and the smallest
    non-negative one (-1 when none), as MuJoCo's ray code solves it."""
    det = b * b - a * c
    if det < _MJ_MINVAL:
        return -1.0, -1.0, -1.0
    det = math.sqrt(det)
    x0 = (-b - det) / a
    x1 = (-b + det) / a
    if x0 >= 0:
        return x0, x1, x0
    if x1 >= 0:
        return x0, x1, x1
    return x0, x1, -1.0


@jit
def _ray_sphere(cx, cy, cz, radius_sq, px, py, pz, vx, vy, vz):
    dx, dy, dz = px - cx, py - cy, pz - cz
    a = vx * vx + vy * vy + vz * vz
    b = vx * dx + vy * dy + vz * dz
    c = dx * dx + dy * dy + dz * dz - radius_sq
    return _quadratic_roots(a, b, c)[2]


@jit
def _ray_geom(g, kinds, xpos, xmat, sizes, px, py, pz, vx, vy, vz):
    """Distance along the ray (p, v) to geom g of type kinds[g] at xpos[g] (3,) with rotation xmat[g] (9,) and
    size sizes[g] (3,); -1: no hit. (Scalars read once: faster than passing row views.)"""
    kind = kinds[g]
    p0, p1, p2 = xpos[g, 0], xpos[g, 1], xpos[g, 2]
    m0, m1, m2, m3, m4, m5, m6, m7, m8 = (xmat[g, 0], xmat[g, 1], xmat[g, 2], xmat[g, 3], xmat[g, 4], xmat[g, 5],
                                          xmat[g, 6], xmat[g, 7], xmat[g, 8])
    s0, s1, s2 = sizes[g, 0], sizes[g, 1], sizes[g, 2]
    if kind == _GEOM_SPHERE:
        return _ray_sphere(p0, p1, p2, s0 * s0, px, py, pz, vx, vy, vz)
    if kind == _GEOM_CAPSULE:
        outer = s0 + s1
        if _ray_sphere(p0, p1, p2, outer * outer, px, py, pz, vx, vy, vz) < 0:
            return -1.0
    elif kind == _GEOM_CYLINDER:
        if _ray_sphere(p0, p1, p2, s0 * s0 + s1 * s1, px, py, pz, vx, vy, vz) < 0:
            return -1.0
    elif kind == _GEOM_BOX:
        if _ray_sphere(p0, p1, p2, s0 * s0 + s1 * s1 + s2 * s2, px, py, pz, vx, vy, vz) < 0:
            return -1.0
    # The ray in the geom's frame: mat' (p - pos) and mat' v.
    dx, dy, dz = px - p0, py - p1, pz - p2
    l0 = m0 * dx + m3 * dy + m6 * dz
    l1 = m1 * dx + m4 * dy + m7 * dz
    l2 = m2 * dx + m5 * dy + m8 * dz
    w0 = m0 * vx + m3 * vy + m6 * vz
    w1 = m1 * vx + m4 * vy + m7 * vz
    w2 = m2 * vx + m5 * vy + m8 * vz
    if kind == _GEOM_ELLIPSOID:
        i0, i1, i2 = 1 / (s0 * s0), 1 / (s1 * s1), 1 / (s2 * s2)
        a = i0 * w0 * w0 + i1 * w1 * w1 + i2 * w2 * w2
        b = i0 * w0 * l0 + i1 * w1 * l1 + i2 * w2 * l2
        c = i0 * l0 * l0 + i1 * l1 * l1 + i2 * l2 * l2 - 1
        return _quadratic_roots(a, b, c)[2]
    x = -1.0
    if kind == _GEOM_BOX:
        for i in range(3):
            li, wi, si = (l0, w0, s0) if i == 0 else ((l1, w1, s1) if i == 1 else (l2, w2, s2))
            if abs(wi) <= _MJ_MINVAL:
                continue
            # The two other axes of face i.
            la, wa, sa = (l1, w1, s1) if i == 0 else (l0, w0, s0)
            lb, wb, sb = (l1, w1, s1) if i == 2 else (l2, w2, s2)
            for side in (-1.0, 1.0):
                sol = (side * si - li) / wi
                if sol >= 0 and abs(la + sol * wa) <= sa and abs(lb + sol * wb) <= sb and (x < 0 or sol < x):
                    x = sol
        return x
    # Capsule and cylinder: the round side first.
    a = w0 * w0 + w1 * w1
    b = w0 * l0 + w1 * l1
    c = l0 * l0 + l1 * l1 - s0 * s0
    if kind == _GEOM_CYLINDER:
        if abs(w2) > _MJ_MINVAL:  # flat ends
            for side in (-1.0, 1.0):
                sol = (side * s1 - l2) / w2
                if sol >= 0:
                    e0, e1 = l0 + sol * w0, l1 + sol * w1
                    if e0 * e0 + e1 * e1 <= s0 * s0 and (x < 0 or sol < x):
                        x = sol
        sol = _quadratic_roots(a, b, c)[2]
        if sol >= 0 and abs(l2 + sol * w2) <= s1 and (x < 0 or sol < x):
            x = sol
        return x
    sol = _quadratic_roots(a, b, c)[2]
    if sol >= 0 and abs(l2 + sol * w2) <= s1:
        x = sol
    # The two hemispherical caps, each only on its own side of the round part.
    a = w0 * w0 + w1 * w1 + w2 * w2
    for side in (1.0, -1.0):
        e2 = l2 - s1 if side > 0 else l2 + s1
        b = w0 * l0 + w1 * l1 + w2 * e2
        c = l0 * l0 + l1 * l1 + e2 * e2 - s0 * s0
        r0, r1, _ = _quadratic_roots(a, b, c)
        for r in (r0, r1):
            if r >= 0 and (l2 + r * w2 >= s1 if side > 0 else l2 + r * w2 <= -s1) and (x < 0 or r < x):
                x = r
    return x


@jit
def _scene_bounds(geom_type, groups, geom_xpos, geom_xmat, geom_size, geom_rbound, bounds):
    """Boxes (lo, hi) around every geom (a box's own corners, the bounding sphere of the others), then
    around every group, into bounds (G + K, 6): a ray whose segment misses them cannot hit them before
    its keypoint."""
    K, G = groups.shape[0] - 1, geom_type.shape[0]
    for g in range(G):
        for i in range(3):
            half = geom_rbound[g]
            if geom_type[g] == _GEOM_BOX:
                half = (abs(geom_xmat[g, 3 * i]) * geom_size[g, 0] + abs(geom_xmat[g, 3 * i + 1]) * geom_size[g, 1]
                        + abs(geom_xmat[g, 3 * i + 2]) * geom_size[g, 2])
            bounds[g, i] = geom_xpos[g, i] - half - _CULL_SLACK_M
            bounds[g, 3 + i] = geom_xpos[g, i] + half + _CULL_SLACK_M
    for k in range(K):
        for i in range(3):
            bounds[G + k, i], bounds[G + k, 3 + i] = np.inf, -np.inf
        for g in range(groups[k], groups[k + 1]):
            for i in range(3):
                bounds[G + k, i] = min(bounds[G + k, i], bounds[g, i])
                bounds[G + k, 3 + i] = max(bounds[G + k, 3 + i], bounds[g, 3 + i])


@jit
def _grid_extent(origins, points, mask):
    """The floor rectangle (x0, y0, x1, y1) holding every segment from a capture's camera centre to a keypoint
    it casts (origins (R, 3), points (R, N, 3), mask (R, N)), and the lowest height any of them reaches:
    geoms outside it cannot meet a ray of the block."""
    x0 = y0 = z0 = np.inf
    x1 = y1 = -np.inf
    for r in range(points.shape[0]):
        any_cast = False
        for n in range(points.shape[1]):
            if mask[r, n]:
                any_cast = True
                x0, x1 = min(x0, points[r, n, 0]), max(x1, points[r, n, 0])
                y0, y1 = min(y0, points[r, n, 1]), max(y1, points[r, n, 1])
                z0 = min(z0, points[r, n, 2])
        if any_cast:
            x0, x1 = min(x0, origins[r, 0]), max(x1, origins[r, 0])
            y0, y1 = min(y0, origins[r, 1]), max(y1, origins[r, 1])
            z0 = min(z0, origins[r, 2])
    return x0 - _GRID_SLACK_M, y0 - _GRID_SLACK_M, x1 + _GRID_SLACK_M, y1 + _GRID_SLACK_M, z0 - _GRID_SLACK_M


@jit
def _grid_cells(lo, hi, origin, cell, n):
    """First and last cell index (clamped to [0, n)) of the interval [lo, hi] on a grid axis."""
    a = int(math.floor((lo - origin) / cell))
    b = int(math.floor((hi - origin) / cell))
    return max(a, 0), min(b, n - 1)


@jit
def _build_grid(geom_box, x0, y0, z0, cell, nx, ny, starts, tops, entries, fill_entries):
    """Bins the geoms by the floor cells their boxes geom_box (G, 6) overlap (geoms wholly below z0 or
    outside the grid left out): cell c holds entries[starts[c]:starts[c + 1]], in geom order, and tops[c]
    is the highest box top in it (-inf when empty). Without fill_entries, only counts. Returns the total."""
    ncell = nx * ny
    starts[:] = 0
    tops[:] = -np.inf
    G = geom_box.shape[0]
    x1, y1 = x0 + nx * cell, y0 + ny * cell
    fill = starts[:ncell].copy()
    for stage in range(2 if fill_entries else 1):
        for g in range(G):
            if (geom_box[g, 5] < z0 or geom_box[g, 3] < x0 or geom_box[g, 0] > x1 or geom_box[g, 4] < y0
                    or geom_box[g, 1] > y1):
                continue
            ia, ib = _grid_cells(geom_box[g, 0], geom_box[g, 3], x0, cell, nx)
            ja, jb = _grid_cells(geom_box[g, 1], geom_box[g, 4], y0, cell, ny)
            for j in range(ja, jb + 1):
                for c in range(j * nx + ia, j * nx + ib + 1):
                    if stage == 0:  # count
                        starts[c + 1] += 1
                        tops[c] = max(tops[c], geom_box[g, 5])
                    else:  # fill
                        entries[fill[c]] = g
                        fill[c] += 1
        if stage == 0:
            for c in range(ncell):
                starts[c + 1] += starts[c]
            fill = starts[:ncell].copy()
    return starts[ncell]


class KeypointRays(NamedTuple):
    """The rays to cast: from each capture's camera centre to its keypoints (R captures, N keypoints each).

    Attributes:
        origins: (R, 3) the camera centre of each capture, m.
        points: (R, N, 3) keypoints, m.
        mask: (R, N) bool which to cast.
        person: (R, N // J) int64 person id of each row of J keypoints.
        scene_of: (R,) int64 the instant (of `Scenes`) of each capture.
        cams: (R,) int64 the camera of each capture (its row of the counts).
    """

    origins: np.ndarray
    points: np.ndarray
    mask: np.ndarray
    person: np.ndarray
    scene_of: np.ndarray
    cams: np.ndarray


class RayModel(NamedTuple):
    """What the ray caster needs of the world that does not change while it runs (G geoms, K groups).

    Attributes:
        kp_bodies: (J, 2) int64 body and parent body of each keypoint.
        geom_body: (G,) int64 each geom's body within its person.
        geom_type: (G,) int64 mjtGeom type of each geom.
        groups: (K + 1,) int64 starts of contiguous geom groups (a person's geoms, the store's).
    """

    kp_bodies: np.ndarray
    geom_body: np.ndarray
    geom_type: np.ndarray
    groups: np.ndarray


class Scenes(NamedTuple):
    """The geoms at T instants; their constant parts once per distinct set (U sets).

    Attributes:
        xpos: (T, G, 3) positions, m.
        xmat: (T, G, 9) rotations, rows of 9.
        size: (U, G, 3) sizes, m.
        rbound: (U, G) bounding radii, m.
        owner: (U, G) int64 the person owning each geom.
        const_of: (T,) int64 the set of each instant.
    """

    xpos: np.ndarray
    xmat: np.ndarray
    size: np.ndarray
    rbound: np.ndarray
    owner: np.ndarray
    const_of: np.ndarray


class RayHits(NamedTuple):
    """What the ray caster writes per keypoint (R, N).

    Attributes:
        occluded, self_occluded: (R, N) bool.
        geomid: (R, N) int32 the nearest geom hit before the keypoint (-1: none).
        dist: (R, N) its distance, m (-1: none).
    """

    occluded: np.ndarray
    self_occluded: np.ndarray
    geomid: np.ndarray
    dist: np.ndarray


@jit
def cast_keypoint_rays(rays, model, scenes, margin, hits, counts, bounds):
    """Occlusion flags of keypoints seen from camera centres (see the section comment).

    rays: the `KeypointRays`; model: the world's `RayModel`; scenes: the geoms at each instant (`Scenes`);
    margin: self_hit_margin_m.
    Writes the `RayHits` hits; adds each capture's keypoints cast, occluded and self-occluded to its camera's
    row of counts (C, 3). bounds: scratch, (T, G + K, 6) at least.
    """
    origins, points, mask, person, scene_of, cams = rays.origins, rays.points, rays.mask, rays.person, \
        rays.scene_of, rays.cams
    kp_bodies, geom_type, geom_body, groups = model.kp_bodies, model.geom_type, model.geom_body, model.groups
    J = kp_bodies.shape[0]
    scene_xpos, scene_xmat, scene_size, scene_rbound = scenes.xpos, scenes.xmat, scenes.size, scenes.rbound
    scene_person, const_of = scenes.owner, scenes.const_of
    occluded, self_occluded, geomid, dist = hits.occluded, hits.self_occluded, hits.geomid, hits.dist
    T, G = scene_xpos.shape[0], geom_type.shape[0]
    for s in range(T):
        u = const_of[s]
        _scene_bounds(geom_type, groups, scene_xpos[s], scene_xmat[s], scene_size[u], scene_rbound[u], bounds[s])
    # One floor grid per instant over the rectangle the block's rays cross.
    x0, y0, x1, y1, z0 = _grid_extent(origins, points, mask)
    if not x1 > x0:  # nothing to cast
        x0, y0, x1, y1 = 0.0, 0.0, 1.0, 1.0
    cell = max(_GRID_CELL_M, (x1 - x0) / _GRID_MAX_CELLS, (y1 - y0) / _GRID_MAX_CELLS)
    nx, ny = max(int(math.ceil((x1 - x0) / cell)), 1), max(int(math.ceil((y1 - y0) / cell)), 1)
    ncell = nx * ny
    starts = np.empty((T, ncell + 1), dtype=np.int64)
    tops = np.empty((T, ncell))
    offset = np.zeros(T + 1, dtype=np.int64)
    counting = np.empty(0, dtype=np.int64)
    for s in range(T):
        offset[s + 1] = offset[s] + _build_grid(bounds[s, :G], x0, y0, z0, cell, nx, ny, starts[s], tops[s], counting,
                                                  False)
    entries = np.empty(offset[T], dtype=np.int64)
    for s in range(T):
        _build_grid(bounds[s, :G], x0, y0, z0, cell, nx, ny, starts[s], tops[s],
                    entries[offset[s]:offset[s + 1]], True)
    seen = np.full(G, -1, dtype=np.int64)  # the last ray that tested each geom
    ray = 0
    for r in range(points.shape[0]):
        s = scene_of[r]
        u = const_of[s]
        geom_xpos, geom_xmat, geom_size, geom_rbound = scene_xpos[s], scene_xmat[s], scene_size[u], scene_rbound[u]
        geom_person, geom_box = scene_person[u], bounds[s, :G]
        cell_start, cell_top, cell_geoms = starts[s], tops[s], entries[offset[s]:offset[s + 1]]
        ox, oy, oz = origins[r, 0], origins[r, 1], origins[r, 2]
        cast_here = occluded_here = self_occluded_here = 0
        for n in range(points.shape[1]):
            occluded[r, n] = False
            self_occluded[r, n] = False
            geomid[r, n] = -1
            dist[r, n] = -1.0
            if not mask[r, n]:
                continue
            cast_here += 1
            ray += 1
            px, py, pz = points[r, n, 0], points[r, n, 1], points[r, n, 2]
            vx, vy, vz = px - ox, py - oy, pz - oz
            length = math.sqrt(vx * vx + vy * vy + vz * vz)
            ux, uy, uz = vx / length, vy / length, vz / length
            lo_x, lo_y, lo_z = min(ox, px), min(oy, py), min(oz, pz)
            hi_x, hi_y, hi_z = max(ox, px), max(oy, py), max(oz, pz)
            # The cells the segment crosses, from the camera on (a 2D grid walk); in each, the distances
            # t_in..t_out along the ray. Only hits nearer than `reach` matter: the keypoint, then the nearest
            # hit so far; ties go to the geom first in model order, as in MuJoCo.
            best, best_g, reach = -1.0, -1, length
            i, j = _grid_cells(ox, ox, x0, cell, nx)[0], _grid_cells(oy, oy, y0, cell, ny)[0]
            step_i, step_j = (1 if ux > 0 else -1), (1 if uy > 0 else -1)
            next_x = x0 + (i + (1 if ux > 0 else 0)) * cell
            next_y = y0 + (j + (1 if uy > 0 else 0)) * cell
            t_x = (next_x - ox) / ux if ux != 0 else np.inf
            t_y = (next_y - oy) / uy if uy != 0 else np.inf
            dt_x = cell / abs(ux) if ux != 0 else np.inf
            dt_y = cell / abs(uy) if uy != 0 else np.inf
            t_in = 0.0
            while True:
                t_out = min(t_x, t_y, length)
                # The segment's lowest point in this cell, against the highest geom top in it.
                if min(oz + t_in * uz, oz + t_out * uz) <= cell_top[j * nx + i] + _GRID_SLACK_M:
                    for e in range(cell_start[j * nx + i], cell_start[j * nx + i + 1]):
                        g = cell_geoms[e]
                        if seen[g] == ray:
                            continue
                        seen[g] = ray
                        # (For a geom bounded by its sphere, the box test adds nothing to the sphere test.)
                        if geom_type[g] == _GEOM_BOX and (
                                hi_x < geom_box[g, 0] or lo_x > geom_box[g, 3] or hi_y < geom_box[g, 1]
                                or lo_y > geom_box[g, 4] or hi_z < geom_box[g, 2] or lo_z > geom_box[g, 5]):
                            continue
                        dx, dy, dz = geom_xpos[g, 0] - ox, geom_xpos[g, 1] - oy, geom_xpos[g, 2] - oz
                        along = dx * ux + dy * uy + dz * uz
                        radius = geom_rbound[g] + _CULL_SLACK_M
                        if (along + radius < 0 or along - radius > reach
                                or dx * dx + dy * dy + dz * dz - along * along > radius * radius):
                            continue
                        x = _ray_geom(g, geom_type, geom_xpos, geom_xmat, geom_size, ox, oy, oz, ux, uy, uz)
                        if x >= 0 and (best < 0 or x < best or (x == best and g < best_g)):
                            best, best_g = x, g
                            reach = min(reach, best)
                # Every hit in a later cell is at least t_out away.
                if t_out >= length:
                    break
                if best >= 0 and best < t_out - _GRID_SLACK_M:
                    break
                if t_x < t_y:
                    i += step_i
                    t_in, t_x = t_x, t_x + dt_x
                else:
                    j += step_j
                    t_in, t_y = t_y, t_y + dt_y
                if i < 0 or i >= nx or j < 0 or j >= ny:
                    break
            if best_g < 0 or not best < length:
                continue
            geomid[r, n] = best_g
            dist[r, n] = best
            q = n // J
            if geom_person[best_g] != person[r, q]:
                occluded[r, n] = True
                occluded_here += 1
            else:
                body = geom_body[best_g]
                k = n - q * J
                near = (body == kp_bodies[k, 0] or body == kp_bodies[k, 1]) and length - best <= margin
                self_occluded[r, n] = not near
                self_occluded_here += not near
        c = cams[r]
        counts[c, 0] += cast_here
        counts[c, 1] += occluded_here
        counts[c, 2] += self_occluded_here



@jit
def count_views(cams, in_img, occluded, self_occluded, counts):
    """Adds each capture's joints in the image, occluded and self-occluded ((R, N) bool) to its camera's row
    of counts (C, 3); cams (R,) the camera of each capture."""
    for r in range(in_img.shape[0]):
        c = cams[r]
        for n in range(in_img.shape[1]):
            counts[c, 0] += in_img[r, n]
            counts[c, 1] += occluded[r, n]
            counts[c, 2] += self_occluded[r, n]

