"""`crossview sweep` and `crossview verify`: the same grid gives the same results.json serially, in a process
pool and on Ray; a rerun resumes; bad input is refused before any cell runs; verify finds a changed recording."""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

import scenarios
from crossview.cli import EXIT_BAD_INPUT, main
from crossview.experiments import sweep, sweep_report
from crossview.parallel import cluster, reaper
from sim import scenario as scenario_mod
from tests.crossview.signalling import signal_when

SCENARIOS = Path(scenarios.__file__).parent

# The small grid: 2 crowd sizes x 2 camera counts x 2 seeds of store_layout1, 1 simulated second each (CI time).
GRID = ["store_layout1", "--people", "2,3", "--cameras", "6,12", "--seeds", "0,1", "--duration", "1"]


def _sweep(out, *extra) -> int:
    return main(["--no-progress", "sweep", *GRID, "-o", str(out), *extra])


def _sha256(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    """The grid run serially in this process: the reference of the other executors."""
    out = tmp_path_factory.mktemp("serial")
    assert _sweep(out, "--workers", "1") == 0
    return out


@pytest.fixture(scope="module")
def ray_instance():
    """One local Ray instance for the module (its start-up is slow)."""
    ray = pytest.importorskip("ray", reason="Ray is the extra '.[ray]' (CI installs it)")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, runtime_env={"env_vars": cluster.RAY_WORKER_ENV})
    yield ray
    ray.shutdown()


def test_serial_sweep_writes_one_row_per_cell_with_scores_and_timings(serial):
    results = json.loads((serial / "results.json").read_text())
    cells = results["cells"]
    # Every cell of the product ran, in grid order (the seed varies fastest).
    assert [(c["crowd.people"], c["cameras"], c["seed"]) for c in cells] == [
        (p, k, s) for p in (2, 3) for k in (6, 12) for s in (0, 1)]
    assert all(c["status"] == "ok" for c in cells)
    # The scenario was resolved per cell: the camera count and crowd size are what was simulated.
    assert [c["num_cameras"] for c in cells] == [6, 6, 12, 12] * 2
    assert all(0 <= c["pcp"] <= 1 and 0 <= c["idf1"] <= 1 for c in cells)
    # Speeds vary from run to run: they are in timings.json and results.csv, not in results.json.
    assert "tracker_fps" not in cells[0]
    timings = json.loads((serial / "timings.json").read_text())["cells"]
    assert [t["key"] for t in timings] == [c["key"] for c in cells]
    assert all(t["tracker_fps"] > 0 and t["wall_s"] > 0 and t["peak_memory_mb"] > 0 for t in timings)
    header = (serial / "results.csv").read_text().splitlines()[0].split(",")
    assert {"crowd.people", "cameras", "seed", "status", "pcp", "idf1", "tracker_fps", "peak_memory_mb"} <= set(header)
    assert len((serial / "results.csv").read_text().splitlines()) == 1 + len(cells)
    # One small score file per cell, the report and its plots.
    assert len(list((serial / "cells").glob("*.json"))) == len(cells)
    report = (serial / "report.md").read_text()
    assert "## Where the bar holds" in report and "cameras=6:" in report
    # Each cell leaves out the default warm-up, half of its second; the report says so.
    assert {c["from_s"] for c in cells} == {0.5} and "scored from 0.5 s on" in report
    # Per grid point, the means over the two seeds with their 95 % intervals.
    first = results["means"][0]
    assert (first["line"], first["crowd.people"], first["cells"], first["ok"]) == ("cameras=6", 2, 2, 2)
    pcps = [c["pcp"] for c in cells[:2]]
    assert first["pcp"]["mean"] == pytest.approx(sum(pcps) / 2) and first["pcp"]["n"] == 2
    assert all((serial / "plots" / f"{m}.png").read_bytes()[:4] == b"\x89PNG" for m, _, _ in sweep_report.METRICS)
    assert not list(serial.rglob("*.tmp"))


def test_pool_gives_the_same_results_json_bytes_as_serial(serial, tmp_path):
    assert _sweep(tmp_path, "--workers", "2") == 0
    assert _sha256(tmp_path / "results.json") == _sha256(serial / "results.json")


def test_ray_gives_the_same_results_json_bytes_as_serial(serial, tmp_path, ray_instance):
    assert _sweep(tmp_path, "--ray") == 0
    assert _sha256(tmp_path / "results.json") == _sha256(serial / "results.json")


def test_a_rerun_skips_finished_cells_and_gives_the_same_results(serial, tmp_path, caplog):
    # An interrupted sweep: three cells' files lost, the results not yet written.
    out = tmp_path / "resumed"
    shutil.copytree(serial, out)
    cells = sorted((out / "cells").glob("*.json"))
    for lost in cells[:3]:
        lost.unlink()
    for written in ("results.json", "results.csv", "timings.json", "report.md"):
        (out / written).unlink()
    # The rerun runs only the three missing cells, and says so as progress (INFO), not as a problem.
    with caplog.at_level("INFO", logger="crossview.experiments.sweep"):
        assert _sweep(out, "--workers", "1") == 0
    resumed = [r for r in caplog.records if "cells already finished" in r.getMessage()]
    assert [r.levelname for r in resumed] == ["INFO"]
    assert f"5 of {len(cells)} cells already finished" in caplog.text
    assert _sha256(out / "results.json") == _sha256(serial / "results.json")


