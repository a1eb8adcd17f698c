"""How many cameras a store needs (`crossview plan`): the fewest ceiling-grid cameras whose predicted tracking
quality (`crossview.measure.coverage`) meets a PCP target, optionally over mounting heights and lenses, and a
short sweep that checks the answer against what the tracker then measures.

The candidates are the ceiling grids whose shape fits the floor (`grid_ladder`), in order of camera count; a
grid step is the next candidate of that ladder. The search assumes that more cameras never predict worse
(checked where it evaluates: the table shows every candidate it predicted): it doubles its way up the ladder
until a candidate meets the target, then bisects between the last that did not and the first that did.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from core.errors import CrossviewError

GRID_ASPECT_TOLERANCE = 1.4
"""A grid fits the floor when its columns-to-rows ratio is within this factor of the floor's width-to-depth."""
MIN_CAMERAS = 2
"""The fewest cameras of a candidate: the tracker triangulates from two views or more."""
CONFIRM_SEEDS = (0, 1, 2)
"""The seeds of `--confirm`'s sweep."""
CONFIRM_DURATION_S = 30.0
"""Simulated seconds of each of `--confirm`'s cells."""


@dataclass(frozen=True)
class Candidate:
    """One rig the planner predicted.

    Attributes:
        cameras: rows x cols.
        grid: (rows, cols).
        height_m: the cameras' mounting height above the floor, metres.
        hfov_deg: their lenses' horizontal field of view, degrees.
        predicted_pcp: `Prediction.predicted_pcp`.
        usable_two_view_share: `Prediction.usable_two_view_share`.
        risk_share: `Prediction.risk_share`.
        coverage: the whole `crossview.measure.coverage.Coverage` the figures come from (for its map).
    """

    cameras: int
    grid: tuple[int, int]
    height_m: float
    hfov_deg: float
    predicted_pcp: float
    usable_two_view_share: float
    risk_share: float
    coverage: object = field(default=None, compare=False, repr=False)

    def as_dict(self) -> dict:
        return {"cameras": self.cameras, "grid": list(self.grid), "height_m": round(self.height_m, 3),
                "hfov_deg": round(self.hfov_deg, 3), "predicted_pcp": round(self.predicted_pcp, 4),
                "usable_two_view_share": round(self.usable_two_view_share, 4),
                "risk_share": round(self.risk_share, 4)}


def grid_ladder(width_m: float, depth_m: float, max_cameras: int) -> list[tuple[int, int]]:
    """The candidate grids (rows, cols) of a floor, one per camera count from `MIN_CAMERAS`, in order of count:
    every grid whose columns-to-rows ratio is within `GRID_ASPECT_TOLERANCE` of the floor's width-to-depth, the
    best-fitting one where several have the same count; at most `max_cameras` cameras."""
    from sim.cameras import MAX_GRID

    aspect = width_m / depth_m
    best: dict[int, tuple[float, tuple[int, int]]] = {}
    for rows in range(1, MAX_GRID + 1):
        for cols in range(1, MAX_GRID + 1):
            count = rows * cols
            if count > max_cameras:
                break
            if count < MIN_CAMERAS:
                continue
            misfit = abs(math.log(cols / rows / aspect))
            if misfit <= math.log(GRID_ASPECT_TOLERANCE) and (count not in best or misfit < best[count][0]):
                best[count] = (misfit, (rows, cols))
    return [best[count][1] for count in sorted(best)]


def parse_floats(option: str, text: str, low: float, high: float, unit: str) -> tuple[float, ...]:
    """Comma-separated numbers in (low, high], each named in the error when it is not."""
    values = []
    for part in text.split(","):
        try:
            value = float(part)
        except ValueError:
            raise CrossviewError(f"{option}: {part.strip()!r} is not a number ({unit} in ({low:g}, {high:g}])") \
                from None
        if not low < value <= high:
            raise CrossviewError(f"{option}: {value:g} is outside ({low:g}, {high:g}] {unit}")
        values.append(value)
    if len(set(values)) != len(values):
        raise CrossviewError(f"{option}: {text!r} repeats a value")
    return tuple(values)


def rig_overrides(scenario, grid: tuple[int, int], height_m: float, hfov_deg: float) -> dict:
    return {"cameras.rows": grid[0], "cameras.cols": grid[1],
            "cameras.ceiling_gap_m": round(scenario.store.ceiling_m - height_m, 9), "cameras.hfov_deg": hfov_deg}


