"""A Ray cluster address: its forms, and the checks made of it before ``ray.init`` connects.

``ray.init`` on an address where nothing answers as a Ray GCS (Global Control Service) does
not fail: it retries for minutes (20 attempts of about 40 s each in Ray 2.60), printing
Ray's C++ warnings, and ``auto`` may name a cluster that is long gone (the address file a
crashed ``ray start`` left behind). :func:`_check_reachable` resolves the address as
``ray.init`` will, opens a TCP connection to it, and asks the GCS there for its cluster id,
within :data:`GCS_ANSWER_S`: a command then gives one line naming the address, at once or
within that time, instead of hanging.
"""

from __future__ import annotations

import os
import socket
from typing import Any

from execution.worker import BackendUnavailableError

#: What a Ray address may be, for the messages that refuse one.
_ADDRESS_FORMS = "HOST:PORT (e.g. 127.0.0.1:6379), ray://HOST:PORT, auto or local"

#: How long (s) a cluster address is given to answer as a Ray GCS before it is refused. A GCS
#: that is up answers in milliseconds (a local one well under 0.1 s, measured), one across a
#: slow or busy link within seconds; a port where something else listens and says nothing (a
#: proxy, a half-open service) is given this long (gRPC itself gives up on a server that
#: sends nothing after about 17 s, measured), where ``ray.init`` would retry for minutes.
GCS_ANSWER_S = 20.0


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


def _check_reachable(address: str, timeout_s: float = 5.0, answer_s: float | None = None) -> None:
    """Fail fast on a cluster address no Ray GCS answers at: ``ray.init`` would retry for
    minutes.

    The address is resolved as ``ray.init`` resolves it (:func:`_resolved`: ``auto`` from
    ``RAY_ADDRESS``, Ray's address file or a Ray running on this machine; ``localhost`` as
    this machine's address), then a TCP connection is opened to it (``timeout_s``, s) and
    the GCS asked for its cluster id (``answer_s``, s; default :data:`GCS_ANSWER_S`).
    ``local`` names no cluster; ``ray://host:port`` (Ray Client, not a GCS) gets the TCP
    connection only.

    :raises BackendUnavailableError: naming the address (and what it resolved to).
    """
    if address == "local":
        return
    # Checked again: RAY_ADDRESS reaches here without passing Backend's own check.
    problem = _address_problem(address)
    if problem is not None:
        raise BackendUnavailableError(
            f"address={address!r} is not a Ray cluster address: {problem}"
        )
    target, source = _resolved(address)
    where = address if target == address else f"{address} ({target}, {source})"
    host, port = _endpoint(target)
    try:
        socket.create_connection((host, int(port)), timeout=timeout_s).close()
    except (OSError, ValueError) as e:
        raise BackendUnavailableError(
            f"cannot reach the Ray cluster at {where}: {getattr(e, 'strerror', None) or e} "
            "(is `ray start --head` running there? see --address and RAY_ADDRESS)"
        ) from None
    if not target.startswith("ray://"):
        _check_answers(target, where, GCS_ANSWER_S if answer_s is None else answer_s)


def _resolved(address: str) -> tuple[str, str]:
    """The ``HOST:PORT`` ``ray.init(address=address)`` connects to, and where it came from
    (for messages): Ray's own ``canonicalize_bootstrap_address``, which ``ray.init`` calls.

    :raises BackendUnavailableError: for ``auto`` when Ray finds no cluster to name.
    """
    if address.startswith("ray://"):  # Ray Client connects to the address as given
        return address, "as given"
    try:
        from ray._private import services, utils
    except ImportError:  # another Ray's layout: its ray.init resolves the address itself
        return address, "as given"
    if address == "auto":
        if os.environ.get("RAY_ADDRESS") not in (None, "", "auto"):
            source = "from RAY_ADDRESS"
        else:  # Ray's order: the one Ray running here, else the file `ray start` wrote
            file = utils.get_ray_address_file(None)  # under RAY_TMPDIR, or /tmp/ray
            running = services.find_gcs_addresses()
            here = len(running) == 1 or not os.path.exists(file)
            source = "a Ray running on this machine" if here else f"from {file}"
    else:
        source = "this machine's address, as Ray names it"
    try:
        target = services.canonicalize_bootstrap_address(address, None)
    except Exception as e:  # ConnectionError: auto finds nothing; ValueError: a bad RAY_ADDRESS
        lines = str(e).strip().splitlines()
        raise BackendUnavailableError(
            f"cannot find the Ray cluster {address} names: {lines[0] if lines else e!r}"
        ) from None
    if not target:  # None: Ray would start a local instance
        return address, "as given"
    return str(target), source


def _check_answers(target: str, where: str, answer_s: float) -> None:
    """Ask the Ray GCS at ``target`` for its cluster id (gRPC, on Ray's own channel: its TLS
    and token settings), waiting at most ``answer_s`` seconds.

    A GCS that refuses the call for want of a token has answered: the token is ``ray.init``'s
    to report.

    :raises BackendUnavailableError: naming ``where`` if nothing answers as a GCS.
    """
    try:
        import grpc
        from ray._private.grpc_utils import init_grpc_channel
        from ray.core.generated import gcs_service_pb2, gcs_service_pb2_grpc
    except ImportError:  # another Ray's layout: ray.init's own retries are all there is
        return
    channel: Any = init_grpc_channel(target)
    try:
        stub = gcs_service_pb2_grpc.NodeInfoGcsServiceStub(channel)
        stub.GetClusterId(gcs_service_pb2.GetClusterIdRequest(), timeout=answer_s)
    except grpc.RpcError as e:
        code = e.code() if callable(getattr(e, "code", None)) else None
        if code in (grpc.StatusCode.UNAUTHENTICATED, grpc.StatusCode.PERMISSION_DENIED):
            return
        if code == grpc.StatusCode.DEADLINE_EXCEEDED:
            why = f"nothing answered within {answer_s:g} s"
        elif code == grpc.StatusCode.UNIMPLEMENTED:
            why = "a gRPC service that is not Ray's answered"
        else:  # gRPC's reason is the last part of its details: "Failed parsing HTTP/2", ...
            details = e.details() if callable(getattr(e, "details", None)) else None
            why = str(details or code).rsplit(": ", 1)[-1].strip()
        raise BackendUnavailableError(
            f"cannot reach the Ray cluster at {where}: a port is open there but no Ray GCS "
            f"answers ({why}; is it the dashboard's or another service's port? give the port "
            "`ray start --head` printed, 6379 by default)"
        ) from None
    finally:
        channel.close()
