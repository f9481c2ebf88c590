"""bridge/protocol/robust.py: the robust framing (COBS, version, sequence number, CRC-16)."""

from __future__ import annotations

import pytest
from cobs import cobs
from hypothesis import given, settings
from hypothesis import strategies as st

from bridge.protocol import (
    PROTOCOL_VERSION,
    Capability,
    CommandKind,
    Feedback,
    Hello,
    Message,
    MsgType,
    PeerRole,
    RobustCodec,
    RobustDecoder,
    VersionMismatch,
    WheelCommand,
    crc16_ccitt_false,
    encode_frame,
    encode_message,
    pack_message,
)
from bridge.protocol.robust import MAX_ENCODED

i16 = st.integers(-(2**15), 2**15 - 1)
i32 = st.integers(-(2**31), 2**31 - 1)
commands = st.builds(
    WheelCommand,
    i16,
    i16,
    st.sampled_from([CommandKind.DUTY_CENTI_PERCENT, CommandKind.SPEED_MM_S]),
)
feedbacks = st.builds(Feedback, i16, i16, i32, i32, st.integers(0, 2**32 - 1), st.integers(0, 255))
hellos = st.builds(
    Hello,
    st.sampled_from(list(PeerRole)),
    st.integers(0, 255).map(Capability),
    st.integers(0, 2**16 - 1),
    st.tuples(st.integers(0, 255), st.integers(0, 255), st.integers(0, 255)),
)
messages = st.one_of(commands, feedbacks, hellos)


def decode_all(stream: bytes, cuts: list[int] | None = None) -> tuple[list, RobustDecoder]:
    decoder = RobustDecoder()
    out: list = []
    start = 0
    for cut in sorted(cuts or []):
        out += decoder.feed(stream[start:cut])
        start = cut
    out += decoder.feed(stream[start:])
    return out + decoder.flush(), decoder


def encode_all(items: list[Message], start_seq: int = 0) -> list[bytes]:
    return [encode_message(m, (start_seq + k) & 0xFFFF) for k, m in enumerate(items)]


# ---- CRC and layout -----------------------------------------------------------------------


def test_crc_is_ccitt_false_with_its_catalogue_check_value() -> None:
    assert crc16_ccitt_false(b"123456789") == 0x29B1
    assert crc16_ccitt_false(b"") == 0xFFFF


def test_crc_of_a_frame_with_its_crc_appended_big_endian_is_zero() -> None:
    raw = cobs.decode(encode_message(Feedback(1, 2, 3, 4, 5, 0), 9)[1:-1])
    assert crc16_ccitt_false(raw) == 0


def test_frame_layout_is_version_type_seq_payload_crc_in_cobs_between_zeros() -> None:
    wire = encode_message(WheelCommand(-2, 0x0102, CommandKind.SPEED_MM_S), 0x1234)
    assert (wire[0], wire[-1]) == (0, 0)
    assert 0 not in wire[1:-1]
    raw = cobs.decode(wire[1:-1])
    body = bytes([PROTOCOL_VERSION, MsgType.WHEEL_COMMAND, 0x12, 0x34, 1, 0xFF, 0xFE, 1, 2])
    assert raw[:-2] == body
    assert raw[-2:] == crc16_ccitt_false(body).to_bytes(2, "big")


def test_feedback_payload_is_17_bytes_big_endian() -> None:
    msg_type, payload = pack_message(Feedback(-1, 2, -3, 4, 0x01020304, 1))
    assert msg_type == MsgType.FEEDBACK
    assert payload.hex() == "ffff0002fffffffd000000040102030401"


def test_duty_in_whole_percent_is_refused_with_the_conversion() -> None:
    with pytest.raises(ValueError, match=r"multiply percent by 100"):
        encode_message(WheelCommand(50, 50, CommandKind.DUTY_PERCENT), 0)


def test_reference_feedback_without_counts_cannot_be_sent_robustly() -> None:
    with pytest.raises(ValueError, match=r"missing: right_count, left_count"):
        encode_message(Feedback(1, 2), 0)


def test_payload_longer_than_the_envelope_allows_is_refused() -> None:
    with pytest.raises(ValueError, match=r"too long"):
        encode_frame(MsgType.FEEDBACK, 0, bytes(65))


# ---- recovery from garbage ----------------------------------------------------------------


@given(st.lists(st.tuples(messages, st.binary(max_size=80)), max_size=12), st.binary(max_size=40))
@settings(max_examples=300)
def test_every_frame_is_recovered_from_garbage_between_frames(
    pairs: list[tuple[Message, bytes]], lead: bytes
) -> None:
    sent = [m for m, _ in pairs]
    wires = encode_all(sent)
    stream = lead + b"".join(w + garbage for w, (_, garbage) in zip(wires, pairs, strict=True))
    got, decoder = decode_all(stream)
    assert got == sent
    assert decoder.stats.frames_ok == len(sent)
    # Skipped: garbage and delimiters, never a byte inside a delivered frame.
    inside_frames = sum(len(w) - 2 for w in wires)
    assert decoder.stats.bytes_skipped <= len(stream) - inside_frames


@given(
    st.lists(messages, max_size=8),
    st.lists(st.binary(max_size=30), max_size=8),
    st.lists(st.integers(0, 600), max_size=16),
)
def test_every_split_of_the_stream_gives_the_same_result(
    sent: list[Message], garbage: list[bytes], cuts: list[int]
) -> None:
    stream = b"".join(w + g for w, g in zip(encode_all(sent), garbage + [b""] * 8, strict=False))
    cuts = [c for c in cuts if c <= len(stream)]
    got, split = decode_all(stream, cuts)
    whole_got, whole = decode_all(stream)
    assert got == whole_got
    assert split.stats == whole.stats


