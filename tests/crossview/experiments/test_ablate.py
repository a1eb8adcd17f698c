"""`crossview ablate`: every experiment runs on a tiny grid, the numbers are the same serially and in a pool,
a rerun resumes from the sweeps' caches, the verdicts follow the numbers, and bad input is one line, exit 2."""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest

from crossview import pipeline
from crossview.cli import EXIT_BAD_INPUT, main
from crossview.experiments import ablate, ablate_report

TINY = ablate.Settings(
    seeds=(0,), duration_s=2.0, affinity_scenario="store_layout1", weights=((1.0, 0.0), (0.4, 0.6)),
    reconstruction_scenarios=("store_layout1",), frame_rates=(10.0, 5.0),
    frame_rate_triangulations=("paper", "conventional"), spread_s=2.0, camera_counts=(4, 8), speed_s=0.6,
    speed_windows_s={"crossview": (0.2, 0.6), "baseline": (0.2, 0.3)}, single_view_scenarios=("store_layout1",),
    single_view_s=2.0, priors_scenario="store_layout1", priors_rows=("none", "all"),
)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """Every experiment on the tiny settings, in this process (workers 1)."""
    out = tmp_path_factory.mktemp("ablate") / "out"
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(ablate, "QUICK", TINY)
        summary = ablate.run(out, quick=True, workers=1, progress=False)
    return out, summary


def test_every_experiment_writes_its_numbers_verdict_and_plots(tiny):
    out, summary = tiny
    assert summary.experiments == list(ablate.EXPERIMENTS)
    results = json.loads((out / "results.json").read_text())["experiments"]
    assert set(results) == set(ablate.EXPERIMENTS)
    assert [r["w_2d"] for r in results["affinity"]["rows"]] == [1.0, 0.4]
    assert all(0.0 <= r["association_accuracy"] <= 1.0 for r in results["affinity"]["rows"])
    methods = [(r["triangulation"], r["row_norm"]) for r in results["reconstruction"]["stores"][0]["rows"]]
    assert methods == [("conventional", "plane"), ("unnormalized", "plane"), ("paper", "row"), ("paper", "plane"),
                       ("velocity", "plane")]
    spreads = [r["spread_s"] for r in results["frame-rate"]["rows"]]
    assert spreads[1] > spreads[0] > 0.0  # fewer frames a second: older points in the sets
    assert results["speed"]["camera_counts"] == [4, 8]
    timings = json.loads((out / "timings.json").read_text())
    assert set(timings["speed"]["round_ms"]) == {"crossview", "baseline"}
    report = (out / "report.md").read_text()
    for experiment in ablate.EXPERIMENTS.values():
        assert experiment.title in report
    assert report.count("the paper's trend ") == len(ablate.EXPERIMENTS) - 1
    assert "beyond the paper, the priors together " in report
    priors = results["priors"]["rows"]
    assert [r["switch"] for r in priors] == ["none", "all"] and priors[0]["changes"] == {}
    assert all(0.0 <= r["lower_arms"] <= 1.0 and r["mpjpe_mm"] > 0 for r in priors)
    assert (out / "plots" / "frame_rate.png").read_bytes()[:4] == b"\x89PNG"
    assert (out / "plots" / "speed.png").read_bytes()[:4] == b"\x89PNG"


def test_a_pool_gives_the_same_numbers_and_a_rerun_resumes(tiny, tmp_path, caplog):
    out, _ = tiny
    other = tmp_path / "pool"
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(ablate, "QUICK", TINY)
        ablate.run(other, ["reconstruction", "affinity"], quick=True, workers=2, progress=False)
        first = json.loads((out / "results.json").read_text())["experiments"]
        pooled = json.loads((other / "results.json").read_text())["experiments"]
        assert pooled == {k: first[k] for k in ("affinity", "reconstruction")}
        # A rerun (an interrupted run's too) finds every finished cell and runs none again.
        before = (other / "results.json").read_bytes()
        (other / "results.json").unlink()
        with caplog.at_level(logging.INFO, logger="crossview.experiments.sweep"):  # (a resume is progress: INFO)
            ablate.run(other, ["reconstruction", "affinity"], quick=True, workers=2, progress=False)
    assert "4 of 4 cells already finished" in caplog.text and "1 of 1 cells already finished" in caplog.text
    assert (other / "results.json").read_bytes() == before


