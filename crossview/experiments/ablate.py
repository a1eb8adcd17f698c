"""`crossview ablate`: the paper's ablations (Tables S1, 4, 5, Figures 5, 6) run on the testbed's own stores.

Each experiment runs its cells through `crossview.experiments.sweep` (cached per cell: a rerun into the same folder
skips what is finished) or, where it needs files a sweep does not keep, through `crossview.pipeline` with
its outputs cached under the experiment's folder by a key of everything that made them. The numbers go to
`DIR/results.json` (the same version gives the same bytes), the timings to `DIR/timings.json`, and
`crossview.experiments.ablate_report` writes `DIR/report.md` with the paper's figures beside ours.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from core.errors import CrossviewError
from crossview import pipeline
from crossview.experiments import sweep

log = logging.getLogger(__name__)

ABLATE_FORMAT = 1
"""Version of the folder's layout (ablate.json)."""

PRESET = "store"
"""The tracker preset every experiment starts from (the shipped stores' own)."""


@dataclass(frozen=True)
class Settings:
    """How big each experiment is: the full report or the quick one (CI).

    Attributes:
        seeds: seeds of every sweep.
        duration_s: simulated seconds of a sweep cell.
        affinity_scenario: the store of Table S1.
        weights: (w_2d, w_3d) pairs of Table S1.
        reconstruction_scenarios: the stores of Table 4.
        frame_rates: camera frame rates of Figure 5, fps.
        frame_rate_triangulations: the triangulations compared in Figure 5.
        spread_s: simulated seconds of the recording whose point sets give Figure 5's time spread.
        camera_counts: numbers of the Panoptic dome's cameras of Figure 6.
        speed_s: simulated seconds of each Figure 6 recording.
        speed_windows_s: per method, the stamps [from, to) of the frames timed (the frames before go through
            the tracker untimed), s.
        single_view_scenarios: the stores of Table 5; single_view_s: their simulated seconds.
        priors_scenario: the store of the body and joint priors' rows; priors_rows: the names of the rows of
            `PRIORS_ROWS` run (None: all).
    """

    seeds: tuple[int, ...]
    duration_s: float
    affinity_scenario: str
    weights: tuple[tuple[float, float], ...]
    reconstruction_scenarios: tuple[str, ...]
    frame_rates: tuple[float, ...]
    frame_rate_triangulations: tuple[str, ...]
    spread_s: float
    camera_counts: tuple[int, ...]
    speed_s: float
    speed_windows_s: dict = field(default_factory=dict)
    single_view_scenarios: tuple[str, ...] = ("store_layout1", "store_layout2")
    single_view_s: float = 60.0
    priors_scenario: str = "store_layout2"
    priors_rows: tuple[str, ...] | None = None


TABLE_S1_WEIGHTS = ((1.0, 0.0), (0.8, 0.2), (0.6, 0.4), (0.4, 0.6), (0.2, 0.8), (0.0, 1.0))

FULL = Settings(
    seeds=(0, 1, 2), duration_s=20.0, affinity_scenario="store_layout2", weights=TABLE_S1_WEIGHTS,
    reconstruction_scenarios=("store_layout1", "store_layout2"), frame_rates=(10.0, 5.0, 10.0 / 3.0, 2.5, 2.0),
    frame_rate_triangulations=("paper", "conventional", "velocity"), spread_s=20.0,
    camera_counts=(6, 11, 16, 21, 26, 31), speed_s=4.5,
    speed_windows_s={"crossview": (0.5, 4.5), "baseline": (0.2, 0.7)}, single_view_s=60.0,
)
QUICK = Settings(
    seeds=(0,), duration_s=5.0, affinity_scenario="store_layout1", weights=((1.0, 0.0), (0.4, 0.6), (0.0, 1.0)),
    reconstruction_scenarios=("store_layout1",), frame_rates=(10.0, 5.0, 2.5),
    frame_rate_triangulations=("paper", "conventional"), spread_s=5.0, camera_counts=(6, 16, 31), speed_s=1.5,
    speed_windows_s={"crossview": (0.3, 1.5), "baseline": (0.2, 0.4)}, single_view_s=8.0,
    priors_scenario="store_layout1", priors_rows=("none", "all"),
)


