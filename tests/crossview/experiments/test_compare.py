"""crossview compare: contenders parsed, every one tracked and scored alike, the best marked, a chart per metric."""

import csv
import io

import pytest

from crossview import recording
from crossview.cli import EXIT_BAD_INPUT, main
from crossview.experiments.compare import (
    METRICS,
    Contender,
    best_values,
    compare_rows,
    csv_text,
    markdown,
    write_report,
)
from crossview.formats.results import json_lines

EXAMPLE = "examples.greedy_triangulation:GreedyTriangulationTracker"


@pytest.mark.parametrize("text, expected", [
    ("crossview", Contender("crossview", "crossview", "store")),
    ("paper=crossview@store-paper", Contender("paper", "crossview", "store-paper")),
    (f"greedy={EXAMPLE}", Contender("greedy", EXAMPLE, "store")),
    ("mine=file:out/{recording}.jsonl", Contender("mine", result="out/{recording}.jsonl")),
])
def test_a_contender_is_a_label_and_a_method_with_its_preset_or_a_result_file(text, expected):
    assert Contender.parse(text) == expected


def _row(recording, tracker, **metrics):
    return {"recording": recording, "tracker": tracker, "spec": tracker} | {m.key: None for m in METRICS} | metrics


def test_the_best_of_each_metric_is_taken_per_recording_in_its_direction():
    rows = [_row("a", "x", pcp=0.9, mpjpe_mm=30.0, id_switches=2),
            _row("a", "y", pcp=0.8, mpjpe_mm=20.0, id_switches=2),
            _row("b", "x", pcp=0.5, mpjpe_mm=50.0),
            _row("b", "y", pcp=0.7, mpjpe_mm=None)]
    best = best_values(rows)
    assert best["a", "pcp"] == 0.9 and best["a", "mpjpe_mm"] == 20.0 and best["a", "id_switches"] == 2
    assert best["b", "pcp"] == 0.7 and best["b", "mpjpe_mm"] == 50.0 and ("b", "idf1") not in best
    table = markdown(rows).splitlines()
    assert table[2].startswith("| a | x | **0.900** | 30.0 |") and "| **2** |" in table[2] and "| **2** |" in table[3]
    assert table[5].startswith("| b | y | **0.700** | - |")
    parsed = list(csv.DictReader(io.StringIO(csv_text(rows))))
    assert [r["best"] for r in parsed] == ["pcp id_switches", "mpjpe_mm id_switches", "mpjpe_mm", "pcp"]
    assert parsed[0]["pcp"] == "0.9" and parsed[3]["mpjpe_mm"] == ""


def test_a_tie_as_printed_is_bold_for_every_tracker_in_it():
    rows = [_row("a", "x", pcp=0.98612), _row("a", "y", pcp=0.98608), _row("a", "z", pcp=0.9849)]
    table = markdown(rows).splitlines()
    assert [line.split(" | ")[2] for line in table[2:]] == ["**0.986**", "**0.986**", "0.985"]
    assert [r["best"].split()[:1] for r in csv.DictReader(io.StringIO(csv_text(rows)))] == [["pcp"], ["pcp"], []]


def test_trackers_methods_and_result_files_are_scored_alike(store_recording, store_tracks, tmp_path):
    # A result file written from the built-in tracker's outputs scores as the built-in tracker (but for the
    # association accuracy and speed, which a result file does not hold).
    name = store_recording.name.removesuffix(".mcap")
    (tmp_path / f"{name}.jsonl").write_text(json_lines(recording.open_tracks(store_tracks).outputs()))
    contenders = [Contender.parse("store=crossview"), Contender.parse(f"greedy={EXAMPLE}"),
                  Contender.parse(f"lines=file:{tmp_path}/{{recording}}.jsonl")]
    rows = compare_rows(contenders, [store_recording], tmp_path / "tracks")
    assert [(r["recording"], r["tracker"]) for r in rows] == [(name, "store"), (name, "greedy"), (name, "lines")]
    store, greedy, lines = rows
    for key in ("pcp", "mpjpe_mm", "idf1", "mota", "hota"):
        assert lines[key] == store[key], key
    assert lines["association_accuracy"] is None and lines["tracker_fps"] is None
    assert greedy["spec"] == f"{EXAMPLE}@store" and 0.5 < greedy["pcp"] <= 1.0
    written = write_report(rows, tmp_path / "report")
    assert sorted(p.name for p in (tmp_path / "report").iterdir()) == sorted(p.name for p in written)
    assert len(written) == 2 + len(METRICS)
    assert all(p.read_bytes().startswith(b"\x89PNG") for p in written if p.suffix == ".png")


@pytest.mark.parametrize("trackers, message", [
    (["a=crossview", "a=baseline"], "label 'a' is given twice"),
    (["a=nosuch.module:X"], "--method nosuch.module:X: no module named 'nosuch'"),
    (["a=crossview@nosuchpreset"], "nosuchpreset"),
    (["a=file:missing-{recording}.jsonl"], "missing-store_layout1.jsonl: no such result file"),
    (["=crossview"], "expected LABEL=METHOD[@PRESET] or LABEL=file:PATH"),
])
def test_a_bad_tracker_is_refused_before_any_work(store_recording, tmp_path, capsys, trackers, message):
    argv = ["--no-progress", "compare", str(store_recording), "-o", str(tmp_path / "out")]
    status = main(argv + [f"--tracker={t}" for t in trackers])
    err = capsys.readouterr().err.strip()
    assert status == EXIT_BAD_INPUT and len(err.splitlines()) == 1 and message in err, err
    assert not (tmp_path / "out").exists()


def test_a_tracker_failing_after_another_keeps_none_of_their_tracks(store_recording, tmp_path, capsys):
    # The built-in tracker's tracks are written, then the plug-in fails at its 6th frame: the command said
    # "nothing kept" but left the first tracks file (issue 49).
    out = tmp_path / "cmp"
    status = main(["--no-progress", "compare", str(store_recording), "-o", str(out), "--tracker", "a=crossview",
                   "--tracker", "b=tests.crossview.test_plugins:Raises"])
    err = capsys.readouterr().err.strip()
    assert status == EXIT_BAD_INPUT and len(err.splitlines()) == 1, err
    assert "update raised RuntimeError: the model file is missing" in err, err
    assert not out.exists() and list(tmp_path.iterdir()) == []
