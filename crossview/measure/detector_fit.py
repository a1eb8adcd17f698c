"""Fitting a detector profile to measured detector statistics (the method of simulated moments).

A profile's parameters are not measured directly: what can be measured, on real detections as on synthetic
ones, is `crossview.measure.detector_stats`'s table. So a profile is fitted by simulating a scenario of the measured
rig with a candidate profile, measuring the same table on the simulated detections, and moving each parameter
by what its statistic still misses, a fixed number of rounds, all with the same seed (common random numbers:
two rounds differ only by the parameters). Each fitted parameter has the one statistic it drives most:

| parameter | statistic it is moved by |
|---|---|
| `offset_m` (per group) | the group's joint error / person size, median |
| `lift_m` (per group) | the group's vertical offset (px at a 400 px person) |
| `joint_miss_prob` (per group) | the group's joint miss rate |
| `noise_frac` | the cross-view reprojection distance (px at 400) |
| `noise_time_s` | the lag-1 correlation of a joint's error |
| `miss_time_s` | P(joint missed next frame given missed now) |
| `miss_prob` | missed person-views |
| `occluded_drop_prob` | the miss rate of the groups whose `joint_miss_prob` is 0 already (occlusion misses too many) |
| `miss_occlusion_gain` | missed person-views, once `miss_prob` is 0 |
| `gross_error_prob` | gross errors |
| `phantom_rate` | false-positive people per camera frame |
| `phantom_keep_prob` | the share of them with >= 6 of 12 joints |

The other parameters (the tails' degrees of freedom, the difficult people's (`difficult_*`, set from the
statistics by hand: docs/sensor-model.md), the self-occlusion drops, fragments, swaps, duplicates, scores,
the offsets' time) stay at the starting profile's values: the tails' were tried and fought the gross errors
over the same p99 (a Student-t offset with few degrees of freedom is a gross error that never ends). The
round with the smallest largest relative deviation is kept. `unreached` says which rows of the kept round are
still more than `REACHED` off their target, and why.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from crossview.measure.detector_stats import GROUPS, detector_stats
from sim.sensing.profiles import JOINT_GROUPS, DetectorConfig, DetectorParams

PERSON_SIZE_M = 1.35
"""The larger side of the box of a standing adult's 12 measured joints (ankles to shoulders), metres: turns a
vertical offset in pixels at a 400 px person into metres of lift."""
SIZE_AT_PX = 400.0
DEFAULT_ROUNDS = 8
MAX_STEP = 2.0  # the most a multiplicative update may change a parameter in one round (either way)
DAMPING = 0.7  # the share of an additive step taken (the statistics move with several parameters at once)
FULL_STEP_ROUNDS = 3
"""Rounds that take the whole `DAMPING` step; after them round k takes DAMPING x FULL_STEP_ROUNDS / (k + 1): a
step shrinking like 1 / k (stochastic approximation), so that a fit whose statistics carry sampling noise settles
instead of stepping across its target and back (a fit of a recording's own profile did that, round after
round, on the rarer joints' miss rates)."""

ROWS: tuple[tuple[str, str | None], ...] = (
    ("error_over_size_median", None), ("error_over_size_p90", None), ("error_over_size_p99", None),
    ("lag1_error_correlation", None), ("gross_error_rate", None), ("miss_rate", None), ("miss_persistence", None),
    ("missed_person_view_rate", None), ("false_positive_people_per_frame", None),
    ("false_positive_people_ge6_per_frame", None), ("cross_view_reprojection_px_at_400", None),
    *((key, group) for group in GROUPS for key in ("error_over_size_median", "vertical_offset_px_at_400", "miss_rate")),
)
"""The rows of the statistics table a fit is judged on: (key, joint group or None for all joints)."""


NOT_TARGETS = ("false_positive_people_per_frame", "false_positive_people_ge6_per_frame")
"""Rows of the shipped real table (`--target shelf-openpose`) that are no target: Shelf's annotation leaves one
of the four people in the room out, and its detections count as false positives (crossview/measure/data)."""
REACHED = 0.25
"""A row within this relative deviation of its target counts as reached."""

MOVED_BY: dict[str, str] = {
    "error_over_size_median": "offset_m", "vertical_offset_px_at_400": "lift_m", "miss_rate": "joint_miss_prob",
    "cross_view_reprojection_px_at_400": "noise_frac", "lag1_error_correlation": "noise_time_s",
    "miss_persistence": "miss_time_s", "missed_person_view_rate": "miss_prob", "gross_error_rate": "gross_error_prob",
    "false_positive_people_per_frame": "phantom_rate", "false_positive_people_ge6_per_frame": "phantom_keep_prob",
}
"""The parameter each statistic moves (per group for the group rows; the all-joint error median and miss rate
follow the groups')."""
BOUNDS: dict[str, tuple[float, float]] = {
    "joint_miss_prob": (0.0, 0.95), "miss_prob": (0.0, 1.0), "gross_error_prob": (0.0, 1.0),
    "phantom_keep_prob": (0.05, 1.0), "phantom_rate": (0.0, 100.0),
}
"""The bounds `update` holds a parameter in."""
LOW_MISS_PROB = 0.02
"""A group's joint miss probability below this that still gives too many misses: the occlusion drops do."""


def value(stats: dict, key: str, group: str | None = None) -> float | None:
    """One figure of a statistics table (a reference's (low, high) range reads as its midpoint)."""
    table = stats if group is None else stats.get("per_group", {}).get(group, {})
    v = table.get(key)
    if isinstance(v, (tuple, list)):
        v = (v[0] + v[1]) / 2
    return None if v is None or not math.isfinite(v) else float(v)


OFFSET_FLOOR_PX = 2.0
"""A vertical offset is compared relative to its target, or to this many pixels (at 400) where the target is
smaller: the knees' and ankles' offsets are a fraction of a pixel, and a tenth of that is no statistic."""


def deviations(stats: dict, target: dict) -> dict[tuple[str, str | None], float]:
    """Per row of `ROWS` that both tables have: (measured - target) / target, relative to at least
    `OFFSET_FLOOR_PX` for vertical offsets (a target of 0 elsewhere: the difference)."""
    out = {}
    for key, group in ROWS:
        got, want = value(stats, key, group), value(target, key, group)
        if got is None or want is None:
            continue
        scale = max(abs(want), OFFSET_FLOOR_PX) if key == "vertical_offset_px_at_400" else abs(want)
        out[(key, group)] = (got - want) / scale if scale else got - want
    return out


@dataclass(frozen=True)
class FitRound:
    """One round of a fit: the parameters simulated, what they measured and the largest relative deviation."""

    params: DetectorParams
    stats: dict
    worst: float


def gain(round_index: int) -> float:
    """The share of a full step round `round_index` (from 0) takes (`FULL_STEP_ROUNDS`)."""
    return DAMPING * min(1.0, FULL_STEP_ROUNDS / (round_index + 1))


def _ratio(got: float | None, want: float | None, power: float, step: float) -> float:
    """(want / got) ** (power x step), bounded to one step; 1 when either is unknown or zero."""
    if not got or not want:
        return 1.0
    return float(np.clip((want / got) ** (power * step), 1.0 / MAX_STEP, MAX_STEP))


def _log_ratio(got: float | None, want: float | None, step: float) -> float:
    """How much longer a correlation time must be for a correlation `got` to become `want` (the ratio of the
    logarithms, exp(-dt / time) being the correlation), to the power `step`, bounded to one step."""
    if got is None or want is None:
        return 1.0
    got, want = (float(np.clip(v, 0.01, 0.99)) for v in (got, want))
    return float(np.clip((math.log(got) / math.log(want)) ** step, 1.0 / MAX_STEP, MAX_STEP))


def update(params: DetectorParams, stats: dict, target: dict, step: float = DAMPING) -> DetectorParams:
    """The next round's parameters: each fitted parameter moved by the deviation of its statistic, taking the
    share `step` of the full move (`gain`)."""
    offset, lift, miss = list(params.offset_m), list(params.lift_m), list(params.joint_miss_prob)
    m_per_px = PERSON_SIZE_M / SIZE_AT_PX
    for group in GROUPS:
        g = JOINT_GROUPS.index(group)
        # The error grows more slowly than the offset (noise and lift add to it): a stronger step.
        offset[g] *= _ratio(value(stats, "error_over_size_median", group),
                            value(target, "error_over_size_median", group), 1.2, step)
        got, want = value(stats, "vertical_offset_px_at_400", group), value(target, "vertical_offset_px_at_400", group)
        if got is not None and want is not None:
            lift[g] += step * (got - want) * m_per_px  # + is below the truth: lift the joint by the excess
        got, want = value(stats, "miss_rate", group), value(target, "miss_rate", group)
        if got is not None and want is not None:
            miss[g] = float(np.clip(miss[g] + step * (want - got), 0.0, 0.95))

    def plus(name: str, key: str, low: float = 0.0, high: float = 1.0) -> float:
        got, want = value(stats, key), value(target, key)
        current = getattr(params, name)
        return current if got is None or want is None else float(np.clip(current + step * (want - got), low, high))

    # Persistence of misses: P(missed | missed) = m + (1 - m) q with q = exp(-dt / miss_time_s).
    rate, want_rate = value(stats, "miss_rate"), value(target, "miss_rate")
    got_q = want_q = None
    if rate is not None and want_rate is not None and value(stats, "miss_persistence") is not None \
            and value(target, "miss_persistence") is not None:
        got_q = (value(stats, "miss_persistence") - rate) / (1.0 - rate)
        want_q = (value(target, "miss_persistence") - want_rate) / (1.0 - want_rate)
    # Occlusion's misses: where a group's own miss probability is already 0 and it still misses too many, or
    # a missed person-view's is and too many views are missed, what is left to lower is what occlusion adds.
    floor = [(value(stats, "miss_rate", g), value(target, "miss_rate", g)) for g in GROUPS
             if params.joint_miss_prob[JOINT_GROUPS.index(g)] <= 0.0]
    floor = [(got, want) for got, want in floor if got and want and got > want]
    drop = params.occluded_drop_prob
    if floor:
        drop = float(np.clip(drop * _ratio(sum(g for g, _ in floor), sum(w for _, w in floor), 1.0, step), 0.0, 1.0))
    gain_occ = params.miss_occlusion_gain
    got_pv, want_pv = value(stats, "missed_person_view_rate"), value(target, "missed_person_view_rate")
    if params.miss_prob <= 0.0 and got_pv and want_pv and got_pv > want_pv:
        gain_occ = float(np.clip(gain_occ * _ratio(got_pv, want_pv, 1.0, step), 0.0, 10.0))
    got_fp, want_fp = value(stats, "false_positive_people_per_frame"), value(target, "false_positive_people_per_frame")
    keep = params.phantom_keep_prob
    if got_fp and want_fp and value(stats, "false_positive_people_ge6_per_frame") is not None \
            and value(target, "false_positive_people_ge6_per_frame") is not None:
        share_got = value(stats, "false_positive_people_ge6_per_frame") / got_fp
        share_want = value(target, "false_positive_people_ge6_per_frame") / want_fp
        keep = float(np.clip(keep + step * (share_want - share_got), 0.05, 1.0))
    return params._replace(
        offset_m=tuple(offset), lift_m=tuple(lift), joint_miss_prob=tuple(miss),
        noise_frac=params.noise_frac * _ratio(value(stats, "cross_view_reprojection_px_at_400"),
                                              value(target, "cross_view_reprojection_px_at_400"), 1.0, step),
        noise_time_s=max(params.noise_time_s, 0.01) * _log_ratio(value(stats, "lag1_error_correlation"),
                                                                 value(target, "lag1_error_correlation"), step),
        miss_time_s=max(params.miss_time_s, 0.01) * _log_ratio(got_q, want_q, step),
        miss_prob=plus("miss_prob", "missed_person_view_rate"),
        gross_error_prob=plus("gross_error_prob", "gross_error_rate"),
        phantom_rate=float(np.clip(params.phantom_rate * _ratio(got_fp, want_fp, 1.0, step), 0.0, 100.0)),
        phantom_keep_prob=keep, occluded_drop_prob=drop, miss_occlusion_gain=gain_occ,
    )


def unreached(best: FitRound, target: dict) -> list[tuple[str, str | None, float, str]]:
    """The rows of `best` further than `REACHED` from `target`: (key, group, relative deviation, why), worst
    first. Why: no parameter is fitted to the statistic, its parameter sits at the bound the fit holds it in,
    or the parameter moved and the statistic did not follow (other parameters move it too: the rounds ran out
    before they agreed, or the model cannot give it with the others' values)."""
    out = []
    for (key, group), dev in deviations(best.stats, target).items():
        if abs(dev) <= REACHED:
            continue
        name = MOVED_BY.get(key)
        if key in ("error_over_size_p90", "error_over_size_p99"):
            why = ("no parameter is fitted to it: the tails (offset_tail_dof, noise_tail_dof) and the difficult "
                   "people (difficult_*) set it, by hand")
        elif name is None or (group is None and key in ("error_over_size_median", "miss_rate")):
            why = "no parameter of its own: it follows the per-group rows"
        else:
            current = getattr(best.params, name)
            if group is not None:
                current = current[JOINT_GROUPS.index(group)]
            low, high = BOUNDS.get(name, (-math.inf, math.inf))
            if name in ("joint_miss_prob", "miss_prob") and dev > 0 and current < LOW_MISS_PROB:
                occlusion = (f"occluded_drop_prob = {best.params.occluded_drop_prob:.3g}" if name == "joint_miss_prob"
                             else f"miss_occlusion_gain = {best.params.miss_occlusion_gain:.3g}")
                why = (f"{name} = {current:.3g}, at or near 0, and still too many: occlusion by the rig's people "
                       f"and shelves ({occlusion}, still falling when the rounds ran out; self_occluded_drop_prob "
                       "not fitted) misses more than the target")
            elif (current <= low and dev > 0) or (current >= high and dev < 0):
                why = f"{name} is at its bound {current:g}"
            else:
                why = (f"{name} = {current:.3g} in the kept round and the statistic did not follow: the other "
                       "parameters move it too (more --rounds or a longer --duration)")
        out.append((key, group, dev, why))
    return sorted(out, key=lambda row: -abs(row[2]))


def measure(scenario, params: DetectorParams, *, seed: int, duration_s: float) -> dict:
    """`detector_stats` of `scenario` simulated for `duration_s` with the detector's parameters `params`."""
    from core.records import CameraFrame
    from sim.simulate import Simulation

    config = DetectorConfig(profile=scenario.detector.profile, self_hit_margin_m=scenario.detector.self_hit_margin_m,
                            occlusion=scenario.detector.occlusion, **params._asdict())
    sim = Simulation(dataclasses.replace(scenario, detector=config), seed=seed)
    frames = (e for e in sim.events(duration_s) if isinstance(e, CameraFrame))
    return detector_stats(frames, sim.cameras, sim.skeleton)


def fit(target: dict, scenario, start: DetectorParams, *, seed: int, duration_s: float,
        rounds: int = DEFAULT_ROUNDS, on_round: Callable[[int, FitRound], None] | None = None) -> FitRound:
    """Fits the profile's parameters to `target` (a `detector_stats` table) on `scenario`.

    Args:
        target: the statistics to reach.
        scenario: a scenario of the rig the target was measured on.
        start: the parameters of the first round.
        seed, duration_s: of every round's simulation.
        rounds: how many rounds.
        on_round: called after each round with its number and result.

    Returns:
        The round whose largest relative deviation from the target is smallest.
    """
    params, best = start, None
    for k in range(rounds):
        stats = measure(scenario, params, seed=seed, duration_s=duration_s)
        dev = deviations(stats, target)
        result = FitRound(params, stats, max((abs(d) for d in dev.values()), default=math.inf))
        if on_round is not None:
            on_round(k, result)
        if best is None or result.worst < best.worst:
            best = result
        params = update(params, stats, target, gain(k))
    return best
