"""Scenarios of a realistic world: corridors, doorways, pillars, bystanders, stops and zigzags.

The reference experiment (reference §1.6) had one person walking 10 m in an empty space; these
scenarios add what real corridors have: walls and obstacles that hide the person, a doorway to
drive through, bystanders who cross in front and can steal the target (the robot follows the
first detection, reference §1.4), stops and sharp turns. Every one starts as the thesis does: the
robot at rest, the person 1 m in front of the camera and centred.

Each lane's layout comes from its own streams (the person's for the target's pace and path,
``rng.world`` for the map and bystanders), never from the robot's actions.

| name | what happens |
|---|---|
| ``corridor_turn`` | a 2.4 m wide L-shaped corridor; the person turns the corner, out of sight |
| ``doorway`` | two rooms joined by a 1 m door; the person walks through it and on |
| ``occlusion`` | the person walks round the robot and behind a column, which hides them |
| ``crossing`` | a bystander crosses between the robot and the person |
| ``crowd`` | four bystanders criss-cross the hall while the person walks about |
| ``stop_and_go`` | 14 m with a stop (1-3 s) every 2-3 m and changes of pace |
| ``zigzag`` | 12 m of 2 m legs turning +-60 deg, corners rounded to 0.6 m |
| ``random_world`` | a random map per seed; paths planned through it (T-RRT, reference §3) |
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from follow_env.sim import streams
from follow_env.sim.rng import LaneRandom
from follow_env.tasks.person_follow.people import N_PW
from follow_env.tasks.person_follow.scenarios.registry import (
    PW,
    SCENARIOS,
    ScenarioBatch,
    ScenarioRandom,
    cruise_speeds,
    pack_lanes,
    person_ahead,
    polyline_paths,
    register_scenario,
    room_size,
)
from follow_env.world.geometry import WALL_HEIGHT_M, box_walls, polygon_walls, room_walls

if TYPE_CHECKING:
    from follow_env.tasks.person_follow.config import EnvConfig

__all__ = ["smooth_path"]

# Keys of the scenarios whose maps and bystanders were drawn from the person's stream with a
# fixed twist before the world stream existed; declared in the randomness table so that their
# recorded episodes stay the same.
CROSSING_KEY = streams.domain(
    "scenario.crossing", streams.PERSON, 0x5151, "crossing: the bystander's draws"
)
CROWD_KEY = streams.domain("scenario.crowd", streams.PERSON, 0xC40D, "crowd: the bystanders' draws")
RANDOM_WORLD_KEY = streams.domain(
    "scenario.random_world", streams.PERSON, 0x3D3D, "random_world: the map and bystanders"
)
for _key in (CROSSING_KEY, CROWD_KEY, RANDOM_WORLD_KEY):
    streams.per_episode(f"{_key.name}.draws", _key, 0, None, doc=_key.doc)

_STEP_M = 0.25  # waypoint spacing along bends (m)
_FURNITURE_HEIGHT_M = 0.9  # tables and cabinets: they hide legs, not heads (m)


def smooth_path(
    corners: np.ndarray,
    cruise_mps: float,
    lateral_accel_mps2: float,
    corner_radius_m: float = 0.8,
    pauses: dict[int, float] | None = None,
    speeds: dict[int, float] | None = None,
) -> np.ndarray:
    """A walkable path through ``corners`` (m, 2): straight legs joined by arcs of
    ``corner_radius_m`` (smaller where legs are short), sampled every ``_STEP_M`` on the arcs.

    Speed caps: ``cruise_mps`` (or ``speeds[i]`` on the leg from corner i), and in arcs at most
    ``sqrt(lateral_accel R)``. ``pauses[i]`` stands still for that long at corner i (0 is the
    start: a delayed start). Returns (m, N_PW) waypoints.
    """
    corners = np.asarray(corners, dtype=float)
    pauses = pauses or {}
    speeds = speeds or {}
    pts: list[tuple[float, float]] = [tuple(corners[0])]
    caps: list[float] = [speeds.get(0, cruise_mps)]
    stops: list[float] = [pauses.get(0, 0.0)]
    for i in range(1, len(corners) - 1):
        a, b, c = corners[i - 1], corners[i], corners[i + 1]
        leg = speeds.get(i - 1, cruise_mps)
        d_in, d_out = b - a, c - b
        l_in, l_out = np.linalg.norm(d_in), np.linalg.norm(d_out)
        u_in, u_out = d_in / l_in, d_out / l_out
        turn = math.atan2(u_in[0] * u_out[1] - u_in[1] * u_out[0], float(u_in @ u_out))
        if i in pauses or abs(turn) < 1e-3:
            pts.append(tuple(b))
            caps.append(speeds.get(i, cruise_mps))
            stops.append(pauses.get(i, 0.0))
            continue
        # Tangent length of the arc, limited to less than half of either leg.
        r = corner_radius_m
        tan_len = min(r * math.tan(abs(turn) / 2.0), 0.45 * l_in, 0.45 * l_out)
        r = tan_len / math.tan(abs(turn) / 2.0)
        p_in = b - u_in * tan_len
        n_arc = max(2, math.ceil(r * abs(turn) / _STEP_M))
        normal = np.array([-u_in[1], u_in[0]]) * math.copysign(1.0, turn)
        centre = p_in + normal * r
        start_ang = math.atan2(p_in[1] - centre[1], p_in[0] - centre[0])
        v_arc = min(leg, math.sqrt(lateral_accel_mps2 * r))
        for k in range(n_arc + 1):
            ang = start_ang + turn * k / n_arc
            pts.append((centre[0] + r * math.cos(ang), centre[1] + r * math.sin(ang)))
            caps.append(v_arc if k < n_arc else speeds.get(i, cruise_mps))
            stops.append(0.0)
    pts.append(tuple(corners[-1]))
    caps.append(0.0)
    stops.append(0.0)
    xy = np.array(pts)
    keep = np.r_[True, np.linalg.norm(np.diff(xy, axis=0), axis=1) > 1e-6]
    xy, caps_a, stops_a = xy[keep], np.array(caps)[keep], np.array(stops)[keep]
    out = np.zeros((len(xy), N_PW))
    out[:, PW.x], out[:, PW.y] = xy[:, 0], xy[:, 1]
    out[1:, PW.s] = np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))
    out[:, PW.vmax] = caps_a
    out[:, PW.pause] = stops_a
    return out


def _start(cfg: EnvConfig, x: float, y: float, heading: float) -> tuple[np.ndarray, np.ndarray]:
    """Robot pose and the person's start 1 m in front of its camera (reference §1.6)."""
    pose = np.array([[x, y, heading]])
    return pose[0], person_ahead(cfg, pose)[0]


