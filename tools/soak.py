"""Soak: a long simulated stream through the tracker in one process, its memory sampled every simulated minute.

    python tools/soak.py [--scenario store_layout2] [--minutes 30] [--json soak.json]

The simulation streams its camera frames (no recording is written) in delivery order straight into
`tracker.Tracker.update`, as a live system would. Every simulated minute the resident memory (VmRSS) of
this process and of the simulation worker process is read from /proc. The verdict compares each later
sample with the first minute's: growth under 10 % passes. Not part of the test suite (it takes as long as
the stream, several minutes of wall time).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import sys
import time
from pathlib import Path

GROWTH_LIMIT = 0.10  # largest allowed growth of memory after the first minute, fraction


def rss_mib(pid: int | str = "self") -> float:
    """Resident memory of a process, MiB (Linux /proc), NaN when it is gone."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return float("nan")


def soak(scenario_name: str, minutes: float, seed: int | None = None) -> dict:
    from core.records import CameraFrame
    from core.types import SKELETONS
    from crossview import pipeline
    from sim.simulate import Simulation

    scenario = pipeline.load_scenario(scenario_name, seed=seed, duration_s=minutes * 60)
    sim = Simulation(scenario, scenario.seed)
    tracker, _ = pipeline.make_tracker("crossview", sim.cameras, "store", None, SKELETONS[sim.skeleton.name])
    samples = []
    next_minute = 1
    frames = 0
    start = time.perf_counter()
    tracker_s = 0.0
    targets = 0
    for event in sim.events(with_poses=False):
        if not isinstance(event, CameraFrame):
            continue
        t = time.perf_counter()
        targets = len(tracker.update(event.frame))
        tracker_s += time.perf_counter() - t
        frames += 1
        if event.truth.delivery_s >= next_minute * 60:
            workers = multiprocessing.active_children()
            samples.append({"minute": next_minute, "wall_s": round(time.perf_counter() - start, 1),
                            "camera_frames": frames, "rss_mib": round(rss_mib(), 1),
                            "worker_rss_mib": round(rss_mib(workers[0].pid), 1) if workers else None,
                            "targets": targets})
            print(json.dumps(samples[-1]), flush=True)
            next_minute += 1
    base = samples[0]["rss_mib"]
    growth = max(s["rss_mib"] for s in samples) / base - 1
    # (the worker has ended by the last sample or two: the stream's tail is delivered after its last block)
    worker = [s["worker_rss_mib"] for s in samples if s["worker_rss_mib"] and s["worker_rss_mib"] > 0]
    worker_growth = max(worker) / worker[0] - 1 if worker else None
    return {"scenario": scenario_name, "minutes": minutes, "seed": scenario.seed, "cameras": len(sim.cameras),
            "camera_frames": frames, "wall_s": round(time.perf_counter() - start, 1),
            "tracker_s": round(tracker_s, 1), "samples": samples,
            "growth_after_first_minute": round(growth, 4),
            "worker_growth_after_first_minute": None if worker_growth is None else round(worker_growth, 4),
            "passed": growth < GROWTH_LIMIT and (worker_growth is None or worker_growth < GROWTH_LIMIT)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="store_layout2")
    parser.add_argument("--minutes", type=float, default=30.0, help="simulated minutes (default 30)")
    parser.add_argument("--seed", type=int)
    parser.add_argument("--json", type=Path, help="write the result here")
    args = parser.parse_args(argv)
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(name, "1")
    result = soak(args.scenario, args.minutes, args.seed)
    worker = result["worker_growth_after_first_minute"] or 0.0
    print(f"{result['scenario']}: {result['minutes']:g} simulated minutes, {result['camera_frames']:,} camera frames "
          f"in {result['wall_s']:.0f} s; memory growth after the first minute "
          f"{100 * result['growth_after_first_minute']:.1f} % (worker {100 * worker:.1f} %): "
          f"{'PASS' if result['passed'] else 'FAIL'} (limit {100 * GROWTH_LIMIT:.0f} %)")
    if args.json:
        from crossview.pipeline import write_json

        write_json(result, args.json)
    return 0 if result["passed"] else 1


if __name__ == "__main__":
    sys.exit(main())
