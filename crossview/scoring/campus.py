"""The published Campus/Shelf PCP protocol on the crossview dataset layout.

The layout is the one released with Chen et al. (CVPR 2020, longcw/crossview_3d_pose_tracking):
`annotation_3d.json` is a list of `{"timestamp", "poses": [{"id", "points_3d": 14 x 3 cm}]}` whose index
is the frame number; a result file has the same shape with COCO-17 `points_3d` in centimetres, zeros
for a missing joint. `evaluate` reproduces that repository's `evaluate.py`: test frames 350-470 and
650-750 for Campus, 300-599 for Shelf (actor 3 left out, following MVPose); for each test frame the
result entry nearest in time within 0.1 s; each true person compared with the nearest result pose
(Frobenius distance in the 14-joint layout); ten bones checked with alpha 0.5; PCP per actor and
per bone group, averaged over actors. Zeros in a result are kept as zeros, as the published script does
(a joint at the origin fails its bones anyway), so that the published figures are reproduced exactly.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from core.errors import CrossviewError
from core.layouts import coco17_to_campus14
from crossview.formats.datasets import UINT64_END, person_id
from crossview.formats.json_input import DatasetError, read_json, stamp_s
from crossview.scoring.pose import PCP_ALPHA, PCP_BONE_GROUPS, match_nearest, pcp_bones

CAMPUS_TEST_FRAMES = tuple(range(350, 471)) + tuple(range(650, 751))
SHELF_TEST_FRAMES = tuple(range(300, 600))
SHELF_EXCLUDED_ACTORS = (3,)
RESULT_TIME_TOLERANCE_S = 0.1
"""Largest time difference between a test frame and the result entry used for it (evaluate.py)."""
METRES_TO_CM = 100.0


class DatasetLayoutError(DatasetError):
    """A dataset directory or result file does not follow the crossview dataset layout."""


def _pose_list(data, path: Path, joints: int) -> tuple[np.ndarray, list[list[tuple[int, np.ndarray]]]]:
    """Parses a `[{"timestamp", "poses": [{"id", "points_3d"}]}]` file, sorted by timestamp."""
    if not isinstance(data, list):
        raise DatasetLayoutError(f"{path}: expected a JSON list of {{timestamp, poses}} entries")
    stamps, entries = [], []
    for i, item in enumerate(data):
        try:
            stamps.append(stamp_s(item["timestamp"], path, f"entry {i}"))
            poses = []
            for p in item["poses"]:
                pts = np.asarray(p["points_3d"], dtype=np.float64)
                if pts.shape != (joints, 3):
                    raise DatasetLayoutError(
                        f"{path}: entry {i} id {p.get('id')}: points_3d has shape {pts.shape}, expected ({joints}, 3)"
                    )
                # A joint is three finite numbers, or [null, null, null]: missing (what `crossview export`
                # writes for a joint the tracker does not know; it never counts as a correct part).
                missing = np.isnan(pts)
                if np.isinf(pts).any() or not np.array_equal(missing.all(axis=1), missing.any(axis=1)):
                    raise DatasetLayoutError(f"{path}: entry {i} id {p.get('id')}: points_3d hold a joint that is "
                                             "neither three finite numbers nor [null, null, null] (missing)")
                poses.append((person_id(p["id"], path, f"entry {i}", UINT64_END), pts))
            entries.append(poses)
        except (KeyError, TypeError, ValueError) as e:
            if isinstance(e, CrossviewError):
                raise
            raise DatasetLayoutError(
                f"{path}: entry {i} lacks {e} (expected timestamp and poses[id, points_3d])"
            ) from e
    return np.asarray(stamps), entries


def _nearest_entry(stamps: np.ndarray, t: float, tolerance_s: float) -> int:
    """Index of the entry nearest in time to t (earlier one on a tie), -1 beyond the tolerance."""
    if len(stamps) == 0:
        return -1
    idx = int(np.searchsorted(stamps, t))
    if idx >= len(stamps) or (idx > 0 and abs(stamps[idx - 1] - t) < abs(stamps[idx] - t)):
        idx -= 1
    return idx if abs(stamps[idx] - t) <= tolerance_s else -1


def evaluate(
    dataset_dir: str | Path,
    result_json: str | Path,
    *,
    test_frames: Sequence[int] | None = None,
    alpha: float = PCP_ALPHA,
) -> dict:
    """Scores a COCO-17 result file on a Campus or Shelf dataset with the published PCP protocol.

    Args:
        dataset_dir: directory holding `annotation_3d.json`; its name says Campus or Shelf unless
            `test_frames` is given.
        result_json: result file in the dataset layout (COCO-17 `points_3d`, centimetres).
        test_frames: frame indices to evaluate; default by dataset name.
        alpha: PCP threshold.

    Returns:
        {"dataset", "num_frames", "actors": {id: pcp}, "average": float,
         "groups": {group: {"actors": {id: pcp}, "average": float}}}.

    Raises:
        DatasetLayoutError: missing or malformed files, or a dataset whose test frames are unknown.
    """
    dataset_dir, result_json = Path(dataset_dir), Path(result_json)
    name = dataset_dir.resolve().name.lower()
    excluded: tuple[int, ...] = ()
    if test_frames is None:
        if "campus" in name:
            test_frames = CAMPUS_TEST_FRAMES
        elif "shelf" in name:
            test_frames, excluded = SHELF_TEST_FRAMES, SHELF_EXCLUDED_ACTORS
        else:
            raise DatasetLayoutError(
                f"{dataset_dir}: cannot tell Campus from Shelf by the folder's name; name the folder after its "
                "dataset (one whose name holds 'campus' or 'shelf') to use that dataset's test frames"
            )
    anno_path = dataset_dir / "annotation_3d.json"
    anno_stamps, anno = _pose_list(read_json(anno_path, "annotation_3d.json"), anno_path, 14)
    # evaluate.py sorts the annotation by timestamp and indexes it by frame number.
    order = np.argsort(anno_stamps, kind="stable")
    anno_stamps, anno = anno_stamps[order], [anno[i] for i in order]
    res_stamps, res = _pose_list(read_json(result_json, "result file"), result_json, 17)
    order = np.argsort(res_stamps, kind="stable")
    res_stamps, res = res_stamps[order], [res[i] for i in order]

    checks: dict[int, list[np.ndarray]] = {}
    for fid in test_frames:
        if not 0 <= fid < len(anno):
            raise DatasetLayoutError(f"{anno_path}: test frame {fid} outside 0..{len(anno) - 1}")
        truth = anno[fid]
        if not truth:
            continue
        gt = np.stack([p for _, p in truth])
        k = _nearest_entry(res_stamps, anno_stamps[fid], RESULT_TIME_TOLERANCE_S)
        est = coco17_to_campus14(np.stack([p for _, p in res[k]])) if k >= 0 and res[k] else np.zeros((0, 14, 3))
        idx = match_nearest(gt, est)
        for g, (pid, _) in enumerate(truth):
            ok = pcp_bones(est[idx[g]], gt[g], alpha) if idx[g] >= 0 else np.zeros(10, dtype=bool)
            checks.setdefault(pid, []).append(ok)
    for pid in excluded:
        checks.pop(pid, None)
    rows = {pid: np.asarray(v) for pid, v in sorted(checks.items())}
    actors = {pid: float(r.mean()) for pid, r in rows.items()}
    groups = {}
    for group, bones in PCP_BONE_GROUPS.items():
        per = {pid: float(r[:, bones].mean()) for pid, r in rows.items()}
        groups[group] = {"actors": per, "average": float(np.mean(list(per.values()))) if per else math.nan}
    return {
        "dataset": dataset_dir.name,
        "num_frames": len(test_frames),
        "actors": actors,
        "average": float(np.mean(list(actors.values()))) if actors else math.nan,
        "groups": groups,
    }


def evaluation_blocks(result: dict) -> list:
    """The evaluation as a title and a table (`crossview.tables`): bone groups by actor, as evaluate.py prints it."""
    from crossview.tables import Table

    actors = list(result["actors"])
    header = ("Bone group", *(f"Actor {a}" for a in actors), "Average")
    lines = [(g.replace("_", " ").capitalize(), *(f"{v['actors'][a]:.4f}" for a in actors), f"{v['average']:.4f}")
             for g, v in result["groups"].items()]
    lines.append(("Total", *(f"{result['actors'][a]:.4f}" for a in actors), f"{result['average']:.4f}"))
    return [f"PCP on {result['dataset']} ({result['num_frames']} test frames, alpha {PCP_ALPHA})",
            Table(header, tuple(lines))]


def format_evaluation(result: dict) -> str:
    """The evaluation as a text table (`evaluation_blocks`)."""
    title, table = evaluation_blocks(result)
    return f"{title}\n{table.text()}"
