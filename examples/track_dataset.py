"""Runs the example tracker over a folder in the dataset layout and writes its outputs as JSON lines: how a
tracker that lives outside this project (in any language) hands its results to `crossview score`.

    crossview export REC.mcap --format dataset -o DIR
    python -m examples.track_dataset DIR -o result.jsonl
    crossview score REC.mcap result.jsonl

Only the layout's files are read (calibration.json, detection.json); the lines follow docs/recording-format.md
("Result files"): one target per line, `stamp_s`, `id`, `joints` in metres with null for a missing joint, and
a line with only `stamp_s` after a frame with no target.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from core.types import COCO17
from crossview.formats.datasets import load_cameras, load_frames
from examples.greedy_triangulation import GreedyTriangulationTracker
from tracker.config import TrackerConfig


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dataset", type=Path, help="folder in the dataset layout (crossview export --format dataset)")
    parser.add_argument("-o", "--output", type=Path, required=True, help="JSON lines file to write")
    args = parser.parse_args(argv)
    calibration = json.loads((args.dataset / "calibration.json").read_text())
    cameras = load_cameras(args.dataset, use_distortion=calibration.get("points_2d_distorted", False))
    tracker = GreedyTriangulationTracker(cameras, TrackerConfig.preset("store"), COCO17)
    lines = []
    for frame in load_frames(args.dataset, "detection"):  # in delivery order
        targets = tracker.update(frame)
        if not targets:
            lines.append({"stamp_s": frame.stamp_s})
        for t in targets:
            joints = [None if np.isnan(joint).any() else joint.tolist() for joint in t.pose]
            lines.append({"stamp_s": frame.stamp_s, "id": t.id, "joints": joints})
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text("".join(json.dumps(line) + "\n" for line in lines))
    print(f"{args.output}: {len(lines)} lines")


if __name__ == "__main__":
    main()
