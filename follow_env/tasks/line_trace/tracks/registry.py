"""The track registry, and how a track's tiles become the line on the floor.

A track is a row of 30 cm tiles laid by a *tile program*, one letter per tile, read like a
turtle: the line enters each tile from the side it is heading from and leaves it into the next.

| letter | tile | leaves |
|---|---|---|
| ``S`` | straight | ahead |
| ``G`` | straight with a gap of ``track.gap_m`` in its middle | ahead |
| ``Z`` | zigzag: ``zigzag_teeth`` teeth of ``zigzag_amplitude_m`` to either side | ahead |
| ``L`` / ``R`` | 90 deg corner, a sharp bend in the tile's centre | to the left / right |
| ``l`` / ``r`` | curve: a quarter circle of half a tile's radius | to the left / right |

The first tile starts at ``(0, 0)`` heading ``+x``; tiles may not overlap. The field is the
tiles' bounding box with one empty tile all round, shifted so that its corner is the origin.
A track function returns the program (:class:`TrackLayout`); :func:`build_track` lays it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from follow_env.sim import streams
from follow_env.sim.checks import out_of_range
from follow_env.sim.rng import LaneRandom
from follow_env.world.floor_line import arc_points, line_segments

if TYPE_CHECKING:
    from follow_env.tasks.line_trace.config import LineTraceConfig

__all__ = [
    "TILE_LETTERS",
    "TRACKS",
    "Track",
    "TrackLayout",
    "TrackSpec",
    "build_track",
    "get_track",
    "register_track",
    "tile_cells",
    "tile_length",
]

TILE_LETTERS = "SGZLRlr"
_TURN = {"S": 0, "G": 0, "Z": 0, "L": 1, "R": -1, "l": 1, "r": -1}
_STEP = ((1, 0), (0, 1), (-1, 0), (0, -1))  # heading 0..3: +x, +y, -x, -y

TRACK_DRAWS = streams.per_episode(
    "track.random", streams.TRACK, 16, None, doc="a random track's choices, drawn as it is laid"
)


@dataclass(frozen=True)
class TrackLayout:
    """What a track function returns: the tile program (module docstring)."""

    program: str


@dataclass(frozen=True)
class Track:
    """A laid track: the line's segments and the field.

    :param name: the track's name. :param program: its tile program.
    :param segments: ``(k, fields)`` float array of the line's segments
        (:data:`~follow_env.world.floor_line.LINE_SEGMENT`).
    :param cells: ``(tiles, 2)`` int: each tile's column and row.
    :param field: ``(x0, y0, x1, y1)`` m: the field's corners (tiles, plus a tile all round).
    :param length_m: the line's length, start to end.
    """

    name: str
    program: str
    segments: np.ndarray
    cells: np.ndarray
    field: tuple[float, float, float, float]
    length_m: float


TrackFn = Callable[[LaneRandom, "LineTraceConfig"], TrackLayout]


@dataclass(frozen=True)
class TrackSpec:
    """A registered track.

    :param name: its name. :param fn: the track function.
    :param max_tiles: most tiles it lays (sizes the lanes' segment arrays); an int or a function
        of the configuration.
    :param random: it draws (a new track per episode); a fixed track is laid once and shared.
    :param shortest: a random track's shortest possible line (m) as a function of the
        configuration, or None when unknown: a start further along than that is refused when
        the env is made (else when a track too short for it is laid).
    """

    name: str
    fn: TrackFn
    max_tiles: int | Callable[[LineTraceConfig], int]
    random: bool
    shortest: Callable[[LineTraceConfig], float] | None = None

    def tiles_for(self, cfg: LineTraceConfig) -> int:
        """Most tiles under ``cfg``."""
        return self.max_tiles(cfg) if callable(self.max_tiles) else self.max_tiles

    def segments_for(self, cfg: LineTraceConfig) -> int:
        """Most segments of the line under ``cfg``: a curve tile has the most (18 chords)."""
        per_tile = max(18, cfg.track.zigzag_teeth + 1, 3)
        return self.tiles_for(cfg) * per_tile


TRACKS: dict[str, TrackSpec] = {}
"""Registered tracks by name."""


def register_track(
    name: str,
    *,
    max_tiles: int | Callable[[LineTraceConfig], int],
    random: bool = False,
    shortest: Callable[[LineTraceConfig], float] | None = None,
) -> Callable[[TrackFn], TrackFn]:
    """Register ``fn`` as track ``name`` (see :class:`TrackSpec`)."""

    def deco(fn: TrackFn) -> TrackFn:
        if name in TRACKS:
            raise ValueError(f"track {name!r} is registered already")
        TRACKS[name] = TrackSpec(name, fn, max_tiles, random, shortest)
        return fn

    return deco


def get_track(name: str) -> TrackSpec:
    """The track called ``name``; ``ValueError`` naming the field and the known ones."""
    if name not in TRACKS:
        raise out_of_range(
            "TrackConfig.name", name, "one of " + ", ".join(repr(n) for n in sorted(TRACKS))
        )
    return TRACKS[name]


def tile_cells(program: str) -> tuple[np.ndarray, list[int]]:
    """Each tile's ``(col, row)`` and the heading (0..3) the line enters it with, from ``(0, 0)``
    heading +x; ``ValueError`` for an unknown letter or tiles that overlap."""
    cells, headings = [], []
    c, r, h = 0, 0, 0
    seen: set[tuple[int, int]] = set()
    for k, letter in enumerate(program):
        if letter not in _TURN:
            raise ValueError(
                f"tile program {program!r}: letter {k} ({letter!r}) is not one of {TILE_LETTERS}"
            )
        if (c, r) in seen:
            raise ValueError(f"tile program {program!r}: tile {k} lies on an earlier tile")
        seen.add((c, r))
        cells.append((c, r))
        headings.append(h)
        h = (h + _TURN[letter]) % 4
        c, r = c + _STEP[h][0], r + _STEP[h][1]
    return np.array(cells, dtype=np.int64).reshape(-1, 2), headings


def _tile_line(letter: str, cfg: Any) -> tuple[np.ndarray, np.ndarray]:
    """One tile's polyline (tile frame: entry at ``(-T/2, 0)``, heading +x) and ink flags."""
    tc = cfg.track
    half = 0.5 * tc.tile_m
    if letter == "S":
        return np.array([[-half, 0.0], [half, 0.0]]), np.array([1.0])
    if letter == "G":
        g = 0.5 * tc.gap_m
        pts = np.array([[-half, 0.0], [-g, 0.0], [g, 0.0], [half, 0.0]])
        return pts, np.array([1.0, 0.0, 1.0])
    if letter == "Z":
        n, a = tc.zigzag_teeth, tc.zigzag_amplitude_m
        xs = -half + tc.tile_m * (np.arange(n) + 0.5) / n
        ys = a * np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
        pts = np.vstack([[-half, 0.0], np.stack([xs, ys], axis=1), [half, 0.0]])
        return pts, np.ones(n + 1)
    sign = 1.0 if letter in "Ll" else -1.0
    if letter in "LR":
        pts = np.array([[-half, 0.0], [0.0, 0.0], [0.0, sign * half]])
        return pts, np.ones(2)
    # A quarter circle round the tile's corner beside the entry: from the entry's midpoint to
    # the exit's.
    pts = arc_points(-half, sign * half, half, -sign * math.pi / 2, 0.0)
    pts[:, 0] = np.where(np.abs(pts[:, 0]) < 1e-12, 0.0, pts[:, 0])
    return pts, np.ones(len(pts) - 1)


def tile_length(letter: str, cfg: Any) -> float:
    """The length (m) of the line over one tile ``letter`` under ``cfg`` (gaps included)."""
    if letter not in _TURN:
        raise ValueError(f"tile letter {letter!r} is not one of {TILE_LETTERS}")
    pts, _ = _tile_line(letter, cfg)
    return float(np.hypot(*np.diff(pts, axis=0).T).sum())


def build_track(name: str, layout: TrackLayout, cfg: Any) -> Track:
    """Lay ``layout``'s tiles under ``cfg`` (module docstring)."""
    program = layout.program
    if not program:
        raise ValueError(f"track {name!r}: the tile program is empty")
    cells, headings = tile_cells(program)
    t = cfg.track.tile_m
    lo = cells.min(axis=0) - 1  # one empty tile all round
    hi = cells.max(axis=0) + 2
    points: list[np.ndarray] = []
    ink: list[np.ndarray] = []
    for (c, r), h, letter in zip(cells - lo, headings, program, strict=True):
        pts, flags = _tile_line(letter, cfg)
        ang = 0.5 * math.pi * h
        rot = np.array([[math.cos(ang), -math.sin(ang)], [math.sin(ang), math.cos(ang)]])
        world = pts @ rot.T + ((c + 0.5) * t, (r + 0.5) * t)
        points.append(world if not points else world[1:])  # the joint is shared
        ink.append(flags)
    segments = line_segments(np.vstack(points), np.concatenate(ink))
    length = float(segments[-1, 4] + segments[-1, 5])
    x1, y1 = (hi - lo) * t
    return Track(name, program, segments, cells - lo, (0.0, 0.0, float(x1), float(y1)), length)


def lay(spec: TrackSpec, keys: np.ndarray, cfg: Any) -> Track:
    """Lay ``spec``'s track for one lane whose track stream key is ``keys`` (shape (1,))."""
    layout = spec.fn(LaneRandom(keys, start=TRACK_DRAWS), cfg)
    if len(layout.program) > spec.tiles_for(cfg):
        raise ValueError(
            f"track {spec.name!r} laid {len(layout.program)} tiles, more than it registered "
            f"({spec.tiles_for(cfg)})"
        )
    return build_track(spec.name, layout, cfg)
