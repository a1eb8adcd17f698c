"""The benchmark's parts on a short recording: what they time and what they print."""

import pytest

from crossview import pipeline
from crossview.experiments import bench


def test_bench_tracker_times_every_update_after_an_untimed_warm_up(tmp_path, monkeypatch):
    scenario = pipeline.load_scenario("store_layout1", duration_s=3.0, seed=2)
    gen = pipeline.generate(scenario, tmp_path / "r.mcap", progress=False)
    warmed = []
    original = pipeline.warm_up_tracker
    monkeypatch.setattr(pipeline, "warm_up_tracker", lambda *a, **k: (warmed.append(a[0]), original(*a, **k)))
    result = bench.bench_tracker(tmp_path / "r.mcap")
    assert warmed == ["crossview"]  # first-use compiles never enter the timed rounds
    assert result["camera_frames"] == gen.num_frames
    assert result["tracker_fps_median"] > 0 and result["tracker_fps_mean"] > 0
    row = {
        "scenario": "store_layout1", "num_cameras": gen.num_cameras, "num_people": 4,
        "generate_realtime_factor": gen.realtime_factor, "generate_running_realtime_factor":
            gen.running_realtime_factor, "generate_startup_s": gen.startup_s, "cold_generate_realtime_factor": 2.5,
        "cold_same_bytes": True, "people_only_realtime_factor": 100.0,
        "read_camera_frames_per_s": 1000.0, "bytes_per_camera_frame": 3000.0, "crossview": result,
        "baseline": result}
    text = bench.format_results([row])
    assert text.splitlines()[0].split()[:6] == ["scenario", "cams", "people", "gen", "x", "RT"]
    assert text.splitlines()[1].split()[:7] == ["store_layout1", str(gen.num_cameras), "4",
                                                f"{gen.realtime_factor:.1f}", f"{gen.running_realtime_factor:.1f}",
                                                f"{gen.startup_s:.2f}", "2.5"]
    assert "WARNING" not in text
    assert "WARNING: a new process wrote other bytes" in bench.format_results([{**row, "cold_same_bytes": False}])
    # The benchmarks page: the run's date, version and machine, and a row of figures per case.
    page = bench.markdown({"date": "2026-01-02 03:04 UTC", "version": "9.9", "machine": "m", "cpus": 2,
                           "python": "3.11", "cases": [{**row, "duration_s": 3.0}]})
    assert "- date: 2026-01-02 03:04 UTC" in page and "crossview-testbed 9.9" in page and "2 CPUs" in page
    assert f"| store_layout1 | {gen.num_cameras} | 4 | {gen.realtime_factor:.1f} |" in page


def test_cold_generate_times_a_new_process_that_writes_the_same_bytes(tmp_path):
    scenario = pipeline.load_scenario("store_layout1", duration_s=1.0)
    pipeline.generate(scenario, tmp_path / "here.mcap", progress=False)  # (also fills numba's cache)
    cold = bench.bench_cold_generate("store_layout1", 1.0, tmp_path / "cold.mcap", same_as=tmp_path / "here.mcap")
    assert cold["cold_same_bytes"] is True


def test_cold_generate_says_why_the_command_failed(tmp_path):
    with pytest.raises(RuntimeError, match=r"generate no_such_store .* exited with 2: .*no_such_store"):
        bench.bench_cold_generate("no_such_store", 1.0, tmp_path / "cold.mcap")
    assert not (tmp_path / "cold.mcap").exists()