def predict_candidate(path, scenario, grid, height_m: float, hfov_deg: float, people: int | None) -> Candidate:
    """The coverage model's prediction for one rig of the planner (the scenario with that grid, height, lens)."""
    from crossview import pipeline
    from crossview.measure.coverage import coverage

    rig = pipeline.load_scenario(path, seed=scenario.seed, people=people,
                                 overrides=rig_overrides(scenario, grid, height_m, hfov_deg))
    cov = coverage(rig)
    pred = cov.prediction
    return Candidate(grid[0] * grid[1], tuple(grid), height_m, hfov_deg, pred.predicted_pcp,
                     pred.usable_two_view_share, pred.risk_share, cov)


def search(ladder: list[tuple[int, int]], target: float, predict_at) -> tuple[int | None, dict[int, Candidate]]:
    """The index in `ladder` of the fewest cameras whose prediction meets `target` (None: not even the last),
    by doubling then bisection (the module's docstring), and every candidate predicted, by index."""
    seen: dict[int, Candidate] = {}

    def meets(i: int) -> bool:
        if i not in seen:
            seen[i] = predict_at(ladder[i])
        return seen[i].predicted_pcp >= target

    return walk(0, len(ladder), meets), seen


@dataclass(frozen=True)
class Plan:
    """The planner's answer.

    Attributes:
        scenario: the scenario's name.
        target_pcp: the target.
        people: the crowd planned for.
        recommended: the chosen rig (the fewest cameras; among equal counts, the first height and lens given).
        candidates: every rig predicted, by camera count, then height and lens.
        ladder: the grids searched (`grid_ladder`), in order of count.
        confirmed: `--confirm`'s measurement (`confirm`), or None.
    """

    scenario: str
    target_pcp: float
    people: int
    recommended: Candidate
    candidates: tuple[Candidate, ...]
    ladder: tuple[tuple[int, int], ...] = ()
    confirmed: dict | None = None

    @property
    def answer(self) -> tuple[int, tuple[int, int], str]:
        """(cameras, grid, by what): the fewest cameras measured to meet the target where `--confirm` found
        them, else the prediction's."""
        c = self.confirmed
        if c and c["meets_target"]:
            return c["cameras"], tuple(c["grid"]), "measurement"
        return self.recommended.cameras, self.recommended.grid, "prediction"

    def as_dict(self) -> dict:
        cameras, grid, by = self.answer
        rec = self.recommended
        return {"scenario": self.scenario, "target_pcp": self.target_pcp, "people": self.people,
                "recommended_cameras": cameras, "grid": list(grid), "recommended_by": by,
                "height_m": round(rec.height_m, 3), "hfov_deg": round(rec.hfov_deg, 3),
                "predicted_cameras": rec.cameras, "predicted_grid": list(rec.grid),
                "predicted_pcp": round(rec.predicted_pcp, 4),
                "candidates": [c.as_dict() for c in self.candidates], "confirmed": self.confirmed}

    _HEADER = ("cameras", "grid", "height m", "lens deg", "predicted PCP", "two views", "at risk")

    def _cells(self) -> list[tuple[tuple[str, ...], bool]]:
        """Each candidate's cells (`_HEADER`) and whether it is the recommendation."""
        return [((str(c.cameras), f"{c.grid[0]} x {c.grid[1]}", f"{c.height_m:.2f}", f"{c.hfov_deg:.1f}",
                  f"{c.predicted_pcp:.3f}", f"{100 * c.usable_two_view_share:.1f}%", f"{100 * c.risk_share:.1f}%"),
                 c == self.recommended) for c in self.candidates]

    def table(self) -> str:
        """The candidates, one line each, the recommendation marked."""
        widths = (7, 7, 8, 8, 13, 9, 7)
        lines = ["  ".join(h.rjust(w) for h, w in zip(self._HEADER, widths))]
        for cells, recommended in self._cells():
            lines.append("  ".join(c.rjust(w) for c, w in zip(cells, widths))
                         + ("  <- recommended" if recommended else ""))
        return "\n".join(lines)

    def candidates_table(self):
        """The same for `crossview.tables` (`--format markdown`): the recommendation marked in its own column."""
        from crossview.tables import Table

        return Table((*self._HEADER, "recommended"),
                     tuple((*cells, "yes" if recommended else "") for cells, recommended in self._cells()))


