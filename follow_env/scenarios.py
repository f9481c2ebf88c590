"""Scenarios: where the robot starts and where people walk. Registered by name.

A scenario is one function decorated with :func:`register_scenario`. It receives a
:class:`~follow_env.rng.LaneRandom` (one random stream per lane being reset) and the
:class:`~follow_env.config.EnvConfig`, and returns a :class:`ScenarioBatch` for all those lanes
at once. Person 0 of each lane is the person to follow.

Built in:

* ``straight``: SPEC §1.6 condition 1. The person starts ``start_distance_m`` (1 m) in front
  of the camera, centred in the image, and walks ``walk_length_m`` (10 m) straight on.
* ``curve``: condition 2, the same start, then the whole walk is one arc turning
  ``curve_turn_deg`` (90 deg left: radius 6.4 m over 10 m). The thesis does not give its curve.
* ``random``: a smooth random walk through the room for ``random_duration_s``: legs of 2-6 m,
  each bending up to +-90 deg, at 0.6-1.4 x cruise pace, some ending in a 1-3 s stop, steering
  away from the walls.

In all of them the person's cruise pace is drawn per episode, uniform within
``cruise_speed_mps +- speed_spread_mps``, and slowed in bends to keep ``v^2 / R`` below
``lateral_accel_mps2``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from follow_env.layout import N_PW, PW_PAUSE, PW_S, PW_VMAX, PW_X, PW_Y
from follow_env.rng import LaneRandom, uniform_at
from follow_env.world import room_walls

if TYPE_CHECKING:
    from follow_env.config import EnvConfig

__all__ = ["SCENARIOS", "ScenarioBatch", "ScenarioSpec", "polyline_paths", "register_scenario"]

# Waypoint spacing used to draw curved paths (m).
_STEP_M = 0.25
# People keep this far from walls (m).
_WALL_MARGIN_M = 0.5


@dataclass
class ScenarioBatch:
    """Initial conditions for ``n`` lanes: robot pose, people's paths, walls."""

    robot_pose: np.ndarray  # (n, 3): x m, y m, heading rad
    paths: np.ndarray  # (n, people, points, N_PW), see follow_env.layout PW_*
    n_points: np.ndarray  # (n, people) int: waypoints used per path (>= 2)
    n_people: np.ndarray  # (n,) int: people present (>= 1; person 0 is the target)
    walls: np.ndarray  # (n, walls, 5): x1, y1, x2, y2, height m (follow_env.layout W_*)
    n_walls: np.ndarray  # (n,) int


ScenarioFn = Callable[[LaneRandom, "EnvConfig"], ScenarioBatch]


@dataclass(frozen=True)
class ScenarioSpec:
    """A registered scenario and the array sizes it needs."""

    name: str
    fn: ScenarioFn
    max_people: int
    max_points: int | Callable[[EnvConfig], int]
    max_walls: int

    def points_for(self, cfg: EnvConfig) -> int:
        """Waypoints a path may have under ``cfg`` (sizes the core's path arrays)."""
        return self.max_points(cfg) if callable(self.max_points) else self.max_points


SCENARIOS: dict[str, ScenarioSpec] = {}


def register_scenario(
    name: str,
    *,
    max_people: int = 1,
    max_points: int | Callable[[EnvConfig], int] = 64,
    max_walls: int = 4,
) -> Callable[[ScenarioFn], ScenarioFn]:
    """Register ``fn`` as scenario ``name``; the sizes bound what the function returns
    (``max_points`` may depend on the configuration)."""

    def deco(fn: ScenarioFn) -> ScenarioFn:
        if name in SCENARIOS:
            raise ValueError(f"scenario {name!r} is registered already")
        SCENARIOS[name] = ScenarioSpec(name, fn, max_people, max_points, max_walls)
        return fn

    return deco


def polyline_paths(
    points: np.ndarray, vmax: np.ndarray, pause: np.ndarray | None = None
) -> np.ndarray:
    """Paths for a batch of polylines: (n, m, 2) points and (n, m) leg speed caps (m/s) ->
    (n, m, N_PW) with the arc length to every waypoint filled in. ``pause`` (n, m) in s."""
    n, m, _ = points.shape
    out = np.zeros((n, m, N_PW))
    out[..., PW_X] = points[..., 0]
    out[..., PW_Y] = points[..., 1]
    seg = np.linalg.norm(np.diff(points, axis=1), axis=-1)
    out[:, 1:, PW_S] = np.cumsum(seg, axis=1)
    out[..., PW_VMAX] = vmax
    if pause is not None:
        out[..., PW_PAUSE] = pause
    return out


def _cruise(rng: LaneRandom, cfg: EnvConfig) -> np.ndarray:
    p = cfg.person
    return rng.uniform(
        low=p.cruise_speed_mps - p.speed_spread_mps, high=p.cruise_speed_mps + p.speed_spread_mps
    )


