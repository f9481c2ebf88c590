"""The thesis's ``serial_read_node``, as printed and as it must have worked (reference §1.7).

The listing reads the MCU's feedback every 0.1 s::

    data = ser.read(8)
    right, left = struct.unpack('>hh', data[2:])

Packets are 6 bytes (``A5 A5`` + right, left as int16 big-endian, mm/s). As printed it cannot
run: ``data[2:]`` is 6 bytes for a 4-byte format, so every read raises ``struct.error``. Read
as ``data[2:6]`` it runs but misframes: each 8-byte read starts 2 bytes further into the
6-byte packet cycle, so the phase runs 0, 2, 4, 0, ... and at best one read in three decodes a
packet (phase 2 gives the left speed and the header, phase 4 the header and the next right
speed; the header ``A5 A5`` read as int16 is -23131, a speed of -23.1 m/s). The robot that
produced the thesis's Table 4.1 followed people, so its reader worked: the one modelled in the
simulator's as-built chain (``ChainConfig.reader_period_s``) and used by the runner hands on
the newest whole packet, found by its header, at each read (:class:`AlignedReader`).

The two printed variants are kept here as demonstrations of those failures, on a real pyserial
port (``tests/bridge/test_serial_read_node.py`` runs them over ``loop://``); nothing else in
the bridge uses them.
"""

from __future__ import annotations

import struct
from typing import Protocol

from .protocol.reference import ReferenceDecoder

__all__ = ["READ_BYTES", "AlignedReader", "read_as_printed", "read_data_2_6"]

READ_BYTES = 8
"""Bytes the listing reads per call (reference §1.7)."""


class _Port(Protocol):
    def read(self, size: int = 1) -> bytes: ...


class _Serial(_Port, Protocol):
    @property
    def in_waiting(self) -> int: ...


def read_as_printed(port: _Port) -> tuple[int, int]:
    """The listing verbatim: ``struct.unpack('>hh', ser.read(8)[2:])``, mm/s.

    :raises struct.error: on every read of 8 bytes (``data[2:]`` has 6 bytes, the format 4).
    """
    data = port.read(READ_BYTES)
    right, left = struct.unpack(">hh", data[2:])
    return right, left


def read_data_2_6(port: _Port) -> tuple[int, int]:
    """The listing with ``data[2:6]``: runs, but misframes two reads in three (module doc), mm/s.

    :raises struct.error: when fewer than 6 bytes came (a timeout on the port).
    """
    data = port.read(READ_BYTES)
    right, left = struct.unpack(">hh", data[2:6])
    return right, left


class AlignedReader:
    """The reader that worked: every byte that came, decoded by header; the newest packet.

    :param port: an open pyserial port (any object with ``read`` and ``in_waiting``).
    """

    def __init__(self, port: _Serial) -> None:
        self._port = port
        self._decoder = ReferenceDecoder()
        self._newest: tuple[int, int] | None = None

    def read(self) -> tuple[int, int] | None:
        """Right and left speed (mm/s) of the newest whole packet; ``None`` before the first."""
        waiting = self._port.in_waiting
        if waiting:
            packets = self._decoder.feed(self._port.read(waiting))
            if packets:
                self._newest = packets[-1]
        return self._newest
