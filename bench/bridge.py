"""Benchmark of the serial link's decoders (``bridge.protocol``).

1 M random bytes with valid frames interleaved (a frame about every 100 bytes), decoded in
4 KiB chunks as a serial read would deliver them, for each framing. Reported: throughput in
MB/s (10^6 bytes/s), the same figure as a ratio against a baseline measured in the same
process on the same bytes (a ``bytes.find`` loop visiting every header or delimiter, the
least any Python decoder of the framing must do), and the frames recovered out of those sent
(all of them, or the decoder is wrong) with the false frames that garbage produced.

    python -m bench.bridge [--quick]
"""

from __future__ import annotations

import argparse
import random
import time
from collections.abc import Callable, Sequence

from bridge.protocol import Feedback, ReferenceDecoder, RobustDecoder, encode_message
from bridge.protocol.reference import encode_reference

CHUNK = 4096  # bytes per feed, like one read of a busy serial port
GAP = 100  # mean garbage bytes between frames


def _interleave(garbage: bytes, frames: Sequence[bytes], rng: random.Random) -> bytes:
    cuts = sorted(rng.randrange(len(garbage) + 1) for _ in frames)
    parts, start = [], 0
    for cut, frame in zip(cuts, frames, strict=True):
        parts += [garbage[start:cut], frame]
        start = cut
    parts.append(garbage[start:])
    return b"".join(parts)


def _recovered(sent: Sequence[object], got: Sequence[object]) -> int:
    """How many of ``sent`` appear in ``got`` in order (extra items in ``got`` allowed)."""
    k = 0
    for item in got:
        if k < len(sent) and item == sent[k]:
            k += 1
    return k


def _best_rate(n_bytes: int, run: Callable[[], object], repeats: int = 5) -> float:
    """Best of ``repeats`` runs, MB/s: the least disturbed by the other core's load."""
    best = 0.0
    for _ in range(repeats):
        t0 = time.perf_counter()
        run()
        best = max(best, n_bytes / (time.perf_counter() - t0) / 1e6)
    return best


def _find_all(data: bytes, needle: bytes) -> int:
    count, i = 0, data.find(needle)
    while i >= 0:
        count += 1
        i = data.find(needle, i + 1)
    return count


def _decode_chunks(decoder: ReferenceDecoder | RobustDecoder, data: bytes) -> list:
    out: list = []
    for i in range(0, len(data), CHUNK):
        out += decoder.feed(data[i : i + CHUNK])
    return out + decoder.flush()


def bench_bridge(quick: bool) -> list[tuple[str, float, str]]:
    """Decoder throughput (MB/s) and frames recovered, both framings."""
    n_garbage = 100_000 if quick else 1_000_000
    n_frames = n_garbage // GAP
    rng = random.Random(12)
    garbage = rng.randbytes(n_garbage)
    rows: list[tuple[str, float, str]] = []

    # Reference: encoder speeds in the robot's range (+-1.5 m/s), reference §1.
    pairs = [(rng.randint(-1500, 1500), rng.randint(-1500, 1500)) for _ in range(n_frames)]
    stream = _interleave(garbage, [encode_reference(*p) for p in pairs], rng)
    base = _best_rate(len(stream), lambda: _find_all(stream, b"\xa5\xa5"))
    rate = _best_rate(len(stream), lambda: _decode_chunks(ReferenceDecoder(), stream))
    got = _decode_chunks(ReferenceDecoder(), stream)
    found = _recovered(pairs, got)
    rows += [
        ("reference: bytes.find A5 A5 (base)", base, "1.00x"),
        ("reference: decoder (MB/s)", rate, f"{rate / base:.3f}x base"),
        ("reference: frames recovered", found, f"{found}/{n_frames}, {len(got) - found} false"),
    ]

    # Robust: feedback messages, numbered consecutively.
    sent = [Feedback(r, left, 40 * k, -40 * k, 10 * k, 0) for k, (r, left) in enumerate(pairs)]
    stream = _interleave(garbage, [encode_message(m, k & 0xFFFF) for k, m in enumerate(sent)], rng)
    base = _best_rate(len(stream), lambda: _find_all(stream, b"\x00"))
    rate = _best_rate(len(stream), lambda: _decode_chunks(RobustDecoder(), stream))
    got = _decode_chunks(RobustDecoder(), stream)
    found = _recovered(sent, got)
    rows += [
        ("robust: bytes.find 00 (base)", base, "1.00x"),
        ("robust: decoder (MB/s)", rate, f"{rate / base:.3f}x base"),
        ("robust: frames recovered", found, f"{found}/{n_frames}, {len(got) - found} false"),
    ]
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(
        prog="python -m bench.bridge", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--quick", action="store_true", help="100 kB instead of 1 MB")
    args = parser.parse_args()
    for name, value, ratio in bench_bridge(args.quick):
        print(f"| {name:<36} | {value:>12,.1f} | {ratio:>26} |")


if __name__ == "__main__":
    main()
