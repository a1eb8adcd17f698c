"""Detector statistics: a recording's 2D detections measured against its 3D truth projected into each camera,
beside real OpenPose on the Shelf dataset.

The measurement is the one made on the real detector, so that a synthetic recording (`crossview generate`) and
a real one (`crossview convert` of a dataset folder with 3D truth) give comparable figures:

- **Truth**: the recording's 3D ground truth (what the scorer uses) at each frame's capture time, projected
  through the camera's lens model (`core.projection.in_image`). The per-detection truth a synthetic recording
  also stores is not used: real data has none, and the detector's joint need not be the scorer's.
- **Joints**: the 12 joints both skeleton layouts name alike (`JOINTS_12`: shoulders, elbows, wrists, hips,
  knees, ankles; COCO-17 and the Campus/Shelf 14 joints). Person size: the larger side of the box of the
  person's 12 projected joints (about 400 px on Shelf), leaving out the joints behind the camera or beyond its
  lens's monotonic radius (whose projections are no pixels a lens gives); a person with no joint in the image
  takes no detection. Errors are divided by it; pixel offsets are given
  at a 400 px person (`SIZE_AT_PX`).
- **Matching**: per camera frame, detections are assigned to the true people by the Hungarian algorithm on
  the mean distance of their common joints divided by the person's size; a pair further apart than
  `MATCH_GATE` is no match. An unmatched detection with any of the 12 joints is a false-positive person (one
  with none, a face alone, is not counted); a person-view (at least half of the 12 joints inside the image)
  without a matched detection is a missed person-view.
- **Joint miss**: a matched detection lacks a joint that is inside the image. Persistence and the lag-1
  correlation pair the same person, joint and camera in consecutive frames of that camera.
- **Per person**: each true person's limb error is the worst of the mean errors / size of its elbows, wrists,
  knees and ankles over all its matched views (`LIMB_JOINTS`, each measured in at least
  `MIN_PERSON_JOINT_VIEWS` views); `per_person` gives them, their median over the people and the share of
  people above `BAD_LIMB_FACTOR` x that median: the people a detector keeps getting wrong.
- **Cross-view agreement**: the matched detections of one person in the frames of different cameras
  captured within half a frame interval (`CROSS_VIEW_WINDOW_FRAC`) of each other are triangulated per joint
  (DLT, at least `CROSS_VIEW_MIN_VIEWS` views): how far the detections lie from the point they agree on
  (reprojection, px at 400) and how far that point lies from the true joint (metres).

- **Why person-views were missed** (a recording with its scenario: `crossview generate`): each missed person-view
  is put down to the first of the rig's geometry that rules it out under the recording's detector profile, as
  the simulated detector rules (`sim.sensing.draws.draw_detections`) and `crossview coverage` predicts: too
  small (the box of all its projected joints below `min_person_frac` of the image height), cut by the image edge
  (fewer than `min_visible_joints` joints inside the image), hidden by shelves (fewer of them left unblocked by
  the store's shelves and counters, `crossview.measure.coverage.blocked_by_boxes`); the rest are the detector's
  own misses or people hidden by other people (a recording holds visibility only for the people it detected).
  A converted dataset holds no profile: its misses are not split.

A camera frame whose truth holds nobody is not measured: datasets leave the frames they did not annotate
empty, so such a frame says nothing about the detector (a synthetic store that is empty is skipped alike).
"""

from __future__ import annotations

import json
import math
from collections import defaultdict
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.optimize import linear_sum_assignment

from core.errors import CrossviewError
from core.projection import in_image
from core.records import CameraFrame
from core.types import JOINT_GROUPS, Camera, Skeleton
from tracker.geometry import undistort_points
from tracker.triangulation import PLANE_ROW, reprojection_error_px, triangulate

JOINTS_12 = (
    "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
    "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle",
)
"""The joints measured, by name: those COCO-17 and the Campus/Shelf 14-joint layout share."""
GROUPS = ("wrists", "hips", "shoulders", "elbows", "ankles", "knees")
"""Joint groups of the table, in its order (`core.types.JOINT_GROUPS` names which joints each holds)."""

MATCH_GATE = 0.5
"""Largest mean joint distance of a detection from a true person, as a fraction of the person's size, that
still counts as a detection of that person (a detection's own error is a few hundredths; two people side by
side are about a third of a size apart, and the assignment takes the nearer)."""
GROSS_ERROR_FRAC = 0.2
"""A joint further than this fraction of the person's size from the truth is a gross error."""
HALF_IN_IMAGE = 0.5
"""A person-view is a person with at least this fraction of the 12 joints inside the image."""
PERSON_LIKE_JOINTS = 6
"""A false-positive person with at least this many of the 12 joints is person-like."""
SIZE_AT_PX = 400.0
"""Pixel offsets are reported at this person size (Shelf's people are about this size)."""
MIN_MATCHED_DETECTIONS = 20
"""Fewer matched detections than this in a recording measure nothing: refused."""
CROSS_VIEW_WINDOW_FRAC = 0.5
"""Frames of different cameras captured within this fraction of the rig's median frame interval of the first
frame of a group are taken as one instant for the cross-view figures."""
BAD_LIMB_FACTOR = 2.0
"""A person whose limb error (`per_person`) is above this many times the crowd's median is one the detector
keeps getting wrong."""
LIMB_JOINTS = ("elbow", "wrist", "knee", "ankle")
"""The joints of a person's limb error: the worst of their mean errors."""
MIN_PERSON_JOINT_VIEWS = 25
"""A person's joint measured in fewer matched views than this (a second at 25 fps) is left out of its limb error."""
CROSS_VIEW_MIN_VIEWS = 3
"""A joint is triangulated for the cross-view figures from at least this many views (two views always agree
up to the epipolar constraint)."""

