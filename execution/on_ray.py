"""The Ray backend: connecting (a local Ray, a named cluster, or the one already running in
this process, if it is the one named) and running units as Ray tasks.

A local Ray that :func:`_connect` starts is this layer's, as a pool is: kept for the next call
while it is used within ``execution.backend.POOL_IDLE_S`` (a local Ray takes about 5 s to
start), then shut down; restarted when a call wants another number of CPUs; stopped by
``execution.shutdown_pools()``. A Ray the caller started, or a cluster, is never shut down.
"""

from __future__ import annotations

import contextlib
import copy
import logging
import os
import re
import signal
import socket
import threading
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING, Any

from execution.ray_address import _check_reachable, _endpoint
from execution.worker import (
    _IN_FLIGHT_PER_SLOT,
    BackendUnavailableError,
    RemoteTraceback,
    WorkerLostError,
    _call,
    _label,
    _note_origin,
)

if TYPE_CHECKING:
    from execution.backend import Backend

#: What to run when Ray is missing (the ``ray`` extra of pyproject.toml): the README's install
#: of a clone, which this project is used from (``personfollow[ray]`` would fetch a release).
RAY_INSTALL = "pip install -e '.[ray]' --config-settings editable_mode=compat (in the clone)"


def _import_ray() -> Any:
    try:
        import ray
    except ImportError:
        raise BackendUnavailableError(
            f"the ray backend needs Ray, which is not installed: {RAY_INSTALL}"
        ) from None
    return ray


def _connect(backend: Backend) -> Any:
    """Ray, initialised: the running instance, the named cluster, or a new local one. Each
    call is paired with a :func:`_release_ray` (the Ray this layer started is not stopped
    while a call uses it).

    :raises BackendUnavailableError: if Ray runs in this process already, connected to another
        cluster than the one named (``address`` or ``RAY_ADDRESS``).
    """
    ray = _import_ray()
    address = backend.address or os.environ.get("RAY_ADDRESS") or None
    global _RAY_BUSY, _STARTED
    with _RAY_LOCK:
        _cancel_idle_timer()
        if ray.is_initialized() and _replace_started(ray, address, _local_cpus(backend)):
            ray.shutdown()
            _STARTED = None
        if ray.is_initialized():
            if address is not None:
                _check_connected_to(ray, address)
            _RAY_BUSY += 1
            return ray
        _start(ray, backend, address)
        _RAY_BUSY += 1
        return ray


def _local_cpus(backend: Backend) -> int:
    """The CPUs of the local Ray started for ``backend``: ``workers * cpus_per_task``, or all
    of this machine's."""
    if backend.workers is not None:
        return backend.workers * backend.cpus_per_task
    return os.cpu_count() or 1


def _start(ray: Any, backend: Backend, address: str | None) -> None:
    """``ray.init``: a new local Ray (no address) or a connection to the cluster named (checked
    first: :func:`execution.ray_address._check_reachable`)."""
    options: dict[str, Any] = {
        "include_dashboard": False,
        "logging_level": logging.WARNING,
        "configure_logging": True,
    }
    if address is None:
        # "local": a new instance, even if a `ray start` node runs on this machine (ray.init()
        # would join that one; a cluster is used only when named).
        options["address"] = "local"
        options["num_cpus"] = _local_cpus(backend)
    else:
        _check_reachable(address)
        options["address"] = address
    caller = _sigterm_handler()
    try:
        ray.init(**options)
    except (ConnectionError, RuntimeError, ValueError) as e:
        where = address or "a local Ray"
        raise BackendUnavailableError(f"cannot start or reach Ray at {where}: {e}") from None
    finally:
        _restore_sigterm(caller)
    global _CONNECTED_ADDRESS, _STARTED
    _CONNECTED_ADDRESS = address
    _STARTED = None
    if address is None:
        with contextlib.suppress(Exception):  # unknown: treated as not this layer's
            _STARTED = (ray.get_runtime_context().gcs_address, options["num_cpus"])


