"""Cuts the small real-data fixtures of the test suite from the full public files.

Usage (from the repository root):

    python tests/data/cut_fixtures.py --campus DIR --panoptic FILE [--shelf SHELF_FILE]

DIR is a Campus dataset in the crossview layout (calibration.json, annotation_2d.json, annotation_3d.json and
the paper authors' result_3d.json); FILE is the Panoptic dome calibration `calibration_160906_band1.json`;
SHELF_FILE is the Shelf rig's calibration as the 4D Association code publishes it
(zhangyux15/4d_association, `data/shelf/calibration.json`).
Sources and licences: tests/data/README.md
and scenarios/calibrations/README.md. The cut is deterministic: the same inputs give the same bytes.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent.parent

CAMPUS_FPS = 25.0
# The published protocol's test frames (crossview_3d_pose_tracking, evaluate.py).
CAMPUS_TEST_FRAMES = tuple(range(350, 471)) + tuple(range(650, 751))
# The tracker tests run the 2D annotations from this frame to the last test frame: two seconds of run-up
# before the first test frame give every actor time to be found.
CAMPUS_FIRST_FRAME = 300
CAMPUS_LAST_FRAME = CAMPUS_TEST_FRAMES[-1]
RESULT_TOLERANCE_S = 0.1  # evaluate.py takes the result entry nearest a test frame within this
PANOPTIC_KIND = "hd"


def _dump(data, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, separators=(",", ":")) + "\n", encoding="utf-8")
    print(f"{path.relative_to(REPO)}: {path.stat().st_size} bytes")


def cut_campus(source: Path, out: Path) -> None:
    """Frames CAMPUS_FIRST_FRAME..CAMPUS_LAST_FRAME of the 2D annotations; the 3D truth of the test frames
    only (the list keeps its index = frame number, other frames with no poses); the result entries that
    evaluate.py can pick for a test frame (without their unused scores)."""
    (out / "calibration.json").parent.mkdir(parents=True, exist_ok=True)
    _dump(json.loads((source / "calibration.json").read_text()), out / "calibration.json")

    ann2d = json.loads((source / "annotation_2d.json").read_text())
    first, last = CAMPUS_FIRST_FRAME / CAMPUS_FPS - 1e-6, CAMPUS_LAST_FRAME / CAMPUS_FPS + 1e-6
    frames = {k: v for k, v in ann2d["frames"].items() if first <= v["timestamp"] <= last}
    _dump({"image_wh": ann2d["image_wh"], "frames": frames}, out / "annotation_2d.json")

    ann3d = json.loads((source / "annotation_3d.json").read_text())
    test = set(CAMPUS_TEST_FRAMES)
    _dump([entry if i in test else {"timestamp": entry["timestamp"], "poses": []}
           for i, entry in enumerate(ann3d[:CAMPUS_LAST_FRAME + 1])], out / "annotation_3d.json")

    result = json.loads((source / "result_3d.json").read_text())
    test_s = [f / CAMPUS_FPS for f in CAMPUS_TEST_FRAMES]
    near = [e for e in result if any(abs(e["timestamp"] - t) <= RESULT_TOLERANCE_S + 1e-9 for t in test_s)]
    _dump([{"timestamp": e["timestamp"], "poses": [{"id": p["id"], "points_3d": p["points_3d"]} for p in e["poses"]]}
           for e in near], out / "result_3d.json")


def cut_campus_rig(source: Path, out: Path) -> None:
    """Campus's calibration.json whole, with the image size of its annotation_2d.json as `image_wh` (K is
    normalised by it, and a scenario's calibration file must say it: `sim.cameras.load_dataset_calibration`)."""
    calibration = json.loads((source / "calibration.json").read_text())
    image_wh = json.loads((source / "annotation_2d.json").read_text())["image_wh"]
    _dump({"image_wh": image_wh, "cameras": calibration["cameras"]}, out)


def cut_panoptic(source: Path, out: Path) -> None:
    """The dome's 31 HD cameras, in the calibration file's own format."""
    calibration = json.loads(source.read_text())
    _dump({"calibDataSource": calibration.get("calibDataSource", source.stem),
           "cameras": [c for c in calibration["cameras"] if c["type"] == PANOPTIC_KIND]}, out)


def cut_shelf_rig(source: Path, out: Path) -> None:
    """The Shelf rig's 5 cameras from 4D Association's calibration (per camera "K" 3x3 in pixels, "RT" the 3x4
    world-to-camera [R | t] in metres, "imgSize") in the dataset layout `calibration_format = "dataset"` reads:
    K normalised by the image size, Tw the camera-to-world 4x4 in centimetres, no distortion (none is given),
    `image_wh` the image size."""
    import numpy as np

    calibration = json.loads(source.read_text())
    cameras, sizes = {}, set()
    for name in sorted(calibration, key=int):
        c = calibration[name]
        w, h = c["imgSize"]
        sizes.add((w, h))
        K = np.array(c["K"], dtype=float).reshape(3, 3)
        K[0] /= w
        K[1] /= h
        world_to_camera = np.eye(4)
        world_to_camera[:3] = np.array(c["RT"], dtype=float).reshape(3, 4)
        Tw = np.linalg.inv(world_to_camera)
        Tw[:3, 3] *= 100.0  # m -> cm
        cameras[f"Camera{name}"] = {"K": K.tolist(), "Tw": Tw.tolist(), "dist_coeffs": [0.0, 0.0, 0.0, 0.0]}
    (image_wh,) = sizes
    _dump({"image_wh": list(image_wh), "cameras": cameras}, out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--campus", type=Path, required=True, help="the Campus dataset folder (crossview layout)")
    parser.add_argument("--panoptic", type=Path, required=True, help="calibration_160906_band1.json")
    parser.add_argument("--shelf", type=Path, help="4d_association's data/shelf/calibration.json (optional)")
    args = parser.parse_args()
    cut_campus(args.campus, HERE / "campus")
    cut_campus_rig(args.campus, REPO / "scenarios" / "calibrations" / "campus_calibration.json")
    cut_panoptic(args.panoptic, REPO / "scenarios" / "calibrations" / "panoptic_160906_hd.json")
    if args.shelf is not None:
        cut_shelf_rig(args.shelf, REPO / "scenarios" / "calibrations" / "shelf_calibration.json")


if __name__ == "__main__":
    main()
