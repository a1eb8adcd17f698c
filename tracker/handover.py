"""The merger of zones' outputs into one store's tracks (issue 47): global identities handed over at the zones'
borders.

Each zone (`tracker.zones`) runs its own tracker on the frames of its cameras; a person in the overlap of two
zones is tracked by both. The merger reads the zones' outputs in delivery order, frame by frame, and makes one
ordinary output per camera frame:

- the tracks at t (`core.tracks`): each zone's latest output, while it stands (`core.tracks.stands`);
- identity: a zone's local id maps to one global id (changed only as the next item says). A new local id takes the
  global id of the nearest target another zone reports at that moment within the gate (mean 3D joint
  distance, the tracker's own gate `alpha_3d_m` of eq. 4 by default) whose global id no live local id of this
  zone holds yet: that is the hand-over. Otherwise it starts a new global id, its own namespaced id
  (`core.tracks.namespaced`), so ids never collide and never depend on worker count or timing. That own id is
  provisional until the zone first reports the target: till then the hand-over is tried again at each of the
  zone's outputs, so a target born at the far edge of the overlap, whose first poses (from the few cameras
  that see it there) lie beyond the gate, is still handed over once its pose settles, before anyone saw its
  provisional id;
- in an overlap, a zone's target follows the id under which another zone reports the same person (the nearest
  within the gate) while this zone does not report it itself, and also while it does when the other zone's id
  was reported first: two zones that took one person for two (each handed over from another neighbour, or one
  that missed the gate) agree on one id, the older, instead of handing the person to and fro under two ids as
  they stand on the border line (measured on `border` with 4 zones: docs/zones.md);
- reporting: each zone reports the targets whose body root (the hips' midpoint) lies in its own cell
  (`tracker.zones.Zone.owns`; the cells tile the floor, so one place has one reporter), and an output holds what
  every zone reports while its latest output stands; a global id two zones report at once (a person on the
  border line, each zone's estimate on its own side) is reported once, by the lower zone;
- hand-over candidates are what the other zones report, so a person is handed over while the zone they come
  from still owns them: inside the overlap, before the border line;
- detections: each detection of the frame goes to the global id its zone gave it, where that zone reports the
  target (the first such zone in zone order); else -1.

Pure: outputs in, outputs out.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence

import numpy as np

from core import tracks
from core.types import Skeleton
from tracker.types import STANDING_STATES, TargetArrays, TargetState, TrackerOutput
from tracker.zones import Zone


def _arrays(output: TrackerOutput, num_joints: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ids, poses and joint states of an output's standing targets (`tracker.types.target_arrays` plus states)."""
    targets = output.targets
    if isinstance(targets, TargetArrays):
        if targets.state in STANDING_STATES:
            return (np.asarray(targets.ids, dtype=np.int64), np.asarray(targets.poses, dtype=np.float64),
                    np.asarray(targets.joint_states, dtype=np.uint8))
        return np.zeros(0, np.int64), np.zeros((0, num_joints, 3)), np.zeros((0, num_joints), np.uint8)
    kept = [t for t in targets if t.state in STANDING_STATES]
    if not kept:
        return np.zeros(0, np.int64), np.zeros((0, num_joints, 3)), np.zeros((0, num_joints), np.uint8)
    states = [np.zeros(num_joints, np.uint8) if t.joint_state is None else np.asarray(t.joint_state, np.uint8)
              for t in kept]
    return (np.array([t.id for t in kept], dtype=np.int64), np.array([np.asarray(t.pose, float) for t in kept]),
            np.array(states))