def _person_ahead(cfg: EnvConfig, pose: np.ndarray) -> np.ndarray:
    """Where the thesis puts the person: ``start_distance_m`` from the camera to the front of
    the body, on the camera's axis (centred in the image). ``pose`` (n, 3) -> (n, 2)."""
    c = cfg.camera
    ahead = c.mount_x_m + cfg.scenario.start_distance_m + 0.5 * cfg.person.depth_m
    cos, sin = np.cos(pose[:, 2]), np.sin(pose[:, 2])
    x = pose[:, 0] + ahead * cos - c.mount_y_m * sin
    y = pose[:, 1] + ahead * sin + c.mount_y_m * cos
    return np.stack([x, y], axis=-1)


def _room(cfg: EnvConfig, n: int) -> tuple[np.ndarray, np.ndarray]:
    walls = room_walls(cfg.scenario.room_length_m, cfg.scenario.room_width_m)
    return np.broadcast_to(walls, (n, *walls.shape)).copy(), np.full(n, len(walls))


def _check_inside(cfg: EnvConfig, points: np.ndarray, what: str) -> None:
    hx = 0.5 * cfg.scenario.room_length_m - _WALL_MARGIN_M
    hy = 0.5 * cfg.scenario.room_width_m - _WALL_MARGIN_M
    if np.any(np.abs(points[..., 0]) > hx) or np.any(np.abs(points[..., 1]) > hy):
        raise ValueError(
            f"ScenarioConfig: the {cfg.scenario.name!r} walk ({what}) does not fit in the room "
            f"of room_length_m={cfg.scenario.room_length_m} x "
            f"room_width_m={cfg.scenario.room_width_m} m; enlarge the room or shorten the walk"
        )


def _single(paths: np.ndarray, pose: np.ndarray, cfg: EnvConfig) -> ScenarioBatch:
    n, m = paths.shape[:2]
    walls, n_walls = _room(cfg, n)
    return ScenarioBatch(
        robot_pose=pose,
        paths=paths[:, None],
        n_points=np.full((n, 1), m),
        n_people=np.ones(n, dtype=np.int64),
        walls=walls,
        n_walls=n_walls,
    )


@register_scenario("straight", max_points=2)
def straight(rng: LaneRandom, cfg: EnvConfig) -> ScenarioBatch:
    """SPEC §1.6 condition 1: start 1 m ahead, centred; walk 10 m straight on."""
    n = rng.n
    length = cfg.scenario.walk_length_m
    pose = np.zeros((n, 3))
    pose[:, 0] = -0.5 * cfg.scenario.room_length_m + 2.0
    start = _person_ahead(cfg, pose)
    end = start + np.array([length, 0.0])
    points = np.stack([start, end], axis=1)
    _check_inside(cfg, points, f"walk_length_m={length}")
    vmax = np.repeat(_cruise(rng, cfg)[:, None], 2, axis=1)
    return _single(polyline_paths(points, vmax), pose, cfg)


def _arc_points(length: float, turn_rad: float) -> np.ndarray:
    """Points every ~_STEP_M along an arc of ``length`` turning ``turn_rad``, starting at the
    origin heading +x: (m, 2)."""
    m = max(2, math.ceil(length / _STEP_M) + 1)
    s = np.linspace(0.0, length, m)
    if abs(turn_rad) < 1e-9:
        return np.stack([s, np.zeros_like(s)], axis=-1)
    radius = length / turn_rad  # signed: left turns positive
    th = s / radius
    return np.stack([radius * np.sin(th), radius * (1.0 - np.cos(th))], axis=-1)


def _curve_points(cfg: EnvConfig) -> int:
    return max(2, math.ceil(cfg.scenario.walk_length_m / _STEP_M) + 1)


@register_scenario("curve", max_points=_curve_points)
def curve(rng: LaneRandom, cfg: EnvConfig) -> ScenarioBatch:
    """SPEC §1.6 condition 2: the thesis start, then one arc of ``curve_turn_deg``."""
    n = rng.n
    sc = cfg.scenario
    turn = math.radians(sc.curve_turn_deg)
    local = _arc_points(sc.walk_length_m, turn)
    pose = np.zeros((n, 3))
    pose[:, 0] = -0.5 * sc.room_length_m + 3.0
    pose[:, 1] = -math.copysign(0.5 * sc.room_width_m - 3.0, turn) if turn != 0 else 0.0
    start = _person_ahead(cfg, pose)
    points = start[:, None, :] + local[None, :, :]
    _check_inside(
        cfg, points, f"walk_length_m={sc.walk_length_m}, curve_turn_deg={sc.curve_turn_deg}"
    )
    cruise = _cruise(rng, cfg)
    v_bend = (
        math.inf
        if turn == 0
        else math.sqrt(cfg.person.lateral_accel_mps2 * sc.walk_length_m / abs(turn))
    )
    vmax = np.repeat(np.minimum(cruise, v_bend)[:, None], len(local), axis=1)
    return _single(polyline_paths(points, vmax), pose, cfg)


_RANDOM_MAX_POINTS = 256


