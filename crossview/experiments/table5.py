"""The paper's Table 5 on a recording: per-camera MOTA and IDF1 of the single-view baseline and the cross-view tracker.

The single-view tracker (`tracker.single_view`, SORT per camera) runs over the recording's frames in
delivery order; the cross-view tracker's per-detection assignments come from a tracks file made from the
same recording. Both are scored per camera by `crossview.scoring.per_camera.detection_2d_scores` on the
same detections and the same per-detection truth; beside them, the cross-view tracker under the paper's
own protocol (its 3D targets projected into each camera, `projected_2d_scores`). See docs/metrics.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from crossview.scoring import TruthTimeline
from crossview.scoring.association import stamp_key
from crossview.scoring.per_camera import Camera2DScores, detection_2d_scores, projected_2d_scores
from tracker.single_view import SingleViewConfig, SingleViewTracker

_DEFAULT_SINGLE_VIEW = SingleViewConfig()

# The paper's Table 5 (Shelf, 5 cameras): camera -> (MOTA, IDF1) in percent, single-view then cross-view.
PAPER_TABLE5 = {
    "Camera1": ((86.7, 81.7), (98.8, 99.4)),
    "Camera2": ((97.6, 63.9), (99.2, 99.6)),
    "Camera3": ((97.3, 98.6), (98.4, 99.2)),
    "Camera4": ((68.8, 41.8), (97.6, 98.8)),
    "Camera5": ((79.0, 69.0), (97.6, 98.8)),
}
"""Chen et al. (CVPR 2020), Table 5, "Tracking performance on the Shelf dataset", MOTA and IDF1 (%)."""


def paper_means_line() -> str:
    """One line with the means over the cameras of the paper's Table 5, to print beside ours."""
    single = np.mean([v[0] for v in PAPER_TABLE5.values()], axis=0)
    cross = np.mean([v[1] for v in PAPER_TABLE5.values()], axis=0)
    return (f"paper, Table 5 (Shelf, {len(PAPER_TABLE5)} cameras, projected), mean: single-view MOTA {single[0]:.1f} "
            f"IDF1 {single[1]:.1f}, cross-view MOTA {cross[0]:.1f} IDF1 {cross[1]:.1f}")


@dataclass
class PerCameraRow:
    """One camera's row: the single-view and the cross-view tracker on its detections, and the projected
    cross-view tracks."""

    camera: str
    single_view: Camera2DScores
    cross_view: Camera2DScores
    cross_view_projected: Camera2DScores


@dataclass
class PerCameraTable:
    """Table 5's rows for one recording, in the cameras' order."""

    scenario: str
    seed: int
    rows: list[PerCameraRow]

    def mean(self, column: str, metric: str) -> float | None:
        """Unweighted mean over the cameras of `metric` ("mota" or "idf1") of `column`; cameras where it is
        undefined are left out."""
        values = [getattr(getattr(r, column), metric) for r in self.rows]
        values = [v for v in values if v is not None]
        return float(np.mean(values)) if values else None

    def to_json(self) -> dict:
        """A JSON-safe dict: scenario, seed, one object per camera, and the means."""
        columns = ("single_view", "cross_view", "cross_view_projected")
        return {
            "scenario": self.scenario,
            "seed": self.seed,
            "cameras": [{"camera": r.camera, **{c: vars(getattr(r, c)) for c in columns}} for r in self.rows],
            "mean": {c: {m: self.mean(c, m) for m in ("mota", "idf1")} for c in columns},
        }

    def table(self):
        """The table (`crossview.tables.Table`), percentages with one decimal, the means in the last row."""
        from crossview.tables import Table

        def pct(v):
            return "-" if v is None or not math.isfinite(v) else f"{100 * v:.1f}"

        head = ("camera", "single-view MOTA", "IDF1", "FP", "FN", "IDS", "cross-view MOTA", "IDF1", "FP", "FN", "IDS",
                "projected MOTA", "IDF1")
        rows = []
        for r in self.rows:
            s, c, p = r.single_view, r.cross_view, r.cross_view_projected
            rows.append((r.camera, pct(s.mota), pct(s.idf1), str(s.false_positives), str(s.false_negatives),
                         str(s.id_switches), pct(c.mota), pct(c.idf1), str(c.false_positives), str(c.false_negatives),
                         str(c.id_switches), pct(p.mota), pct(p.idf1)))
        m = {(col, k): pct(self.mean(col, k)) for col in ("single_view", "cross_view", "cross_view_projected")
             for k in ("mota", "idf1")}
        rows.append(("mean", m["single_view", "mota"], m["single_view", "idf1"], "", "", "",
                     m["cross_view", "mota"], m["cross_view", "idf1"], "", "", "",
                     m["cross_view_projected", "mota"], m["cross_view_projected", "idf1"]))
        return Table(head, tuple(rows))

    def markdown(self) -> str:
        """The table as Markdown."""
        return self.table().markdown()


def per_camera_table(rec_path: Path, tracks_path: Path, config: SingleViewConfig = _DEFAULT_SINGLE_VIEW,
                     progress: bool = False) -> PerCameraTable:
    """Table 5's rows for a recording and a cross-view tracks file made from it (see the module docstring).

    Args:
        rec_path: the recording.
        tracks_path: a tracks file of the cross-view tracker (or any tracker that reports
            `detection_target_ids` and 3D targets) made from that recording.
        config: the single-view tracker's parameters.
        progress: show a bar of the frames read and tracked by the single-view tracker.

    Raises:
        CrossviewError: unreadable files, or tracks made from another recording.
    """
    from crossview.pipeline import open_run

    rec, tracks = open_run(rec_path, tracks_path)
    cameras = [c.name for c in rec.cameras]
    outputs = list(tracks.outputs())
    cross_ids = {stamp_key(o.camera, o.stamp_s): o.detection_target_ids for o in outputs}
    from tqdm import tqdm

    # in delivery order, the order the cross-view tracker saw them
    frames = list(tqdm(rec.frames(), total=len(outputs), unit="frame", desc="per-camera: read", disable=not progress,
                       leave=False))
    single = SingleViewTracker(rec.cameras, config)
    single_ids = {}
    for cf in tqdm(frames, unit="frame", desc="per-camera: single-view", disable=not progress, leave=False):
        single.update(cf.frame)
        single_ids[stamp_key(cf.frame.camera, cf.frame.stamp_s)] = single.last_output.detection_track_ids
    single_scores = detection_2d_scores(frames, single_ids, cameras)
    cross_scores = detection_2d_scores(frames, cross_ids, cameras)
    projected = projected_2d_scores(outputs, rec.cameras, TruthTimeline(list(rec.truth())).at)
    rows = [PerCameraRow(name, single_scores[name], cross_scores[name], projected[name]) for name in cameras]
    return PerCameraTable(rec.header.scenario_name, rec.header.seed, rows)