@dataclass
class Context:
    """What every experiment is given: the output folder, the settings, the pool size, progress bars."""

    out: Path
    settings: Settings
    workers: int | None
    progress: bool
    timings: dict = field(default_factory=dict)

    def sweep(self, folder: str, spec: sweep.SweepSpec) -> list[dict]:
        """Runs (or resumes) one sweep under out/folder; returns its cells' stored outcomes in grid order."""
        executor = sweep.Executor.SERIAL if self.workers == 1 else sweep.Executor.POOL
        summary = sweep.run_sweep(spec, self.out / folder, executor=executor, workers=self.workers,
                                  progress=self.progress)
        failed = [r for r in summary.rows if r["status"] != "ok"]
        if failed:
            raise CrossviewError(f"{self.out / folder}: cell {failed[0]['label']} failed: {failed[0]['status']}")
        return summary.rows


def _mean(rows: list[dict], name: str, group: str | None = None) -> float:
    """Mean over the rows (seeds) of a score field, or of one entry of a per-group field."""
    values = [r["score"][name] if group is None else r["score"][name][group] for r in rows]
    values = [float(v) for v in values if v is not None]
    return float(np.mean(values)) if values else math.nan


def _by(rows: list[dict], key: str) -> dict:
    """Rows grouped by the value of one axis, in the grid's order."""
    grouped: dict = {}
    for row in rows:
        grouped.setdefault(dict((k, v) for k, v in row["values"])[key], []).append(row)
    return grouped


# ---------------------------------------------------------------- the experiments


def affinity(ctx: Context) -> dict:
    """Table S1: the weights of the 2D and 3D affinity terms (eq. 1) against association accuracy and PCP."""
    s = ctx.settings
    rows = []
    for w_2d, w_3d in s.weights:
        spec = sweep.SweepSpec(s.affinity_scenario, axes=(sweep.Axis("tracker.w_2d", (w_2d,)),
                                                          sweep.Axis("tracker.w_3d", (w_3d,))),
                               seeds=s.seeds, presets=(PRESET,), duration_s=s.duration_s)
        cells = ctx.sweep(f"affinity/w2d-{w_2d:g}-w3d-{w_3d:g}", spec)
        rows.append({"w_2d": w_2d, "w_3d": w_3d, "association_accuracy": _mean(cells, "association_accuracy"),
                     "pcp": _mean(cells, "pcp"), "idf1": _mean(cells, "idf1"),
                     "false_positives": _mean(cells, "false_positives")})
    return {"scenario": s.affinity_scenario, "seeds": list(s.seeds), "duration_s": s.duration_s, "rows": rows}


RECONSTRUCTION_METHODS = ("conventional", "unnormalized", "paper", "velocity")
"""Table 4's rows (the paper's 3DPS is not implemented here) and this tracker's velocity-compensated one, with
the preset's row norm; the paper's row is also run with eq. (11)'s own (`ROW_NORM_AS_PRINTED`)."""

ROW_NORM_AS_PRINTED = "row"
"""`tracker.row_norm` of eq. (11) as printed (the preset divides by the norm of a row's first three entries)."""


def reconstruction(ctx: Context) -> dict:
    """Table 4: the triangulations against PCP of torso, upper arms, lower arms and the whole body; each row
    names its triangulation and row norm, the paper's eq. (11) with its own row norm first."""
    s = ctx.settings
    preset_norm = pipeline.tracker_config(PRESET).row_norm.value
    stores = []
    for scenario in s.reconstruction_scenarios:
        spec = sweep.SweepSpec(scenario, axes=(sweep.Axis("tracker.triangulation", RECONSTRUCTION_METHODS),),
                               seeds=s.seeds, presets=(PRESET,), duration_s=s.duration_s)
        groups = [((method, preset_norm), cells) for method, cells in
                  _by(ctx.sweep(f"reconstruction/{scenario}", spec), "tracker.triangulation").items()]
        printed = sweep.SweepSpec(scenario, axes=(sweep.Axis("tracker.triangulation", ("paper",)),
                                                  sweep.Axis("tracker.row_norm", (ROW_NORM_AS_PRINTED,))),
                                  seeds=s.seeds, presets=(PRESET,), duration_s=s.duration_s)
        paper_at = [key for key, _ in groups].index(("paper", preset_norm))
        groups.insert(paper_at, (("paper", ROW_NORM_AS_PRINTED),
                                 ctx.sweep(f"reconstruction/{scenario}-row-norm-{ROW_NORM_AS_PRINTED}", printed)))
        rows = [{"triangulation": method, "row_norm": norm,
                 **{part: _mean(cells, "pcp_per_group", part) for part in ("torso", "upper_arms", "lower_arms")},
                 "pcp": _mean(cells, "pcp"), "mpjpe_mm": _mean(cells, "mpjpe_mm"), "idf1": _mean(cells, "idf1")}
                for (method, norm), cells in groups]
        stores.append({"scenario": scenario, "rows": rows})
    return {"seeds": list(s.seeds), "duration_s": s.duration_s, "row_norm": preset_norm, "stores": stores}