SHELF_OPENPOSE_FILE = Path(__file__).with_name("data") / "shelf-openpose-detector-stats.json"
"""Real OpenPose (BODY25) on the Shelf dataset (Belagiannis et al., CVPR 2014; 5 cameras, 1032 x 776, 25 fps),
measured by this module (`crossview detector-stats -o`) against the dataset's annotated 3D joints; source and
licence in crossview/measure/data/README.md."""
SHELF_OPENPOSE_LABEL = "real OpenPose, Shelf"

FIGURE_KEYS = (
    "error_over_size_median", "error_over_size_p90", "error_over_size_p99", "gross_error_rate",
    "vertical_offset_px_at_400", "lag1_error_correlation", "miss_rate", "miss_persistence",
    "cross_view_reprojection_px_at_400", "cross_view_error_m",
)
"""The figures a statistics file holds for all joints and for each joint group (`per_group`)."""
TOTAL_KEYS = ("missed_person_view_rate", "false_positive_people_per_frame", "false_positive_people_ge6_per_frame")
"""The figures a statistics file holds for all joints only."""


def read_stats_file(path) -> dict:
    """A statistics table written by `crossview detector-stats -o`, checked: a JSON object with every key of
    `FIGURE_KEYS` and `TOTAL_KEYS` at the top and `FIGURE_KEYS` for each of `GROUPS` under `per_group`, each a
    finite number or null (nothing measured).

    Raises:
        CrossviewError: the file is unreadable or is not such a table; the message names the file and the key.
    """
    try:
        stats = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise CrossviewError(f"{path}: no such file (a detector statistics file: `crossview detector-stats REC "
                             "-o FILE.json`)") from None
    except (OSError, UnicodeDecodeError) as e:
        raise CrossviewError(f"{path}: cannot read it: {e}") from None
    except json.JSONDecodeError as e:
        raise CrossviewError(f"{path}: not JSON ({e}); a detector statistics file is what `crossview "
                             "detector-stats REC -o FILE.json` writes") from None
    if not isinstance(stats, dict) or not isinstance(stats.get("per_group"), dict):
        raise CrossviewError(f"{path}: per_group: missing; not a detector statistics file (what `crossview "
                             "detector-stats REC -o FILE.json` writes)")
    tables = [("", stats, FIGURE_KEYS + TOTAL_KEYS)]
    for g in GROUPS:
        table = stats["per_group"].get(g)
        if not isinstance(table, dict):
            raise CrossviewError(f"{path}: per_group.{g}: missing; a detector statistics file has the groups "
                                 f"{', '.join(GROUPS)}")
        tables.append((f"per_group.{g}.", table, FIGURE_KEYS))
    for prefix, table, keys in tables:
        for key in keys:
            if key not in table:
                raise CrossviewError(f"{path}: {prefix}{key}: missing; a detector statistics file has every key "
                                     "`crossview detector-stats -o` writes")
            v = table[key]
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)):
                raise CrossviewError(f"{path}: {prefix}{key}: {v!r} is not a finite number (nor null, nothing "
                                     "measured)")
    return stats


SHELF_OPENPOSE: dict = read_stats_file(SHELF_OPENPOSE_FILE)
"""`SHELF_OPENPOSE_FILE`'s table: the reference beside which `format_detector_stats` prints, and the target of
`crossview fit-detector --target shelf-openpose`."""


SHELF_OPENPOSE_NAME = "shelf-openpose"
"""The `--reference` (`detector-stats`) and `--target` (`fit-detector`) that name `SHELF_OPENPOSE_FILE`."""


@dataclass(frozen=True)
class Reference:
    """What a recording's statistics are put beside: a statistics table, the column's heading (its source) and
    the words saying where it comes from."""

    stats: dict
    label: str
    where: str


def reference(text: str = SHELF_OPENPOSE_NAME) -> Reference:
    """The reference `text` names: `shelf-openpose` (real OpenPose on Shelf, shipped) or a statistics file
    (`crossview detector-stats -o FILE.json`), labelled by the source it records (`source`: the recording it was
    measured on) or, in a file without one, by its own name.

    Raises:
        CrossviewError: the file is no statistics table (`read_stats_file`).
    """
    if text == SHELF_OPENPOSE_NAME:
        return Reference(SHELF_OPENPOSE, SHELF_OPENPOSE_LABEL,
                         f"real OpenPose on the Shelf dataset ({SHELF_OPENPOSE_NAME}: 5 cameras, people "
                         f"{SHELF_OPENPOSE['person_size_px_median']:.0f} px, a different scene from a store's)")
    stats = read_stats_file(text)
    source = stats.get("source")
    label = source if isinstance(source, str) and source else Path(text).name
    return Reference(stats, label, f"{text}" + (f" (measured on {source})" if label == source else ""))


