"""The reaper of the processes a library starts for a command (a local Ray instance's): once the command has ended,
even killed with SIGKILL, it ends them. Moved here from `core/processes.py`, beside the executors that start Ray
(`crossview.parallel.cluster`); Linux only (it reads /proc).
"""

from __future__ import annotations

import contextlib
import os
import secrets
import signal

_ENDING = {signal.SIGINT, signal.SIGTERM, signal.SIGHUP}


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
