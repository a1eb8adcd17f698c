"""Every output goes through one atomic path: nothing under a final name until complete, nothing left
beside it on any failure (a really full disk included), no folder made for a command that fails."""

import os
import resource
import signal
import subprocess
import sys

import pytest

from crossview import outputs, pipeline
from crossview.cli import EXIT_BAD_INPUT, main
from crossview.outputs import AtomicOutput, OutputError

CROSSVIEW = [sys.executable, "-c", "from crossview.cli import run; run()", "--no-progress"]


@pytest.fixture
def small_disk(tmp_path):
    """A real 256 kB file system (tmpfs) mounted on a fresh folder: writing more fills it (ENOSPC)."""
    mount = tmp_path / "disk"
    mount.mkdir()
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs to fill needs root (the file-size limit tests cover the rest)")
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(mount)], capture_output=True,
                          text=True)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({done.stderr.strip() or done.returncode})")
    try:
        yield mount
    finally:
        subprocess.run(["umount", str(mount)], check=True)


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """A 1 s recording of store_layout1 and its tracks file, made by the command line."""
    folder = tmp_path_factory.mktemp("made")
    rec, tracks = folder / "rec.mcap", folder / "tracks.mcap"
    assert main(["--no-progress", "generate", "store_layout1", "-o", str(rec), "--duration", "1"]) == 0
    assert main(["--no-progress", "track", str(rec), "-o", str(tracks)]) == 0
    return rec, tracks


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


def test_a_complete_output_appears_only_on_commit(tmp_path):
    path = tmp_path / "new" / "deeper" / "out.bin"
    with AtomicOutput(path) as out:
        out.write(b"half")
        assert not path.exists() and out.tmp.exists() and out.tmp.parent == path.parent
        out.write(b" and half")
    assert path.read_bytes() == b"half and half"
    assert sorted(p.name for p in path.parent.iterdir()) == ["out.bin"]


def test_a_failed_output_leaves_neither_file_nor_the_folders_made_for_it(tmp_path):
    # An existing file keeps its bytes; the folders made on the way are removed again.
    (tmp_path / "kept.bin").write_bytes(b"old")
    for path in (tmp_path / "kept.bin", tmp_path / "new" / "deeper" / "out.bin"):
        with pytest.raises(KeyboardInterrupt):
            with AtomicOutput(path) as out:
                out.write(b"partial")
                raise KeyboardInterrupt
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.bin"]
    assert (tmp_path / "kept.bin").read_bytes() == b"old"


@pytest.mark.parametrize("failure", [KeyboardInterrupt, RuntimeError], ids=["interrupt", "error"])
def test_outputs_kept_together_are_all_removed_when_a_later_step_fails(tmp_path, failure):
    # `compare`'s case: the first tracker's tracks committed, then the second fails or a signal arrives.
    # What was there before stays; what the group wrote goes, with the folders made for it.
    (tmp_path / "old.bin").write_bytes(b"old")
    with pytest.raises(failure):
        with outputs.kept_together(tmp_path / "cmp"):
            outputs.write_bytes(b"first", tmp_path / "cmp" / "tracks" / "a.bin")
            with outputs.kept_together(tmp_path / "cmp" / "tracks"):
                outputs.write_bytes(b"second", tmp_path / "cmp" / "tracks" / "b.bin")
            assert (tmp_path / "cmp" / "tracks" / "b.bin").read_bytes() == b"second"
            raise failure
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.bin"]
    with outputs.kept_together(tmp_path / "cmp"):  # a clean exit keeps them
        outputs.write_bytes(b"first", tmp_path / "cmp" / "a.bin")
    assert (tmp_path / "cmp" / "a.bin").read_bytes() == b"first"


def test_checking_an_output_makes_no_folder(tmp_path):
    pipeline.check_writable(tmp_path / "a" / "b" / "c.json")
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "file").write_text("x")
    with pytest.raises(OutputError, match=r"file/sub: output folder cannot be created \(.*file is a file"):
        pipeline.check_writable(tmp_path / "file" / "sub" / "c.json")
    with pytest.raises(OutputError, match="is a folder"):
        pipeline.check_writable(tmp_path)


