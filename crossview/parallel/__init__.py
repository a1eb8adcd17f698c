"""Executors for work beside the command: one-shot tasks (a sweep's cells) and long-lived actors (a zone's
tracker), on one interface, in this process (`Executor.SERIAL`), on a local process pool (`Executor.POOL`) or on
Ray (`Executor.RAY`, a local instance or a cluster joined by address: `cluster.session`).

The rule of every executor: a task's or an actor call's result depends only on its inputs, never on where it ran
or on how many workers there are, so the caller that orders results by its own keys gets the same bytes from
any executor and any worker count. A worker warms up once (`Setup`: the modules its fork server preloads, a
`warm_up` run once in each worker process before its first task or in each actor before its first call), not once
per task.

- `tasks(fn, items, ...)`: fn(item) for every item; yields (item, result, error) as they finish, where error is
  the Exception fn raised (None: it returned). A signal or Ctrl-C ends the block; the tasks left are dropped.
- `actors(factory, args, ...)`: one long-lived object per args tuple, each in its own worker; `Actors.call`
  calls one method on each, concurrently, and returns the results in the actors' order. An actor whose process
  dies (kill -9) raises `WorkerLost`, a `CrossviewError` naming it.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable, Iterator

from crossview.parallel.workers import Actors, Executor, Setup, WorkerLost, run_task, warm

__all__ = ["Actors", "Executor", "Setup", "WorkerLost", "actors", "tasks", "warm"]


@contextlib.contextmanager
def tasks(fn: Callable, items: Iterable, *, executor: Executor, workers: int = 1, setup: Setup = Setup(),
          started: Callable | None = None, cancel_left: bool = False) -> Iterator[Iterator[tuple]]:
    """fn(item) for every item on `executor`; yields an iterator of (item, result, error) in the order they finish.

    Args:
        fn, items: a module-level function and its picklable inputs.
        workers: processes of a pool.
        started: told of each item as it starts (serial only: elsewhere they start together).
        cancel_left: Ray: cancel the unfinished tasks when the block is left early, for a connection the
            caller keeps (`cluster.tasks`).
    """
    items = list(items)
    if executor is Executor.SERIAL:
        def outcomes():
            for item in items:
                if started is not None:
                    started(item)
                try:
                    yield item, run_task(fn, setup, item), None
                except Exception as e:  # noqa: BLE001 - the item's failure, handed to the caller
                    yield item, None, e

        yield outcomes()
    elif executor is Executor.POOL:
        from crossview.parallel import pool

        with pool.tasks(fn, items, workers, setup) as outcomes:
            yield outcomes
    else:
        from crossview.parallel import cluster

        with cluster.tasks(fn, items, setup, cancel_left) as outcomes:
            yield outcomes


class _Local:
    """An actor in this process (`Executor.SERIAL`)."""

    def __init__(self, factory, args: tuple, setup: Setup):
        warm(setup)
        self.obj = factory(*args)

    def send(self, method: str, args: tuple):
        return method, args  # (run by `result`: one actor's failure leaves the others' calls to run, as elsewhere)

    def result(self, pending):
        method, args = pending
        return getattr(self.obj, method)(*args)


@contextlib.contextmanager
def actors(factory: Callable, args: list[tuple], *, executor: Executor, setup: Setup = Setup(),
           what: str = "worker") -> Iterator[Actors]:
    """One actor per args tuple, `factory(*args[i])` made in its own worker (a pool: one process each; Ray: one
    actor, one CPU, never restarted), stopped when the block ends, whatever ends it.

    Args:
        factory: a module-level class or function; its result's methods are what `Actors.call` calls.
        what: how errors name an actor ("zone 3's tracker"), followed by its index.
    """
    if executor is Executor.SERIAL:
        yield Actors([_Local(factory, a, setup) for a in args])
    elif executor is Executor.POOL:
        from crossview.parallel import pool

        with pool.actors(factory, args, setup, what) as group:
            yield group
    else:
        from crossview.parallel import cluster

        with cluster.actors(factory, args, setup, what) as group:
            yield group
