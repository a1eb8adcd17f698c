"""Reading and writing the dataset layout published with Chen et al., CVPR 2020 (Campus, Shelf, Store).

A dataset directory holds `calibration.json` (per camera `K` normalised by the image size, `Tw` the
camera-to-world pose in centimetres, `dist_coeffs` k1 k2 p1 p2), the 2D input as `detection.json` (COCO-17
detections, `id` -1) or `annotation_2d.json` (ground-truth joints, e.g. the 14 Campus joints), and optionally
`annotation_3d.json` (truth, 14 joints, centimetres; the list index is the frame number). Results use the
`annotation_3d.json` shape with COCO-17 joints (longcw/crossview_3d_pose_tracking documents the layout).

Distortion: the 2D points of the published files already fit the undistorted pinhole model (Campus: median
0.3 px without distortion), so `load_cameras` gives zero distortion unless asked for the listed coefficients.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from core.calibration import calibration_image_wh, dataset_cameras
from core.errors import ScenarioError
from core.layouts import campus14_to_coco17
from core.types import CAMPUS14, COCO17, Camera, Frame
from crossview.formats import openpose
from crossview.formats.json_input import DatasetError, read_json, stamp_s
from crossview.outputs import write_bytes
from tracker.types import TrackerOutput

CM_TO_M = 0.01
_SOURCES = ("detection.json", "annotation_2d.json")
_INT64 = 2 ** 63
UINT64_END = 2 ** 64


def _table(value, path: Path, key: str, kind: type = dict):
    """`value` if it is a JSON object (`kind` dict) or array (`kind` list), else a DatasetError naming `key`."""
    if not isinstance(value, kind):
        want = "an object" if kind is dict else "an array"
        raise DatasetError(f"{path}: {key} must be {want}, got {type(value).__name__}")
    return value


def person_id(value, path: Path, where: str, high: int = _INT64) -> int:
    """A person id: an integer in [-2^63, high) (-1: none; the default `high` makes it fit int64, as 2D and 3D
    truth store it; result files may use unsigned 64-bit ids), else a DatasetError naming `where`."""
    if isinstance(value, bool) or not isinstance(value, int) or not -_INT64 <= value < high:
        raise DatasetError(f"{path}: {where}: id {value!r} must be an integer in [-2^63, 2^{high.bit_length() - 1})")
    return value


def _source_path(dataset_dir: Path, source: str) -> Path:
    if source == "auto":
        for name in _SOURCES:
            if (dataset_dir / name).is_file():
                return dataset_dir / name
        raise DatasetError(f"{dataset_dir}: neither detection.json, annotation_2d.json nor a folder of OpenPose "
                           "*_keypoints.json per camera found")
    names = {"detection": "detection.json", "annotation_2d": "annotation_2d.json", "annotation": "annotation_2d.json"}
    if source not in names:
        raise DatasetError(f"source {source!r}: expected auto, detection, annotation_2d or openpose")
    return dataset_dir / names[source]


def image_size(dataset_dir, source: str = "auto") -> tuple[int, int]:
    """(width, height) in pixels from the 2D file's `image_wh`, or from calibration.json's (ours) for a folder
    whose 2D input is OpenPose output (`crossview.formats.openpose`)."""
    dataset_dir = Path(dataset_dir)
    if source in ("auto", "openpose") and not any((dataset_dir / name).is_file() for name in _SOURCES):
        path = dataset_dir / "calibration.json"
    else:
        path = _source_path(dataset_dir, source)
    data = _table(read_json(path), path, "the file")
    try:
        return calibration_image_wh(data.get("image_wh"))
    except ValueError as exc:
        raise DatasetError(f"{path}: {exc}") from None


def load_cameras(dataset_dir, use_distortion: bool = False) -> list[Camera]:
    """The cameras of `calibration.json` in metres, sorted by name (parsed by `core.calibration.dataset_cameras`, which
    scenarios use for the same files).

    K is de-normalised with the image size of the 2D file; `Tw` (camera-to-world, cm) is inverted into
    R_cam_from_world and t_cam_from_world (m).

    Args:
        dataset_dir: the dataset directory.
        use_distortion: keep the listed k1 k2 p1 p2 (the published 2D points are already undistorted).
    """
    dataset_dir = Path(dataset_dir)
    path = dataset_dir / "calibration.json"
    data = read_json(path)
    width, height = image_size(dataset_dir)
    try:
        return dataset_cameras(data, width, height, use_distortion=use_distortion)
    except ValueError as exc:
        raise DatasetError(f"{path}: {exc}") from None


def load_frames(dataset_dir, source: str = "auto") -> list[Frame]:
    """Every 2D frame of the dataset in the order a tracker receives them, each with its own camera and stamp.

    The order is delivery order when every frame has a `delivery_s` (as `export_dataset` writes), else
    timestamp order (then camera name).

    Args:
        dataset_dir: the dataset directory.
        source: "auto" (detection.json if present, else annotation_2d.json), "detection" or "annotation_2d".

    Returns:
        Frames with (D, J, 2) pixels and (D, J) scores; a joint with score 0 is NaN.
    """
    return [item.frame for item in _read_frames(Path(dataset_dir), source)]


@dataclass(frozen=True, eq=False)
class _FrameItem:
    """One frame of a 2D file: the frame, its key, the (D,) `id` of its poses (-1 for detections) and its
    capture and delivery times (the stamp where the file gives none)."""

    key: str
    frame: Frame
    ids: np.ndarray
    capture_s: float
    delivery_s: float


def _read_frames(dataset_dir: Path, source: str) -> list[_FrameItem]:
    """The frames of a 2D file in delivery order (see `load_frames`)."""
    path = _source_path(dataset_dir, source)
    data = read_json(path)
    items = _table(_table(data, path, "the file").get("frames"), path, "key 'frames' (frame name -> frame)")
    num_joints = None
    parsed = []
    for key, item in items.items():
        item = _table(item, path, f"frame {key!r}")
        stamp = stamp_s(item.get("timestamp"), path, f"frame {key!r}", camera_clock=True)
        poses = [_table(p, path, f"frame {key!r}: a pose") for p in _table(item.get("poses"), path,
                                                                           f"frame {key!r}: poses", list)]
        ids = np.asarray([person_id(p.get("id", -1), path, f"frame {key!r}") for p in poses], dtype=np.int64)
        try:
            camera = str(item["camera"])
            capture = stamp_s(item.get("capture_s", stamp), path, f"frame {key!r}: capture_s")
            delivery = stamp_s(item.get("delivery_s", stamp), path, f"frame {key!r}: delivery_s")
            points = [np.asarray(p["points_2d"], dtype=np.float64) for p in poses]
            scores = [np.asarray(p.get("scores", np.ones(len(p["points_2d"]))), dtype=np.float64) for p in poses]
        except (KeyError, TypeError, ValueError) as exc:
            raise DatasetError(f"{path}: frame {key!r}: key {exc} missing or malformed "
                               "(expected camera, timestamp, poses[points_2d, scores])") from exc
        for k, (p, sc) in enumerate(zip(points, scores)):
            if p.ndim != 2 or p.shape[1] != 2 or sc.shape != p.shape[:1]:
                raise DatasetError(f"{path}: frame {key!r}: points_2d {p.shape} / scores {sc.shape} do not match")
            for name, values, bound, valid in (("points_2d", p, openpose.MAX_PIXEL, "pixels finite, within 1e6"),
                                               ("scores", sc, np.inf, "scores finite")):
                bad = ~(np.isfinite(values) & (np.abs(values) <= bound))  # (1e400 reads as inf, not a JSON error)
                if bad.any():
                    raise DatasetError(f"{path}: frame {key!r}: pose {k}: {name} holds {float(values[bad][0])!r}; "
                                       f"expected {valid}")
            if num_joints is None:
                num_joints = p.shape[0]
            elif p.shape[0] != num_joints:
                raise DatasetError(f"{path}: frame {key!r}: {p.shape[0]} joints, earlier frames have {num_joints}")
        parsed.append((str(key), stamp, camera, points, scores, ids, capture, delivery))
    num_joints = num_joints or COCO17.num_joints
    delivered = all("delivery_s" in item for item in items.values())
    order = (lambda x: x[7]) if delivered else (lambda x: (x[1], x[2]))  # (sorted() is stable: file order on ties)
    out = []
    for key, stamp, camera, points, scores, ids, capture, delivery in sorted(parsed, key=order):
        kp = np.stack(points) if points else np.zeros((0, num_joints, 2))
        sc = np.stack(scores) if scores else np.zeros((0, num_joints))
        kp = np.where((sc > 0)[..., None], kp, np.nan)
        out.append(_FrameItem(key, Frame(camera=camera, stamp_s=stamp, keypoints_px=kp, scores=sc), ids, capture,
                              delivery))
    return out


def skeleton_of(frames: list[Frame], source: Path | None = None):
    """The skeleton the frames' joint count implies (14: CAMPUS14, 17: COCO17); `source`: the file the frames
    were read from, named in the error."""
    for frame in frames:
        if frame.num_detections:
            J = frame.keypoints_px.shape[1]
            for skeleton in (COCO17, CAMPUS14):
                if skeleton.num_joints == J:
                    return skeleton
            where = "" if source is None else f"{source}: "
            raise DatasetError(f"{where}key 'points_2d' of camera {frame.camera!r} at {frame.stamp_s} s holds {J:,} "
                               "joints per pose: expected 17 (COCO-17) or 14 (the Campus joints)")
    return COCO17


def load_truth_3d(dataset_dir, num_joints: int = 14) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """`annotation_3d.json` as a list, index = frame number: (t_s, ids (P,), poses (P, J, 3) metres).

    Args:
        dataset_dir: the dataset directory.
        num_joints: J, the joints of each pose: 14 (Campus, Shelf) or 17 (COCO-17, as `export_dataset` writes).
    """
    path = Path(dataset_dir) / "annotation_3d.json"
    data = _table(read_json(path), path, "the file (a list of {timestamp, poses} entries)", list)
    out = []
    for i, entry in enumerate(data):
        entry = _table(entry, path, f"entry {i}")
        t = stamp_s(entry.get("timestamp"), path, f"entry {i}")
        given = [_table(p, path, f"entry {i}: a pose") for p in _table(entry.get("poses"), path, f"entry {i}: poses",
                                                                       list)]
        ids = np.asarray([person_id(p.get("id"), path, f"entry {i}") for p in given], dtype=np.int64)
        try:
            poses = np.asarray([p["points_3d"] for p in given], dtype=np.float64).reshape(len(given), -1, 3) \
                if given else np.zeros((0, num_joints, 3))
        except (KeyError, TypeError, ValueError) as exc:
            raise DatasetError(f"{path}: entry {i}: key {exc} missing or points_3d not {num_joints}x3") from exc
        if poses.shape != (len(given), num_joints, 3):
            raise DatasetError(f"{path}: entry {i}: points_3d must be {num_joints}x3 for each pose; got "
                               f"{poses.shape[1:]}")
        if not np.all(np.isfinite(poses)):
            raise DatasetError(f"{path}: entry {i}: points_3d hold a value that is not finite")
        out.append((t, ids, poses * CM_TO_M))
    return out


ScenarioCheck = Callable[[str, str, str], object]
"""Reads a scene's `scenario_text` as a scenario, `(text, name, where) -> scenario`, raising `ScenarioError`
naming `where` when it is none (the simulator's `sim.scenario.from_source_text`; the formats do not import
`sim/`, so their caller hands it in)."""


def read_scene(path: Path, check_scenario: ScenarioCheck) -> dict:
    """scene.json (`export_dataset`): an object whose `scenario_name` is text, `scenario_text` a scenario (the
    TOML a synthetic recording was made from: how its truth is scored, what `fit-detector` simulates), `seed` an
    integer in [0, 2^63), `duration_s` a timestamp (`stamp_s`) and `boxes` an array of objects, each where
    given.

    Args:
        path: the scene.json.
        check_scenario: reads `scenario_text` as a scenario (`ScenarioCheck`).

    Raises:
        DatasetError: naming the file and the key.
    """
    scene = _table(read_json(path), path, "the file")
    if not isinstance(scene.get("scenario_name", ""), str):
        raise DatasetError(f"{path}: scenario_name {scene['scenario_name']!r} must be text")
    text = scene.get("scenario_text", "")
    if not isinstance(text, str):
        raise DatasetError(f"{path}: scenario_text must be text (the scenario TOML the recording was made from)")
    if text:
        try:
            check_scenario(text, str(scene.get("scenario_name", "")), f"{path}: scenario_text")
        except ScenarioError as e:
            raise DatasetError(str(e)) from None
    seed = scene.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < _INT64:
        raise DatasetError(f"{path}: seed {seed!r} must be an integer in [0, 2^63)")
    if "duration_s" in scene:
        stamp_s(scene["duration_s"], path, "duration_s")
    for k, box in enumerate(_table(scene.get("boxes", []), path, "key 'boxes'", list)):
        _table(box, path, f"boxes[{k}]")
    return scene


def write_result_3d(outputs: Iterable[TrackerOutput], path, inputs: tuple = ()) -> int:
    """Writes tracker outputs in the result_3d.json layout (COCO-17, centimetres; a joint the tracker does not
    know is written as missing, [null, null, null], never as a point at the origin).

    Outputs sharing a stamp (several cameras of one synchronised instant) keep the last, the most informed.
    Poses with 14 joints (CAMPUS14) are written as COCO-17 with `campus14_to_coco17`.

    Returns:
        The number of entries written.
    """
    by_stamp: dict[float, TrackerOutput] = {}
    for out in outputs:
        by_stamp[float(out.stamp_s)] = out
    entries = []
    for stamp in sorted(by_stamp):
        poses = []
        for target in by_stamp[stamp].targets:
            pose = np.asarray(target.pose, dtype=np.float64)
            if pose.shape == (14, 3):
                pose = campus14_to_coco17(pose)
            if pose.shape != (17, 3):
                raise ValueError(f"write_result_3d: target {target.id} at {stamp} s has pose {pose.shape}; "
                                 "expected (17, 3) COCO-17 or (14, 3) Campus joints")
            cm = np.round(pose / CM_TO_M, 3).tolist()
            missing = ~np.all(np.isfinite(pose), axis=-1)
            points = [[None, None, None] if gone else xyz for xyz, gone in zip(cm, missing.tolist())]
            poses.append({"id": int(target.id), "points_3d": points})
        entries.append({"timestamp": stamp if math.isfinite(stamp) else 0.0, "poses": poses})
    write_bytes(json.dumps(entries).encode("utf-8"), path, inputs)
    return len(entries)


def convert(dataset_dir, out_mcap, source: str = "auto", fps: float | None = None, inputs: tuple = (), *,
            check_scenario: ScenarioCheck) -> int:
    """Writes a dataset of the published layout as a recording (crossview.recording), frames in delivery order.

    Each frame keeps its own camera and stamp, and its capture and delivery times where the file gives them
    (else both are the stamp). The per-detection truth holds the ids and joints of annotation_2d.json when
    its 2D input is that file, or when detection.json comes with an annotation_2d.json of the same frames and
    poses (as `export_dataset` writes); with detection.json alone the ids are -1. The 3D truth of
    annotation_3d.json is written when its poses have the 2D joints' layout (CAMPUS14, or COCO17 as exported),
    and as COCO-17 (`campus14_to_coco17`) when COCO-17 detections come with the published 14-joint truth.
    calibration.json's `points_2d_distorted` and scene.json are read when present (see `export_dataset`).
    A folder with no 2D file but one sub-folder of OpenPose output per camera is read with `crossview.formats.openpose`
    (source "openpose"; `fps` gives the stamps that its timestamps.json does not). `check_scenario` reads
    scene.json's `scenario_text` (`ScenarioCheck`).

    Returns:
        The number of camera frames written.
    """
    import hashlib

    from core.records import CameraFrame, DetectionTruth, PoseTruth
    from crossview.recording import RecordingHeader, RecordingWriter, box_from_json

    dataset_dir = Path(dataset_dir)
    calibration = read_json(dataset_dir / "calibration.json")
    distorted = isinstance(calibration, dict) and calibration.get(DISTORTED_KEY) is True
    cameras = load_cameras(dataset_dir, use_distortion=distorted)
    known = {c.name for c in cameras}
    if source == "openpose" or (source == "auto" and not any((dataset_dir / n).is_file() for n in _SOURCES)
                                and openpose.camera_folders(dataset_dir)):
        source_path = dataset_dir
        frames = [_FrameItem(key, frame, np.full(frame.num_detections, -1, dtype=np.int64), frame.stamp_s, delivery)
                  for key, frame, delivery in openpose.read_frames(dataset_dir, fps)]
        sources = [*sorted(dataset_dir.glob("*/*_keypoints.json")), dataset_dir / openpose.TIMESTAMPS_FILE]
    else:
        source_path = _source_path(dataset_dir, source)
        frames = _read_frames(dataset_dir, source)
        sources = [source_path]
    for item in frames:
        if item.frame.camera not in known:
            raise DatasetError(f"{source_path}: camera {item.frame.camera!r} is not in "
                               f"calibration.json ({', '.join(sorted(known))})")
    truth_2d = _matching_annotation_2d(dataset_dir, source_path, frames)
    skeleton = skeleton_of([item.frame for item in frames], source_path)
    truth = []
    if (dataset_dir / "annotation_3d.json").is_file():
        try:
            truth = load_truth_3d(dataset_dir, skeleton.num_joints)
        except DatasetError:
            if skeleton.num_joints == CAMPUS14.num_joints:
                raise
            # COCO-17 detections beside the published 14-joint truth (Shelf, Campus): the truth is stored as
            # COCO-17, its twelve limb joints exactly (`campus14_to_coco17`); a file in neither layout is
            # malformed and named (the recording would have no truth).
            truth = [(t, ids, campus14_to_coco17(poses))
                     for t, ids, poses in load_truth_3d(dataset_dir, CAMPUS14.num_joints)]
    truth.sort(key=lambda entry: entry[0])
    scene = read_scene(dataset_dir / SCENE_FILE, check_scenario) if (dataset_dir / SCENE_FILE).is_file() else {}
    digest = hashlib.sha256()
    for path in (dataset_dir / "calibration.json", *sources, dataset_dir / "annotation_3d.json",
                 dataset_dir / SCENE_FILE):
        if path.is_file():
            digest.update(path.read_bytes())
    end_s = max([f.delivery_s for f in frames] + [e[0] for e in truth] + [0.0])
    try:
        header = RecordingHeader(scenario_name=str(scene.get("scenario_name", dataset_dir.resolve().name)),
                                 scenario_text=scene.get("scenario_text", ""), scenario_digest=digest.hexdigest(),
                                 seed=int(scene.get("seed", 0)),
                                 duration_s=float(scene.get("duration_s", end_s)), skeleton_name=skeleton.name)
        boxes = [box_from_json(b) for b in scene.get("boxes", [])]
    except (TypeError, ValueError, KeyError) as exc:  # (`read_scene` checked the types: a box's key or value)
        raise DatasetError(f"{dataset_dir / SCENE_FILE}: malformed ({exc}); expected scenario_name, seed, "
                           "duration_s and boxes as a recording's header holds them") from None
    J = skeleton.num_joints
    events = [(t, 0, i) for i, (t, _, _) in enumerate(truth)] + [(f.delivery_s, 1, i) for i, f in enumerate(frames)]
    events.sort()
    with RecordingWriter(out_mcap, header, cameras, boxes, inputs=(*inputs, *sources)) as writer:
        for _, kind, i in events:
            if kind == 0:
                writer.write(PoseTruth(float(truth[i][0]), truth[i][1], truth[i][2]))
                continue
            item = frames[i]
            frame, ids = item.frame, item.ids
            D = frame.num_detections
            if truth_2d is not None:
                ids, keypoints = truth_2d[item.key]
            else:
                keypoints = np.where((ids >= 0)[:, None, None], frame.keypoints_px, np.nan)
            in_image = np.isfinite(keypoints[..., 0])
            none = np.zeros((D, J), dtype=bool)
            det_truth = DetectionTruth(capture_s=item.capture_s, delivery_s=item.delivery_s, person_ids=ids,
                                       keypoints_px=keypoints, in_image=in_image, occluded=none,
                                       self_occluded=none, effects=np.zeros(D, dtype=np.int64))
            # (The poses at capture are not stored: a reader derives them from the truth written here.)
            writer.write(CameraFrame(frame=frame, truth=det_truth, poses_at_capture=None))
    return len(frames)


def _matching_annotation_2d(dataset_dir: Path, source_path: Path, frames: list[_FrameItem]):
    """Per frame key, (ids (D,), true joints (D, J, 2)) from annotation_2d.json when the 2D input is
    detection.json and annotation_2d.json holds the same frames with one pose per detection; else None."""
    path = dataset_dir / "annotation_2d.json"
    if source_path.name != "detection.json" or not path.is_file():  # (an OpenPose folder: source_path is it)
        return None
    annotated = {item.key: item for item in _read_frames(dataset_dir, "annotation_2d")}
    if set(annotated) != {item.key for item in frames}:
        return None
    if any(annotated[f.key].frame.keypoints_px.shape != f.frame.keypoints_px.shape for f in frames):
        return None
    return {key: (item.ids, item.frame.keypoints_px) for key, item in annotated.items()}


DISTORTED_KEY = "points_2d_distorted"
"""calibration.json: true when the 2D points are the camera's raw (distorted) pixels, to be undistorted with
`dist_coeffs` (k1 k2 p1 p2 k3); absent in the published datasets, whose points fit the pinhole model."""
SCENE_FILE = "scene.json"
"""The exported recording's scenario name, seed, duration and store boxes (the floor is the scored area)."""


