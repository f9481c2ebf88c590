"""The runner's perception sources by name: ``--perception sim | sim:HOST:PORT |
replay:LOG.csv | realsense:MODEL.pt``."""

from __future__ import annotations

from typing import Any

from bridge.perception import PerceptionSource, Replay, SimCamera, perception_address

__all__ = ["open_source"]


def open_source(
    spec: str, port_url: str, seed: int | None = None, ahead: dict[str, Any] | None = None
) -> PerceptionSource:
    """A perception source from the runner's ``--perception`` value.

    :param spec: ``sim``, ``sim:HOST:PORT``, ``replay:LOG.csv`` or ``realsense:MODEL.pt``.
    :param port_url: the runner's ``--port`` (``sim`` finds the emulator's camera from it).
    :param seed: the world's seed for ``sim``.
    :param ahead: the reading ahead the policy reads (``PPOPolicy.reads_ahead``): the
        RealSense source publishes it with these settings; the emulator's world and a replay
        publish what they were configured or recorded with (the runner checks).
    :raises ValueError: an unknown kind, ``sim`` without a ``socket://`` port, or a
        ``sim:HOST:PORT`` that is not one (an IPv6 host in brackets, a port in 1-65535).
    """
    kind, _, rest = spec.partition(":")
    if kind == "sim":
        if rest:
            if rest.startswith("["):  # an IPv6 address: sim:[::1]:5761
                host, colon, port = rest[1:].partition("]:")
                host = host if colon else ""
            else:
                host, _, port = rest.rpartition(":")
                host = "" if ":" in host else host  # an IPv6 address without its brackets
            if not host:
                raise ValueError(
                    f"--perception {spec!r}: expected sim or sim:HOST:PORT (an IPv6 host in "
                    "brackets: sim:[::1]:5761)"
                )
            number = port.isascii() and port.isdigit()
            if not number or not 1 <= int(port) <= 65535:
                what = "is out of range" if number else "is not a number"
                raise ValueError(f"--perception {spec!r}: port {port!r} {what}: must be in 1-65535")
            return SimCamera(host, int(port), seed)
        try:
            host, port_no = perception_address(port_url)
        except ValueError:
            raise ValueError(
                f"--perception sim needs --port socket://HOST:PORT (the emulator's), not "
                f"{port_url!r}; or give the camera as sim:HOST:PORT"
            ) from None
        return SimCamera(host, port_no, seed)
    if kind == "replay":
        if not rest:
            raise ValueError("--perception replay needs a step log: replay:LOG.csv")
        return Replay(rest)
    if kind == "realsense":
        from bridge.realsense import RealSensePerception  # an optional extra's glue

        if not rest:
            raise ValueError(
                "--perception realsense needs a detector model file: realsense:MODEL.pt "
                "(nothing is downloaded at run time)"
            )
        return RealSensePerception(rest, ahead=ahead)
    raise ValueError(
        f"--perception {spec!r} is out of range: must be sim, sim:HOST:PORT, replay:LOG.csv "
        "or realsense:MODEL.pt"
    )