def _lat(cfg: EnvConfig) -> float:
    return cfg.person.lateral_accel_mps2


@register_scenario("corridor_turn", max_points=128, max_walls=8, room=None)
def corridor_turn(rng: ScenarioRandom, cfg: EnvConfig) -> ScenarioBatch:
    """An L-shaped corridor 2.4 m wide: 8 m along x, a left turn, 8 m along y."""
    cruise = cruise_speeds(rng, cfg)
    shift = rng.uniform(low=-0.3, high=0.3)  # where in the corridor the person walks
    half = 1.2
    outer = [(-11.0, -half), (half, -half), (half, 9.0)]
    inner = [(-11.0, half), (-half, half), (-half, 9.0)]
    walls = np.vstack(
        [
            polygon_walls(outer, WALL_HEIGHT_M)[:-1],
            polygon_walls(inner, WALL_HEIGHT_M)[:-1],
            [[-11.0, -half, -11.0, half, WALL_HEIGHT_M], [-half, 9.0, half, 9.0, WALL_HEIGHT_M]],
        ]
    )
    poses, people = [], []
    for i in range(rng.n):
        pose, p0 = _start(cfg, -9.5, 0.0, 0.0)
        corners = np.array([p0, (shift[i], 0.0), (shift[i], 8.0)])
        poses.append(pose)
        people.append([smooth_path(corners, cruise[i], _lat(cfg), corner_radius_m=0.9)])
    return pack_lanes(np.array(poses), people, [walls] * rng.n)


@register_scenario("doorway", max_points=128, max_walls=12, room=None)
def doorway(rng: ScenarioRandom, cfg: EnvConfig) -> ScenarioBatch:
    """Two 9 x 10 m rooms joined by a 1 m door; the person walks through and turns away."""
    cruise = cruise_speeds(rng, cfg)
    side = np.where(rng.uniform() < 0.5, -1.0, 1.0)
    door = 0.5
    walls = np.vstack(
        [
            room_walls(18.0, 10.0),
            [[0.0, -5.0, 0.0, -door, WALL_HEIGHT_M], [0.0, door, 0.0, 5.0, WALL_HEIGHT_M]],
        ]
    )
    poses, people = [], []
    for i in range(rng.n):
        pose, p0 = _start(cfg, -7.0, 0.0, 0.0)
        corners = np.array([p0, (1.5, 0.0), (5.0, 3.0 * side[i])])
        poses.append(pose)
        people.append([smooth_path(corners, cruise[i], _lat(cfg), corner_radius_m=1.5)])
    return pack_lanes(np.array(poses), people, [walls] * rng.n)


