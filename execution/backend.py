"""Backends that run work units: this process, a process pool, or Ray tasks.

:func:`execute` is the only entry point callers need; :class:`Backend` says where the units
run. See the package docstring for what a unit is. The local pool is here; Ray is in
:mod:`execution.on_ray`, and what runs in a worker around each unit in :mod:`execution.worker`.
"""

from __future__ import annotations

import atexit
import logging
import os
import signal
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from multiprocessing import get_context
from numbers import Integral
from typing import Any, TypeVar

from execution.on_ray import _connect, _import_ray, _release_ray, _run_ray, _stop_started_ray
from execution.ray_address import _address_problem, _check_reachable
from execution.worker import (
    _IN_FLIGHT_PER_SLOT,
    WORKERS_LOST,
    BackendUnavailableError,
    RemoteTraceback,
    UnitError,
    WorkerLostError,
    _exit_reason,
    _label,
    _note_origin,
    _run_unit,
    _start_worker,
    error_line,
    pin_threads,
    unit_origin,
)

__all__ = [
    "BACKENDS",
    "POOL_IDLE_S",
    "WORKERS_LOST",
    "Backend",
    "BackendUnavailableError",
    "RemoteTraceback",
    "UnitError",
    "WorkerLostError",
    "backend_from_args",
    "error_line",
    "execute",
    "pin_threads",
    "shutdown_pools",
    "unit_origin",
]

U = TypeVar("U")
R = TypeVar("R")

#: The backends by name: ``local`` (this process or a process pool) and ``ray``.
BACKENDS = ("local", "ray")

#: Where a worker's death is reported (one warning line each; with no logging configured,
#: Python prints a warning's message alone on stderr).
_LOG = logging.getLogger("execution")


