"""The scale benchmark's parts: the cases it runs, the camera subsets, the fit and the page it writes."""

import numpy as np
import pytest

from crossview.experiments import bench_scale


def test_a_crowd_the_floor_cannot_hold_is_benchmarked_at_the_most_it_holds(caplog):
    scenario = bench_scale._scenario_that_fits(bench_scale.ScaleCase("store_layout1", 400), 2.0)
    assert scenario.crowd.people == 12
    assert "holds at most 12 people, not 400" in caplog.text
    assert bench_scale._scenario_that_fits(bench_scale.ScaleCase("store_layout1", 3), 2.0).crowd.people == 3


def test_camera_subsets_take_whole_grid_columns_from_one_side():
    from crossview import pipeline
    from sim.cameras import build_rig
    from sim.rng import child_rng

    scenario = pipeline.load_scenario("supermarket")  # a grid of 6 rows x 10 columns
    cams = build_rig(scenario, child_rng(scenario.seed, "cameras"))
    subsets = bench_scale.column_subsets(cams, steps=(1, 2, 5, 10, 11))
    assert [len(s) for s in subsets] == [6, 12, 30, 60]  # (11 columns: none)
    xs = {c.name: c.center_world[0] for c in cams}
    assert max(xs[n] for n in subsets[1]) < min(x for n, x in xs.items() if n not in subsets[1])
    assert all(set(a) < set(b) for a, b in zip(subsets, subsets[1:]))


def test_the_fitted_exponent_of_a_power_law_is_its_exponent():
    cams = np.array([24, 48, 96, 240])
    assert np.isclose(bench_scale.fit_exponent(cams, 3.0 * cams ** 1.3), 1.3)


def test_one_case_end_to_end_and_the_page_section(tmp_path):
    row = bench_scale.run_case(bench_scale.ScaleCase("store_layout1"), 3.0, tmp_path, progress=False)
    assert row["num_cameras"] == 12 and row["num_people"] == row["people_asked"] == 4
    assert row["camera_frames"] == row["camera_frames_timed"] > 0
    assert row["worst_update_ms"] >= row["update_ms_p99"] > 0
    assert row["cost_per_camera_frame_ms"] == 1e3 / row["camera_frames_per_s"]
    # the cost per detection: the same tracking time over the detections of the timed frames
    assert row["us_per_detection"] * row["detections_per_camera_frame"] == pytest.approx(
        1e3 * row["cost_per_camera_frame_ms"])
    assert row["unknown_joints"] == 0 and row["false_positives_per_min"] >= 0 and row["pcp"] > 0.5
    # Past its budget a case is timed over the start of its stream only, and left unscored.
    short = bench_scale.run_case(bench_scale.ScaleCase("store_layout1"), 3.0, tmp_path / "b", False, budget_s=0.0)
    assert short["camera_frames_timed"] == 1 and short["pcp"] is None and short["false_positives_per_min"] is None
    linear = {"scenario": "store_layout1", "duration_s": 3.0, "exponent": 1.1,
              "points": [{"num_cameras": n, "round_ms": n * 0.5, "camera_frames_per_s": 2000.0,
                          "worst_update_ms": 3.0} for n in (3, 6, 12)]}
    payload = {"date": "2026-01-02 03:04 UTC", "machine": "m", "cpus": 2, "duration_s": 3.0, "budget_s": 9.0,
               "cases": [row, short],
               "linear": linear}
    section = bench_scale.markdown_section(payload, "benchmarks/linear_in_cameras.png")
    assert section.startswith(bench_scale.SECTION) and "| store_layout1 | 12 | 4 (4) |" in section
    assert "timed over the first 1 of" in section
    assert "b = 1.10" in section and "![time per round against cameras](benchmarks/linear_in_cameras.png)" in section
    # Written into the benchmarks page: replacing its own section, keeping the rest.
    page = "# Benchmarks\n\ntable\n"
    once = bench_scale.replace_section(page, section)
    assert once.startswith(page) and once.count(bench_scale.SECTION) == 1
    assert bench_scale.replace_section(once, section) == once
    bench_scale.plot_linear(linear, tmp_path / "plot.png")
    assert (tmp_path / "plot.png").read_bytes().startswith(b"\x89PNG")
    assert "fitted exponent of time per round against cameras: 1.10" in bench_scale.format_results([row], linear)


def test_the_generate_command_is_timed_with_its_worker_and_their_memory(tmp_path):
    g = bench_scale.bench_generate_command("store_layout1", 1.0, tmp_path / "r.mcap")
    assert (tmp_path / "r.mcap").stat().st_size == g["bytes_per_simulated_s"]
    assert g["wall_s"] > 0 and g["cpu_s"] > 0 and g["realtime_factor"] == 1.0 / g["wall_s"]
    assert g["peak_rss_mb"] > 50  # (Python, numpy, MuJoCo and numba at the least)
    assert "peak resident memory of both" in bench_scale._generation_line(g)
