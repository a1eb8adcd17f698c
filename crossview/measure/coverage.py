"""Where a rig will track people, predicted from the store, the cameras and the detector (`crossview coverage`,
`crossview plan`).

The tracker triangulates a joint from two views or more (`tracker.triangulation`), so a person is tracked
only where at least two cameras *detect* them, which is less than where two cameras *see* the point above the
floor. For each cell of the walkable floor (`sim.store.StoreGeometry.free`: where a pelvis may be), the model
stands three people of the crowd's heights there (`crowd_heights`; `sim.humanoid.standing_keypoints`, turned to
four headings) and asks, for each camera, what the scenario's detector (`sim.sensing.draws.draw_detections`, with the
scenario's `DetectorParams`) would do with that person-view:

- the joints in the image, through the camera's own lens (`core.projection.in_image`): a body cut by the image
  edge keeps only what is inside;
- the joints hidden by the store's shelves and counters: each joint's ray from the camera centre is cast against
  their boxes;
- the joints hidden by other people, in expectation at the scenario's density (people over walkable area): other
  people are upright cylinders `OCCLUDER_WIDTH_M` wide and `OCCLUDER_HEIGHT_M` tall scattered at random no
  nearer than `PERSONAL_SPACE_M`, so the chance that a ray is blocked is 1 - exp(-density x width x the length
  of ray below their heads);
- the person's size in the image against the profile's `min_person_frac`, and the visible joints against its
  `min_visible_joints` (never detected below either);
- the profile's miss model: missed with `miss_prob` + `miss_occlusion_gain` x the occluded share, and each joint
  then reported at its group's rate (`joint_miss_prob`, or `occluded_drop_prob` where occluded).

This gives each camera's chance of reporting each joint of a person at the cell in a frame. The chance that two
cameras or more report a joint follows (cameras independent, a Poisson-binomial, for each height, then
averaged); a bone of the score's ten (`crossview.scoring.pose`) is usable when its end joints are, and the cell's
*quality* is the mean over the ten bones. The predicted PCP is that quality through a curve calibrated once
against the tracker on the shipped scenarios (`PCP_CALIBRATION`; docs/coverage.md gives the runs and the fit),
the same for every scenario.

The old figure, a point above the cell inside two frustums, is kept as an upper bound: the most a rig can see
before shelves, sizes, image edges and the detector (`HeightCoverage`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from core.records import BoxKind
from core.types import Camera
from tracker.visibility import HIP_HEIGHT_M, floor_sight

HEAD_HEIGHT_M = 1.6
"""Height of an adult's head above the floor, metres (the top of the body, the first to leave a view)."""
HEIGHTS_M = (("hip", HIP_HEIGHT_M), ("head", HEAD_HEIGHT_M))
WARN_TWO_VIEW_SHARE = 0.9
"""`generate`, `run` and `coverage` warn when less than this share of the walkable floor is seen by two
cameras or more (at either height)."""
SHARES_OF = (1, 2, 3)
"""The shares reported: of the walkable floor seen by at least 1, 2 and 3 cameras."""


PERSON_HEIGHT_M = 1.70
"""The crowd's mean height (`sim.humanoid.sample_heights`: an even mix of women, N(1.63, 0.065) m, and men,
N(1.76, 0.07) m): the occluders' height."""
HEIGHT_QUANTILES = (1 / 6, 1 / 2, 5 / 6)
"""The people stood on each cell: the crowd's heights at these quantiles (`crowd_heights`), each standing for a
third of the crowd. Near a detector's size limit a short person is missed where a tall one is not."""
HEADINGS = 4
"""Headings the person is turned to on each cell (0, 90, 180, 270 degrees); the figures are their mean."""
PREDICT_CELL_M = 0.5
"""Side of the cells the prediction is made on, metres: every fifth cell of the navigation grid each way."""
OCCLUDER_WIDTH_M = 0.45
"""Width of another person as an occluder, metres: the humanoid's shoulders and arms at `PERSON_HEIGHT_M`."""
OCCLUDER_HEIGHT_M = PERSON_HEIGHT_M
"""Height of another person as an occluder, metres."""
PERSONAL_SPACE_M = 0.5
"""No other person stands nearer than this to the person looked at, metres (the crowd's passing distance)."""
TWO_VIEW_RISK = 0.5
"""A cell is *at risk* (of lost joints and broken identities) where the chance that two cameras or more detect a
person there is below this."""

