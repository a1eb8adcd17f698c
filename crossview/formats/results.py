"""Tracker results from files made outside this project: the dataset layout's result_3d.json and JSON lines.

Both become the `TrackerOutput`s that `crossview.scoring.score` takes (docs/recording-format.md, "Result
files"). Every entry is checked against the recording it is scored with: an id that is not an integer, a stamp
outside the recording's span, a pose with another joint count, a joint that is not three finite numbers or
missing: one line naming the file and the entry.
"""

from __future__ import annotations

import json
import math
import numbers
from pathlib import Path

import numpy as np

from core.errors import CrossviewError
from core.types import CAMPUS14, COCO17, Skeleton
from crossview.formats.json_input import parse_json, read_text
from tracker.types import Target, TrackerOutput

CM_TO_M = 0.01
MCAP_MAGIC = b"\x89MCAP"


class ResultError(CrossviewError):
    """A result file that cannot be scored; the message names the file and the entry."""


def is_result_file(path) -> bool:
    """Whether `path` is a result file of this module (JSON), not an MCAP tracks file."""
    with open(path, "rb") as f:
        return f.read(len(MCAP_MAGIC)) != MCAP_MAGIC


def read_results(path, skeleton: Skeleton, span_s: tuple[float, float]) -> list[TrackerOutput]:
    """The outputs of a result file, one per stamp in file order, targets checked.

    A file whose first character is `[` is the dataset layout's result_3d.json (COCO-17 in cm; [null, null,
    null] or 0, 0, 0 for a missing joint; mapped to the 14 Campus joints for a CAMPUS14 recording); one whose
    first character is `{` is JSON lines, one target per line (`stamp_s`, `id`, `joints` in metres, null for a
    missing joint), or a line with only `stamp_s` for an output with no target.

    Args:
        path: the result file.
        skeleton: the recording's joint layout (J joints).
        span_s: (first, last) time the recording covers, seconds; stamps may lie up to `OUTPUT_MAX_AGE_S`
            outside it.

    Raises:
        ResultError: naming the file and the entry at fault.
    """
    path = Path(path)
    text = read_text(path, ResultError)
    first = text.lstrip()[:1]
    if first == "[":
        entries = _result_3d_entries(path, text)
    elif first == "{":
        entries = _json_lines_entries(path, text)
    else:
        raise ResultError(f"{path}: neither a tracks file (.mcap), result_3d.json (a JSON list) nor JSON lines "
                          "(one JSON object per line)")
    from crossview.scoring import OUTPUT_MAX_AGE_S

    lo, hi = span_s[0] - OUTPUT_MAX_AGE_S, span_s[1] + OUTPUT_MAX_AGE_S
    by_stamp: dict[float, list[Target]] = {}
    ids_at: dict[float, set[int]] = {}
    for where, stamp, target_id, joints in entries:
        if isinstance(stamp, bool) or not isinstance(stamp, numbers.Real) or not math.isfinite(stamp):
            raise ResultError(f"{path}: {where}: stamp {stamp!r} is not a finite number of seconds")
        if not lo <= stamp <= hi:
            raise ResultError(f"{path}: {where}: stamp {stamp} s is outside the recording ({span_s[0]:.3f} to "
                              f"{span_s[1]:.3f} s, give or take {OUTPUT_MAX_AGE_S} s)")
        targets = by_stamp.setdefault(float(stamp), [])
        if target_id is None and joints is None:
            continue  # an output with no target
        if isinstance(target_id, bool) or not isinstance(target_id, numbers.Integral):
            raise ResultError(f"{path}: {where}: id {target_id!r} of type {type(target_id).__name__}; ids must be "
                              "integers")
        if int(target_id) in ids_at.setdefault(float(stamp), set()):
            raise ResultError(f"{path}: {where}: id {target_id} appears twice at stamp {stamp} s")
        ids_at[float(stamp)].add(int(target_id))
        targets.append(Target(id=int(target_id), pose=joints(skeleton, where), stamp_s=float(stamp)))
    if not by_stamp:
        raise ResultError(f"{path}: holds no output")
    return [TrackerOutput(stamp_s=stamp, camera="", targets=targets, detection_target_ids=np.zeros(0, dtype=np.int64))
            for stamp, targets in by_stamp.items()]


