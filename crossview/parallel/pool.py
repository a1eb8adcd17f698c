"""The local process pool of `crossview.parallel`: tasks on a `ProcessPoolExecutor`, actors one process each.
Workers are forked from a fork server that has the heavy modules loaded (`Setup.preload`), not from the command,
whose threads a fork would copy in an unknown state. Every worker ends when the command does, even one killed
with SIGKILL (`core.processes.exit_with`). Moved here from `crossview/experiments/sweep.py` (tasks), unchanged in
behaviour.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import threading
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed

from core import processes
from crossview.parallel.workers import Actors, Setup, WorkerLost, run_task, warm


def _context(setup: Setup):
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(["crossview.parallel.pool", *setup.preload])
    return context


@contextlib.contextmanager
def tasks(fn, items: list, workers: int, setup: Setup) -> Iterator[Iterator[tuple]]:
    """fn(item) on a pool of `workers` processes; (item, result, error) as they finish. On Ctrl-C or SIGTERM
    the queued tasks are dropped and the running workers terminated."""
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=_context(setup), initializer=worker_started,
                               initargs=(os.getpid(),))
    finished = False
    try:
        futures = {pool.submit(run_task, fn, setup, item): item for item in items}

        def outcomes():
            for future in as_completed(futures):
                item = futures[future]
                try:
                    yield item, future.result(), None
                except Exception as e:  # noqa: BLE001 - the item's failure, handed to the caller
                    yield item, None, e

        yield outcomes()
        finished = True
    finally:
        if not finished:
            pool.shutdown(wait=False, cancel_futures=True)
            for process in multiprocessing.active_children():  # the pool's workers, still running a task
                process.terminate()
        pool.shutdown(wait=True)  # (the workers gone, the pool's own thread and queues end and are released)


def worker_started(driver_pid: int) -> None:
    """Gives tqdm a thread lock in a pool worker. Its progress bars (disabled in a worker) otherwise share a
    named semaphore, registered with multiprocessing's resource tracker, that a worker terminated on Ctrl-C or
    SIGTERM never releases: the tracker then warns of leaked semaphores. A worker runs one task at a time, in
    one thread, and shows no bar, so a thread lock is enough.

    The worker also ends when the command does, even one killed with SIGKILL (`processes.exit_with`): it
    would otherwise wait for tasks forever, and the fork server (which ends when the last holder of the
    command's end of its pipe does, a worker among them) and the resource tracker with it."""
    from tqdm import tqdm

    processes.exit_with(driver_pid)

    tqdm.set_lock(threading.RLock())


def _serve_actor(factory, args: tuple, setup: Setup, connection, driver_pid: int) -> None:
    """An actor's process: made once, then (method, args) in, ("ok", result) or ("error", exception) out, until
    the command closes its end. Ctrl-C is the command's (the whole group gets it); SIGTERM ends the actor."""
    worker_started(driver_pid)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    try:
        warm(setup)
        obj = factory(*args)
        connection.send(("ok", None))
    except Exception as e:  # noqa: BLE001 - handed to the command
        connection.send(("error", e))
        return
    while True:
        try:
            method, call_args = connection.recv()
        except EOFError:
            return
        try:
            connection.send(("ok", getattr(obj, method)(*call_args)))
        except Exception as e:  # noqa: BLE001 - handed to the command
            connection.send(("error", e))


class _Host:
    """One actor's process and the command's end of its pipe."""

    def __init__(self, context, factory, args: tuple, setup: Setup, name: str):
        self.name = name
        self.connection, theirs = context.Pipe(duplex=True)
        self.process = context.Process(target=_serve_actor, args=(factory, args, setup, theirs, os.getpid()),
                                       name=name, daemon=True)
        self.process.start()
        theirs.close()

    def receive(self):
        try:
            kind, payload = self.connection.recv()
        except (EOFError, ConnectionResetError):
            self.process.join(processes.STOP_WAIT_S)
            code = self.process.exitcode
            how = f"killed by signal {-code}" if code is not None and code < 0 else f"exit code {code}"
            raise WorkerLost(f"{self.name} (process {self.process.pid}) ended unexpectedly ({how})") from None
        if kind == "error":
            raise payload
        return payload

    def send(self, method: str, args: tuple) -> None:
        try:
            self.connection.send((method, args))
        except (BrokenPipeError, ConnectionResetError):
            pass  # (the loss is reported by `result`)

    def result(self, pending):
        return self.receive()

    def stop(self) -> None:
        self.connection.close()
        processes.stop_worker(self.process, self.name)


@contextlib.contextmanager
def actors(factory, args: list[tuple], setup: Setup, what: str) -> Iterator[Actors]:
    """One process per actor, forked from the fork server; all made before the block runs, all stopped after."""
    context = _context(setup)
    hosts: list[_Host] = []
    try:
        for index, a in enumerate(args):
            hosts.append(_Host(context, factory, a, setup, f"{what} {index}"))
        for host in hosts:  # (made concurrently: each answers once its object exists)
            host.receive()
        yield Actors(hosts)
    finally:
        for host in hosts:
            host.stop()