# The ten bones of the score (`crossview.scoring.pose`: lower legs, upper legs, lower arms, upper arms, the head,
# the torso) as the COCO-17 joints a tracker needs for each: the head's from the nose and ears, the torso's from
# the shoulders and hips.
PCP_BONE_JOINTS: tuple[tuple[str, tuple[int, ...]], ...] = (
    ("lower_legs", (13, 15)), ("lower_legs", (14, 16)), ("upper_legs", (11, 13)), ("upper_legs", (12, 14)),
    ("lower_arms", (7, 9)), ("lower_arms", (8, 10)), ("upper_arms", (5, 7)), ("upper_arms", (6, 8)),
    ("head", (0, 3, 4)), ("torso", (5, 6, 11, 12)),
)

PCP_CALIBRATION = (0.831, 0.946)
"""(a, b) of the calibration curve: the predicted PCP's log-odds are a + b x the quality's log-odds,
PCP = 1 / (1 + exp(-(a + b ln(q / (1 - q))))): 0 where no bone is usable, 1 where every bone always is, and in
between the tracker's odds of a correct bone are e^a times (b = 1: proportional to) the odds that the bone has two
views (it recovers part of the rest from its memory of earlier views). Fitted once by least squares to the
tracker's PCP on store_layout1 and supermarket at several camera counts (`tools/calibrate_coverage.py`;
docs/coverage.md, "Calibration"), the same for every scenario."""


def calibrated_pcp(quality, calibration: tuple[float, float] = PCP_CALIBRATION):
    """A floor's (or a cell's) quality as a PCP, through the calibration curve (`PCP_CALIBRATION`)."""
    a, b = calibration
    q = np.clip(np.asarray(quality, dtype=float), 1e-9, 1.0 - 1e-9)
    return 1.0 / (1.0 + np.exp(-(a + b * np.log(q / (1.0 - q)))))


@dataclass(frozen=True)
class ViewLosses:
    """Where the person-views of a rig go: of every (cell, heading, camera) with part of the body in the image,
    the share never detected because the person is too small in the image, because too few joints are inside the
    image (cut by its edge), because shelves or people hide too many, or lost to the detector's misses; the rest
    is detected (each a share of the person-views, summing to 1)."""

    too_small: float
    cut: float
    hidden: float
    missed: float
    detected: float

    def line(self) -> str:
        return (f"too small {100 * self.too_small:.0f} %, cut by the image edge {100 * self.cut:.0f} %, hidden "
                f"{100 * self.hidden:.0f} %, missed by the detector {100 * self.missed:.0f} %, detected "
                f"{100 * self.detected:.0f} %")


