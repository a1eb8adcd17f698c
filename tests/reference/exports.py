"""Reference helpers of the export tests and of tools/export_readback.py: forward kinematics of a BVH by bvhio
against its source, and tracks disturbed with every error the MOT scores count."""

from __future__ import annotations

import dataclasses

import numpy as np

from crossview.formats.motion import BVH_JOINT_NAMES, bvh_bone_lengths, bvh_points
from crossview.recording import TracksWriter, open_tracks
from tracker.types import Target, TargetState, TrackerOutput

# (each BVH joint's chain of bones from the root, for the error bound of forward kinematics)
CHAIN = {
    "Hips": [], "Spine": [], "LeftUpLeg": ["hip_half"], "RightUpLeg": ["hip_half"],
    "LeftLeg": ["hip_half", "left_thigh"], "LeftFoot": ["hip_half", "left_thigh", "left_shin"],
    "RightLeg": ["hip_half", "right_thigh"], "RightFoot": ["hip_half", "right_thigh", "right_shin"],
    "Chest": ["spine"], "Neck": ["spine"], "Head": ["spine", "neck"],
    "LeftArm": ["spine", "shoulder_half"], "LeftForeArm": ["spine", "shoulder_half", "left_upper_arm"],
    "LeftHand": ["spine", "shoulder_half", "left_upper_arm", "left_forearm"],
    "RightArm": ["spine", "shoulder_half"], "RightForeArm": ["spine", "shoulder_half", "right_upper_arm"],
    "RightHand": ["spine", "shoulder_half", "right_upper_arm", "right_forearm"],
}
def bvh_errors(motion, person, path, step=1):
    """Per frame (every `step`-th) and BVH joint: (bvhio's forward-kinematics position - the source point, the
    bound: the summed change of the bone lengths along the joint's chain), centimetres."""
    import bvhio

    root = bvhio.readAsHierarchy(str(path))
    layout = [j for j, _, _ in root.layout()]
    assert [j.Name for j in layout] == list(BVH_JOINT_NAMES)
    pts = bvh_points(motion.skeleton, motion.people[person])
    bones = bvh_bone_lengths(pts)
    median = {k: np.median(v) for k, v in bones.items()}
    errors, bounds = [], []
    assert len(root.Keyframes) == len(pts["Hips"])
    for f in range(0, len(root.Keyframes), step):
        root.loadPose(f)
        errors.append([np.linalg.norm(np.array(tuple(j.PositionWorld)) - pts[j.Name][f]) for j in layout])
        bounds.append([sum(abs(bones[b][f] - median[b]) for b in CHAIN[j.Name]) for j in layout])
    return np.array(errors), np.array(bounds), {k: v[::step] for k, v in bones.items()}


def disturbed_tracks(tracks_path, out_path):
    """The tracks with errors of every kind TrackEval and `crossview score` count: two targets swap ids for a
    while (switches), one is dropped for a second (misses), one is moved 1.4 m away for a second (a false positive
    and a miss), and a ghost stands in the store for 2 s."""
    tracks = open_tracks(tracks_path)
    a, b, c, d = sorted({t.id for out in tracks.outputs() for t in out.targets})[:4]
    header = dataclasses.replace(tracks.header, method="disturbed")
    swap = {b: c, c: b}
    with TracksWriter(out_path, header, tracks.cameras) as writer:
        for out in tracks.outputs():
            t = out.stamp_s
            kept = []
            for target in out.targets:
                target = dataclasses.replace(target, pose=np.array(target.pose))
                if 1.0 <= t < 2.0 and target.id == a:
                    continue
                if 2.5 <= t < 4.5 and target.id in swap:
                    target = dataclasses.replace(target, id=swap[target.id])
                if 3.0 <= t < 4.0 and target.id == d:
                    target = dataclasses.replace(target, pose=target.pose + np.array([1.4, 0.0, 0.0]))
                kept.append(target)
            if 0.5 <= t < 2.5 and kept:
                ghost = np.array(kept[0].pose) + np.array([0.0, 2.5, 0.0])
                kept.append(Target(987654, ghost, t, TargetState.CONFIRMED))
            writer.write(TrackerOutput(t, out.camera, kept, out.detection_target_ids))
        writer.finish(tracks.summary)
    return out_path