class Merger:
    """Global identities from zones' outputs (see the module docstring).

    Args:
        zones: the zones, in their index order.
        skeleton: the outputs' joint layout.
        gate_m: the mean 3D joint distance within which two zones' targets are one person, metres.
    """

    def __init__(self, zones: Sequence[Zone], skeleton: Skeleton, gate_m: float):
        self.zones = list(zones)
        self.skeleton = skeleton
        self.gate_m = float(gate_m)
        self.global_of: dict[tuple[int, int], int] = {}  # (zone, local id) -> global id, for the local id's life
        self.latest: dict[int, tuple[float, np.ndarray, np.ndarray, np.ndarray]] = {}  # zone -> stamp, arrays
        self.handovers: list[tuple[float, int, int, int]] = []  # (stamp, from zone, to zone, global id)
        self.provisional: set[tuple[int, int]] = set()  # (zone, local id) of own ids not reported yet
        self.first_reported: dict[int, float] = {}  # global id -> when a zone first reported it

    def _roots(self, poses: np.ndarray) -> np.ndarray:
        """(N, 2) body roots: the hips' midpoint on the floor (one hip where the other is unknown; NaN for none)."""
        hips = poses[:, list(self.skeleton.hips), :2]
        roots = hips.mean(axis=1)
        bad = ~np.isfinite(roots).all(axis=1)
        if bad.any():  # (a tracker's output holds no NaN; a plug-in's may)
            with np.errstate(invalid="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                roots[bad] = np.nanmean(hips[bad], axis=1)
        return roots

    def _distance(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """(len(a), len(b)) mean 3D joint distance of poses a (N, J, 3) and b (M, J, 3) over joints both know
        (inf where none)."""
        d = np.linalg.norm(a[:, None] - b[None], axis=-1)
        if not d.size:
            return np.zeros(d.shape[:2])
        known = np.isfinite(d)
        with np.errstate(invalid="ignore", divide="ignore"):
            out = np.where(known, d, 0.0).sum(axis=-1) / known.sum(axis=-1)
        return np.where(np.isfinite(out), out, np.inf)

    def _standing(self, t: float) -> dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Zone -> what it reports (global ids, poses, joint states) at t, while its latest output stands."""
        return {z: v[1:] for z, v in sorted(self.latest.items()) if tracks.stands(v[0], t)}

    def _in_overlap(self, zone: int, roots: np.ndarray) -> np.ndarray:
        """(N,) whether body roots (N, 2) lie in another zone's region too (in an overlap of `zone`'s)."""
        out = np.zeros(len(roots), dtype=bool)
        x, y = roots[:, 0], roots[:, 1]
        for other in self.zones:
            if other.index != zone:
                x0, y0, x1, y1 = other.region
                out |= (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
        return out

    def _identify(self, zone: int, ids: np.ndarray, poses: np.ndarray, t: float, owned: np.ndarray,
                  overlap: np.ndarray) -> np.ndarray:
        """Global ids of zone `zone`'s local ids (module docstring): a new local id is handed over or starts its
        own; one in an overlap follows the other zone's report of the same person while this zone does not report
        it, or while its own id is provisional, or when the other zone's id was reported first."""
        out = np.empty(len(ids), dtype=np.int64)
        known = [self.global_of.get((zone, local)) for local in ids.tolist()]
        pending = [g is None or (zone, local) in self.provisional for g, local in zip(known, ids.tolist())]
        if not any(pending) and not overlap.any():
            out[:] = known
            return out
        others = []  # the other zones' reports at this moment: (zone, global ids, poses)
        for z, (o_global, o_poses, _) in self._standing(t).items():
            if z != zone and len(o_global):
                others.append((z, o_global, o_poses))
        held = {g for g in known if g is not None}
        for n, local in enumerate(ids.tolist()):
            key, current = (zone, local), known[n]
            if not (pending[n] or overlap[n]):
                out[n] = current
                continue
            best = None  # the nearest person another zone reports within the gate, whose id no other local holds
            for z, g_ids, o_poses in others:
                dist = self._distance(poses[n:n + 1], o_poses)[0]
                for k in np.argsort(dist, kind="stable"):
                    if dist[k] > self.gate_m:
                        break
                    if int(g_ids[k]) == current or int(g_ids[k]) not in held:
                        if best is None or dist[k] < best[0]:
                            best = (float(dist[k]), z, int(g_ids[k]))
                        break
            if best is not None and best[2] != current:
                first = self.first_reported
                if current is None or pending[n] or not owned[n] or (
                        first.get(best[2], np.inf) < first.get(current, np.inf)):
                    self.global_of[key] = best[2]
                    self.handovers.append((t, best[1], zone, best[2]))
                    self.provisional.discard(key)
                    held.discard(current)
            if key not in self.global_of:
                self.global_of[key] = tracks.namespaced(zone, local)
                self.provisional.add(key)
            held.add(self.global_of[key])
            out[n] = self.global_of[key]
        return out

    def add(self, outputs: Mapping[int, TrackerOutput], num_detections: int) -> TrackerOutput:
        """The merged output of one camera frame, from the outputs of the zones that processed it (zone -> its
        output, all of one camera and stamp)."""
        J = self.skeleton.num_joints
        first = outputs[min(outputs)]
        t, camera = first.stamp_s, first.camera
        detections = np.full(num_detections, -1, dtype=np.int64)
        for z in sorted(outputs):
            ids, poses, states = _arrays(outputs[z], J)
            roots = self._roots(poses) if len(ids) else np.zeros((0, 2))
            owned = self.zones[z].owns(roots) if len(ids) else np.zeros(0, bool)
            global_ids = self._identify(z, ids, poses, t, owned, self._in_overlap(z, roots))
            if self.provisional:  # reported now: the id is seen
                self.provisional.difference_update((z, local) for local in ids[owned].tolist())
            for g in global_ids[owned].tolist():
                self.first_reported.setdefault(g, t)
            self.latest[z] = (t, global_ids[owned], poses[owned], states[owned])
            local = np.asarray(outputs[z].detection_target_ids, dtype=np.int64)
            if len(local) == num_detections and len(ids):
                # Each detection to the global id of its target, where this zone reports that target.
                order = np.argsort(ids, kind="stable")
                at = np.clip(np.searchsorted(ids[order], local), 0, len(ids) - 1)
                found = (local >= 0) & (ids[order][at] == local)
                target = order[at]
                take = (detections < 0) & found & owned[target]
                detections[take] = global_ids[target[take]]
        parts = [v for _, v in sorted(self.latest.items()) if tracks.stands(v[0], t)]
        ids = np.concatenate([p[1] for p in parts]) if parts else np.zeros(0, np.int64)
        poses = np.concatenate([p[2] for p in parts]) if parts else np.zeros((0, J, 3))
        states = np.concatenate([p[3] for p in parts]) if parts else np.zeros((0, J), np.uint8)
        _, keep = np.unique(ids, return_index=True)  # (one id reported once: the first zone's, at a border)
        keep = np.sort(keep)
        targets = TargetArrays(ids[keep], poses[keep].reshape(-1, J, 3), states[keep].reshape(-1, J), t,
                               TargetState.CONFIRMED)
        return TrackerOutput(t, camera, targets, detections)