def joint_indices(skeleton: Skeleton) -> np.ndarray:
    """(12,) the index in `skeleton` of each of `JOINTS_12`.

    Raises:
        CrossviewError: the skeleton lacks one of them.
    """
    missing = [name for name in JOINTS_12 if name not in skeleton.joints]
    if missing:
        raise CrossviewError(f"skeleton {skeleton.name} has no {', '.join(missing)}; detector-stats measures "
                             f"{', '.join(JOINTS_12)}")
    return np.array([skeleton.index(name) for name in JOINTS_12])


def group_members() -> dict[str, tuple[int, ...]]:
    """Group name -> the positions in `JOINTS_12` of its joints, in `GROUPS` order."""
    return {g: tuple(i for i, name in enumerate(JOINTS_12) if any(w in name for w in JOINT_GROUPS[g]))
            for g in GROUPS}


def person_sizes_px(points_px: np.ndarray) -> np.ndarray:
    """(P,) the larger side of the box of each person's projected joints points_px (P, J, 2); NaN joints are
    left out, and a person with none has size NaN."""
    finite = np.isfinite(points_px).all(axis=-1)[..., None]  # (P, J, 1)
    extent = (np.where(finite, points_px, -np.inf).max(axis=1) - np.where(finite, points_px, np.inf).min(axis=1))
    extent = extent.max(axis=-1)
    return np.where(np.isfinite(extent), extent, np.nan)


@dataclass
class _View:
    """One matched detection: a person seen by one camera in one frame (12 joints)."""

    detection_px: np.ndarray  # (12, 2) reported pixels, NaN missing
    error: np.ndarray  # (12, 2) (detection - truth) / size, NaN where either is missing
    detected: np.ndarray  # (12,) bool
    inside: np.ndarray  # (12,) bool, the true joint is inside the image
    size_px: float
    truth_m: np.ndarray  # (12, 3) the true joints at the capture time


@dataclass
class _FrameRecord:
    camera: int
    capture_s: float
    views: dict[int, _View] = field(default_factory=dict)  # person id -> view


MISS_CAUSES = ("too_small", "cut_by_image_edge", "hidden_by_shelves", "detector_or_people")
"""Why person-views were missed (module docstring), in the order they are tried."""
MISS_CAUSE_LABELS = ("too small for the profile's size limit", "cut by the image edge", "hidden by shelves",
                     "the detector's own, or hidden by people")


@dataclass(frozen=True)
class MissGeometry:
    """What rules a person-view out before the detector's own misses: the detector profile's size and visible-joint
    limits and the store's shelves and counters (`sim.store.Obstacle`s; none where the scenario's detector ignores
    occlusion)."""

    min_person_frac: float
    min_visible_joints: int
    obstacles: tuple = ()

    @classmethod
    def of(cls, scenario) -> MissGeometry:
        """The geometry of a `sim.scenario.Scenario`'s detector and store."""
        from sim.store import StoreGeometry

        params = scenario.detector.params()
        obstacles = StoreGeometry(scenario.store, name=scenario.where).obstacles if scenario.detector.occlusion else ()
        return cls(float(params.min_person_frac), int(params.min_visible_joints), tuple(obstacles))

    def cause(self, camera: Camera, joints_m: np.ndarray) -> str:
        """The first of `MISS_CAUSES` that explains a missed view by `camera` of a person with joints `joints_m`
        (J, 3): all of the skeleton's joints, as the detector sees them."""
        from crossview.measure.coverage import blocked_by_boxes

        px, inside = in_image(camera, joints_m)
        if not person_sizes_px(px[None])[0] >= self.min_person_frac * camera.height_px:  # (NaN: no joint known)
            return "too_small"
        if inside.sum() < self.min_visible_joints:
            return "cut_by_image_edge"
        if self.obstacles:
            hidden = blocked_by_boxes(camera.center_world, joints_m[inside], self.obstacles)
            if inside.sum() - hidden.sum() < self.min_visible_joints:
                return "hidden_by_shelves"
        return "detector_or_people"


