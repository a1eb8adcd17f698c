"""Skeleton scenes built message by message with protobuf's own classes: the plain reference the compiled
scene encoder (`crossview.recording.wire.skeleton_scene`, through `crossview.recording.messages`) is tested
against, byte for byte."""

from __future__ import annotations

import numpy as np
from foxglove_schemas_protobuf.Color_pb2 import Color
from foxglove_schemas_protobuf.LinePrimitive_pb2 import LinePrimitive
from foxglove_schemas_protobuf.Point3_pb2 import Point3
from foxglove_schemas_protobuf.Pose_pb2 import Pose
from foxglove_schemas_protobuf.Quaternion_pb2 import Quaternion
from foxglove_schemas_protobuf.SceneEntity_pb2 import SceneEntity
from foxglove_schemas_protobuf.SceneEntityDeletion_pb2 import SceneEntityDeletion
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from foxglove_schemas_protobuf.SpherePrimitive_pb2 import SpherePrimitive
from foxglove_schemas_protobuf.TextPrimitive_pb2 import TextPrimitive
from foxglove_schemas_protobuf.Vector3_pb2 import Vector3

from core.records import PoseTruth
from core.types import Skeleton
from crossview.recording.foxglove import (
    JOINT_SPHERE_M,
    TRACK_LINE_M,
    TRUTH_LINE_M,
    WORLD_FRAME,
    timestamp,
    track_color,
    truth_color,
)
from tracker.types import TrackerOutput


def bone_points(points: np.ndarray, skeleton: Skeleton) -> np.ndarray:
    """LINE_LIST endpoints of the bones whose both ends are known: (J, K) -> (2 * bones kept, K)."""
    bones = np.asarray(skeleton.bones, dtype=np.intp).reshape(-1, 2)
    known = np.isfinite(points).all(axis=1)
    kept = bones[known[bones[:, 0]] & known[bones[:, 1]]]
    return points[kept.ravel()]


def skeleton_entity(
    entity_id: str, pose: np.ndarray, skeleton: Skeleton, t_ns: int, rgba: Color, thickness_m: float, label: str
) -> SceneEntity:
    known = pose[np.all(np.isfinite(pose), axis=1)]
    entity = SceneEntity(timestamp=timestamp(t_ns), frame_id=WORLD_FRAME, id=entity_id)
    entity.lines.append(LinePrimitive(
        type=LinePrimitive.LINE_LIST, pose=Pose(orientation=Quaternion(w=1.0)), thickness=thickness_m, color=rgba,
        points=[Point3(x=x, y=y, z=z) for x, y, z in bone_points(pose, skeleton).tolist()],
    ))
    if len(known):
        top = known[np.argmax(known[:, 2])]
        entity.texts.append(
            TextPrimitive(
                pose=Pose(position=Vector3(x=float(top[0]), y=float(top[1]), z=float(top[2]) + 0.25),
                          orientation=Quaternion(w=1.0)),
                billboard=True,
                font_size=12.0,
                scale_invariant=True,
                color=rgba,
                text=label,
            )
        )
        entity.spheres.append(  # a ball on the highest joint makes a person easy to pick out from above
            SpherePrimitive(
                pose=Pose(position=Vector3(x=float(top[0]), y=float(top[1]), z=float(top[2])),
                          orientation=Quaternion(w=1.0)),
                size=Vector3(x=JOINT_SPHERE_M * 2, y=JOINT_SPHERE_M * 2, z=JOINT_SPHERE_M * 2),
                color=rgba,
            )
        )
    return entity


def replace_all(t_ns: int, entities: list[SceneEntity]) -> SceneUpdate:
    """A SceneUpdate that first deletes everything older, so people who left disappear."""
    deletion = SceneEntityDeletion(timestamp=timestamp(t_ns), type=SceneEntityDeletion.ALL)
    return SceneUpdate(deletions=[deletion], entities=entities)


def truth_skeletons(truth: PoseTruth, skeleton: Skeleton, t_ns: int) -> SceneUpdate:
    """Everybody's true skeleton at one instant, pale, labelled with the person id."""
    entities = [
        skeleton_entity(f"person/{pid}", pose, skeleton, t_ns, truth_color(pid), TRUTH_LINE_M, f"p{pid}")
        for pid, pose in zip(np.asarray(truth.person_ids).tolist(), truth.poses)
    ]
    return replace_all(t_ns, entities)


def tracker_skeletons(output: TrackerOutput, skeleton: Skeleton, t_ns: int) -> SceneUpdate:
    """The tracker's targets after one update, each in its own saturated colour, labelled with its id."""
    entities = [
        skeleton_entity(
            f"target/{target.id}", np.asarray(target.pose), skeleton, t_ns, track_color(target.id), TRACK_LINE_M,
            f"T{target.id}",
        )
        for target in output.targets
    ]
    return replace_all(t_ns, entities)
