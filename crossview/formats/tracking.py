"""Exports in the standard tracking formats: MOTChallenge's ground-plane layout for TrackEval, and COCO keypoints
per camera (see docs/exports.md).

MOT: the instants `crossview score` compares (`crossview.scoring.scored_grid`: its 10 Hz grid, the truth at the
instant of the tracker output it takes, the people and targets of the scored area), one body root per person or
target, so that an evaluator outside the project scores the same instants with the same gate.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from core.types import COCO17
from crossview.formats.motion import ExportError

MOT_BENCHMARK = "CROSSVIEW"
MOT_SPLIT = "test"


def _mot_rows(frame: int, ids: np.ndarray, roots: np.ndarray) -> list[str]:
    """MOT15-3D rows: frame, id, bb_left, bb_top, bb_width, bb_height (-1: no image box), conf 1, x, y, z (the
    body root on the floor, metres, z 0)."""
    return [f"{frame},{int(i)},-1,-1,-1,-1,1,{x:.6f},{y:.6f},0" for i, (x, y) in zip(ids, roots)]


def export_mot(rec, tracks, out_dir, scored_area=None, from_s: float = 0.0) -> str:
    """Writes a recording's truth, or a tracks file with its recording's truth, as a TrackEval MOTChallenge folder:
    `gt/mot_challenge/CROSSVIEW-test/SEQ/gt/gt.txt` with `seqinfo.ini`, `gt/mot_challenge/seqmaps/CROSSVIEW-test.txt`
    and, for tracks, `trackers/mot_challenge/CROSSVIEW-test/METHOD/data/SEQ.txt` (SEQ: scenario and seed). Frame k
    is the k-th tick of `crossview score`'s grid (1-based); a tick `score` does not score has no rows.

    Args:
        rec: the opened recording.
        tracks: the opened tracks file made from it (checked by the caller), or None for the truth alone.
        out_dir: a new folder.
        scored_area: the store's floor, as `crossview score` takes it (`core.records.watched_floor`).
        from_s: the warm-up left out, seconds after the first truth sample (`score --from`).

    Returns:
        A line saying what was written.
    """
    from crossview.formats.datasets import check_new_folder, write_folder
    from crossview.scoring import scored_grid
    from crossview.scoring.identity import body_roots

    out_dir = Path(out_dir)
    check_new_folder(out_dir)
    outputs = () if tracks is None else tracks.outputs()
    rate = 10.0
    truth = list(rec.truth())
    t0 = min((s.t_s for s in truth), default=0.0)
    grid = scored_grid(truth, outputs, eval_rate_hz=rate, scored_area=scored_area, skeleton=rec.skeleton,
                       from_s=from_s)
    gt, found, ticks = [], [], 0
    for tick, _, g_ids, g_poses, t_ids, t_poses in grid:
        frame = int(round((tick - t0) * rate)) + 1
        ticks = frame
        gt += _mot_rows(frame, g_ids, body_roots(g_poses, rec.skeleton))
        found += _mot_rows(frame, t_ids, body_roots(t_poses, rec.skeleton))
    seq = f"{rec.header.scenario_name}-s{rec.header.seed}"
    bench = f"{MOT_BENCHMARK}-{MOT_SPLIT}"
    (w, h), = {(c.width_px, c.height_px) for c in rec.cameras[:1]}
    files = {
        f"gt/mot_challenge/{bench}/{seq}/gt/gt.txt": ("\n".join(gt) + "\n" if gt else "").encode(),
        f"gt/mot_challenge/{bench}/{seq}/seqinfo.ini": (
            f"[Sequence]\nname={seq}\nimDir=img1\nframeRate={rate:g}\nseqLength={ticks}\nimWidth={w}\n"
            f"imHeight={h}\nimExt=.jpg\n").encode(),
        f"gt/mot_challenge/seqmaps/{bench}.txt": f"name\n{seq}\n".encode(),
    }
    if tracks is not None:
        files[f"trackers/mot_challenge/{bench}/{tracks.header.method}/data/{seq}.txt"] = \
            ("\n".join(found) + "\n" if found else "").encode()
    write_folder(out_dir, files)
    what = f"truth ({len(gt)} rows)" + (f" and tracks ({len(found)} rows)" if tracks is not None else "")
    return f"{out_dir}: {what} of {ticks} frames at {rate:g} Hz in TrackEval's MOTChallenge layout, sequence {seq}"


# --------------------------------------------------------------------------------------------------
# COCO keypoints

COCO_CATEGORY = {
    "id": 1, "name": "person", "supercategory": "person",
    "keypoints": list(COCO17.joints),
    "skeleton": [[a + 1, b + 1] for a, b in COCO17.bones],  # (COCO numbers keypoints from 1)
}


def _box(xy: np.ndarray) -> list[float]:
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    return [float(lo[0]), float(lo[1]), float(hi[0] - lo[0]), float(hi[1] - lo[1])]


def export_coco(path, out_dir) -> str:
    """Writes a recording as COCO keypoints per camera: `CAMERA_keypoints.json`, the annotation file (images: each
    delivered frame of the camera; annotations: everybody's true joints at the frame's capture, projected with the
    camera's model and distortion, v 2 inside the image, 0 (and 0, 0) elsewhere; bbox and area from the joints
    inside) and `CAMERA_detections.json`, the detector's output in COCO's results layout (keypoints with their
    scores, a missing joint 0, 0, 0; score: the mean of the known joints' scores). COCO-17 recordings only.

    Returns:
        A line saying what was written.
    """
    from crossview.formats.datasets import check_new_folder, write_folder
    from crossview.recording import open_recording
    from crossview.scoring.association import project_points

    out_dir = Path(out_dir)
    check_new_folder(out_dir)
    rec = open_recording(path)
    if rec.skeleton.name != COCO17.name:
        raise ExportError(f"{path}: {rec.skeleton.name} joints; --format coco needs COCO-17 joints (the layout COCO's "
                          "keypoint scoring is defined for)")
    cameras = {c.name: c for c in rec.cameras}
    docs = {name: {"info": {"description": f"{rec.header.scenario_name} seed {rec.header.seed}, camera {name}"},
                   "images": [], "annotations": [], "categories": [COCO_CATEGORY]} for name in cameras}
    results: dict[str, list] = {name: [] for name in cameras}
    annotations = 0
    for cf in rec.frames(with_poses=True):
        camera = cameras[cf.frame.camera]
        doc = docs[camera.name]
        image_id = len(doc["images"]) + 1
        doc["images"].append({"id": image_id, "file_name": f"{camera.name}/{image_id:06d}.jpg",
                              "width": camera.width_px, "height": camera.height_px, "stamp_s": cf.frame.stamp_s})
        truth = cf.poses_at_capture
        for pid, pose in zip(truth.person_ids, truth.poses):
            px = project_points(camera, pose)
            inside = (np.isfinite(px).all(axis=1) & (px[:, 0] >= 0) & (px[:, 0] <= camera.width_px)
                      & (px[:, 1] >= 0) & (px[:, 1] <= camera.height_px))
            if not inside.any():
                continue
            kp = np.zeros((len(px), 3))
            kp[inside, :2], kp[inside, 2] = px[inside], 2
            box = _box(px[inside])
            annotations += 1
            doc["annotations"].append({"id": annotations, "image_id": image_id, "category_id": 1,
                                       "keypoints": kp.reshape(-1).tolist(), "num_keypoints": int(inside.sum()),
                                       "bbox": box, "area": box[2] * box[3], "iscrowd": 0, "person_id": int(pid)})
        for kp, sc in zip(cf.frame.keypoints_px, cf.frame.scores):
            known = np.isfinite(kp).all(axis=1)
            if not known.any():
                continue
            flat = np.zeros((len(kp), 3))
            flat[known, :2], flat[known, 2] = kp[known], sc[known]
            results[camera.name].append({"image_id": image_id, "category_id": 1,
                                         "keypoints": flat.reshape(-1).tolist(), "score": float(sc[known].mean())})
    files: dict = {}
    for name in cameras:
        files[f"{name}_keypoints.json"] = docs[name]
        files[f"{name}_detections.json"] = results[name]
    write_folder(out_dir, files)
    detections = sum(len(r) for r in results.values())
    return (f"{out_dir}: {len(cameras)} cameras, {sum(len(d['images']) for d in docs.values())} images, "
            f"{annotations} projected true poses, {detections} detections in COCO's keypoints layout")