def test_a_rerun_with_nothing_left_starts_nothing(serial, tmp_path, capsys):
    # Every cell finished: Ray is not started nor joined (the address, where nothing listens, would be refused
    # in one line if it were tried), and the results are written again from the cells' files.
    out = tmp_path / "done"
    shutil.copytree(serial, out)
    (out / "results.json").unlink()
    assert _sweep(out, "--ray", "127.0.0.1:1") == 0
    assert "8 already finished (skipped), 0 run" in capsys.readouterr().out
    assert _sha256(out / "results.json") == _sha256(serial / "results.json")


def test_a_method_label_names_the_method_in_the_results(tmp_path, capsys):
    out = tmp_path / "labelled"
    assert main(["--no-progress", "sweep", "store_layout1", "--people", "2", "--duration", "1", "--workers", "1",
                 "--method", "mine=crossview", "-o", str(out)]) == 0
    cells = json.loads((out / "results.json").read_text())["cells"]
    assert [c["method"] for c in cells] == ["mine"] and cells[0]["status"] == "ok"
    assert cells[0]["seed"] == scenario_mod.load("store_layout1").seed  # no --seeds: the scenario's
    # One label for two methods is refused before any cell runs.
    err = _run_bad(capsys, ["sweep", "store_layout1", "--method", "a=crossview,a=baseline", "-o", str(tmp_path / "x")])
    assert "--method: the label 'a' is given twice" in err
    assert not (tmp_path / "x").exists()