def test_a_command_that_fails_before_writing_makes_no_folder(tmp_path, capsys):
    bad_config = tmp_path / "bad.toml"
    bad_config.write_text("[nonsense\n")
    status = main(["--no-progress", "run", "--duration", "1", "--config", str(bad_config),
                   "-o", str(tmp_path / "new" / "out")])
    assert status == EXIT_BAD_INPUT
    assert "bad.toml" in _one_line(capsys.readouterr().err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml"]


def test_a_full_disk_while_writing_leaves_nothing_and_names_the_path(small_disk):
    """A real file system filling up, with the failure at the final flush (all data still buffered: the
    abort closes the file, whose flush fails again, and must still remove the temporary file), at a write,
    and in `write_json`."""
    filler = small_disk / "filler"
    filler.write_bytes(b"\0" * (256 * 1024 - 4096))  # one page left
    for chunk, count in ((1000, 6), (1000, 300), (100_000, 3)):  # buffered, then written through
        path = small_disk / "sub" / "big.bin"
        with pytest.raises(OutputError, match=r"disk/sub/big\.bin: cannot be written \(No space left on device\)"):
            with AtomicOutput(path) as out:
                for _ in range(count):
                    out.write(b"x" * chunk)
        assert list(small_disk.iterdir()) == [filler]
    with pytest.raises(OutputError, match=r"s\.json: cannot be written \(No space left on device\)"):
        pipeline.write_json({"x": "y" * 400_000}, small_disk / "s.json")
    assert list(small_disk.iterdir()) == [filler]


def test_every_command_on_a_full_disk_says_so_in_one_line_and_leaves_nothing(small_disk, made, capsys):
    rec, tracks = made
    (small_disk / "filler").write_bytes(b"\0" * (256 * 1024 - 4096))  # one page left: less than any output
    for argv, out in (
        (["generate", "store_layout1", "--duration", "1", "-o"], small_disk / "g" / "rec.mcap"),
        (["track", str(rec), "-o"], small_disk / "t.mcap"),
        (["score", str(rec), str(tracks), "-o"], small_disk / "s.json"),
        (["export", str(tracks), "-o"], small_disk / "e.json"),
        (["convert", "tests/data/campus", "-o"], small_disk / "c.mcap"),
    ):
        status = main(["--no-progress", *argv, str(out)])
        assert status == EXIT_BAD_INPUT, argv
        err = _one_line(capsys.readouterr().err)
        assert f"{out}: cannot be written (No space left on device); nothing was kept" in err
        assert sorted(p.name for p in small_disk.iterdir()) == ["filler"], argv


def _file_size_limit(limit_bytes: int):
    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG instead
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))
    return limit


def test_a_file_size_limit_reached_by_a_real_command_leaves_nothing(tmp_path):
    """The kernel refusing a write part-way (RLIMIT_FSIZE, EFBIG; no root needed) in a real `generate`."""
    out = tmp_path / "new" / "rec.mcap"
    done = subprocess.run([*CROSSVIEW, "generate", "store_layout1", "--duration", "5", "-o", str(out)],
                          capture_output=True, text=True, preexec_fn=_file_size_limit(200_000), timeout=300)
    assert done.returncode == EXIT_BAD_INPUT, done.stderr
    line = _one_line(done.stderr)
    assert line == f"crossview generate: error: {out}: cannot be written (File too large); nothing was kept"
    assert list(tmp_path.iterdir()) == []


def test_writing_bytes_refuses_an_input(tmp_path):
    given = tmp_path / "in.json"
    given.write_text("{}")
    with pytest.raises(OutputError, match="is also an input"):
        outputs.write_bytes(b"x", tmp_path / "." / "in.json", inputs=(given,))
    assert given.read_text() == "{}"


def test_a_rerun_removes_the_temporary_files_of_a_killed_run_and_only_those(tmp_path):
    """kill -9 leaves `.NAME.PID.tmp` (nothing can remove it then); the next write of that output removes the
    ones whose process is gone, and leaves a live writer's, another output's and any other file alone."""
    dead = subprocess.Popen(["true"])
    dead.wait()  # (a pid no process has now)
    out = tmp_path / "rec.mcap"
    left = tmp_path / f".rec.mcap.{dead.pid}.tmp"
    left.write_bytes(b"half a recording")
    live = tmp_path / f".rec.mcap.{os.getppid()}.tmp"  # (a live process's: a concurrent writer)
    live.write_bytes(b"being written")
    other = tmp_path / f".other.mcap.{dead.pid}.tmp"
    other.write_bytes(b"another output's")
    mine = tmp_path / f".rec.mcap.{dead.pid}.tmp.keep"
    mine.write_bytes(b"not the pattern")
    outputs.write_bytes(b"done", out)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([out.name, live.name, other.name, mine.name])
    # A dataset export's temporary folder likewise.
    folder = tmp_path / f".ds.{dead.pid}.tmp"
    (folder / "cam").mkdir(parents=True)
    assert outputs.remove_dead_temporaries(tmp_path / "ds") == [folder] and not folder.exists()
