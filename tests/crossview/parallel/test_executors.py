"""The executors of `crossview.parallel`: tasks and actors give the same results on every executor and worker
count, a worker warms up once, a failure is handed over as what it was, a killed actor is named."""

from __future__ import annotations

import hashlib
import os
import signal

import pytest

from crossview import parallel
from crossview.parallel import Executor, Setup

WARMED = []  # (in a worker: whether its warm-up ran)


def warm_up() -> None:
    WARMED.append(os.getpid())


def digest(item: int) -> tuple[str, int]:
    """A task: a result fixed by its input, and how many warm-ups its process has run."""
    if item == 5:
        raise ValueError("five is refused")
    return hashlib.sha256(str(item).encode()).hexdigest(), len(WARMED)


class Counter:
    """An actor with state: the running sum of what it is given, and the pid that holds it."""

    def __init__(self, start: int):
        self.total = start

    def add(self, value: int) -> tuple[int, int]:
        if value < 0:
            raise ValueError(f"negative: {value}")
        self.total += value
        return self.total, len(WARMED)

    def pid(self) -> int:
        return os.getpid()


SETUP = Setup(preload=("tests.crossview.parallel.test_executors",), warm_up=warm_up)


def _run(executor, workers):
    with parallel.tasks(digest, range(8), executor=executor, workers=workers, setup=SETUP) as outcomes:
        found = {item: (result, isinstance(error, ValueError) and str(error).endswith("five is refused"))
                 for item, result, error in outcomes}
    return found


@pytest.mark.parametrize(("executor", "workers"), [(Executor.POOL, 1), (Executor.POOL, 2)])
def test_tasks_give_the_serial_results_on_a_pool_of_any_size_each_worker_warmed_once(executor, workers):
    serial = _run(Executor.SERIAL, 1)
    found = _run(executor, workers)
    assert {k: (v[0] and v[0][0], v[1]) for k, v in found.items()} == {k: (v[0] and v[0][0], v[1])
                                                                      for k, v in serial.items()}
    assert serial[5] == (None, True)
    # Every task in a worker saw exactly one warm-up of its process, however many tasks that process ran.
    assert {v[0][1] for k, v in found.items() if k != 5} == {1}
    assert sorted(found) == list(range(8)) and all(hashlib.sha256(str(k).encode()).hexdigest() == v[0][0]
                                                   for k, v in found.items() if k != 5)


@pytest.mark.parametrize("executor", [Executor.SERIAL, Executor.POOL])
def test_actors_keep_their_state_between_calls_and_hand_over_their_errors(executor):
    with parallel.actors(Counter, [(0,), (100,)], executor=executor, setup=SETUP, what="counter") as group:
        assert group.call("add", [(1,), (2,)]) == [(1, 1), (102, 1)]
        assert group.call("add", [(10,), (20,)]) == [(11, 1), (122, 1)]
        with pytest.raises(ValueError, match="negative: -1"):
            group.call("add", [(-1,), (1,)])
        assert group.call("add", [(0,), (0,)]) == [(11, 1), (123, 1)]  # (no answer left over from the failure)
        pids = group.call("pid", [(), ()])
    assert (len(set(pids)) == 2 and os.getpid() not in pids) if executor is Executor.POOL else pids == [os.getpid()] * 2


def test_a_killed_pool_actor_is_named_and_the_others_stopped():
    lost = r"counter 1 \(process \d+\) ended unexpectedly \(killed by signal 9\)"
    with pytest.raises(parallel.WorkerLost, match=lost):
        with parallel.actors(Counter, [(0,), (0,)], executor=Executor.POOL, setup=SETUP, what="counter") as group:
            pids = group.call("pid", [(), ()])
            os.kill(pids[1], signal.SIGKILL)
            group.call("add", [(1,), (1,)])
    for pid in pids:  # (both reaped: neither is left, not even as a zombie)
        assert not os.path.exists(f"/proc/{pid}")


def test_tasks_and_actors_on_ray_give_the_serial_results():
    ray = pytest.importorskip("ray", reason="Ray is the extra '.[ray]' (CI installs it)")
    from crossview.parallel import cluster

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False,
             runtime_env={"env_vars": cluster.RAY_WORKER_ENV})
    try:
        found = _run(Executor.RAY, 2)
        with parallel.actors(Counter, [(0,), (100,)], executor=Executor.RAY, setup=SETUP, what="counter") as group:
            assert group.call("add", [(1,), (2,)]) == [(1, 1), (102, 1)]
            with pytest.raises(ValueError, match="negative: -1"):
                group.call("add", [(-1,), (1,)])
            pid = group.call("pid", [(), ()])[1]
            os.kill(pid, signal.SIGKILL)
            with pytest.raises(parallel.WorkerLost, match="counter 1 .a Ray actor. ended unexpectedly"):
                group.call("add", [(1,), (1,)])
    finally:
        ray.shutdown()
    serial = _run(Executor.SERIAL, 1)
    assert {k: (v[0] and v[0][0], v[1]) for k, v in found.items()} == {k: (v[0] and v[0][0], v[1])
                                                                      for k, v in serial.items()}
    assert {v[0][1] for k, v in found.items() if k != 5} == {1}


def test_dead_processes_folders_are_removed_and_only_those(tmp_path, monkeypatch):
    import subprocess
    import tempfile

    from crossview.parallel.pool import POOL_FOLDER, remove_dead_folders

    ended = subprocess.Popen(["true"])
    ended.wait()  # (a pid whose process is gone)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    for name in (f"{POOL_FOLDER}{ended.pid}-abc/pymp-x", f"{POOL_FOLDER}{os.getpid()}-abc/pymp-y",
                 f"{POOL_FOLDER}notapid-abc", f"crossview-cell-{ended.pid}-abc"):
        (tmp_path / name).mkdir(parents=True)
    remove_dead_folders(POOL_FOLDER)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        [f"{POOL_FOLDER}{os.getpid()}-abc", f"{POOL_FOLDER}notapid-abc", f"crossview-cell-{ended.pid}-abc"])


_POOL_IN_A_LONG_TMPDIR = """
from crossview import parallel
from crossview.parallel import Executor
if __name__ == "__main__":
    with parallel.tasks(abs, [-1, -2], executor=Executor.POOL, workers=1) as outcomes:
        print(sorted(r for _, r, _ in outcomes))
"""


# (60: room for pymp-* and its socket, not inside crossview-pool-*)
@pytest.mark.parametrize("length", [20, 60], ids=["short", "long"])
def test_a_pool_runs_and_leaves_nothing_whatever_the_length_of_tmpdir(tmp_path, length):
    """multiprocessing's folder (the fork server's socket) goes inside the command's own `crossview-pool-PID-*`
    unless the socket's path would then pass the 107 bytes a Unix socket allows: the pool runs either way."""
    import subprocess
    import sys
    import tempfile

    root = tempfile.mkdtemp(prefix="cv-")
    try:
        temporary = os.path.join(root, "t" * (length - len(root) - 1))
        os.mkdir(temporary)
        env = {**os.environ, "TMPDIR": temporary}
        done = subprocess.run([sys.executable, "-c", _POOL_IN_A_LONG_TMPDIR], capture_output=True, text=True,
                              env=env, timeout=120)
        assert (done.returncode, done.stdout.strip()) == (0, "[1, 2]"), done.stderr
        assert os.listdir(temporary) == []
    finally:
        import shutil

        shutil.rmtree(root, ignore_errors=True)