@njit(cache=True)
def _random_walk(
    keys: np.ndarray,
    counter0: int,
    start: np.ndarray,
    heading: np.ndarray,
    cruise: np.ndarray,
    hx: float,
    hy: float,
    duration_s: float,
    stop_prob: float,
    lateral_accel: float,
    out: np.ndarray,
    n_points: np.ndarray,
) -> None:
    """Fill ``out`` (n, _RANDOM_MAX_POINTS, N_PW) with one random walk per lane."""
    step = 0.5
    for i in range(keys.shape[0]):
        c = counter0
        x, y, th = start[i, 0], start[i, 1], heading[i]
        s, t = 0.0, 0.0
        k = 0
        out[i, 0, PW_X], out[i, 0, PW_Y] = x, y
        leg = 0
        while k < _RANDOM_MAX_POINTS - 1 and t < duration_s:
            if leg == 0:  # first leg: 2 m straight on, at cruise pace, as in the thesis start
                length, turn, speed = 2.0, 0.0, cruise[i]
            else:
                length = 2.0 + 4.0 * uniform_at(keys[i], c)
                turn = (uniform_at(keys[i], c + 1) - 0.5) * np.pi
                speed = cruise[i] * (0.6 + 0.8 * uniform_at(keys[i], c + 2))
            stop_draw, pause_draw = uniform_at(keys[i], c + 3), uniform_at(keys[i], c + 4)
            c += 8
            m = max(1, int(length / step))
            dth = turn / m
            if turn != 0.0:
                speed = min(speed, np.sqrt(lateral_accel * length / abs(turn)))
            out[i, k, PW_VMAX] = speed
            for _ in range(m):
                if k >= _RANDOM_MAX_POINTS - 1:
                    break
                # Steer towards the middle of the room well before a wall: the robot behind
                # needs room to follow through the turn.
                nx, ny = x + 4.0 * step * np.cos(th + dth), y + 4.0 * step * np.sin(th + dth)
                if abs(nx) > hx - 2.0 or abs(ny) > hy - 2.0:
                    to_centre = np.arctan2(-y, -x)
                    err = (to_centre - th + np.pi) % (2.0 * np.pi) - np.pi
                    th += max(-0.15, min(0.15, err))
                    out[i, k, PW_VMAX] = min(
                        out[i, k, PW_VMAX], np.sqrt(lateral_accel * step / 0.15)
                    )
                else:
                    th += dth
                x += step * np.cos(th)
                y += step * np.sin(th)
                x, y = max(-hx + 1.0, min(hx - 1.0, x)), max(-hy + 1.0, min(hy - 1.0, y))
                k += 1
                s += step
                out[i, k, PW_X], out[i, k, PW_Y], out[i, k, PW_S] = x, y, s
                out[i, k, PW_VMAX] = speed
                t += step / speed
            if leg > 0 and stop_draw < stop_prob:
                pause = 1.0 + 2.0 * pause_draw
                out[i, k, PW_PAUSE] = pause
                t += pause
            leg += 1
        out[i, k, PW_PAUSE] = 0.0
        n_points[i] = k + 1


@register_scenario("random", max_points=_RANDOM_MAX_POINTS)
def random(rng: LaneRandom, cfg: EnvConfig) -> ScenarioBatch:
    """A smooth random walk with speed changes, stops and turns, inside the room."""
    n = rng.n
    sc = cfg.scenario
    hx = 0.5 * sc.room_length_m - _WALL_MARGIN_M
    hy = 0.5 * sc.room_width_m - _WALL_MARGIN_M
    pose = np.zeros((n, 3))
    # The robot starts somewhere it has room around it, facing anywhere.
    margin = min(3.0, 0.45 * min(sc.room_length_m, sc.room_width_m) - 0.5)
    pose[:, 0] = rng.uniform(low=-hx + margin, high=hx - margin)
    pose[:, 1] = rng.uniform(low=-hy + margin, high=hy - margin)
    pose[:, 2] = rng.uniform(low=-np.pi, high=np.pi)
    start = _person_ahead(cfg, pose)
    cruise = _cruise(rng, cfg)
    paths = np.zeros((n, _RANDOM_MAX_POINTS, N_PW))
    n_points = np.zeros(n, dtype=np.int64)
    counter0 = rng.reserve(8 * _RANDOM_MAX_POINTS)  # 8 draws a leg at most, <= 1 leg a point
    _random_walk(
        rng.keys,
        counter0,
        start,
        pose[:, 2].copy(),
        cruise,
        hx,
        hy,
        sc.random_duration_s,
        sc.stop_prob,
        cfg.person.lateral_accel_mps2,
        paths,
        n_points,
    )
    walls, n_walls = _room(cfg, n)
    return ScenarioBatch(
        robot_pose=pose,
        paths=paths[:, None],
        n_points=n_points[:, None],
        n_people=np.ones(n, dtype=np.int64),
        walls=walls,
        n_walls=n_walls,
    )


# The realistic-world scenarios register themselves on import (they build on the helpers above).
import follow_env.world_scenarios  # noqa: E402, F401
