"""The scenario registry and the helpers scenario functions share (see the package docstring)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from follow_env.sim import streams
from follow_env.sim.checks import out_of_range
from follow_env.sim.rng import LaneRandom
from follow_env.tasks.person_follow.people import N_PW, WAYPOINT
from follow_env.world.geometry import WALL_FIELDS, room_walls

if TYPE_CHECKING:
    from follow_env.tasks.person_follow.config import EnvConfig

__all__ = [
    "PW",
    "SCENARIOS",
    "SPLITS",
    "ScenarioBatch",
    "ScenarioRandom",
    "ScenarioSpec",
    "check_inside",
    "cruise_speeds",
    "get_scenario",
    "pack_lanes",
    "person_ahead",
    "polyline_paths",
    "register_scenario",
    "room",
    "room_size",
    "single_person",
]

PW = WAYPOINT.columns()
"""Column of each waypoint field in a scenario's float path arrays (``PW.x`` .. ``PW.pause``)."""

# People keep this far from walls (m).
WALL_MARGIN_M = 0.5

PERSON_DRAWS = streams.per_episode(
    "scenario.person", streams.PERSON, 0, None, doc="a scenario's draws for the target person"
)
WORLD_DRAWS = streams.per_episode(
    "scenario.world", streams.WORLD, 0, None, doc="a scenario's draws for its map and bystanders"
)


class ScenarioRandom(LaneRandom):
    """The person's stream of every lane being reset (draw from it directly), and ``world``:
    the stream for the scenario's map and bystanders."""

    def __init__(self, person_keys: np.ndarray, world_keys: np.ndarray) -> None:
        super().__init__(person_keys)
        self.world = LaneRandom(world_keys)


@dataclass
class ScenarioBatch:
    """Initial conditions for ``n`` lanes: robot pose, people's paths, walls."""

    robot_pose: np.ndarray  # (n, 3): x m, y m, heading rad
    paths: np.ndarray  # (n, people, points, N_PW): columns PW.x .. PW.pause
    n_points: np.ndarray  # (n, people) int: waypoints used per path (>= 2)
    n_people: np.ndarray  # (n,) int: people present (>= 1; person 0 is the target)
    walls: np.ndarray  # (n, walls, 5): x1, y1, x2, y2, height m (follow_env.world.geometry.WALL)
    n_walls: np.ndarray  # (n,) int
    # (n, people) int: whose look each person has for the tracker's re-identification gate
    # (a look-alike of the target: 0); None: everybody their own
    look_of: np.ndarray | None = None


ScenarioFn = Callable[[ScenarioRandom, "EnvConfig"], ScenarioBatch]


@dataclass(frozen=True)
class ScenarioSpec:
    """A registered scenario, the array sizes it needs and its randomness.

    :param room: the hall's size ``(length, width)`` in m when the scenario takes
        ``scenario.room_length_m`` / ``room_width_m`` (these defaults otherwise); ``None`` for a
        scenario with a fixed map, which refuses the room fields.
    :param world: the key of ``rng.world``: the world stream, or a declared domain.
    :param split: which of :data:`SPLITS` the scenario belongs to, as the social-navigation
        benchmarks group theirs: ``single_target`` (the person alone), ``distractor`` (other
        people walk where the detector sees them) or ``look_alike`` (another person looks
        like the target to the re-identification gate).
    """

    name: str
    fn: ScenarioFn
    max_people: int
    max_points: int | Callable[[EnvConfig], int]
    max_walls: int
    room: tuple[float, float] | None
    world: streams.Stream | streams.Domain
    split: str = "single_target"

    def points_for(self, cfg: EnvConfig) -> int:
        """Waypoints a path may have under ``cfg`` (sizes the core's path arrays)."""
        return self.max_points(cfg) if callable(self.max_points) else self.max_points

    def check(self, cfg: EnvConfig) -> None:
        """Refuse room fields for a scenario with a fixed map (they would do nothing)."""
        if self.room is None:
            for name in ("room_length_m", "room_width_m"):
                value = getattr(cfg.scenario, name)
                if value is not None:
                    raise out_of_range(
                        f"ScenarioConfig.{name}",
                        value,
                        f"None: scenario {self.name!r} has a fixed map",
                    )

    def random(self, keys: np.ndarray) -> ScenarioRandom:
        """The scenario's streams for lanes with these episode keys ``(n, N_STREAMS)``."""
        world = keys[
            :,
            self.world.index if isinstance(self.world, streams.Stream) else self.world.stream.index,
        ]
        if isinstance(self.world, streams.Domain):
            world = world ^ np.uint64(self.world.constant)
        return ScenarioRandom(keys[:, streams.PERSON.index], world)


