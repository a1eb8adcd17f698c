"""`crossview bench`: speed of every stage on the shipped stores, as medians and ratios from one run.

Speed is measured here and written in notes, never asserted in tests: these machines are noisy.
"""

from __future__ import annotations

import datetime
import filecmp
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from crossview import pipeline, recording

CASES = ("store_layout1", "store_layout2")
# The all-pairs baseline re-partitions every frame; a few seconds of stream give a stable median.
BASELINE_S = 3.0


def _round_times(update_s: list[float], num_cameras: int) -> list[float]:
    """Sums per-update times over consecutive rounds of `num_cameras` updates (one paper 'frame')."""
    rounds = len(update_s) // num_cameras
    return [sum(update_s[i * num_cameras : (i + 1) * num_cameras]) for i in range(rounds)]


def bench_tracker(
    rec_path: Path, method: str = "crossview", preset: str = "store", max_stamp_s: float = float("inf"),
    min_stamp_s: float = 0.0, warm_up_s: float = pipeline.WARM_UP_S,
) -> dict:
    """Times every tracker update over a recording's frames (decoded beforehand, so I/O is excluded).

    Args:
        rec_path: the recording.
        method, preset: which tracker.
        max_stamp_s: only frames stamped before this (the all-pairs baseline is too slow for long runs).
        min_stamp_s: frames stamped before this go through the tracker untimed (it starts its targets there).
        warm_up_s: stamps of the frames a throwaway tracker sees first (`pipeline.warm_up_tracker`), s.
    """
    rec = recording.open_recording(rec_path)
    every = [cf.frame for cf in rec.frames() if cf.frame.stamp_s < max_stamp_s]
    pipeline.warm_up_tracker(method, rec, preset, None, _skeleton(rec), until_s=warm_up_s)  # (compiles stay out)
    tracker, _ = pipeline.make_tracker(method, rec.cameras, preset, None, _skeleton(rec))
    for frame in every:
        if frame.stamp_s >= min_stamp_s:
            break
        tracker.update(frame)
    frames = [f for f in every if f.stamp_s >= min_stamp_s]
    update_s = []
    for frame in frames:
        start = time.perf_counter()
        tracker.update(frame)
        update_s.append(time.perf_counter() - start)
    rounds = _round_times(update_s, len(rec.cameras))
    total = sum(update_s)
    return {
        "method": method,
        "camera_frames": len(frames),
        "tracker_fps_median": 1.0 / statistics.median(rounds) if rounds else None,
        "tracker_fps_mean": len(rounds) / sum(rounds) if rounds else None,
        "camera_frames_per_s": len(frames) / total if total else None,
        "update_ms_p50": 1e3 * float(np.percentile(update_s, 50)),
        "update_ms_p95": 1e3 * float(np.percentile(update_s, 95)),
    }


def _skeleton(rec):
    from core.types import SKELETONS

    return SKELETONS[rec.header.skeleton_name]


def bench_people_only(scenario, duration_s: float) -> dict:
    """Simulated seconds per wall second for the people and their keypoints alone, at 100 Hz."""
    from sim.rng import child_rng
    from sim.world import World

    world = World(scenario, child_rng(scenario.seed, "crowd"))
    ticks = np.arange(0.0, duration_s, 0.01)
    start = time.perf_counter()
    for t in ticks:
        world.advance(float(t))
    wall = time.perf_counter() - start
    return {"people_only_realtime_factor": duration_s / wall}


def bench_read(rec_path: Path) -> dict:
    """Camera frames decoded per second when streaming a recording."""
    start = time.perf_counter()
    count = sum(1 for _ in recording.open_recording(rec_path).frames())
    wall = time.perf_counter() - start
    return {"read_camera_frames_per_s": count / wall, "bytes_per_camera_frame": rec_path.stat().st_size / count}


_CHILD_STOP_S = 10.0
"""How long an interrupted bench gives its `crossview generate` process to end on SIGTERM, seconds."""