def export_dataset(rec_path, out_dir) -> int:
    """Writes a recording in the dataset layout, so that tools written for Campus, Shelf and Store read it.

    Files (see docs/recording-format.md): calibration.json (K normalised by the image size, `Tw`
    camera-to-world in cm, all five `dist_coeffs`, `points_2d_distorted: true`); detection.json (every
    delivered frame in delivery order under the key `CAMERA/INDEX`, with its camera, stamp (`timestamp`),
    `capture_s` and `delivery_s`, and its detections: `id` -1, COCO-17 `points_2d` in distorted pixels, 0
    where missing, `scores`); annotation_2d.json (the same keys, one pose per detection: the true person
    `id`, -1 for a false positive, and the true joints, score 1 inside the image); annotation_3d.json (every
    truth sample: `timestamp`, poses with `id` and `points_3d` in cm); scene.json (scenario name, seed,
    duration, store boxes). `convert` reads it back into the same frames, truth and store.

    The folder is written under a temporary name beside `out_dir` and renamed when complete; `out_dir` must
    not exist or be empty.

    Returns:
        The number of camera frames written.
    """
    rec, files = _open_export(rec_path, out_dir)
    (width, height), = {(c.width_px, c.height_px) for c in rec.cameras}
    detections, annotations = {}, {}
    for index, cf in enumerate(rec.frames()):
        key = f"{cf.frame.camera}/{index:06d}"
        head = {"camera": cf.frame.camera, "timestamp": cf.frame.stamp_s, "capture_s": cf.truth.capture_s,
                "delivery_s": cf.truth.delivery_s}
        kp, scores = cf.frame.keypoints_px, cf.frame.scores
        usable = np.isfinite(kp).all(axis=-1)
        detections[key] = head | {"poses": [
            {"id": -1, "points_2d": np.where(u[:, None], k, 0.0).tolist(), "scores": np.where(u, s, 0.0).tolist()}
            for k, s, u in zip(kp, scores, usable)]}
        true_kp = cf.truth.keypoints_px
        seen = np.isfinite(true_kp).all(axis=-1)
        annotations[key] = head | {"poses": [
            {"id": int(i), "points_2d": np.where(u[:, None], k, 0.0).tolist(), "scores": u.astype(float).tolist()}
            for i, k, u in zip(cf.truth.person_ids, true_kp, seen)]}
    files["detection.json"] = {"image_wh": [width, height], "frames": detections}
    files["annotation_2d.json"] = {"image_wh": [width, height], "frames": annotations}
    write_folder(out_dir, files)
    return len(detections)