SCENARIOS: dict[str, ScenarioSpec] = {}
"""Registered scenarios by name."""

SPLITS = ("single_target", "distractor", "look_alike")
"""The groups evaluations report scenarios by (:attr:`ScenarioSpec.split`)."""


def register_scenario(
    name: str,
    *,
    max_people: int = 1,
    max_points: int | Callable[[EnvConfig], int] = 64,
    max_walls: int = 4,
    room: tuple[float, float] | None = (24.0, 16.0),
    world: streams.Stream | streams.Domain = streams.WORLD,
    split: str | None = None,
) -> Callable[[ScenarioFn], ScenarioFn]:
    """Register ``fn`` as scenario ``name``; the sizes bound what the function returns
    (``max_points`` may depend on the configuration). See :class:`ScenarioSpec` for ``room``,
    ``world`` and ``split`` (default: ``distractor`` if the scenario has room for other people,
    ``single_target`` otherwise)."""
    if split is None:
        split = "distractor" if max_people > 1 else "single_target"
    if split not in SPLITS:
        raise out_of_range("register_scenario.split", split, "one of " + ", ".join(SPLITS))

    def deco(fn: ScenarioFn) -> ScenarioFn:
        if name in SCENARIOS:
            raise ValueError(f"scenario {name!r} is registered already")
        SCENARIOS[name] = ScenarioSpec(
            name, fn, max_people, max_points, max_walls, room, world, split
        )
        return fn

    return deco


def get_scenario(name: str) -> ScenarioSpec:
    """The scenario called ``name``; ``ValueError`` naming the field and the known ones."""
    if name not in SCENARIOS:
        raise out_of_range(
            "ScenarioConfig.name", name, "one of " + ", ".join(repr(n) for n in sorted(SCENARIOS))
        )
    return SCENARIOS[name]


def room_size(cfg: EnvConfig) -> tuple[float, float]:
    """The hall ``(length, width)`` (m) of the configured scenario: the config's room fields
    where set, the scenario's own size otherwise."""
    spec = get_scenario(cfg.scenario.name)
    default = spec.room if spec.room is not None else (24.0, 16.0)
    sc = cfg.scenario
    return (
        default[0] if sc.room_length_m is None else sc.room_length_m,
        default[1] if sc.room_width_m is None else sc.room_width_m,
    )


def polyline_paths(
    points: np.ndarray, vmax: np.ndarray, pause: np.ndarray | None = None
) -> np.ndarray:
    """Paths for a batch of polylines: (n, m, 2) points and (n, m) leg speed caps (m/s) ->
    (n, m, N_PW) with the arc length to every waypoint filled in. ``pause`` (n, m) in s."""
    n, m, _ = points.shape
    out = np.zeros((n, m, N_PW))
    out[..., PW.x] = points[..., 0]
    out[..., PW.y] = points[..., 1]
    seg = np.linalg.norm(np.diff(points, axis=1), axis=-1)
    out[:, 1:, PW.s] = np.cumsum(seg, axis=1)
    out[..., PW.vmax] = vmax
    if pause is not None:
        out[..., PW.pause] = pause
    return out


def cruise_speeds(rng: LaneRandom, cfg: EnvConfig) -> np.ndarray:
    """Each lane's cruise pace (m/s), uniform within ``cruise_speed_mps +- speed_spread_mps``."""
    p = cfg.person
    return rng.uniform(
        low=p.cruise_speed_mps - p.speed_spread_mps, high=p.cruise_speed_mps + p.speed_spread_mps
    )