@register_scenario("occlusion", max_points=128, max_walls=8, room=(16.0, 12.0))
def occlusion(rng: ScenarioRandom, cfg: EnvConfig) -> ScenarioBatch:
    """The person walks round the robot at arm's length (an arc of ~1.45 m radius about the
    robot's start) and passes behind a slim column standing 0.8 m from the robot, which hides
    them for a moment; then they walk off. A follower that keeps its distance mostly turns on
    the spot here, so the column hides the person without standing in the robot's way."""
    cruise = cruise_speeds(rng, cfg)
    side = np.where(rng.uniform() < 0.5, -1.0, 1.0)  # round to the left or the right
    where = rng.uniform(low=math.radians(55.0), high=math.radians(80.0))
    walls_all, poses, people = [], [], []
    for i in range(rng.n):
        pose, p0 = _start(cfg, -4.0, 0.0, 0.0)
        cx, cy = pose[0], pose[1]
        radius = float(np.hypot(p0[0] - cx, p0[1] - cy))
        ang = side[i] * where[i]
        column = (cx + 0.8 * math.cos(ang), cy + 0.8 * math.sin(ang))
        walls_all.append(
            np.vstack(
                [room_walls(*room_size(cfg)), box_walls(*column, 0.3, 0.3, 0.0, WALL_HEIGHT_M)]
            )
        )
        arc = np.linspace(0.0, side[i] * math.radians(150.0), 40)
        pts = np.column_stack([cx + radius * np.cos(arc), cy + radius * np.sin(arc)])
        heading = arc[-1] + side[i] * 0.5 * math.pi
        away = pts[-1] + 4.0 * np.array([math.cos(heading), math.sin(heading)])
        corners = np.vstack([pts, away])
        poses.append(pose)
        people.append([smooth_path(corners, 0.8 * cruise[i], _lat(cfg), corner_radius_m=0.5)])
    return pack_lanes(np.array(poses), people, walls_all)


@register_scenario(
    "crossing", max_people=2, max_points=64, max_walls=4, room=(24.0, 12.0), world=CROSSING_KEY
)
def crossing(rng: ScenarioRandom, cfg: EnvConfig) -> ScenarioBatch:
    """The thesis' straight walk while a bystander crosses between the robot and the person,
    4-5 s into it, just in front of the person (0.45 m before their centre), so that it is
    nearer the camera and its larger box comes first in the detector's list."""
    cruise = cruise_speeds(rng, cfg)
    world = rng.world  # the bystander's own draws
    t_cross = world.uniform(low=4.0, high=5.0)
    v_by = world.uniform(low=1.0, high=1.4)
    from_side = np.where(world.uniform() < 0.5, -1.0, 1.0)
    walls = room_walls(*room_size(cfg))
    accel = cfg.person.accel_mps2
    poses, people = [], []
    for i in range(rng.n):
        pose, p0 = _start(cfg, -10.0, 0.0, 0.0)
        target = smooth_path(np.array([p0, p0 + np.array([12.0, 0.0])]), cruise[i], _lat(cfg))
        # Walking from rest costs v / (2 a) of time against cruising all the way.
        x_cross = p0[0] + cruise[i] * (t_cross[i] - cruise[i] / (2.0 * accel)) - 0.45
        y0 = 3.0 * from_side[i]
        walk_s = v_by[i] / (2.0 * accel) + abs(y0) / v_by[i]
        delay = max(0.0, t_cross[i] - walk_s)
        by = smooth_path(
            np.array([(x_cross, y0), (x_cross, -y0)]), v_by[i], _lat(cfg), pauses={0: delay}
        )
        poses.append(pose)
        people.append([target, by])
    return pack_lanes(np.array(poses), people, [walls] * rng.n)


