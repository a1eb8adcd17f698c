"""The error table of docs/exports.md: every export of one recording and its tracks read back by its independent
reader (bvhio, the TRC text layout, ezc3d, TrackEval, pycocotools).

    python tools/export_readback.py DIR

makes store_layout1, seed 0, 6 s and its tracks in DIR (a new folder), exports them in every format and prints
the table's figures.
"""

from __future__ import annotations

import contextlib
import io
import json
import sys
from pathlib import Path

import ezc3d
import numpy as np
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval

from crossview import pipeline
from crossview.cli import main
from crossview.formats.motion import BVH_JOINT_NAMES, Y_UP, read_motion
from crossview.recording import open_recording
from examples.trackeval_mot import score as te_score
from tests.reference.exports import CHAIN, bvh_errors, disturbed_tracks


def export(args) -> None:
    status = main(["--no-progress", "export", *map(str, args)])
    if status:
        sys.exit(status)


D = Path(sys.argv[1])
D.mkdir(parents=True)
pipeline.generate(pipeline.load_scenario("store_layout1", duration_s=6.0, seed=0), D / "rec.mcap", progress=False)
pipeline.track(D / "rec.mcap", D / "tracks.mcap", progress=False)
for fmt in ("bvh", "trc", "c3d", "coco"):
    export([D / "rec.mcap", "--format", fmt, "-o", D / fmt])
export([D / "tracks.mcap", "--format", "bvh", "-o", D / "bvh_t"])
for which, src, folder in (("truth", D / "rec.mcap", D / "bvh"), ("tracks", D / "tracks.mcap", D / "bvh_t")):
    m = read_motion(src)
    for p in sorted(m.people):
        e, b, bones = bvh_errors(m, p, folder / f"person_{p}.bvh")
        const = [j for j, n in enumerate(BVH_JOINT_NAMES) if all(np.ptp(bones[x]) < 1e-6 for x in CHAIN[n])]
        print(f"BVH {which} person {p}: {e.shape[0]} frames, FK error max {10 * e.max():.3f} mm (median "
              f"{10 * np.median(e):.4f}, 95th pct {10 * np.percentile(e, 95):.3f}), bound max {10 * b.max():.3f} mm, "
              f"over bound by at most {10 * max(0, (e - b).max()):.4f} mm; {len(const)} constant-bone joints, "
              f"max {10 * e[:, const].max():.4f} mm")
m = read_motion(D / "rec.mcap")
worst = 0.0
for p in sorted(m.people):
    lines = (D / "trc" / f"person_{p}.trc").read_text().split("\n")
    t = np.array([[float(c) if c else np.nan for c in line.split("\t")] for line in lines[5:] if line])
    worst = max(worst, np.nanmax(np.abs(t[:, 2:] - (m.people[p] @ Y_UP.T).reshape(len(t), -1))))
print(f"TRC truth (parsed as text, tab-separated): max |error| {1000 * worst:.6f} mm over {len(m.people)} people")
worst = 0.0
for p in sorted(m.people):
    c = ezc3d.c3d(str(D / "c3d" / f"person_{p}.c3d"))
    worst = max(worst, np.max(np.abs(c["data"]["points"][:3].transpose(2, 1, 0) - m.people[p] * 1000)))
print(f"C3D truth (ezc3d): max |error| {worst:.6f} mm")
disturbed = disturbed_tracks(D / "tracks.mcap", D / "disturbed.mcap")
for name, tracks in (("tracks", D / "tracks.mcap"), ("disturbed", disturbed)):
    out = D / f"mot_{name}"
    export([tracks, "--recording", D / "rec.mcap", "--format", "mot", "-o", out])
    r, _ = pipeline.score(D / "rec.mcap", tracks, progress=False, worker_process=False)
    (_, te), = te_score(out).items()
    ours = {"MOTA": r.mota, "IDF1": r.idf1, "HOTA": r.hota, "DetA": r.deta, "AssA": r.assa, "MOTP_m": r.motp_m,
            "IDSW": r.id_switches, "FP": r.false_positives, "FN": r.false_negatives}
    for who, figures in (("crossview score", ours), ("TrackEval", te)):
        print(f"MOT {name}, {who}: " + " ".join(f"{k} {figures[k]:.4f}" if isinstance(figures[k], float)
                                                 else f"{k} {figures[k]}" for k in ours))
    print(f"MOT {name}: largest difference {max(abs(ours[k] - te[k]) for k in ours):.2e}")
rec = open_recording(D / "rec.mcap")
worst_t = worst_d = 0.0
aps = []
for cam in rec.cameras:
    frames = [cf for cf in rec.frames() if cf.frame.camera == cam.name]
    with contextlib.redirect_stdout(io.StringIO()):
        gt = COCO(str(D / "coco" / f"{cam.name}_keypoints.json"))
        evaluation = COCOeval(gt, gt.loadRes(str(D / "coco" / f"{cam.name}_detections.json")), "keypoints")
        evaluation.evaluate()
        evaluation.accumulate()
        evaluation.summarize()
    aps.append(evaluation.stats[0])
    by_image: dict[int, list] = {}
    for d in json.loads((D / "coco" / f"{cam.name}_detections.json").read_text()):
        by_image.setdefault(d["image_id"], []).append(np.reshape(d["keypoints"], (-1, 3)))
    for i, cf in enumerate(frames, start=1):
        anns = {a["person_id"]: np.reshape(a["keypoints"], (-1, 3)) for a in gt.loadAnns(gt.getAnnIds(i))}
        for pid, px in zip(cf.truth.person_ids, cf.truth.keypoints_px):
            if pid >= 0 and pid in anns:
                seen = np.isfinite(px).all(1) & (anns[pid][:, 2] == 2)
                if seen.any():
                    worst_t = max(worst_t, np.max(np.abs(anns[pid][seen, :2] - px[seen])))
        found = [k for k in cf.frame.keypoints_px if np.isfinite(k).all(-1).any()]
        for k, got in zip(found, by_image.get(i, [])):
            known = np.isfinite(k).all(1)
            worst_d = max(worst_d, np.max(np.abs(got[known, :2] - k[known])))
print(f"COCO (pycocotools): projected truth vs the simulator's true 2D joints max {worst_t:.2e} px; detections vs "
      f"the recording max {worst_d:.2e} px; keypoint AP (OKS) per camera {', '.join(f'{a:.3f}' for a in aps)}")