def export_openpose(rec_path, out_dir) -> int:
    """Writes a recording as OpenPose's JSON output (`crossview.formats.openpose`) beside the dataset layout's files.

    `out_dir` gets one folder per camera of `CAMERA_NNNNNNNNNNNN_keypoints.json` (BODY_25, NNN the camera's
    frame number), timestamps.json (each frame's stamp and delivery time by frame number), and
    calibration.json, annotation_3d.json and scene.json as `export_dataset` writes them; `convert` reads it
    back into the same frames (no per-detection truth: OpenPose's output has none). Written atomically like
    `export_dataset`.

    Returns:
        The number of camera frames written.
    """
    rec, files = _open_export(rec_path, out_dir)
    (width, height), = {(c.width_px, c.height_px) for c in rec.cameras}
    files["calibration.json"]["image_wh"] = [width, height]  # (no detection.json to hold it)
    times: dict[str, dict[str, list[float]]] = {c.name: {"stamp_s": [], "delivery_s": []} for c in rec.cameras}
    count = 0
    for cf in rec.frames():
        camera = cf.frame.camera
        number = len(times[camera]["stamp_s"])
        times[camera]["stamp_s"].append(cf.frame.stamp_s)
        times[camera]["delivery_s"].append(cf.truth.delivery_s)
        people = [{"person_id": [-1], "pose_keypoints_2d": openpose.body_25(k, s)}
                  for k, s in zip(cf.frame.keypoints_px, cf.frame.scores)]
        files[f"{camera}/{camera}_{number:012d}_keypoints.json"] = {"version": 1.3, "people": people}
        count += 1
    files[openpose.TIMESTAMPS_FILE] = times
    write_folder(out_dir, files)
    return count


