"""The orchestrator of scoring: pose accuracy, ground-plane identity metrics, HOTA and association accuracy in one
run, each from its own module's accumulator.

`score` compares tracker outputs with the simulator's ground truth on a regular evaluation grid:

- grid: ticks t_k = t_0 + k / eval_rate_hz from the first to the last truth sample; ticks before the
  tracker's first output (before any camera frame was delivered) are not scored, and neither are outputs
  stamped before t_0 (a camera whose clock reads behind): the people of the first sample are created at
  t_0, so no truth exists to compare those outputs with, and the first tick waits for an output stamped
  at or after t_0;
- scored area: with `scored_area` (the store's floor), the rest is an ignored region: only people whose
  body root lies on the floor are scored, targets off the floor are dropped, and so is a target nearest
  to a person off the floor (in a doorway, where no camera sees) within `root_threshold_m` of them;
- at each tick the latest tracker output with stamp <= tick is taken (outputs sorted by stamp, on equal
  stamps the later one delivered), and its targets are compared with the truth interpolated at that
  output's stamp (a tracker output stamped at t is compared with the truth at t);
- a tick with no output yet, or whose latest output is older than `OUTPUT_MAX_AGE_S`, is compared
  with the truth at the tick and no targets (every person missed);
- warm-up (`from_s`): ticks before t_0 + from_s are not scored, nor are the outputs and camera frames stamped
  before it (association accuracy, per-camera 2D scores); the first scored tick takes the latest output as
  any tick does.

Besides the totals, the report says when and where the tracker failed: a per-person time line (per time bin
the ticks matched and missed on the ground plane, and the share of correct PCP bones) and a floor grid of the
true person-instants, misses, false positives and identity switches (`ScoreReport.timeline`, `.floor_grid`).

The grid makes the MOT counts comparable across camera counts: a 12-camera rig produces many more
outputs per second than a 3-camera one, but both are scored eval_rate_hz times per second.
Association accuracy uses every delivered camera frame; the per-camera 2D scores every output of
each camera. See docs/metrics.md.
"""

from __future__ import annotations

import logging
from collections.abc import Collection, Iterable, Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np

from core.errors import CrossviewError
from core.head import HeadConvention, HeadPoints
from core.records import CameraFrame, PoseTruth
from core.tracks import OUTPUT_MAX_AGE_S, LatestPerTick, stands
from core.types import COCO17, Camera, Skeleton
from crossview.scoring.association import AssociationAccumulator
from crossview.scoring.hota import HOTA_ZERO_DISTANCE_M, ground_similarity, hota
from crossview.scoring.identity import ROOT_MATCH_THRESHOLD_M, IdentityAccumulator, IdEvent, body_roots
from crossview.scoring.per_camera import Projected2DAccumulator, projected_2d_scores
from crossview.scoring.pose import PoseAccumulator
from crossview.scoring.report import ScoreReport
from crossview.scoring.truth import TruthTimeline
from tracker.types import STANDING_STATES, TrackerOutput, target_arrays

logger = logging.getLogger(__name__)

TIMELINE_BIN_S = 1.0
"""Width of a time bin of the per-person time line, seconds."""

FLOOR_CELL_M = 1.0
"""Side of a cell of the floor grid of misses, false positives and identity switches, metres."""


WARM_UP_S = 5.0
"""The default warm-up of `run` and `sweep` cells, seconds (`default_from_s`; measured in docs/metrics.md)."""


def default_from_s(duration_s: float) -> float:
    """The warm-up `run` and a sweep's cells leave out unless told: `WARM_UP_S`, but at most half the run, so that
    a short run still scores its second half (docs/metrics.md, "Warm-up")."""
    return min(WARM_UP_S, duration_s / 2)


class ScoringError(CrossviewError):
    """Tracks and truth that cannot be scored together (another recording, wrong joint layout)."""


