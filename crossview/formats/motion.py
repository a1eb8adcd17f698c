"""Motion exports for the tools people animate and analyse with: BVH (Blender, Unity, game engines), TRC (OpenSim,
as Pose2Sim writes it) and C3D (biomechanics), one file per person, from a recording's truth or a tracks file.

The people's motion (`Motion`) comes from a recording's truth samples as they are (100 Hz), or from a tracks file
on a regular grid (`rate_hz`): at each tick the latest output stamped at or before it, as `crossview score` takes
it (`core.tracks.LatestPerTick`), its confirmed and lost targets. See docs/exports.md.
"""

from __future__ import annotations

import io
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from core.errors import CrossviewError
from core.types import Skeleton

M_TO_CM = 100.0
DEFAULT_TRACKS_RATE_HZ = 30.0
"""Rate of the grid a tracks file's motion is sampled on unless `--rate` says otherwise, Hz."""

Y_UP = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
"""World (x, y, z; z up) to the Y-up frame of BVH and TRC: (y, z, x), the axes Pose2Sim's `zup2yup` gives OpenSim
(a rotation: no mirror)."""


class ExportError(CrossviewError):
    """An export that cannot be made from its input; the message names the file, person or joint."""


@dataclass
class Motion:
    """Everybody's joints on one time grid.

    Attributes:
        skeleton: the joint layout.
        times: (F,) seconds since the recording's start, increasing.
        people: person or target id -> (n, J, 3) world positions, metres (z up), from the person's first frame to
            their last: NaN where the person is absent or the joint unknown. (Only each person's own span is held:
            a long recording's hundreds of passers-by each keep their minute, not the whole recording.)
        first: person id -> the index in `times` of their first frame.
        source: "truth" or "tracks".
    """

    skeleton: Skeleton
    times: np.ndarray
    people: dict[int, np.ndarray]
    first: dict[int, int]
    source: str

    @property
    def rate_hz(self) -> float:
        return float(1.0 / np.median(np.diff(self.times))) if len(self.times) > 1 else 1.0

    def times_of(self, person: int) -> np.ndarray:
        """The times of the person's frames (`people[person]`)."""
        start = self.first[person]
        return self.times[start:start + len(self.people[person])]


def _collect(rows, times: np.ndarray, skeleton: Skeleton, source: str) -> Motion:
    """A Motion from (frame index, ids (P,), poses (P, J, 3)) rows, each person over their own span."""
    seen: dict[int, list[tuple[int, np.ndarray]]] = {}
    for f, ids, poses in rows:
        for i, pose in zip(ids, poses):
            seen.setdefault(int(i), []).append((f, pose))
    people, first = {}, {}
    for i in sorted(seen):
        frames = [f for f, _ in seen[i]]
        first[i] = frames[0]
        people[i] = np.full((frames[-1] - frames[0] + 1, skeleton.num_joints, 3), np.nan)
        for f, pose in seen[i]:
            people[i][f - frames[0]] = pose
    return Motion(skeleton, times, people, first, source)


def read_motion(path, rate_hz: float | None = None) -> Motion:
    """The motion of a recording's truth (every sample; `rate_hz` must then be None) or of a tracks file (a grid at
    `rate_hz`, default `DEFAULT_TRACKS_RATE_HZ`).

    Raises:
        RecordingError: an unreadable file.
        ExportError: `rate_hz` for a recording.
    """
    from crossview.recording import open_recording, open_tracks
    from crossview.recording.reader import read_kind
    from crossview.recording.schemas import KIND_RECORDING

    if read_kind(path) == KIND_RECORDING:
        if rate_hz is not None:
            raise ExportError(f"{path}: --rate resamples a tracks file; a recording's truth is written at its own "
                              "rate (every sample)")
        rec = open_recording(path)
        times: list[float] = []

        def rows():
            for f, sample in enumerate(rec.truth()):  # (streamed: only each person's own frames are kept)
                times.append(sample.t_s)
                yield f, sample.person_ids, sample.poses

        motion = _collect(rows(), np.zeros(0), rec.skeleton, "truth")
        motion.times = np.array(times, dtype=np.float64)
        return motion
    tracks = open_tracks(path)
    return tracks_motion(tracks.outputs(), tracks.skeleton, rate_hz or DEFAULT_TRACKS_RATE_HZ)