@register_scenario(
    "lookalike",
    max_people=2,
    max_points=64,
    max_walls=4,
    room=(24.0, 12.0),
    world=CROSSING_KEY,
    split="look_alike",
)
def lookalike(rng: ScenarioRandom, cfg: EnvConfig) -> ScenarioBatch:
    """``crossing`` (the same walk, the same bystander on the same seed) with a bystander who
    looks like the person: their detections carry the target's appearance (each detection
    still its own appearance noise), so the tracker's re-identification gate
    (``perception.association = "tracker"``) cannot tell them apart and only its box gate
    holds the track. Without the tracker the detector knows nobody's look, and this is
    ``crossing`` exactly."""
    batch = crossing(rng, cfg)
    batch.look_of = np.zeros((rng.n, 2), dtype=np.int64)  # both look like person 0
    return batch


def _bystander_paths(world: LaneRandom, n_by: int, hx: float, hy: float) -> np.ndarray:
    """Bystanders criss-crossing a hall, for all lanes at once: (n, n_by, 5, N_PW). Each
    walks four legs between random points on alternate sides of the hall, at their own pace,
    starting at their own time and turning round (0.5 s) at each side."""
    legs = 4
    pts = world.uniform(n_by, legs + 1, 2, low=-1.0, high=1.0) * np.array([hx, hy])
    pace = world.uniform(n_by, low=0.8, high=1.3)
    delay = world.uniform(n_by, low=0.0, high=4.0)
    # Alternate sides so that every leg crosses the hall.
    side = np.where(pts[..., 0, 0] >= 0.0, 1.0, -1.0)[..., None]
    pts[..., 0] = np.abs(pts[..., 0]) * side * np.where(np.arange(legs + 1) % 2 == 0, 1.0, -1.0)
    n = world.n
    pause = np.full((n, n_by, legs + 1), 0.5)
    pause[..., 0] = delay
    pause[..., -1] = 0.0
    flat = polyline_paths(
        pts.reshape(n * n_by, legs + 1, 2),
        np.repeat(pace.reshape(-1, 1), legs + 1, axis=1),
        pause.reshape(n * n_by, legs + 1),
    )
    return flat.reshape(n, n_by, legs + 1, N_PW)


@register_scenario("crowd", max_people=5, max_points=256, max_walls=4, world=CROWD_KEY)
def crowd(rng: ScenarioRandom, cfg: EnvConfig) -> ScenarioBatch:
    """The person walks about the hall (a 30 s random walk) while four bystanders criss-cross
    it."""
    base = SCENARIOS["random"].fn(rng, cfg.replace(scenario={"random_duration_s": 30.0}))
    length, width = room_size(cfg)
    hx = 0.5 * length - 2.0
    hy = 0.5 * width - 2.0
    world = rng.world
    bystanders = _bystander_paths(world, 4, hx, hy)
    n, n_by, m = bystanders.shape[:3]
    paths = np.zeros((n, 1 + n_by, base.paths.shape[2], N_PW))
    paths[:, :1] = base.paths
    paths[:, 1:, :m] = bystanders
    n_points = np.concatenate([base.n_points, np.full((n, n_by), m)], axis=1)
    return ScenarioBatch(
        robot_pose=base.robot_pose,
        paths=paths,
        n_points=n_points,
        n_people=np.full(n, 1 + n_by, dtype=np.int64),
        walls=base.walls,
        n_walls=base.n_walls,
    )


@register_scenario("stop_and_go", max_points=64, max_walls=4, room=(24.0, 10.0))
def stop_and_go(rng: ScenarioRandom, cfg: EnvConfig) -> ScenarioBatch:
    """14 m straight on, stopping for 1-3 s every 2-3 m, each stretch at its own pace."""
    cruise = cruise_speeds(rng, cfg)
    gaps = rng.uniform(6, low=2.0, high=3.0)
    stops = rng.uniform(6, low=1.0, high=3.0)
    pace = rng.uniform(8, low=0.6, high=1.4)
    walls = room_walls(*room_size(cfg))
    poses, people = [], []
    for i in range(rng.n):
        pose, p0 = _start(cfg, -10.5, 0.0, 0.0)
        xs = p0[0] + np.concatenate([[0.0], np.cumsum(gaps[i])])
        xs = xs[xs < p0[0] + 14.0]
        corners = np.column_stack([np.append(xs, p0[0] + 14.0), np.zeros(len(xs) + 1)])
        pauses = {k: float(stops[i, k - 1]) for k in range(1, len(corners) - 1)}
        speeds = {k: float(cruise[i] * pace[i, k]) for k in range(len(corners))}
        poses.append(pose)
        people.append([smooth_path(corners, cruise[i], _lat(cfg), pauses=pauses, speeds=speeds)])
    return pack_lanes(np.array(poses), people, [walls] * rng.n)