def plan(path, target_pcp: float, *, people: int | None = None, heights_m: tuple[float, ...] | None = None,
         lenses_deg: tuple[float, ...] | None = None, max_cameras: int | None = None, progress=None) -> Plan:
    """The fewest cameras whose predicted PCP meets `target_pcp`, for each mounting height and lens given.

    Args:
        path: the scenario (a file or a shipped name); its rig must be a ceiling grid.
        target_pcp: in (0, 1].
        people: the crowd (default the scenario's).
        heights_m: mounting heights to try, metres above the floor (default: the scenario's).
        lenses_deg: horizontal fields of view to try, degrees (default: the scenario's).
        max_cameras: the most cameras to try (default: one per square metre of floor, at least 16).
        progress: called with a line as each candidate is predicted, or None.

    Raises:
        CrossviewError: a target outside (0, 1], a rig that is no grid, a height above the ceiling, or a target
            no candidate up to `max_cameras` meets (naming the best prediction and the largest count tried).
    """
    from crossview import pipeline

    if not 0.0 < target_pcp <= 1.0:
        raise CrossviewError(f"--target-pcp: {target_pcp:g} is outside (0, 1]")
    scenario = pipeline.load_scenario(path, people=people)
    rig = scenario.cameras
    if rig.placements or rig.calibration:
        key = "cameras.placements" if rig.placements else "cameras.calibration"
        raise CrossviewError(f"{scenario.where}: {key}: plan searches ceiling grids (cameras.rows and cameras.cols); "
                             "this rig is placed camera by camera")
    store = scenario.store
    heights = heights_m or (store.ceiling_m - rig.ceiling_gap_m,)
    for h in heights:
        if h > store.ceiling_m:
            raise CrossviewError(f"--heights: {h:g} m is above {scenario.where}'s ceiling (store.ceiling_m = "
                                 f"{store.ceiling_m:g} m)")
    lenses = lenses_deg or (rig.hfov_deg,)
    limit = max_cameras or max(16, int(store.width_m * store.depth_m))
    ladder = grid_ladder(store.width_m, store.depth_m, limit)
    if not ladder:
        raise CrossviewError(f"--max-cameras: {limit} holds no grid that fits the {store.width_m:g} x "
                             f"{store.depth_m:g} m floor")
    found: list[Candidate] = []
    predicted: list[Candidate] = []
    for h in heights:
        for lens in lenses:
            def predict_at(grid, h=h, lens=lens):
                c = predict_candidate(path, scenario, grid, h, lens, people)
                if progress:
                    progress(f"{c.cameras} cameras ({grid[0]} x {grid[1]}), {h:g} m, {lens:g} deg: predicted PCP "
                             f"{c.predicted_pcp:.3f}")
                return c
            index, seen = search(ladder, target_pcp, predict_at)
            predicted += list(seen.values())
            if index is not None:
                found.append(seen[index])
    predicted.sort(key=lambda c: (c.cameras, heights.index(c.height_m), lenses.index(c.hfov_deg)))
    if not found:
        best = max(predicted, key=lambda c: c.predicted_pcp)
        largest = max(c.cameras for c in predicted)
        raise CrossviewError(f"--target-pcp: {target_pcp:g} is out of reach: the best prediction is "
                             f"{best.predicted_pcp:.3f} ({best.cameras} cameras, {best.height_m:g} m, "
                             f"{best.hfov_deg:g} deg), and the largest count tried {largest} (--max-cameras "
                             f"{limit})")
    recommended = min(found, key=lambda c: (c.cameras, heights.index(c.height_m), lenses.index(c.hfov_deg)))
    return Plan(scenario.name, target_pcp, scenario.crowd.people, recommended, tuple(predicted), tuple(ladder))


