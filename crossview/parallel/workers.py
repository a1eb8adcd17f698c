"""What every executor of `crossview.parallel` shares: where the work runs (`Executor`), a worker's setup and
its warm-up run once (`Setup`, `warm`, `run_task`), a lost worker (`WorkerLost`) and the handle on a group of
actors (`Actors`). The executors (`pool`, `cluster`) and the package's face import it; it imports neither.
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass

from core.errors import CrossviewError


class Executor(enum.Enum):
    """Where the work runs."""

    SERIAL = "serial"  # one after another in this process
    POOL = "pool"  # a local process pool
    RAY = "ray"  # Ray tasks and actors, on a local instance or a cluster


@dataclass(frozen=True)
class Setup:
    """What a worker does once, before its first task or call.

    preload: modules a pool's fork server imports once, so that each worker it forks starts with them loaded.
    warm_up: a module-level function run once in each worker (numba's kernels loaded, a throwaway tracker run).
    """

    preload: tuple[str, ...] = ()
    warm_up: Callable[[], None] | None = None


class WorkerLost(CrossviewError):
    """A worker or actor process ended while it held work (killed, out of memory)."""


_warmed: set = set()  # the warm-ups this process has run


def warm(setup: Setup) -> None:
    """Runs `setup.warm_up` unless this process already has."""
    if setup.warm_up is not None and setup.warm_up not in _warmed:
        setup.warm_up()
        _warmed.add(setup.warm_up)


def run_task(fn, setup: Setup, item):
    """A task in a worker: the worker's warm-up (once), then fn(item)."""
    warm(setup)
    return fn(item)


class Actors:
    """Long-lived objects in workers (`actors`): `call` runs one method on each, concurrently."""

    def __init__(self, hosts: list):
        self.hosts = hosts

    def __len__(self) -> int:
        return len(self.hosts)

    def call(self, method: str, args: list[tuple]) -> list:
        """Calls `method(*args[i])` on actor i for every i at once; their results in the actors' order. An
        actor's exception is raised here (the first actor's first); a lost worker raises `WorkerLost`."""
        return self.gather(self.submit(method, args))

    def submit(self, method: str, args: list[tuple]) -> list:
        """Starts `call` without waiting: the actors work while the caller does something else; `gather` gives
        the results. Gather one submission before the next is submitted (a pipe's results are read before more
        work is written into it)."""
        if len(args) != len(self.hosts):
            raise ValueError(f"{len(args)} argument tuples for {len(self.hosts)} actors")
        return [host.send(method, a) for host, a in zip(self.hosts, args, strict=True)]

    def gather(self, pending: list) -> list:
        """The results of a `submit`, in the actors' order (errors as `call` raises them)."""
        results, errors = [], []
        for host, p in zip(self.hosts, pending, strict=True):  # (every answer read: none left for the next call)
            try:
                results.append(host.result(p))
            except Exception as e:  # noqa: BLE001 - raised below, once all have answered
                results.append(None)
                errors.append(e)
        if errors:
            raise errors[0]
        return results
