"""The Ray backend: connecting (a local Ray, a named cluster, or the one already running in
this process, if it is the one named) and running units as Ray tasks.
"""

from __future__ import annotations

import contextlib
import logging
import os
import socket
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING, Any

from execution.worker import _IN_FLIGHT_PER_SLOT, BackendUnavailableError, WorkerLostError, _call

if TYPE_CHECKING:
    from execution.backend import Backend

#: What to run when Ray is missing (the ``ray`` extra of pyproject.toml).
RAY_INSTALL = "pip install 'personfollow[ray]'"


#: What a Ray address may be, for the messages that refuse one.
_ADDRESS_FORMS = "HOST:PORT (e.g. 127.0.0.1:6379), ray://HOST:PORT, auto or local"


def _address_problem(address: object) -> str | None:
    """Why ``address`` is not a Ray cluster address (None if it is one).

    ``auto`` and ``local`` are Ray's own words; otherwise ``HOST:PORT`` or Ray Client's
    ``ray://HOST:PORT``, the port in 1..65535 and the host without spaces (``[...]`` for IPv6).
    """
    if not isinstance(address, str):
        return f"must be a string: {_ADDRESS_FORMS}"
    if address in ("auto", "local"):
        return None
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    bare = host.removeprefix("[").removesuffix("]") if host.startswith("[") else host
    if (
        not sep
        or not bare
        or any(c.isspace() for c in address)
        or (":" in bare and not host.startswith("["))  # an IPv6 host needs its brackets
        or "/" in bare
    ):
        return f"must be {_ADDRESS_FORMS}"
    if not (port.isascii() and port.isdigit()) or not 1 <= int(port) <= 65535:
        return f"the port must be an integer in 1..65535: {_ADDRESS_FORMS}"
    return None


def _endpoint(address: str) -> tuple[str, str]:
    """``(host, port)`` of a ``[ray://]HOST:PORT`` address, an IPv6 host without its brackets
    (the form sockets take)."""
    host, _, port = address.removeprefix("ray://").rpartition(":")
    return host.strip("[]"), port


def _import_ray() -> Any:
    try:
        import ray
    except ImportError:
        raise BackendUnavailableError(
            f"the ray backend needs Ray, which is not installed: {RAY_INSTALL}"
        ) from None
    return ray


def _connect(backend: Backend) -> Any:
    """Ray, initialised: the running instance, the named cluster, or a new local one.

    :raises BackendUnavailableError: if Ray runs in this process already, connected to another
        cluster than the one named (``address`` or ``RAY_ADDRESS``).
    """
    ray = _import_ray()
    address = backend.address or os.environ.get("RAY_ADDRESS") or None
    if ray.is_initialized():
        if address is not None:
            _check_connected_to(ray, address)
        return ray
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
    global _CONNECTED_ADDRESS
    _CONNECTED_ADDRESS = address
    return ray


#: The address :func:`_connect` last initialised Ray with (None: a local Ray, or none yet).
_CONNECTED_ADDRESS: str | None = None


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


def _check_reachable(address: str, timeout_s: float = 5.0) -> None:
    """Fail fast on a cluster address nothing listens at: ``ray.init`` would retry for minutes.

    ``auto`` and ``local`` are Ray's own words (no host to try); ``ray://host:port`` is Ray
    Client's form of ``host:port``.
    """
    if address in ("auto", "local"):
        return
    # Checked again: RAY_ADDRESS reaches here without passing Backend's own check.
    problem = _address_problem(address)
    if problem is not None:
        raise BackendUnavailableError(
            f"address={address!r} is not a Ray cluster address: {problem}"
        )
    host, port = _endpoint(address)
    try:
        socket.create_connection((host, int(port)), timeout=timeout_s).close()
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
