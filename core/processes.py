"""The plumbing of the forked worker processes that work beside a command (the simulation's, the 2D scorer's):
how many cores there are, how a worker starts, how its failure reaches the command, how it is stopped.

A worker ignores Ctrl-C (the whole process group gets it; the command decides), hands its error over to be
raised in the command, and is stopped and reaped whenever the command stops using it. A `Reaper` ends, once the
command has ended (even killed with SIGKILL), the processes a library started for it (a local Ray instance's).
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import os
import secrets
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


MARK_ENV = "CROSSVIEW_PROCESS_MARK"
"""The environment variable that marks the processes started while a `Reaper` watches (theirs inherit it)."""

REAP_INTERVAL_S = 0.2
"""How often a `Reaper` notes the descendants of the process it watches, s."""

REAP_FOR_S = 5.0
"""How long a `Reaper` goes on ending the processes it finds once the process it watches has ended, s."""


class Reaper:
    """Ends, once this process has ended (even killed with SIGKILL, which lets it stop nothing itself), every process
    it started while the reaper ran: its descendants, and the processes carrying the reaper's mark in their
    environment (`MARK_ENV`, set in this process's environment from `start` to `stop` and inherited by all it starts),
    which finds those whose parent had already ended. For a library whose processes outlive a killed command: those
    of a local Ray instance (its agents poll for their parent, and end ~90 s later).

    The reaper is a small forked process holding the read end of a pipe whose write end only this process holds: the
    end of file it reads is this process's end, however it came. Until then it notes this process's descendants
    every `REAP_INTERVAL_S` (pid and start time: a pid used again is never taken for one of them), so that one whose
    environment a library has rewritten (a process title set over it) is still known once its parent is gone. Then
    it kills (SIGKILL) what it knows and what carries the mark, and their descendants, until none is left (at most
    `REAP_FOR_S`), and ends. The mark is this process's pid and a random nonce: no other run's process carries it.

    Linux only (it reads /proc): elsewhere `start` does nothing.
    """

    def __init__(self):
        self.mark = f"{os.getpid()}-{secrets.token_hex(8)}"
        self.pid: int | None = None
        self._write_fd: int | None = None
        self._environ_before: str | None = None

    def start(self) -> None:
        """Forks the reaper and marks this process's environment (`MARK_ENV`); the processes it starts from now on
        carry the mark. The reaper ignores the ending signals (Ctrl-C reaches the whole group: it is this process
        that decides, and the reaper's work begins when it has ended)."""
        if self.pid is not None or not os.path.isdir("/proc/self/task"):
            return
        read_fd, write_fd = os.pipe()  # (not inherited by the processes started later: close-on-exec)
        parent_pid = os.getpid()
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, _ENDING)
        try:
            pid = os.fork()
            if pid == 0:  # the reaper
                try:
                    os.close(write_fd)
                    for ending in _ENDING:
                        signal.signal(ending, signal.SIG_IGN)
                    signal.pthread_sigmask(signal.SIG_UNBLOCK, _ENDING)
                    _detach_files(keep=read_fd)
                    _reap(read_fd, parent_pid, self.mark)
                finally:
                    os._exit(0)
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        os.close(read_fd)
        self.pid, self._write_fd = pid, write_fd
        self._environ_before = os.environ.get(MARK_ENV)
        os.environ[MARK_ENV] = self.mark

    def stop(self) -> None:
        """Takes the mark off this process's environment and lets the reaper end what is left of the processes
        started since `start` (nothing, where they were stopped), then reaps it."""
        if self.pid is None:
            return
        if self._environ_before is None:
            os.environ.pop(MARK_ENV, None)
        else:
            os.environ[MARK_ENV] = self._environ_before
        os.close(self._write_fd)
        os.waitpid(self.pid, 0)
        self.pid = self._write_fd = None


def _detach_files(keep: int) -> None:
    """In the reaper: standard streams to /dev/null and every other file closed but `keep`, so that it holds none
    of the command's (a pipe its caller reads to its end, an output)."""
    null = os.open(os.devnull, os.O_RDWR)
    for fd in (0, 1, 2):
        os.dup2(null, fd)
    os.closerange(3, keep)
    os.closerange(keep + 1, os.sysconf("SC_OPEN_MAX") if hasattr(os, "sysconf") else 4096)


def _reap(read_fd: int, parent_pid: int, mark: str) -> None:
    """The reaper: notes `parent_pid`'s descendants until its end of file, then ends them and the marked processes."""
    import select
    import time

    known: dict[int, str] = {}  # pid: start time
    while not (select.select([read_fd], [], [], REAP_INTERVAL_S)[0] and os.read(read_fd, 1) == b""):
        known = {pid: started for pid, started in known.items() if _start_time(pid) == started}
        known.update(_descendants(parent_pid))
    known.pop(os.getpid(), None)
    marked = f"{MARK_ENV}={mark}".encode()
    deadline = time.monotonic() + REAP_FOR_S
    while time.monotonic() < deadline:
        table = _process_table()  # pid: (parent pid, start time)
        found = {pid for pid, started in known.items() if pid in table and table[pid][1] == started}
        found |= {pid for pid in table if _has_environ(pid, marked)}
        found |= {pid for pid in table if _has_ancestor_in(pid, found, table)}
        found.discard(os.getpid())
        if not found:
            return
        for pid in found:
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)
        time.sleep(REAP_INTERVAL_S / 2)


def _stat(pid: int) -> list[str] | None:
    """/proc/PID/stat's fields from the state on (the third), or None for a process gone."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            return f.read().rsplit(b") ", 1)[1].decode().split()
    except (OSError, IndexError):
        return None


def _start_time(pid: int) -> str | None:
    """When process `pid` started (clock ticks since boot), None for one gone or a zombie."""
    fields = _stat(pid)
    return fields[19] if fields and fields[0] != "Z" else None


def _descendants(pid: int) -> dict[int, str]:
    """The descendants of process `pid` that are alive, with their start times (each thread's children)."""
    found: dict[int, str] = {}
    parents = [pid]
    while parents:
        parent = parents.pop()
        try:
            threads = os.listdir(f"/proc/{parent}/task")
        except OSError:
            continue
        for thread in threads:
            try:
                with open(f"/proc/{parent}/task/{thread}/children") as f:
                    children = [int(c) for c in f.read().split()]
            except (OSError, ValueError):
                continue
            for child in children:
                started = _start_time(child)
                if started is not None and child not in found:
                    found[child] = started
                    parents.append(child)
    return found


def _process_table() -> dict[int, tuple[int, str]]:
    """Every live process: its parent's pid and its start time."""
    table = {}
    for name in os.listdir("/proc"):
        if name.isdigit():
            fields = _stat(int(name))
            if fields and fields[0] != "Z":
                table[int(name)] = (int(fields[1]), fields[19])
    return table


def _has_environ(pid: int, entry: bytes) -> bool:
    """Whether process `pid`'s environment holds `entry` (NAME=VALUE) as it was started (one it may not read: no)."""
    try:
        with open(f"/proc/{pid}/environ", "rb") as f:
            return entry in f.read().split(b"\0")
    except OSError:
        return False


def _has_ancestor_in(pid: int, pids: set[int], table: dict[int, tuple[int, str]]) -> bool:
    """Whether one of process `pid`'s ancestors (in `table`) is in `pids`."""
    seen = set()
    while pid in table and pid not in seen:
        seen.add(pid)
        pid = table[pid][0]
        if pid in pids:
            return True
    return False


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