def test_a_cell_too_crowded_for_the_floor_fails_alone_and_kept_recordings_verify(tmp_path, capsys):
    # store_layout1 holds at most a dozen people: the 200-people cell fails with its one-line error.
    out = tmp_path / "kept"
    assert main(["--no-progress", "sweep", "store_layout1", "--people", "2,200", "--duration", "1", "--workers", "1",
                 "--keep-recordings", "-o", str(out)]) == 0
    cells = json.loads((out / "results.json").read_text())["cells"]
    assert cells[0]["status"] == "ok"
    # The one-line error names the scenario file as the user knows it, not where it lies on this machine.
    assert cells[1]["status"].startswith("store_layout1.toml: crowd.people: 200 people need")
    assert cells[1]["pcp"] is None
    results_text = (out / "results.json").read_text()
    assert str(SCENARIOS) not in results_text and str(tmp_path) not in results_text
    assert "## Failed cells" in (out / "report.md").read_text()
    # The manifest lists the recording that was made, with its sha256.
    manifest = json.loads((out / "manifest.json").read_text())["recordings"]
    assert len(manifest) == 1
    kept = out / manifest[0]["file"]
    assert _sha256(kept) == manifest[0]["sha256"]
    assert "people = 2" in manifest[0]["resolved_scenario"]
    # verify regenerates it: the same bytes.
    capsys.readouterr()
    assert main(["--no-progress", "verify", str(out)]) == 0
    assert "1 of 1 recordings match" in capsys.readouterr().out
    # A changed byte in the kept recording is found.
    data = bytearray(kept.read_bytes())
    data[len(data) // 2] ^= 0xFF
    kept.write_bytes(bytes(data))
    assert main(["--no-progress", "verify", str(out), "--cells", "1"]) == EXIT_BAD_INPUT
    captured = capsys.readouterr()
    assert "MISMATCH" in captured.out and "1 of 1 recordings differ" in captured.err


def _run_bad(capsys, argv):
    status = main(["--no-progress", *argv])
    err = capsys.readouterr().err.strip()
    assert status == EXIT_BAD_INPUT, err
    assert len(err.splitlines()) == 1, err
    assert "Traceback" not in err
    return err


@pytest.mark.parametrize(("args", "named"), [
    (["--set", "crowd.peeple=1,2"], "unknown key 'crowd.peeple'"),
    (["--set", "crowd.people=2,many"], "crowd.people = 'many' must be an integer"),
    (["--set", "detector.profile=typical,rough"], "is not one of ['ideal', 'typical', 'harsh']"),
    (["--set", "clock.fps="], "--set clock.fps: '' is an empty axis"),
    (["--people", "2,,3"], "empty value"),
    (["--seeds", "0,one"], "--seeds: '0,one' is not a comma-separated list"),
    (["--cameras", "0"], "--cameras: 0 is not a camera count"),
    (["--method", "crossview,magic"], "--method 'magic': not a known tracker"),
    (["--set", "crowd.people=2", "--people", "3"], "--set crowd.people: given twice"),
    (["--ray", "127.0.0.1:1"], "--ray 127.0.0.1:1: unreachable"),
    (["--set", "tracker.w_2e=0.4"], "tracker.w_2e: unknown tracker setting"),
    (["--set", "tracker.triangulation=paper,sideways"], "'sideways' is not one of"),
    (["--set", "tracker.alpha_3d_m=0.1,-1"], "alpha_3d_m: -1 must be > 0"),
])
def test_bad_input_is_one_line_exit_2_before_any_cell(tmp_path, capsys, args, named):
    out = tmp_path / "out"
    err = _run_bad(capsys, ["sweep", "store_layout1", "--duration", "1", *args, "-o", str(out)])
    assert named in err
    assert not out.exists()


def test_ray_asked_for_but_not_installed_names_the_extra(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # what `import ray` meets where it is not installed
    out = tmp_path / "out"
    err = _run_bad(capsys, ["sweep", "store_layout1", "--duration", "1", "--ray", "-o", str(out)])
    assert "Ray is not installed" in err and "crossview-testbed[ray]" in err
    assert not out.exists()


def test_a_folder_holding_another_sweep_is_refused(serial, tmp_path, capsys):
    out = tmp_path / "other"
    shutil.copytree(serial, out)
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    err = _run_bad(capsys, ["sweep", "store_layout1", "--people", "2,4", "--duration", "1", "-o", str(out)])
    assert "holds another sweep's results" in err
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


def test_verify_without_a_manifest_is_refused(tmp_path, capsys):
    err = _run_bad(capsys, ["verify", str(tmp_path)])
    assert "manifest.json: no manifest" in err


def test_axis_values_are_read_as_toml_values_with_text_as_a_fallback():
    assert sweep.parse_values("--set k", "10,2.5,true,typical,[1, 2]") == (10, 2.5, True, "typical", [1, 2])


def test_tracker_axes_set_the_tracker_of_each_cell_and_only_its_key():
    spec = sweep.SweepSpec("store_layout1", axes=(sweep.parse_axis("tracker.triangulation", "paper,conventional"),),
                           duration_s=1.0)
    paper, conventional = sweep.plan(spec)
    assert paper.tracker_overrides == {"triangulation": "paper"}
    assert conventional.tracker_overrides == {"triangulation": "conventional"}
    assert paper.overrides == conventional.overrides  # the same recording
    assert paper.key != conventional.key and paper.error is None and conventional.error is None
    # Without tracker axes a cell keeps the key it had before they existed.
    plain, = sweep.plan(sweep.SweepSpec("store_layout1", duration_s=1.0))
    assert plain.tracker_overrides == {} and plain.key not in (paper.key, conventional.key)


def test_zoned_cells_are_tracked_as_zones_and_keyed_apart():
    """`sweep --zones 2`: the same recording, another key (a plain cell keeps its own), and the cell's tracks made
    by the zones (its score lists the switches by place, which only a zoned tracks file has)."""
    spec = sweep.SweepSpec("store_layout1", duration_s=0.6, warm_up_s=0.0, zones="2")
    zoned_cell, = sweep.plan(spec)
    plain, = sweep.plan(dataclasses.replace(spec, zones=None))
    assert zoned_cell.zones == "2" and plain.zones is None
    assert zoned_cell.overrides == plain.overrides and zoned_cell.key != plain.key
    outcome = sweep.run_cell(zoned_cell)
    assert outcome["status"] == "ok", outcome["status"]
    assert outcome["score"]["switches_by_place"] is not None
    assert len(outcome["score"]["switches_by_place"]) == outcome["score"]["id_switches"]


def test_a_tracker_value_invalid_with_the_cells_preset_fails_that_cell_alone():
    # view_margin_m must be >= alpha_3d_m: 0.2 is fine for "campus" (alpha_3d_m 0.1), not for "store" (0.25).
    spec = sweep.SweepSpec("store_layout1", axes=(sweep.parse_axis("tracker.view_margin_m", "0.2"),),
                           presets=("campus", "store"), duration_s=1.0)
    campus, store = sweep.plan(spec)
    assert campus.error is None
    assert "view_margin_m: 0.2 must be >= alpha_3d_m 0.25" in store.error


def test_cameras_of_a_calibrated_rig_are_that_many_of_its_cameras():
    spec = sweep.SweepSpec("panoptic_dome", axes=(sweep.parse_axis("cameras", "6,31"),), duration_s=1.0)
    six, all_ = sweep.plan(spec)
    assert six.overrides["cameras.calibration_count"] == 6 and all_.overrides["cameras.calibration_count"] == 31
    assert six.error is None and all_.error is None
def test_failed_cells_name_paths_relative_to_the_scenario_file(tmp_path):
    # A worker's copy of the scenario and the driver's file are named alike: relative to the scenario's folder.
    copy = tmp_path / "crossview-cell-x"
    message = f"{copy}/calibrations/dome.json: cannot be read; {copy}/dome.toml: cameras.calibration"
    assert sweep.portable(message, copy) == "calibrations/dome.json: cannot be read; dome.toml: cameras.calibration"
    assert sweep.portable(f"{SCENARIOS}/supermarket.toml: x", SCENARIOS) == "supermarket.toml: x"


def test_a_smaller_grid_of_the_same_sweep_reuses_its_cells(serial, tmp_path, caplog):
    out = tmp_path / "subset"
    shutil.copytree(serial, out)
    with caplog.at_level("INFO", logger="crossview.experiments.sweep"):
        assert main(["--no-progress", "sweep", "store_layout1", "--people", "3", "--cameras", "12,6", "--seeds", "1",
                     "--duration", "1", "--workers", "1", "-o", str(out)]) == 0
    assert "2 of 2 cells already finished" in caplog.text
    rows = json.loads((out / "results.json").read_text())["cells"]
    full = {r["key"]: r for r in json.loads((serial / "results.json").read_text())["cells"]}
    assert [(r["crowd.people"], r["cameras"], r["seed"]) for r in rows] == [(3, 12, 1), (3, 6, 1)]
    assert rows == [full[r["key"]] for r in rows]
    # The folder keeps every finished cell: the full grid again runs nothing and gives the full results.
    caplog.clear()
    with caplog.at_level("INFO", logger="crossview.experiments.sweep"):
        assert _sweep(out, "--workers", "1") == 0
    assert "8 of 8 cells already finished" in caplog.text
    assert _sha256(out / "results.json") == _sha256(serial / "results.json")


@pytest.mark.parametrize(("args", "named"), [
    (["store_layout2", "--people", "2,3", "--cameras", "6,12"], "its scenario \"store_layout1\""),
    (["store_layout1", "--people", "2,3", "--set", "clock.fps=10"], "its axis_keys"),
    (["store_layout1", "--people", "2,3", "--cameras", "6,12", "--duration", "2"], "its duration_s 1.0"),
])
def test_a_folder_holding_a_different_sweep_is_refused(serial, tmp_path, capsys, args, named):
    out = tmp_path / "other"
    shutil.copytree(serial, out)
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    if "--duration" not in args:
        args = [*args, "--duration", "1"]
    err = _run_bad(capsys, ["sweep", *args, "-o", str(out)])
    assert "holds another sweep's results" in err and named in err
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


def test_a_kept_sweep_of_a_scenario_with_a_relative_calibration_verifies_from_another_folder(tmp_path, capsys):
    # panoptic_dome names its calibration relative to its own file: the manifest carries the file itself.
    out = tmp_path / "dome"
    assert main(["--no-progress", "sweep", "panoptic_dome", "--people", "1", "--duration", "0.2", "--workers", "1",
                 "--keep-recordings", "-o", str(out)]) == 0
    assert json.loads((out / "results.json").read_text())["cells"][0]["status"] == "ok"
    text = (out / "manifest.json").read_text()
    assert str(SCENARIOS) not in text and str(tmp_path) not in text
    manifest = json.loads(text)
    entry = manifest["recordings"][0]
    calibration = (SCENARIOS / "calibrations" / "panoptic_160906_hd.json").read_text()
    digest = hashlib.sha256(calibration.encode()).hexdigest()
    assert entry["files"] == {"calibrations/panoptic_160906_hd.json": digest}
    assert manifest["files"][digest] == calibration
    assert 'calibration = "calibrations/panoptic_160906_hd.json"' in entry["resolved_scenario"]
    # Moved elsewhere (as on another machine), the folder verifies: the same bytes regenerated.
    moved = tmp_path / "elsewhere" / "dome"
    shutil.move(out, moved)
    capsys.readouterr()
    assert main(["--no-progress", "verify", str(moved)]) == 0
    assert "1 of 1 recordings match" in capsys.readouterr().out


def _command(out, duration_s: str) -> list[str]:
    return [sys.executable, "-m", "crossview.cli", "--no-progress", "sweep", "store_layout1", "--people", "2,3",
            "--seeds", "0,1", "--duration", duration_s, "--workers", "2", "-o", str(out)]


@pytest.fixture
def own_temporary_folder():
    """A temporary folder of the test's own for a sweep (TMPDIR; a short path, as the fork server's socket
    below it needs), and the environment that points at it."""
    temporary = Path(tempfile.mkdtemp(prefix="cv-"))
    yield temporary, {**os.environ, "TMPDIR": str(temporary)}
    shutil.rmtree(temporary, ignore_errors=True)


@pytest.mark.parametrize("ending", ["SIGTERM to the sweep", "Ctrl-C to its process group"])
def test_an_interrupted_pool_sweep_keeps_finished_cells_and_leaks_nothing(tmp_path, ending, own_temporary_folder):
    out = tmp_path / "interrupted"
    temporary, env = own_temporary_folder
    # A new session (so that Ctrl-C can go to the whole group, as a terminal sends it), SIGINT not ignored.
    process = subprocess.Popen(_command(out, "4"), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               start_new_session=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
                               env=env)
    try:
        while not list((out / "cells").glob("*.json")) and process.poll() is None:
            time.sleep(0.2)
        assert process.poll() is None, process.communicate()
        assert list(temporary.glob("crossview-pool-*/pymp-*"))  # (the pool's, beside the running cells' folders)
        if ending.startswith("SIGTERM"):
            process.send_signal(signal.SIGTERM)
        else:
            os.killpg(process.pid, signal.SIGINT)
        _, err = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == (143 if ending.startswith("SIGTERM") else 130), err
    assert "crossview: ended by" in err or "interrupted" in err, err
    # The resource tracker found nothing left behind (it warns of leaked semaphores otherwise).
    assert "leaked" not in err and "resource_tracker" not in err and "Traceback" not in err, err
    assert 1 <= len(list((out / "cells").glob("*.json"))) < 4
    assert not (out / "results.json").exists()
    assert not [p for p in out.rglob("*") if p.name.endswith(".tmp") or p.name.startswith(".")]
    # Nothing in the temporary folder: the terminated workers' cell folders and multiprocessing's `pymp-*`.
    assert list(temporary.rglob("*")) == []


def test_tracker_settings_of_a_cell_are_checked_together_not_one_by_one():
    from crossview import pipeline

    # alpha_3d_m 0.6 alone breaks view_margin_m >= alpha_3d_m (0.5); with view_margin_m 0.7 the whole holds.
    config = pipeline.tracker_config("shelf", None, {"alpha_3d_m": 0.6, "view_margin_m": 0.7})
    assert (config.alpha_3d_m, config.view_margin_m) == (0.6, 0.7)
    with pytest.raises(sweep.CrossviewError, match="view_margin_m: 0.5 must be >= alpha_3d_m 0.6"):
        pipeline.tracker_config("shelf", None, {"alpha_3d_m": 0.6})


def test_tracker_axes_valid_only_together_are_planned_not_refused():
    """alpha_3d_m 0.6 is valid with view_margin_m 0.7, not with 0.5: the grid is planned and only that cell fails,
    with its reason; a value that no cell can take (alpha_3d_m 0.9 with either margin) is refused up front."""
    axes = (sweep.parse_axis("tracker.alpha_3d_m", "0.3,0.6"), sweep.parse_axis("tracker.view_margin_m", "0.5,0.7"))
    cells = sweep.plan(sweep.SweepSpec("store_layout1", axes=axes, seeds=(0,), methods=("crossview",),
                                       presets=("shelf",), duration_s=1.0))
    assert [c.error is None for c in cells] == [True, True, False, True]
    assert "view_margin_m: 0.5 must be >= alpha_3d_m 0.6" in cells[2].error
    axes = (sweep.parse_axis("tracker.alpha_3d_m", "0.6,0.9"), sweep.parse_axis("tracker.view_margin_m", "0.5,0.7"))
    with pytest.raises(sweep.CrossviewError, match=r"--set tracker.alpha_3d_m: .*view_margin_m: 0.5 must be >= "
                                                   r"alpha_3d_m 0.9"):
        sweep.plan(sweep.SweepSpec("store_layout1", axes=axes, seeds=(0,), methods=("crossview",),
                                   presets=("shelf",), duration_s=1.0))


def test_a_profile_file_is_an_axis_value_and_a_broken_one_is_named_with_the_key(tmp_path):
    """docs/sweeps.md: any scenario key can be an axis, detector.profile with a profile file among its values
    (was refused as "not one of ['ideal', 'typical', 'harsh']"); a broken file is named with the key."""
    fitted = tmp_path / "fitted.toml"
    fitted.write_text('base = "ideal"\nnoise_frac = 0.02\n')
    axis = sweep.parse_axis("detector.profile", f"{fitted},typical")
    assert axis.values == (str(fitted), "typical")
    cells = sweep.plan(sweep.SweepSpec("store_layout1", axes=(axis,), seeds=(0,), methods=("crossview",),
                                       presets=("store",), duration_s=1.0))
    assert [c.error for c in cells] == [None, None]
    broken = tmp_path / "broken.toml"
    broken.write_text("noise_frac = -1\n")
    with pytest.raises(sweep.CrossviewError) as info:
        sweep.parse_axis("detector.profile", f"typical,{broken}")
    assert str(info.value) == f"--set detector.profile: {broken}: noise_frac: -1.0 must be in [0, 1]"


def _report_row(people: int, pcp: float, idf1: float = 1.0) -> dict:
    return {"values": [["crowd.people", people]], "status": "ok", "score": {"pcp": pcp, "idf1": idf1},
            "method": "crossview", "preset": "store"}


def test_the_report_says_from_or_up_to_which_value_the_bar_holds_in_either_direction():
    wanted = {"axes": [{"key": "crowd.people", "values": [4, 8, 12]}], "methods": ["crossview"], "presets": ["store"]}
    breaks_later = [_report_row(4, 0.99), _report_row(8, 0.95), _report_row(12, 0.5)]
    below_first = [_report_row(4, 0.5), _report_row(8, 0.4), _report_row(12, 0.3)]
    holds_later = [_report_row(4, 0.909), _report_row(8, 0.948), _report_row(12, 0.962)]  # (the issue's cameras)
    bar = "PCP >= 0.95 and IDF1 >= 0.9"
    assert sweep_report.breaking_points(wanted, breaks_later) == [
        f"all: meets {bar} up to crowd.people = 8; breaks at crowd.people = 12 (PCP 0.500 < 0.95)"]
    assert sweep_report.breaking_points(wanted, below_first) == [
        f"all: below the bar ({bar}) at every value, crowd.people = 4 to 12 (crowd.people = 12: PCP 0.300 < 0.95)"]
    assert sweep_report.breaking_points(wanted, holds_later) == [
        f"all: meets {bar} from crowd.people = 12 (PCP 0.962, IDF1 1.000); below at crowd.people = 8 "
        "(PCP 0.948 < 0.95)"]
    # Values given out of order are read in rising order; a bar met, lost and met again names each.
    wanted["axes"][0]["values"] = [12, 4, 8]
    assert sweep_report.breaking_points(wanted, holds_later)[0].startswith(f"all: meets {bar} from crowd.people = 12")
    bumpy = [_report_row(4, 0.96), _report_row(8, 0.9), _report_row(12, 0.97, idf1=0.95)]
    assert sweep_report.breaking_points(wanted, bumpy) == [
        f"all: meets {bar} at crowd.people = 4, 12; below at 8 (not monotonic along crowd.people)"]
    assert sweep_report.breaking_points(wanted, [_report_row(4, 0.96), _report_row(8, 0.99, idf1=0.8)]) == [
        f"all: meets {bar} up to crowd.people = 4; breaks at crowd.people = 8 (IDF1 0.800 < 0.9)"]


def test_a_cells_key_covers_an_absolute_calibrations_content_and_a_plugins_code(tmp_path, monkeypatch):
    """Change the calibration a scenario names by an absolute path, or the code of a plug-in tracker, and a
    finished cell is no longer found: the old scores would be stale."""
    calibration = tmp_path / "campus_calibration.json"
    shutil.copy(SCENARIOS / "calibrations" / "campus_calibration.json", calibration)
    scenario = tmp_path / "campus.toml"
    scenario.write_text((SCENARIOS / "campus.toml").read_text().replace(
        'calibration = "calibrations/campus_calibration.json"', f'calibration = "{calibration}"'))
    plugin = tmp_path / "keyedplugin.py"
    plugin.write_text("from examples.greedy_triangulation import GreedyTriangulationTracker as T\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    spec = sweep.SweepSpec(scenario=str(scenario), methods=("crossview", "keyedplugin:T"), duration_s=1.0)
    try:
        first = [c.key for c in sweep.plan(spec)]
        assert len(set(first)) == 2
        assert [c.key for c in sweep.plan(spec)] == first  # (the same inputs: the same keys)
        data = json.loads(calibration.read_text())
        data["cameras"].pop(sorted(data["cameras"])[0])  # a camera fewer
        calibration.write_text(json.dumps(data))
        second = [c.key for c in sweep.plan(spec)]
        assert not set(second) & set(first)
        plugin.write_text(plugin.read_text() + "# a change to the tracker\n")
        third = [c.key for c in sweep.plan(spec)]
        assert third[0] == second[0] and third[1] != second[1]  # (only the plug-in's cell)
    finally:
        sys.modules.pop("keyedplugin", None)


def test_a_cell_failed_by_its_environment_is_not_final_and_the_next_run_says_so(tmp_path):
    """A cell whose recording hit the file-size limit (EFBIG, as a full disk gives ENOSPC) is stored as not
    final: the next run, without the limit, runs it again, says why, and it succeeds."""
    import resource

    out = tmp_path / "sweep"
    command = [sys.executable, "-m", "crossview.cli", "--no-progress", "sweep", "store_layout1", "--people", "2",
               "--duration", "1", "--workers", "1", "--out", str(out)]

    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG instead
        resource.setrlimit(resource.RLIMIT_FSIZE, (60_000, 60_000))

    subprocess.run(command, capture_output=True, text=True, preexec_fn=limit, timeout=600)
    (cell,) = [json.loads(p.read_text()) for p in (out / "cells").glob("*.json")]
    assert "File too large" in cell["status"] and cell[sweep.RETRY_KEY] is True, cell
    again = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr
    assert "failed in an earlier run for a reason of its environment" in again.stderr
    assert "File too large" in again.stderr and "1 run, 0 failed" in again.stdout
    (cell,) = [json.loads(p.read_text()) for p in (out / "cells").glob("*.json")]
    assert cell["status"] == "ok" and sweep.RETRY_KEY not in cell


def _session_processes(sid: int) -> list[str]:
    """The live processes of session `sid` (zombies, ended and waiting to be reaped, left out)."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(") ", 1)[1].split()
        except (OSError, IndexError):
            continue
        if int(fields[3]) == sid and fields[0] != "Z":
            found.append(stat.parent.name)
    return found


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads the processes from /proc (Linux)")
def test_a_pool_sweep_killed_with_sigkill_leaves_no_process_and_its_rerun_no_temporary_file(tmp_path,
                                                                                            own_temporary_folder):
    """kill -9 of the sweep stops nothing itself: its pool workers (waiting on the sweep), the fork server and
    the resource tracker must still end on their own; the rerun finishes, leaves no temporary file, and removes
    the folders the killed sweep left in the temporary folder (their process is gone: provably dead)."""
    out = tmp_path / "killed"
    temporary, env = own_temporary_folder
    process = subprocess.Popen(_command(out, "4"), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               start_new_session=True, env=env)
    try:
        while not list((out / "cells").glob("*.json")) and process.poll() is None:
            time.sleep(0.2)
        assert process.poll() is None
        process.kill()
        process.wait()
        for _ in range(300):  # (up to 30 s)
            if not _session_processes(process.pid):
                break
            time.sleep(0.1)
        left = _session_processes(process.pid)
    finally:
        for pid in _session_processes(process.pid):
            os.kill(int(pid), signal.SIGKILL)
    assert left == []
    # What the killed sweep could not remove: its cells' folders and its pool's folder, with `pymp-*` in it.
    assert [p.name for p in temporary.glob("crossview-pool-*/pymp-*")] and list(temporary.glob("crossview-cell-*"))
    again = subprocess.run(_command(out, "4"), capture_output=True, text=True, timeout=600, env=env)
    assert again.returncode == 0, again.stderr
    assert not [p for p in out.rglob("*") if p.name.endswith(".tmp")]
    assert list(temporary.rglob("*")) == []  # (the rerun removed the dead sweep's folders, and its own)


def _environ_marks(pids) -> set[str]:
    """The marks (`reaper.MARK_ENV`) the environments of processes `pids` carry."""
    marks = set()
    for pid in pids:
        with contextlib.suppress(OSError):
            for entry in Path(f"/proc/{pid}/environ").read_bytes().split(b"\0"):
                name, _, value = entry.decode(errors="replace").partition("=")
                if name == reaper.MARK_ENV:
                    marks.add(value)
    return marks


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads the processes from /proc (Linux)")
def test_a_ray_sweep_killed_with_sigkill_leaves_no_process_of_its_instance(tmp_path):
    """kill -9 of a sweep that started a local Ray instance: its raylet and GCS end with it (Ray asks the kernel),
    but its agents and workers polled for their parent and lived ~90 s on. The sweep's reaper ends every process
    of the instance (all in the sweep's session, or carrying its mark); a process with another mark lives on."""
    pytest.importorskip("ray", reason="Ray is the extra '.[ray]' (CI installs it)")
    out = tmp_path / "killed"
    command = [sys.executable, "-m", "crossview.cli", "--no-progress", "sweep", "store_layout1", "--people", "2,3",
               "--duration", "4", "--ray", "-o", str(out)]
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    bystander = subprocess.Popen(["sleep", "300"], env={reaper.MARK_ENV: f"{process.pid}-{'0' * 16}"})
    left = marked = []
    try:
        while not (out / "sweep.json").exists() and process.poll() is None:  # (written once Ray is up)
            time.sleep(0.2)
        time.sleep(2.0)  # (the cells running)
        assert process.poll() is None
        (mark,) = _environ_marks(_session_processes(process.pid))
        assert mark.startswith(f"{process.pid}-")  # (the sweep's pid and a nonce: no other run's)
        process.kill()
        process.wait()
        for _ in range(300):  # (up to 30 s)
            left = _session_processes(process.pid)
            marked = [p.name for p in Path("/proc").glob("[0-9]*") if mark in _environ_marks([p.name])]
            if not left and not marked:
                break
            time.sleep(0.1)
        assert bystander.poll() is None
    finally:
        for pid in _session_processes(process.pid):
            os.kill(int(pid), signal.SIGKILL)
        bystander.kill()
        bystander.wait()
    assert left == [] and marked == []


def test_a_damaged_cell_file_is_named_and_its_cell_run_again(serial, tmp_path, caplog):
    out = tmp_path / "damaged"
    shutil.copytree(serial, out)
    damaged = sorted((out / "cells").glob("*.json"))[0]
    damaged.write_text('[{"key": "a list, not a cell"}]')
    with caplog.at_level("WARNING", logger="crossview.experiments.sweep"):
        assert _sweep(out, "--workers", "1") == 0
    assert f"{damaged}: not a cell file of this sweep (an object expected, got list): running the cell again" \
        in caplog.text
    assert _sha256(out / "results.json") == _sha256(serial / "results.json")


_ENTRY = {"file": "recordings/a.mcap", "sha256": "0" * 64, "version": "1", "scenario_name": "s",
          "scenario_text": "", "overrides": {}, "files": {}}


@pytest.mark.parametrize("manifest, message", [
    ({"recordings": [{k: v for k, v in _ENTRY.items() if k != "version"}]}, "recordings[0]: key 'version' missing"),
    ({"recordings": [{**_ENTRY, "file": "/etc/passwd"}]}, "file '/etc/passwd' must lie inside the folder"),
    ({"recordings": [{**_ENTRY, "files": {"/etc/x.json": "d"}}], "files": {"d": "{}"}},
     "the files it names must be relative to the scenario"),
    ({"recordings": [], "files": {"d": 5}}, "a file it carries does not match its sha256"),
    ({"recordings": {"a": 1}}, "'recordings' must be an array"),
], ids=["entry-without-version", "file-outside", "named-file-absolute", "carried-file-not-text", "not-a-list"])
def test_a_damaged_manifest_is_one_line_before_any_regeneration(tmp_path, capsys, manifest, message):
    (tmp_path / "manifest.json").write_text(json.dumps(manifest))
    assert main(["--no-progress", "verify", str(tmp_path)]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "manifest.json" in err and message in err, err


def test_sigterm_during_a_ray_sweep_ends_it_like_everywhere_else(tmp_path):
    """ray.init sets its own SIGTERM handler (exit 1, a dump of the task loop); the sweep puts the command's
    back, and a signal that comes while it waits inside Ray (where raising it gave a SystemError) is held until
    Ray returns: one line, exit 143. (2 s after sweep.json, the cells are running or, on a fast machine, have just
    ended and Ray is stopping: the test below sends its signal there on purpose.)"""
    out = tmp_path / "ray"
    seen_s = []

    def running(process) -> bool:  # (sweep.json: written once Ray is up)
        if not seen_s and (out / "sweep.json").exists():
            seen_s.append(time.monotonic())
        return bool(seen_s) and time.monotonic() - seen_s[0] >= 2.0

    _ended_by_sigterm(*_ray_sweep_signalled(out, "2,3", 10, running, "ran its cells"))
    assert not (out / "results.json").exists()
    # The running cells end with the sweep's Ray job (its ray.shutdown), not left to run on.
    assert _running_ray_cells() == []


@pytest.mark.parametrize("started", [b"gcs_server", b"raylet"])
def test_sigterm_while_ray_starts_ends_the_sweep_like_everywhere_else(tmp_path, started):
    """ray.init sets a SIGTERM handler that ends the process by sys.exit, which ended the sweep with exit 15 and no
    word; sent while the driver connects (once the raylet runs), the interpreter's exit then also crashed (SIGSEGV)
    in about one run of two. A SIGTERM while the local instance starts ends the sweep as anywhere else, one line and
    exit 143, and none of Ray's processes is left."""
    out = tmp_path / "ray"
    _ended_by_sigterm(*_ray_sweep_signalled(out, "2", 10, lambda process: _child_running(process.pid, started),
                                            f"started {started.decode()}"))
    assert not (out / "results.json").exists()


def test_sigterm_while_the_sweeps_ray_instance_stops_ends_it_like_everywhere_else(tmp_path):
    """ray.shutdown set SIGTERM back to the default (Ray's failure-signal handler uninstalled) for the second it took
    to stop the local instance: a SIGTERM then killed the sweep with no word (exit -15), as the first SIGTERM test
    above did now and then when its cells had finished first. Sent once the sweep's raylet has ended (ray.shutdown
    stops it first), it now ends the sweep as anywhere else, once the instance has stopped."""
    raylets = []

    def raylet_ended(process) -> bool:
        if not raylets and (raylet := _child_running(process.pid, b"raylet")) is not None:
            raylets.append(raylet)
        return bool(raylets) and not _alive(raylets[0])

    _ended_by_sigterm(*_ray_sweep_signalled(tmp_path / "ray", "2", 2, raylet_ended, "stopped its raylet"))


def _ray_sweep_signalled(out: Path, people: str, duration_s: float, ready, what: str) -> tuple[str, int]:
    """`signal_when` SIGTERM to `crossview sweep store_layout1 --ray` (a local instance): its stderr and session."""
    pytest.importorskip("ray", reason="Ray is the extra '.[ray]' (CI installs it)")
    return signal_when(["sweep", "store_layout1", "--people", people, "--duration", str(duration_s), "--ray",
                        "--out", str(out)], ready, what, signal.SIGTERM)


def _ended_by_sigterm(err: str, session: int) -> None:
    """A command ended by SIGTERM as everywhere (exit 143, checked by `signal_when`): one line, no traceback, and
    (within 30 s: Ray's processes end with its job, or by the sweep's reaper) no process of its session left."""
    assert err.strip().splitlines()[-1] == "crossview: ended by SIGTERM; no partial output was kept", err
    assert "Traceback" not in err
    deadline = time.monotonic() + 30
    while _session_processes(session) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert _session_processes(session) == []


def _alive(pid: int | None) -> bool:
    """Whether process `pid` runs (not ended, not a zombie), by /proc."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(") ", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


def _child_running(pid: int, program: bytes) -> int | None:
    """A child of process `pid` that runs a program whose path holds `program` (its pid), by /proc."""
    for entry in Path("/proc").glob("[0-9]*"):
        with contextlib.suppress(OSError, IndexError, ValueError):
            if int((entry / "stat").read_text().rsplit(") ", 1)[1].split()[1]) == pid and \
                    program in (entry / "cmdline").read_bytes().split(b"\0")[0]:
                return int(entry.name)
    return None


def _running_ray_cells() -> list[int]:
    """The processes running a sweep cell as a Ray task (titled `ray::run_cell`), by /proc (none without it)."""
    found = []
    for entry in Path("/proc").glob("[0-9]*"):
        with contextlib.suppress(OSError):
            if (entry / "cmdline").read_bytes().startswith(b"ray::run_cell"):
                found.append(int(entry.name))
    return found