@dataclass(frozen=True)
class Backend:
    """Where work units run.

    :param kind: ``"local"`` or ``"ray"``.
    :param workers: local: processes (1 = this process, no pool); ray: units in flight at once
        (None = the cluster's CPUs / ``cpus_per_task``; the local Ray started when no cluster is
        named gets ``workers * cpus_per_task`` CPUs, or all of this machine's).
    :param address: ray only: the cluster (``"auto"``, ``"local"``, ``"ray://host:10001"``,
        ``"host:6379"``); None uses ``RAY_ADDRESS`` when set, else starts a local Ray. If Ray
        is already initialised in this process it is used, but only if it is the cluster named
        (``auto`` and ``local`` match any).
    :param cpus_per_task: CPUs each unit is given and pins its threads to (1..64).
    :param max_retries: times a unit whose worker died is run again (0..100), counted per unit;
        an exception the unit itself raises is never retried. The death counts against the
        unit the dead worker was running (in a local pool, against every unit in flight if that
        is not known: a worker ended by SIGTERM, as the pool ends the others). Each death is
        logged as a warning (logger ``execution``) naming the unit.

    Integers may be numpy integers; they are stored as ``int``.
    """

    kind: str = "local"
    workers: int | None = None
    address: str | None = None
    cpus_per_task: int = 1
    max_retries: int = 3

    def __post_init__(self) -> None:
        if self.kind not in BACKENDS:
            raise ValueError(
                f"backend={self.kind!r} is unknown: must be one of {', '.join(BACKENDS)}"
            )
        _check_int(self, "workers", 1, 4096, optional=True)
        _check_int(self, "cpus_per_task", 1, 64)
        _check_int(self, "max_retries", 0, 100)
        if self.address is not None:
            if self.kind != "ray":
                raise ValueError(f"address={self.address!r} is given but backend is {self.kind!r}")
            # Here, not when Ray connects: a typo is then refused with the other options, before
            # a command writes anything, and as a bad value rather than an unreachable cluster.
            problem = _address_problem(self.address)
            if problem is not None:
                raise ValueError(f"address={self.address!r} is not allowed: {problem}")

    def check_reachable(self) -> None:
        """Fail fast, without ``ray.init``, if this is Ray at a cluster address (given or
        ``RAY_ADDRESS``; ``auto`` resolved as Ray resolves it) that no Ray GCS answers at
        within ``execution.ray_address.GCS_ANSWER_S`` (20 s); callers check it before they
        write anything.

        :raises BackendUnavailableError: naming the address.
        """
        address = self.address or os.environ.get("RAY_ADDRESS")
        if self.kind == "ray" and address:
            _check_reachable(address)

    def reach(self) -> None:
        """Connect now, as the first call would (ray: join the cluster named, or start the
        local Ray, kept for the calls that follow as ``execute`` keeps it; local: nothing), so
        that a caller finds an unreachable backend before it writes anything.

        :raises BackendUnavailableError: naming the address, or why Ray did not start.
        """
        if self.kind != "ray":
            return
        self.check_reachable()  # first: a Ray initialised here would be refused for another
        _connect(self)
        _release_ray(POOL_IDLE_S)

    def slots(self) -> int:
        """Units that run at once: local, the workers; ray, the cluster's CPUs (connects)."""
        if self.kind == "local":
            return self.workers or 1
        if self.workers is not None:
            return self.workers
        ray = _connect(self)
        try:
            cpus = int(ray.cluster_resources().get("CPU", 1))
        finally:
            _release_ray(POOL_IDLE_S)
        return max(1, cpus // self.cpus_per_task)


def _check_int(backend: Backend, name: str, low: int, high: int, *, optional: bool = False) -> None:
    """Refuse ``backend.<name>`` unless an integer in ``low..high``; store it as ``int``.

    numpy integers count (a value read from an array or a config): the same test as
    ``follow_env.sim.checks.is_integer``, not imported from there because this package imports
    nothing of the project.
    """
    value = getattr(backend, name)
    if value is None and optional:
        return
    if isinstance(value, bool) or not isinstance(value, Integral) or not low <= value <= high:
        raise ValueError(f"{name}={value!r} is out of range: must be an integer in {low}..{high}")
    # As int: Ray's options and the kept pools' keys want the same plain value either way.
    object.__setattr__(backend, name, int(value))


def backend_from_args(
    kind: str = "local",
    *,
    workers: int | None = None,
    address: str | None = None,
    cpus_per_task: int = 1,
) -> Backend:
    """The backend a command line names (``--backend``, ``--workers``, ``--address``).

    :raises ValueError: for an unknown backend or an out-of-range value (names the option).
    :raises BackendUnavailableError: for ``ray`` when Ray is not installed (says how to install it).
    """
    backend = Backend(kind, workers=workers, address=address, cpus_per_task=cpus_per_task)
    if backend.kind == "ray":
        _import_ray()
    return backend


def execute(
    fn: Callable[[U], R],
    units: Iterable[U],
    backend: Backend | None = None,
    *,
    done: Mapping[int, R] | None = None,
    on_result: Callable[[int, R], None] | None = None,
    describe: Callable[[U], str] | None = None,
) -> list[R]:
    """Run ``fn(unit)`` for every unit on ``backend``; the results in the units' order.

    :param fn: a module-level function (pickled by reference for a pool or Ray); pure in its
        unit, so that a retry or another backend gives the same result.
    :param units: the units (picklable).
    :param backend: where to run them (default: this process).
    :param done: results already had, by unit index (a resumed run): those units are skipped.
    :param on_result: called in this process as each unit finishes (in the order they finish)
        with its index and result: a progress bar, a journal for resuming.
    :param describe: names a unit in messages (a worker's death, :class:`WorkerLostError`,
        :func:`unit_origin`), in its caller's terms; default its ``repr``, cut short.
    :raises WorkerLostError: if a unit's worker died more than ``backend.max_retries`` times.
    :raises UnitError: in place of an exception of ``fn`` that cannot be pickled, from a pool
        or Ray worker.
    :raises BackendUnavailableError: if Ray is wanted and missing or its cluster unreachable.
    :raises Exception: whatever ``fn`` raised for a unit, as it raised it; from a pool or Ray
        worker with the worker's traceback as its ``__cause__`` (:class:`RemoteTraceback`) and
        the unit and host in a note (:func:`unit_origin`).
    """
    backend = backend or Backend()
    work = list(units)
    missing = object()
    results: list[Any] = [missing] * len(work)
    for i, result in (done or {}).items():
        if not 0 <= i < len(work):
            raise ValueError(f"done holds unit {i}, but there are {len(work)} units")
        results[i] = result
    todo = [(i, u) for i, u in enumerate(work) if results[i] is missing]
    if backend.kind == "local":
        ran = _run_local(fn, todo, backend, describe)
    else:  # the idle time read now: tests shorten it
        ran = _run_ray(fn, todo, backend, describe, POOL_IDLE_S)
    for i, result in ran:
        results[i] = result
        if on_result is not None:
            on_result(i, result)
    return results


# -- local ------------------------------------------------------------------------------------


def _run_local(
    fn: Callable[[Any], Any],
    todo: Sequence[tuple[int, Any]],
    backend: Backend,
    describe: Callable[[Any], str] | None = None,
) -> Iterator[tuple[int, Any]]:
    workers = backend.workers or 1
    # On the workers asked for, not on the number of units: a caller that asked for a pool
    # asked for its crash isolation, retries and pinned threads even for one unit (and the
    # pool is kept, so a later call does not start it again). Callers that want small runs in
    # this process ask for workers=1 (eval.rollout.auto_workers does).
    if workers <= 1:
        for i, unit in todo:
            yield i, fn(unit)
        return
    if not todo:
        return  # nothing to run: no pool to start
    pending = dict(todo)
    deaths: dict[int, int] = {}  # by unit: times its worker died (see below)
    while pending:
        submitted: set[int] = set()
        lost: list[tuple[int, int | None]] = []
        try:
            yield from _pool_pass(
                fn, pending, workers, backend.cpus_per_task, submitted, lost, describe
            )
        except BrokenProcessPool as e:
            # A worker died (killed, out of memory): the pool is gone with every unit it held.
            # Units are pure, so running the unfinished ones again in a new pool is a retry.
            # The death counts against the unit the worker was running; if that is not known
            # (it was killed by SIGTERM, like the pool's other workers, or between units),
            # against every unit in flight, or every pending one: some unit must count it, or
            # a pool that can never run would be restarted for ever.
            in_flight = {i for i in submitted if i in pending}
            known = {i: code for i, code in lost if i in in_flight}
            charged = sorted(known) or sorted(in_flight) or sorted(pending)
            for i in charged:
                deaths[i] = deaths.get(i, 0) + 1
            codes = [code for _, code in lost]  # of every worker that died on its own
            over = [i for i in charged if deaths[i] > backend.max_retries]
            if over:
                i = over[0]
                reason = _exit_reason(known[i] if i in known else codes[0] if codes else None)
                label = _label(describe, pending[i])
                raise WorkerLostError(
                    i, label, deaths[i], backend.max_retries, len(pending), reason
                ) from e
            _warn_deaths(charged, known, codes, pending, deaths, backend.max_retries, describe)


def _warn_deaths(
    charged: Sequence[int],
    known: Mapping[int, int | None],
    codes: Sequence[int | None],
    pending: Mapping[int, Any],
    deaths: Mapping[int, int],
    max_retries: int,
    describe: Callable[[Any], str] | None,
) -> None:
    """One warning line per worker death that the pool survives, naming the unit it ran (or
    the units in flight when that is not known) and how the worker ended."""
    if known:
        for i in charged:
            _LOG.warning(
                "warning: a worker process died running unit %d %s, %s; it runs again "
                "(retry %d of max_retries=%d)",
                i, _label(describe, pending[i]), _exit_reason(known[i]), deaths[i], max_retries,
            )  # fmt: skip
        return
    units = ", ".join(map(str, charged[:8])) + (", ..." if len(charged) > 8 else "")
    _LOG.warning(
        "warning: a worker process died %s, while units %s were in flight (which one it ran "
        "is not known); they run again (a retry of max_retries=%d each)",
        _exit_reason(codes[0] if codes else None), units, max_retries,
    )  # fmt: skip


#: A kept pool's workers exit after this long without a unit (s): long enough to span the
#: batches of one command (a tuning search's trials, a run's episodes and then its scoring, each
#: a fraction of a second apart), short enough that an interactive session does not hold an idle
#: worker's memory (about 0.5 GB each with an agent loaded, measured) for long after its last call.
POOL_IDLE_S = 60.0

#: The pools kept between calls of :func:`execute`, by (workers, CPUs per worker), and the
#: timers that stop the idle ones; both under ``_POOLS_LOCK`` (a timer fires on its own thread).
_POOLS: dict[tuple[int, int], ProcessPoolExecutor] = {}
_IDLE: dict[tuple[int, int], threading.Timer] = {}
_BUSY: dict[tuple[int, int], int] = {}  # passes running on each pool (threads may share one)
_POOLS_LOCK = threading.Lock()


class _Pool(ProcessPoolExecutor):
    """A pool of spawned workers pinned to ``cpus`` CPUs each, which exit with this process
    and say which unit each runs (in :attr:`slots`), so that a dead worker's unit is known."""

    def __init__(self, workers: int, cpus: int) -> None:
        context = get_context("spawn")
        # Per worker: its pid and the index of the unit it runs (-1: none). Shared memory,
        # not a queue: a worker that dies mid-unit has written it already, and nothing has to
        # be read while the pool runs.
        self.slots = context.Array("q", 2 * workers)
        # spawn, not fork: a forked child of a process with live threads (tqdm's monitor,
        # BLAS pools) can deadlock; spawned workers load the cached kernels in about 2 s.
        super().__init__(
            workers,
            mp_context=context,
            initializer=_start_worker,
            initargs=(cpus, os.getpid(), self.slots),
        )

    def dead_workers(self, processes: Iterable[Any]) -> list[tuple[int, int | None]]:
        """Those of ``processes`` (this pool's, all exited) that died on their own, not ended by
        SIGTERM as the pool ends the others when one dies: (the unit each ran, -1 if none or
        not known; its exit code)."""
        codes = {p.pid: _exit_code(p) for p in processes}
        died = {pid: code for pid, code in codes.items() if code not in (None, -signal.SIGTERM)}
        # Read without the lock: a worker killed while holding it would never release it.
        slots = self.slots.get_obj()
        running = {slots[k]: slots[k + 1] for k in range(0, len(slots), 2) if slots[k]}
        return [(running.get(pid, -1), code) for pid, code in died.items()]


def _exit_code(process: Any, timeout_s: float = 1.0) -> int | None:
    """The exit code of ``process``, which has exited (None if none is known within
    ``timeout_s``).

    Waited for: the pool's own thread may have reaped the process a moment before this one
    looked, and not yet stored its code (``exitcode`` is None meanwhile).
    """
    deadline = time.monotonic() + timeout_s
    while process.exitcode is None and time.monotonic() < deadline:
        time.sleep(0.01)
    return process.exitcode


def _pool(workers: int, cpus: int) -> ProcessPoolExecutor:
    """The kept pool of ``workers`` processes pinned to ``cpus`` CPUs each, started if need be.

    Kept, because a caller may run many small batches (a tuning search asks for a few
    episodes at a time; a run scores its episodes after running them), and a spawned pool
    costs about 2 s to start. Its processes start as units arrive, not all at once.
    """
    key = (workers, cpus)
    with _POOLS_LOCK:
        timer = _IDLE.pop(key, None)
        if timer is not None:
            timer.cancel()
        if key not in _POOLS:
            _POOLS[key] = _Pool(workers, cpus)
            _BUSY[key] = 0
        _BUSY[key] += 1
        return _POOLS[key]


def _keep(key: tuple[int, int], pool: ProcessPoolExecutor) -> None:
    """``pool`` has finished its units: stop it if no call takes it within ``POOL_IDLE_S``."""
    with _POOLS_LOCK:
        if _POOLS.get(key) is not pool:
            return
        _BUSY[key] -= 1
        if _BUSY[key]:
            return  # another thread's pass is running on it
        timer = threading.Timer(POOL_IDLE_S, _expire, (key, pool))
        timer.daemon = True
        _IDLE[key] = timer
        timer.start()


def _expire(key: tuple[int, int], pool: ProcessPoolExecutor) -> None:
    with _POOLS_LOCK:
        # A call that took the pool meanwhile cancelled this timer (or replaced it).
        if _IDLE.get(key) is not threading.current_thread() or _POOLS.get(key) is not pool:
            return
        del _IDLE[key], _POOLS[key], _BUSY[key]
    pool.shutdown(wait=True)


#: How long a terminated pool worker is given to exit before it is killed (s).
_TERMINATE_S = 2.0


def _drop(key: tuple[int, int], pool: ProcessPoolExecutor) -> list[Any]:
    """Forget ``pool`` (it failed, or holds units nobody waits for) and end its workers now.

    Terminated, not shut down: a shutdown lets each worker finish the unit it runs, and after
    an error or Ctrl-C the command would wait for units whose results nobody wants (minutes,
    for a training run).
    """
    with _POOLS_LOCK:
        if _POOLS.get(key) is pool:
            del _POOLS[key], _BUSY[key]
    # Taken before the shutdown, which forgets them. A private attribute, but the only handle
    # on the workers before Python 3.14's terminate_workers().
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.terminate()
    for process in processes:
        process.join(_TERMINATE_S)
        if process.is_alive():  # SIGTERM caught or ignored by the unit
            process.kill()
            process.join(_TERMINATE_S)
    return processes


def shutdown_pools() -> None:
    """Stop the worker processes kept between calls of :func:`execute` (at exit, or to free
    their memory before ``POOL_IDLE_S`` does; the next call with a pool starts a new one), and
    the local Ray that :func:`execute` started, if it did and it is idle."""
    _stop_started_ray()
    with _POOLS_LOCK:
        pools = list(_POOLS.values())
        _POOLS.clear()
        _BUSY.clear()
        for timer in _IDLE.values():
            timer.cancel()
        _IDLE.clear()
    for pool in pools:
        pool.shutdown(wait=True, cancel_futures=True)


atexit.register(shutdown_pools)


def _pool_pass(
    fn: Callable[[Any], Any],
    pending: dict[int, Any],
    workers: int,
    cpus: int,
    submitted: set[int] | None = None,
    lost: list[tuple[int, int | None]] | None = None,
    describe: Callable[[Any], str] | None = None,
) -> Iterator[tuple[int, Any]]:
    """One pass over the pending units on the kept pool; removes each from ``pending`` as it
    is yielded.

    :param submitted: the units submitted are added to it (those still pending when the pass
        fails were in flight).
    :param lost: if the pass fails, (unit or -1, exit code) of each worker that died on its own
        is added to it (:meth:`_Pool.dead_workers`).
    :param describe: names a unit whose exception is raised (:func:`execute`).
    """
    pool = _pool(workers, cpus)
    queue = iter(list(pending.items()))
    in_flight: dict[Future[Any], int] = {}

    def submit() -> None:
        for i, unit in queue:
            in_flight[pool.submit(_run_unit, fn, unit, i)] = i
            if submitted is not None:
                submitted.add(i)  # after: a submission that found the pool broken sent nothing
            return

    finished_all = False
    try:
        for _ in range(_IN_FLIGHT_PER_SLOT * workers):
            submit()
        while in_flight:
            finished, _ = wait(in_flight, return_when=FIRST_COMPLETED)
            for future in finished:
                i = in_flight.pop(future)
                try:
                    result = future.result()
                except BrokenProcessPool:
                    raise
                except BaseException as e:  # the unit's own: say which and where
                    _note_origin(e, i, _label(describe, pending[i]))
                    raise
                del pending[i]
                yield i, result
                # After the yield: a pool broken meanwhile (a worker died) raises here, and the
                # unit just finished must already have been handed out, or it would be neither
                # pending for the retry nor in the results.
                submit()
        finished_all = True
    finally:
        if finished_all:
            _keep((workers, cpus), pool)
        else:
            # An error, a dead worker, Ctrl-C or a caller that stopped reading: this pool may
            # be broken or still busy with units nobody waits for, so it is not kept, and its
            # workers are ended now rather than when they finish.
            processes = _drop((workers, cpus), pool)
            if lost is not None and isinstance(pool, _Pool):
                lost.extend(pool.dead_workers(processes))