def _targets(out: TrackerOutput, skeleton: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    J = skeleton.num_joints
    try:
        ids, poses = target_arrays(out.targets, J)
    except ValueError:
        poses = None
    if poses is None or poses.ndim != 3 or poses.shape[1:] != (J, 3):
        shapes = sorted({np.shape(t.pose) for t in out.targets if t.state in STANDING_STATES})
        raise ScoringError(f"tracker output {out.camera}@{out.stamp_s}: target poses have shape "
                           f"{', '.join(map(str, shapes))}, expected ({J}, 3) {skeleton.name}")
    return ids, poses


def _in_area(g_ids, g_poses, t_ids, t_poses, area, reach_m, skeleton: Skeleton):
    """The people whose body root lies in `area`, and the targets that are not about anybody outside it.

    Outside the area is an ignored region, as in MOT benchmarks: people there are not scored and targets
    there are dropped. A target inside the area is dropped too when it is within `reach_m` of a person
    outside it and nearer to that person than to every person inside (somebody in a doorway, on the way
    in or out). Any other target counts: a ghost on the floor with nobody near is a false positive.
    """
    x0, y0, x1, y1 = area

    def inside(roots):
        return (roots[:, 0] >= x0) & (roots[:, 0] <= x1) & (roots[:, 1] >= y0) & (roots[:, 1] <= y1)

    g_roots, t_roots = body_roots(g_poses, skeleton), body_roots(t_poses, skeleton)
    g_in = inside(g_roots)
    t_keep = inside(t_roots) | ~np.isfinite(t_roots[:, 0])  # no root: cannot be placed, so it counts
    if t_roots.size and (~g_in).any():
        with np.errstate(invalid="ignore"):
            dist = np.linalg.norm(t_roots[:, None, :] - g_roots[None, :, :], axis=-1)  # (T, G), NaN: no root
        dist = np.where(np.isfinite(dist), dist, np.inf)
        near_out = np.min(np.where(~g_in[None, :], dist, np.inf), axis=1)
        near_in = np.min(np.where(g_in[None, :], dist, np.inf), axis=1, initial=np.inf)
        t_keep &= ~((near_out <= reach_m) & (near_out < near_in))
    return g_ids[g_in], g_poses[g_in], t_ids[t_keep], t_poses[t_keep]


class _Compared(NamedTuple):
    """One scored tick: its time, the instant compared (the output's stamp), the people's ids, body roots and
    shares of correct PCP bones, and the targets' ids and body roots."""

    tick_s: float
    at_s: float
    truth_ids: np.ndarray
    truth_roots: np.ndarray
    pcp_shares: np.ndarray
    target_ids: np.ndarray
    target_roots: np.ndarray


def _over_time_and_place(compared: list[_Compared], events: list[IdEvent], switches, start_s: float, bin_s: float,
                         cell_m: float, area) -> tuple[dict, dict]:
    """The per-person time line and the floor grid of `ScoreReport` from the scored ticks and py-motmetrics'
    events (the same matches, misses and false positives that MOTA and IDF1 count)."""
    num_bins = int(np.floor((compared[-1].tick_s - start_s) / bin_s + 1e-9)) + 1 if compared else 0
    if area is not None:
        x0, y0, x1, y1 = area
    else:
        xy = np.concatenate([np.zeros((0, 2))] + [c.truth_roots for c in compared] + [c.target_roots for c in compared])
        xy = xy[np.isfinite(xy).all(axis=1)]
        x0, y0 = (np.floor(xy.min(axis=0) / cell_m) * cell_m) if len(xy) else (0.0, 0.0)
        x1, y1 = xy.max(axis=0) if len(xy) else (cell_m, cell_m)
    cols = max(1, int(np.ceil((x1 - x0) / cell_m - 1e-9)))
    rows = max(1, int(np.ceil((y1 - y0) / cell_m - 1e-9)))
    grids = {name: np.zeros((rows, cols), dtype=np.int64) for name in ("truth", "misses", "false_positives",
                                                                         "id_switches")}

    def add(grid: str, xy) -> None:
        if np.isfinite(xy).all():
            col = min(max(int(np.floor((xy[0] - x0) / cell_m)), 0), cols - 1)
            row = min(max(int(np.floor((xy[1] - y0) / cell_m)), 0), rows - 1)
            grids[grid][row, col] += 1

    people: dict[int, dict] = {}
    pcp_sum = np.zeros((0, num_bins))
    index: dict[int, int] = {}

    def person(pid: int) -> dict:
        nonlocal pcp_sum
        if pid not in people:
            index[pid] = len(index)
            people[pid] = {"matched": [0] * num_bins, "missed": [0] * num_bins, "pcp": [], "switches": []}
            pcp_sum = np.vstack([pcp_sum, np.zeros(num_bins)])
        return people[pid]

    bins = [int(np.floor((c.tick_s - start_s) / bin_s + 1e-9)) for c in compared]
    for c, b in zip(compared, bins):
        for pid, root, share in zip(c.truth_ids.tolist(), c.truth_roots, c.pcp_shares):
            person(pid)
            pcp_sum[index[pid], b] += share
            add("truth", root)
    for e in events:
        c, b = compared[e.update], bins[e.update]
        if e.kind == "FP":
            add("false_positives", c.target_roots[list(c.target_ids).index(e.target_id)])
            continue
        row = person(e.person_id)
        row["missed" if e.kind == "MISS" else "matched"][b] += 1
        if e.kind == "MISS":
            add("misses", c.truth_roots[list(c.truth_ids).index(e.person_id)])
    for t, pid, target, x, y in switches:
        person(pid)["switches"].append({"t_s": t, "target_id": target, "x_m": x, "y_m": y})
        add("id_switches", np.array([x, y]))
    for pid, row in people.items():
        ticks = np.array(row["matched"]) + np.array(row["missed"])
        row["pcp"] = [float(s / n) if n else None for s, n in zip(pcp_sum[index[pid]], ticks)]
    timeline = {"start_s": float(start_s), "bin_s": float(bin_s), "bins": num_bins,
                "people": {pid: people[pid] for pid in sorted(people)}}
    floor = {"origin_m": [float(x0), float(y0)], "cell_m": float(cell_m), "shape": [rows, cols],
             **{name: grid.tolist() for name, grid in grids.items()}}
    return timeline, floor


def grid_ticks(t_start: float, t_end: float, rate_hz: float) -> np.ndarray:
    """The evaluation grid: ticks t_start + k / rate_hz from t_start to t_end (the same floats as that sum)."""
    num_ticks = int(np.floor((t_end - t_start) * rate_hz + 1e-9)) + 1
    return t_start + np.arange(num_ticks) / rate_hz


def _compared(timeline: TruthTimeline, latest: LatestPerTick, any_output: bool, cutoff: float, skeleton: Skeleton,
              scored_area, root_threshold_m: float):
    """Per scored tick, (tick, at, person ids, true poses, target ids, target poses): what `score` compares (see
    the module docstring); ticks before the first output (when there is any) and before `cutoff` (the warm-up)
    are skipped."""
    for k, tick in enumerate(latest.ticks.tolist()):
        chosen = latest.latest(k)  # the latest output stamped at or before the tick
        if chosen is None and any_output:
            continue  # nothing delivered yet: no tracker could know anything
        if tick < cutoff:
            continue  # the warm-up
        if chosen is not None and stands(chosen.stamp_s, tick):
            t_ids, t_poses = _targets(chosen, skeleton)
            at = chosen.stamp_s
        else:
            t_ids, t_poses = np.zeros(0, dtype=np.int64), np.zeros((0, skeleton.num_joints, 3))
            at = tick
        g_ids, g_poses = timeline.at(at)
        if scored_area is not None:
            g_ids, g_poses, t_ids, t_poses = _in_area(g_ids, g_poses, t_ids, t_poses, scored_area,
                                                      root_threshold_m, skeleton)
        yield tick, at, g_ids, g_poses, t_ids, t_poses


def scored_grid(truth: Sequence[PoseTruth], outputs: Iterable[TrackerOutput], *, eval_rate_hz: float = 10.0,
                root_threshold_m: float = ROOT_MATCH_THRESHOLD_M,
                scored_area: tuple[float, float, float, float] | None = None, skeleton: Skeleton = COCO17,
                from_s: float = 0.0):
    """What `score` compares at each scored tick of its grid, (tick, at, person ids, true poses, target ids,
    target poses), the people and targets in the scored area only, from `from_s` on (its warm-up): the
    MOTChallenge export (`crossview.formats.tracking`) writes these, so that another evaluator scores the same
    instants."""
    timeline = TruthTimeline(truth)
    timeline.num_joints = skeleton.num_joints
    t_start, t_end = timeline.span
    latest = LatestPerTick(grid_ticks(t_start, t_end, eval_rate_hz) if len(timeline.times) else np.zeros(0))
    num_outputs = 0
    for out in outputs:
        num_outputs += 1
        latest.offer(out.stamp_s, out)
    yield from _compared(timeline, latest, num_outputs > 0, t_start + from_s - 1e-9, skeleton, scored_area,
                         root_threshold_m)


def score(
    truth: Sequence[PoseTruth],
    outputs: Iterable[TrackerOutput],
    camera_frames: Iterable[CameraFrame] | None = None,
    cameras: Sequence[Camera] | None = None,
    *,
    eval_rate_hz: float = 10.0,
    root_threshold_m: float = ROOT_MATCH_THRESHOLD_M,
    hota_zero_distance_m: float = HOTA_ZERO_DISTANCE_M,
    scored_area: tuple[float, float, float, float] | None = None,
    skeleton: Skeleton = COCO17,
    projected: bool | Collection[str] = True,
    truth_head: HeadPoints | None = None,
    from_s: float = 0.0,
    timeline_bin_s: float = TIMELINE_BIN_S,
    floor_cell_m: float = FLOOR_CELL_M,
    zones: Sequence | None = None,
) -> ScoreReport:
    """Scores a tracker run against the ground truth (see the module docstring and docs/metrics.md).

    Args:
        truth: true poses (metres, in `skeleton`'s layout), e.g. 100 Hz.
        outputs: tracker outputs in delivery order, read once (a stream: only one per grid tick is kept).
        camera_frames: delivered frames with per-detection truth, in delivery order, read once alongside the
            outputs; enables association accuracy.
        cameras: calibrated cameras; enables the per-camera 2D scores (and the check that the outputs come
            from them).
        eval_rate_hz: rate of the evaluation grid.
        root_threshold_m: ground-plane gate of MOTA/IDF1, metres.
        hota_zero_distance_m: distance at which the HOTA similarity reaches 0, metres.
        scored_area: (x_min, y_min, x_max, y_max) of the floor the cameras watch, metres; None: everywhere.
        skeleton: the joint layout of the truth and the targets (the recording's).
        projected: with cameras, the cameras whose per-camera 2D scores (`camera_2d`) are computed here:
            True every camera, False none, or a collection of camera names (those only, in `cameras`' order).
            The caller computes the others (`crossview.pipeline.score` leaves a share to a second process:
            `projected_2d_scores`).
        truth_head: with a COCO-17 truth, PCP's true head joints as points of the true head (the scenario's
            `scoring.truth_head` "annotated", `crossview.pipeline.truth_head`); None: mapped as the estimate's.
        from_s: warm-up left out, seconds after the first truth sample (see the module docstring).
        timeline_bin_s: width of the time line's bins, seconds.
        floor_cell_m: side of the floor grid's cells, metres.
        zones: the zones of a zoned run (`tracker.zones.Zone`, `crossview.scoring.switches.zones_of` reads them
            from a tracks file's summary): the report then lists every switch by place and cause
            (`switches_by_place`).

    Returns:
        the report; metrics that cannot be measured are None.

    Raises:
        ScoringError: tracks that do not belong to the truth, poses not in `skeleton`'s layout, or a warm-up
            past the end of the truth.
    """
    if not eval_rate_hz > 0:
        raise ValueError(f"eval_rate_hz={eval_rate_hz}: must be > 0")
    if not hota_zero_distance_m > 0:
        raise ValueError(f"hota_zero_distance_m={hota_zero_distance_m}: must be > 0 metres")
    if not (timeline_bin_s > 0 and floor_cell_m > 0):
        raise ValueError(f"timeline_bin_s={timeline_bin_s}, floor_cell_m={floor_cell_m}: must be > 0")
    if not (np.isfinite(from_s) and from_s >= 0):
        raise ScoringError(f"--from {from_s}: the warm-up must be a number of seconds >= 0")
    timeline = TruthTimeline(truth)
    if timeline.num_joints not in (None, skeleton.num_joints):
        raise ScoringError(f"truth poses have {timeline.num_joints} joints, expected {skeleton.num_joints} "
                           f"({skeleton.name})")
    timeline.num_joints = skeleton.num_joints
    t_start, t_end = timeline.span
    if len(timeline.times) and from_s > t_end - t_start + 1e-9:
        raise ScoringError(f"--from {from_s:g}: the warm-up reaches past the end of the recording, which holds "
                           f"{t_end - t_start:.2f} s of truth; give at most {t_end - t_start:.2f}")
    cutoff = t_start + from_s - 1e-9  # (ticks are t_0 + k / rate: a tick at the warm-up's end is scored)
    ticks = grid_ticks(t_start, t_end, eval_rate_hz) if len(timeline.times) else np.zeros(0)

    # One pass over the outputs. The grid needs, per tick, only the latest output stamped at or before it
    # (`core.tracks.LatestPerTick`: at most one output per tick is held).
    latest = LatestPerTick(ticks)
    names = None if cameras is None else {c.name for c in cameras}
    foreign: set[str] = set()
    num_outputs = inside = 0
    if cameras is None or projected is False:
        projected_cameras = []
    else:
        projected_cameras = [c for c in cameras if projected is True or c.name in projected]
    projected_names = {c.name for c in projected_cameras}
    camera_2d = Projected2DAccumulator(projected_cameras, timeline.at) if projected_cameras else None
    association = AssociationAccumulator() if camera_frames is not None else None
    frames = iter(cf for cf in camera_frames if cf.frame.stamp_s >= cutoff) if camera_frames is not None else iter(())
    for out in outputs:
        num_outputs += 1
        if names is not None and out.camera not in names:
            foreign.add(out.camera)
            continue
        inside += t_start - OUTPUT_MAX_AGE_S <= out.stamp_s <= t_end + OUTPUT_MAX_AGE_S
        # (An output stamped before t_0 predates every person of the recording: not kept, see the module docstring.)
        latest.offer(out.stamp_s, out)
        if out.stamp_s < cutoff:
            continue  # in the warm-up: it may still be the latest output at the first scored tick
        if out.camera in projected_names:
            camera_2d.add(out)
        if association is not None:
            association.add_output(out)
            while association.waiting_outputs and (cf := next(frames, None)) is not None:
                association.add_frame(cf)
    if foreign:
        raise ScoringError(f"tracks come from cameras {sorted(foreign)} not in this recording ({sorted(names)})")
    if num_outputs and len(timeline.times) and inside == 0:
        raise ScoringError(
            f"no tracker output stamp falls in the recording's span {t_start:.2f}..{t_end:.2f} s; "
            "the tracks belong to another recording"
        )

    pose_acc = PoseAccumulator(skeleton=skeleton, truth_head=truth_head)
    id_acc = IdentityAccumulator(root_threshold_m, skeleton)
    hota_truth, hota_targets, hota_sims = [], [], []
    evaluated = truth_head is None and skeleton.name == COCO17.name  # a 14-joint truth is a dataset's annotation
    report = ScoreReport(eval_rate_hz=eval_rate_hz, root_threshold_m=root_threshold_m,
                         hota_zero_distance_m=hota_zero_distance_m,
                         truth_head=(HeadConvention.EVALUATE if evaluated else HeadConvention.ANNOTATED).value)
    scored_ticks = 0
    compared: list[_Compared] = []  # per identity update
    for tick, at, g_ids, g_poses, t_ids, t_poses in _compared(timeline, latest, num_outputs > 0, cutoff, skeleton,
                                                              scored_area, root_threshold_m):
        scored_ticks += 1
        shares = pose_acc.update(g_ids, g_poses, t_poses)
        id_acc.update(g_ids, g_poses, t_ids, t_poses)
        compared.append(_Compared(float(tick), float(at), g_ids, body_roots(g_poses, skeleton), shares, t_ids,
                                  body_roots(t_poses, skeleton)))
        hota_truth.append(g_ids)
        hota_targets.append(t_ids)
        hota_sims.append(ground_similarity(body_roots(g_poses, skeleton), body_roots(t_poses, skeleton),
                                           hota_zero_distance_m))
        report.truth_person_instants += len(g_ids)
    report.eval_instants = scored_ticks

    p = pose_acc.result()
    report.pcp, report.pcp_per_actor, report.pcp_per_group = p.pcp, p.pcp_per_actor, p.pcp_per_group
    report.mpjpe_mm, report.mpjpe_per_group_mm = p.mpjpe_mm, p.mpjpe_per_group_mm
    report.pck_50mm, report.pck_100mm, report.pck_150mm = p.pck.get(50), p.pck.get(100), p.pck.get(150)
    report.pck_per_group, report.nan_joints = p.pck_per_group, p.num_nan_joints

    ident = id_acc.result()
    report.mota, report.motp_m, report.idf1 = ident.mota, ident.motp_m, ident.idf1
    report.idp, report.idr = ident.idp, ident.idr
    report.id_switches, report.false_positives = ident.id_switches, ident.false_positives
    report.false_negatives = ident.false_negatives
    for switch in id_acc.switches():
        c = compared[switch.update]
        x, y = c.truth_roots[list(c.truth_ids).index(switch.person_id), :2]
        report.id_switch_events.append((c.at_s, switch.person_id, switch.target_id, float(x), float(y)))
    if zones:
        from crossview.scoring.switches import place

        report.switches_by_place = place(
            id_acc.events(), [c.at_s for c in compared], [(c.truth_ids, c.truth_roots) for c in compared],
            [(c.target_ids, c.target_roots) for c in compared], zones)
    report.from_s = float(from_s)
    report.timeline, report.floor_grid = _over_time_and_place(
        compared, id_acc.events(), report.id_switch_events, t_start + from_s, timeline_bin_s, floor_cell_m,
        scored_area)
    if ident.num_truth == 0 and ident.num_predictions == 0:
        report.idf1 = None  # nothing to identify: undefined rather than 0

    h = hota(hota_truth, hota_targets, hota_sims)
    if report.truth_person_instants or ident.num_predictions:
        report.hota, report.deta, report.assa, report.loca = h.hota, h.deta, h.assa, h.loca

    if association is not None:
        for cf in frames:
            association.add_frame(cf)
        a = association.result()
        if num_outputs and a.frames_scored == 0 and a.frames_without_output > 0:
            raise ScoringError(
                f"none of the {num_outputs} tracker outputs has the camera and stamp of one of the recording's "
                f"{a.frames_without_output} frames; the tracks belong to another recording"
            )
        report.association_accuracy = a.overall
        report.association_accuracy_per_camera = a.per_camera
        report.false_positive_detections_assigned = a.false_positive_assigned
        if a.frames_without_output:
            logger.warning("association accuracy: %d camera frames had no tracker output", a.frames_without_output)
    if camera_2d is not None:
        report.camera_2d = camera_2d.result()
    return report


# ---------------------------------------------------------------- the 2D scores in a second process

SCORE_WORKER = "2D scoring worker"  # (how errors and warnings name the process)

SCORED_HERE = 3
"""`crossview.pipeline.score` with a worker (`camera_2d_worker`) computes the 2D scores of every SCORED_HERE-th
camera itself, the worker those of the others. The worker's reading of the tracks file and the 2D scores took
about 14 s over 6 s of the hypermarket, while the rest took about 8 s (2-core test machine, 2026-11-26,
format-3 tracks): a third of the cameras here about evens them. Over 30 s of it (format 4), every 3rd, 4th or
6th camera here scored in 54.0, 52.5 and 53.7 s: the split is not critical."""


def camera_2d_worker(truth, num_joints: int, cameras, tracks_path: Path, from_s: float, sender) -> None:
    """The second process of `crossview.pipeline.score` (a `core.processes.Worker`): the per-camera 2D scores
    of `cameras`, leaving out the outputs of the warm-up as `score` does."""
    from crossview import recording  # (this process reads the tracks file on its own)

    timeline = TruthTimeline(truth)
    timeline.num_joints = num_joints
    names = {c.name for c in cameras}
    cutoff = timeline.span[0] + from_s - 1e-9
    outputs = (out for out in recording.open_tracks(tracks_path).outputs()
               if out.camera in names and out.stamp_s >= cutoff)
    sender.send(("result", projected_2d_scores(outputs, cameras, timeline.at)))