@register_scenario("zigzag", max_points=128, max_walls=4, room=(24.0, 12.0))
def zigzag(rng: ScenarioRandom, cfg: EnvConfig) -> ScenarioBatch:
    """Six 2 m legs turning alternately 60 deg left and right, after a 1.5 m straight start."""
    cruise = cruise_speeds(rng, cfg)
    first_left = rng.uniform() < 0.5
    walls = room_walls(*room_size(cfg))
    poses, people = [], []
    for i in range(rng.n):
        pose, p0 = _start(cfg, -10.0, 0.0, 0.0)
        corners = [p0, p0 + np.array([1.5, 0.0])]
        sign = 1.0 if first_left[i] else -1.0
        for leg in range(6):
            ang = math.radians(30.0) * (sign if leg % 2 == 0 else -sign)
            corners.append(corners[-1] + 2.0 * np.array([math.cos(ang), math.sin(ang)]))
        poses.append(pose)
        people.append([smooth_path(np.array(corners), cruise[i], _lat(cfg), corner_radius_m=0.6)])
    return pack_lanes(np.array(poses), people, [walls] * rng.n)


def _curvature_caps(xy: np.ndarray, cruise_mps: float, lateral_accel_mps2: float) -> np.ndarray:
    """Speed caps along a densely sampled path: ``sqrt(a_lat R)`` with the local radius R
    estimated from the turn at each waypoint over its neighbouring legs."""
    caps = np.full(len(xy), cruise_mps)
    if len(xy) >= 3:
        d_in, d_out = np.diff(xy, axis=0)[:-1], np.diff(xy, axis=0)[1:]
        turn = np.abs(
            np.arctan2(
                d_in[:, 0] * d_out[:, 1] - d_in[:, 1] * d_out[:, 0], np.sum(d_in * d_out, axis=1)
            )
        )
        seg = 0.5 * (np.linalg.norm(d_in, axis=1) + np.linalg.norm(d_out, axis=1))
        radius = np.where(turn > 1e-6, seg / np.maximum(turn, 1e-6), np.inf)
        caps[1:-1] = np.minimum(cruise_mps, np.sqrt(lateral_accel_mps2 * radius))
        # The leg into a bend is walked at the bend's pace.
        caps[:-1] = np.minimum(caps[:-1], caps[1:])
    caps[-1] = 0.0
    return caps


def _planned_path(
    cost_map: object,
    start: np.ndarray,
    goal: np.ndarray,
    key: np.uint64,
    cruise: float,
    cfg: EnvConfig,
    delay: float = 0.0,
) -> np.ndarray | None:
    """A T-RRT path (reference §3) from start to goal as walkable waypoints, or None."""
    from follow_env.world.trrt import plan

    result = plan(cost_map, start, goal, key)  # type: ignore[arg-type]
    if not result.success:
        return None
    xy = result.path
    out = np.zeros((len(xy), N_PW))
    out[:, PW.x], out[:, PW.y] = xy[:, 0], xy[:, 1]
    out[1:, PW.s] = np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))
    out[:, PW.vmax] = _curvature_caps(xy, cruise, cfg.person.lateral_accel_mps2)
    out[0, PW.pause] = delay
    return out


_RW_LENGTH_M, _RW_WIDTH_M = 20.0, 14.0
_RW_MAX_OBSTACLES = 10
_RW_MAX_BYSTANDERS = 3


