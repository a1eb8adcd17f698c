"""The command line behaves like one: --version, the global flags before or after the command, an unknown flag
named, a line before the kernels compile, --cameras saying its grid, commands saying where they wrote."""

import re

import pytest

from core import jit
from crossview import cli
from crossview.cli import COMPILING_LINE, EXIT_BAD_INPUT, GLOBAL_OPTIONS, build_parser, main
from crossview.recording import software_version


def test_version(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out == f"crossview {software_version()}\n"


def test_every_command_takes_the_global_flags_after_its_name():
    parser = build_parser()
    assert sorted(parser.commands) == sorted(cli.COMMANDS)
    for name, command in parser.commands.items():
        text = command.format_help()
        assert all(re.search(rf"(^|[ ,]){flag}\b", text, re.M) for flags, _ in GLOBAL_OPTIONS for flag in flags), name
    before = parser.parse_args(["-v", "--no-progress", "info", "x.mcap"])
    after = parser.parse_args(["info", "x.mcap", "-v", "--no-progress"])
    neither = parser.parse_args(["info", "x.mcap"])
    assert (before.verbose, before.no_progress) == (after.verbose, after.no_progress) == (True, True)
    assert (neither.verbose, neither.no_progress) == (False, False)


def test_global_flags_after_the_command_run_it(capsys):
    assert main(["scenarios", "--no-progress", "-v"]) == 0
    assert "store_layout1" in capsys.readouterr().out


@pytest.mark.parametrize("argv", [["--bogus"], ["--bogus", "info", "x.mcap"], ["info", "x.mcap", "--bogus"]],
                         ids=["alone", "before", "after"])
def test_an_unknown_flag_is_named(argv, capsys):
    assert main(argv) == EXIT_BAD_INPUT
    err = capsys.readouterr().err.strip()
    assert err == "crossview: error: unrecognized arguments: --bogus"


def test_cold_cache_is_seen(tmp_path, monkeypatch):
    """A kernel module without an index in numba's cache is cold; one with an index (here under $NUMBA_CACHE_DIR,
    as numba names it) is not."""
    monkeypatch.setattr(jit, "GROUPS", {"probe": ("core.errors",)})  # (a module no kernel of which is cached)
    monkeypatch.setattr(jit, "PLAIN", frozenset())
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert jit.cold_cache()
    (tmp_path / "core").mkdir()
    (tmp_path / "core" / f"errors.kernel-1.py{jit.sys.version_info.major}{jit.sys.version_info.minor}.nbi").touch()
    assert not jit.cold_cache()
    monkeypatch.setattr(jit, "PLAIN", frozenset({"probe"}))  # (a plain group never compiles)
    monkeypatch.delenv("NUMBA_CACHE_DIR")
    assert not jit.cold_cache()


def test_a_cold_cache_is_said_as_compiling_starts_and_bad_input_stays_one_line(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(jit, "cold_cache", lambda: True)

    def command(args):  # (a kernel never compiled in this process: numba compiles it here)
        assert jit.numba.njit(lambda x: x + 1)(1) == 2
        print("done")

    monkeypatch.setitem(cli.COMMANDS, "world-stats", command)
    assert main(["world-stats", "store_layout1"]) == 0
    captured = capsys.readouterr()
    assert captured.err.splitlines() == [COMPILING_LINE] and captured.out == "done\n"
    # Bad input found before anything compiles: the one line of the contract, nothing more.
    assert main(["track", str(tmp_path / "missing.mcap"), "-o", str(tmp_path / "t.mcap")]) == EXIT_BAD_INPUT
    assert len(capsys.readouterr().err.splitlines()) == 1
    main(["scenarios"])  # (no kernel: nothing said)
    assert COMPILING_LINE not in capsys.readouterr().err


def test_cameras_says_its_grid(capsys):
    from crossview import pipeline

    assert main(["coverage", "store_layout1", "--cameras", "6"]) == 0
    scenario = pipeline.load_scenario("store_layout1", cameras=6)
    rows, cols = scenario.cameras.rows, scenario.cameras.cols
    assert rows * cols == 6
    assert f"--cameras 6: a grid of {rows} rows x {cols} columns" in capsys.readouterr().out
