"""`crossview world-stats`: the crowd a scenario simulates, measured: clearances, foot slip, activities, walking
and limb speeds, and how fast the people simulate (`measure`).

Read-only over `sim.world.World`: it advances a fresh world and looks at its truth, its crowd and who is present.
"""

from __future__ import annotations

import math
import time

import numpy as np

from core.records import PoseTruth
from core.types import COCO17
from sim import humanoid as hm
from sim.crowd import Activity
from sim.world import World


def simulation_speed(scenario, seconds: float = 60.0, rate_hz: float = 10.0, seed: int | None = None) -> dict:
    """How much faster than real time the people and their keypoints simulate (no cameras).

    Builds a fresh world and times `advance` at `rate_hz` for `seconds` of simulated time.

    Returns:
        dict with `rate_hz`, `simulated_s`, `wall_s`, `cpu_s` (this process's CPU time, which other
        processes on the machine disturb less), `realtime_factor` (simulated / wall) and
        `realtime_factor_cpu` (simulated / CPU).
    """
    from sim.rng import child_rng

    world = World(scenario, child_rng(scenario.seed if seed is None else seed, "crowd"))
    n = int(round(seconds * rate_hz))
    wall0, cpu0 = time.perf_counter(), time.process_time()
    for k in range(n + 1):
        world.advance(k / rate_hz)
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    return {"rate_hz": rate_hz, "simulated_s": n / rate_hz, "wall_s": wall, "cpu_s": cpu,
            "realtime_factor": n / rate_hz / wall, "realtime_factor_cpu": n / rate_hz / cpu}


def measure(scenario, seed: int | None = None, duration_s: float = 600.0, rate_hz: float = 50.0) -> dict:
    """The issue's figures for one scenario, from `duration_s` seconds of simulation posed at `rate_hz`.

    Returns a flat dict: the minimum pelvis-pelvis and pelvis-shelf distances (hip midpoints of the
    keypoints), the mean horizontal speed of ankles in stance (ankle within 1 cm of its standing
    height, over consecutive samples), the share of person-time walking, standing, browsing and paying,
    arrivals and departures, walking speeds (percentiles and a histogram, sampled once per second), the speeds
    of wrists, ankles and hips of standing and walking people over one 25 fps frame and over one second
    (`sim.limb_speeds`), and the simulation speed at 10 Hz and 100 Hz (`simulation_speed`, 60 s each).
    """
    from sim.limb_speeds import LimbSpeeds
    from sim.rng import child_rng
    from sim.store import rect_distance

    seed = scenario.seed if seed is None else seed
    world = World(scenario, child_rng(seed, "crowd"))
    n = int(round(duration_s * rate_hz))
    obstacles = world.store.obstacles
    min_pair = math.inf
    min_shelf = math.inf
    act_counts = np.zeros(len(Activity))
    speeds = []
    stance_speed_sum = 0.0
    stance_count = 0
    prev: PoseTruth | None = None
    la, ra = COCO17.index("left_ankle"), COCO17.index("right_ankle")
    lh, rh = COCO17.index("left_hip"), COCO17.index("right_hip")
    per_second = int(round(rate_hz))
    limbs = LimbSpeeds(rate_hz)
    for k in range(n + 1):
        truth = world.advance(k / rate_hz)
        doing = world.activities()
        limbs.add(truth, np.array([doing[p] == Activity.WALK for p in truth.person_ids.tolist()], dtype=bool))
        pelvis = (truth.poses[:, lh, :2] + truth.poses[:, rh, :2]) / 2
        if len(pelvis) > 1:
            dd = np.linalg.norm(pelvis[:, None] - pelvis[None], axis=-1)
            np.fill_diagonal(dd, np.inf)
            min_pair = min(min_pair, float(dd.min()))
        for ob in obstacles:
            if len(pelvis):
                min_shelf = min(min_shelf, float(rect_distance(pelvis, ob.center, ob.half, ob.yaw).min()))
        acts = world.crowd.activities()[world.present]
        act_counts += np.bincount(acts, minlength=len(Activity))
        if prev is not None:
            common, ia, ib = np.intersect1d(prev.person_ids, truth.person_ids, return_indices=True)
            if len(common):
                rest = np.array([hm.ANKLE_HEIGHT * world.height_m(int(p)) for p in common])[:, None] + 0.01
                a, b = prev.poses[ia][:, [la, ra]], truth.poses[ib][:, [la, ra]]
                grounded = (a[..., 2] < rest) & (b[..., 2] < rest)
                v = np.linalg.norm(b[..., :2] - a[..., :2], axis=-1) * rate_hz
                stance_speed_sum += float(v[grounded].sum())
                stance_count += int(grounded.sum())
        prev = truth
        if k % per_second == 0:
            crowd = world.crowd
            for s in np.nonzero(world.present)[0]:
                if crowd.agents[s].activity == Activity.WALK:
                    speeds.append(float(np.hypot(*crowd.vel[s])))
    speeds = np.array(speeds) if speeds else np.zeros(1)
    share = act_counts / max(act_counts.sum(), 1)
    edges = np.array([0.0, 0.3, 0.6, 0.9, 1.2, 1.5, 2.0])
    hist = np.histogram(speeds, edges)[0] / len(speeds)
    out = {
        "scenario": scenario.name,
        "simulated_s": n / rate_hz,
        "people": scenario.crowd.people,
        "min_pelvis_distance_m": min_pair,
        "min_pelvis_shelf_distance_m": min_shelf if obstacles else None,
        "mean_stance_foot_speed_m_s": stance_speed_sum / max(stance_count, 1),
        "share_walk": float(share[Activity.WALK]),
        "share_stand": float(share[Activity.STAND]),
        "share_browse": float(share[Activity.BROWSE]),
        "share_checkout": float(share[Activity.CHECKOUT]),
        "arrivals": world.crowd.arrivals,
        "departures": world.crowd.departures,
        "walk_speed_p10_m_s": float(np.percentile(speeds, 10)),
        "walk_speed_median_m_s": float(np.median(speeds)),
        "walk_speed_p90_m_s": float(np.percentile(speeds, 90)),
    }
    for lo, hi, h in zip(edges[:-1], edges[1:], hist):
        out[f"walk_speed_share_{lo:.1f}_{hi:.1f}_m_s"] = float(h)
    out.update(limbs.summary())
    for rate in (10.0, 100.0):
        sp = simulation_speed(scenario, 60.0, rate, seed)
        out[f"realtime_factor_{rate:.0f}hz"] = sp["realtime_factor"]
        out[f"realtime_factor_cpu_{rate:.0f}hz"] = sp["realtime_factor_cpu"]
    return out
