"""`crossview track --zones` and `crossview zones`: the same tracks whatever the executor and worker count, an
ordinary tracks file that scores, and bad input refused in one line with nothing written."""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import signal
import subprocess
import time

import numpy as np
import pytest

from core import tracks
from crossview import parallel, pipeline, recording, zoned
from crossview.cli import EXIT_BAD_INPUT, main
from tests.crossview.signalling import CROSSVIEW


def outputs_digest(path) -> str:
    """sha256 of every output of a tracks file (camera, stamp, ids, poses, joint states, detections): its
    content without the summary's timings."""
    digest = hashlib.sha256()
    for out in recording.open_tracks(path).outputs():
        ids = np.array([t.id for t in out.targets], dtype=np.int64)
        poses = np.array([t.pose for t in out.targets], dtype=np.float64)
        states = np.array([t.joint_state for t in out.targets], dtype=np.uint8)
        for part in (out.camera.encode(), np.float64(out.stamp_s).tobytes(), ids.tobytes(), poses.tobytes(),
                     states.tobytes(), np.asarray(out.detection_target_ids, np.int64).tobytes()):
            digest.update(part)
    return digest.hexdigest()


@pytest.fixture(scope="module")
def zoned_serial(store_recording, tmp_path_factory):
    out = tmp_path_factory.mktemp("zoned") / "z.tracks.mcap"
    result = zoned.track_zoned(store_recording, out, zones_text="2", overlap_m=2.0, executor=parallel.Executor.SERIAL,
                               workers=1, progress=False)
    return out, result


def test_zoned_tracks_are_the_same_bytes_in_process_and_on_a_pool(zoned_serial, store_recording, tmp_path, capsys):
    out, result = zoned_serial
    assert result.zone_cameras == (12, 12) and result.updates > 0
    # Each zone tracked every frame of its cameras, counted here from the recording itself.
    rec = recording.open_recording(store_recording)
    cut = zoned.cut(list(rec.cameras), rec.boxes, "2", 2.0)
    names = [{rec.cameras[i].name for i in z.cameras} for z in cut]
    frames = [cf.frame.camera for cf in rec.frames()]
    assert result.zone_frames == tuple(sum(c in n for c in frames) for n in names)
    assert result.worker_peak_memory == (result.peak_memory,)  # (one worker: this process)
    pooled = tmp_path / "pool.tracks.mcap"
    capsys.readouterr()
    assert main(["--no-progress", "track", str(store_recording), "--zones", "2", "--workers", "2", "-o",
                 str(pooled)]) == 0
    assert outputs_digest(pooled) == outputs_digest(out)
    printed = capsys.readouterr().out
    for z, n in enumerate(result.zone_frames):
        assert f"  zone {z}: 12 cameras, {n} camera frames, update " in printed
    # Two worker processes, each holding numpy, numba's kernels and a tracker: tens of MiB at least.
    peaks = re.search(r"peak memory: (\d+) MiB this process; workers (\d+), (\d+) MiB", printed)
    assert peaks and all(50 <= int(m) < 64 * 1024 for m in peaks.groups())


def test_a_zoned_tracks_file_is_ordinary_and_scores_near_the_single_tracker(zoned_serial, store_recording,
                                                                              store_tracks):
    out, _ = zoned_serial
    ids = {t.id for o in recording.open_tracks(out).outputs() for t in o.targets}
    assert ids and all(tracks.namespace_of(i) in (0, 1) for i in ids)  # (each id names the zone that first saw it)
    _, zoned_score = pipeline.score(store_recording, out, progress=False)
    _, single = pipeline.score(store_recording, store_tracks, progress=False)
    assert zoned_score["pcp"] >= single["pcp"] - 0.02
    assert zoned_score["idf1"] >= single["idf1"] - 0.1
    # Every switch of the zoned run listed by place and cause (tests/crossview/scoring/test_switches.py); none for
    # the single tracker.
    assert len(zoned_score["switches_by_place"]) == zoned_score["id_switches"]
    assert single.get("switches_by_place") is None


def test_zoned_tracks_on_ray_are_the_pool_s(zoned_serial, store_recording, tmp_path):
    ray = pytest.importorskip("ray", reason="Ray is the extra '.[ray]' (CI installs it)")
    from crossview.parallel import cluster

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False,
             runtime_env={"env_vars": cluster.RAY_WORKER_ENV})
    try:
        out = tmp_path / "ray.tracks.mcap"
        zoned.track_zoned(store_recording, out, zones_text="2", overlap_m=2.0, executor=parallel.Executor.RAY,
                          workers=2, progress=False)
    finally:
        ray.shutdown()
    assert outputs_digest(out) == outputs_digest(zoned_serial[0])