class DetectorStatsAccumulator:
    """Measures detections frame by frame (`add`), then gives the figures (`result`).

    Args:
        cameras: the rig (a sequence or name -> Camera).
        skeleton: the joint layout of both the frames and the truth.
        geometry: the rig's detector limits and shelves, to say why person-views were missed (None: not said).
    """

    def __init__(self, cameras: Sequence[Camera] | Mapping[str, Camera], skeleton: Skeleton,
                 geometry: MissGeometry | None = None):
        self._geometry = geometry
        cams = list(cameras.values()) if isinstance(cameras, Mapping) else list(cameras)
        self.cameras = cams
        self._camera_of = {c.name: i for i, c in enumerate(cams)}
        self._joints = joint_indices(skeleton)
        self._records: list[_FrameRecord] = []
        self._frames = 0
        self._counts = [defaultdict(int) for _ in cams]

    def add(self, camera_frame: CameraFrame) -> None:
        """Measures one delivered frame; its `poses_at_capture` must be given (`Recording.frames(with_poses=True)`).

        Raises:
            CrossviewError: the frame's camera is not in the rig.
        """
        frame, poses = camera_frame.frame, camera_frame.poses_at_capture
        if frame.camera not in self._camera_of:
            raise CrossviewError(f"frame of camera {frame.camera!r}, which is not in the rig "
                                 f"({', '.join(self._camera_of)})")
        if poses is None:
            raise ValueError("detector stats need each frame's poses_at_capture")
        self._frames += 1
        if len(poses.person_ids) == 0:
            return
        c = self._camera_of[frame.camera]
        counts = self._counts[c]
        truth_m = np.asarray(poses.poses, dtype=np.float64)[:, self._joints]  # (P, 12, 3)
        truth_px, inside = in_image(self.cameras[c], truth_m)  # (P, 12, 2), (P, 12)
        # A joint behind the camera or beyond the lens's monotonic radius has no pixel a lens would give it (its
        # projection runs to 1e12 px): it is left out of the size, as a NaN joint is, and a person with no joint
        # inside the image is nobody a detection can be of (its size would make every detection match it).
        size = person_sizes_px(np.where(_projectable(self.cameras[c], truth_m)[..., None], truth_px, np.nan))
        size[~inside.any(axis=1)] = np.nan
        detections = np.asarray(frame.keypoints_px, dtype=np.float64)[:, self._joints]  # (D, 12, 2)
        record = _FrameRecord(c, float(camera_frame.truth.capture_s))
        counts["frames"] += 1
        matched_truth, matched_det = _match(truth_px, size, detections)
        for p, d in zip(matched_truth, matched_det):
            error = (detections[d] - truth_px[p]) / size[p]
            record.views[int(poses.person_ids[p])] = _View(
                detections[d], error, np.isfinite(detections[d, :, 0]), inside[p], float(size[p]), truth_m[p])
        view = inside.mean(axis=1) >= HALF_IN_IMAGE
        counts["person_views"] += int(view.sum())
        missed = np.flatnonzero(view & ~np.isin(np.arange(len(view)), matched_truth))
        counts["missed_person_views"] += len(missed)
        if self._geometry is not None:
            everyone = np.asarray(poses.poses, dtype=np.float64)
            for p in missed:
                counts[f"missed_{self._geometry.cause(self.cameras[c], everyone[p])}"] += 1
        unmatched = np.setdiff1d(np.arange(len(detections)), matched_det)
        # A detection with none of the 12 measured joints (a face alone) cannot be told from a person: not counted.
        unmatched = unmatched[np.isfinite(detections[unmatched, :, 0]).any(axis=1)]
        counts["false_positive_people"] += len(unmatched)
        counts["false_positive_people_ge6"] += int(
            np.count_nonzero(np.isfinite(detections[unmatched, :, 0]).sum(axis=1) >= PERSON_LIKE_JOINTS))
        self._records.append(record)

    def result(self) -> dict:
        """The figures (see the module docstring); None where nothing was measured."""
        records = self._records
        views = [(r.camera, v) for r in records for v in r.views.values()]
        person_of = np.array([pid for r in records for pid in r.views], dtype=np.int64)
        frames_measured = sum(c["frames"] for c in self._counts)
        members = group_members()
        err = np.array([v.error for _, v in views], dtype=np.float64).reshape(-1, 12, 2)
        detected = np.array([v.detected for _, v in views], dtype=bool).reshape(-1, 12)
        inside = np.array([v.inside for _, v in views], dtype=bool).reshape(-1, 12)
        norm = np.linalg.norm(err, axis=-1)  # (N, 12), NaN where not measured
        pairs = _consecutive_pairs(records)
        lag_a, lag_b, miss_now, miss_next = _pair_arrays(pairs)
        cross = _cross_view(records, self.cameras)

        def figures(joints) -> dict:
            joints = list(joints)
            e = norm[:, joints]
            e = e[np.isfinite(e)]
            dy = err[:, joints, 1]
            dy = dy[np.isfinite(dy)]
            in_img = inside[:, joints]
            missed = in_img & ~detected[:, joints]
            now = miss_now[:, joints]
            return {
                "error_over_size_median": _quantile(e, 50), "error_over_size_p90": _quantile(e, 90),
                "error_over_size_p99": _quantile(e, 99),
                "gross_error_rate": _ratio(np.count_nonzero(e > GROSS_ERROR_FRAC), e.size),
                "vertical_offset_px_at_400": None if dy.size == 0 else float(np.median(dy) * SIZE_AT_PX),
                "lag1_error_correlation": _lag1_correlation(lag_a[:, joints], lag_b[:, joints]),
                "miss_rate": _ratio(np.count_nonzero(missed), np.count_nonzero(in_img)),
                "miss_persistence": _ratio(np.count_nonzero(now & miss_next[:, joints]), np.count_nonzero(now)),
                "cross_view_reprojection_px_at_400": _median(cross["reprojection"], joints),
                "cross_view_error_m": _median(cross["error"], joints),
                "joints_measured": int(e.size),
            }

        stats = figures(range(12))
        total = {k: sum(c[k] for c in self._counts) for k in
                 ("person_views", "missed_person_views", "false_positive_people", "false_positive_people_ge6")}
        sizes = np.array([v.size_px for _, v in views], dtype=np.float64)
        stats.update({
            "frames": self._frames, "frames_measured": frames_measured, "matched_detections": len(views),
            "person_views": total["person_views"],
            "missed_person_view_rate": _ratio(total["missed_person_views"], total["person_views"]),
            "false_positive_people_per_frame": _ratio(total["false_positive_people"], frames_measured),
            "false_positive_people_ge6_per_frame": _ratio(total["false_positive_people_ge6"], frames_measured),
            "missed_person_views_by_cause": None if self._geometry is None else {
                cause: _ratio(sum(c[f"missed_{cause}"] for c in self._counts), total["person_views"])
                for cause in MISS_CAUSES},
            "person_size_px_median": _quantile(sizes, 50), "cross_view_joints": cross["count"],
            "match_gate": MATCH_GATE,
            "per_joint": {name: figures([j]) for j, name in enumerate(JOINTS_12)},
            "per_group": {g: figures(js) for g, js in members.items()},
            "per_camera": {},
            "per_person": _per_person(person_of, norm),
        })
        for c, cam in enumerate(self.cameras):
            counts = self._counts[c]
            if not counts["frames"]:
                continue
            mine = np.array([i for i, (vc, _) in enumerate(views) if vc == c], dtype=np.int64)
            e = norm[mine]
            e = e[np.isfinite(e)]
            stats["per_camera"][cam.name] = {
                "frames_measured": counts["frames"], "matched_detections": len(mine),
                "error_over_size_median": _quantile(e, 50),
                "miss_rate": _ratio(np.count_nonzero(inside[mine] & ~detected[mine]), np.count_nonzero(inside[mine])),
                "missed_person_view_rate": _ratio(counts["missed_person_views"], counts["person_views"]),
                "missed_person_views_by_cause": None if self._geometry is None else {
                    cause: _ratio(counts[f"missed_{cause}"], counts["person_views"]) for cause in MISS_CAUSES},
                "false_positive_people_per_frame": _ratio(counts["false_positive_people"], counts["frames"]),
            }
        return stats


