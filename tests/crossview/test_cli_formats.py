"""One output rule for every command that prints a table (`crossview.tables`): `--format text|json|markdown` on
stdout, `-o FILE` in --format or as its suffix says, and a line saying where it wrote."""

from __future__ import annotations

import json
import re

import pytest

from crossview import cli
from crossview.cli import build_parser, main
from crossview.tables import FORMATS, Table, key_values

MD = ".md"  # (spelt apart: the test of cited documents would read a file name ending in it as a document)


def _option(parser, flag):
    return next((a for a in parser._actions if flag in a.option_strings), None)


def test_every_command_that_prints_a_table_takes_format_and_output():
    commands = build_parser().commands
    for name in cli.TABLE_COMMANDS:
        fmt = _option(commands[name], "--format")
        assert fmt is not None and tuple(fmt.choices) == FORMATS, name
        assert _option(commands[name], "-o") is not None, name
    # ... and no other command's --format is this one (export's names file formats).
    others = [n for n, p in commands.items() if n not in cli.TABLE_COMMANDS and _option(p, "--format")
              and tuple(_option(p, "--format").choices) == FORMATS]
    assert others == []


def _markdown_tables(text: str) -> list[list[list[str]]]:
    """Each pipe table of a Markdown text as its rows of cells, the separator row checked and left out."""
    tables, rows = [], []
    for line in [*text.splitlines(), ""]:
        if line.startswith("|"):
            rows.append([c.strip() for c in re.split(r"(?<!\\)\|", line.strip())[1:-1]])
            continue
        if rows:
            assert len(rows) >= 2 and all(set(c) <= set("-:") and c for c in rows[1]), rows[:2]
            assert {len(r) for r in rows} == {len(rows[0])}, rows
            tables.append([rows[0], *rows[2:]])
            rows = []
    return tables


def test_a_table_in_text_and_markdown_holds_the_same_cells():
    table = Table(("name", "a|b", "n"), (("x", "1", "22"), ("longer", "333", "")))
    md = _markdown_tables(table.markdown())
    assert md == [[["name", "a\\|b", "n"], ["x", "1", "22"], ["longer", "333", ""]]]
    text = table.text().splitlines()
    assert text[0].split() == ["name", "a|b", "n"] and set(text[1]) == {"-"}
    assert [line.split() for line in text[2:]] == [["x", "1", "22"], ["longer", "333"]]
    with pytest.raises(ValueError, match="has 2 cells"):
        Table(("a", "b", "c"), (("1", "2"),))


def test_key_values_flattens_nested_figures():
    rows = key_values({"a": {"b": 1.5, "c": [1, 2]}, "d": None, "e": [{"f": float("nan")}]}).rows
    assert rows == (("a.b", "1.5"), ("a.c", "1, 2"), ("d", "-"), ("e[0].f", "-"))


def _measured_once(monkeypatch, module, name):
    """`module.name` run once for real, its answer given again to the later calls (the formats are tested here,
    not the measuring)."""
    real, answers = getattr(module, name), {}

    def once(*args, **kwargs):
        key = tuple(map(str, args))
        if key not in answers:
            answers[key] = real(*args, **kwargs)
        return answers[key]

    monkeypatch.setattr(module, name, once)


def test_score_prints_and_writes_each_format(store_recording, store_tracks, tmp_path, capsys, monkeypatch):
    from crossview import pipeline

    _measured_once(monkeypatch, pipeline, "score")
    args = ["--no-progress", "score", str(store_recording), str(store_tracks)]
    assert main([*args, "-o", str(tmp_path / "s.json")]) == 0
    text = capsys.readouterr().out
    written = json.loads((tmp_path / "s.json").read_text())
    assert text.splitlines()[-1] == f"score JSON: {tmp_path / 's.json'}"
    assert "  MOTA " in text and "PCP (alpha 0.5)" in text  # (the terminal's table, as before)

    assert main([*args, "--format", "json", "-o", str(tmp_path / ("s" + MD))]) == 0  # (--format names the file's too)
    out, err = capsys.readouterr()
    assert json.loads(out) == written  # stdout is the document alone; the line saying where is on stderr
    assert json.loads((tmp_path / ("s" + MD)).read_text()) == written
    assert err.strip().splitlines()[-1] == f"score JSON: {tmp_path / ('s' + MD)}"

    assert main([*args, "--format", "markdown"]) == 0
    tables = _markdown_tables(capsys.readouterr().out)
    assert tables[0][0] == ["metric", "value"]
    mota = next(r[1] for r in tables[0] if r[0] == "MOTA")
    assert mota == f"{100 * written['mota']:.1f} %"
    assert main([*args, "-o", str(tmp_path / ("s" + MD))]) == 0  # (no --format: the suffix says Markdown)
    assert _markdown_tables((tmp_path / ("s" + MD)).read_text()) == tables
    assert capsys.readouterr().out.splitlines()[-1] == f"score Markdown: {tmp_path / ('s' + MD)}"


