"""Runs a crossview command as a real process and signals it at a chosen moment (the signal tests of every
command, and the sweep's under Ray)."""

import os
import signal
import subprocess
import sys
import time

# (-X faulthandler: should the process crash instead, its stderr, in the failure's message, says where)
CROSSVIEW = [sys.executable, "-X", "faulthandler", "-c", "from crossview.cli import run; run()", "--no-progress"]


def signal_when(argv, ready, what: str, signum: int, env=None, group: bool = False) -> tuple[str, int]:
    """Runs `crossview ARGV`, signals it (its whole process group with `group`, as Ctrl-C in a terminal does)
    once ready(process) holds; returns its stderr and process id (which is its group's)."""
    # (SIGINT at its default, as in a terminal: a shell starts background jobs, and so a suite run in the
    # background, with SIGINT ignored, which Python and its children keep)
    process = subprocess.Popen([*CROSSVIEW, *argv], stderr=subprocess.PIPE, text=True, start_new_session=True,
                               env=env, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 300
        while not ready(process) and process.poll() is None and time.monotonic() < deadline:
            time.sleep(0.002)
        process.send_signal(signal.SIGSTOP)
        assert ready(process), f"{argv}: never {what} (exit {process.poll()})"
        if group:
            os.killpg(process.pid, signum)
        else:
            process.send_signal(signum)
        process.send_signal(signal.SIGCONT)
        _, err = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
    assert process.returncode == 128 + signum, err
    return err, process.pid
