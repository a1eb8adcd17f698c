"""The command line's contract for bad input: one line naming the problem, exit status 2, no output file."""

import os
import sys

import pytest

from crossview.cli import EXIT_BAD_INPUT, main


def _run_bad(capsys, argv):
    status = main(argv)
    err = capsys.readouterr().err.strip()
    assert status == EXIT_BAD_INPUT
    assert len(err.splitlines()) == 1, err
    assert "Traceback" not in err
    return err


def test_missing_scenario_names_the_path(tmp_path, capsys):
    out = tmp_path / "a.mcap"
    err = _run_bad(capsys, ["generate", str(tmp_path / "missing.toml"), "-o", str(out)])
    assert "missing.toml: no such scenario file" in err
    assert not out.exists()


def test_malformed_toml_names_the_file(tmp_path, capsys):
    bad = tmp_path / "broken.toml"
    bad.write_text("[store\n")
    err = _run_bad(capsys, ["generate", str(bad), "-o", str(tmp_path / "a.mcap")])
    assert "broken.toml: malformed TOML" in err


def test_unknown_key_is_named(tmp_path, capsys):
    bad = tmp_path / "typo.toml"
    bad.write_text("[crowd]\npeeple = 3\n")
    err = _run_bad(capsys, ["generate", str(bad), "-o", str(tmp_path / "a.mcap")])
    assert "typo.toml: unknown key 'crowd.peeple'" in err


def test_negative_duration_is_refused(tmp_path, capsys):
    err = _run_bad(capsys, ["generate", "store_layout1", "-o", str(tmp_path / "a.mcap"), "--duration", "-5"])
    assert "--duration" in err and "-5" in err
    assert not (tmp_path / "a.mcap").exists()


def test_negative_duration_in_the_file_is_refused(tmp_path, capsys):
    bad = tmp_path / "neg.toml"
    bad.write_text("duration_s = -1.0\n")
    err = _run_bad(capsys, ["run", str(bad), "-o", str(tmp_path)])
    assert "neg.toml: duration_s: -1.0 must be in (0, 86400] s" in err