def measure(path, grid: tuple[int, int], height_m: float, hfov_deg: float, out: Path, *, target_pcp: float,
            people: int | None, seeds: tuple[int, ...], duration_s: float, workers: int | None,
            progress: bool) -> dict:
    """The tracker's PCP on one rig: a sweep of `seeds` cells (`crossview.experiments.sweep`, each leaving out the
    default warm-up) into `out`: {cameras, grid, seeds, duration_s, pcp, pcp_mean, pcp_ci95, meets_target, sweep}.

    Raises:
        CrossviewError: a cell failed (its line names it).
    """
    from crossview import pipeline
    from crossview.experiments import sweep
    from crossview.experiments.sweep_report import t_interval

    scenario = pipeline.load_scenario(path)
    fixed = rig_overrides(scenario, grid, height_m, hfov_deg)
    if people is not None:
        fixed["crowd.people"] = people
    axes = tuple(sweep.Axis(key, (value,)) for key, value in fixed.items())
    spec = sweep.SweepSpec(scenario=str(path), axes=axes, seeds=tuple(seeds), duration_s=duration_s,
                           warm_up_s=None)  # (each cell leaves out the default warm-up, as `crossview sweep`'s)
    summary = sweep.run_sweep(spec, out, executor=sweep.Executor.POOL, workers=workers, progress=progress)
    failed = [r for r in summary.rows if r["status"] != "ok"]
    if failed:
        raise CrossviewError(f"--confirm: {len(failed)} of {len(summary.rows)} cells failed: {failed[0]['status']} "
                             f"({out})")
    pcp = [float(r["score"]["pcp"]) for r in summary.rows]
    mean = sum(pcp) / len(pcp)
    low, high = t_interval(pcp)
    return {"cameras": grid[0] * grid[1], "grid": list(grid), "seeds": list(seeds), "duration_s": duration_s,
            "pcp": [round(p, 4) for p in pcp], "pcp_mean": round(mean, 4), "pcp_ci95": [round(low, 4), round(high, 4)],
            "meets_target": mean >= target_pcp, "sweep": str(out)}


def walk(start: int, length: int, meets) -> int | None:
    """The fewest index of a ladder of `length` rigs at which `meets(i)` holds, asking as few as it can from
    `start`: down from a start that meets (one step, then two, four, ... until one falls short, then bisection
    between), or up from one that does not (the same, upward; None where not even the last meets). Assumes that
    `meets` never turns false with more cameras."""
    if meets(start):
        low, high, step = -1, start, 1  # ladder[low] falls short (-1: none asked), ladder[high] meets
        while high - step >= 0:
            if not meets(high - step):
                low = high - step
                break
            high, step = high - step, step * 2
    else:
        low, high, step = start, None, 1
        while low + step < length:
            if meets(low + step):
                high = low + step
                break
            low, step = low + step, step * 2
        if high is None:
            if low == length - 1 or not meets(length - 1):
                return None
            high = length - 1
    while high - low > 1:
        mid = (low + high) // 2
        if meets(mid):
            high = mid
        else:
            low = mid
    return high


def confirm(path, result: Plan, out: Path, *, people: int | None = None, seeds: tuple[int, ...] = CONFIRM_SEEDS,
            duration_s: float = CONFIRM_DURATION_S, workers: int | None = None, progress=None) -> dict:
    """The recommendation measured, then the ladder walked with the tracker to the fewest cameras that meet the
    target (same height and lens): down from a recommendation that meets it (one grid step, then two, four, ...
    until a rig falls short, then bisection between), or up from one that does not. Each rig is a sweep of
    `seeds` cells (`measure`) into out/cN/ (a rerun resumes). Like the prediction's search, it assumes that more
    cameras never measure worse; the measured rigs are all listed.

    Returns:
        {cameras, grid, seeds, duration_s, pcp, pcp_mean, pcp_ci95, meets_target, sweep}: the fewest cameras
        measured to meet the target (else the most measured, `meets_target` false), with `measured` (every rig
        measured, by count) and `steps_below_prediction` (grid steps from the prediction's answer down to it).

    Raises:
        CrossviewError: a cell failed.
    """
    rec = result.recommended
    ladder = list(result.ladder) or [rec.grid]
    start = ladder.index(rec.grid)
    measured: dict[int, dict] = {}

    def meets(i: int) -> bool:
        if i not in measured:
            grid = ladder[i]
            measured[i] = measure(path, grid, rec.height_m, rec.hfov_deg, out / f"c{grid[0] * grid[1]}",
                                  target_pcp=result.target_pcp, people=people, seeds=seeds, duration_s=duration_s,
                                  workers=workers, progress=bool(progress))
            m = measured[i]
            if progress:
                progress(f"measured {m['cameras']} cameras ({grid[0]} x {grid[1]}): PCP {m['pcp_mean']:.3f} "
                         f"(95 % interval {m['pcp_ci95'][0]:.3f} to {m['pcp_ci95'][1]:.3f}): "
                         f"{'meets' if m['meets_target'] else 'below'} {result.target_pcp:g}")
        return measured[i]["meets_target"]

    high = walk(start, len(ladder), meets)
    answer = measured[high] if high is not None else measured[max(measured)]
    return {**answer, "measured": [measured[i] for i in sorted(measured)],
            "steps_below_prediction": start - high if high is not None else None}
