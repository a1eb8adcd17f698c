"""Ray for the executors (`crossview.parallel`): joining or starting an instance, the ending signals held while Ray
starts and stops, the wait for a task, and Ray's tasks and actors. Moved here from `crossview/experiments/sweep.py`,
unchanged in behaviour (see the commits that made `signals_held` and the no-cancel rule: the SIGTERM windows of
ray.init and ray.shutdown).
"""

from __future__ import annotations

import atexit
import contextlib
import logging
import os
import signal
import socket
import sys
import threading

from core.errors import CrossviewError, one_line
from crossview.parallel.reaper import Reaper
from crossview.parallel.workers import Actors, WorkerLost, run_task, warm

# Environment of Ray workers on a cluster (local workers inherit the driver's, which the CLI sets): one BLAS
# thread per process, and no MuJoCo rendering back-end to look for.
RAY_WORKER_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "MUJOCO_GL": "disable"}

# Ray's authentication mode (its environment variable) for a local instance a command starts: token, Ray's own
# default for a new local instance (`connect_ray`).
RAY_AUTH_MODE_ENV = "RAY_AUTH_MODE"
RAY_LOCAL_AUTH_MODE = "token"

# Ray's switch (its environment variable, read when Ray is imported) that keeps its C++ failure-signal handler out
# of a Python process: set for the command's driver and its local instance (`connect_ray`).
RAY_NO_FAILURE_HANDLER_ENV = ("RAY_DISABLE_FAILURE_SIGNAL_HANDLER", "1")


@contextlib.contextmanager
def session(address: str | None, connect: bool = True):
    """Ray connected for the block (`connect_ray`, with a `Reaper` for a local instance), disconnected at its end
    with the ending signals held, the reaper stopped even when ray.shutdown raises. `connect` False: nothing
    (a block with no Ray work). Yields whether this call connected."""
    reaper, disconnect = Reaper(), False
    try:
        disconnect = connect_ray(address, reaper) if connect else False
        yield disconnect
    finally:
        try:
            if disconnect:
                import ray

                with signals_held():
                    ray.shutdown()
        finally:
            reaper.stop()


def connect_ray(address: str | None, reaper: Reaper | None = None) -> bool:
    """Starts or joins Ray before any cell runs: `address` None starts a local instance (or joins the one
    $RAY_ADDRESS names); an address, once something answers there, joins that cluster. Where this process
    is already connected (a program that called `ray.init` itself), that connection is used.

    Args:
        address: the cluster to join, None for a local instance.
        reaper: started just before a local instance is (never for a cluster given by an address or
            $RAY_ADDRESS, whose processes are not the sweep's): once this process has ended, even killed with
            SIGKILL, it ends the processes the instance started (its raylet and GCS end with this process, but
            its agents and workers only ~90 s later, polling for their parent). The caller stops it. (Where
            `ray.init` joins an instance that `ray start` left running instead, the reaper ends none of it:
            its processes neither descend from this one nor carry the reaper's mark.)

    Returns:
        whether this call connected (and the sweep should disconnect at its end).

    Raises:
        CrossviewError: Ray is not installed, or the address cannot be reached.
    """
    if "ray" not in sys.modules:  # (Ray reads both settings below when it is first imported, so only before that)
        if not address and not os.environ.get("RAY_ADDRESS"):
            # The local instance this starts keeps Ray's default, token authentication, said explicitly: Ray warns
            # on every start where the mode is left unset (and only there). A mode the user set is kept; a cluster
            # joined decides its own.
            os.environ.setdefault(RAY_AUTH_MODE_ENV, RAY_LOCAL_AUTH_MODE)
        # Ray's failure-signal handler (a stack dump of its core) takes SIGTERM in this process from ray.init on,
        # and ray.shutdown sets SIGTERM back to the default before it stops the local instance: a SIGTERM in that
        # second then killed the sweep silently (exit -15) instead of ending it as the command's handler does.
        # Without it, SIGTERM stays the command's, or held, throughout (`signals_held`).
        os.environ.setdefault(*RAY_NO_FAILURE_HANDLER_ENV)
    try:
        import ray
    except ImportError:
        raise CrossviewError("--ray: Ray is not installed; install the extra: pip install "
                             "'crossview-testbed[ray]' (or pip install -e '.[ray]' in a checkout)") from None
    if address and address != "auto":
        check_reachable(address)
    if ray.is_initialized():  # (a program that connected already)
        return False
    if not address and reaper is not None and not os.environ.get("RAY_ADDRESS"):
        reaper.start()
    try:
        try:
            with signals_held():
                if address:
                    ray.init(address=address, runtime_env={"env_vars": RAY_WORKER_ENV}, log_to_driver=False,
                             logging_level=logging.WARNING)
                else:
                    ray.init(log_to_driver=False, logging_level=logging.WARNING)
        except BaseException:
            # A connection half made (a SIGTERM inside ray.init), or made just before a held signal, is undone:
            # left to the interpreter's exit, it crashed it.
            with signals_held():
                ray.shutdown()
            raise
    except (ConnectionError, RuntimeError, ValueError, TimeoutError) as e:
        # A cluster that `ray start` made (Ray 2.59 on) wants token authentication, and a driver joins it only with
        # the same mode set: Ray's refusal does not say so, the line does.
        hint = (f"; a cluster started by `ray start` wants its token: {RAY_AUTH_MODE_ENV}={RAY_LOCAL_AUTH_MODE} "
                "(and its token in ~/.ray/auth_token or RAY_AUTH_TOKEN)"
                if address and not os.environ.get(RAY_AUTH_MODE_ENV) else "")
        raise CrossviewError(f"--ray {address or ''}: cannot start or reach Ray ({one_line(e)}){hint}"
                             .replace("  ", " ")) from None
    return True


