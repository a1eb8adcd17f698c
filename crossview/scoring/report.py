"""The score report: every metric of one run, as a terminal table and as the flat JSON of docs/metrics.md ("JSON")."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from crossview.scoring.per_camera import Camera2DScores

JSON_KEYS = (
    "scenario", "seed", "num_cameras", "num_people", "duration_s", "pcp", "mpjpe_mm", "pck_100mm", "mota",
    "idf1", "id_switches", "hota", "association_accuracy", "tracker_fps", "camera_frames_per_s",
)
"""The keys every score JSON starts with, in this order (docs/metrics.md, "JSON")."""


def _clean(value):
    """JSON-safe value: NaN and infinity become None; numpy scalars become Python numbers."""
    if value is None:
        return None
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    if isinstance(value, (bool, str)):
        return value
    if hasattr(value, "item"):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


@dataclass
class ScoreReport:
    """Pose, identity and association scores of one run (fractions in [0, 1]; None = not measurable).

    See docs/metrics.md for the definition of every field.
    """

    # Pose (evaluation grid, nearest-estimate matching as in the Campus/Shelf protocol).
    pcp: float | None = None
    pcp_per_actor: dict[int, float] = field(default_factory=dict)
    pcp_per_group: dict[str, float | None] = field(default_factory=dict)
    mpjpe_mm: float | None = None
    mpjpe_per_group_mm: dict[str, float | None] = field(default_factory=dict)
    pck_50mm: float | None = None
    pck_100mm: float | None = None
    pck_150mm: float | None = None
    pck_per_group: dict[int, dict[str, float | None]] = field(default_factory=dict)
    nan_joints: int = 0
    # Identity on the ground plane (evaluation grid).
    mota: float | None = None
    motp_m: float | None = None
    idf1: float | None = None
    idp: float | None = None
    idr: float | None = None
    id_switches: int | None = None
    false_positives: int | None = None
    false_negatives: int | None = None
    # Each switch: (time s, person id, the target it switched to, person's root x, y in metres) at the compared
    # instant (the tracker output's stamp).
    id_switch_events: list[tuple[float, int, int, float, float]] = field(default_factory=list)
    # A zoned tracks file's switches by place and cause (`crossview.scoring.switches.PlacedSwitch`); None for a
    # run that is not zoned.
    switches_by_place: list | None = None
    # When and where (`crossview.scoring.score`, docs/metrics.md "Over time and place"): per person the time
    # bins' matched and missed ticks, PCP share and switches; the floor grid's counts.
    timeline: dict = field(default_factory=dict)
    floor_grid: dict = field(default_factory=dict)
    hota: float | None = None
    deta: float | None = None
    assa: float | None = None
    loca: float | None = None
    # Association (all delivered frames) and per-camera 2D tracking (the paper's Figure 4 and Table 5).
    association_accuracy: float | None = None
    association_accuracy_per_camera: dict[str, float | None] = field(default_factory=dict)
    false_positive_detections_assigned: float | None = None
    camera_2d: dict[str, Camera2DScores] = field(default_factory=dict)
    # Speed, measured by the caller (the pipeline) and set here for the table.
    tracker_fps: float | None = None
    camera_frames_per_s: float | None = None
    # Bookkeeping.
    eval_rate_hz: float = 10.0
    eval_instants: int = 0
    from_s: float = 0.0  # the warm-up left out, seconds after the truth's start
    truth_person_instants: int = 0
    root_threshold_m: float = 1.0
    hota_zero_distance_m: float = 2.0
    # Where PCP's true head joints lie: "evaluate" (mapped as the estimate's) or "annotated" (on the true head,
    # or a dataset's annotated truth); `core.head.HeadConvention`.
    truth_head: str = "evaluate"

    def to_json(
        self,
        *,
        scenario: str | None,
        seed: int | None,
        num_cameras: int | None,
        num_people: int | None,
        duration_s: float | None,
        tracker_fps: float | None = None,
        camera_frames_per_s: float | None = None,
    ) -> dict:
        """The flat score object: the keys of `JSON_KEYS` first (None for a missing metric), then extras.

        The speed arguments default to the report's own `tracker_fps` and `camera_frames_per_s` fields.
        """
        tracker_fps = self.tracker_fps if tracker_fps is None else tracker_fps
        camera_frames_per_s = self.camera_frames_per_s if camera_frames_per_s is None else camera_frames_per_s
        head = {
            "scenario": scenario,
            "seed": seed,
            "num_cameras": num_cameras,
            "num_people": num_people,
            "duration_s": duration_s,
            "pcp": self.pcp,
            "mpjpe_mm": self.mpjpe_mm,
            "pck_100mm": self.pck_100mm,
            "mota": self.mota,
            "idf1": self.idf1,
            "id_switches": self.id_switches,
            "hota": self.hota,
            "association_accuracy": self.association_accuracy,
            "tracker_fps": tracker_fps,
            "camera_frames_per_s": camera_frames_per_s,
        }
        extra = {
            "pck_50mm": self.pck_50mm,
            "pck_150mm": self.pck_150mm,
            "motp_m": self.motp_m,
            "idp": self.idp,
            "idr": self.idr,
            "false_positives": self.false_positives,
            "false_negatives": self.false_negatives,
            "deta": self.deta,
            "assa": self.assa,
            "loca": self.loca,
            "nan_joints": self.nan_joints,
            "pcp_per_actor": self.pcp_per_actor,
            "pcp_per_group": self.pcp_per_group,
            "mpjpe_per_group_mm": self.mpjpe_per_group_mm,
            "pck_per_group": {f"{k}mm": v for k, v in self.pck_per_group.items()},
            "association_accuracy_per_camera": self.association_accuracy_per_camera,
            "false_positive_detections_assigned": self.false_positive_detections_assigned,
            "camera_2d": {name: vars(s) for name, s in self.camera_2d.items()},
            "eval_rate_hz": self.eval_rate_hz,
            "eval_instants": self.eval_instants,
            "from_s": self.from_s,
            "truth_person_instants": self.truth_person_instants,
            "root_threshold_m": self.root_threshold_m,
            "hota_zero_distance_m": self.hota_zero_distance_m,
            "truth_head": self.truth_head,
            "id_switch_events": [{"t_s": t, "person_id": p, "target_id": h, "x_m": x, "y_m": y}
                                 for t, p, h, x, y in self.id_switch_events],
            "switches_by_place": (None if self.switches_by_place is None
                                  else [sw.to_json() for sw in self.switches_by_place]),
            "timeline": self.timeline,
            "floor_grid": self.floor_grid,
        }
        return _clean({**head, **extra})

    def _rows(self) -> tuple[list[tuple[str, str]], list[tuple[str, ...]]]:
        """The figures as the table shows them: (name, value) rows, then one row per camera (name, association
        accuracy, MOTA, IDF1, FP, FN, IDS)."""

        def pct(v):
            return "-" if v is None else f"{100 * v:.1f} %"

        def num(v, fmt="{:.1f}"):
            return "-" if v is None else fmt.format(v)

        rows = [
            ("Pose", ""),
            ("  PCP (alpha 0.5)", pct(self.pcp)),
            ("  MPJPE", num(self.mpjpe_mm, "{:.1f} mm")),
            ("  PCK 50 / 100 / 150 mm", " / ".join(pct(v) for v in (self.pck_50mm, self.pck_100mm, self.pck_150mm))),
            ("  NaN joints in matched estimates", str(self.nan_joints)),
            ("Scored from", f"{self.from_s:g} s (warm-up left out)" if self.from_s else "the start"),
            (f"Identity (ground plane, {self.root_threshold_m:g} m, {self.eval_rate_hz:g} Hz grid)", ""),
            ("  MOTA", pct(self.mota)),
            ("  MOTP", num(self.motp_m, "{:.3f} m")),
            ("  IDF1", pct(self.idf1)),
            ("  ID switches / FP / FN",
             " / ".join("-" if v is None else str(v) for v in (self.id_switches, self.false_positives,
                                                               self.false_negatives))),
            ("  HOTA (DetA, AssA)", f"{pct(self.hota)} ({pct(self.deta)}, {pct(self.assa)})"),
            ("Association accuracy", pct(self.association_accuracy)),
        ]
        if self.tracker_fps is not None or self.camera_frames_per_s is not None:
            rows.append(("Speed (FPS all cameras once / camera frames per s)",
                         f"{num(self.tracker_fps)} / {num(self.camera_frames_per_s, '{:.0f}')}"))
        if self.pcp_per_group:
            rows.insert(2, ("  PCP by bone group", ", ".join(f"{k} {pct(v)}" for k, v in self.pcp_per_group.items())))
        cameras = []
        for cam in dict.fromkeys([*self.camera_2d, *self.association_accuracy_per_camera]):
            s = self.camera_2d.get(cam)
            mot = ((pct(s.mota), pct(s.idf1), str(s.false_positives), str(s.false_negatives), str(s.id_switches))
                   if s else ("-",) * 5)
            cameras.append((cam, pct(self.association_accuracy_per_camera.get(cam)), *mot))
        return rows, cameras

    def table(self) -> str:
        """A readable text table for the terminal."""
        rows, cameras = self._rows()
        width = max(len(r[0]) for r in rows) + 2
        lines = [f"{name:<{width}}{value}" for name, value in rows]
        if cameras:
            lines.append("")
            header = f"{'Camera':<12}{'Assoc.':>9}{'MOTA':>9}{'IDF1':>9}{'FP':>7}{'FN':>7}{'IDS':>6}"
            lines += [header, "-" * len(header)]
            lines += [f"{c:<12}{a:>9}{m:>9}{i:>9}{fp:>7}{fn:>7}{ids:>6}" for c, a, m, i, fp, fn, ids in cameras]
        if self.switches_by_place is not None:
            from crossview.scoring.switches import summary_lines

            lines += ["", *summary_lines(self.switches_by_place)]
        return "\n".join(lines)

    def markdown_blocks(self) -> list:
        """The same table for `crossview.tables` (`--format markdown`): the figures, then the cameras."""
        from crossview.tables import Table

        rows, cameras = self._rows()
        blocks = [Table(("metric", "value"), tuple((name.strip(), value) for name, value in rows))]
        if cameras:
            blocks.append(Table(("camera", "association", "MOTA", "IDF1", "FP", "FN", "IDS"), tuple(cameras)))
        return blocks
