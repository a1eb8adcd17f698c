"""Property: any dataset folder, however wrong its JSON, is read into valid cameras, frames and truth or
refused with a DatasetError naming the file; never another exception."""

import copy
import json
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import event, given, seed
from hypothesis import strategies as st

from crossview.formats import datasets
from crossview.formats.datasets import DatasetError
from sim.scenario import from_source_text
from tests.fuzz import FUZZ

# A small valid dataset in the published layout: two cameras, three frames of 14 joints, one truth entry.
_K = [[1.2, 0.0, 0.5], [0.0, 1.5, 0.45], [0.0, 0.0, 1.0]]
_TW = [[0.0, 0.0, 1.0, -600.0], [-1.0, 0.0, 0.0, 500.0], [0.0, -1.0, 0.0, 200.0], [0.0, 0.0, 0.0, 1.0]]
VALID = {
    "calibration.json": {"cameras": {"Camera0": {"K": _K, "Tw": _TW, "dist_coeffs": [0.1, 0.0, 0, 0]},
                                     "Camera1": {"K": _K, "Tw": _TW}}},
    "annotation_2d.json": {"image_wh": [360, 288], "frames": {
        f"Camera{c}/{t}": {"camera": f"Camera{c}", "timestamp": 12.0 + t * 0.04,
                           "poses": [{"id": 1, "points_2d": [[100.0 + j, 50.0 + 2 * j] for j in range(14)],
                                      "scores": [1.0] * 14}]}
        for c in range(2) for t in range(2)}},
    "annotation_3d.json": [{"timestamp": 12.0, "poses": [{"id": 1, "points_3d": [[10.0 * j, 5.0, 100.0]
                                                                                 for j in range(14)]}]}],
}

json_values = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-2**70, 2**70), st.integers(-2, 20),
              st.floats(allow_nan=False, allow_infinity=False), st.floats(-1e3, 1e3), st.text(max_size=5)),
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=5), inner, max_size=3)),
    max_leaves=8)


def _paths(doc, prefix=()):
    """Every place in a JSON document: the paths of its values."""
    yield prefix
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            yield from _paths(v, prefix + (i,))


@st.composite
def datasets_(draw, valid=None):
    files = copy.deepcopy(VALID if valid is None else valid)
    for _ in range(draw(st.integers(1, 3))):
        name = draw(st.sampled_from(sorted(files)))
        where = draw(st.sampled_from(list(_paths(files[name]))))
        change = draw(st.sampled_from(["replace", "delete", "add"]))
        if not where:
            files[name] = draw(json_values)
            continue
        parent = files[name]
        try:
            for step in where[:-1]:
                parent = parent[step]
            if change == "replace" or not isinstance(parent, (dict, list)):
                parent[where[-1]] = draw(json_values)
            elif change == "delete":
                del parent[where[-1]]
            elif isinstance(parent, dict):
                parent[draw(st.text(max_size=5))] = draw(json_values)
            else:
                parent.append(draw(json_values))
        except (KeyError, IndexError, TypeError):  # (an earlier change moved this place)
            pass
    return files


@FUZZ
@given(datasets_())
def test_fuzz_any_dataset_folder_reads_valid_or_is_refused_naming_the_file(files):
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        for name, doc in files.items():
            (folder / name).write_text(json.dumps(doc), encoding="utf-8")
        try:
            cameras = datasets.load_cameras(folder)
            frames = datasets.load_frames(folder)
            skeleton = datasets.skeleton_of(frames, folder / "annotation_2d.json")
            truth = datasets.load_truth_3d(folder)
        except DatasetError as e:
            assert str(e).startswith(str(folder)) and "\n" not in str(e), e
            event("refused")
            return
    event("read")
    # What is read is valid: finite calibrations, frames of one joint layout, finite stamps and truth.
    assert all(np.isfinite(c.P).all() for c in cameras)
    for frame in frames:
        assert np.isfinite(frame.stamp_s) and frame.keypoints_px.shape[1:] == (skeleton.num_joints, 2)
    for t, ids, poses in truth:
        assert np.isfinite(t) and np.isfinite(poses).all() and poses.shape == (len(ids), 14, 3)


# A small valid OpenPose folder beside the dataset layout's other files, as `export --format openpose` writes it:
# two cameras of BODY_25 output, their stamps, 17-joint truth and the scene.
def _body25(x: float) -> list[float]:
    return [v for j in range(25) for v in (x + 3.0 * j, 40.0 + 2.0 * j, 0.9 if j < 19 else 0.0)]


VALID_OPENPOSE = {
    "calibration.json": {"image_wh": [360, 288], "points_2d_distorted": True, "cameras": {
        "cam0": {"K": _K, "Tw": _TW, "dist_coeffs": [0.01, 0.0, 0.0, 0.0, 0.0]}, "cam1": {"K": _K, "Tw": _TW}}},
    **{f"cam{c}/cam{c}_{n:012d}_keypoints.json": {"version": 1.3, "people": [
        {"person_id": [-1], "pose_keypoints_2d": _body25(100.0 + 10 * c + n)}]} for c in range(2) for n in range(2)},
    "timestamps.json": {f"cam{c}": {"stamp_s": [12.0, 12.04], "delivery_s": [12.01, 12.05]} for c in range(2)},
    "annotation_3d.json": [{"timestamp": 12.0, "poses": [{"id": 1, "points_3d": [[10.0 * j, 5.0, 100.0]
                                                                                 for j in range(17)]}]}],
    "scene.json": {"scenario_name": "fuzz", "seed": 3, "duration_s": 1.0, "boxes": []},
}


@FUZZ
@seed(36)
@given(datasets_(VALID_OPENPOSE), st.sampled_from([None, 25.0, 1e-300]))
def test_fuzz_any_openpose_folder_converts_or_is_refused_naming_the_file(files, fps):
    """`convert` of an OpenPose folder with the dataset layout's files beside it (calibration.json,
    timestamps.json, annotation_3d.json, scene.json), however wrong their JSON: a recording that reads back,
    or a CrossviewError naming a file of the folder; never another exception, never a file left."""
    from core.errors import CrossviewError
    from crossview import recording

    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        dataset = folder / "op"
        for name, doc in files.items():
            (dataset / name).parent.mkdir(parents=True, exist_ok=True)
            (dataset / name).write_text(json.dumps(doc), encoding="utf-8")
        out = folder / "out.mcap"
        try:
            written = datasets.convert(dataset, out, fps=fps, check_scenario=from_source_text)
        except CrossviewError as e:
            assert str(e).startswith(str(dataset)) and "\n" not in str(e), e
            assert sorted(p.name for p in folder.iterdir()) == ["op"], e
            event("refused")
            return
        event("converted")
        rec = recording.open_recording(out)
        frames = list(rec.frames())
        assert len(frames) == written
        assert all(np.isfinite(f.frame.stamp_s) and np.isfinite(f.truth.delivery_s) for f in frames)
