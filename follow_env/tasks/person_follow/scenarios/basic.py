"""The reference experiment's walks (reference §1.6) and a random walk.

* ``straight``: condition 1. The person starts ``start_distance_m`` (1 m) in front of the
  camera, centred in the image, and walks ``walk_length_m`` (10 m) straight on.
* ``curve``: condition 2, the same start, then the whole walk is one arc turning
  ``curve_turn_deg`` (90 deg left: radius 6.4 m over 10 m). The thesis does not give its curve.
* ``random``: a smooth random walk through the hall for ``random_duration_s``: legs of 2-6 m,
  each bending up to +-90 deg, at 0.6-1.4 x cruise pace, some ending in a 1-3 s stop, steering
  away from the walls.

All three take the hall's size from ``scenario.room_length_m`` / ``room_width_m`` (24 x 16 m).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from follow_env.sim.jit import njit
from follow_env.sim.rng import uniform_at
from follow_env.tasks.person_follow.people import N_PW
from follow_env.tasks.person_follow.scenarios.registry import (
    PW,
    WALL_MARGIN_M,
    ScenarioBatch,
    ScenarioRandom,
    check_inside,
    cruise_speeds,
    person_ahead,
    polyline_paths,
    register_scenario,
    room,
    room_size,
    single_person,
)

if TYPE_CHECKING:
    from follow_env.tasks.person_follow.config import EnvConfig

# Waypoint spacing used to draw curved paths (m).
_STEP_M = 0.25
# Columns of the waypoint fields, as compile-time constants for the random walk.
_PW_X, _PW_Y, _PW_S, _PW_VMAX, _PW_PAUSE = PW.x, PW.y, PW.s, PW.vmax, PW.pause


@register_scenario("straight", max_points=2)
def straight(rng: ScenarioRandom, cfg: EnvConfig) -> ScenarioBatch:
    """reference §1.6 condition 1: start 1 m ahead, centred; walk 10 m straight on."""
    n = rng.n
    length = cfg.scenario.walk_length_m
    pose = np.zeros((n, 3))
    pose[:, 0] = -0.5 * room_size(cfg)[0] + 2.0
    start = person_ahead(cfg, pose)
    end = start + np.array([length, 0.0])
    points = np.stack([start, end], axis=1)
    check_inside(cfg, points, f"walk_length_m={length}")
    vmax = np.repeat(cruise_speeds(rng, cfg)[:, None], 2, axis=1)
    return single_person(polyline_paths(points, vmax), pose, cfg)


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
def curve(rng: ScenarioRandom, cfg: EnvConfig) -> ScenarioBatch:
    """reference §1.6 condition 2: the thesis start, then one arc of ``curve_turn_deg``."""
    n = rng.n
    sc = cfg.scenario
    turn = math.radians(sc.curve_turn_deg)
    local = _arc_points(sc.walk_length_m, turn)
    pose = np.zeros((n, 3))
    length, width = room_size(cfg)
    pose[:, 0] = -0.5 * length + 3.0
    pose[:, 1] = -math.copysign(0.5 * width - 3.0, turn) if turn != 0 else 0.0
    start = person_ahead(cfg, pose)
    points = start[:, None, :] + local[None, :, :]
    check_inside(
        cfg, points, f"walk_length_m={sc.walk_length_m}, curve_turn_deg={sc.curve_turn_deg}"
    )
    cruise = cruise_speeds(rng, cfg)
    v_bend = (
        math.inf
        if turn == 0
        else math.sqrt(cfg.person.lateral_accel_mps2 * sc.walk_length_m / abs(turn))
    )
    vmax = np.repeat(np.minimum(cruise, v_bend)[:, None], len(local), axis=1)
    return single_person(polyline_paths(points, vmax), pose, cfg)


_RANDOM_MAX_POINTS = 256


@njit
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
        out[i, 0, _PW_X], out[i, 0, _PW_Y] = x, y
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
            out[i, k, _PW_VMAX] = speed
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
                    out[i, k, _PW_VMAX] = min(
                        out[i, k, _PW_VMAX], np.sqrt(lateral_accel * step / 0.15)
                    )
                else:
                    th += dth
                x += step * np.cos(th)
                y += step * np.sin(th)
                x, y = max(-hx + 1.0, min(hx - 1.0, x)), max(-hy + 1.0, min(hy - 1.0, y))
                k += 1
                s += step
                out[i, k, _PW_X], out[i, k, _PW_Y], out[i, k, _PW_S] = x, y, s
                out[i, k, _PW_VMAX] = speed
                t += step / speed
            if leg > 0 and stop_draw < stop_prob:
                pause = 1.0 + 2.0 * pause_draw
                out[i, k, _PW_PAUSE] = pause
                t += pause
            leg += 1
        out[i, k, _PW_PAUSE] = 0.0
        n_points[i] = k + 1


@register_scenario("random", max_points=_RANDOM_MAX_POINTS)
def random(rng: ScenarioRandom, cfg: EnvConfig) -> ScenarioBatch:
    """A smooth random walk with speed changes, stops and turns, inside the room."""
    n = rng.n
    sc = cfg.scenario
    length, width = room_size(cfg)
    hx = 0.5 * length - WALL_MARGIN_M
    hy = 0.5 * width - WALL_MARGIN_M
    pose = np.zeros((n, 3))
    # The robot starts somewhere it has room around it, facing anywhere.
    margin = min(3.0, 0.45 * min(length, width) - 0.5)
    pose[:, 0] = rng.uniform(low=-hx + margin, high=hx - margin)
    pose[:, 1] = rng.uniform(low=-hy + margin, high=hy - margin)
    pose[:, 2] = rng.uniform(low=-np.pi, high=np.pi)
    start = person_ahead(cfg, pose)
    cruise = cruise_speeds(rng, cfg)
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
    walls, n_walls = room(cfg, n)
    return ScenarioBatch(
        robot_pose=pose,
        paths=paths[:, None],
        n_points=n_points[:, None],
        n_people=np.ones(n, dtype=np.int64),
        walls=walls,
        n_walls=n_walls,
    )
