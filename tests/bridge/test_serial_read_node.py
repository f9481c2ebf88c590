"""bridge/serial_read_node.py: the thesis's reader as printed fails; the aligned one works."""

from __future__ import annotations

import struct

import pytest
import serial

from bridge.protocol.reference import encode_reference
from bridge.serial_read_node import READ_BYTES, AlignedReader, read_as_printed, read_data_2_6

# 30 packets of the MCU's feedback (right, left mm/s), none ending in 0xA5.
PACKETS = [(250 + k, -250 - 3 * k) for k in range(30)]
HEADER_AS_INT16 = struct.unpack(">h", b"\xa5\xa5")[0]


def _port_with(packets: list[tuple[int, int]]) -> serial.SerialBase:
    port = serial.serial_for_url("loop://", timeout=0.2)
    port.write(b"".join(encode_reference(r, left) for r, left in packets))
    return port


def test_the_listing_as_printed_raises_on_every_read() -> None:
    with _port_with(PACKETS) as port:
        for _ in range(len(PACKETS) * 6 // READ_BYTES):
            with pytest.raises(struct.error, match="4"):
                read_as_printed(port)


def test_the_data_2_6_reading_misframes_two_reads_in_three() -> None:
    with _port_with(PACKETS) as port:
        reads = [read_data_2_6(port) for _ in range(len(PACKETS) * 6 // READ_BYTES)]
    right = [r for r in reads if r in PACKETS]
    assert len(right) == (len(reads) + 2) // 3  # phase 0 of 0, 2, 4: one read in three
    assert reads[0] == PACKETS[0]
    # read 1 starts at byte 8, phase 2 of packet 1: (its left, the header of packet 2); read 2
    # at byte 16, phase 4 of packet 2: (the header of packet 3, its right)
    assert reads[1] == (PACKETS[1][1], HEADER_AS_INT16)
    assert reads[2] == (HEADER_AS_INT16, PACKETS[3][0])
    assert HEADER_AS_INT16 == -23131  # -23.1 m/s


def test_the_aligned_reader_hands_on_the_newest_whole_packet() -> None:
    with _port_with(PACKETS[:10]) as port:
        reader = AlignedReader(port)
        assert reader.read() == PACKETS[9]
        port.write(encode_reference(*PACKETS[10])[:4])  # half a packet: still the last whole one
        assert reader.read() == PACKETS[9]
        port.write(encode_reference(*PACKETS[10])[4:])
        assert reader.read() == PACKETS[10]


def test_the_aligned_reader_before_any_packet_has_nothing() -> None:
    with serial.serial_for_url("loop://", timeout=0.0) as port:
        assert AlignedReader(port).read() is None