@dataclass(frozen=True)
class Prediction:
    """What the detector and tracker will make of a rig, cell by cell of the walkable floor.

    Attributes:
        cells_xy: (M, 2) centres of the prediction's cells (`PREDICT_CELL_M`), metres.
        cell_m: their side, metres.
        people: the crowd the occlusion by people was predicted for (0: none).
        density_per_m2: that crowd over the walkable floor.
        detecting: (M,) expected number of cameras that detect a person on the cell in a frame.
        two_view: (M,) chance that two cameras or more detect them.
        bones: (M, 10) chance that each bone of the score (`PCP_BONE_JOINTS`) has both ends reported by two
            cameras or more.
        losses: where the person-views go (`ViewLosses`).
        camera_detect: (C, M) chance that each camera detects a person on each cell in a frame.
    """

    cells_xy: np.ndarray
    cell_m: float
    people: int
    density_per_m2: float
    detecting: np.ndarray
    two_view: np.ndarray
    bones: np.ndarray
    losses: ViewLosses
    camera_detect: np.ndarray

    @property
    def usable_two_view_share(self) -> float:
        """The share of floor-time in which two cameras or more detect a person (people spread evenly)."""
        return float(self.two_view.mean()) if len(self.two_view) else 0.0

    @property
    def quality(self) -> np.ndarray:
        """(M,) each cell's quality: the mean over the score's ten bones of the chance that they are usable."""
        return self.bones.mean(axis=1)

    @property
    def floor_quality(self) -> float:
        return float(self.quality.mean()) if len(self.quality) else 0.0

    @property
    def predicted_pcp(self) -> float:
        """The floor's quality through the calibration curve (`calibrated_pcp`)."""
        return float(calibrated_pcp(self.floor_quality))

    @property
    def risk_share(self) -> float:
        """The share of the floor at risk: two cameras detect a person there less often than `TWO_VIEW_RISK`."""
        return float((self.two_view < TWO_VIEW_RISK).mean()) if len(self.two_view) else 0.0

    def group_quality(self) -> dict[str, float]:
        """The floor's mean quality per bone group of the score."""
        groups: dict[str, list[int]] = {}
        for k, (group, _) in enumerate(PCP_BONE_JOINTS):
            groups.setdefault(group, []).append(k)
        return {g: float(self.bones[:, ks].mean()) if len(self.bones) else 0.0 for g, ks in groups.items()}


def _two_or_more(p: np.ndarray, axis: int) -> np.ndarray:
    """The chance that two or more of independent events with chances `p` happen (a Poisson-binomial tail)."""
    q = np.clip(1.0 - p, 1e-12, 1.0)
    none = np.prod(q, axis=axis)
    one = none * np.sum(p / q, axis=axis)
    return np.clip(1.0 - none - one, 0.0, 1.0)


def blocked_by_boxes(origin: np.ndarray, points: np.ndarray, obstacles) -> np.ndarray:
    """(N,) whether the segment from `origin` (3,) to each point (N, 3) passes through a shelf or counter box
    (yawed boxes standing on the floor) before it reaches the point: the slab test in each box's own frame."""
    blocked = np.zeros(len(points), dtype=bool)
    for ob in obstacles:
        c, s = np.cos(ob.yaw), np.sin(ob.yaw)
        rot = np.array([[c, s], [-s, c]])  # world to the box's frame
        o = np.array([*(rot @ (origin[:2] - ob.center)), origin[2]])
        p = np.column_stack([(points[:, :2] - ob.center) @ rot.T, points[:, 2]])
        d = p - o
        low = np.array([-ob.half[0], -ob.half[1], 0.0])
        high = np.array([ob.half[0], ob.half[1], ob.height])
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (low - o) / d, (high - o) / d
        # An axis the segment runs parallel to: inside its slab for every t, or never.
        parallel = d == 0
        inside = (o >= low) & (o <= high)
        t_near = np.where(parallel, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2)).max(axis=1)
        t_far = np.where(parallel, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2)).min(axis=1)
        blocked |= (t_near <= t_far) & (t_far > 0.0) & (t_near < 1.0)
    return blocked


