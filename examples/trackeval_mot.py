"""Scores a folder written by `crossview export TRACKS --recording REC --format mot` with TrackEval alone (numpy and
TrackEval's metrics; nothing of crossview): MOTA, MOTP, IDF1, HOTA and the counts of every tracker and sequence.

The rows are MOT15-3D's (frame, id, -1, -1, -1, -1, conf, x, y, z: body roots on the floor, metres), so the
similarity is MOT15-3D's ground-plane one, max(0, 1 - d / 2 m) (TrackEval's Euclidean similarity): CLEAR and
Identity's threshold 0.5 is then a 1 m gate, as `crossview score` matches; HOTA averages over its thresholds.

    python examples/trackeval_mot.py EXPORT_FOLDER
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from trackeval.metrics import CLEAR, HOTA, Identity

ZERO_DISTANCE_M = 2.0


def read_rows(path: Path) -> np.ndarray:
    """(N, 10) rows of a MOTChallenge text file (an empty file: none)."""
    return np.loadtxt(path, delimiter=",", ndmin=2).reshape(-1, 10)


def sequence_data(gt: np.ndarray, found: np.ndarray, num_frames: int) -> dict:
    """TrackEval's per-sequence data: ids numbered from 0, per frame the ground-plane similarities."""
    gt_ids = {v: k for k, v in enumerate(np.unique(gt[:, 1]))}
    found_ids = {v: k for k, v in enumerate(np.unique(found[:, 1]))}
    data = {"gt_ids": [], "tracker_ids": [], "similarity_scores": [], "num_timesteps": num_frames,
            "num_gt_ids": len(gt_ids), "num_tracker_ids": len(found_ids), "num_gt_dets": len(gt),
            "num_tracker_dets": len(found)}
    for frame in range(1, num_frames + 1):
        g, t = gt[gt[:, 0] == frame], found[found[:, 0] == frame]
        d = np.linalg.norm(g[:, None, 7:9] - t[None, :, 7:9], axis=-1)
        data["gt_ids"].append(np.array([gt_ids[i] for i in g[:, 1]], dtype=int))
        data["tracker_ids"].append(np.array([found_ids[i] for i in t[:, 1]], dtype=int))
        data["similarity_scores"].append(np.nan_to_num(np.maximum(0.0, 1.0 - d / ZERO_DISTANCE_M), nan=0.0))
    return data


def score(folder) -> dict[tuple[str, str], dict[str, float]]:
    """{(tracker, sequence): figures} for every tracker file of the export."""
    folder = Path(folder)
    results = {}
    for gt_file in sorted(folder.glob("gt/mot_challenge/*/*/gt/gt.txt")):
        sequence, benchmark = gt_file.parent.parent.name, gt_file.parent.parent.parent.name
        info = dict(line.split("=", 1) for line in (gt_file.parent.parent / "seqinfo.ini").read_text().split()
                    if "=" in line)
        num_frames = int(info["seqLength"])
        for tracker_file in sorted(folder.glob(f"trackers/mot_challenge/{benchmark}/*/data/{sequence}.txt")):
            data = sequence_data(read_rows(gt_file), read_rows(tracker_file), num_frames)
            config = {"PRINT_CONFIG": False}
            clear = CLEAR(config).eval_sequence(data)
            identity = Identity(config).eval_sequence(data)
            hota = HOTA(config).eval_sequence(data)
            results[(tracker_file.parent.parent.name, sequence)] = {
                "MOTA": float(clear["MOTA"]), "MOTP_m": ZERO_DISTANCE_M * (1.0 - float(clear["MOTP"])),
                "IDF1": float(identity["IDF1"]), "HOTA": float(np.mean(hota["HOTA"])),
                "DetA": float(np.mean(hota["DetA"])), "AssA": float(np.mean(hota["AssA"])),
                "IDSW": int(clear["IDSW"]), "FP": int(clear["CLR_FP"]), "FN": int(clear["CLR_FN"]),
            }
    return results


if __name__ == "__main__":
    for (tracker, sequence), figures in score(sys.argv[1]).items():
        print(tracker, sequence, " ".join(f"{k} {v:.4f}" if isinstance(v, float) else f"{k} {v}"
                                          for k, v in figures.items()))
