"""LineTrace as the runner sees it: its blocks, world arrays, resets, observations and info.

The compiled part is in :mod:`.kernel` (with the sensor grid of
:mod:`follow_env.sensors.light_grid` and :mod:`.reward`); this module is the numpy side: the
task's parameter and state blocks, the per-lane world (the line's segments), what a reset does
before the kernel runs (lay the track, place the robot, draw the sensors' randomisation), and
how observations and the ``info`` dict are read from the state.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, NamedTuple

import numpy as np
from gymnasium import spaces

from follow_env.platforms.base import Platform, PlatformConfig
from follow_env.sensors import light_grid
from follow_env.sim import streams
from follow_env.sim.rng import LaneRandom
from follow_env.sim.runner import BatchedSim
from follow_env.sim.schema import Block, f8, float_column, i8, nested
from follow_env.tasks.config import TaskPlatforms, resolve_config, section_or_name
from follow_env.tasks.line_trace import reward
from follow_env.tasks.line_trace.config import PAPER, PRESETS, LineTraceConfig, TrackConfig
from follow_env.tasks.line_trace.spec import N_CELLS, SPEC
from follow_env.tasks.line_trace.tracks import Track, TrackSpec, get_track, lay
from follow_env.world.floor_line import LINE_SEGMENT, SEG

__all__ = ["PARAMS", "STATE", "TASK", "LineTraceTask", "batched_sim"]

WINDOW_BACK_M = 0.10
"""Progress is searched this far behind the last point (m; choice: more than a step's travel)."""
WINDOW_AHEAD_M = 0.20
"""... and this far ahead (m; choice: a corner cut short, but not the next zigzag tooth)."""

PARAMS = Block(
    "line_trace_params",
    "the sensor grid, the reward, the line and the episode",
    [
        nested("sensor", light_grid.PARAMS),
        nested("reward", reward.PARAMS),
        f8("dt", "s", "control period", source="episode.control_dt_s"),
        f8("max_steps", "steps", "episode step cap", source=lambda c: c.max_steps),
        f8("lost_timeout", "s", "lost after this long", source="episode.lost_timeout_s"),
        f8(
            "finish_margin",
            "m",
            "the end is this short of the last point",
            source="episode.finish_margin_m",
        ),
        f8("field_margin", "m", "the field's tolerance", source="episode.field_margin_m"),
        f8("half_w", "m", "half the line's width", source=lambda c: 0.5 * c.track.line_width_m),
        f8("window_back", "m", "progress window behind", source=lambda c: WINDOW_BACK_M),
        f8("window_ahead", "m", "progress window ahead", source=lambda c: WINDOW_AHEAD_M),
    ],
)

STATE = Block(
    "line_trace_state",
    "what the grid reads, where the robot is along the line, the line and the field in use",
    [
        nested("grid", light_grid.STATE),
        i8("n_seg", "", "segments of the lane's line"),
        i8("seg_i", "", "the segment of the line point nearest the robot"),
        f8("length", "m", "the line's length"),
        f8("x0", "m", "field corner, x"),
        f8("y0", "m", "field corner, y"),
        f8("x1", "m", "opposite field corner, x"),
        f8("y1", "m", "opposite field corner, y"),
        f8("s", "m", "progress: arc length of the line point nearest the robot"),
        f8("cte", "m", "signed cross-track error (> 0: robot left of the line)"),
        f8("head_err", "rad", "heading error against the line's direction"),
        f8("in_gap", "", "1: the nearest line point lies in a gap"),
        f8("lost_t", "s", "time no spot has overlapped the line"),
        f8("prev_v", "m/s", "forward speed a step ago"),
        f8("prev_vy", "m/s", "sideways speed a step ago"),
        f8("prev_w", "rad/s", "turn rate a step ago"),
        f8(
            "reward_terms",
            "",
            "this step's reward terms (reward.TERMS)",
            shape=(len(reward.TERMS),),
        ),
    ],
)

START = streams.per_episode(
    "track.start",
    streams.TRACK,
    0,
    2,
    space="normal",
    doc="the start's sideways offset and heading error",
)

# info keys read from a float state field, by path into a lane's state record.
_FLOAT_INFO: dict[str, tuple[str, ...]] = {
    "time_s": ("episode", "t"),
    "robot_x_m": ("body", "x"),
    "robot_y_m": ("body", "y"),
    "robot_theta_rad": ("body", "th"),
    "robot_v_mps": ("body", "v"),
    "robot_vy_mps": ("body", "vy"),
    "robot_w_radps": ("body", "w"),
    "encoder_speed_mps": ("body", "v_meas"),
    "accel_mps2": ("body", "accel"),
    "progress_m": ("task", "s"),
    "track_length_m": ("task", "length"),
    "cross_track_m": ("task", "cte"),
    "heading_error_rad": ("task", "head_err"),
    "lost_s": ("task", "lost_t"),
}
_FLAG_INFO: dict[str, tuple[str, ...]] = {
    "in_gap": ("task", "in_gap"),
    "line_seen": ("task", "grid", "seen"),
}
_REASONS = np.array(SPEC.terminations, dtype=object)


class _Columns(NamedTuple):
    names: tuple[str, ...]  # the float keys, in the info dict's order
    cols: np.ndarray  # their words, then the flags', then active_cells'
    n_float: int
    flags: tuple[str, ...]
    ints: np.ndarray  # step, reason
    obs: int  # the first observation word


def _int_column(dtype: np.dtype, path: tuple[str, ...]) -> int:
    offset, current = 0, dtype
    for name in path:
        current, off = current.fields[name][:2]
        offset += off
    if current != np.dtype(np.int64) or offset % 8:
        raise ValueError(f"{'.'.join(path)} is not an int64 field on an 8-byte boundary")
    return offset // 8


class LineTraceTask(TaskPlatforms):
    """The line-tracing task (reference §2) for the runner and the env faces."""

    name = SPEC.name
    spec = SPEC
    kernel_module = "follow_env.tasks.line_trace.kernel"
    params = PARAMS
    state = STATE
    config_class = LineTraceConfig
    presets = PRESETS
    default_config = PAPER
    variant_key = "track"

    def __init__(self) -> None:
        self._fixed: dict[tuple[str, Any], Track] = {}
        self._columns_by_layout: dict[tuple[Any, ...], _Columns] = {}

    # -- configuration -------------------------------------------------------------------------

    def resolve_config(
        self,
        config: LineTraceConfig | str | dict[str, Any] | None = None,
        track: str | TrackConfig | Mapping[str, Any] | None = None,
        platform: str | PlatformConfig | Mapping[str, Any] | None = None,
        **overrides: Any,
    ) -> LineTraceConfig:
        """Build a :class:`LineTraceConfig` from ``gym.make`` keyword arguments.

        :param config: a preset name (``"paper"``, ``"ideal"``, ``"noisy"``), a
            ``LineTraceConfig``, or a mapping of section overrides applied to ``paper``.
        :param track: a track name (shorthand for ``track={"name": ...}``), or the
            ``track`` section itself (a ``TrackConfig`` or a mapping of its fields).
        :param platform: a platform name (its default configuration), a platform config,
            or a mapping ``{"name": ..., <section>: {...}}``.
        :param overrides: sections (``sensor={...}``) or ``section__field=value`` pairs.
        """
        return resolve_config(
            LineTraceConfig,
            PRESETS,
            PAPER,
            config,
            platform,
            shorthands=section_or_name("track", track),
            overrides=overrides,
        )

    def spaces(self, cfg: LineTraceConfig, platform: Platform) -> tuple[spaces.Box, spaces.Box]:
        """``(observation_space, action_space)``, float32: the 25 readings in [0, 1] and the
        platform's action, bounded by what it can do."""
        observation = spaces.Box(0.0, 1.0, shape=(N_CELLS,), dtype=np.float32)
        return observation, self.action_space(cfg, platform)

    def variants(self) -> list[str]:
        """The registered tracks (``variant_key`` is their ``gym.make`` keyword)."""
        from follow_env.tasks.line_trace.tracks import TRACKS

        return sorted(TRACKS)

    def renderer(self, cfg: LineTraceConfig) -> Any:
        """A renderer of this task's frames (OpenCV, headless)."""
        from follow_env.tasks.line_trace.render import Renderer

        return Renderer(cfg)

    def track_spec(self, cfg: LineTraceConfig) -> TrackSpec:
        """The configured track (``ValueError`` naming the field when unknown)."""
        return get_track(cfg.track.name)

    def fixed_track(self, cfg: LineTraceConfig) -> Track | None:
        """The configured track laid, when it is a fixed one (laid once per track section)."""
        spec = self.track_spec(cfg)
        if spec.random:
            return None
        key = (spec.name, cfg.track)
        if key not in self._fixed:
            self._fixed[key] = lay(spec, np.zeros(1, dtype=np.uint64), cfg)
        return self._fixed[key]

    def check(self, cfg: LineTraceConfig) -> None:
        """Refuse an unknown track, and a start beyond a fixed track's end or beyond the end of
        the shortest track a random one may lay (when it says how short that is)."""
        track = self.fixed_track(cfg)
        if track is not None:
            _check_start(cfg, track.length_m, f"the {track.name!r} track's length")
            return
        spec = self.track_spec(cfg)
        if spec.shortest is not None:
            shortest = spec.shortest(cfg)
            _check_start(cfg, shortest, f"the shortest {spec.name!r} track's length")

    # -- the runner's side -----------------------------------------------------------------------

    def world(self, cfg: LineTraceConfig, num_lanes: int) -> tuple[np.ndarray, ...]:
        """``(segments,)``: the line of every lane, sized by the track."""
        return (LINE_SEGMENT.zeros(num_lanes, self.track_spec(cfg).segments_for(cfg)),)

    def lay_lanes(self, cfg: LineTraceConfig, keys: np.ndarray) -> list[Track]:
        """The track of each lane starting an episode with these keys ``(n, N_STREAMS)``."""
        fixed = self.fixed_track(cfg)
        if fixed is not None:
            return [fixed] * len(keys)
        spec = self.track_spec(cfg)
        return [lay(spec, keys[k : k + 1, streams.TRACK.index], cfg) for k in range(len(keys))]

    def prepare_reset(self, sim: BatchedSim, lanes: np.ndarray, keys: np.ndarray) -> np.ndarray:
        """Lay the lanes' tracks and write their lines and fields, draw the sensors'
        randomisation; return the robots' start poses: on the line ``start.distance_m`` from
        its start, facing along it, off by the drawn sideways offset and heading error."""
        cfg = sim.cfg
        tracks = self.lay_lanes(cfg, keys)
        (segs,) = sim.world
        flat = segs.view(np.float64).reshape(*segs.shape, -1)
        ts = sim.state["task"]
        z = LaneRandom(keys[:, streams.TRACK.index]).normal(2, at=START)
        sc = cfg.start
        pose = np.zeros((len(lanes), 3))
        for k, (lane, track) in enumerate(zip(lanes, tracks, strict=True)):
            n = len(track.segments)
            if n > segs.shape[1]:
                raise ValueError(
                    f"track {track.name!r} has {n} segments, more than it registered "
                    f"({segs.shape[1]})"
                )
            # A random track too short for the start (one registered without `shortest`).
            _check_start(cfg, track.length_m, f"the length of the {track.name!r} track laid")
            flat[lane] = 0.0
            flat[lane, :n] = track.segments
            ts["n_seg"][lane] = n
            ts["length"][lane] = track.length_m
            ts["x0"][lane], ts["y0"][lane], ts["x1"][lane], ts["y1"][lane] = track.field
            ts["s"][lane] = sc.distance_m
            x, y, th = point_along(track.segments, sc.distance_m)
            off = sc.lateral_spread_m * z[k, 0]
            pose[k] = (
                x - off * math.sin(th),
                y + off * math.cos(th),
                th + math.radians(sc.heading_spread_deg) * z[k, 1],
            )
        light_grid.randomize(sim.params["task"]["sensor"], lanes, cfg, keys)
        return pose

    # -- what the env faces read ---------------------------------------------------------------

    def _columns(self, sim: BatchedSim) -> _Columns:
        columns = sim.__dict__.get("_line_columns")
        if columns is not None:
            return columns
        key = (sim.state_dtype, sim.platform.name)
        columns = self._columns_by_layout.get(key)
        if columns is None:
            dtype = sim.state_dtype
            names: list[str] = []
            cols: list[int] = []
            platform = {e[0]: e for e in sim.platform.info}
            for name in self.info_keys(sim.platform):
                if name in _FLOAT_INFO:
                    names.append(name)
                    cols.append(float_column(dtype, _FLOAT_INFO[name]))
                elif name in platform:
                    entry = platform[name]
                    names.append(name)
                    cols.append(float_column(dtype, ("platform", entry[1]), entry[2] or 0))
            flags = [float_column(dtype, path) for path in _FLAG_INFO.values()]
            active = float_column(dtype, ("task", "grid", "active"))
            ints = [_int_column(dtype, ("episode", f)) for f in ("step", "reason")]
            obs = float_column(dtype, ("task", "grid", "reading"))
            columns = _Columns(
                tuple(names),
                np.array([*cols, *flags, active]),
                len(names),
                tuple(_FLAG_INFO),
                np.array(ints),
                obs,
            )
            self._columns_by_layout[key] = columns
        sim.__dict__["_line_columns"] = columns
        return columns

    def observations(self, sim: BatchedSim) -> np.ndarray:
        """The readings of every lane, ``(N, 25)`` float32."""
        c = self._columns(sim)
        return sim.state_words[:, c.obs : c.obs + N_CELLS].astype(np.float32)

    def observation(self, sim: BatchedSim, lane: int) -> np.ndarray:
        """The readings of one lane, ``(25,)`` float32."""
        c = self._columns(sim)
        return sim.state_words[lane, c.obs : c.obs + N_CELLS].astype(np.float32)

    def lane_info(self, sim: BatchedSim, lane: int) -> dict[str, Any]:
        """The ``info`` dict of one lane, as Python scalars, in :meth:`info_keys` order."""
        c = self._columns(sim)
        values = sim.state_words[lane][c.cols].tolist()
        step, reason = sim.state_ints[lane][c.ints].tolist()
        out = dict(zip(c.names, values[: c.n_float], strict=True))
        for k, flag in enumerate(c.flags):
            out[flag] = values[c.n_float + k] > 0.0
        out["active_cells"] = int(values[-1])
        out["step"] = step
        out["termination"] = SPEC.terminations[reason]
        return {key: out[key] for key in self.info_keys(sim.platform)}

    def batch_info(self, sim: BatchedSim, lanes: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """The ``info`` of many lanes as Gymnasium's dict of arrays (all lanes, or those in
        ``lanes``), without the ``_key`` masks."""
        c = self._columns(sim)
        sel = slice(None) if lanes is None else lanes
        floats = sim.state_words[sel].T[c.cols]
        out: dict[str, Any] = dict(zip(c.names, floats[: c.n_float], strict=True))
        for k, flag in enumerate(c.flags):
            out[flag] = floats[c.n_float + k] > 0.0
        out["active_cells"] = floats[-1].astype(np.int64)
        step, reason = sim.state_ints[sel].T[c.ints]
        out["step"] = step
        out["termination"] = _REASONS[reason]
        return {key: out[key] for key in self.info_keys(sim.platform)}

    def termination(self, sim: BatchedSim, lane: int) -> str:
        """Why lane ``lane``'s episode ended (``""`` while it runs)."""
        return SPEC.terminations[int(sim.episode["reason"][lane])]


def _check_start(cfg: LineTraceConfig, length_m: float, what: str) -> None:
    """``ValueError`` naming ``start.distance_m`` unless the start lies before the end of a line
    ``length_m`` long (less ``finish_margin_m``, where the episode would end at once)."""
    end = length_m - cfg.episode.finish_margin_m
    if cfg.start.distance_m >= end:
        raise ValueError(
            f"StartConfig.distance_m={cfg.start.distance_m!r} is out of range: must be < {what} "
            f"less finish_margin_m ({length_m:.3f} - {cfg.episode.finish_margin_m:g} = "
            f"{end:.3f} m)"
        )


def point_along(segments: np.ndarray, s_m: float) -> tuple[float, float, float]:
    """``(x, y, direction)`` of the line ``segments`` (float array) ``s_m`` along it."""
    k = int(np.searchsorted(segments[:, SEG.s], s_m, side="right")) - 1
    k = min(max(k, 0), len(segments) - 1)
    seg = segments[k]
    t = min(max((s_m - seg[SEG.s]) / seg[SEG.length], 0.0), 1.0)
    dx, dy = seg[SEG.x2] - seg[SEG.x1], seg[SEG.y2] - seg[SEG.y1]
    return seg[SEG.x1] + t * dx, seg[SEG.y1] + t * dy, math.atan2(dy, dx)


TASK = LineTraceTask()
"""The task model the env faces use."""


def batched_sim(cfg: LineTraceConfig, num_lanes: int) -> BatchedSim:
    """A runner of ``num_lanes`` line-tracing lanes under ``cfg`` (for tools and tests)."""
    return BatchedSim(TASK, cfg, num_lanes)
