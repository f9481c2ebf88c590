"""Backends that run work units: this process, a process pool, or Ray tasks.

:func:`execute` is the only entry point callers need; :class:`Backend` says where the units
run. See the package docstring for what a unit is.
"""

from __future__ import annotations

import atexit
import logging
import os
import socket
import sys
import threading
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from multiprocessing import get_context
from typing import Any, TypeVar

__all__ = [
    "BACKENDS",
    "POOL_IDLE_S",
    "Backend",
    "BackendUnavailableError",
    "WorkerLostError",
    "backend_from_args",
    "execute",
    "pin_threads",
    "shutdown_pools",
]

U = TypeVar("U")
R = TypeVar("R")

#: The backends by name: ``local`` (this process or a process pool) and ``ray``.
BACKENDS = ("local", "ray")
#: What to run when Ray is missing (the ``ray`` extra of pyproject.toml).
RAY_INSTALL = "pip install 'personfollow[ray]'"
#: Units kept in flight per slot: enough that a slot never waits for the driver, few enough
#: that a long grid is not all queued (and pickled) at once.
_IN_FLIGHT_PER_SLOT = 2


class BackendUnavailableError(RuntimeError):
    """The backend cannot run here (Ray not installed, cluster unreachable); says what to do."""


class WorkerLostError(RuntimeError):
    """Workers kept dying: a unit was retried ``max_retries`` times and its worker died again."""


