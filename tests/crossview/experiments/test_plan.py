"""`crossview plan`: the grid ladder, the search against a plain scan, the plan file, and bad input."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from crossview.cli import main
from crossview.experiments.plan import GRID_ASPECT_TOLERANCE, Candidate, grid_ladder, search, walk
from tests.crossview.test_cli import _run_bad


def test_the_ladder_holds_one_grid_per_count_that_fits_the_floor():
    ladder = grid_ladder(18.0, 12.0, 40)
    counts = [r * c for r, c in ladder]
    assert counts == sorted(set(counts)) and max(counts) <= 40 and min(counts) >= 2
    for rows, cols in ladder:
        assert abs(math.log(cols / rows / 1.5)) <= math.log(GRID_ASPECT_TOLERANCE)
    # The convenience store: 3 x 4 and 4 x 5 and 5 x 6 are on it, 1 x 12 is not.
    assert {(3, 4), (4, 5), (5, 6), (2, 4)} <= set(ladder) and (1, 12) not in ladder
    # Each rung is the grid `--cameras N` fits to the same floor (the one rule for a count's grid).
    from sim.cameras import camera_grid

    assert all(camera_grid(r * c, 18.0, 12.0) == (r, c) for r, c in ladder)


@pytest.mark.parametrize("seed", range(20))
def test_the_search_finds_what_a_plain_scan_finds_on_a_rising_prediction(seed):
    rng = np.random.default_rng(seed)
    ladder = [(1, n) for n in range(1, int(rng.integers(1, 60)) + 1)]
    rising = np.sort(rng.uniform(0.0, 1.0, len(ladder)))
    target = float(rng.uniform(0.0, 1.05))
    calls = []

    def predict_at(grid):
        calls.append(grid)
        return Candidate(grid[1], grid, 3.0, 90.0, float(rising[grid[1] - 1]), 1.0, 0.0)

    index, seen = search(ladder, target, predict_at)
    scan = next((i for i, p in enumerate(rising) if p >= target), None)
    assert index == scan
    assert len(calls) == len(set(calls)) <= 2 * math.ceil(math.log2(len(ladder) + 1)) + 2  # each grid once, few


def test_plan_writes_the_fewest_cameras_that_meet_the_target_and_their_map(tmp_path, capsys):
    out = tmp_path / "plan" / "l1.json"
    assert main(["--no-progress", "plan", "store_layout1", "--target-pcp", "0.6", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    plan = json.loads(out.read_text())
    assert isinstance(plan["recommended_cameras"], int) and plan["grid"][0] * plan["grid"][1] == \
        plan["recommended_cameras"]
    assert plan["confirmed"] is None
    for c in plan["candidates"]:
        assert set(c) >= {"cameras", "grid", "predicted_pcp", "usable_two_view_share"}
    meeting = [c["cameras"] for c in plan["candidates"] if c["predicted_pcp"] >= 0.6]
    failing = [c["cameras"] for c in plan["candidates"] if c["predicted_pcp"] < 0.6]
    assert plan["recommended_cameras"] == min(meeting) and all(f < min(meeting) for f in failing)
    assert f"recommended: {plan['recommended_cameras']} cameras" in printed
    assert (tmp_path / "plan" / "l1.png").stat().st_size > 0


@pytest.mark.parametrize("target", ["0", "1.5", "-0.2", "nan"])
def test_a_target_outside_0_1_is_named_and_nothing_written(tmp_path, capsys, target):
    out = tmp_path / "p.json"
    err = _run_bad(capsys, ["plan", "store_layout1", "--target-pcp", target, "-o", str(out)])
    assert "--target-pcp" in err and "(0, 1]" in err
    assert not out.exists()


def test_an_impossible_target_names_the_best_prediction_and_the_largest_count(tmp_path, capsys):
    out = tmp_path / "p.json"
    err = _run_bad(capsys, ["--no-progress", "plan", "store_layout1", "--target-pcp", "0.999", "--max-cameras", "4",
                            "-o", str(out)])
    assert "out of reach" in err and "best prediction" in err and "largest count tried 4" in err
    assert not out.exists() and not out.with_suffix(".png").exists()


def test_a_height_above_the_ceiling_or_a_placed_rig_is_refused(tmp_path, capsys):
    out = tmp_path / "p.json"
    err = _run_bad(capsys, ["plan", "store_layout1", "--target-pcp", "0.9", "--heights", "2.5,9", "-o", str(out)])
    assert "--heights: 9 m is above" in err and "store.ceiling_m" in err
    err = _run_bad(capsys, ["plan", "store_layout1", "--target-pcp", "0.9", "--lenses", "90,wide", "-o", str(out)])
    assert "--lenses: 'wide' is not a number" in err
    placed = tmp_path / "placed.toml"
    placed.write_text("[store]\nwidth_m = 4.0\ndepth_m = 4.0\n[[cameras.placements]]\nposition_m = [2.0, 2.0, 2.8]\n"
                      "look_at_m = [2.0, 2.0, 0.0]\n")
    err = _run_bad(capsys, ["plan", str(placed), "--target-pcp", "0.9", "-o", str(out)])
    assert "cameras.placements" in err and "grids" in err
    assert not out.exists()


def test_confirm_walks_the_ladder_to_the_fewest_cameras_the_tracker_measures_meeting_the_target(tmp_path, capsys):
    out = tmp_path / "l1.json"
    assert main(["--no-progress", "plan", "store_layout1", "--target-pcp", "0.5", "--confirm", "--seeds", "0,1",
                 "--duration", "1.5", "--workers", "1", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    plan = json.loads(out.read_text())
    confirmed = plan["confirmed"]
    measured = {m["cameras"]: m for m in confirmed["measured"]}
    assert plan["predicted_cameras"] in measured  # the prediction's answer is measured first
    for m in measured.values():
        assert m["seeds"] == [0, 1] and len(m["pcp"]) == 2
        low, high = m["pcp_ci95"]
        assert low <= m["pcp_mean"] <= high and m["pcp_mean"] == pytest.approx(np.mean(m["pcp"]), abs=1e-4)
        assert m["meets_target"] == (m["pcp_mean"] >= 0.5)
        # The sweep's own results hold the cells: the rig's grid, the seeds.
        results = json.loads((tmp_path / "l1.confirm" / f"c{m['cameras']}" / "results.json").read_text())
        cells = results["cells"] if isinstance(results, dict) else results
        assert len(cells) == 2
    # The answer is the fewest measured that meet the target, and the rig one grid step below it, measured too,
    # does not (unless the answer is the ladder's first).
    meeting = sorted(c for c, m in measured.items() if m["meets_target"])
    assert confirmed["meets_target"] and confirmed["cameras"] == meeting[0]
    from crossview import pipeline

    store = pipeline.load_scenario("store_layout1").store
    ladder = [r * c for r, c in grid_ladder(store.width_m, store.depth_m, max(16, int(store.width_m * store.depth_m)))]
    below = [c for c in ladder if c < meeting[0]]
    assert not below or (below[-1] in measured and not measured[below[-1]]["meets_target"])
    assert plan["recommended_cameras"] == confirmed["cameras"] and plan["recommended_by"] == "measurement"
    assert confirmed["steps_below_prediction"] == ladder.index(plan["predicted_cameras"]) - ladder.index(
        confirmed["cameras"])
    assert "confirmed:" in printed and "measured:" in printed


@pytest.mark.parametrize("length", [1, 2, 7, 16])
def test_the_measured_walk_finds_the_fewest_meeting_rig_from_any_start(length):
    """`walk` against the plain answer (the first index that meets, by looking at all), for every threshold and
    start on ladders of several lengths, asking each rig at most once and fewer than the ladder holds when long."""
    for first in range(length + 1):  # index of the first rig that meets (length: none does)
        for start in range(length):
            asked = []

            def meets(i, asked=asked, first=first):
                assert 0 <= i < length and i not in asked
                asked.append(i)
                return i >= first

            assert walk(start, length, meets) == (first if first < length else None)
            if length == 16:
                assert len(asked) <= 9