def _sigterm_handler() -> Any:
    """The SIGTERM handler the caller installed (a Python function), or None: the default, an
    ignored signal, or a call off the main thread (where handlers cannot be set)."""
    if threading.current_thread() is not threading.main_thread():
        return None
    handler = signal.getsignal(signal.SIGTERM)
    return handler if callable(handler) else None


def _restore_sigterm(handler: Any) -> None:
    """Put the caller's SIGTERM handler back: ``ray.init`` replaces it with its own (exit
    status 15, and Ray's C++ stack dump), so a command that stops cleanly on SIGTERM (a
    study's locks released, one line) would not. Without one of the caller's, Ray's stays:
    it shuts Ray down on the way out."""
    if handler is not None:
        signal.signal(signal.SIGTERM, handler)


def _started_here(ray: Any) -> bool:
    """Whether the Ray initialised in this process is the local one :func:`_connect` started
    (not one the caller started since, after shutting that one down)."""
    if _STARTED is None or not ray.is_initialized():
        return False
    try:
        return bool(ray.get_runtime_context().gcs_address == _STARTED[0])
    except Exception:
        return False


def _replace_started(ray: Any, address: str | None, cpus: int) -> bool:
    """Whether the running Ray is the local one this layer started with other CPUs than a call
    without a cluster address now wants, and idle: then it is shut down and started again
    (reused as it is, it would run the units on the CPUs an earlier call asked for).

    Busy with another thread's call, it is reused, with a warning.
    """
    if address is not None or not _started_here(ray) or _STARTED is None:
        return False
    if _STARTED[1] == cpus:
        return False
    if _RAY_BUSY:
        logging.getLogger("execution").warning(
            "warning: the local Ray this process started has %d CPUs and is busy with another "
            "call; this call, which asks for %d, runs on it",
            _STARTED[1], cpus,
        )  # fmt: skip
        return False
    return True


def _release_ray(idle_s: float) -> None:
    """A call that :func:`_connect` served is done with Ray: once no call uses the local Ray
    this layer started, it is shut down if no call takes it within ``idle_s`` seconds."""
    global _RAY_BUSY, _RAY_IDLE
    with _RAY_LOCK:
        _RAY_BUSY = max(0, _RAY_BUSY - 1)
        if _RAY_BUSY or _STARTED is None:
            return
        _cancel_idle_timer()
        timer = threading.Timer(idle_s, _expire_ray)
        timer.daemon = True
        _RAY_IDLE = timer
        timer.start()


def _expire_ray() -> None:
    with _RAY_LOCK:
        # A call that took Ray meanwhile cancelled this timer (or replaced it).
        if _RAY_IDLE is threading.current_thread():
            _shutdown_started()


def _stop_started_ray() -> None:
    """Shut down the local Ray this layer started, now, unless a call is using it."""
    with _RAY_LOCK:
        _cancel_idle_timer()
        _shutdown_started()


def _shutdown_started() -> None:
    """With ``_RAY_LOCK`` held: shut down the local Ray this layer started, if idle."""
    global _STARTED, _RAY_IDLE
    _RAY_IDLE = None
    if _STARTED is None or _RAY_BUSY:
        return
    import ray  # imported already: this layer started it

    if _started_here(ray):
        ray.shutdown()
    _STARTED = None


def _cancel_idle_timer() -> None:
    global _RAY_IDLE
    if _RAY_IDLE is not None:
        _RAY_IDLE.cancel()
        _RAY_IDLE = None


#: The address :func:`_connect` last initialised Ray with (None: a local Ray, or none yet).
_CONNECTED_ADDRESS: str | None = None
#: The local Ray :func:`_connect` started and has not shut down: (its GCS address, its CPUs).
_STARTED: tuple[str, int] | None = None
#: Calls using Ray now, and the timer that stops the Ray this layer started when idle; both,
#: and ``_STARTED``, under ``_RAY_LOCK`` (a timer fires on its own thread).
_RAY_BUSY = 0
_RAY_IDLE: threading.Timer | None = None
_RAY_LOCK = threading.RLock()