@dataclass(frozen=True)
class Backend:
    """Where work units run.

    :param kind: ``"local"`` or ``"ray"``.
    :param workers: local: processes (1 = this process, no pool); ray: units in flight at once
        (None = the cluster's CPUs / ``cpus_per_task``; the local Ray started when no cluster is
        named gets ``workers * cpus_per_task`` CPUs, or all of this machine's).
    :param address: ray only: the cluster (``"auto"``, ``"ray://host:10001"``, ``"host:6379"``);
        None uses ``RAY_ADDRESS`` when set, else starts a local Ray.
    :param cpus_per_task: CPUs each unit is given and pins its threads to (1..64).
    :param max_retries: times a unit whose worker died is run again (0..100); an exception the
        unit itself raises is never retried.
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
        _check_int("workers", self.workers, 1, 4096, optional=True)
        _check_int("cpus_per_task", self.cpus_per_task, 1, 64)
        _check_int("max_retries", self.max_retries, 0, 100)
        if self.address is not None:
            if self.kind != "ray":
                raise ValueError(f"address={self.address!r} is given but backend is {self.kind!r}")
            if not isinstance(self.address, str) or not self.address.strip():
                raise ValueError(f"address={self.address!r} is out of range: a non-empty string")

    def check_reachable(self) -> None:
        """Fail fast, without connecting, if this is Ray at a cluster address (given or
        ``RAY_ADDRESS``) nothing listens at; callers check it before they write anything.

        :raises BackendUnavailableError: naming the address.
        """
        address = self.address or os.environ.get("RAY_ADDRESS")
        if self.kind == "ray" and address:
            _check_reachable(address)

    def slots(self) -> int:
        """Units that run at once: local, the workers; ray, the cluster's CPUs (connects)."""
        if self.kind == "local":
            return self.workers or 1
        if self.workers is not None:
            return self.workers
        ray = _connect(self)
        cpus = int(ray.cluster_resources().get("CPU", 1))
        return max(1, cpus // self.cpus_per_task)


def _check_int(name: str, value: Any, low: int, high: int, *, optional: bool = False) -> None:
    if value is None and optional:
        return
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise ValueError(f"{name}={value!r} is out of range: must be an integer in {low}..{high}")


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


def pin_threads(cpus: int) -> None:
    """Limit this process's numba, torch and OpenMP/BLAS threads to ``cpus``.

    Runs at the start of every task: Ray sets ``OMP_NUM_THREADS=1`` only for tasks without
    ``num_cpus``, and numba sizes its pool from the machine, so without this two tasks on a
    2-core machine would each start two busy threads (STACK.md, Ray).
    """
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = str(cpus)
    if "numba" in sys.modules:
        import numba

        numba.set_num_threads(max(1, min(cpus, numba.config.NUMBA_NUM_THREADS)))
    else:
        # Read when numba is first imported; changing it afterwards is refused by numba.
        os.environ["NUMBA_NUM_THREADS"] = str(cpus)
    if "torch" in sys.modules:
        import torch

        torch.set_num_threads(cpus)


def _call(fn: Callable[[Any], Any], unit: Any, cpus: int) -> Any:
    pin_threads(cpus)
    return fn(unit)


def execute(
    fn: Callable[[U], R],
    units: Iterable[U],
    backend: Backend | None = None,
    *,
    done: Mapping[int, R] | None = None,
    on_result: Callable[[int, R], None] | None = None,
) -> list[R]:
    """Run ``fn(unit)`` for every unit on ``backend``; the results in the units' order.

    :param fn: a module-level function (pickled by reference for a pool or Ray); pure in its
        unit, so that a retry or another backend gives the same result.
    :param units: the units (picklable).
    :param backend: where to run them (default: this process).
    :param done: results already had, by unit index (a resumed run): those units are skipped.
    :param on_result: called in this process as each unit finishes (in the order they finish)
        with its index and result: a progress bar, a journal for resuming.
    :raises WorkerLostError: if a unit's worker died more than ``backend.max_retries`` times.
    :raises BackendUnavailableError: if Ray is wanted and missing or its cluster unreachable.
    :raises Exception: whatever ``fn`` raised for a unit, as it raised it.
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
    run = _run_local if backend.kind == "local" else _run_ray
    for i, result in run(fn, todo, backend):
        results[i] = result
        if on_result is not None:
            on_result(i, result)
    return results


# -- local ------------------------------------------------------------------------------------


def _run_local(
    fn: Callable[[Any], Any], todo: Sequence[tuple[int, Any]], backend: Backend
) -> Iterator[tuple[int, Any]]:
    workers = min(backend.workers or 1, len(todo))
    if workers <= 1:
        for i, unit in todo:
            yield i, fn(unit)
        return
    pending = dict(todo)
    deaths = 0
    while pending:
        try:
            yield from _pool_pass(fn, pending, backend.workers or 1, backend.cpus_per_task)
        except BrokenProcessPool as e:
            # A worker died (killed, out of memory): the pool is gone with every unit it held.
            # Units are pure, so running the unfinished ones again in a new pool is a retry.
            deaths += 1
            if deaths > backend.max_retries:
                raise WorkerLostError(
                    f"a worker process died {deaths} times ({len(pending)} units unfinished); "
                    f"max_retries={backend.max_retries}"
                ) from e


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
            # spawn, not fork: a forked child of a process with live threads (tqdm's monitor,
            # BLAS pools) can deadlock; spawned workers load the cached kernels in about 2 s.
            _POOLS[key] = ProcessPoolExecutor(
                workers, mp_context=get_context("spawn"), initializer=pin_threads, initargs=(cpus,)
            )
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


def _drop(key: tuple[int, int], pool: ProcessPoolExecutor) -> None:
    """Forget ``pool`` (it failed, or holds units nobody waits for) and stop it."""
    with _POOLS_LOCK:
        if _POOLS.get(key) is pool:
            del _POOLS[key], _BUSY[key]
    pool.shutdown(wait=False, cancel_futures=True)


def shutdown_pools() -> None:
    """Stop the worker processes kept between calls of :func:`execute` (at exit, or to free
    their memory before ``POOL_IDLE_S`` does; the next call with a pool starts a new one)."""
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
    fn: Callable[[Any], Any], pending: dict[int, Any], workers: int, cpus: int
) -> Iterator[tuple[int, Any]]:
    """One pass over the pending units on the kept pool; removes each from ``pending`` as it
    is yielded."""
    pool = _pool(workers, cpus)
    queue = iter(list(pending.items()))
    in_flight: dict[Future[Any], int] = {}

    def submit() -> None:
        for i, unit in queue:
            in_flight[pool.submit(fn, unit)] = i
            return

    finished_all = False
    try:
        for _ in range(_IN_FLIGHT_PER_SLOT * workers):
            submit()
        while in_flight:
            finished, _ = wait(in_flight, return_when=FIRST_COMPLETED)
            for future in finished:
                i = in_flight.pop(future)
                result = future.result()
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
            # be broken or still busy with units nobody waits for, so it is not kept.
            _drop((workers, cpus), pool)


# -- ray --------------------------------------------------------------------------------------


def _import_ray() -> Any:
    try:
        import ray
    except ImportError:
        raise BackendUnavailableError(
            f"the ray backend needs Ray, which is not installed: {RAY_INSTALL}"
        ) from None
    return ray


def _connect(backend: Backend) -> Any:
    """Ray, initialised: the running instance, the named cluster, or a new local one."""
    ray = _import_ray()
    if ray.is_initialized():
        return ray
    address = backend.address or os.environ.get("RAY_ADDRESS") or None
    options: dict[str, Any] = {
        "include_dashboard": False,
        "logging_level": logging.WARNING,
        "configure_logging": True,
    }
    if address is None:
        # "local": a new instance, even if a `ray start` node runs on this machine (ray.init()
        # would join that one; a cluster is used only when named).
        options["address"] = "local"
        cpus = os.cpu_count() or 1
        if backend.workers is not None:
            cpus = backend.workers * backend.cpus_per_task
        options["num_cpus"] = cpus
    else:
        _check_reachable(address)
        options["address"] = address
    try:
        ray.init(**options)
    except (ConnectionError, RuntimeError, ValueError) as e:
        where = address or "a local Ray"
        raise BackendUnavailableError(f"cannot start or reach Ray at {where}: {e}") from None
    return ray


def _check_reachable(address: str, timeout_s: float = 5.0) -> None:
    """Fail fast on a cluster address nothing listens at: ``ray.init`` would retry for minutes.

    ``auto`` and ``local`` are Ray's own words (no host to try); ``ray://host:port`` is Ray
    Client's form of ``host:port``.
    """
    if address in ("auto", "local"):
        return
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not (port.isascii() and port.isdigit()) or not host:
        raise BackendUnavailableError(
            f"address={address!r} is not a Ray cluster address: give HOST:PORT (e.g. "
            "127.0.0.1:6379), ray://HOST:PORT or auto"
        )
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout_s).close()
    except OSError as e:
        raise BackendUnavailableError(
            f"cannot reach the Ray cluster at {address}: {e.strerror or e} (is `ray start "
            "--head` running there? see --address and RAY_ADDRESS)"
        ) from None


def _run_ray(
    fn: Callable[[Any], Any], todo: Sequence[tuple[int, Any]], backend: Backend
) -> Iterator[tuple[int, Any]]:
    if not todo:
        return
    ray = _connect(backend)
    task = ray.remote(_call).options(
        num_cpus=backend.cpus_per_task,
        max_retries=backend.max_retries,
        retry_exceptions=False,  # a unit's own exception is a result, not a lost worker
    )
    queue = iter(todo)
    in_flight: dict[Any, int] = {}

    def submit() -> None:
        for i, unit in queue:
            in_flight[task.remote(fn, unit, backend.cpus_per_task)] = i
            return

    try:
        for _ in range(_IN_FLIGHT_PER_SLOT * backend.slots()):
            submit()
        while in_flight:
            ready, _ = ray.wait(list(in_flight), num_returns=1)
            i = in_flight.pop(ready[0])
            try:
                result = ray.get(ready[0])
            except ray.exceptions.RayTaskError as e:
                cause = getattr(e, "cause", None)
                raise (cause if isinstance(cause, BaseException) else e) from None
            except (ray.exceptions.WorkerCrashedError, ray.exceptions.NodeDiedError) as e:
                raise WorkerLostError(
                    f"unit {i}'s worker died {backend.max_retries + 1} times: {e}"
                ) from None
            # The next unit goes out before this result is handed on (the cluster stays busy
            # while the caller keeps it), but a submission that fails (the cluster lost) must
            # not lose the unit just finished: it is handed on first, then the error raised.
            try:
                submit()
            except BaseException:
                yield i, result
                raise
            yield i, result
    finally:
        for ref in in_flight:
            ray.cancel(ref, force=True)