def test_detector_stats_json_and_markdown_agree(store_recording, tmp_path, capsys, monkeypatch):
    from crossview.measure import detector_stats

    _measured_once(monkeypatch, detector_stats, "recording_detector_stats")
    assert main(["--no-progress", "detector-stats", str(store_recording), "--format", "json"]) == 0
    stats = json.loads(capsys.readouterr().out)
    assert main(["--no-progress", "detector-stats", str(store_recording), "--format", "markdown"]) == 0
    figures, cameras = _markdown_tables(capsys.readouterr().out)
    assert figures[0] == ["statistic", "measured", "real OpenPose, Shelf"]
    assert [r[0] for r in cameras[1:]] == list(stats["per_camera"])
    assert [r[2] for r in cameras[1:]] == [str(c["matched_detections"]) for c in stats["per_camera"].values()]

    # The recording's own figures as the reference: the column is headed by their source, and equals the measured.
    own = tmp_path / "own.json"
    assert main(["--no-progress", "detector-stats", str(store_recording), "-o", str(own)]) == 0
    assert json.loads(own.read_text())["source"] == store_recording.name
    capsys.readouterr()
    assert main(["--no-progress", "detector-stats", str(store_recording), "--reference", str(own), "--format",
                 "markdown"]) == 0
    printed = capsys.readouterr().out
    assert f"beside: {own} (measured on {store_recording.name})" in printed
    figures = _markdown_tables(printed)[0]
    assert figures[0] == ["statistic", "measured", store_recording.name]
    assert [r[1] for r in figures[1:]] == [r[2] for r in figures[1:]]


def test_a_reference_that_is_no_statistics_file_is_one_line(store_recording, tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    assert main(["detector-stats", str(store_recording), "--reference", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"crossview detector-stats: error: {bad}: per_group: missing; not a detector statistics file "
                   "(what `crossview detector-stats REC -o FILE.json` writes)")


def test_world_stats_writes_its_figures(monkeypatch, tmp_path, capsys):
    from crossview.measure import world_stats

    timed = world_stats.simulation_speed  # (the real timing, over 1 s instead of 60: the figures, not the speed)
    monkeypatch.setattr(world_stats, "simulation_speed", lambda scenario, seconds, rate, seed: timed(
        scenario, 1.0, rate, seed))
    out = tmp_path / "world.json"
    assert main(["world-stats", "store_layout1", "--duration", "2", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    figures = json.loads(out.read_text())
    assert figures["scenario"] == "store_layout1" and figures["simulated_s"] == 2.0
    assert printed.splitlines()[-1] == f"figures JSON: {out}"
    rows = dict(line.split(None, 1) for line in printed.splitlines()[2:-1])
    assert rows["people"] == str(figures["people"]) and float(rows["share_walk"]) == pytest.approx(
        figures["share_walk"], rel=1e-5)


def test_coverage_figures_follow_the_rule(tmp_path, capsys):
    figures = tmp_path / ("cov" + MD)
    assert main(["coverage", "store_layout1", "--cameras", "6", "--format", "json", "--figures", str(figures)]) == 0
    out, err = capsys.readouterr()
    doc = json.loads(out)  # (the grid it chose goes to stderr, beside the line saying where)
    assert doc["cameras"] == 6 and "--cameras 6: a grid of" in err
    assert f"figures JSON: {figures}" in err and json.loads(figures.read_text()) == doc


def test_evaluate_prints_the_papers_campus_table_in_each_format(tmp_path, capsys):
    from pathlib import Path

    campus = Path(__file__).resolve().parents[1] / "data" / "campus"
    args = ["evaluate", str(campus), str(campus / "result_3d.json")]
    out = tmp_path / ("campus" + MD)
    assert main([*args, "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "Total" in text and "0.9663" in text and text.splitlines()[-1] == f"evaluation Markdown: {out}"
    (table,) = _markdown_tables(out.read_text())
    assert table[0][0] == "Bone group" and table[-1][0] == "Total" and table[-1][-1] == "0.9663"  # (Table 2: 96.6)
    assert main([*args, "--format", "json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert round(result["average"], 4) == 0.9663 and result["num_frames"] == 222


def test_zones_json_and_markdown_hold_the_same_cut(tmp_path, capsys):
    assert main(["zones", "store_layout2", "--zones", "2", "--format", "markdown"]) == 0
    (table,) = _markdown_tables(capsys.readouterr().out)
    figures = tmp_path / "zones.json"
    assert main(["zones", "store_layout2", "--zones", "2", "--figures", str(figures)]) == 0  # (JSON: its suffix)
    assert capsys.readouterr().out.splitlines()[-1] == f"figures JSON: {figures}"
    doc = json.loads(figures.read_text())
    rows = [[str(z["index"]), *(f"{v:.1f}" for v in (z["cell_m"][0], z["cell_m"][2], z["cell_m"][1],
                                                      z["cell_m"][3])), str(z["cameras"])] for z in doc["zones"]]
    assert table[1:] == rows and len(rows) == 2
