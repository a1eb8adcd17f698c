"""The command line's contract for bad input: one line naming the problem, exit status 2, no output file."""

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
    err = _run_bad(capsys, ["run", str(bad), "--out", str(tmp_path)])
    assert "neg.toml: duration_s: -1.0 must be in (0, 86400] s" in err


def test_unwritable_output_folder_is_named(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    err = _run_bad(capsys, ["run", "--duration", "1", "--out", str(blocker / "sub")])
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
    from sim import scenario

    assert main(["scenarios", "--show", "store_layout2"]) == 0
    (tmp_path / "mine.toml").write_text(capsys.readouterr().out)
    assert scenario.load(tmp_path / "mine.toml").store == scenario.load("store_layout2").store
    assert main(["scenarios", "--reference"]) == 0
    assert capsys.readouterr().out == scenario.reference_markdown()
    err = _run_bad(capsys, ["scenarios", "--show", "nowhere"])
    assert ("nowhere: no such scenario file (shipped scenarios: campus, hypermarket, panoptic_dome, shelf, "
            "store_layout1") in err


def test_an_output_that_is_an_input_is_refused_and_the_input_kept(tmp_path, capsys):
    rec = tmp_path / "rec.mcap"
    assert main(["--no-progress", "generate", "store_layout1", "-o", str(rec), "--duration", "1"]) == 0
    tracks = tmp_path / "t.mcap"
    assert main(["--no-progress", "track", str(rec), "-o", str(tracks)]) == 0
    before = {p: p.read_bytes() for p in (rec, tracks)}
    # The same file under its own name, another spelling of it, and as the score JSON of its own run.
    for argv in (["track", str(rec), "-o", str(rec)],
                 ["track", str(rec), "-o", str(tmp_path / "." / "rec.mcap")],
                 ["score", str(rec), str(tracks), "--json", str(tracks)],
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
