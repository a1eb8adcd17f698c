"""What `run --live --speed max` costs against `run`, and what one client loses (docs/recording-format.md).

    python tools/live_rate.py [--scenario store_layout1] [--duration 10] [--seed 0] [--repeats 2] [--read-delay-s 0]

Alternates, `--repeats` times each in this one process, a plain run's two stages (`pipeline.generate`, then
`pipeline.track`) and a live run (`pipeline.live_run` on a `crossview.live` server at --speed max) with one client
connected (the tests' independent `websockets` client, tests/crossview/live_client.py, reading at once or one
message per `--read-delay-s`). Prints, per run, camera frames per wall second from the start of generating to the
tracks file written, the tracker's FPS and generation's real-time factor once running; for the live run, the messages
the client received of the files' (the rest are the SDK's drops). Scoring is left out: it is the same in both.
Not part of the test suite (a minute of wall time).
"""

from __future__ import annotations

import argparse
import math
import re
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from crossview import live, pipeline  # noqa: E402
from tests.crossview.live_client import collect  # noqa: E402


def file_count(*paths) -> int:
    from mcap.reader import make_reader

    count = 0
    for path in paths:
        with open(path, "rb") as f:
            count += sum(1 for _ in make_reader(f).iter_messages(log_time_order=False))
    return count


def plain(scenario, folder: Path) -> dict:
    rec, tracks = folder / "plain.mcap", folder / "plain.tracks.mcap"
    start = time.perf_counter()
    gen = pipeline.generate(scenario, rec, progress=False)
    trk = pipeline.track(rec, tracks, progress=False)
    wall = time.perf_counter() - start
    return {"frames_per_s": gen.num_frames / wall, "wall_s": wall, "tracker_fps": trk.tracker_fps,
            "generate_x": gen.running_realtime_factor}


def live_run(scenario, folder: Path, read_delay_s: float) -> dict:
    rec, tracks = folder / "live.mcap", folder / "live.tracks.mcap"
    got: dict = {}
    threads = []

    def announce(line: str) -> None:
        url = re.search(r"ws://\S+", line).group(0).rstrip(";,)")
        thread = threading.Thread(target=lambda: got.update(received=collect(
            url, quiet_s=10.0, timeout_s=600.0, read_delay_s=read_delay_s)))
        thread.start()
        threads.append(thread)
        time.sleep(0.5)  # (the client connects before the first message)

    with live.live_stream(0, math.inf, announce) as stream:
        start = time.perf_counter()
        gen, trk = pipeline.live_run(scenario, rec, tracks, progress=False, live=stream())
        wall = time.perf_counter() - start
    threads[0].join(120)
    received = sum(len(v) for v in got["received"].values())
    return {"frames_per_s": gen.num_frames / wall, "wall_s": wall, "tracker_fps": trk.tracker_fps,
            "generate_x": gen.running_realtime_factor, "received": received, "in_files": file_count(rec, tracks)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="store_layout1")
    parser.add_argument("--duration", type=float, default=10.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--read-delay-s", type=float, default=0.0)
    args = parser.parse_args()
    scenario = pipeline.load_scenario(args.scenario, duration_s=args.duration, seed=args.seed)
    best: dict = {}
    with tempfile.TemporaryDirectory() as folder:
        for repeat in range(args.repeats):
            for name, measure in (("run", lambda: plain(scenario, Path(folder))),
                                  ("run --live --speed max", lambda: live_run(scenario, Path(folder),
                                                                              args.read_delay_s))):
                figures = measure()
                extra = (f", client received {figures['received']} of {figures['in_files']} messages "
                         f"({figures['in_files'] - figures['received']} dropped)") if "received" in figures else ""
                print(f"{repeat + 1}: {name}: {figures['frames_per_s']:.1f} camera frames/s ({figures['wall_s']:.2f} s "
                      f"wall), tracker {figures['tracker_fps']:.1f} FPS, generating {figures['generate_x']:.1f}x real "
                      f"time once running{extra}", flush=True)
                if name not in best or figures["frames_per_s"] > best[name]["frames_per_s"]:
                    best[name] = figures
    plain_best, live_best = best["run"], best["run --live --speed max"]
    print(f"best of {args.repeats}: {args.scenario} seed {args.seed}, {args.duration:g} s: run "
          f"{plain_best['frames_per_s']:.1f}, run --live --speed max {live_best['frames_per_s']:.1f} camera frames/s "
          f"(ratio {live_best['frames_per_s'] / plain_best['frames_per_s']:.2f})")


if __name__ == "__main__":
    main()