FRAME_RATE_SCENARIO = "store_layout1"


def point_set_spread_s(rec_path: Path, max_age_s: float) -> float:
    """Figure 5's "average time difference within every 2D joint collection": over every true detection of
    a recording, in delivery order, the mean age t - t_i of the points its person's collection J_t^k holds
    then (the latest point of each camera that saw the person within `max_age_s`, eq. 6), s.

    Taken per person from the truth (which detection is whom), so it measures the input, the same for every
    tracker; the newest point (age 0) counts in the mean, as it does in the collection.
    """
    from crossview import recording

    rec = recording.open_recording(rec_path)
    latest: dict[int, dict[str, float]] = {}
    total, count = 0.0, 0
    for cf in rec.frames():
        t, camera = cf.frame.stamp_s, cf.frame.camera
        for person in {int(p) for p in cf.truth.person_ids if p >= 0}:
            seen = latest.setdefault(person, {})
            seen[camera] = t
            ages = [t - t_i for t_i in seen.values() if t - t_i <= max_age_s]
            if len(ages) >= 2:
                total += float(np.mean(ages))
                count += 1
    return total / count if count else math.nan


def frame_rate(ctx: Context) -> dict:
    """Figure 5: PCP against the cameras' frame rate, time-weighted against conventional triangulation, and
    the mean time spread inside the point sets at each rate."""
    s = ctx.settings
    spec = sweep.SweepSpec(FRAME_RATE_SCENARIO, axes=(sweep.Axis("clock.fps", s.frame_rates),
                                                      sweep.Axis("tracker.triangulation", s.frame_rate_triangulations)),
                           seeds=s.seeds, presets=(PRESET,), duration_s=s.duration_s)
    cells = ctx.sweep("frame-rate/sweep", spec)
    max_age_s = pipeline.tracker_config(PRESET).max_observation_age_s
    rows = []
    for fps, at_rate in _by(cells, "clock.fps").items():
        scenario = pipeline.load_scenario(FRAME_RATE_SCENARIO, seed=s.seeds[0], duration_s=s.spread_s,
                                          overrides={"clock.fps": fps})
        rec = _cached_recording(ctx.out / "frame-rate" / "recordings", scenario, ctx.progress)
        by_method = _by(at_rate, "tracker.triangulation")
        rows.append({"fps": fps, "spread_s": point_set_spread_s(rec, max_age_s),
                     "pcp": {m: _mean(c, "pcp") for m, c in by_method.items()},
                     "lower_arms": {m: _mean(c, "pcp_per_group", "lower_arms") for m, c in by_method.items()},
                     "idf1": {m: _mean(c, "idf1") for m, c in by_method.items()},
                     "mpjpe_mm": {m: _mean(c, "mpjpe_mm") for m, c in by_method.items()}})
    return {"scenario": FRAME_RATE_SCENARIO, "seeds": list(s.seeds), "duration_s": s.duration_s,
            "max_observation_age_s": max_age_s, "rows": rows}


SPEED_SCENARIO = "panoptic_dome"
SPEED_METHODS = ("crossview", "baseline")


def speed(ctx: Context) -> dict:
    """Figure 6: time per round (every camera once) against the number of the Panoptic dome's cameras, the
    iterative tracker against the all-pairs baseline, with exponents fitted in log-log.

    Timed serially in this process (`crossview.experiments.bench.bench_tracker`), one method at a time; the numbers are
    timings, so they go to timings.json, and only the camera counts and frame counts to results.json.
    """
    from crossview.experiments import bench

    s = ctx.settings
    counts, frames = [], []
    times: dict[str, list[float]] = {m: [] for m in SPEED_METHODS}
    for n in s.camera_counts:
        scenario = pipeline.load_scenario(SPEED_SCENARIO, seed=0, duration_s=s.speed_s, cameras=n)
        rec = _cached_recording(ctx.out / "speed" / "recordings", scenario, ctx.progress)
        counts.append(n)
        timed = {}
        for method in SPEED_METHODS:
            start_s, end_s = s.speed_windows_s[method]
            result = bench.bench_tracker(rec, method, PRESET, max_stamp_s=end_s, min_stamp_s=start_s,
                                         warm_up_s=min(start_s, pipeline.WARM_UP_S))
            times[method].append(1.0 / result["tracker_fps_mean"])
            timed[method] = result["camera_frames"]
        frames.append(timed)
        log.info("Figure 6: %d cameras: %s", n, {m: f"{1e3 * t[-1]:.1f} ms" for m, t in times.items()})
    ctx.timings["speed"] = {
        "round_ms": {m: [1e3 * t for t in ts] for m, ts in times.items()},
        "exponent": {m: fitted_exponent(counts, ts) for m, ts in times.items()},
    }
    return {"scenario": SPEED_SCENARIO, "camera_counts": counts, "timed_camera_frames": frames,
            "windows_s": {m: list(w) for m, w in s.speed_windows_s.items()}, "preset": PRESET}