def _open_export(rec_path, out_dir):
    """The recording and the files every export holds (calibration.json, annotation_3d.json, scene.json),
    after checking that `out_dir` is new or empty and that the cameras share one image size."""
    from crossview.recording import box_json, open_recording

    check_new_folder(out_dir)
    rec = open_recording(rec_path)
    sizes = {(c.width_px, c.height_px) for c in rec.cameras}
    if len(sizes) != 1:
        raise DatasetError(f"{rec_path}: cameras of {len(sizes)} image sizes; the layout has one image_wh")
    files = {
        "calibration.json": {"cameras": {c.name: _calibration_entry(c) for c in rec.cameras}, DISTORTED_KEY: True},
        "annotation_3d.json": [{"timestamp": p.t_s, "poses": [{"id": int(i), "points_3d": (pose / CM_TO_M).tolist()}
                                                              for i, pose in zip(p.person_ids, p.poses)]}
                               for p in rec.truth()],
        SCENE_FILE: {"scenario_name": rec.header.scenario_name, "scenario_text": rec.header.scenario_text,
                     "seed": rec.header.seed,
                     "duration_s": rec.header.duration_s, "boxes": [box_json(b) for b in rec.boxes]},
    }
    return rec, files


def check_new_folder(out_dir) -> None:
    """Fails early, before any work, unless `out_dir` is new or an empty folder (an export's output folder)."""
    from crossview.outputs import check_output

    out_dir = Path(out_dir)
    if out_dir.exists() and (not out_dir.is_dir() or any(out_dir.iterdir())):
        raise DatasetError(f"{out_dir}: exists and is not an empty folder; choose a new folder for the export")
    if not out_dir.exists():
        check_output(out_dir)  # (its folder can be made and written; it is no input)


