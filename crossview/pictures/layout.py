"""Top-down pictures of store layouts: shelves, doors, cameras and people's trajectories, drawn with OpenCV."""

from __future__ import annotations

import colorsys
import math
from pathlib import Path

import cv2
import numpy as np

from core.records import Box, BoxKind
from core.types import Camera
from crossview.outputs import write_bytes

# BGR colours of the store's boxes.
_BOX_BGR = {
    BoxKind.FLOOR: (235, 235, 235),
    BoxKind.WALL: (70, 70, 70),
    BoxKind.SHELF: (60, 105, 160),
    BoxKind.CHECKOUT: (160, 110, 50),
    BoxKind.ENTRANCE: (90, 190, 90),
    BoxKind.EXIT: (80, 80, 210),
}
_MARGIN_PX = 30
# Opacity of one camera's field of view on the floor; overlapping fields add up.
_FOV_ALPHA = 0.06
_FOV_BGR = (200, 140, 60)
_LEGEND_PX = 40
# BGR colour of a floor cell seen by 0, 1, 2, 3 or more cameras (`draw_layout(seen_by=...)`): red where
# nobody can be tracked, amber where one view cannot triangulate, greens where two or more can.
_SEEN_BY_BGR = ((120, 120, 235), (110, 200, 250), (170, 225, 170), (100, 180, 90))


# BGR colour of a false positive detection (no true person behind it).
FALSE_POSITIVE_BGR = (150, 150, 150)


def person_bgr(person_id: int) -> tuple[int, int, int]:
    """A stable, distinct colour per person (golden-ratio hues)."""
    r, g, b = colorsys.hsv_to_rgb((person_id * 0.618034) % 1.0, 0.85, 0.8)
    return int(b * 255), int(g * 255), int(r * 255)


