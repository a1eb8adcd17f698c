"""The local process pool of `crossview.parallel`: tasks on a `ProcessPoolExecutor`, actors one process each.
Workers are forked from a fork server that has the heavy modules loaded (`Setup.preload`), not from the command,
whose threads a fork would copy in an unknown state. Every worker ends when the command does, even one killed
with SIGKILL (`core.processes.exit_with`). Moved here from `crossview/experiments/sweep.py` (tasks), unchanged in
behaviour.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import multiprocessing.util
import os
import shutil
import signal
import tempfile
import threading
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

from core import processes
from crossview import outputs
from crossview.parallel.workers import Actors, Setup, WorkerLost, run_task, warm

POOL_FOLDER = "crossview-pool-"
"""The command's folder in the system's temporary folder, `crossview-pool-PID-XXXXXXXX`, that holds
multiprocessing's own temporary folder (`pymp-*`, the fork server's socket): named after the command, so that
after a kill -9 the next pool can prove it dead and remove it (`_own_temporary_folder`)."""


def remove_dead_folders(prefix: str) -> None:
    """Removes the folders `PREFIX` + `PID-*` in the system's temporary folder whose process no longer exists (a
    command killed with SIGKILL, which could remove nothing); a live process's are left alone."""
    for folder in Path(tempfile.gettempdir()).glob(f"{prefix}*-*"):
        pid = folder.name[len(prefix):].partition("-")[0]
        if pid.isdigit() and not outputs.process_alive(int(pid)):
            shutil.rmtree(folder, ignore_errors=True)


_SOCKET_PATH_MAX = 108  # bytes of a Unix socket's path, its final NUL included (Linux's sun_path)
_own_folder: list[str] = []  # this process's POOL_FOLDER, once made


def _own_temporary_folder() -> None:
    """Before this process's first pool: removes the pool folders of dead commands, and makes multiprocessing's
    temporary folder (made once per process, removed by multiprocessing when the process exits normally) inside
    this process's own POOL_FOLDER, removed at exit too. A process whose multiprocessing folder already exists
    keeps it where it is."""
    if _own_folder:
        return
    remove_dead_folders(POOL_FOLDER)
    folder = tempfile.mkdtemp(prefix=f"{POOL_FOLDER}{os.getpid()}-")
    _own_folder.append(folder)
    if len(os.fsencode(folder)) + len("/pymp-12345678/listener-12345678") >= _SOCKET_PATH_MAX:
        os.rmdir(folder)  # (a long TMPDIR: the fork server's socket would not fit below it; pymp-* as ever)
        return
    # (at exit after multiprocessing's own folder, whose finalizer has priority -100)
    multiprocessing.util.Finalize(None, shutil.rmtree, args=(folder,), kwargs={"ignore_errors": True},
                                  exitpriority=-200)
    previous = tempfile.tempdir
    tempfile.tempdir = folder
    try:
        multiprocessing.util.get_temp_dir()
    finally:
        tempfile.tempdir = previous


def _context(setup: Setup):
    _own_temporary_folder()
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
            running = multiprocessing.active_children()  # the pool's workers, still running a task
            for process in running:
                process.terminate()
            for process in running:  # (gone before the caller goes on: it may remove what they left)
                process.join(processes.STOP_WAIT_S)
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