def tracks_motion(outputs, skeleton: Skeleton, rate_hz: float) -> Motion:
    """Tracker outputs on a grid at `rate_hz` from the first output's stamp to the last: at each tick the targets
    of the latest output stamped at or before it (`core.tracks.LatestPerTick`), nobody where it no longer stands
    (`core.tracks.stands`: older than `core.tracks.OUTPUT_MAX_AGE_S`)."""
    from core.tracks import LatestPerTick
    from crossview.scoring import grid_ticks
    from tracker.types import target_arrays

    outputs = list(outputs)
    if not outputs:
        return Motion(skeleton, np.zeros(0), {}, {}, "tracks")
    stamps = [o.stamp_s for o in outputs]
    ticks = grid_ticks(min(stamps), max(stamps), rate_hz)
    grid = LatestPerTick(ticks)
    for out in outputs:
        grid.offer(out.stamp_s, out)

    def rows():
        for f in range(len(ticks)):
            chosen = grid.at(f)
            if chosen is not None:
                yield (f, *target_arrays(chosen.targets, skeleton.num_joints))

    return _collect(rows(), np.asarray(ticks, dtype=np.float64), skeleton, "tracks")


# --------------------------------------------------------------------------------------------------
# BVH

@dataclass(frozen=True)
class _BvhJoint:
    name: str
    parent: str | None
    rest_dir: tuple[float, float, float]  # unit direction of the offset from the parent in the rest pose
    length: str | None  # the bone whose median length is the offset (None: zero offset)


# The BVH skeleton: rest pose Y up, facing +Z, the person's left at +X, arms out (T pose). A joint's rotation
# aligns its bone to its child: the trunk's three rotations take their twist from the hip and shoulder lines
# (Hips: hip line and spine; Spine: spine and shoulder line; Chest: shoulder line and spine), every limb joint
# the smallest rotation from its parent's frame (no twist of its own: one child each, so the positions are exact).
_BVH_JOINTS = (
    _BvhJoint("Hips", None, (0, 0, 0), None),
    _BvhJoint("LeftUpLeg", "Hips", (1, 0, 0), "hip_half"),
    _BvhJoint("LeftLeg", "LeftUpLeg", (0, -1, 0), "left_thigh"),
    _BvhJoint("LeftFoot", "LeftLeg", (0, -1, 0), "left_shin"),
    _BvhJoint("RightUpLeg", "Hips", (-1, 0, 0), "hip_half"),
    _BvhJoint("RightLeg", "RightUpLeg", (0, -1, 0), "right_thigh"),
    _BvhJoint("RightFoot", "RightLeg", (0, -1, 0), "right_shin"),
    _BvhJoint("Spine", "Hips", (0, 1, 0), None),
    _BvhJoint("Chest", "Spine", (0, 1, 0), "spine"),
    _BvhJoint("LeftArm", "Chest", (1, 0, 0), "shoulder_half"),
    _BvhJoint("LeftForeArm", "LeftArm", (1, 0, 0), "left_upper_arm"),
    _BvhJoint("LeftHand", "LeftForeArm", (1, 0, 0), "left_forearm"),
    _BvhJoint("RightArm", "Chest", (-1, 0, 0), "shoulder_half"),
    _BvhJoint("RightForeArm", "RightArm", (-1, 0, 0), "right_upper_arm"),
    _BvhJoint("RightHand", "RightForeArm", (-1, 0, 0), "right_forearm"),
    _BvhJoint("Neck", "Chest", (0, 1, 0), None),
    _BvhJoint("Head", "Neck", (0, 1, 0), "neck"),
)
BVH_JOINT_NAMES = tuple(j.name for j in _BVH_JOINTS)
_HEAD_JOINTS = ("nose", "top_head")  # the Head end: COCO-17's nose, or the Campus joints' top of the head
_LIMB_JOINTS = ("left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle", "left_shoulder",
                "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist")