def _people_hiding(origin: np.ndarray, points: np.ndarray, density_per_m2: float) -> np.ndarray:
    """(N,) the chance that another person of a crowd of `density_per_m2` stands in the ray from `origin` to each
    point: the ray's length below their heads (`OCCLUDER_HEIGHT_M`), beyond `PERSONAL_SPACE_M` from the point,
    swept by their width, as a Poisson count of people."""
    if density_per_m2 <= 0:
        return np.zeros(len(points))
    horizontal = np.linalg.norm(points[:, :2] - origin[:2], axis=1)
    rise = origin[2] - points[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        below = np.where(rise > 0, horizontal * (OCCLUDER_HEIGHT_M - points[:, 2]) / rise, horizontal)
    below = np.clip(np.where(points[:, 2] >= OCCLUDER_HEIGHT_M, 0.0, below), 0.0, horizontal)
    return 1.0 - np.exp(-density_per_m2 * OCCLUDER_WIDTH_M * np.maximum(below - PERSONAL_SPACE_M, 0.0))


def crowd_heights(crowd, people: int | None = None) -> tuple[float, ...]:
    """The heights of the people the prediction stands on each cell: the `HEIGHT_QUANTILES` of the crowd's heights
    (a `sim.crowd.CrowdConfig`: its fixed `heights_m` where they name everybody, else its mixture within
    `height_range_m`, drawn from a fixed stream), metres."""
    from sim.humanoid import sample_heights

    people = crowd.people if people is None else people
    if people and len(crowd.heights_m) >= people:
        pool = np.asarray(crowd.heights_m[:people], dtype=float)
    else:
        pool = sample_heights(np.random.default_rng(0), 2000, *crowd.height_range_m)
    return tuple(float(h) for h in np.quantile(pool, HEIGHT_QUANTILES))


def predict(store, cameras: list[Camera], params, people: int, occlusion: bool = True,
            heights_m: tuple[float, ...] = (PERSON_HEIGHT_M,)) -> Prediction:
    """The detection model of the module's docstring over a store's walkable floor.

    Args:
        store: a `sim.store.StoreGeometry`.
        cameras: the rig.
        params: the detector's `sim.sensing.profiles.DetectorParams`.
        people: how many people share the floor (their occlusion); 0 leaves it out.
        occlusion: whether shelves and people hide joints (the scenario's `[detector] occlusion`).
        heights_m: the heights of the people stood on each cell (`crowd_heights`), equally likely.
    """
    from core.projection import in_image
    from core.types import COCO17
    from sim.humanoid import standing_keypoints
    from sim.sensing.draws import joint_groups, person_size_px
    from sim.store import GRID_CELL_M

    step = max(1, round(PREDICT_CELL_M / GRID_CELL_M))
    free = store.free[step // 2::step, step // 2::step]
    cells_xy = store.cell_centers[step // 2::step, step // 2::step][free]
    M, J, H = len(cells_xy), COCO17.num_joints, HEADINGS
    area = float(store.free.sum()) * GRID_CELL_M**2
    density = people / area if occlusion and people > 0 and area > 0 else 0.0
    group = joint_groups(COCO17)
    joint_miss = np.asarray(params.joint_miss_prob)[group]  # (J,)
    occluded_miss = np.maximum(joint_miss, params.occluded_drop_prob)
    angles = 2 * np.pi * np.arange(H) / H
    tally = dict(too_small=0.0, cut=0.0, hidden=0.0, missed=0.0, detected=0.0)
    two_view, bones, camera_detect = np.zeros(M), np.zeros((M, len(PCP_BONE_JOINTS))), np.zeros((len(cameras), M))
    for height_m in heights_m:
        body = standing_keypoints(height_m)
        turned = np.stack([np.column_stack([body[:, 0] * np.cos(a) - body[:, 1] * np.sin(a),
                                            body[:, 0] * np.sin(a) + body[:, 1] * np.cos(a), body[:, 2]])
                           for a in angles])  # (H, J, 3)
        points = np.concatenate([np.broadcast_to(cells_xy[:, None, None, :], (M, H, J, 2)),
                                 np.zeros((M, H, J, 1))], axis=-1) + turned[None]  # (M, H, J, 3)
        report = np.zeros((len(cameras), M, H, J))
        detect = np.zeros((len(cameras), M, H))
        for c, camera in enumerate(cameras):
            px, inside = in_image(camera, points)  # (M, H, J, 2), (M, H, J)
            some = inside.any(axis=2)
            if not some.any():
                continue
            view_px, view_in, view_points = px[some], inside[some], points[some]  # (V, J, ...)
            origin = camera.center_world
            hidden = np.zeros(view_in.shape)
            if occlusion and store.obstacles:
                hidden[view_in] = blocked_by_boxes(origin, view_points[view_in], store.obstacles)
            crowd = np.zeros(view_in.shape)
            crowd[view_in] = _people_hiding(origin, view_points[view_in], density)
            occluded = 1.0 - (1.0 - hidden) * (1.0 - crowd)  # (V, J): chance each joint is hidden
            n_in = view_in.sum(axis=1)
            n_visible = ((1.0 - occluded) * view_in).sum(axis=1)
            large = person_size_px(view_px) >= params.min_person_frac * camera.height_px
            enough_in = n_in >= params.min_visible_joints
            enough = n_visible >= params.min_visible_joints
            detectable = large & enough
            miss = np.clip(params.miss_prob + params.miss_occlusion_gain * (occluded * view_in).sum(axis=1)
                           / np.maximum(n_in, 1), 0.0, 1.0)
            p_detect = np.where(detectable, 1.0 - miss, 0.0)
            rate = (1.0 - occluded) * (1.0 - joint_miss) + occluded * (1.0 - occluded_miss)
            detect[c][some] = p_detect
            report[c][some] = p_detect[:, None] * rate * view_in
            tally["too_small"] += float((~large).sum())
            tally["cut"] += float((large & ~enough_in).sum())
            tally["hidden"] += float((large & enough_in & ~enough).sum())
            tally["missed"] += float(miss[detectable].sum())
            tally["detected"] += float(p_detect.sum())
        # A person has one height: the chances over the cameras are combined per height, then averaged.
        two_view += _two_or_more(detect, axis=0).mean(axis=1) / len(heights_m)  # (M,)
        joint_two = _two_or_more(report, axis=0)  # (M, H, J)
        bones += np.stack([np.prod(joint_two[:, :, list(ends)], axis=2) for _, ends in PCP_BONE_JOINTS],
                          axis=-1).mean(axis=1) / len(heights_m)  # (M, 10)
        camera_detect += detect.mean(axis=2) / len(heights_m)
    total = sum(tally.values())
    losses = ViewLosses(**{k: v / total if total else 0.0 for k, v in tally.items()})
    return Prediction(cells_xy, step * GRID_CELL_M, int(people), density, camera_detect.sum(axis=0), two_view, bones,
                      losses, camera_detect)


@dataclass(frozen=True)
class HeightCoverage:
    """The walkable floor's cells seen at one height.

    Attributes:
        name: "hip" or "head".
        height_m: the height above the floor of the points tested, metres.
        counts: (N,) int, how many cameras see the point above each walkable cell's centre.
    """

    name: str
    height_m: float
    counts: np.ndarray

    def share(self, at_least: int) -> float:
        """The share of the walkable floor seen by `at_least` cameras or more (0 for a floor without cells)."""
        return float((self.counts >= at_least).mean()) if len(self.counts) else 0.0


@dataclass(frozen=True)
class Coverage:
    """A rig's coverage of a store's walkable floor.

    Attributes:
        scenario: the scenario's name.
        cameras: the rig.
        cell_m: the side of a floor cell, metres (`sim.store.GRID_CELL_M`).
        cells_xy: (N, 2) centres of the walkable cells, metres, world frame.
        boxes: the store's boxes (for the map).
        heights: the upper bound: the coverage of points at hip and at head height (`HEIGHTS_M`).
        prediction: what the detector and the tracker will make of the rig (`predict`).
        grid: (rows, cols) of a ceiling grid rig, None for placed or calibrated cameras.
        detector: the detector profile's name the prediction is for.
    """

    scenario: str
    cameras: tuple[Camera, ...]
    cell_m: float
    cells_xy: np.ndarray
    boxes: tuple
    heights: tuple[HeightCoverage, ...]
    prediction: Prediction
    grid: tuple[int, int] | None = None
    detector: str = ""

    @property
    def floor_m2(self) -> float:
        """The walkable floor's area, m²."""
        return len(self.cells_xy) * self.cell_m**2

    def warning(self) -> str | None:
        """One line when less than `WARN_TWO_VIEW_SHARE` of the walkable floor is seen by two cameras or more;
        None otherwise (`upper_bound_warning`)."""
        return upper_bound_warning(self.scenario, self.heights)

    def lines(self) -> list[str]:
        """The answer in words: the rig, the floor and the crowd; the prediction (PCP, the share of floor-time
        with two detecting cameras, the floor at risk, per bone group, where the person-views go); then the
        upper bound, per height the shares seen by 1, 2, 3 cameras or more."""
        n = len(self.cameras)
        cameras = f"{n} camera{'' if n == 1 else 's'}" + (f" ({self.grid[0]} x {self.grid[1]})" if self.grid else "")
        pred = self.prediction
        crowd = (f"{pred.people} people ({pred.density_per_m2:.2f} per m²)" if pred.people else "no other people")
        out = [f"{self.scenario}: {cameras}, {self.floor_m2:.1f} m² of walkable floor, {crowd}, detector "
               f"{self.detector or '?'}",
               f"  predicted PCP {pred.predicted_pcp:.3f} (calibrated on the tracker, docs/coverage.md); two "
               f"detecting cameras {100 * pred.usable_two_view_share:.1f} % of floor-time; at risk (two views "
               f"< {100 * TWO_VIEW_RISK:.0f} % of the time) {100 * pred.risk_share:.1f} % of the floor",
               "  usable bones by group: " + ", ".join(f"{g} {100 * q:.1f} %"
                                                      for g, q in pred.group_quality().items()),
               f"  person-views: {pred.losses.line()}",
               "  upper bound (a point inside the image; no shelves, sizes, image edges or misses):"]
        for h in self.heights:
            shares = ", ".join(f">= {n}: {100 * h.share(n):5.1f} %" for n in SHARES_OF)
            out.append(f"    {h.name:<4} height {h.height_m:g} m  seen by {shares}")
        return out

    def as_dict(self) -> dict:
        """The figures as JSON-ready data (`crossview coverage --figures`, `crossview plan`)."""
        pred = self.prediction
        return {
            "scenario": self.scenario, "cameras": len(self.cameras), "grid": list(self.grid) if self.grid else None,
            "detector": self.detector, "walkable_m2": round(self.floor_m2, 3), "people": pred.people,
            "predicted_pcp": round(pred.predicted_pcp, 4), "floor_quality": round(pred.floor_quality, 4),
            "usable_two_view_share": round(pred.usable_two_view_share, 4), "risk_share": round(pred.risk_share, 4),
            "group_quality": {g: round(q, 4) for g, q in pred.group_quality().items()},
            "person_views": {k: round(v, 4) for k, v in vars(pred.losses).items()},
            "upper_bound": {h.name: {f">={n}": round(h.share(n), 4) for n in SHARES_OF} for h in self.heights},
        }


def upper_bound_warning(name: str, heights) -> str | None:
    """One line when less than `WARN_TWO_VIEW_SHARE` of the walkable floor is seen by two cameras or more at
    either height of `heights` (`HeightCoverage`s) of the scenario `name`; None otherwise."""
    worst = min(heights, key=lambda h: h.share(2))
    if worst.share(2) >= WARN_TWO_VIEW_SHARE:
        return None
    return (f"warning: {name}: only {100 * worst.share(2):.0f} % of the walkable floor is seen by two "
            f"cameras or more at {worst.name} height ({worst.height_m:g} m), below "
            f"{100 * WARN_TWO_VIEW_SHARE:.0f} %: people elsewhere cannot be triangulated "
            "(`crossview coverage SCENARIO -o MAP.png` shows where)")


def upper_bound(scenario, cameras: list[Camera] | None = None):
    """The upper bound alone (no prediction): the store, the rig, its grid (None for placed or calibrated
    cameras), the walkable cells' centres and their `HeightCoverage` at hip and at head height."""
    from sim.cameras import build_rig
    from sim.rng import child_rng
    from sim.store import StoreGeometry

    store = StoreGeometry(scenario.store, name=scenario.where)
    rig = scenario.cameras
    grid = (rig.rows, rig.cols) if cameras is None and not rig.placements and not rig.calibration else None
    if cameras is None:
        cameras = build_rig(scenario, child_rng(scenario.seed, "cameras"))
    cells_xy = store.cell_centers[store.free]
    heights = tuple(HeightCoverage(name, height_m,
                                   floor_sight(cameras, cells_xy, height_m).sum(axis=0, dtype=np.int64))
                    for name, height_m in HEIGHTS_M)
    return store, list(cameras), grid, cells_xy, heights


def warning(scenario) -> str | None:
    """`generate`'s and `run`'s warning about a scenario's rig (`upper_bound_warning`), without the prediction."""
    return upper_bound_warning(scenario.name, upper_bound(scenario)[4])


def coverage(scenario, cameras: list[Camera] | None = None, people: int | None = None) -> Coverage:
    """The prediction (`predict`) and the upper bound (how many cameras see each cell of the walkable floor at hip
    and at head height) of a scenario's rig.

    Args:
        scenario: a `sim.scenario.Scenario`.
        cameras: the rig; None builds the scenario's own (`sim.cameras.build_rig`, with its seed, as
            `crossview generate` does).
        people: the crowd whose occlusion to predict; None: the scenario's (`[crowd] people`).

    Raises:
        ScenarioError: the store or the rig cannot be built (named by the scenario's file and key).
    """
    from sim.store import GRID_CELL_M

    store, cameras, grid, cells_xy, heights = upper_bound(scenario, cameras)
    crowd = scenario.crowd.people if people is None else people
    params = scenario.detector.params()
    prediction = predict(store, list(cameras), params, crowd, occlusion=scenario.detector.occlusion,
                         heights_m=crowd_heights(scenario.crowd, crowd))
    return Coverage(scenario.name, tuple(cameras), GRID_CELL_M, cells_xy, store.boxes, tuple(heights), prediction,
                    grid, scenario.detector.profile.value)


def write_map(cov: Coverage, path: Path, px_per_m: float | None = None) -> Path:
    """Writes the coverage map (PNG): the store from above, first as predicted (each cell of the prediction
    coloured by how many cameras detect a person there, in expectation, rounded down), then the upper bound at
    hip height and at head height (each walkable cell by how many cameras see the point), side by side
    (`crossview.pictures.layout.draw_layout`)."""
    from crossview.pictures import layout as pictures

    floor = next(b for b in cov.boxes if b.kind == BoxKind.FLOOR)
    scale = px_per_m or pictures.layout_scale(floor.size_m[0])
    pred = cov.prediction
    title = (f"{cov.scenario}, predicted: cameras detecting a person; PCP {pred.predicted_pcp:.2f}, two views "
             f"{100 * pred.usable_two_view_share:.0f} % of floor-time")
    images = [pictures.draw_layout(cov.boxes, list(cov.cameras), title=title, px_per_m=scale,
                                   seen_by=(pred.cells_xy, np.floor(pred.detecting + 1e-9).astype(int), pred.cell_m))]
    for h in cov.heights:
        title = (f"{cov.scenario}, upper bound at {h.name} height {h.height_m:g} m: "
                 + ", ".join(f">= {n} cameras {100 * h.share(n):.0f} %" for n in SHARES_OF))
        images.append(pictures.draw_layout(cov.boxes, list(cov.cameras), title=title, px_per_m=scale,
                                           seen_by=(cov.cells_xy, h.counts, cov.cell_m)))
    gap = np.full((images[0].shape[0], 12, 3), 255, np.uint8)
    row = [images[0]]
    for image in images[1:]:
        row += [gap, image]
    return pictures.write_png(np.hstack(row), path)