def _result_3d_entries(path: Path, text: str):
    """(where, stamp, id, joints) of result_3d.json; `joints(skeleton, where)` gives the (J, 3) pose, metres."""
    data = parse_json(text, path, "", ResultError)
    for i, entry in enumerate(data):
        where = f"entry {i}"
        if not isinstance(entry, dict) or "timestamp" not in entry or not isinstance(entry.get("poses"), list):
            raise ResultError(f"{path}: {where}: expected {{\"timestamp\": seconds, \"poses\": [...]}}")
        if not entry["poses"]:
            yield where, entry["timestamp"], None, None
        for k, pose in enumerate(entry["poses"]):
            if not isinstance(pose, dict) or "points_3d" not in pose:
                raise ResultError(f"{path}: {where} pose {k}: expected {{\"id\": int, \"points_3d\": 17x3 cm}}")
            yield f"{where} pose {k}", entry["timestamp"], pose.get("id"), _result_3d_pose(path, pose["points_3d"])


def _result_3d_pose(path: Path, points):
    def joints(skeleton: Skeleton, where: str) -> np.ndarray:
        cm = _array(path, where, points, (COCO17.num_joints, skeleton.num_joints))
        pose = np.where((cm == 0).all(axis=-1, keepdims=True), np.nan, cm * CM_TO_M)  # 0, 0, 0: missing
        if skeleton.num_joints == CAMPUS14.num_joints and len(pose) == COCO17.num_joints:
            from core.layouts import coco17_to_campus14

            pose = coco17_to_campus14(pose)
        elif len(pose) != skeleton.num_joints:
            raise ResultError(f"{path}: {where}: {len(pose)} joints, the recording's {skeleton.name} has "
                              f"{skeleton.num_joints}")
        return pose
    return joints


def _json_lines_entries(path: Path, text: str):
    for n, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        where = f"line {n}"
        item = parse_json(line, path, f"{where}: ", ResultError)
        if not isinstance(item, dict) or "stamp_s" not in item:
            raise ResultError(f"{path}: {where}: expected {{\"stamp_s\": seconds, \"id\": int, \"joints\": Jx3 m}}")
        if "id" not in item and "joints" not in item:
            yield where, item["stamp_s"], None, None
            continue
        if "joints" not in item:
            raise ResultError(f"{path}: {where}: key 'joints' missing (J x 3 metres, null for a missing joint)")
        yield where, item["stamp_s"], item.get("id"), _json_lines_pose(path, item["joints"])


def _json_lines_pose(path: Path, joints_m):
    def joints(skeleton: Skeleton, where: str) -> np.ndarray:
        if isinstance(joints_m, list):
            filled = [[math.nan] * 3 if j is None else j for j in joints_m]
        else:
            filled = joints_m
        pose = _array(path, where, filled, (skeleton.num_joints,))
        if len(pose) != skeleton.num_joints:
            raise ResultError(f"{path}: {where}: {len(pose)} joints, the recording's {skeleton.name} has "
                              f"{skeleton.num_joints}")
        return pose
    return joints


def _array(path: Path, where: str, value, joint_counts: tuple[int, ...]) -> np.ndarray:
    """(J, 3) float array of `value`; J is checked by the caller. NaN allowed only as a whole missing joint."""
    try:
        pose = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ResultError(f"{path}: {where}: joints are not a list of [x, y, z] numbers") from None
    if pose.ndim != 2 or pose.shape[1] != 3:
        counts = " or ".join(str(j) for j in sorted(set(joint_counts)))
        raise ResultError(f"{path}: {where}: joints have shape {pose.shape}, expected ({counts}, 3)")
    if np.isinf(pose).any() or (np.isnan(pose).any(axis=1) & ~np.isnan(pose).all(axis=1)).any():
        raise ResultError(f"{path}: {where}: a joint is infinite or NaN in some coordinates only")
    return pose


def json_lines(outputs) -> str:
    """Tracker outputs as JSON lines text (one target per line; a line with only the stamp for an output with no
    target). Joints in metres, null for a missing joint."""
    lines = []
    for output in outputs:
        if not output.targets:
            lines.append(json.dumps({"stamp_s": float(output.stamp_s)}))
        for target in output.targets:
            joints = [None if not np.isfinite(j).all() else [float(v) for v in j] for j in np.asarray(target.pose)]
            lines.append(json.dumps({"stamp_s": float(output.stamp_s), "id": int(target.id), "joints": joints}))
    return "".join(line + "\n" for line in lines)
