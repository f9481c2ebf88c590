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
    :raises ValueError: an unknown kind, or ``sim`` without a ``socket://`` port.
    """
    kind, _, rest = spec.partition(":")
    if kind == "sim":
        if rest:
            host, _, port = rest.rpartition(":")
            if not host or not port.isdigit():
                raise ValueError(f"--perception {spec!r}: expected sim or sim:HOST:PORT")
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