END_SITE_FRACTION = 0.25
"""A leaf joint's End Site continues its bone by this fraction of the bone's length: a stub that tools draw the
leaf with, not a measured point."""
BVH_ROTATION_ORDER = "ZXY"
"""Channel order of every rotation: Zrotation Xrotation Yrotation, the local rotation Rz @ Rx @ Ry (CMU's order)."""


def bvh_source_joints(skeleton: Skeleton) -> tuple[str, ...]:
    """The skeleton's joints a BVH is made from (12 limb joints and the head's end); ExportError naming those the
    layout lacks."""
    head = next((j for j in _HEAD_JOINTS if j in skeleton.joints), None)
    missing = [j for j in _LIMB_JOINTS if j not in skeleton.joints] + ([] if head else ["nose or top_head"])
    if missing:
        raise ExportError(f"skeleton {skeleton.name}: too few joints for a BVH (missing {', '.join(missing)})")
    return (*_LIMB_JOINTS, head)


def bvh_points(skeleton: Skeleton, pose: np.ndarray) -> dict[str, np.ndarray]:
    """The BVH joints' positions (F, 3) in the Y-up frame, centimetres, from (F, J, 3) world poses in metres."""
    names = bvh_source_joints(skeleton)
    p = {n: (pose[:, skeleton.index(n)] @ Y_UP.T) * M_TO_CM for n in names}
    return {
        "Hips": (p["left_hip"] + p["right_hip"]) / 2,
        "LeftUpLeg": p["left_hip"], "LeftLeg": p["left_knee"], "LeftFoot": p["left_ankle"],
        "RightUpLeg": p["right_hip"], "RightLeg": p["right_knee"], "RightFoot": p["right_ankle"],
        "Spine": (p["left_hip"] + p["right_hip"]) / 2,
        "Chest": (p["left_shoulder"] + p["right_shoulder"]) / 2,
        "LeftArm": p["left_shoulder"], "LeftForeArm": p["left_elbow"], "LeftHand": p["left_wrist"],
        "RightArm": p["right_shoulder"], "RightForeArm": p["right_elbow"], "RightHand": p["right_wrist"],
        "Neck": (p["left_shoulder"] + p["right_shoulder"]) / 2,
        "Head": p[names[-1]],
    }


