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