def fitted_exponent(counts, seconds) -> float:
    """b of the least-squares fit log t = a + b log n: how the time per round grows with the cameras."""
    if len(counts) < 2:
        return math.nan
    return float(np.polyfit(np.log(np.asarray(counts, float)), np.log(np.asarray(seconds, float)), 1)[0])


def single_view(ctx: Context) -> dict:
    """Table 5: per-camera MOTA and IDF1 of a single-view 2D tracker (SORT per camera) against the
    cross-view tracker, on the same detections (`crossview.experiments.table5`)."""
    from crossview.experiments.table5 import per_camera_table

    s = ctx.settings
    stores = []
    for name in s.single_view_scenarios:
        scenario = pipeline.load_scenario(name, seed=0, duration_s=s.single_view_s)
        rec = _cached_recording(ctx.out / "single-view" / "recordings", scenario, ctx.progress)
        tracks = rec.with_suffix(".tracks.mcap")
        if not tracks.is_file():
            pipeline.track(rec, tracks, preset=PRESET, progress=ctx.progress)
        stores.append(per_camera_table(rec, tracks).to_json())
    return {"duration_s": s.single_view_s, "stores": stores}


PRIORS_OFF = {"limb_velocity_window_s": 0.0, "velocity_quadratic": False, "joint_gate_m": 0.0,
              "bone_prior_tolerance": 0.0, "bone_symmetry": False, "head_bones": False, "bone_prior_resolve": False}
"""The tracker's body and joint priors (docs/tracker.md, "Body and joint priors"), every one off: the paper's
updates, which each row of the `priors` experiment changes."""

PRIORS_ROWS = (
    ("none", {}),
    ("limb_velocity_window_s", {"limb_velocity_window_s": 0.2}),
    ("velocity_quadratic", {"velocity_quadratic": True}),
    ("joint_gate_m", {"joint_gate_m": 0.25}),
    ("bone_prior_tolerance", {"bone_prior_tolerance": 0.15}),
    ("bone_symmetry", {"bone_prior_tolerance": 0.15, "bone_symmetry": True}),
    ("head_bones", {"bone_prior_tolerance": 0.15, "head_bones": True}),
    ("bone_prior_resolve", {"bone_prior_tolerance": 0.15, "bone_prior_resolve": True}),
    ("all", {"limb_velocity_window_s": 0.2, "velocity_quadratic": True, "joint_gate_m": 0.25,
             "bone_prior_tolerance": 0.15, "bone_symmetry": True, "head_bones": True, "bone_prior_resolve": True}),
)
"""The rows of the `priors` experiment: a name and the switches it turns on over `PRIORS_OFF` (the bone prior's
own switches, symmetry, head bones and the re-solve, need its tolerance)."""

def priors(ctx: Context) -> dict:
    """Each body and joint prior alone and all together, over the `store` preset with every prior off: PCP by
    bone group, MPJPE and IDF1 on the store where the head and the forearms lose most (issue 46)."""
    s = ctx.settings
    rows = []
    for name, changes in PRIORS_ROWS:
        if s.priors_rows is not None and name not in s.priors_rows:
            continue
        values = {**PRIORS_OFF, **changes}
        spec = sweep.SweepSpec(s.priors_scenario, axes=tuple(sweep.Axis(f"tracker.{k}", (v,))
                                                             for k, v in values.items()),
                               seeds=s.seeds, presets=(PRESET,), duration_s=s.duration_s)
        cells = ctx.sweep(f"priors/{name}", spec)
        rows.append({"switch": name, "changes": changes, "pcp": _mean(cells, "pcp"),
                     **{group: _mean(cells, "pcp_per_group", group) for group in PCP_GROUPS},
                     "mpjpe_mm": _mean(cells, "mpjpe_mm"), "idf1": _mean(cells, "idf1")})
    return {"scenario": s.priors_scenario, "seeds": list(s.seeds), "duration_s": s.duration_s, "rows": rows}


PCP_GROUPS = ("head", "torso", "upper_arms", "lower_arms", "upper_legs", "lower_legs")
"""The PCP bone groups of the score (`crossview.scoring.pose.PCP_BONE_GROUPS`)."""


