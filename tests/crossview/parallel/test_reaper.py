"""The reaper of a local Ray instance's processes (`crossview.parallel.reaper`), moved with it from core."""

from __future__ import annotations

import os
import signal

import pytest

from crossview.parallel import reaper as processes

_COMMAND_WITH_A_REAPER = """
import subprocess, sys, time
from crossview.parallel import reaper as processes
reaper = processes.Reaper()
reaper.start()
child = subprocess.Popen(["sleep", "300"])
unmarked = subprocess.Popen(["sleep", "300"], env={})  # (its environment not the command's: a descendant only)
orphan = subprocess.run(["sh", "-c", "sleep 300 >/dev/null 2>&1 & echo $!"], capture_output=True, text=True)
print(child.pid, unmarked.pid, orphan.stdout.strip(), flush=True)  # (the orphan: adopted, marked only)
time.sleep(3600)
"""


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return not f.read().rsplit(") ", 1)[1].startswith("Z")  # (a zombie has ended)
    except OSError:
        return False


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="the reaper reads /proc (Linux)")
def test_a_reaper_ends_what_its_command_started_once_it_is_killed_and_nothing_else():
    """kill -9 of a command with a reaper: its child, a child whose environment is not the command's (known as
    a descendant), and an orphan whose parent had already ended (known by the mark) all end; a process carrying
    another mark of the same command's pid does not."""
    import subprocess
    import sys
    import time

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
    command = subprocess.Popen([sys.executable, "-c", _COMMAND_WITH_A_REAPER], stdout=subprocess.PIPE, text=True,
                               cwd=root)
    bystander = subprocess.Popen(["sleep", "300"], env={processes.MARK_ENV: f"{command.pid}-{'0' * 16}"})
    started = []
    try:
        started = [int(pid) for pid in command.stdout.readline().split()]
        assert len(started) == 3 and all(_alive(pid) for pid in started)
        time.sleep(3 * processes.REAP_INTERVAL_S)  # (the unmarked child noted as a descendant)
        command.kill()
        command.wait()
        for _ in range(300):  # (up to 30 s)
            if not any(_alive(pid) for pid in started):
                break
            time.sleep(0.1)
        left = [pid for pid in started if _alive(pid)]
        assert left == [] and bystander.poll() is None
    finally:
        for pid in started:
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)
        bystander.kill()
        bystander.wait()


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="the reaper reads /proc (Linux)")
def test_a_reaper_stopped_ends_what_is_left_and_takes_its_mark_off():
    """Stopped with a process it watched still running, the reaper ends it; the environment is as before."""
    import subprocess

    before = os.environ.get(processes.MARK_ENV)
    reaper = processes.Reaper()
    reaper.start()
    assert os.environ[processes.MARK_ENV] == reaper.mark and reaper.mark.startswith(f"{os.getpid()}-")
    child = subprocess.Popen(["sleep", "300"])
    reaper.stop()
    try:
        assert child.wait(timeout=30) == -signal.SIGKILL
    finally:
        child.kill()
    assert os.environ.get(processes.MARK_ENV) == before and reaper.pid is None
