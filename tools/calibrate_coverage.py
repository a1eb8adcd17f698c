"""The coverage model's calibration: the tracker's PCP beside the model's floor quality, and the curve between them.

    python tools/calibrate_coverage.py --fit store_layout1:2,3,4,6,8,12 supermarket:6,9,12,20,30,60 \
        --check convenience:4,8,12,20,30@0,1,2 store_layout2:6,12,28 [--seeds 0,1] [--duration 30] \
        [--out calibration/]

Each SCENARIO:COUNTS[@SEEDS] runs `crossview generate` (the scenario with `--cameras N`, `--seed S`, `--duration`),
`crossview track` (store preset) and `crossview score` (leaving out `crossview run`'s default warm-up) per
camera count and seed, into OUT as
NAME-cN-sS.mcap, .tracks.mcap and .score.json (a rerun skips what is there: the runs take minutes each). Then
it predicts each rig (`crossview.measure.coverage`), fits the calibration curve
PCP = 1 / (1 + exp(-(a + b ln(q / (1 - q))))) of the floor quality q by least squares on the `--fit` scenarios'
runs alone, and prints a Markdown table of every scenario's counts: the floor quality, the prediction through the
fitted curve, the measured PCP (mean and spread over the seeds), and per scenario the rank correlation (Spearman)
of predicted and measured PCP across the counts. docs/coverage.md holds the table, and (a, b) go into
`crossview.measure.coverage.PCP_CALIBRATION`. Not part of the test suite.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from scipy import optimize, stats

from crossview import pipeline
from crossview.measure.coverage import calibrated_pcp, coverage
from crossview.scoring import default_from_s


def parse_spec(text: str, seeds: tuple[int, ...]) -> tuple[str, tuple[int, ...], tuple[int, ...]]:
    """SCENARIO:N1,N2[@S1,S2]: the scenario, its camera counts and its seeds (default `seeds`)."""
    text, _, own = text.partition("@")
    name, _, counts = text.rpartition(":")
    return name, tuple(int(c) for c in counts.split(",")), tuple(int(s) for s in own.split(",")) if own else seeds


def run(out: Path, path: str, count: int, seed: int, duration_s: float) -> dict:
    """One run's score JSON, scored as `crossview run` scores (leaving out its default warm-up): generated and
    tracked unless OUT has them, scored again if OUT's score left out another warm-up."""
    scenario = pipeline.load_scenario(path, seed=seed, duration_s=duration_s, cameras=count)
    stem = out / f"{scenario.name}-c{count}-s{seed}"
    score_path = stem.with_suffix(".score.json")
    rec, tracks = stem.with_suffix(".mcap"), stem.with_suffix(".tracks.mcap")
    from_s = default_from_s(duration_s)
    if score_path.exists() and json.loads(score_path.read_text()).get("from_s", 0.0) == from_s:
        return json.loads(score_path.read_text())
    if not tracks.exists():
        pipeline.generate(scenario, rec, progress=False)
        pipeline.track(rec, tracks, progress=False)
    _, result = pipeline.score(rec, tracks, progress=False, from_s=from_s)
    pipeline.write_json(result, score_path)
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fit", nargs="+", required=True, metavar="SCENARIO:N1,N2")
    parser.add_argument("--check", nargs="*", default=[], metavar="SCENARIO:N1,N2")
    parser.add_argument("--seeds", default="0,1")
    parser.add_argument("--duration", type=float, default=30.0)
    parser.add_argument("--out", type=Path, default=Path("calibration"))
    args = parser.parse_args()
    seeds = tuple(int(s) for s in args.seeds.split(","))
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []  # (role, scenario name, count, grid, prediction, measured pcps)
    for role, specs in (("fit", args.fit), ("check", args.check)):
        for spec in specs:
            path, counts, own_seeds = parse_spec(spec, seeds)
            for count in counts:
                measured = [run(args.out, path, count, seed, args.duration)["pcp"] for seed in own_seeds]
                rig = pipeline.load_scenario(path, cameras=count)
                rows.append((role, rig.name, count, (rig.cameras.rows, rig.cameras.cols), coverage(rig).prediction,
                             measured))
    fit = [(r[4].floor_quality, p) for r in rows if r[0] == "fit" for p in r[5]]
    quality, pcp = np.array(fit).T
    (a, b), _ = optimize.curve_fit(lambda q, a, b: calibrated_pcp(q, (a, b)), quality, pcp, p0=(1.0, 1.0))
    print(f"PCP_CALIBRATION = ({a:.3f}, {b:.3f})  # fitted on {len(fit)} runs")
    print()
    print("| scenario | role | cameras | grid | floor quality | two detecting cameras | predicted PCP | measured PCP "
          "(mean, min-max over seeds) |")
    print("|---|---|---|---|---|---|---|---|")
    for role, name, count, grid, pred, measured in rows:
        predicted = float(calibrated_pcp(pred.floor_quality, (a, b)))
        print(f"| {name} | {role} | {count} | {grid[0]} x {grid[1]} | {pred.floor_quality:.3f} | "
              f"{100 * pred.usable_two_view_share:.1f} % | {predicted:.3f} | {np.mean(measured):.3f} "
              f"({min(measured):.3f}-{max(measured):.3f}) |")
    print()
    errors = []
    for name in dict.fromkeys(r[1] for r in rows):
        mine = [r for r in rows if r[1] == name]
        predicted = [float(calibrated_pcp(r[4].floor_quality, (a, b))) for r in mine]
        measured = [float(np.mean(r[5])) for r in mine]
        errors += [p - m for p, m in zip(predicted, measured)]
        rho = stats.spearmanr(predicted, measured)[0] if len(mine) > 2 else float("nan")
        print(f"{name}: rank correlation {rho:.2f} over {len(mine)} counts; mean |predicted - measured| "
              f"{np.mean(np.abs(np.subtract(predicted, measured))):.3f}")
    print(f"all: mean |predicted - measured| {np.mean(np.abs(errors)):.3f}")


if __name__ == "__main__":
    main()
