"""The built-in tracks: fixed courses of each kind of tile, a mixed course, and a random one.

Fixed (laid once, the same in every episode): ``straight`` (six straight tiles), ``corners``
(90 deg corners both ways), ``curves`` (the same course with quarter circles), ``zigzag``,
``gaps`` (gaps of ``track.gap_m``, 20 cm by default, between straight tiles) and ``course``
(every kind of tile: the default). ``random`` lays a new course per episode from the track
stream (module :mod:`.registry` explains the tile letters).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from follow_env.sim.rng import LaneRandom
from follow_env.tasks.line_trace.tracks.registry import TrackLayout, register_track, tile_length

__all__ = ["FIXED_PROGRAMS", "random_program", "shortest_random_length"]

FIXED_PROGRAMS: dict[str, str] = {
    "straight": "SSSSSS",
    "corners": "SSLSLSSRSRSSLS",
    "curves": "SSlSlSSrSrSSlS",
    "zigzag": "SZSZSZS",
    "gaps": "SGSGSGS",
    "course": "SSlZSRGSLlSZrGSRS",
}
"""Each fixed track's tile program."""


def _fixed(program: str) -> Any:
    def track(rng: LaneRandom, cfg: Any) -> TrackLayout:
        return TrackLayout(program)

    return track


for _name, _program in FIXED_PROGRAMS.items():
    register_track(_name, max_tiles=len(_program))(_fixed(_program))

_STEP = ((1, 0), (0, 1), (-1, 0), (0, -1))
_MOVES = ("S", "L", "R")
_TURN = {"S": 0, "L": 1, "R": -1}
_WEIGHT = np.array([2.0, 1.0, 1.0])  # straight on twice as likely as either turn
_BUDGET = 20_000  # tiles tried per attempt before starting over


def random_program(rng: LaneRandom, cfg: Any) -> str:
    """A random course of ``track.random_tiles`` tiles within ``random_cols`` x
    ``random_rows``: a self-avoiding walk from the field's left edge, found by depth-first
    search in an order drawn per tile (straight on twice as likely as a turn); a plain start
    and end tile; each straight tile a gap or a zigzag with their chances, each turn a curve
    or a 90 deg corner. Every choice is a draw of ``rng`` (one lane), so the course is a pure
    function of the episode's track key."""
    tc = cfg.track
    n, cols, rows = tc.random_tiles, tc.random_cols, tc.random_rows
    for _ in range(100):
        row0 = min(int(rng.uniform()[0] * rows), rows - 1)
        moves = _walk(rng, n, cols, rows, row0)
        if moves is not None:
            break
    else:  # pragma: no cover - a field this crowded is refused by TrackConfig
        raise ValueError(f"no random track of {n} tiles found within {cols} x {rows} tiles")
    out = []
    for k, m in enumerate(moves):
        u = float(rng.uniform()[0])
        if m == "S":
            if 0 < k < n - 1 and u < tc.random_gap_prob:
                out.append("G")
            elif 0 < k < n - 1 and u < tc.random_gap_prob + tc.random_zigzag_prob:
                out.append("Z")
            else:
                out.append("S")
        else:
            out.append(m.lower() if u < tc.random_curve_prob else m)
    return "".join(out)


def _walk(rng: LaneRandom, n: int, cols: int, rows: int, row0: int) -> list[str] | None:
    """The moves of a self-avoiding walk of ``n`` tiles (the first and last straight), or
    None when the search ran out of budget."""
    visited = {(0, row0)}
    moves: list[str] = []
    budget = [_BUDGET]

    def extend(c: int, r: int, h: int) -> bool:
        if len(moves) == n - 1:
            moves.append("S")  # the last tile: the line runs straight out of it
            return True
        if budget[0] <= 0:
            return False
        budget[0] -= 1
        # A weighted random order (Efraimidis-Spirakis keys); the first tile goes straight.
        keys = -np.log(1.0 - rng.uniform(3)[0]) / _WEIGHT
        order = [_MOVES[i] for i in np.argsort(keys, kind="stable")] if moves else ["S"]
        for m in order:
            h2 = (h + _TURN[m]) % 4
            c2, r2 = c + _STEP[h2][0], r + _STEP[h2][1]
            if 0 <= c2 < cols and 0 <= r2 < rows and (c2, r2) not in visited:
                visited.add((c2, r2))
                moves.append(m)
                if extend(c2, r2, h2):
                    return True
                moves.pop()
                visited.discard((c2, r2))
        return False

    return moves if extend(0, row0, 0) else None


def shortest_random_length(cfg: Any) -> float:
    """The shortest line (m) a ``random`` track can have under ``cfg``: its first and last tiles
    straight, every other one the shortest tile it may be (a curve's chords when curves may be
    drawn, else a tile's length: a corner, a gap or a straight)."""
    tc = cfg.track
    inner = min(tile_length(k, cfg) for k in ("S", "l" if tc.random_curve_prob > 0.0 else "L"))
    return 2 * tile_length("S", cfg) + (tc.random_tiles - 2) * inner


@register_track(
    "random",
    max_tiles=lambda cfg: cfg.track.random_tiles,
    random=True,
    shortest=shortest_random_length,
)
def random_track(rng: LaneRandom, cfg: Any) -> TrackLayout:
    """A new course per episode (:func:`random_program`)."""
    return TrackLayout(random_program(rng, cfg))