def _check_connected_to(ray: Any, address: str) -> None:
    """Refuse to run on the Ray already initialised in this process unless it is ``address``.

    Ray allows one connection per process: running a cluster's units on a Ray started earlier
    (a local one, another cluster) would silently compute them elsewhere than the user named.
    ``auto`` and ``local`` name no particular cluster, so any running Ray is theirs.
    """
    if address in ("auto", "local"):
        return
    connected = here = None
    with contextlib.suppress(Exception):
        connected = ray.get_runtime_context().gcs_address  # HOST:PORT of the running cluster
        here = ray.util.get_node_ip_address()  # this machine, as Ray names it
    if address.startswith("ray://") or not connected:
        # Ray Client: the cluster's own address is not known here, only the one :func:`_connect`
        # connected with (if it did).
        if address == _CONNECTED_ADDRESS:
            return
    elif _same_endpoint(address, connected, {here} if here else set()):
        return
    where = connected or _CONNECTED_ADDRESS or "a Ray started earlier in this process"
    raise BackendUnavailableError(
        f"the ray backend names the cluster at {address} (address or RAY_ADDRESS), but Ray is "
        f"already initialised in this process, connected to {where}: call ray.shutdown() "
        "first, or name no address to use the running Ray"
    )


def _same_endpoint(a: str, b: str, own: set[str]) -> bool:
    """Whether HOST:PORT ``a`` and ``b`` are the same port of the same machine (``localhost``
    and this machine's own addresses, ``own`` among them, count as one machine: a head node
    started here reports its own IP, a user may name it ``localhost``)."""
    (host_a, port_a), (host_b, port_b) = _endpoint(a), _endpoint(b)
    if port_a != port_b:
        return False
    ips_a, ips_b = _addresses(host_a), _addresses(host_b)
    if ips_a & ips_b:
        return True
    here = _addresses("localhost") | _addresses(socket.gethostname()) | own | _LOOPBACK
    return bool(ips_a and ips_b and ips_a | ips_b <= here)


_LOOPBACK = {"127.0.0.1", "::1"}


def _addresses(host: str) -> set[str]:
    """The IP addresses ``host`` resolves to (none if it does not)."""
    try:
        infos = socket.getaddrinfo(host, None)
    except (OSError, UnicodeError):
        return set()
    return {str(info[4][0]) for info in infos}


#: What ``ray.get`` raises when a unit's worker or node died, or the node holding its result:
#: a death, retried by :func:`_run_ray` as a local pool retries one.
_DEATHS = ("WorkerCrashedError", "NodeDiedError", "OutOfMemoryError", "ObjectLostError")


def _run_ray(
    fn: Callable[[Any], Any],
    todo: Sequence[tuple[int, Any]],
    backend: Backend,
    describe: Callable[[Any], str] | None,
    idle_s: float,
) -> Iterator[tuple[int, Any]]:
    """Run the units as Ray tasks; ``(index, result)`` as each finishes. ``idle_s``: how long
    (s) the local Ray this layer started is kept without a call (``POOL_IDLE_S``).

    A worker's death is retried here rather than by Ray (``max_retries=0`` on the task), so
    that it is counted per unit and reported as a local pool reports it. A result is copied out
    of Ray's object store as it arrives (:func:`_own`) and its reference dropped.
    """
    if not todo:
        return
    ray = _connect(backend)
    try:
        yield from _ray_pass(ray, fn, todo, backend, describe)
    finally:
        _release_ray(idle_s)