def _per_person(person_of: np.ndarray, norm: np.ndarray) -> dict:
    """The per-person spread (module docstring, "Per person").

    Args:
        person_of: (N,) the true person of each matched view; norm: (N, 12) its joints' error / size (NaN: not
            measured).
    """
    limbs = [i for i, name in enumerate(JOINTS_12) if name.split("_", 1)[1] in LIMB_JOINTS]
    by_person = {}
    for pid in np.unique(person_of).tolist():
        e = norm[person_of == pid][:, limbs]
        counts = np.isfinite(e).sum(axis=0)
        if not (counts >= MIN_PERSON_JOINT_VIEWS).any():
            continue
        with np.errstate(invalid="ignore"):
            means = np.nansum(e, axis=0) / np.maximum(counts, 1)
        by_person[str(pid)] = float(means[counts >= MIN_PERSON_JOINT_VIEWS].max())
    values = np.array(list(by_person.values()))
    median = float(np.median(values)) if values.size else None
    return {
        "people_measured": len(by_person), "limb_error_median": median, "bad_limb_factor": BAD_LIMB_FACTOR,
        "bad_limb_person_share": None if median is None else float(np.mean(values > BAD_LIMB_FACTOR * median)),
        "limb_error_by_person": by_person,
    }


def _match(truth_px: np.ndarray, size_px: np.ndarray, detections_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hungarian assignment of detections to true people on the mean distance of their common joints over the
    person's size, pairs beyond `MATCH_GATE` dropped.

    Args:
        truth_px: (P, J, 2) projected truth; size_px: (P,) person sizes; detections_px: (D, J, 2).

    Returns:
        (truth rows, detection columns) of the matched pairs.
    """
    P, D = len(truth_px), len(detections_px)
    if P == 0 or D == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    dist = np.linalg.norm(truth_px[:, None] - detections_px[None], axis=-1)  # (P, D, J)
    common = np.isfinite(dist)
    with np.errstate(invalid="ignore", divide="ignore"):
        cost = np.where(common, dist, 0.0).sum(axis=-1) / common.sum(axis=-1) / size_px[:, None]  # (P, D)
    cost = np.where(np.isfinite(cost), cost, np.inf)
    allowed = cost <= MATCH_GATE
    rows, cols = linear_sum_assignment(np.where(allowed, cost, 2 * MATCH_GATE + 1))
    keep = allowed[rows, cols]
    return rows[keep], cols[keep]


def _projectable(camera: Camera, points_m: np.ndarray) -> np.ndarray:
    """(...,) whether each world point (..., 3) lies in front of `camera` within its lens's monotonic radius
    (`core.projection.monotonic_radius`), where its projection is a pixel a real lens would give it."""
    from core.projection import monotonic_radius

    cam = points_m @ np.asarray(camera.R_cam_from_world).T + np.asarray(camera.t_cam_from_world)
    z = cam[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        r2 = (cam[..., 0] ** 2 + cam[..., 1] ** 2) / z**2
    return (z > 0) & (r2 <= monotonic_radius(camera.dist) ** 2)


def _consecutive_pairs(records: list[_FrameRecord]) -> list[tuple[_View, _View]]:
    """(view at frame k, view at frame k + 1) of the same person in consecutive measured frames of a camera."""
    by_camera = defaultdict(list)
    for r in records:
        by_camera[r.camera].append(r)
    pairs = []
    for frames in by_camera.values():
        frames.sort(key=lambda r: r.capture_s)
        for now, after in zip(frames, frames[1:]):
            pairs.extend((now.views[pid], after.views[pid]) for pid in now.views.keys() & after.views.keys())
    return pairs


def _pair_arrays(pairs) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The errors (N, 12, 2) at k and k + 1, and (N, 12) bool: missed (inside, not detected) at k with the
    joint inside at k + 1, and missed at k + 1."""
    if not pairs:
        return np.zeros((0, 12, 2)), np.zeros((0, 12, 2)), np.zeros((0, 12), bool), np.zeros((0, 12), bool)
    a = np.array([p[0].error for p in pairs])
    b = np.array([p[1].error for p in pairs])
    in_both = np.array([p[0].inside & p[1].inside for p in pairs])
    now = np.array([~p[0].detected for p in pairs]) & in_both
    after = np.array([~p[1].detected for p in pairs]) & in_both
    return a, b, now, after


def _lag1_correlation(a: np.ndarray, b: np.ndarray) -> float | None:
    """Pearson correlation of a joint's error with its error one frame later, both image axes pooled.

    Args:
        a, b: (N, J, 2) errors at frames k and k + 1 (NaN where not measured). Each joint's and axis's own
            mean is taken out (the vertical bias is no correlation), then all are pooled.
    """
    ok = np.isfinite(a).all(axis=-1) & np.isfinite(b).all(axis=-1)  # (N, J)
    if ok.sum() < 2:
        return None
    x_all, y_all = [], []
    for j in range(a.shape[1]):
        x, y = a[ok[:, j], j], b[ok[:, j], j]  # (n, 2)
        if len(x):
            x_all.append(x - x.mean(axis=0))
            y_all.append(y - y.mean(axis=0))
    x, y = np.concatenate(x_all), np.concatenate(y_all)
    denominator = np.sqrt((x * x).sum() * (y * y).sum())
    return float((x * y).sum() / denominator) if denominator > 0 else None


def _frame_interval_s(records: list[_FrameRecord]) -> float | None:
    """The median interval between consecutive captures of a camera, over the rig."""
    by_camera = defaultdict(list)
    for r in records:
        by_camera[r.camera].append(r.capture_s)
    gaps = np.concatenate([np.diff(np.sort(t)) for t in by_camera.values()]) if by_camera else np.zeros(0)
    gaps = gaps[gaps > 0]
    return float(np.median(gaps)) if gaps.size else None


def _cross_view(records: list[_FrameRecord], cameras: list[Camera]) -> dict:
    """Per joint, the reprojection distances (px at 400) and 3D errors (m) of the joints of a person
    triangulated from the frames of several cameras at one instant (see the module docstring).

    Returns:
        {"reprojection": list of 12 arrays, "error": list of 12 arrays, "count": joints triangulated}.
    """
    reprojection = [[] for _ in range(12)]
    error = [[] for _ in range(12)]
    interval = _frame_interval_s(records)
    ordered = sorted(records, key=lambda r: r.capture_s)
    P = np.array([c.P for c in cameras])
    i = 0
    while interval is not None and i < len(ordered):
        start, group = ordered[i].capture_s, {}
        while i < len(ordered) and ordered[i].capture_s - start < CROSS_VIEW_WINDOW_FRAC * interval:
            group.setdefault(ordered[i].camera, ordered[i])
            i += 1
        if len(group) < CROSS_VIEW_MIN_VIEWS:
            continue
        people = defaultdict(list)
        for r in group.values():
            for pid, view in r.views.items():
                people[pid].append((r.camera, view))
        for seen in people.values():
            if len(seen) < CROSS_VIEW_MIN_VIEWS:
                continue
            cams = [c for c, _ in seen]
            points = np.stack([undistort_points(cameras[c], v.detection_px) for c, v in seen], axis=1)  # (12, V, 2)
            # The standard DLT (eq. 8-9) on undistorted pixels, rows divided as distances in metres (PLANE_ROW).
            X = triangulate(P[cams], points, min_views=CROSS_VIEW_MIN_VIEWS, row_norm=PLANE_ROW)  # (12, 3)
            scale = SIZE_AT_PX / np.array([v.size_px for _, v in seen])
            distances = reprojection_error_px(P[cams], X, points) * scale  # (12, V)
            truth = np.mean([v.truth_m for _, v in seen], axis=0)  # (12, 3): the instant's mean over the views
            off = np.linalg.norm(X - truth, axis=-1)
            for j in range(12):
                if np.isfinite(off[j]):
                    error[j].append(off[j])
                    d = distances[j]
                    reprojection[j].extend(d[np.isfinite(d)].tolist())
    return {"reprojection": [np.array(r) for r in reprojection], "error": [np.array(e) for e in error],
            "count": sum(len(e) for e in error)}


def _median(per_joint: list[np.ndarray], joints) -> float | None:
    values = np.concatenate([per_joint[j] for j in joints])
    return float(np.median(values)) if values.size else None


def _quantile(values: np.ndarray, q: float) -> float | None:
    return float(np.percentile(values, q)) if values.size else None


def _ratio(a: float, b: float) -> float | None:
    return float(a / b) if b else None


def detector_stats(camera_frames: Iterable[CameraFrame], cameras: Sequence[Camera] | Mapping[str, Camera],
                   skeleton: Skeleton, geometry: MissGeometry | None = None) -> dict:
    """Measures detections against their projected 3D truth (see the module docstring).

    Args:
        camera_frames: the frames, each with `poses_at_capture`.
        cameras: the rig.
        skeleton: the joint layout of the frames and the truth.
        geometry: the rig's detector limits and shelves, to say why person-views were missed (None: not said).

    Returns:
        The figures: the keys of `SHELF_OPENPOSE` at the top level (all joints) and, the same per joint
        name ("per_joint"), per group ("per_group"), a few per camera ("per_camera"), and the counts
        behind them.
    """
    acc = DetectorStatsAccumulator(cameras, skeleton, geometry)
    for cf in camera_frames:
        acc.add(cf)
    return acc.result()


def recording_detector_stats(path, progress: bool = False) -> dict:
    """`detector_stats` of a recording file, refused when it cannot be measured; `progress` shows a bar of the
    frames measured.

    Raises:
        RecordingError: the file is not a readable recording.
        CrossviewError: it holds no 3D truth at its frames' times, or fewer than `MIN_MATCHED_DETECTIONS`
            detections match a true person; the message names the file.
    """
    from tqdm import tqdm

    from crossview import recording

    rec = recording.open_recording(path)
    geometry = None
    if rec.header.scenario_text:  # (a converted dataset holds no scenario, so no detector profile)
        from sim import scenario as scenario_mod

        try:
            geometry = MissGeometry.of(scenario_mod.from_source_text(rec.header.scenario_text,
                                                                     rec.header.scenario_name, str(path)))
        except CrossviewError:  # (a profile file it names, moved since: the misses are measured, not split)
            geometry = None
    frames = tqdm(rec.frames(with_poses=True), unit="frame", desc="detector-stats", disable=not progress, leave=False)
    try:
        stats = detector_stats(frames, rec.cameras, rec.skeleton, geometry)
    except CrossviewError as e:
        raise CrossviewError(f"{path}: {e}") from None
    if stats["frames_measured"] == 0:
        raise CrossviewError(f"{path}: no 3D truth at the times of its {stats['frames']} camera frames; "
                             "detector-stats needs a recording with truth (`crossview generate`, or `crossview "
                             "convert` of a dataset folder with annotation_3d.json)")
    if stats["matched_detections"] < MIN_MATCHED_DETECTIONS:
        raise CrossviewError(f"{path}: only {stats['matched_detections']} detections match a true person (at "
                             f"most {MATCH_GATE} of its size away on average); detector-stats needs at least "
                             f"{MIN_MATCHED_DETECTIONS}")
    stats["source"] = Path(path).name  # (the label of its column where the file is a --reference)
    return stats


def _fmt(value, kind: str) -> str:
    """A figure or a reference (a number or a (low, high) range) for the table."""
    if value is None:
        return "-"
    if isinstance(value, tuple):
        return " to ".join(_fmt(v, kind) for v in value)
    if kind == "%":
        return f"{100 * value:.2f} %"
    if kind == "signed px":
        return f"{value:+.1f}"
    if kind == "px":
        return f"{value:.1f}"
    if kind == "cm":
        return f"{100 * value:.1f}"
    return f"{value:.3f}"


def _people(spread: dict) -> str:
    """The per-person spread for the table: the share and how many people it is of."""
    share = spread.get("bad_limb_person_share")
    return "-" if share is None else f"{100 * share:.0f} % of {spread['people_measured']}"


def _table_rows(stats: dict, ref: Reference) -> tuple[str, list[tuple[str, str | None, str | None]],
                                                        list[tuple[str, ...]]]:
    """The table's parts: the lines above it (what was measured, what it is beside), its rows (statistic, measured,
    reference; a heading row has None for both), and one row per camera (name, frames, matched, error/size, joint
    miss, missed views, FP / frame)."""
    reference = ref.stats
    groups, ref_groups = stats["per_group"], reference.get("per_group", {})
    rows = [("joint error / person size: median", stats, reference, "error_over_size_median", ""),
            ("  p90", stats, reference, "error_over_size_p90", ""),
            ("  p99", stats, reference, "error_over_size_p99", "")]
    per_group = [
        ("error / size median", "error_over_size_median", ""),
        ("vertical offset px at 400 (+ below truth)", "vertical_offset_px_at_400", "signed px"),
        ("lag-1 correlation of a joint's error", "lag1_error_correlation", ""),
        ("joint miss rate", "miss_rate", "%"),
    ]
    for label, key, kind in per_group:
        if key in ("lag1_error_correlation", "miss_rate"):
            rows.append((f"{label}: all", stats, reference, key, kind))
        else:
            rows.append((f"{label}:", None, None, key, kind))
        rows.extend((f"  {g}", groups[g], ref_groups.get(g, {}), key, kind) for g in GROUPS)
    rows += [
        ("gross errors (> 0.2 x size)", stats, reference, "gross_error_rate", "%"),
        ("P(joint missed next frame | missed now)", stats, reference, "miss_persistence", ""),
        ("missed person-views", stats, reference, "missed_person_view_rate", "%"),
        *((f"  {label}", stats.get("missed_person_views_by_cause") or {},
           reference.get("missed_person_views_by_cause") or {}, cause, "%")
          for cause, label in zip(MISS_CAUSES, MISS_CAUSE_LABELS) if stats.get("missed_person_views_by_cause")),
        ("false-positive people per camera frame", stats, reference, "false_positive_people_per_frame", ""),
        (f"  with >= {PERSON_LIKE_JOINTS} of 12 joints", stats, reference, "false_positive_people_ge6_per_frame", ""),
        (f"cross-view reprojection px at 400 (>= {CROSS_VIEW_MIN_VIEWS} views): all", stats, reference,
         "cross_view_reprojection_px_at_400", "px"),
        *((f"  {g}", groups[g], ref_groups.get(g, {}), "cross_view_reprojection_px_at_400", "px") for g in GROUPS),
        ("cross-view 3D distance to the true joint, cm: all", stats, reference, "cross_view_error_m", "cm"),
        *((f"  {g}", groups[g], ref_groups.get(g, {}), "cross_view_error_m", "cm") for g in GROUPS),
    ]
    size = stats["person_size_px_median"]
    intro = (f"{stats['frames_measured']} of {stats['frames']} camera frames measured (truth at their capture "
             f"time), {stats['matched_detections']} matched detections, {stats['person_views']} person-views, "
             f"person size median {'-' if size is None else f'{size:.0f}'} px, "
             f"{stats['cross_view_joints']} joints triangulated across views\n"
             f"beside: {ref.where}")
    cells = [(label, None, None) if measured is None
             else (label, _fmt(measured.get(key), kind), _fmt(ref.get(key), kind))
             for label, measured, ref, key, kind in rows]
    spread, ref_spread = stats.get("per_person") or {}, reference.get("per_person") or {}
    cells.append((f"people with a limb error > {BAD_LIMB_FACTOR:g} x the median (of people measured)",
                  _people(spread), _people(ref_spread)))
    cameras = [(name, str(c["frames_measured"]), str(c["matched_detections"]), _fmt(c["error_over_size_median"], ""),
                _fmt(c["miss_rate"], "%"), _fmt(c["missed_person_view_rate"], "%"), _geometry_share(c),
                _fmt(c["false_positive_people_per_frame"], "")) for name, c in stats["per_camera"].items()]
    return intro, cells, cameras


_CAMERA_HEADER = ("camera", "frames", "matched", "error/size", "joint miss", "missed views", "by geometry",
                  "FP / frame")


def _geometry_share(figures: dict) -> str:
    """The missed person-views the rig's geometry explains (too small, cut, behind shelves), or - (not split)."""
    causes = figures.get("missed_person_views_by_cause")
    if not causes or any(causes[c] is None for c in MISS_CAUSES[:-1]):
        return "-"
    return _fmt(sum(causes[c] for c in MISS_CAUSES[:-1]), "%")


def format_detector_stats(stats: dict, ref: Reference | None = None) -> str:
    """The statistics table: the measured figures beside `ref` (by default real OpenPose on Shelf), whose column
    is headed by its label."""
    ref = ref or reference()
    intro, cells, cameras = _table_rows(stats, ref)
    lines = [intro, f"{'statistic':<56}{'measured':>12}{ref.label[:22]:>24}"]
    for label, measured, ref in cells:
        lines.append(label if measured is None else f"{label:<56}{measured:>12}{ref:>24}")
    if cameras:
        widths = (16, 8, 9, 12, 12, 14, 13, 12)
        lines += ["", "".join(h.ljust(w) if i == 0 else h.rjust(w) for i, (h, w) in enumerate(zip(_CAMERA_HEADER,
                                                                                                   widths)))]
        lines += ["".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(row, widths)))
                  for row in cameras]
    return "\n".join(lines)


def detector_stats_blocks(stats: dict, ref: Reference | None = None) -> list:
    """The same table for `crossview.tables` (`--format markdown`): the lines above it, the statistics beside the
    reference, the cameras."""
    from crossview.tables import Table

    ref = ref or reference()
    intro, cells, cameras = _table_rows(stats, ref)
    blocks = [*intro.splitlines(), Table(("statistic", "measured", ref.label),
                           tuple((label.strip(), m or "", r or "") for label, m, r in cells))]
    if cameras:
        blocks.append(Table(_CAMERA_HEADER, tuple(cameras)))
    return blocks