def test_oversized_run_is_counted_and_the_next_frame_still_decodes() -> None:
    stream = bytes([0x11] * 500) + encode_message(Feedback(1, 2, 3, 4, 5, 0), 0)
    got, decoder = decode_all(stream)
    assert got == [Feedback(1, 2, 3, 4, 5, 0)]
    assert decoder.stats.oversized_frames == 1
    assert decoder.stats.bytes_skipped == 501  # the run and the delimiter that ended it
    assert MAX_ENCODED == 71


def test_cut_frame_is_counted_as_false_and_dropped() -> None:
    whole = encode_message(Feedback(1, 2, 3, 4, 5, 0), 0)
    stream = whole[:10] + encode_message(Feedback(6, 7, 8, 9, 10, 0), 1)
    got, decoder = decode_all(stream)
    assert got == [Feedback(6, 7, 8, 9, 10, 0)]
    assert decoder.stats.false_frames + decoder.stats.crc_failures == 1


# ---- corruption, sequence, version --------------------------------------------------------


@given(feedbacks, st.integers(0, 2**16 - 1), st.data())
def test_a_corrupted_frame_is_counted_as_a_crc_failure_and_dropped(
    message: Feedback, seq: int, data: st.DataObject
) -> None:
    # Corrupt the frame before COBS (any one byte, any bit flips): COBS stays valid and a
    # burst of at most 8 bits is always caught by a CRC-16.
    msg_type, payload = pack_message(message)
    raw = bytearray(cobs.decode(encode_frame(msg_type, seq, payload)[1:-1]))
    k = data.draw(st.integers(0, len(raw) - 1))
    raw[k] ^= data.draw(st.integers(1, 255))
    stream = b"\x00" + cobs.encode(bytes(raw)) + b"\x00" + encode_message(message, seq)
    got, decoder = decode_all(stream)
    assert got == [message]
    assert decoder.stats.crc_failures == 1


def test_sequence_gaps_are_counted_across_the_wrap_around() -> None:
    seqs = [65533, 65534, 0, 3, 4, 4, 10]
    stream = b"".join(encode_message(Feedback(0, 0, 0, 0, 0, 0), s) for s in seqs)
    got, decoder = decode_all(stream)
    assert len(got) == 7
    # 65534 -> 0 skips 65535 (1 lost), 0 -> 3 (2 lost), 4 -> 10 (5 lost); 4 -> 4 repeats.
    assert (decoder.stats.seq_gaps, decoder.stats.frames_lost) == (3, 8)
    assert decoder.stats.seq_resets == 1


@given(st.integers(0, 2**16 - 1), st.lists(st.booleans(), min_size=1, max_size=40))
def test_lost_frames_are_exactly_the_ones_not_delivered(start: int, delivered: list[bool]) -> None:
    sent = [Feedback(k, 0, 0, 0, 0, 0) for k in range(len(delivered))]
    wires = encode_all(sent, start_seq=start)
    delivered[0] = delivered[-1] = True  # losses are only visible between received frames
    stream = b"".join(w for w, keep in zip(wires, delivered, strict=True) if keep)
    _, decoder = decode_all(stream)
    assert decoder.stats.frames_lost == delivered.count(False)


def test_a_hello_starts_a_new_sequence() -> None:
    hello = Hello(PeerRole.MCU, Capability.DUTY_COMMANDS, 10, (1, 0, 0))
    stream = encode_message(Feedback(0, 0, 0, 0, 0, 0), 500) + encode_message(hello, 0)
    _, decoder = decode_all(stream)
    assert decoder.stats.seq_gaps == decoder.stats.seq_resets == 0


def test_a_frame_of_another_version_is_refused_not_decoded() -> None:
    msg_type, payload = pack_message(Feedback(1, 2, 3, 4, 5, 0))
    alien = encode_frame(msg_type, 0, payload, version=PROTOCOL_VERSION + 1)
    got, decoder = decode_all(alien + encode_message(Feedback(6, 7, 8, 9, 10, 0), 1))
    assert got == [
        VersionMismatch(PROTOCOL_VERSION + 1, PROTOCOL_VERSION, msg_type),
        Feedback(6, 7, 8, 9, 10, 0),
    ]
    assert decoder.stats.version_mismatches == 1


def test_unknown_type_and_wrong_length_are_false_frames() -> None:
    stream = encode_frame(0x7F, 0, b"\x01\x02") + encode_frame(MsgType.FEEDBACK, 1, b"\x00" * 16)
    got, decoder = decode_all(stream)
    assert got == []
    assert decoder.stats.false_frames == 2
    assert decoder.stats.seq_gaps == 0  # both were intact frames: their numbers still count


# ---- the codec ----------------------------------------------------------------------------


@given(st.lists(messages, max_size=10), st.integers(0, 2**16 - 1))
def test_codec_round_trip_numbers_frames_consecutively(sent: list[Message], start: int) -> None:
    sender, receiver = RobustCodec("mcu", start_seq=start), RobustCodec("pc")
    stream = b"".join(sender.encode(m) for m in sent)
    assert receiver.feed(stream) == sent
    assert sender.next_seq == (start + len(sent)) & 0xFFFF
    # Hellos restart the sequence; otherwise consecutive numbers: nothing counted as lost.
    assert receiver.stats.frames_lost == receiver.stats.seq_resets == 0
