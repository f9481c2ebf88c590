"""bridge/protocol/reference.py: the reference framing (reference §1) and its decoder's guarantees.

Each guarantee and each documented ambiguity of ``ReferenceDecoder`` is tested here as stated
in its docstring.
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bridge.protocol import CommandKind, Feedback, ReferenceCodec, WheelCommand
from bridge.protocol.reference import ReferenceDecoder, encode_reference

A5 = 0xA5
# Bytes that make A5 patterns likely: A5 itself and its neighbours in value and bit pattern.
TRICKY = [0x00, 0x01, 0xA5, 0x5A, 0xFF, 0xA4, 0x25]


def _s16(hi: int, lo: int) -> int:
    v = hi << 8 | lo
    return v - 65536 if v >= 32768 else v


any_value = st.one_of(
    st.integers(-32768, 32767),
    st.builds(_s16, st.sampled_from(TRICKY), st.sampled_from(TRICKY)),
    st.sampled_from([-23131, -91, 165, 421, -23296, -23041]),
)
plausible_value = any_value.filter(lambda v: (v >> 8) & 0xFF != A5)
noise = st.binary(min_size=1, max_size=12).map(lambda b: b.replace(b"\xa5", b"\x5a"))
tricky_noise = st.lists(st.sampled_from([b for b in TRICKY if b != A5]), min_size=1, max_size=8)


def decode_all(stream: bytes, cuts: list[int] | None = None) -> list[tuple[int, int]]:
    """Feed ``stream`` (split at ``cuts``), then flush."""
    decoder = ReferenceDecoder()
    frames: list[tuple[int, int]] = []
    start = 0
    for cut in sorted(cuts or []):
        frames += decoder.feed(stream[start:cut])
        start = cut
    frames += decoder.feed(stream[start:])
    return frames + decoder.flush()


# ---- the format ---------------------------------------------------------------------------


def test_frame_is_header_then_right_then_left_big_endian() -> None:
    assert encode_reference(0x0102, -2) == bytes([0xA5, 0xA5, 0x01, 0x02, 0xFF, 0xFE])
    assert encode_reference(-23131, 0) == bytes([0xA5, 0xA5, 0xA5, 0xA5, 0x00, 0x00])


def test_out_of_range_value_is_refused_naming_it() -> None:
    with pytest.raises(ValueError, match=r"left=32768 is out of range"):
        encode_reference(0, 32768)


def test_a_frame_without_a5_in_its_data_is_decided_on_its_last_byte() -> None:
    decoder = ReferenceDecoder()
    assert decoder.feed(encode_reference(100, -100)[:5]) == []
    assert decoder.feed(encode_reference(100, -100)[5:]) == [(100, -100)]


def test_a_frame_ending_in_a5_waits_for_the_next_byte_or_flush() -> None:
    decoder = ReferenceDecoder()
    assert decoder.feed(encode_reference(0, -91)) == []  # -91 = 0xFFA5
    assert decoder.pending_bytes == 6
    assert decoder.flush() == [(0, -91)]


# ---- guarantee 1: a clean stream, any values ---------------------------------------------


@given(st.lists(st.tuples(any_value, any_value), min_size=1, max_size=12))
def test_clean_stream_is_decoded_exactly_whatever_the_values(frames: list[tuple[int, int]]) -> None:
    stream = b"".join(encode_reference(r, left) for r, left in frames)
    decoder = ReferenceDecoder()
    assert decoder.feed(stream) + decoder.flush() == frames
    assert decoder.stats.frames_ok == len(frames)
    assert decoder.stats.bytes_skipped == 0


def test_steady_a5a5_values_stay_locked() -> None:
    frames = [(-23131, -23131)] * 5 + [(0x00A5, _s16(0xA5, 0x01))] * 5 + [(1, 2)]
    assert decode_all(b"".join(encode_reference(*f) for f in frames)) == frames


# ---- guarantee 2: plausible frames, noise and cut frames ----------------------------------


@st.composite
def frames_noise_and_cuts(draw: st.DrawFn) -> tuple[bytes, list[tuple[int, int]]]:
    """A stream in the class of guarantee 2 and the frames sent in it."""
    kinds = draw(st.lists(st.sampled_from(["frame", "frame", "noise", "cut"]), max_size=10))
    chunks: list[bytes] = []
    sent: list[tuple[int, int]] = []
    last = ""  # what the previous chunk was: "frame", "noise", "cut1" (a lone A5), "cut"

    def frame(after_lone_a5: bool) -> None:
        left = plausible_value.filter(lambda v: v & 0xFF != A5) if after_lone_a5 else None
        pair = (draw(plausible_value), draw(plausible_value if left is None else left))
        chunks.append(encode_reference(*pair))
        sent.append(pair)

    for i, kind in enumerate(kinds):
        if kind == "frame":
            frame(last == "cut1")
            last = "frame"
        elif kind == "noise":
            chunks.append(draw(st.one_of(noise, tricky_noise.map(bytes))))
            last = "noise"
        else:
            length = draw(st.integers(1, 5))
            pair = (draw(plausible_value), draw(plausible_value))
            chunks.append(encode_reference(*pair)[:length])
            frame(length == 1)  # a cut frame is followed by a whole frame ...
            nxt = kinds[i + 1] if i + 1 < len(kinds) else None
            if nxt == "noise":  # ... which is confirmed: by a frame, a cut frame or the end
                frame(False)
            last = "frame"
    return b"".join(chunks), sent


@given(frames_noise_and_cuts())
@settings(max_examples=300)
def test_every_frame_is_recovered_from_noise_and_cut_frames(
    case: tuple[bytes, list[tuple[int, int]]],
) -> None:
    stream, sent = case
    decoder = ReferenceDecoder()
    assert decoder.feed(stream) + decoder.flush() == sent
    assert decoder.stats.bytes_skipped == len(stream) - 6 * len(sent)


def test_resynchronises_after_a_cut_frame() -> None:
    cut = encode_reference(1000, 1000)[:3]
    stream = encode_reference(1, 2) + cut + encode_reference(3, 4) + encode_reference(5, 6)
    decoder = ReferenceDecoder()
    assert decoder.feed(stream) + decoder.flush() == [(1, 2), (3, 4), (5, 6)]
    assert decoder.stats.bytes_skipped == 3
    assert decoder.stats.false_frames == 1  # the cut frame's header was a candidate


def test_garbage_is_counted_as_skipped_as_it_arrives() -> None:
    decoder = ReferenceDecoder()
    decoder.feed(bytes(100) + b"\xa5")
    assert decoder.stats.bytes_skipped == 100  # the trailing A5 may start a header
    assert decoder.pending_bytes == 1


def test_resynchronises_after_garbage_that_has_no_a5() -> None:
    stream = bytes(range(0x10, 0x50)) + encode_reference(-91, 165) + b"\x00\x01"
    assert decode_all(stream) == [(-91, 165)]


# ---- guarantee 3: chunking ---------------------------------------------------------------


@given(
    frames_noise_and_cuts(),
    st.lists(st.binary(max_size=8), max_size=4),
    st.lists(st.integers(0, 400), max_size=12),
)
def test_every_split_of_the_stream_gives_the_same_frames(
    case: tuple[bytes, list[tuple[int, int]]], garbage: list[bytes], cuts: list[int]
) -> None:
    # Arbitrary garbage too: chunking invariance holds for any bytes, not just guarantee 2's.
    stream = case[0] + b"".join(garbage)
    cuts = [c for c in cuts if c <= len(stream)]
    assert decode_all(stream, cuts) == decode_all(stream)


def test_byte_by_byte_feeding_gives_the_same_frames() -> None:
    stream = (
        b"\xa5" + encode_reference(-23131, 165) + b"\xa5\xa5\x01" + encode_reference(2, -91) * 3
    )
    assert decode_all(stream, list(range(len(stream)))) == decode_all(stream)


# ---- the documented ambiguities ----------------------------------------------------------


def test_garbage_that_looks_like_a_frame_is_emitted() -> None:
    fake = bytes([0xA5, 0xA5, 0x01, 0x02, 0x03, 0x04])
    stream = encode_reference(1, 1) + b"\x11" + fake + b"\x22" + encode_reference(2, 2)
    assert decode_all(stream) == [(1, 1), (0x0102, 0x0304), (2, 2)]


def test_cut_frame_then_unconfirmed_frame_reads_as_the_cut_frame_reading() -> None:
    # A5 A5 a b c + A5 A5 d e f g + noise == a frame ending in A5 + "A5 d e f g" garbage.
    stream = bytes([0xA5, 0xA5, 1, 2, 3]) + encode_reference(0x0405, 0x0607) + b"\x11\x22"
    assert decode_all(stream) == [(0x0405, 0x0607)]


def test_lone_a5_before_frames_ending_in_a5_shifts_them_until_one_does_not() -> None:
    frames = [(10, 165), (20, 165), (30, 7)]  # 165 = 0x00A5
    stream = encode_reference(1, 1) + b"\xa5" + b"".join(encode_reference(*f) for f in frames)
    got = decode_all(stream)
    assert got[0] == (1, 1)
    assert got[-1] == (30, 7)  # resynchronised where the left low byte is no longer A5
    assert (10, 165) not in got  # the frames in between were read one byte early


# ---- the codec ---------------------------------------------------------------------------


def test_pc_codec_decodes_feedback_and_mcu_codec_decodes_commands() -> None:
    pc, mcu = ReferenceCodec("pc"), ReferenceCodec("mcu")
    command = WheelCommand(50, -50, CommandKind.DUTY_PERCENT)
    assert mcu.feed(pc.encode(command)) == [command]
    assert pc.feed(mcu.encode(Feedback(800, 790))) == [Feedback(800, 790)]


def test_codec_refuses_a_command_in_another_unit() -> None:
    with pytest.raises(ValueError, match=r"carries DUTY_PERCENT commands"):
        ReferenceCodec("pc").encode(WheelCommand(5000, 0, CommandKind.DUTY_CENTI_PERCENT))


def test_codec_for_speed_firmware_carries_speed_targets() -> None:
    pc = ReferenceCodec("pc", command_kind=CommandKind.SPEED_MM_S)
    mcu = ReferenceCodec("mcu", command_kind=CommandKind.SPEED_MM_S)
    command = WheelCommand(1200, 1100, CommandKind.SPEED_MM_S)
    assert mcu.feed(pc.encode(command)) == [command]
