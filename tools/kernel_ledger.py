"""The kernel ledger: what compiling each kernel group buys on the whole command it speeds up.

    python tools/kernel_ledger.py [--duration 3] [--repeats 2] [--scenario store_layout1] [--group G ...]

For each group of `core.jit.GROUPS` the command it serves (`crossview generate` for the simulation's groups
and the recording's wire encoders, `crossview track` of a recording made once for the tracker's) runs as a
fresh process, timed from its start to its exit, with every group compiled and with that one group plain
(`CROSSVIEW_JIT_PLAIN=group`), the two interleaved `--repeats` times in this one run; the table gives the
median of each and their ratio (plain / compiled). numba's disk cache is filled by one untimed compiled run
of each command first, so no figure includes compiling. A group under `MIN_RATIO` goes back to numpy or
Python (CONTRIBUTING.md); docs/benchmarks.md holds the table. Not part of the test suite (minutes of wall
time); the machine should be otherwise quiet, or the figures quoted as one noisy run's.
"""

from __future__ import annotations

import argparse
import importlib
import inspect
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from core import jit

MIN_RATIO = 1.3  # a group whose whole command is less than this much faster compiled goes back to Python


def command_of(group: str) -> str:
    """Which crossview command a group's kernels speed up."""
    return "track" if group.startswith("tracker.") else "generate"


def kernels_and_lines(group: str) -> tuple[int, int]:
    """The number of kernels of a group and their source lines (the code numba compiles)."""
    for module in jit.GROUPS[group]:
        importlib.import_module(module)
    kernels = jit.KERNELS[group]
    return len(kernels), sum(len(inspect.getsourcelines(k.py_func)[0]) for k in kernels)


def timed_s(argv: list[str], plain: str) -> float:
    """Wall time of one crossview command in a fresh process, with the group `plain` ("" for none) plain."""
    env = {k: v for k, v in os.environ.items() if k not in (jit.MODE_ENV, jit.PLAIN_ENV)}
    if plain:
        env[jit.PLAIN_ENV] = plain
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "crossview.cli", "--no-progress", *argv], env=env, check=True,
                   stdout=subprocess.DEVNULL)
    return time.perf_counter() - start


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="store_layout1")
    parser.add_argument("--duration", type=float, default=3.0, help="simulated seconds of each command")
    parser.add_argument("--repeats", type=int, default=2, help="interleaved runs of each mode")
    parser.add_argument("--group", action="append", choices=list(jit.GROUPS), help="only these groups")
    args = parser.parse_args(argv)
    groups = args.group or list(jit.GROUPS)
    with tempfile.TemporaryDirectory() as tmp:
        recording = Path(tmp) / "ledger.mcap"
        commands = {
            "generate": ["generate", args.scenario, "--duration", str(args.duration), "-o", str(recording)],
            "track": ["track", str(recording), "-o", str(Path(tmp) / "ledger.tracks.mcap")],
        }
        for argv_ in commands.values():  # fills numba's cache (and makes the recording track reads)
            timed_s(argv_, "")
        print(f"crossview {' '.join(commands['generate'][:4])} / crossview track of it; medians of "
              f"{args.repeats} interleaved runs; ratio = plain / compiled (under {MIN_RATIO}: back to Python)")
        print("| group | kernels | compiled lines | command | compiled (s) | plain (s) | ratio |")
        print("|---|---:|---:|---|---:|---:|---:|")
        for group in groups:
            command = command_of(group)
            times: dict[str, list[float]] = {"": [], group: []}
            for _ in range(args.repeats):
                for plain in times:
                    times[plain].append(timed_s(commands[command], plain))
            compiled_s, plain_s = statistics.median(times[""]), statistics.median(times[group])
            n, lines = kernels_and_lines(group)
            print(f"| {group} | {n} | {lines} | {command} | {compiled_s:.2f} | {plain_s:.2f} | "
                  f"{plain_s / compiled_s:.2f}x |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