def bvh_bone_lengths(pts: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """(F,) length of each bone a BVH offset stands for, centimetres."""
    def dist(a, b):
        return np.linalg.norm(pts[a] - pts[b], axis=-1)
    return {
        "hip_half": dist("LeftUpLeg", "RightUpLeg") / 2, "shoulder_half": dist("LeftArm", "RightArm") / 2,
        "left_thigh": dist("LeftLeg", "LeftUpLeg"), "left_shin": dist("LeftFoot", "LeftLeg"),
        "right_thigh": dist("RightLeg", "RightUpLeg"), "right_shin": dist("RightFoot", "RightLeg"),
        "spine": dist("Chest", "Hips"), "neck": dist("Head", "Neck"),
        "left_upper_arm": dist("LeftForeArm", "LeftArm"), "left_forearm": dist("LeftHand", "LeftForeArm"),
        "right_upper_arm": dist("RightForeArm", "RightArm"), "right_forearm": dist("RightHand", "RightForeArm"),
    }


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _frame(x_dir: np.ndarray, y_dir: np.ndarray, keep: str) -> np.ndarray:
    """(F, 3, 3) rotations whose columns are X, Y, Z: `keep` ("x" or "y") is exactly its direction, the other is
    the given one made orthogonal to it (Gram-Schmidt), Z = X x Y."""
    if keep == "x":
        x = _unit(x_dir)
        y = _unit(y_dir - np.sum(y_dir * x, axis=-1, keepdims=True) * x)
    else:
        y = _unit(y_dir)
        x = _unit(x_dir - np.sum(x_dir * y, axis=-1, keepdims=True) * y)
    return np.stack([x, y, np.cross(x, y)], axis=-1)


def _swing(parent: np.ndarray, rest: np.ndarray, bone: np.ndarray) -> np.ndarray:
    """(F, 3, 3) global rotations parent @ S, S the smallest rotation taking `rest` to the bone's direction seen
    from the parent's frame (a bone pointing straight against `rest` turns about the parent's Z)."""
    from scipy.spatial.transform import Rotation

    local = np.einsum("fji,fj->fi", parent, _unit(bone))  # parent^T @ direction
    axis = np.cross(rest, local)
    sin, cos = np.linalg.norm(axis, axis=-1), local @ rest
    angle = np.arctan2(sin, cos)
    perp = np.cross(rest, [0.0, 0.0, 1.0]) if abs(rest[2]) < 0.5 else np.cross(rest, [1.0, 0.0, 0.0])
    axis = np.where((sin > 1e-12)[:, None], axis / np.maximum(sin, 1e-300)[:, None], perp / np.linalg.norm(perp))
    return parent @ Rotation.from_rotvec(axis * angle[:, None]).as_matrix()


@dataclass
class BvhResult:
    """One person's BVH: the file's text and what it took."""

    person: int
    text: str
    frames: int
    filled_frames: int
    bone_lengths_cm: dict[str, float]
    bone_change_cm: dict[str, float]  # largest |length - median| over the frames written, per bone


def bvh_person(motion: Motion, person: int) -> BvhResult:
    """The BVH of one person of `motion`: hierarchy from the median bone lengths, one frame per time of the grid
    from the first to the last where every joint BVH needs is known; a frame between them missing one is filled by
    linear interpolation of the joints over time (counted in `filled_frames`).

    Raises:
        ExportError: a layout without the joints (`bvh_source_joints`), or a person never seen with all of them.
    """
    from scipy.spatial.transform import Rotation

    names = bvh_source_joints(motion.skeleton)
    pose = motion.people[person][:, [motion.skeleton.index(n) for n in names]]
    complete = np.isfinite(pose).all(axis=(1, 2))
    if not complete.any():
        never = [n for n, seen in zip(names, np.isfinite(pose).all(axis=-1).any(axis=0)) if not seen]
        raise ExportError(f"{motion.source}: person {person}: never seen with all {len(names)} joints a BVH needs "
                          f"(never known: {', '.join(never) or 'none, but never all at once'}); too few joints "
                          "for a BVH")
    first, last = np.flatnonzero(complete)[[0, -1]]
    frames = np.arange(first, last + 1)
    known = np.flatnonzero(complete)
    full = np.empty((len(frames), *pose.shape[1:]))
    for j in range(pose.shape[1]):
        for c in range(3):
            full[:, j, c] = np.interp(frames, known, pose[known, j, c])
    whole = np.full((len(frames), motion.skeleton.num_joints, 3), np.nan)
    whole[:, [motion.skeleton.index(n) for n in names]] = full
    pts = bvh_points(motion.skeleton, whole)
    bones = bvh_bone_lengths(pts)
    lengths = {k: float(np.median(v)) for k, v in bones.items()}
    change = {k: float(np.max(np.abs(v - lengths[k]))) for k, v in bones.items()}

    glob = {"Hips": _frame(pts["LeftUpLeg"] - pts["RightUpLeg"], pts["Chest"] - pts["Hips"], "x")}
    glob["Spine"] = _frame(pts["LeftArm"] - pts["RightArm"], pts["Chest"] - pts["Hips"], "y")
    glob["Chest"] = _frame(pts["LeftArm"] - pts["RightArm"], pts["Chest"] - pts["Hips"], "x")
    children = {j.parent: [] for j in _BVH_JOINTS}
    for j in _BVH_JOINTS:
        children[j.parent].append(j)
    for j in _BVH_JOINTS:
        if j.name in glob:
            continue
        kids = children.get(j.name, [])
        if not kids:  # a leaf: its parent's rotation
            glob[j.name] = glob[j.parent]
            continue
        child = kids[0]
        glob[j.name] = _swing(glob[j.parent], np.asarray(child.rest_dir, dtype=np.float64),
                              pts[child.name] - pts[j.name])
    channels, lines = [], ["HIERARCHY"]

    def write(j: _BvhJoint, depth: int):
        pad = "  " * depth
        offset = np.zeros(3) if j.length is None else np.asarray(j.rest_dir) * lengths[j.length]
        lines.append(f"{pad}{'ROOT' if j.parent is None else 'JOINT'} {j.name}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}  OFFSET {offset[0]:.6f} {offset[1]:.6f} {offset[2]:.6f}")
        if j.parent is None:
            lines.append(f"{pad}  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation")
        else:
            lines.append(f"{pad}  CHANNELS 3 Zrotation Xrotation Yrotation")
        channels.append(j)
        kids = children.get(j.name, [])
        for k in kids:
            write(k, depth + 1)
        if not kids:
            end = offset * END_SITE_FRACTION
            lines.append(f"{pad}  End Site")
            lines.append(f"{pad}  {{")
            lines.append(f"{pad}    OFFSET {end[0]:.6f} {end[1]:.6f} {end[2]:.6f}")
            lines.append(f"{pad}  }}")
        lines.append(f"{pad}}}")

    write(_BVH_JOINTS[0], 0)
    columns = [pts["Hips"]]
    for j in channels:
        local = glob[j.name] if j.parent is None else np.einsum("fji,fjk->fik", glob[j.parent], glob[j.name])
        columns.append(Rotation.from_matrix(local).as_euler(BVH_ROTATION_ORDER, degrees=True))
    values = np.concatenate(columns, axis=1)
    lines += ["MOTION", f"Frames: {len(frames)}", f"Frame Time: {1.0 / motion.rate_hz:.6f}"]
    lines += [" ".join(f"{v:.6f}" for v in row) for row in values]
    return BvhResult(person, "\n".join(lines) + "\n", len(frames), int(len(frames) - complete[first:last + 1].sum()),
                     lengths, change)


# --------------------------------------------------------------------------------------------------
# TRC

TRC_MARKERS = {
    # Pose2Sim's names (its skeletons.py) for COCO-17 and for the joints of the Campus layout
    "nose": "Nose", "left_eye": "LEye", "right_eye": "REye", "left_ear": "LEar", "right_ear": "REar",
    "left_shoulder": "LShoulder", "right_shoulder": "RShoulder", "left_elbow": "LElbow", "right_elbow": "RElbow",
    "left_wrist": "LWrist", "right_wrist": "RWrist", "left_hip": "LHip", "right_hip": "RHip", "left_knee": "LKnee",
    "right_knee": "RKnee", "left_ankle": "LAnkle", "right_ankle": "RAnkle", "bottom_head": "Neck",
    "top_head": "Head",
}


def trc_person(motion: Motion, person: int, file_name: str) -> tuple[str, int]:
    """One person's TRC as Pose2Sim writes it (its `make_trc`): tab-separated, header of five lines (PathFileType,
    the rate line's names and values with units m, marker names, X1 Y1 Z1 ...), then `Frame#` from 1 and `Time`
    (seconds since the recording's start) and the markers in metres, Y up (`Y_UP`); an unknown joint is an empty
    cell. Frames from the person's first to last appearance. Returns (text, frames)."""
    pose = motion.people[person] @ Y_UP.T
    times = motion.times_of(person)
    names = [TRC_MARKERS.get(j, j) for j in motion.skeleton.joints]
    rate = motion.rate_hz
    n = len(times)
    lines = [
        f"PathFileType\t4\t(X/Y/Z)\t{file_name}",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
        f"{rate:g}\t{rate:g}\t{n}\t{len(names)}\tm\t{rate:g}\t1\t{n}",
        "Frame#\tTime\t" + "\t\t\t".join(names) + "\t\t",
        "\t\t" + "\t".join(f"X{i + 1}\tY{i + 1}\tZ{i + 1}" for i in range(len(names))),
    ]
    for f in range(n):
        cells = ["" if not np.isfinite(v) else f"{v:.6f}" for v in pose[f].reshape(-1)]
        lines.append(f"{f + 1}\t{times[f]:.6f}\t" + "\t".join(cells))
    return "\n".join(lines) + "\n", n


# --------------------------------------------------------------------------------------------------
# C3D

C3D_EXTRA = "c3d"


def c3d_person(motion: Motion, person: int) -> tuple[bytes, int]:
    """One person's C3D (the `c3d` package, the optional extra `.[c3d]`): points in millimetres in the world frame
    (z up, as labs keep it), labelled with `TRC_MARKERS`' names, at the motion's rate; an unknown joint has
    residual -1 (the C3D convention for an invalid point). Returns (bytes, frames).

    Raises:
        ExportError: the `c3d` package is not installed.
    """
    try:
        import c3d
    except ImportError:
        raise ExportError("--format c3d needs the optional extra: pip install 'crossview-testbed[c3d]'") from None
    pose = motion.people[person] * 1000.0
    writer = c3d.Writer(point_rate=float(motion.rate_hz), point_units="mm  ")
    writer.set_point_labels([TRC_MARKERS.get(j, j) for j in motion.skeleton.joints])
    frames = []
    for frame in pose:
        points = np.zeros((len(frame), 5), dtype=np.float32)
        known = np.isfinite(frame).all(axis=-1)
        points[known, :3] = frame[known]
        points[~known, 3] = -1.0
        frames.append((points, np.zeros((0, 0), dtype=np.float32)))
    writer.add_frames(frames)
    buffer = io.BytesIO()
    with warnings.catch_warnings():  # ("No analog data found": a motion file has none)
        warnings.filterwarnings("ignore", message="No analog data")
        writer.write(buffer)
    return buffer.getvalue(), len(frames)


def person_file(person: int, suffix: str) -> str:
    return f"person_{person}{suffix}"


def export_motion(path, out_dir, fmt: str, rate_hz: float | None = None) -> list[str]:
    """Writes every person of a recording's truth or a tracks file as `out_dir/person_ID.bvh|.trc|.c3d` (a new
    folder, written under a temporary name and renamed when complete). Returns one line per person saying what
    was written (BVH: the bone lengths' largest change, the filled frames)."""
    from crossview.formats.datasets import check_new_folder, write_folder

    out_dir = Path(out_dir)
    check_new_folder(out_dir)
    motion = read_motion(path, rate_hz)
    if fmt == "bvh":
        bvh_source_joints(motion.skeleton)
    if not motion.people:
        raise ExportError(f"{path}: nobody in it ({motion.source}); nothing to export")
    files: dict[str, bytes] = {}
    report = []
    for person in sorted(motion.people):
        if fmt == "bvh":
            try:
                r = bvh_person(motion, person)
            except ExportError as e:
                raise ExportError(f"{path}: {e}") from None
            name = person_file(person, ".bvh")
            files[name] = r.text.encode("ascii")
            worst = max(r.bone_change_cm, key=r.bone_change_cm.get)
            report.append(f"{name}: {r.frames} frames at {motion.rate_hz:g} Hz, {r.filled_frames} filled; bone "
                          f"lengths change by up to {10 * r.bone_change_cm[worst]:.2f} mm ({worst})")
        elif fmt == "trc":
            name = person_file(person, ".trc")
            text, n = trc_person(motion, person, name)
            files[name] = text.encode("ascii")
            report.append(f"{name}: {n} frames at {motion.rate_hz:g} Hz")
        else:
            name = person_file(person, ".c3d")
            files[name], n = c3d_person(motion, person)
            report.append(f"{name}: {n} frames at {motion.rate_hz:g} Hz")
    write_folder(out_dir, files)
    return report
