"""The benchmark's parts on a short recording: what they time and what they print."""

from crossview import bench, pipeline


def test_bench_tracker_times_every_update_after_an_untimed_warm_up(tmp_path, monkeypatch):
    scenario = pipeline.load_scenario("store_layout1", duration_s=3.0, seed=2)
    gen = pipeline.generate(scenario, tmp_path / "r.mcap", progress=False)
    warmed = []
    original = pipeline.warm_up_tracker
    monkeypatch.setattr(pipeline, "warm_up_tracker", lambda *a: (warmed.append(a[0]), original(*a)))
    result = bench.bench_tracker(tmp_path / "r.mcap")
    assert warmed == ["crossview"]  # first-use compiles never enter the timed rounds
    assert result["camera_frames"] == gen.num_frames
    assert result["tracker_fps_median"] > 0 and result["tracker_fps_mean"] > 0
    assert result["update_ms_p50"] <= result["update_ms_p95"]
    text = bench.format_results([{
        "scenario": "store_layout1", "num_cameras": gen.num_cameras, "num_people": 4,
        "generate_realtime_factor": gen.realtime_factor, "generate_running_realtime_factor":
            gen.running_realtime_factor, "generate_startup_s": gen.startup_s, "people_only_realtime_factor": 100.0,
        "read_camera_frames_per_s": 1000.0, "bytes_per_camera_frame": 3000.0, "crossview": result,
        "baseline": result}])
    assert text.splitlines()[0].split()[:6] == ["scenario", "cams", "people", "gen", "x", "RT"]
    assert "store_layout1" in text.splitlines()[1]