@register_scenario(
    "random_world",
    max_people=1 + _RW_MAX_BYSTANDERS,
    max_points=256,
    max_walls=4 + 4 * _RW_MAX_OBSTACLES + 2,
    room=None,
    world=RANDOM_WORLD_KEY,
)
def random_world(rng: ScenarioRandom, cfg: EnvConfig) -> ScenarioBatch:
    """A random map per seed: a 20 x 14 m hall with 3-10 pillars and pieces of furniture, and
    in half the maps a partition with a 1.2 m door; the person's walk to a far goal and up to
    three bystanders' walks are planned through it with T-RRT (reference §3), keeping 0.45 m from
    obstacles so that the robot behind fits too."""
    from follow_env.world.trrt import cost_map_from_obstacles

    world = rng.world
    cruise = cruise_speeds(rng, cfg)
    hx, hy = 0.5 * _RW_LENGTH_M, 0.5 * _RW_WIDTH_M
    n_obs = (3 + np.floor(world.uniform() * (_RW_MAX_OBSTACLES - 2))).astype(int)
    obs = world.uniform(_RW_MAX_OBSTACLES, 6)  # x, y, size a, size b, yaw, kind
    partition = world.uniform(2)  # present?, door position
    robot_y = world.uniform(low=-hy + 3.0, high=hy - 3.0)
    goals = world.uniform(4, 2)
    n_by = np.floor(world.uniform() * (_RW_MAX_BYSTANDERS + 1)).astype(int)
    by_pts = world.uniform(_RW_MAX_BYSTANDERS, 2, 2, low=-1.0, high=1.0)
    by_delay = world.uniform(_RW_MAX_BYSTANDERS, low=0.0, high=5.0)
    plan_keys = world.uniform(8) * 2.0**53  # one planner key per path, from the lane's stream
    poses, people, walls_all = [], [], []
    for i in range(rng.n):
        pose, p0 = _start(cfg, -hx + 2.5, float(robot_y[i]), 0.0)
        walls = [room_walls(_RW_LENGTH_M, _RW_WIDTH_M)]
        boxes = []
        for k in range(n_obs[i]):
            x = -hx + 5.0 + obs[i, k, 0] * (_RW_LENGTH_M - 6.5)
            y = -hy + 1.0 + obs[i, k, 1] * (_RW_WIDTH_M - 2.0)
            pillar = obs[i, k, 5] < 0.4
            a = 0.4 + 0.4 * obs[i, k, 2] if pillar else 0.6 + 1.4 * obs[i, k, 2]
            b = a if pillar else 0.5 + 0.5 * obs[i, k, 3]
            yaw = 0.0 if pillar else float(obs[i, k, 4] * np.pi)
            height = WALL_HEIGHT_M if pillar else _FURNITURE_HEIGHT_M
            walls.append(box_walls(x, y, a, b, yaw, height))
            boxes.append((x, y, a, b, yaw))
        if partition[i, 0] < 0.5:
            x_w = 1.0
            door = -hy + 2.0 + partition[i, 1] * (_RW_WIDTH_M - 4.0)
            walls.append(
                np.array(
                    [
                        [x_w, -hy, x_w, door - 0.6, WALL_HEIGHT_M],
                        [x_w, door + 0.6, x_w, hy, WALL_HEIGHT_M],
                    ]
                )
            )
        wall_arr = np.vstack(walls)
        cmap = cost_map_from_obstacles(
            (-hx, -hy, hx, hy),
            walls=wall_arr[:, :4],
            boxes=np.array(boxes) if boxes else None,
            body_radius_m=0.45,
        )
        # The start area is kept clear: drop any obstacle that lands on it and re-plan.
        target = None
        for g in range(4):
            goal = np.array(
                [hx - 2.0 - goals[i, g, 0] * 4.0, -hy + 2.0 + goals[i, g, 1] * (2 * hy - 4.0)]
            )
            if cmap.is_free(p0) and cmap.is_free(goal):
                target = _planned_path(cmap, p0, goal, np.uint64(plan_keys[i, g]), cruise[i], cfg)
            if target is not None:
                break
        if target is None:  # no way through this map: the same start in an empty hall
            wall_arr = room_walls(_RW_LENGTH_M, _RW_WIDTH_M)
            target = smooth_path(np.array([p0, (hx - 3.0, p0[1])]), cruise[i], _lat(cfg))
        lane = [target]
        for b in range(n_by[i]):
            a_pt = by_pts[i, b, 0] * np.array([hx - 1.5, hy - 1.5])
            b_pt = by_pts[i, b, 1] * np.array([hx - 1.5, hy - 1.5])
            if np.linalg.norm(a_pt - pose[:2]) < 2.0 or not (
                cmap.is_free(a_pt) and cmap.is_free(b_pt)
            ):
                continue
            path = _planned_path(
                cmap, a_pt, b_pt, np.uint64(plan_keys[i, 4 + b]), 1.1, cfg, float(by_delay[i, b])
            )
            if path is not None:
                lane.append(path)
        poses.append(pose)
        people.append(lane)
        walls_all.append(wall_arr)
    return pack_lanes(np.array(poses), people, walls_all)