def person_ahead(cfg: EnvConfig, pose: np.ndarray) -> np.ndarray:
    """Where the thesis puts the person: ``start_distance_m`` from the camera to the front of
    the body, on the camera's axis (centred in the image; a camera turned by ``yaw_deg`` looks
    at them, not straight ahead). ``pose`` (n, 3) -> (n, 2)."""
    c = cfg.camera
    ahead = c.mount_x_m + cfg.scenario.start_distance_m + 0.5 * cfg.person.depth_m
    cos, sin = np.cos(pose[:, 2]), np.sin(pose[:, 2])
    x = pose[:, 0] + ahead * cos - c.mount_y_m * sin
    y = pose[:, 1] + ahead * sin + c.mount_y_m * cos
    # Turned by the camera's yaw about the camera. Written as a correction so that with no yaw
    # it adds exactly 0 and every start stays bit for bit what it was.
    look = cfg.scenario.start_distance_m + 0.5 * cfg.person.depth_m
    yawed = pose[:, 2] + np.radians(c.yaw_deg)
    x = x + look * (np.cos(yawed) - cos)
    y = y + look * (np.sin(yawed) - sin)
    return np.stack([x, y], axis=-1)


def room(cfg: EnvConfig, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The scenario's hall (:func:`room_size`) as walls for ``n`` lanes, and their count."""
    walls = room_walls(*room_size(cfg))
    return np.broadcast_to(walls, (n, *walls.shape)).copy(), np.full(n, len(walls))


def check_inside(cfg: EnvConfig, points: np.ndarray, what: str) -> None:
    """Refuse a walk that leaves the hall (less the wall margin), naming the fields.

    The walk starts where :func:`person_ahead` puts the person, so the start distance and the
    camera's mount and yaw move it as much as the walk's own fields do: the message names them
    all, and where the walk goes furthest past the margin."""
    length, width = room_size(cfg)
    half = np.array([0.5 * length - WALL_MARGIN_M, 0.5 * width - WALL_MARGIN_M])
    past = np.abs(points) - half  # (..., 2): metres beyond the margin along x and y
    if np.any(past > 0.0):
        furthest = int(np.argmax(past))  # a flat index into points, whose last axis is (x, y)
        axis, reach = furthest % 2, points.flat[furthest]
        c = cfg.camera
        raise ValueError(
            f"ScenarioConfig: the {cfg.scenario.name!r} walk ({what}) does not fit in the room "
            f"of room_length_m={length} x room_width_m={width} m: it reaches "
            f"{'xy'[axis]} = {reach:+.2f} m, where people keep within +-{half[axis]:.2f} m "
            f"({WALL_MARGIN_M} m from the walls). It starts start_distance_m="
            f"{cfg.scenario.start_distance_m} in front of the camera (CameraConfig.mount_x_m="
            f"{c.mount_x_m}, mount_y_m={c.mount_y_m}, yaw_deg={c.yaw_deg}); enlarge the room, "
            "shorten the walk, or start it elsewhere (the start distance, the camera's mount "
            "or yaw)"
        )


def single_person(paths: np.ndarray, pose: np.ndarray, cfg: EnvConfig) -> ScenarioBatch:
    """A batch with one walker per lane (paths ``(n, m, N_PW)``) in the scenario's hall."""
    n, m = paths.shape[:2]
    walls, n_walls = room(cfg, n)
    return ScenarioBatch(
        robot_pose=pose,
        paths=paths[:, None],
        n_points=np.full((n, 1), m),
        n_people=np.ones(n, dtype=np.int64),
        walls=walls,
        n_walls=n_walls,
    )


def pack_lanes(
    poses: np.ndarray, people: list[list[np.ndarray]], walls: list[np.ndarray]
) -> ScenarioBatch:
    """Pad per-lane lists of paths ((m, N_PW) each, target first) and walls ((k, 5)) into a
    ScenarioBatch."""
    n = len(people)
    n_people = np.array([len(p) for p in people], dtype=np.int64)
    max_pts = max(len(path) for lane in people for path in lane)
    paths = np.zeros((n, int(n_people.max()), max_pts, N_PW))
    n_points = np.zeros((n, int(n_people.max())), dtype=np.int64)
    for i, lane in enumerate(people):
        for j, path in enumerate(lane):
            paths[i, j, : len(path)] = path
            n_points[i, j] = len(path)
    n_walls = np.array([len(w) for w in walls], dtype=np.int64)
    wall_arr = np.zeros((n, int(n_walls.max()), WALL_FIELDS))
    for i, w in enumerate(walls):
        wall_arr[i, : len(w)] = w
    return ScenarioBatch(
        robot_pose=np.asarray(poses, dtype=float),
        paths=paths,
        n_points=n_points,
        n_people=n_people,
        walls=wall_arr,
        n_walls=n_walls,
    )