@dataclass(frozen=True)
class Experiment:
    """One of the paper's ablations: its name on the command line, its title, and what runs it."""

    name: str
    title: str
    run: Callable[[Context], dict]


EXPERIMENTS = {e.name: e for e in (
    Experiment("affinity", "Table S1: affinity weights", affinity),
    Experiment("reconstruction", "Table 4: 3D reconstruction methods", reconstruction),
    Experiment("frame-rate", "Figure 5: PCP against the cameras' frame rate", frame_rate),
    Experiment("speed", "Figure 6: time per round against the number of cameras", speed),
    Experiment("single-view", "Table 5: single-view against cross-view tracking, per camera", single_view),
    Experiment("priors", "Beyond the paper: the body and joint priors, each alone and all together", priors),
)}


# ---------------------------------------------------------------- cached recordings


def _cached_recording(folder: Path, scenario, progress: bool) -> Path:
    """The recording of a resolved scenario under `folder`, named by a key of the scenario, the content of
    the files it names (`sweep.content_digest`) and the package version: generated once, found by a rerun."""
    from crossview.recording import software_version

    key = hashlib.sha256(f"{sweep.content_digest(scenario)} {software_version()}".encode()).hexdigest()[:16]
    path = folder / f"{scenario.name}-{key}.mcap"
    if not path.is_file():
        pipeline.generate(scenario, path, progress=progress)
    return path


# ---------------------------------------------------------------- the command


def parse_names(names: list[str]) -> list[str]:
    """The experiments asked for (all when none), in the report's order.

    Raises:
        CrossviewError: an unknown name (the valid ones listed).
    """
    for name in names:
        if name not in EXPERIMENTS:
            raise CrossviewError(f"experiment {name!r} is unknown; valid: {', '.join(EXPERIMENTS)}")
    return [n for n in EXPERIMENTS if n in names] if names else list(EXPERIMENTS)


def check_output(out: Path, quick: bool) -> dict:
    """The folder's identity (ablate.json); refuses a file, or a folder holding an ablation of another size
    or version (creates nothing).

    Raises:
        CrossviewError: `out` is a file, or holds another ablation.
    """
    from crossview.recording import software_version

    wanted = {"format": ABLATE_FORMAT, "quick": quick, "version": software_version()}
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise CrossviewError(f"--output {out}: is a file; choose a folder for the ablations")
    found = out / "ablate.json"
    if found.is_file():
        try:
            held = json.loads(found.read_text(encoding="utf-8"))
        except (OSError, ValueError, UnicodeDecodeError) as e:
            raise CrossviewError(f"{found}: unreadable ({e}); choose another --output") from None
        for key, value in wanted.items():
            if held.get(key) != value:
                raise CrossviewError(f"--output {out}: holds ablations with {key} {json.dumps(held.get(key))}, these "
                                     f"have {json.dumps(value)}; choose another --output or remove that folder")
    elif out.is_dir() and any(out.iterdir()):
        raise CrossviewError(f"--output {out}: is not empty and holds no ablate.json; choose another --output")
    return wanted


@dataclass(frozen=True)
class AblateSummary:
    """What `run` wrote: the report, the experiments run and the wall time, s."""

    report: Path
    experiments: list[str]
    wall_s: float


def run(out: Path, names: list[str] | None = None, *, quick: bool = False, workers: int | None = None,
        progress: bool = True, command: str = "crossview ablate") -> AblateSummary:
    """Runs the experiments (all by default) into `out` and writes results.json, timings.json and report.md.

    Raises:
        CrossviewError: bad input (found before anything runs), or a cell that failed.
    """
    from crossview.experiments import ablate_report

    chosen = parse_names(list(names or []))
    out = Path(out)
    wanted = check_output(out, quick)
    pipeline.write_json(wanted, out / "ablate.json")
    ctx = Context(out, QUICK if quick else FULL, workers, progress)
    start = time.perf_counter()
    results = {}
    for name in chosen:
        began = time.perf_counter()
        log.info("ablation %s: %s", name, EXPERIMENTS[name].title)
        results[name] = EXPERIMENTS[name].run(ctx)
        ctx.timings.setdefault("wall_s", {})[name] = time.perf_counter() - began
    wall_s = time.perf_counter() - start
    ctx.timings["total_wall_s"] = wall_s
    pipeline.write_json({"ablate": wanted, "experiments": results}, out / "results.json")
    pipeline.write_json(ctx.timings, out / "timings.json")
    report = ablate_report.write_report(out, results, ctx.timings, titles={n: EXPERIMENTS[n].title for n in chosen},
                                        quick=quick, command=command)
    return AblateSummary(report, chosen, wall_s)