def draw_layout(
    boxes: tuple[Box, ...] | list[Box],
    cameras: list[Camera] | None = None,
    trajectories: dict[int, np.ndarray] | None = None,
    title: str = "",
    px_per_m: float = 40.0,
    *,
    fields_of_view: bool = False,
    tracked: dict[int, np.ndarray] | None = None,
    switches: list[tuple[float, int, int, float, float]] | None = None,
    seen_by: tuple[np.ndarray, np.ndarray, float] | None = None,
    zones: list[tuple[tuple, tuple, str]] | None = None,
) -> np.ndarray:
    """Draws a store seen from above (x to the right, y up).

    Args:
        boxes: the store's boxes (`World.boxes`); the floor box sets the extent.
        cameras: cameras to mark: a dot at the centre and a line to where the optical axis meets the floor.
        trajectories: person id -> (N, 2) pelvis positions over time, metres (solid lines in the person's colour).
        title: one line printed under the picture.
        px_per_m: scale.
        fields_of_view: shade where each camera's image meets the floor (darker where more cameras see).
        tracked: target id -> (N, 2) tracked body roots over time, metres (dotted, in the id's colour, labelled).
        switches: identity switches (time s, person id, new target id, x m, y m): a red ring, labelled.
        seen_by: (cells (N, 2) centres in metres, counts (N,), cell side in metres): paint each cell by how many
            cameras see it (0, 1, 2, 3 or more; `crossview.measure.coverage`), with a legend.
        zones: (cell, region, label) per zone (`tracker.zones`; boxes x0, y0, x1, y1 in metres): the cell outlined
            in the zone's colour and labelled, the region it tracks (the cell widened into its neighbours) thin.

    Returns:
        (H, W, 3) uint8 BGR image.
    """
    floor = next((b for b in boxes if b.kind == BoxKind.FLOOR), None)
    if floor is None:
        raise ValueError("boxes: no FLOOR box to size the picture")
    x0 = floor.center_m[0] - floor.size_m[0] / 2
    y0 = floor.center_m[1] - floor.size_m[1] / 2
    width = int(math.ceil(floor.size_m[0] * px_per_m)) + 2 * _MARGIN_PX
    height = int(math.ceil(floor.size_m[1] * px_per_m)) + 2 * _MARGIN_PX + _LEGEND_PX
    image = np.full((height, width, 3), 255, np.uint8)
    plot_h = height - _LEGEND_PX

    def px(points: np.ndarray) -> np.ndarray:
        p = np.atleast_2d(np.asarray(points, float))
        u = _MARGIN_PX + (p[:, 0] - x0) * px_per_m
        v = plot_h - _MARGIN_PX - (p[:, 1] - y0) * px_per_m
        return np.round(np.stack([u, v], axis=-1)).astype(np.int32)

    def footprint(box: Box) -> np.ndarray:
        c, s = math.cos(box.yaw_rad), math.sin(box.yaw_rad)
        hx, hy = box.size_m[0] / 2, box.size_m[1] / 2
        local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
        return np.array(box.center_m[:2]) + local @ np.array([[c, s], [-s, c]])

    # The floor and the door mats, then the fields of view on them, then what stands on the floor.
    for kind in (BoxKind.FLOOR, BoxKind.ENTRANCE, BoxKind.EXIT, None, BoxKind.WALL, BoxKind.SHELF, BoxKind.CHECKOUT):
        if kind is None and fields_of_view:
            image = _tint_fields_of_view(image, cameras or [], px, footprint(floor))
        if kind is None and seen_by is not None:
            _paint_seen_by(image, px, *seen_by)
        for box in boxes:
            if box.kind == kind:
                cv2.fillPoly(image, [px(footprint(box))], _BOX_BGR[kind], lineType=cv2.LINE_AA)
    for pid, xy in sorted((trajectories or {}).items()):
        xy = np.asarray(xy, float)
        if len(xy) < 2:
            continue
        colour = person_bgr(pid)
        cv2.polylines(image, [px(xy)], False, colour, 1, lineType=cv2.LINE_8)  # aliased: PNGs stay small
        cv2.circle(image, tuple(int(v) for v in px(xy[-1])[0]), 3, colour, -1, lineType=cv2.LINE_AA)
    for tid, xy in sorted((tracked or {}).items()):
        xy = np.asarray(xy, float)
        xy = xy[np.all(np.isfinite(xy), axis=1)]
        if len(xy) < 2:
            continue
        colour = track_bgr(tid)
        for p in px(xy)[::2]:
            cv2.circle(image, (int(p[0]), int(p[1])), 1, colour, -1)
        end = px(xy[-1])[0]
        cv2.putText(image, f"#{tid}", (int(end[0]) + 4, int(end[1]) - 4), cv2.FONT_HERSHEY_SIMPLEX, 0.35, colour, 1,
                    lineType=cv2.LINE_AA)
    for t_s, pid, tid, x, y in switches or []:
        centre = tuple(int(v) for v in px(np.array([x, y]))[0])
        cv2.circle(image, centre, 9, (0, 0, 220), 2, lineType=cv2.LINE_AA)
        cv2.putText(image, f"P{pid}->#{tid} {t_s:.1f}s", (centre[0] + 11, centre[1] + 4), cv2.FONT_HERSHEY_SIMPLEX,
                    0.35, (0, 0, 220), 1, lineType=cv2.LINE_AA)
    for index, (cell, region, label) in enumerate(zones or []):
        colour = track_bgr(index)
        r = px(np.array([region[:2], region[2:]]))
        cv2.rectangle(image, tuple(int(v) for v in r[0]), tuple(int(v) for v in r[1]), colour, 1)
        c = px(np.array([cell[:2], cell[2:]]))
        cv2.rectangle(image, tuple(int(v) for v in c[0]), tuple(int(v) for v in c[1]), colour, 3)
        cv2.putText(image, label, (int(c[0][0]) + 6, int(c[1][1]) + 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, colour, 1,
                    lineType=cv2.LINE_AA)
    for cam in cameras or []:
        centre = cam.center_world
        axis = cam.R_cam_from_world[2]  # optical axis in the world frame
        if axis[2] < -1e-6:
            ground = centre + axis * (-centre[2] / axis[2])
            cv2.line(image, tuple(int(v) for v in px(centre)[0]), tuple(int(v) for v in px(ground)[0]),
                     (40, 40, 40), 1, lineType=cv2.LINE_AA)
        cv2.circle(image, tuple(int(v) for v in px(centre)[0]), 4, (0, 0, 0), -1, lineType=cv2.LINE_AA)
    if title:
        # One line if it fits, else split at the first ": ".
        lines = [title]
        if cv2.getTextSize(title, cv2.FONT_HERSHEY_SIMPLEX, 0.45, 1)[0][0] > width - _MARGIN_PX and ": " in title:
            head, tail = title.split(": ", 1)
            lines = [head + ":", tail]
        for n, line in enumerate(lines[-2:]):
            cv2.putText(image, line, (8, height - 26 + 16 * n + (8 if len(lines) == 1 else 0)),
                        cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1, lineType=cv2.LINE_AA)
    # Scale bar: 1 m.
    bar = px(np.array([[x0, y0], [x0 + 1.0, y0]]))
    bar[:, 1] += _MARGIN_PX // 2
    cv2.line(image, tuple(int(v) for v in bar[0]), tuple(int(v) for v in bar[1]), (0, 0, 0), 2)
    cv2.putText(image, "1 m", (int(bar[1, 0]) + 4, int(bar[1, 1]) + 4), cv2.FONT_HERSHEY_SIMPLEX, 0.35,
                (0, 0, 0), 1, lineType=cv2.LINE_AA)
    if seen_by is not None:
        for n, colour in enumerate(_SEEN_BY_BGR):  # the legend, right of the scale bar
            u = int(bar[1, 0]) + 40 + 52 * n
            cv2.rectangle(image, (u, int(bar[1, 1]) - 6), (u + 10, int(bar[1, 1]) + 4), colour, -1)
            cv2.putText(image, f"{n}{'+' if n == len(_SEEN_BY_BGR) - 1 else ''}", (u + 14, int(bar[1, 1]) + 4),
                        cv2.FONT_HERSHEY_SIMPLEX, 0.35, (0, 0, 0), 1, lineType=cv2.LINE_AA)
    return image


def _paint_seen_by(image: np.ndarray, px, cells_xy: np.ndarray, counts: np.ndarray, cell_m: float) -> None:
    """Fills each cell's square with the colour of its camera count (`_SEEN_BY_BGR`), in place."""
    half = cell_m / 2
    for xy, count in zip(np.asarray(cells_xy, float), np.asarray(counts)):
        corners = px(np.array([xy - half, xy + half]))
        colour = _SEEN_BY_BGR[min(int(count), len(_SEEN_BY_BGR) - 1)]
        cv2.rectangle(image, tuple(int(v) for v in corners[0]), tuple(int(v) for v in corners[1]), colour, -1)


def _tint_fields_of_view(image: np.ndarray, cameras: list[Camera], px, floor_xy: np.ndarray) -> np.ndarray:
    """`image` with each camera's floor footprint tinting the floor; where several overlap the tint deepens."""
    seen_by = np.zeros(image.shape[:2], np.float32)
    for cam in cameras:
        footprint_xy = floor_footprint(cam)
        if len(footprint_xy) >= 3:
            mask = np.zeros(image.shape[:2], np.uint8)
            cv2.fillPoly(mask, [px(footprint_xy)], 1)
            seen_by += mask
    on_floor = np.zeros(image.shape[:2], np.uint8)
    cv2.fillPoly(on_floor, [px(floor_xy)], 1)
    tint = ((1.0 - (1.0 - _FOV_ALPHA) ** seen_by) * on_floor)[..., None]
    return (image * (1.0 - tint) + np.array(_FOV_BGR, np.float32) * tint).astype(np.uint8)


def track_bgr(target_id: int) -> tuple[int, int, int]:
    """A stable colour per tracker id, from another walk around the hue circle than `person_bgr`'s."""
    r, g, b = colorsys.hsv_to_rgb((target_id * 0.381966 + 0.5) % 1.0, 0.9, 0.65)
    return int(b * 255), int(g * 255), int(r * 255)


def floor_footprint(camera: Camera, samples_per_side: int = 24) -> np.ndarray:
    """(N, 2) where the border of `camera`'s image meets the floor (z = 0), metres, following the border; rays
    of the border that do not reach the floor (above the horizon) are left out.

    Each border pixel is undistorted to its ray (OpenCV's lens model, the camera's own) and the ray is cut
    with the floor plane.
    """
    W, H = camera.width_px, camera.height_px
    s = np.linspace(0.0, 1.0, samples_per_side, endpoint=False)
    border = np.concatenate([
        np.stack([s * (W - 1), np.zeros_like(s)], 1), np.stack([np.full_like(s, W - 1), s * (H - 1)], 1),
        np.stack([(1 - s) * (W - 1), np.full_like(s, H - 1)], 1), np.stack([np.zeros_like(s), (1 - s) * (H - 1)], 1)])
    rays = cv2.undistortPoints(border.reshape(-1, 1, 2), camera.K, camera.dist).reshape(-1, 2)
    directions = np.column_stack([rays, np.ones(len(rays))]) @ camera.R_cam_from_world  # world frame, (N, 3)
    centre = camera.center_world
    down = directions[:, 2] < -1e-9
    scale = -centre[2] / directions[down, 2]
    return centre[:2] + directions[down, :2] * scale[:, None]


def top_down_picture(rec, tracks, t0_s: float, t1_s: float, rate_hz: float = 10.0,
                     px_per_m: float | None = None) -> np.ndarray:
    """The plan of a recording's store with each camera's field of view on the floor, everybody's true path from
    `t0_s` to `t1_s` and, with a tracks file, the tracked paths and the identity switches the scoring counts
    (`crossview.scoring.score` over the whole recording, those in the range).

    Args:
        rec: an opened recording (`crossview.recording.Recording`).
        tracks: its opened tracks file, or None.
        t0_s, t1_s: the time range, seconds.
        rate_hz: samples per second of the paths.
        px_per_m: scale; None fits the store to about 1000 pixels across.

    Returns:
        (H, W, 3) uint8 BGR image.
    """
    from core.records import watched_floor
    from crossview.scoring import score
    from crossview.scoring.identity import body_roots

    skeleton = rec.skeleton
    truth = list(rec.truth())
    paths: dict[int, list[np.ndarray]] = {}
    step = 1.0 / rate_hz
    next_t = t0_s
    for tick in truth:
        if tick.t_s < next_t - 1e-9 or tick.t_s > t1_s + 1e-9:
            continue
        next_t = tick.t_s + step
        for pid, root in zip(tick.person_ids.tolist(), body_roots(tick.poses, skeleton)):
            paths.setdefault(pid, []).append(root)
    tracked: dict[int, list[np.ndarray]] = {}
    switches = None
    if tracks is not None:
        outputs = list(tracks.outputs())
        next_t = t0_s
        for output in sorted(outputs, key=lambda o: o.stamp_s):
            if output.stamp_s < next_t - 1e-9 or output.stamp_s > t1_s + 1e-9:
                continue
            next_t = output.stamp_s + step
            for target in output.targets:
                tracked.setdefault(target.id, []).append(body_roots(target.pose[None], skeleton)[0])
        report = score(truth, outputs, scored_area=watched_floor(rec.boxes), skeleton=skeleton)
        switches = [s for s in report.id_switch_events if t0_s <= s[0] <= t1_s]
    floor = next(b for b in rec.boxes if b.kind == BoxKind.FLOOR)
    scale = px_per_m or min(120.0, 1000.0 / max(floor.size_m[0], floor.size_m[1]))
    title = (f"{rec.header.scenario_name} seed {rec.header.seed}: {len(rec.cameras)} cameras, true paths "
             f"{t0_s:g}-{t1_s:g} s" + (f" (solid), tracked (dotted, #id), {len(switches)} id switches (red)"
                                      if tracks is not None else ""))
    return draw_layout(rec.boxes, rec.cameras, {k: np.array(v) for k, v in paths.items()}, title, scale,
                       fields_of_view=True, tracked={k: np.array(v) for k, v in tracked.items()}, switches=switches)


def layout_picture(scenario, seconds: float = 60.0, seed: int | None = None, cameras: list[Camera] | None = None,
                   px_per_m: float = 40.0) -> np.ndarray:
    """Top-down picture of a scenario: its store, its cameras and `seconds` of everybody's trajectories.

    Args:
        scenario: a `sim.scenario.Scenario`.
        seconds: how long to simulate the crowd for the trajectories.
        seed: the scenario's seed when None.
        cameras: cameras to draw; None builds the scenario's rig with `sim.cameras.build_rig`.
        px_per_m: scale.

    Returns:
        (H, W, 3) uint8 BGR image.
    """
    from sim.rng import child_rng
    from sim.world import World

    seed = scenario.seed if seed is None else seed
    if cameras is None:
        from sim.cameras import build_rig

        cameras = build_rig(scenario, child_rng(seed, "cameras"))
    world = World(scenario, child_rng(seed, "crowd"))
    paths: dict[int, list[np.ndarray]] = {}
    lh, rh = world.skeleton.index("left_hip"), world.skeleton.index("right_hip")
    for k in range(int(seconds * 10) + 1):
        truth = world.advance(k / 10)
        pelvis = (truth.poses[:, lh, :2] + truth.poses[:, rh, :2]) / 2
        for pid, xy in zip(truth.person_ids.tolist(), pelvis):
            paths.setdefault(pid, []).append(xy)
    s = scenario.store
    title = (f"{scenario.name}: {s.width_m:g} x {s.depth_m:g} m, {len(cameras)} cameras, "
             f"{scenario.crowd.people} people, {seconds:g} s of paths")
    return draw_layout(world.boxes, cameras, {k: np.array(v) for k, v in paths.items()}, title, px_per_m)


def write_layout_pictures(out_dir: str | Path, names: tuple[str, ...] = ("store_layout1", "store_layout2",
                                                                          "supermarket"),
                          seconds: float = 60.0) -> list[Path]:
    """Writes `<name>.png` top-down pictures of shipped scenarios into `out_dir`; returns the paths."""
    from sim import scenario as sc

    out = Path(out_dir)
    written = []
    for name in names:
        scenario = sc.load(name)
        image = layout_picture(scenario, seconds, px_per_m=layout_scale(scenario.store.width_m))
        written.append(write_png(image, out / f"{name}.png"))
    return written


def layout_scale(width_m: float) -> float:
    """Pixels per metre of a store's top-down picture: larger for a small store (docs/layouts)."""
    return 60.0 if width_m <= 6 else 40.0 if width_m <= 10 else 30.0


def write_png(image: np.ndarray, path: str | Path) -> Path:
    """Writes a (H, W, 3) BGR picture as PNG, atomically; returns the path."""
    path = Path(path)
    encoded, png = cv2.imencode(".png", image, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    if not encoded:
        raise OSError(f"{path}: cannot encode PNG")
    write_bytes(png.tobytes(), path)
    return path