def write_folder(out_dir, files: dict) -> None:
    """Writes each {relative path: JSON document, or bytes as they are} under a temporary folder beside `out_dir`,
    then renames it to `out_dir` (an empty folder of that name is replaced); nothing is left behind on an error
    or a signal."""
    import os
    import shutil

    from crossview.outputs import OutputError, remove_dead_temporaries, temporary_name

    out_dir = Path(out_dir)
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    remove_dead_temporaries(out_dir)  # (those of an earlier export killed with SIGKILL)
    tmp = temporary_name(out_dir)
    try:
        tmp.mkdir()
        for name, doc in files.items():
            (tmp / name).parent.mkdir(parents=True, exist_ok=True)
            if isinstance(doc, bytes):
                (tmp / name).write_bytes(doc)
                continue
            with open(tmp / name, "w", encoding="utf-8") as f:
                json.dump(doc, f, separators=(",", ":"), allow_nan=False)
        os.chmod(tmp, 0o755)
        os.replace(tmp, out_dir)
    except OSError as e:  # (a full disk: named by the output, not by the temporary folder)
        shutil.rmtree(tmp, ignore_errors=True)
        error = OutputError(f"{out_dir}: cannot be written ({e.strerror or e}); nothing was kept")
        error.errno = e.errno
        raise error from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _calibration_entry(camera: Camera) -> dict:
    """One camera of calibration.json: K normalised by the image size, Tw camera-to-world in cm, dist_coeffs."""
    Tw = np.eye(4)
    Tw[:3, :3] = camera.R_cam_from_world.T
    Tw[:3, 3] = camera.center_world / CM_TO_M
    K = camera.K / np.array([[camera.width_px], [camera.height_px], [1.0]])
    return {"K": K.tolist(), "Tw": Tw.tolist(), "dist_coeffs": camera.dist.tolist()}
