"""The worker-process plumbing: failures reach the command as what they were, stopping never hangs."""

import multiprocessing
import os
import signal

import pytest

from core import processes


def _fails(sender):
    raise ArithmeticError("worker broke")


def _answers(value, sender):
    sender.send(("result", value))


def _exits(sender):
    os._exit(3)  # (dies without a word, as a killed worker does)


def test_a_worker_hands_over_its_result_or_its_error_and_is_reaped():
    worker = processes.Worker(_answers, ({"a": 1},), "test-worker", "test worker", pipe_bytes=1 << 20)
    worker.stop()  # (never started: nothing to stop)
    worker = processes.Worker(_answers, ({"a": 1},), "test-worker", "test worker", pipe_bytes=1 << 20)
    worker.start()
    assert worker.receive() == ("result", {"a": 1})
    worker.stop()
    worker = processes.Worker(_fails, (), "test-worker", "test worker")
    worker.start()
    with pytest.raises(ArithmeticError, match="worker broke") as failure:
        worker.receive()
    assert any("raised in the test worker process" in note for note in failure.value.__notes__)
    worker.stop()
    worker = processes.Worker(_exits, (), "test-worker", "test worker")
    worker.start()
    with pytest.raises(RuntimeError, match="the test worker process stopped unexpectedly"):
        worker.receive()
    worker.stop()
    assert worker.process.exitcode == 3
    assert multiprocessing.active_children() == []


def test_stopping_a_worker_that_ignores_sigterm_kills_it(monkeypatch):
    """A worker stuck where SIGTERM cannot end it is killed after the wait, and reaped: stopping never hangs."""
    monkeypatch.setattr(processes, "STOP_WAIT_S", 0.5)
    context = multiprocessing.get_context("fork")
    ready = context.Event()
    worker = context.Process(target=_ignore_sigterm_forever, args=(ready,), daemon=True)
    worker.start()
    assert ready.wait(60)  # (it has set SIGTERM aside)
    processes.stop_worker(worker, "test worker")
    assert worker.exitcode == -signal.SIGKILL
    assert multiprocessing.active_children() == []


def _ignore_sigterm_forever(ready):
    import time

    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    ready.set()
    while True:
        time.sleep(1)


_COMMAND_KILLED = """
import sys, time
from core import processes

def fill_the_pipe(sender):
    while True:  # (sends until the pipe is full, then blocks: the command never reads)
        sender.send(("block", b"x" * 65536))

worker = processes.Worker(fill_the_pipe, (), "test-worker", "test worker")
worker.start()
print(worker.process.pid, flush=True)
time.sleep(600)
"""


def test_a_worker_ends_when_its_command_is_killed_with_sigkill(tmp_path):
    """kill -9 of the command can stop nothing; its worker, blocked on a full pipe, must still end: it holds
    only its own end of the pipe (the reader's end gone, its send fails) and the kernel ends it with its
    parent (PR_SET_PDEATHSIG)."""
    import subprocess
    import sys
    import time

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    command = subprocess.Popen([sys.executable, "-c", _COMMAND_KILLED], stdout=subprocess.PIPE, text=True, cwd=root)
    worker_pid = int(command.stdout.readline())
    command.kill()
    command.wait()
    for _ in range(200):  # (up to 10 s)
        try:
            os.kill(worker_pid, 0)
        except ProcessLookupError:
            break
        if open(f"/proc/{worker_pid}/stat").read().split(") ")[1].startswith("Z"):
            break  # (ended, and waiting for init to reap it)
        time.sleep(0.05)
    else:
        os.kill(worker_pid, signal.SIGKILL)
        pytest.fail("the worker outlived its command")


def test_die_with_parent_ends_a_process_whose_parent_is_already_gone():
    """A worker whose command ended before it asked the kernel (its parent pid is no longer the command's)
    ends at once instead of running on as an orphan."""
    context = multiprocessing.get_context("fork")
    worker = context.Process(target=processes.die_with_parent, args=(os.getpid() + 1_000_000,))
    worker.start()
    worker.join(30)
    assert worker.exitcode == 1