def test_point_set_spread_matches_a_brute_force_count(tiny):
    out, _ = tiny
    from crossview import recording

    rec_path = sorted((out / "frame-rate" / "recordings").glob("*.mcap"))[0]
    frames = [(cf.frame.stamp_s, cf.frame.camera, set(int(p) for p in cf.truth.person_ids if p >= 0))
              for cf in recording.open_recording(rec_path).frames()]
    means = []
    for i, (t, _, people) in enumerate(frames):
        for person in people:
            latest = {}
            for s, camera, seen in frames[: i + 1]:  # every earlier frame, in delivery order
                if person in seen:
                    latest[camera] = s
            ages = [t - s for s in latest.values() if t - s <= 1.0]
            if len(ages) >= 2:
                means.append(np.mean(ages))
    assert ablate.point_set_spread_s(rec_path, 1.0) == pytest.approx(np.mean(means), rel=1e-12)


def test_verdicts_follow_the_numbers():
    holds, partly, fails = ablate_report.HOLDS, ablate_report.PARTLY, ablate_report.FAILS
    rows = [{"w_2d": 1.0, "w_3d": 0.0, "association_accuracy": 0.4, "pcp": 0.6},
            {"w_2d": 0.4, "w_3d": 0.6, "association_accuracy": 0.96, "pcp": 0.97},
            {"w_2d": 0.0, "w_3d": 1.0, "association_accuracy": 0.965, "pcp": 0.96}]
    assert ablate_report.affinity_verdict({"rows": rows})[0] == holds
    rows[2]["association_accuracy"] = 0.99  # 3 points above the other: not robust to the weights
    assert ablate_report.affinity_verdict({"rows": rows})[0] == partly
    rows[0]["association_accuracy"] = 0.95  # and 2D only as good: 3D not critical either
    assert ablate_report.affinity_verdict({"rows": rows})[0] == fails
    rate = {"rows": [{"fps": 10.0, "spread_s": 0.05, "pcp": {"paper": 0.99, "conventional": 0.98}},
                     {"fps": 2.0, "spread_s": 0.2, "pcp": {"paper": 0.985, "conventional": 0.90}}]}
    assert ablate_report.frame_rate_verdict(rate)[0] == holds
    rate["rows"][1]["pcp"]["paper"] = 0.93
    assert ablate_report.frame_rate_verdict(rate)[0] == partly
    # Table 4: eq. (11) as printed (the whole row's norm) against the conventional DLT decides, not the plane norm.
    store = {"scenario": "s", "rows": [
        {"triangulation": "conventional", "row_norm": "plane", "lower_arms": 0.80, "pcp": 0.90},
        {"triangulation": "paper", "row_norm": "row", "lower_arms": 0.79, "pcp": 0.91},
        {"triangulation": "paper", "row_norm": "plane", "lower_arms": 0.95, "pcp": 0.97}]}
    assert ablate_report.reconstruction_verdict({"stores": [store]})[0] == fails
    store["rows"][1]["lower_arms"] = 0.85
    assert ablate_report.reconstruction_verdict({"stores": [store]})[0] == holds
    timings = {"speed": {"exponent": {"crossview": 1.05, "baseline": 2.1}}}
    assert ablate_report.speed_verdict({}, timings)[0] == holds
    timings["speed"]["exponent"]["crossview"] = 1.8
    assert ablate_report.speed_verdict({}, timings)[0] == partly


def test_the_fitted_exponent_of_a_power_law_is_its_power():
    counts = [6, 11, 16, 21, 26, 31]
    assert ablate.fitted_exponent(counts, [3e-4 * n ** 1.7 for n in counts]) == pytest.approx(1.7)


def _run_bad(capsys, argv):
    status = main(["--no-progress", *argv])
    err = capsys.readouterr().err.strip()
    assert status == EXIT_BAD_INPUT, err
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


def test_an_unknown_experiment_lists_the_valid_ones(tmp_path, capsys):
    err = _run_bad(capsys, ["ablate", "affinity", "table9", "-o", str(tmp_path / "out")])
    assert "experiment 'table9' is unknown; valid: affinity, reconstruction, frame-rate, speed, single-view" in err
    assert not (tmp_path / "out").exists()


def test_an_output_that_is_a_file_or_holds_something_else_is_refused(tmp_path, capsys):
    target = tmp_path / "report"
    target.write_text("mine")
    assert "is a file" in _run_bad(capsys, ["ablate", "--quick", "-o", str(target)])
    assert target.read_text() == "mine"
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    assert "holds no ablate.json" in _run_bad(capsys, ["ablate", "--quick", "-o", str(other)])
    pipeline.write_json({"format": ablate.ABLATE_FORMAT, "quick": False, "version": "0"}, tmp_path / "full" /
                        "ablate.json")
    assert "holds ablations with quick false" in _run_bad(capsys, ["ablate", "--quick", "-o",
                                                                   str(tmp_path / "full")])
