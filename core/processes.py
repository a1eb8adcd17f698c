"""The plumbing of the forked worker processes that work beside a command (the simulation's, the 2D scorer's):
how many cores there are, how a worker starts, how its failure reaches the command, how it is stopped.

A worker ignores Ctrl-C (the whole process group gets it; the command decides), hands its error over to be
raised in the command, and is stopped and reaped whenever the command stops using it. (The reaper of a local Ray
instance's processes is `crossview.parallel.reaper`, beside the executors that start them.)
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import signal
import traceback

log = logging.getLogger(__name__)

_ENDING = {signal.SIGINT, signal.SIGTERM, signal.SIGHUP}

STOP_WAIT_S = 5.0
"""How long a stopping worker is given to end after SIGTERM, then after SIGKILL, seconds."""


def usable_cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def can_fork() -> bool:
    """Whether this platform starts processes by fork (a `Worker` needs it)."""
    return "fork" in multiprocessing.get_all_start_methods()


def can_fork_worker() -> bool:
    """Whether a worker process would run beside this one: more than one core, and fork to start it."""
    return usable_cores() > 1 and can_fork()


class Worker:
    """A daemon process forked to run target(*args, sender): what target sends on `sender` arrives through
    `receive`, through a pipe of `pipe_bytes` when given (Linux; elsewhere, or when refused, the system's
    default). The worker's signal handling, the hand-over of target's error and the closing of `sender` are
    the Worker's (`_serve`): target only computes and sends.

    Made first, started then, inside the try whose finally calls `stop`: a signal that arrives right after
    the fork (it is held back during it) then still finds the worker to stop.

    Args:
        what: how errors and warnings name it ("simulation worker").
    """

    def __init__(self, target, args: tuple, name: str, what: str, pipe_bytes: int | None = None):
        context = multiprocessing.get_context("fork")
        self.what = what
        self._receiver, self._sender = context.Pipe(duplex=False)
        if pipe_bytes:
            _widen_pipe(self._sender, pipe_bytes)
        self.process = context.Process(target=_serve, args=(target, args, self._sender, what, self._receiver,
                                                            os.getpid()), name=name, daemon=True)

    def start(self) -> None:
        """Forks the worker. It is born with the ending signals blocked, until `_worker_signals` has set its
        own handling: a Ctrl-C reaching the whole group a moment after the fork would otherwise raise in its
        start-up. (Here they wait for the fork, then arrive.)"""
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, _ENDING)
        try:
            self.process.start()
            self._sender.close()
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)

    def receive(self):
        """The next (kind, payload) the worker sent; its error, when it sent one, is raised here."""
        try:
            kind, payload = self._receiver.recv()
        except EOFError:
            raise RuntimeError(f"the {self.what} process stopped unexpectedly (exit code "
                               f"{self.process.exitcode})") from None
        if kind == "error":
            raise payload
        return kind, payload

    def stop(self) -> None:
        """Closes the pipe, and ends and reaps the worker if it was started (`stop_worker`)."""
        self._receiver.close()
        self._sender.close()
        if self.process.pid is not None:
            stop_worker(self.process, self.what)


def _serve(target, args: tuple, sender, what: str, receiver, parent_pid: int) -> None:
    """The worker process: its signal handling, then target(*args, sender); target's error is handed over to
    be raised in the command, and a command that is gone (a broken pipe) ends the worker quietly.

    The worker keeps only its end of the pipe (the command's end, copied by the fork, is closed: held here, a
    full pipe whose reader died would block the worker's send forever), and dies with the command
    (`die_with_parent`), even one killed with SIGKILL that could stop nothing."""
    receiver.close()
    die_with_parent(parent_pid)
    _worker_signals()
    try:
        target(*args, sender)
    except BrokenPipeError:  # the command is gone
        pass
    except BaseException as e:
        _send_error(sender, e, what)
    finally:
        sender.close()


_PR_SET_PDEATHSIG = 1  # prctl(2)'s option: the signal this process gets when its parent ends


def die_with_parent(parent_pid: int | None = None) -> None:
    """Makes this (forked) process end when its parent does: on Linux the kernel sends it SIGKILL then
    (prctl PR_SET_PDEATHSIG); a parent that ended before the request (this process adopted: its parent pid is
    no longer `parent_pid`, or is 1) ends it at once. Elsewhere nothing is asked (the pipes' ends, closed
    when the parent dies, end its workers there). The kernel watches the parent's thread that forked: a
    worker is started from a thread that outlives it (the commands start theirs from the main thread).

    Args:
        parent_pid: the parent's pid as the parent knew it; None: whatever parent this process has now.
    """
    import ctypes
    import ctypes.util
    import sys

    if not sys.platform.startswith("linux"):  # pragma: no cover - not Linux
        return
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):  # pragma: no cover - no libc to ask
        return
    if os.getppid() == 1 or (parent_pid is not None and os.getppid() != parent_pid):
        os._exit(1)


WATCH_INTERVAL_S = 1.0
"""How often `exit_with` looks whether the process it watches is gone where the system cannot tell it, s."""


def exit_with(pid: int) -> None:
    """Ends this process as soon as process `pid` (not its parent: a pool's worker is the fork server's child)
    is gone, even killed with SIGKILL: a daemon thread waits on a pidfd of it (Linux), or looks every
    `WATCH_INTERVAL_S`. A process already gone ends this one at once."""
    import select
    import threading

    try:
        fd = os.pidfd_open(pid)
    except ProcessLookupError:
        os._exit(1)
    except (AttributeError, OSError):  # pragma: no cover - no pidfd (before Linux 5.3, elsewhere)
        fd = None

    def watch() -> None:
        if fd is not None:
            select.select([fd], [], [])  # (readable once the process has ended)
            os._exit(1)
        while True:  # pragma: no cover - no pidfd
            try:
                os.kill(pid, 0)
            except ProcessLookupError:
                os._exit(1)
            except PermissionError:
                pass
            threading.Event().wait(WATCH_INTERVAL_S)

    threading.Thread(target=watch, name=f"exit-with-{pid}", daemon=True).start()


def _worker_signals() -> None:
    """In a worker: Ctrl-C is the command's to handle; SIGTERM and SIGHUP end the worker (the command's
    handlers, inherited through the fork, are not the worker's)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # (a Ctrl-C that came since the fork is dropped)
    for ending in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(ending, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, _ENDING)


def _send_error(sender, error: BaseException, what: str) -> None:
    """In a worker: hands `error` over to be raised in the command, with where it happened (a note with the
    worker's traceback); an error that cannot be pickled goes as a RuntimeError naming it."""
    error.add_note(f"raised in the {what} process:\n" + traceback.format_exc().rstrip())
    try:
        sender.send(("error", error))
    except BrokenPipeError:  # the command is gone
        pass
    except (TypeError, ValueError, AttributeError):  # an unpicklable error
        sender.send(("error", RuntimeError(f"{what}: {type(error).__name__}: {error}")))


def stop_worker(worker, what: str) -> None:
    """Ends the worker process and reaps it: SIGTERM, then SIGKILL if it has not ended in `STOP_WAIT_S` (it
    may be stuck, e.g. on a lock a fork copied held), so that stopping never hangs."""
    if worker.is_alive():
        worker.terminate()
        worker.join(STOP_WAIT_S)
    if worker.is_alive():
        log.warning("the %s process did not end on SIGTERM; killing it", what)
        worker.kill()
        worker.join(STOP_WAIT_S)
    if worker.exitcode is None:
        log.warning("the %s process %d could not be reaped", what, worker.pid)
    else:
        worker.join()


def _widen_pipe(connection, pipe_bytes: int) -> None:
    """Asks for a pipe of `pipe_bytes` (at most the system's limit) behind `connection`."""
    try:
        import fcntl

        with open("/proc/sys/fs/pipe-max-size") as f:
            limit = int(f.read())
        fcntl.fcntl(connection.fileno(), fcntl.F_SETPIPE_SZ, min(pipe_bytes, limit))
    except (ImportError, AttributeError, OSError, ValueError):
        pass