@contextlib.contextmanager
def signals_held():
    """Runs a call into Ray (ray.init, ray.shutdown) with the ending signals held: one that comes meanwhile is raised
    once the call has returned and the command's handlers are back, as the command's handler raises it (one line,
    128 + the signal). A signal raised inside the call would leave Ray half connected or half stopped (the
    interpreter's exit then crashed). ray.init puts its own SIGTERM handler over the holding one, which ends the
    process by sys.exit (exit 15 before the driver connects; 1 once a local head stopped its processes): a
    SystemExit out of the call is that SIGTERM. Outside the main thread (where handlers cannot be set) the call
    just runs."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: list[int] = []

    def hold(signum, frame):
        held.append(signum)

    handlers = {s: signal.signal(s, hold) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    try:
        yield
    except SystemExit:
        if not callable(handlers[signal.SIGTERM]):  # (a program's own handling: Ray's exit stands)
            raise
        held.append(signal.SIGTERM)
        # What Ray's handler leaves half made when it exits while ray.init connects (a core worker whose threads run
        # on, out of reach of ray.shutdown) crashes the interpreter's exit (SIGSEGV). The command unwinds and cleans
        # up as on any signal; the process then ends at the first step of that exit, with the signal's status.
        atexit.register(exit_at_once, 128 + signal.SIGTERM)
    finally:
        for signum, handler in handlers.items():
            signal.signal(signum, signal.SIG_DFL if handler is None else handler)  # (None: one set outside Python)
        if held:
            handler = handlers[held[0]]
            if callable(handler):
                handler(held[0], None)
            elif handler in (signal.SIG_DFL, None):
                signal.raise_signal(held[0])


def exit_at_once(status: int) -> None:
    """Ends the process at once (no finalization: Ray's exit handlers, C++ destructors) once its output is out."""
    for stream in (sys.stdout, sys.stderr, sys.__stdout__, sys.__stderr__):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(status)


RAY_CONNECT_TIMEOUT_S = 5.0
"""How long the check that a Ray address answers waits (`ray.init` itself retries an unreachable one forever)."""


def check_reachable(address: str) -> None:
    """Fails unless something listens at a Ray address (`HOST:PORT` or `ray://HOST:PORT`)."""
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not host or not port.isdigit():
        raise CrossviewError(f"--ray {address}: not an address of the form HOST:PORT (e.g. 10.0.0.5:6379) "
                             "or ray://HOST:PORT")
    try:
        socket.create_connection((host, int(port)), timeout=RAY_CONNECT_TIMEOUT_S).close()
    except OSError as e:
        raise CrossviewError(f"--ray {address}: unreachable ({e.strerror or e}); is `ray start --head` running "
                             "there, and the port open?") from None


def wait_one(ray, waiting: list) -> tuple[list, list]:
    """`ray.wait` for one task. A signal's exception (Ctrl-C, the command line's SIGTERM) raised while Ray's
    compiled core waits comes out of it as a SystemError ("returned a result with an exception set") caused by
    it: it is raised as itself, so that the sweep ends as on a signal anywhere else (one line, 128 + signal)."""
    try:
        return ray.wait(waiting, num_returns=1)
    except SystemError as e:
        if isinstance(e.__cause__, BaseException) and not isinstance(e.__cause__, Exception):
            raise e.__cause__ from None
        raise


@contextlib.contextmanager
def tasks(fn, items: list, setup, cancel_left: bool):
    """Ray tasks, one CPU each, never retried (a task that fails is handed over as failed); (item, result, error)
    as they finish. Ray reuses a worker process for the tasks of one function, so its warm-up runs once per process.

    Left early (Ctrl-C, SIGTERM, an error), with `cancel_left` the tasks not yet finished are cancelled
    (running ones force-stopped): for a connection the caller keeps, whose job goes on. Without it the command
    disconnects itself (`ray.shutdown`), and Ray ends the job's tasks with the job, on a local instance and on a
    joined cluster alike (measured: the running cells gone 1-3 s after SIGTERM, as with the cancel). Cancelling
    first there raced inside Ray with the tasks' replies: its driver aborted ("Tried to complete task that was
    not pending"), exit 1 and a stack dump instead of the command's one line, about one SIGTERM in eight."""
    import ray

    # (named after fn, not the wrapper: its worker's process title is ray::FN, e.g. ray::run_cell)
    task = ray.remote(num_cpus=1, max_retries=0)(run_task).options(name=getattr(fn, "__name__", "task"))
    refs: dict = {}
    finished = False
    try:
        refs = {task.remote(fn, setup, item): item for item in items}

        def outcomes():
            waiting = list(refs)
            while waiting:
                ready, waiting = wait_one(ray, waiting)
                for ref in ready:
                    item = refs[ref]
                    try:
                        yield item, ray.get(ref), None
                    except Exception as e:  # noqa: BLE001 - the item's failure, handed to the caller
                        yield item, None, e

        yield outcomes()
        finished = True
    finally:
        if not finished and cancel_left:
            for ref in refs:
                with contextlib.suppress(Exception):
                    ray.cancel(ref, force=True)


class ActorHost:
    """A Ray actor's body: the warm-up, then the object `factory(*args)`, whose methods `call` runs."""

    def __init__(self, factory, args: tuple, setup):
        warm(setup)
        self.obj = factory(*args)

    def ready(self) -> bool:
        """Answers once the object exists (its making done or failed)."""
        return True

    def call(self, method: str, args: tuple):
        return getattr(self.obj, method)(*args)


class _Handle:
    """The command's side of one Ray actor (`Actors`' host)."""

    def __init__(self, ray, actor, name: str):
        self.ray, self.actor, self.name = ray, actor, name

    def send(self, method: str, args: tuple):
        return self.actor.call.remote(method, args)

    def result(self, ref):
        try:
            return get_one(self.ray, ref)
        except self.ray.exceptions.RayActorError as e:
            raise WorkerLost(f"{self.name} (a Ray actor) ended unexpectedly ({one_line(e)})") from None
        except self.ray.exceptions.RayTaskError as e:
            raise e.as_instanceof_cause() from None


def get_one(ray, ref):
    """`ray.get` of one result, a signal's exception inside Ray's compiled core raised as itself (`wait_one`)."""
    wait_one(ray, [ref])
    return ray.get(ref)


@contextlib.contextmanager
def actors(factory, args: list[tuple], setup, what: str):
    """One Ray actor per args tuple (one CPU, never restarted), all made before the block runs, all ended after."""
    import ray

    remote = ray.remote(num_cpus=1, max_restarts=0, max_task_retries=0)(ActorHost)
    handles: list[_Handle] = []
    try:
        for index, a in enumerate(args):
            handles.append(_Handle(ray, remote.remote(factory, a, setup), f"{what} {index}"))
        for handle in handles:  # (made concurrently: each answers once its object exists)
            handle.result(handle.actor.ready.remote())
        yield Actors(handles)
    finally:
        for handle in handles:
            with contextlib.suppress(Exception):
                ray.kill(handle.actor, no_restart=True)