def test_unwritable_output_folder_is_named(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    err = _run_bad(capsys, ["run", "--duration", "1", "-o", str(blocker / "sub")])
    assert str(blocker / "sub") in err
    assert list(tmp_path.iterdir()) == [blocker]


@pytest.mark.parametrize("argv", [["run", "--cameras", "0"], ["run", "--seed", "-1"], ["track"]])
def test_bad_arguments_exit_2(capsys, argv):
    _run_bad(capsys, argv)


def test_geometry_errors_found_while_building_the_world_name_the_file(tmp_path, capsys):
    # Two shelves on the same spot: only building the store finds it, and the message still names the file.
    bad = tmp_path / "overlap.toml"
    bad.write_text(
        "[store]\nwidth_m = 8.0\ndepth_m = 6.0\n"
        "[[store.shelves]]\ncenter_m = [4.0, 2.0]\nsize_m = [2.0, 0.5, 1.6]\n"
        "[[store.shelves]]\ncenter_m = [4.2, 2.1]\nsize_m = [2.0, 0.5, 1.6]\n"
    )
    out = tmp_path / "a.mcap"
    err = _run_bad(capsys, ["generate", str(bad), "-o", str(out), "--duration", "1"])
    assert f"{bad}: store.shelves[1]: overlaps store.shelves[0]" in err
    assert not out.exists()


def test_scenarios_lists_every_shipped_one_with_its_description(capsys):
    from sim import scenario

    assert main(["scenarios"]) == 0
    out = capsys.readouterr().out
    for path in scenario.shipped():
        line = next(line for line in out.splitlines() if line.startswith(path.stem + " "))
        assert scenario.load(path).description in line


def test_scenarios_show_prints_a_file_that_loads_and_reference_is_the_docs(tmp_path, capsys):
    from sim import scenario, scenario_reference

    assert main(["scenarios", "--show", "store_layout2"]) == 0
    (tmp_path / "mine.toml").write_text(capsys.readouterr().out)
    assert scenario.load(tmp_path / "mine.toml").store == scenario.load("store_layout2").store
    # An explicit name is kept, so the printed file saved under another name is still that scenario.
    (tmp_path / "named.toml").write_text('name = "pharmacy"\n[crowd]\npeople = 2\n')
    assert main(["scenarios", "--show", str(tmp_path / "named.toml")]) == 0
    (tmp_path / "copy.toml").write_text(capsys.readouterr().out)
    assert scenario.load(tmp_path / "copy.toml").name == "pharmacy"
    assert main(["scenarios", "--reference"]) == 0
    assert capsys.readouterr().out == scenario_reference.reference_markdown()
    err = _run_bad(capsys, ["scenarios", "--show", "nowhere"])
    assert ("nowhere: no such scenario file (shipped scenarios: border, campus, convenience, hypermarket, "
            "megastore, panoptic_dome, shelf, store_layout1") in err


def test_an_output_that_is_an_input_is_refused_and_the_input_kept(tmp_path, capsys):
    rec = tmp_path / "rec.mcap"
    assert main(["--no-progress", "generate", "store_layout1", "-o", str(rec), "--duration", "1"]) == 0
    tracks = tmp_path / "t.mcap"
    assert main(["--no-progress", "track", str(rec), "-o", str(tracks)]) == 0
    before = {p: p.read_bytes() for p in (rec, tracks)}
    # The same file under its own name, another spelling of it, and as the score JSON of its own run.
    for argv in (["track", str(rec), "-o", str(rec)],
                 ["track", str(rec), "-o", str(tmp_path / "." / "rec.mcap")],
                 ["score", str(rec), str(tracks), "-o", str(tracks)],
                 ["export", str(tracks), "-o", str(tracks)]):
        err = _run_bad(capsys, ["--no-progress", *argv])
        assert ": is also an input (" in err, err
    assert {p: p.read_bytes() for p in (rec, tracks)} == before
    scenario = tmp_path / "s.toml"
    scenario.write_text("duration_s = 1.0\n")
    err = _run_bad(capsys, ["generate", str(scenario), "-o", str(scenario)])
    assert "s.toml: is also an input" in err and scenario.read_text() == "duration_s = 1.0\n"


def test_an_output_that_is_not_a_regular_file_is_refused(tmp_path, capsys):
    rec = tmp_path / "rec.mcap"
    err = _run_bad(capsys, ["generate", "store_layout1", "-o", "/dev/null", "--duration", "1"])
    assert "/dev/null: is not a regular file" in err and not rec.exists()


def _help(capsys, argv) -> str:
    assert main([*argv, "--help"]) == 0
    return capsys.readouterr().out


def _entries(text: str) -> list[tuple[str, str]]:
    """(invocation, help) of each entry of an argparse --help's argument sections; help "" when it has none."""
    entries, section = [], False
    for line in text.splitlines():
        if line.endswith(":") and not line.startswith(" "):
            section = line in ("positional arguments:", "options:")
            continue
        if not section or not line.strip():
            continue
        if line.startswith("  ") and not line.startswith("   "):  # an entry: invocation, then its help (if any)
            invocation, _, help_text = line.strip().partition("  ")
            entries.append((invocation, help_text.strip()))
        elif entries and not entries[-1][1]:  # the help of an invocation too long to share its line
            entries[-1] = (entries[-1][0], line.strip())
    return entries


def test_every_command_option_and_positional_has_help_and_the_output_is_o_output(capsys):
    from crossview.cli import COMMANDS

    listed = [line.split()[0] for line in _help(capsys, []).splitlines()  # (the commands: indented 4 spaces)
              if line.startswith("    ") and not line.startswith("     ")]
    commands = [name for name in listed if name in COMMANDS]
    assert sorted(commands) == sorted(COMMANDS)
    assert commands[:4] == ["run", "scenarios", "generate", "coverage"]  # in the order a user meets them
    for command in COMMANDS:
        text = _help(capsys, [command])
        entries = _entries(text)
        assert entries, command
        missing = [invocation for invocation, help_text in entries if not help_text]
        assert missing == [], f"{command}: {missing} have no help"
        # The one spelling of the main output; the old ones are hidden.
        assert "--out " not in text and "--minutes" not in text, command
        outputs = [invocation for invocation, _ in entries if "--output" in invocation]
        assert all(invocation.startswith("-o ") for invocation in outputs), (command, outputs)
        assert "--json" not in text or command == "run", command  # (run: the score JSON beside its folder)


@pytest.mark.parametrize("old, argv", [
    ("--out", ["sweep", "store_layout1"]), ("--out", ["compare", "r.mcap", "--tracker", "a=crossview"]),
    ("--out", ["ablate"]), ("--out", ["run"]), ("--json", ["score", "r.mcap", "t.mcap"]),
    ("--json", ["per-camera", "r.mcap", "t.mcap"]), ("--json", ["bench"]),
])
def test_the_old_output_spellings_still_work_for_one_version(old, argv):
    from pathlib import Path

    from crossview.cli import build_parser

    assert build_parser().parse_args([*argv, old, "x"]).output == Path("x")
    assert build_parser().parse_args([*argv, "-o", "x"]).output == Path("x")


def test_world_stats_takes_seconds_and_its_old_minutes_as_seconds():
    from crossview.cli import build_parser

    assert build_parser().parse_args(["world-stats", "store_layout1"]).duration == 600.0
    assert build_parser().parse_args(["world-stats", "store_layout1", "--duration", "90"]).duration == 90.0
    assert build_parser().parse_args(["world-stats", "store_layout1", "--minutes", "2"]).duration == 120.0


def _files_of(folder):
    return {p: p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_no_output_of_any_command_can_be_one_of_its_inputs_under_any_name(tmp_path, capsys, monkeypatch):
    """Every file a command reads (its scenario and the calibration it names, its tracker config, its plug-in's
    module, its recordings, result and dataset files) is refused as its output, by path, through a symlink or
    a hard link, before any work."""
    import shutil

    from sim.scenario import SCENARIO_DIR

    shutil.copytree(SCENARIO_DIR / "calibrations", tmp_path / "calibrations")
    scenario = tmp_path / "campus.toml"
    scenario.write_text((SCENARIO_DIR / "campus.toml").read_text())
    calibration = tmp_path / "calibrations" / "campus_calibration.json"
    config = tmp_path / "c.toml"
    config.write_text("min_views = 2\n")
    plugin = tmp_path / "aliasplugin.py"
    plugin.write_text("from examples.greedy_triangulation import GreedyTriangulationTracker as T\n")
    rec, tracks = tmp_path / "rec.mcap", tmp_path / "t.mcap"
    rec.write_bytes(b"not read: the refusal comes first")
    tracks.write_bytes(b"not read either")
    (tmp_path / "link.json").symlink_to(calibration)
    (tmp_path / "hard.toml").hardlink_to(config)
    (tmp_path / "tp.png").hardlink_to(tracks)
    dataset = tmp_path / "ds"
    dataset.mkdir()
    (dataset / "calibration.json").write_text("{}")
    monkeypatch.chdir(tmp_path)
    before = _files_of(tmp_path)
    cases = [
        (["run", str(scenario), "--out", "o", "--json", str(scenario)], "campus.toml"),
        (["run", str(scenario), "--out", "o", "--config", str(config), "--json", "hard.toml"], "hard.toml"),
        (["generate", str(scenario), "-o", "calibrations/campus_calibration.json"], "campus_calibration.json"),
        (["generate", str(scenario), "-o", "link.json"], "link.json"),
        (["track", str(rec), "-o", str(plugin), "--method", "aliasplugin:T"], "aliasplugin.py"),
        (["track", str(rec), "-o", "hard.toml", "--config", str(config)], "hard.toml"),
        (["score", str(rec), str(tracks), "--json", str(tracks)], "t.mcap"),
        (["convert", str(dataset), "-o", str(dataset / "calibration.json")], "calibration.json"),
        (["per-camera", str(rec), str(tracks), "--json", str(rec)], "rec.mcap"),
        (["render", str(rec), "--top-down", "--time", "1", "--tracks", str(tracks), "-o", "tp.png"], "tp.png"),
    ]
    for argv, named in cases:
        err = _run_bad(capsys, ["--no-progress", *argv])
        assert f"{named}: is also an input (" in err, (argv, err)
    sys.modules.pop("aliasplugin", None)
    assert _files_of(tmp_path) == before
    assert not (tmp_path / "o").exists()


def test_an_input_that_is_a_fifo_is_refused_by_name_without_waiting_on_it(tmp_path, capsys):
    """A named pipe given as scenario, calibration, tracker config, recording or dataset file: its reader would
    wait for a writer forever; it is named as what it is instead."""
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    scenario = tmp_path / "s.toml"
    scenario.write_text(f'duration_s = 1.0\n[cameras]\ncalibration = "{fifo.name}"\ncalibration_format = "dataset"\n')
    dataset = tmp_path / "ds"
    dataset.mkdir()
    os.mkfifo(dataset / "calibration.json")
    out = tmp_path / "out.mcap"
    for argv, named in ((["generate", str(fifo), "-o", str(out)], fifo),
                        (["generate", str(scenario), "-o", str(out)], fifo),
                        (["run", "--config", str(fifo), "--out", str(tmp_path / "o")], fifo),
                        (["track", str(fifo), "-o", str(out)], fifo),
                        (["info", str(fifo)], fifo),
                        (["convert", str(dataset), "-o", str(out)], dataset / "calibration.json"),
                        (["evaluate", str(dataset), str(fifo)], fifo)):
        err = _run_bad(capsys, ["--no-progress", *argv])
        assert f"{named}: is a FIFO (named pipe), not a regular file" in err, (argv, err)
    assert not out.exists() and not (tmp_path / "o").exists()


def test_a_closed_stdout_ends_quietly_with_every_output_written(tmp_path):
    """`crossview run ... | head -1`: the reader of stdout is gone before the command has printed its table; the
    command runs on, writes its files and ends with its own status, without a word about the pipe."""
    import subprocess

    process = subprocess.Popen([sys.executable, "-m", "crossview.cli", "--no-progress", "run", "store_layout1",
                                "--duration", "1", "--out", str(tmp_path)], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    process.stdout.close()  # (as `head -1` does once it has its line)
    err = process.stderr.read()
    assert process.wait(timeout=600) == 0, err
    assert err == ""
    assert (tmp_path / "store_layout1.score.json").is_file()


def test_an_empty_stream_is_tracked_and_said_to_have_no_speed(tmp_path, capsys):
    # A millionth of a second holds no camera frame: `run` printed "0 updates at nan FPS" (issue 49).
    assert main(["--no-progress", "run", "--duration", "1e-6", "-o", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "tracks.mcap: 0 updates (no camera frame in the stream: no speed measured)" in out, out
    assert "nan FPS" not in out, out
