"""Tracks: the course the line runs on, registered by name like PersonFollow's scenarios.

A track is one function decorated with :func:`register_track` that returns a
:class:`TrackLayout`: a tile program, one letter per 30 cm tile (``S`` straight, ``G`` gap,
``Z`` zigzag, ``L``/``R`` 90 deg corners, ``l``/``r`` curves; :mod:`.registry` has the table).
It receives a :class:`~follow_env.sim.rng.LaneRandom` of one lane (the episode's track stream)
and the configuration; a track registered with ``random=True`` is laid anew every episode,
any other once. Built in (:mod:`.builtin`): ``straight``, ``corners``, ``curves``, ``zigzag``,
``gaps``, ``course`` and ``random``.

A track of your own::

    from follow_env.tasks.line_trace.tracks import TrackLayout, register_track

    @register_track("hook", max_tiles=5)
    def hook(rng, cfg):
        return TrackLayout("SSlGr")

    env = gym.make("LineTrace-v0", track="hook")
"""

from follow_env.tasks.line_trace.tracks import builtin  # noqa: F401  (registers)
from follow_env.tasks.line_trace.tracks.registry import (
    TILE_LETTERS,
    TRACK_DRAWS,
    TRACKS,
    Track,
    TrackLayout,
    TrackSpec,
    build_track,
    get_track,
    lay,
    register_track,
    tile_cells,
    tile_length,
)

__all__ = [
    "TILE_LETTERS",
    "TRACKS",
    "TRACK_DRAWS",
    "Track",
    "TrackLayout",
    "TrackSpec",
    "build_track",
    "get_track",
    "lay",
    "register_track",
    "tile_cells",
    "tile_length",
]