def bench_cold_generate(name: str, duration_s: float, out: Path, same_as: Path | None = None) -> dict:
    """`crossview generate` in a new process, timed from its start to its exit: what someone who runs the
    command waits for. Unlike the in-process figure (whose process has imported everything, set numba up
    and, after the first case, loaded the compiled kernels), it includes Python's start, the imports and
    numba's set-up. numba's disk cache must be filled already (by an in-process run of any case), or the
    figure would time the compiler.

    Args:
        same_as: a recording of the same scenario and duration: whether the new process wrote the same
            bytes is reported (it must, or the two figures timed different work).
    """
    command = [sys.executable, "-m", "crossview.cli", "--no-progress", "generate", name,
               "--duration", repr(float(duration_s)), "-o", str(out)]
    start = time.perf_counter()
    with subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as process:
        try:
            _, stderr = process.communicate()
        except BaseException:  # interrupted: the command ends as on SIGTERM (worker stopped, temporary removed)
            process.terminate()
            try:
                process.wait(_CHILD_STOP_S)
            except subprocess.TimeoutExpired:
                process.kill()
            raise
    wall = time.perf_counter() - start
    if process.returncode != 0:
        last = (stderr.strip().splitlines() or ["(nothing on stderr)"])[-1]
        raise RuntimeError(f"{' '.join(command[2:])} exited with {process.returncode}: {last}")
    result = {"cold_generate_s": wall, "cold_generate_realtime_factor": duration_s / wall}
    if same_as is not None:
        result["cold_same_bytes"] = filecmp.cmp(out, same_as, shallow=False)
    return result


def run_case(name: str, duration_s: float, folder: Path, progress: bool) -> dict:
    scenario = pipeline.load_scenario(name, duration_s=duration_s)
    rec_path = folder / f"{name}.mcap"
    gen = pipeline.generate(scenario, rec_path, progress=progress)
    result = {
        "scenario": name,
        "duration_s": duration_s,
        "num_cameras": gen.num_cameras,
        "num_people": scenario.crowd.people,
        "generate_realtime_factor": gen.realtime_factor,
        "generate_running_realtime_factor": gen.running_realtime_factor,
        "generate_startup_s": gen.startup_s,
    }
    result.update(bench_cold_generate(name, duration_s, folder / f"{name}-cold.mcap", same_as=rec_path))
    result.update(bench_people_only(scenario, duration_s))
    result.update(bench_read(rec_path))
    result["crossview"] = bench_tracker(rec_path, "crossview")
    result["baseline"] = bench_tracker(rec_path, "baseline", max_stamp_s=BASELINE_S)
    return result


def format_results(results: list[dict]) -> str:
    lines = [
        f"{'scenario':<15} {'cams':>4} {'people':>6} {'gen x RT':>8} {'running':>7} {'start s':>7} {'cold x RT':>9} "
        f"{'people x RT':>11} {'read fr/s':>9} {'B/frame':>7} {'FPS med':>8} {'FPS mean':>8} {'base FPS':>8}"
    ]
    for r in results:
        lines.append(
            f"{r['scenario']:<15} {r['num_cameras']:>4} {r['num_people']:>6} {r['generate_realtime_factor']:>8.1f} "
            f"{r['generate_running_realtime_factor']:>7.1f} {r['generate_startup_s']:>7.2f} "
            f"{r['cold_generate_realtime_factor']:>9.1f} {r['people_only_realtime_factor']:>11.0f} "
            f"{r['read_camera_frames_per_s']:>9.0f} {r['bytes_per_camera_frame']:>7.0f} "
            f"{r['crossview']['tracker_fps_median']:>8.1f} {r['crossview']['tracker_fps_mean']:>8.1f} "
            f"{r['baseline']['tracker_fps_median']:>8.1f}"
        )
    lines.append("FPS: one frame = every camera updated once (the paper's convention); x RT: faster than real time, "
                 "in this process; running: x RT after the start-up (start s: building the world, loading the "
                 "compiled kernels, the first block); cold: `crossview generate` in a new process, timed from its "
                 "start to its exit (Python's start, the imports and numba's set-up included)")
    if any(r.get("cold_same_bytes") is False for r in results):
        lines.append("WARNING: a new process wrote other bytes than this one for the same scenario: "
                     "the two generate figures timed different work")
    return "\n".join(lines)


