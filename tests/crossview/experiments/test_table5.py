"""Table 5 on a short real recording: every camera gets a row of both trackers, the command prints and writes it,
and tracks of another recording are refused."""

import json

import pytest

from crossview import pipeline
from crossview.cli import EXIT_BAD_INPUT, main
from crossview.experiments.table5 import per_camera_table

COLUMNS = ("single_view", "cross_view", "cross_view_projected")


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("table5")
    scenario = pipeline.load_scenario("store_layout1", duration_s=4.0, seed=5)
    pipeline.generate(scenario, out / "rec.mcap", progress=False)
    pipeline.track(out / "rec.mcap", out / "tracks.mcap", progress=False)
    return out


def test_every_camera_has_a_row_of_both_trackers_over_all_its_frames(short_run):
    from crossview import recording

    table = per_camera_table(short_run / "rec.mcap", short_run / "tracks.mcap")
    rec = recording.open_recording(short_run / "rec.mcap")
    frames = list(rec.frames())
    assert [r.camera for r in table.rows] == [c.name for c in rec.cameras]
    for r in table.rows:
        count = sum(cf.frame.camera == r.camera for cf in frames)
        true_detections = sum(len(set(cf.truth.person_ids[cf.truth.person_ids >= 0].tolist()))
                              for cf in frames if cf.frame.camera == r.camera)
        # Both per-detection columns score every frame of the camera against the same truth.
        for s in (r.single_view, r.cross_view):
            assert (s.num_frames, s.num_truth) == (count, true_detections)
            assert s.mota is None or s.mota <= 1.0
            assert s.idf1 is None or 0.0 <= s.idf1 <= 1.0
    # The single-view tracker needs min_hits frames before it reports anybody: it misses more than the
    # cross-view tracker, which assigns detections to the targets it already holds from other cameras.
    assert sum(r.single_view.false_negatives for r in table.rows) > sum(r.cross_view.false_negatives
                                                                         for r in table.rows)


def test_the_command_prints_the_table_and_writes_the_same_numbers(short_run, capsys):
    path = short_run / "table5.json"
    assert main(["per-camera", str(short_run / "rec.mcap"), str(short_run / "tracks.mcap"), "-o", str(path)]) == 0
    printed = capsys.readouterr().out
    result = json.loads(path.read_text())
    assert (result["scenario"], result["seed"]) == ("store_layout1", 5)
    assert len(result["cameras"]) == 12 and set(result["mean"]) == set(COLUMNS)
    mean = result["mean"]["single_view"]["mota"]
    mean_row = next(line for line in printed.splitlines() if line.startswith("mean "))
    assert mean_row.split()[1] == f"{100 * mean:.1f}"  # (the text table's last row: the means)
    assert printed.splitlines()[-1] == f"table JSON: {path}"
    assert "single-view MOTA 85.9 IDF1 71.0, cross-view MOTA 98.3 IDF1 99.2" in printed  # Table 5's means
    # The same inputs give the same table.
    again = per_camera_table(short_run / "rec.mcap", short_run / "tracks.mcap").to_json()
    assert again == result


def test_tracks_of_another_recording_are_refused_in_one_line(short_run, tmp_path, capsys):
    other = tmp_path / "other.mcap"
    pipeline.generate(pipeline.load_scenario("store_layout1", duration_s=1.0, seed=6), other, progress=False)
    status = main(["per-camera", str(other), str(short_run / "tracks.mcap")])
    err = capsys.readouterr().err.strip()
    assert status == EXIT_BAD_INPUT and len(err.splitlines()) == 1
    assert "tracks were made from scenario 'store_layout1' seed 5" in err