def _ray_pass(
    ray: Any,
    fn: Callable[[Any], Any],
    todo: Sequence[tuple[int, Any]],
    backend: Backend,
    describe: Callable[[Any], str] | None,
) -> Iterator[tuple[int, Any]]:
    task = ray.remote(_call).options(
        num_cpus=backend.cpus_per_task,
        max_retries=0,  # retried below, per unit (a death is reported, and counted per unit)
        retry_exceptions=False,  # a unit's own exception is a result, not a lost worker
    )
    deaths_of = tuple(getattr(ray.exceptions, name) for name in _DEATHS)
    units = dict(todo)
    queue = iter(todo)
    retry: list[int] = []  # units whose worker died, to run again before the queue's
    in_flight: dict[Any, int] = {}
    deaths: dict[int, int] = {}

    def submit() -> None:
        if retry:
            i = retry.pop(0)
            in_flight[task.remote(fn, units[i], backend.cpus_per_task, i)] = i
            return
        for i, unit in queue:
            in_flight[task.remote(fn, unit, backend.cpus_per_task, i)] = i
            return

    try:
        for _ in range(_IN_FLIGHT_PER_SLOT * backend.slots()):
            submit()
        while in_flight:
            ready, _ = ray.wait(list(in_flight), num_returns=1)
            ref = ready.pop()
            i = in_flight.pop(ref)
            try:
                result = _own(ray.get(ref))
            except ray.exceptions.RayTaskError as e:
                cause = _unit_exception(e, i, _label(describe, units[i]))
                if cause is e:
                    raise
                # The unit's exception as raised, its worker's frames chained to it (a pool's
                # way): `from None` would leave a traceback that shows only this module.
                raise cause from _remote_traceback(e)
            except deaths_of as e:
                deaths[i] = deaths.get(i, 0) + 1
                _died(i, e, deaths[i], backend.max_retries, len(units), describe, units[i])
                retry.append(i)
                submit()
                continue
            finally:
                del ref  # the last reference: Ray frees the object (its copy is ours)
            del units[i]
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


def _own(result: Any) -> Any:
    """``result`` as ``ray.get`` returned it, copied into this process's memory.

    ``ray.get`` maps a result's arrays (numpy, pandas) from Ray's shared-memory object store
    without copying them: they are read-only, and each keeps its object pinned in the store
    (``/dev/shm``) for as long as it lives, which is as long as a run keeps its results. A deep
    copy owns its arrays; on a unit of 20 episodes with their step logs (0.8 MB) it took 0.6 ms
    against 2.7 ms for a pickle round trip (protocol 5 would even hand the read-only buffers
    back), and running those episodes about 700 ms.
    """
    return copy.deepcopy(result)


def _unit_exception(error: Any, index: int, label: str) -> BaseException:
    """The exception a unit raised, from the ``RayTaskError`` that carries it, named (unit,
    host: :func:`execution.unit_origin`); the ``RayTaskError`` itself when it carries none."""
    cause = getattr(error, "cause", None)
    if not isinstance(cause, BaseException):
        return error
    _note_origin(cause, index, label)
    return cause


#: Terminal colours in Ray's traceback text.
_ANSI = re.compile(r"\x1b\[[0-9;]*m")


def _remote_traceback(error: Any) -> RemoteTraceback:
    """The worker's traceback of a ``RayTaskError`` (its ``str``: the task, pid and node, and
    the unit's frames), to chain to the unit's exception as a pool's is."""
    try:
        text = str(error)
    except Exception:
        text = f"(the traceback in the Ray worker could not be read: {type(error).__name__})"
    return RemoteTraceback(_ANSI.sub("", text))


def _died(
    index: int,
    error: BaseException,
    deaths: int,
    max_retries: int,
    unfinished: int,
    describe: Callable[[Any], str] | None,
    unit: Any,
) -> None:
    """A unit's worker died: raise :class:`WorkerLostError` past ``max_retries``, else warn."""
    lines = str(error).strip().splitlines() or [type(error).__name__]
    reason = f"with Ray's {type(error).__name__}: {lines[0][:200].rstrip('.')}"
    label = _label(describe, unit)
    if deaths > max_retries:
        raise WorkerLostError(index, label, deaths, max_retries, unfinished, reason) from error
    logging.getLogger("execution").warning(
        "warning: the Ray worker running unit %d %s died %s; it runs again "
        "(retry %d of max_retries=%d)",
        index, label, reason, deaths, max_retries,
    )  # fmt: skip