def markdown(payload: dict) -> str:
    """docs/benchmarks.md from one `crossview bench` payload: when, where, which version, and the figures."""
    cases = payload["cases"]
    lines = [
        "# Benchmarks",
        "",
        "Written by `crossview bench --duration {:g} -o bench.json --markdown docs/benchmarks.md` from one run;"
        .format(cases[0]["duration_s"]),
        "the only place in the docs with speed figures. Compare figures only within one run: the project's test",
        "machine moves by up to 3x from day to day.",
        "",
        f"- date: {payload['date']}",
        f"- version: crossview-testbed {payload['version']}",
        f"- machine: {payload['machine']}, {payload['cpus']} CPUs, Python {payload['python']}",
        "",
        "| scenario | cameras | people | generate x real time (in process) | once running | start-up s "
        "| fresh `crossview generate` x real time | people only x real time | read camera frames/s | bytes/frame "
        "| tracker FPS (median round) | tracker FPS (mean) | tracker camera frames/s | all-pairs baseline FPS |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in cases:
        t = r["crossview"]
        lines.append(
            f"| {r['scenario']} | {r['num_cameras']} | {r['num_people']} | {r['generate_realtime_factor']:.1f} "
            f"| {r['generate_running_realtime_factor']:.1f} | {r['generate_startup_s']:.2f} "
            f"| {r['cold_generate_realtime_factor']:.1f} | {r['people_only_realtime_factor']:.0f} "
            f"| {r['read_camera_frames_per_s']:.0f} | {r['bytes_per_camera_frame']:.0f} "
            f"| {t['tracker_fps_median']:.0f} | {t['tracker_fps_mean']:.0f} | {t['camera_frames_per_s']:.0f} "
            f"| {r['baseline']['tracker_fps_median']:.1f} |")
    lines += [
        "",
        "Tracker FPS counts a frame as every camera updated once (the paper's convention; its C++ reaches 154 and",
        "34 FPS on the Store layouts of 12 and 28 cameras). Generation is timed in this process (the first case",
        "pays numba's compiles on a cold cache) and as a fresh command from its start to its exit (Python's start,",
        "the imports and numba's set-up included); both write the same bytes, which the bench checks.",
    ]
    return "\n".join(lines) + "\n"


def main(json_path: Path | None = None, duration_s: float = 20.0, progress: bool = True,
         markdown_path: Path | None = None, show=None) -> list[dict]:
    """Times every case and prints the table, or hands it to `show(payload, text)` (the CLI's `--format`)."""
    for path in (json_path, markdown_path):
        if path:
            pipeline.check_writable(path)
    with tempfile.TemporaryDirectory(prefix="crossview-bench-") as tmp:
        results = [run_case(name, duration_s, Path(tmp), progress) for name in CASES]
    payload = {"date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"),
               "version": recording.software_version(), "machine": platform.platform(),
               "cpus": os.cpu_count(), "python": platform.python_version(), "cases": results}
    (show or (lambda _, text: print(text)))(payload, format_results(results))
    if json_path:
        pipeline.write_json(payload, json_path)
    if markdown_path:
        from crossview.experiments.bench_scale import SECTION

        page = markdown(payload)
        old = markdown_path.read_text(encoding="utf-8") if markdown_path.exists() else ""
        if SECTION in old:  # (`crossview bench --scale`'s section is kept)
            page = page.rstrip("\n") + "\n\n" + old[old.index(SECTION):]
        pipeline.write_text(page, markdown_path)
    return results