@pytest.mark.parametrize(("options", "expected"), [
    (["--zones", "0"], "--zones 0: must be auto or a whole number of zones, at least 1"),
    (["--zones", "two"], "--zones two: must be auto or a whole number of zones, at least 1"),
    (["--zones", "6"], "--zones 6: cells of 1.6 x 2.0 m (3 x 2) are not wider than the overlap 2.0 m"),
    (["--zones", "2", "--overlap", "1"], "zone overlap 1.0 m: must be at least 2.0 m"),
    (["--zones", "2", "--overlap", "3"], "--zones 2: cells of 2.4 x 4.0 m (2 x 1) are not wider than the overlap"),
    (["--workers", "2"], "--workers: only with --zones"),
    (["--zones", "2", "--workers", "0"], "--workers: 0 must be >= 1"),
    (["--zones", "2", "--ray", "127.0.0.1:1"], "--ray 127.0.0.1:1: unreachable"),
], ids=["zones-0", "zones-word", "zones-too-many", "overlap-small", "overlap-wide", "workers-alone", "workers-0",
        "ray-unreachable"])
def test_bad_zoned_tracking_is_refused_in_one_line_and_writes_nothing(options, expected, store_recording, tmp_path,
                                                                      capsys):
    out = tmp_path / "out" / "t.mcap"
    assert main(["--no-progress", "track", str(store_recording), "-o", str(out), *options]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err.strip()
    assert expected in err and len(err.splitlines()) == 1
    assert not out.parent.exists() or not any(out.parent.iterdir())


@pytest.mark.parametrize(("options", "expected"), [
    (["--zones", "6"], "--zones 6: cells of 1.6 x 2.0 m (3 x 2) are not wider than the overlap 2.0 m"),
    (["--zones", "2", "--live"], "--live: not with --zones"),
], ids=["run-zones-too-many", "run-zones-live"])
def test_bad_zoned_run_is_refused_before_generating(options, expected, tmp_path, capsys):
    """`run --zones`: a cut the rig cannot hold, or --live, is refused before anything is generated."""
    out = tmp_path / "out"
    assert main(["--no-progress", "run", "store_layout1", "--duration", "1", "-o", str(out), *options]) == (
        EXIT_BAD_INPUT)
    err = capsys.readouterr().err.strip()
    assert expected in err and len(err.splitlines()) == 1
    assert not out.exists() or not any(out.iterdir())


def test_zones_prints_the_cut_and_draws_it(tmp_path, capsys):
    import cv2

    picture = tmp_path / "zones.png"
    assert main(["zones", "hypermarket", "--zones", "4", "-o", str(picture)]) == 0
    printed = capsys.readouterr().out
    assert "hypermarket: 4 zones, 240 cameras" in printed and printed.count("  zone ") == 4
    image = cv2.imread(str(picture))
    assert image is not None and image.shape[0] > 500


def _children(pid: int) -> list[int]:
    found = []
    for task in os.listdir(f"/proc/{pid}/task") if os.path.isdir(f"/proc/{pid}/task") else []:
        with contextlib.suppress(OSError), open(f"/proc/{pid}/task/{task}/children") as f:
            found += [int(c) for c in f.read().split()]
    return found


def _cmdline(pid: int) -> str:
    with contextlib.suppress(OSError), open(f"/proc/{pid}/cmdline", "rb") as f:
        return f.read().replace(b"\0", b" ").decode(errors="replace")
    return ""


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="finds the workers in /proc (Linux)")
def test_a_zone_worker_killed_mid_run_ends_the_command_in_one_line_with_nothing_left(store_recording, tmp_path):
    """kill -9 of a zone worker while it tracks: exit 2, the one line naming it, no tracks file, and none of the
    command's processes (fork server, workers) left."""
    out = tmp_path / "t.mcap"
    process = subprocess.Popen([*CROSSVIEW, "track", str(store_recording), "--zones", "2", "--workers", "2", "-o",
                                str(out)], stderr=subprocess.PIPE, text=True, start_new_session=True)
    workers: list[int] = []
    try:
        deadline = time.monotonic() + 120
        while len(workers) < 2 and process.poll() is None and time.monotonic() < deadline:
            servers = [c for c in _children(process.pid) if "forkserver" in _cmdline(c)]
            workers = [w for s in servers for w in _children(s)]
            time.sleep(0.05)
        assert len(workers) == 2, f"no zone workers seen (exit {process.poll()})"
        os.kill(workers[1], signal.SIGKILL)
        _, err = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
    assert process.returncode == EXIT_BAD_INPUT, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "zone worker" in lines[0] and "ended unexpectedly (killed by signal 9)" in lines[0]
    assert not out.exists() and [p.name for p in tmp_path.iterdir()] == []
    deadline = time.monotonic() + 30  # (the fork server and the resource tracker end a moment after the command)
    while _session(process.pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert _session(process.pid) == []


def _session(sid: int) -> list[int]:
    """The live processes of session `sid` (the command's: it started one)."""
    found = []
    for name in os.listdir("/proc"):
        if name.isdigit():
            with contextlib.suppress(OSError):
                if os.getsid(int(name)) == sid:
                    found.append(int(name))
    return found
