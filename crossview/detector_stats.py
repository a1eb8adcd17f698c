"""Detector statistics measured from camera frames and their truth, beside OpenPose's on Shelf.

The figures mirror how a real detector was measured (OpenPose BODY25 on the Shelf dataset, against its
projected 3D truth, 301 frames of 5 cameras): per-joint error
normalised by the person's size in the image on limb joints, gross errors above 0.2 of that size,
person-views (at least half of the joints inside the image) with no detection, and fragments
(fewer than 6 of the 15 BODY25 body joints) among detections of person-views at least half inside the
image (Shelf's people are in full view; `fragment_rate_all` counts every detection, people cut by the
image border included).
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable, Mapping, Sequence

import numpy as np

from core.types import COCO17, Camera
from sim.cameras import in_image
from sim.sensing.draws import person_size_px
from sim.types import CameraFrame, DetectionEffect

# OpenPose (BODY25) on the Shelf dataset (Belagiannis et al., CVPR 2014), 5 cameras, 301 frames, limb joints.
SHELF_OPENPOSE = {
    "error_median": 0.02,
    "error_p95": 0.06,
    "error_p99": 0.11,
    "miss_rate": 0.04,
    "gross_error_rate": 0.003,
    "fragment_rate": 0.07,
}
# Limb joints of COCO-17 (hips and neck are defined differently in Shelf, so the reference skips them).
LIMB_JOINTS = tuple(COCO17.index(n) for n in (
    "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
    "left_knee", "right_knee", "left_ankle", "right_ankle",
))
GROSS_ERROR_FRAC = 0.2
FRAGMENT_MAX_JOINTS = 6  # a fragment has fewer than this many of the 15 BODY25 body joints
HALF_IN_IMAGE = 0.5
_NOSE = COCO17.index("nose")
_SHOULDERS = (COCO17.index("left_shoulder"), COCO17.index("right_shoulder"))
_HIPS = (COCO17.index("left_hip"), COCO17.index("right_hip"))
_BODY = tuple(range(5, 17))


def body25_joint_count(detected: np.ndarray) -> np.ndarray:
    """(D,) how many of BODY25's 15 body joints a COCO-17 detection holds.

    Neck and mid-hip, which COCO-17 lacks, count when either shoulder or either hip is there.

    Args:
        detected: (D, 17) bool, the joint was reported.
    """
    return (
        detected[:, _NOSE].astype(int)
        + detected[:, _BODY].sum(axis=1)
        + detected[:, _SHOULDERS].any(axis=1)
        + detected[:, _HIPS].any(axis=1)
    )


def detector_stats(camera_frames: Iterable[CameraFrame],
                   cameras: Sequence[Camera] | Mapping[str, Camera] | None = None) -> dict:
    """Measures the detector's figures from delivered frames and their truth.

    Args:
        camera_frames: the frames (any order).
        cameras: the rig; needed for the miss rate (which people were in view), else it is None.

    Returns:
        A flat dict of fractions and counts (missing figures are None), plus "per_camera": a dict
        camera name -> {"occluded_share", "self_occluded_share", "detections", "miss_rate"}.
    """
    if cameras is not None and not isinstance(cameras, Mapping):
        cameras = {c.name: c for c in cameras}
    errors, joint_errors = [], defaultdict(list)
    counts = defaultdict(int)
    per_camera = defaultdict(lambda: defaultdict(int))
    for cf in camera_frames:
        frame, truth = cf.frame, cf.truth
        cam = per_camera[frame.camera]
        counts["frames"] += 1
        effects = np.asarray(truth.effects, dtype=np.int64)
        ids = np.asarray(truth.person_ids)
        detected = ~np.isnan(frame.keypoints_px[..., 0])
        phantom = ids < 0
        duplicate = (effects & DetectionEffect.DUPLICATE) != 0
        real = ~phantom & ~duplicate
        counts["detections"] += len(ids)
        counts["phantoms"] += int(phantom.sum())
        counts["duplicates"] += int(duplicate.sum())
        counts["real"] += int(real.sum())
        counts["swaps"] += int(((effects & DetectionEffect.LEFT_RIGHT_SWAP) != 0)[real].sum())
        cam["detections"] += len(ids)
        if real.any():
            fragment = body25_joint_count(detected[real]) < FRAGMENT_MAX_JOINTS
            in_view = truth.in_image[real].mean(axis=1) >= HALF_IN_IMAGE
            counts["fragments_all"] += int(fragment.sum())
            counts["fragments"] += int((fragment & in_view).sum())
            counts["real_in_view"] += int(in_view.sum())
            in_img = truth.in_image[real]
            for name, flags in (("occluded", truth.occluded[real]), ("self_occluded", truth.self_occluded[real])):
                counts[name] += int((flags & in_img).sum())
                cam[name] += int((flags & in_img).sum())
            counts["in_image"] += int(in_img.sum())
            cam["in_image"] += int(in_img.sum())
            true_px = truth.keypoints_px[real]
            size = person_size_px(true_px)
            err = np.linalg.norm(frame.keypoints_px[real] - true_px, axis=-1) / size[:, None]
            limb = err[:, LIMB_JOINTS]
            errors.append(limb[np.isfinite(limb)])
            for j in LIMB_JOINTS:
                e = err[:, j]
                joint_errors[COCO17.joints[j]].append(e[np.isfinite(e)])
        if cameras is not None and frame.camera in cameras:
            poses = cf.poses_at_capture
            if len(poses.person_ids):
                _, inside = in_image(cameras[frame.camera], poses.poses)
                in_view = inside.mean(axis=1) >= HALF_IN_IMAGE
                seen = set(ids[real].tolist())
                missed = sum(1 for pid in np.asarray(poses.person_ids)[in_view] if int(pid) not in seen)
                counts["person_views"] += int(in_view.sum())
                counts["missed"] += missed
                cam["person_views"] += int(in_view.sum())
                cam["missed"] += missed
    errors = np.concatenate(errors) if errors else np.zeros(0)

    def ratio(a, b):
        return a / b if b else None

    def pct(q):
        return float(np.percentile(errors, q)) if errors.size else None

    stats = {
        "frames": counts["frames"],
        "detections": counts["detections"],
        "limb_joints_measured": int(errors.size),
        "error_median": pct(50),
        "error_p95": pct(95),
        "error_p99": pct(99),
        "gross_error_rate": float(np.mean(errors > GROSS_ERROR_FRAC)) if errors.size else None,
        "miss_rate": ratio(counts["missed"], counts["person_views"]) if cameras is not None else None,
        "person_views": counts["person_views"] if cameras is not None else None,
        "fragment_rate": ratio(counts["fragments"], counts["real_in_view"]),
        "fragment_rate_all": ratio(counts["fragments_all"], counts["real"]),
        "false_positive_rate": ratio(counts["phantoms"] + counts["duplicates"], counts["detections"]),
        "phantom_rate": ratio(counts["phantoms"], counts["detections"]),
        "duplicate_rate": ratio(counts["duplicates"], counts["detections"]),
        "phantoms_per_frame": ratio(counts["phantoms"], counts["frames"]),
        "swap_rate": ratio(counts["swaps"], counts["real"]),
        "occluded_share": ratio(counts["occluded"], counts["in_image"]),
        "self_occluded_share": ratio(counts["self_occluded"], counts["in_image"]),
        "joint_error_median": {
            name: float(np.median(np.concatenate(v))) if sum(len(x) for x in v) else None
            for name, v in joint_errors.items()
        },
        "per_camera": {
            name: {
                "detections": c["detections"],
                "occluded_share": ratio(c["occluded"], c["in_image"]),
                "self_occluded_share": ratio(c["self_occluded"], c["in_image"]),
                "miss_rate": ratio(c["missed"], c["person_views"]) if cameras is not None else None,
            }
            for name, c in sorted(per_camera.items())
        },
    }
    return stats


def format_detector_stats(stats: dict) -> str:
    """A plain-text table of `detector_stats` output beside the Shelf/OpenPose reference."""

    def fmt(value, percent=False):
        if value is None:
            return "-"
        return f"{100 * value:.2f} %" if percent else f"{value:.4f}"

    rows = [
        ("normalised error, median", "error_median", False),
        ("normalised error, p95", "error_p95", False),
        ("normalised error, p99", "error_p99", False),
        ("gross errors (> 0.2)", "gross_error_rate", True),
        ("missed person-views", "miss_rate", True),
        ("fragments (< 6 of 15 joints)", "fragment_rate", True),
        ("  of all detections", "fragment_rate_all", True),
        ("false positives", "false_positive_rate", True),
        ("  duplicates", "duplicate_rate", True),
        ("  phantoms", "phantom_rate", True),
        ("left/right swaps", "swap_rate", True),
        ("occluded joints", "occluded_share", True),
        ("self-occluded joints", "self_occluded_share", True),
    ]
    lines = [f"{stats['frames']} frames, {stats['detections']} detections, "
             f"{stats['limb_joints_measured']} limb joints measured",
             f"{'figure':<32}{'measured':>12}{'Shelf OpenPose':>16}"]
    for label, key, percent in rows:
        ref = SHELF_OPENPOSE.get(key)
        lines.append(f"{label:<32}{fmt(stats.get(key), percent):>12}{fmt(ref, percent):>16}")
    if stats["per_camera"]:
        lines.append("")
        lines.append(f"{'camera':<16}{'detections':>12}{'occluded':>12}{'self-occl.':>12}{'missed':>12}")
        for name, c in stats["per_camera"].items():
            lines.append(f"{name:<16}{c['detections']:>12}{fmt(c['occluded_share'], True):>12}"
                         f"{fmt(c['self_occluded_share'], True):>12}{fmt(c['miss_rate'], True):>12}")
    return "\n".join(lines)
