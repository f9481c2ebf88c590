"""Scenarios: where the robot starts and where people walk. Registered by name.

A scenario is one function decorated with :func:`register_scenario`. It receives a
:class:`ScenarioRandom` (one random stream per lane being reset: the person's, and ``.world`` for
the map and bystanders) and the env configuration, and returns a :class:`ScenarioBatch` for all
those lanes at once. Person 0 of each lane is the person to follow. Paths and walls are plain
float arrays whose columns are the fields of :data:`~follow_env.tasks.person_follow.people.WAYPOINT`
(:data:`PW`) and :data:`~follow_env.world.geometry.WALL`.

Built in: ``straight``, ``curve`` and ``random`` (:mod:`.basic`), and the realistic world's
``corridor_turn``, ``doorway``, ``occlusion``, ``crossing``, ``lookalike``, ``crowd``,
``stop_and_go``, ``zigzag`` and ``random_world`` (:mod:`.realistic`). In all of them the
person's cruise pace is drawn per episode, uniform within ``cruise_speed_mps +-
speed_spread_mps``, and slowed in bends to keep ``v^2 / R`` below ``lateral_accel_mps2``.

Each scenario belongs to one of :data:`SPLITS`, the groups the social-navigation benchmarks
report by (``register_scenario(..., split=...)``; by default ``distractor`` when the scenario
has room for people besides the target, ``single_target`` otherwise): ``crossing``, ``crowd``
and ``random_world`` are distractor scenarios, ``lookalike`` (crossing's bystander with the
target's look, :attr:`ScenarioBatch.look_of`) the look-alike one, the rest single-target.
Everybody else's appearance is an independent uniform draw per episode.

A minimal scenario of your own (the person walks 8.5 m diagonally):

>>> import gymnasium as gym
>>> import numpy as np
>>> from follow_env import register_scenario
>>> from follow_env.tasks.person_follow.scenarios import (
...     cruise_speeds, person_ahead, polyline_paths, single_person
... )
>>> @register_scenario("diagonal", max_points=2, room=(24.0, 16.0))
... def diagonal(rng, cfg):
...     pose = np.zeros((rng.n, 3))                    # robot at the origin, facing +x
...     start = person_ahead(cfg, pose)                # 1 m in front of the camera, centred
...     end = start + np.array([6.0, 6.0])             # then 8.5 m diagonally
...     pace = np.repeat(cruise_speeds(rng, cfg)[:, None], 2, axis=1)
...     paths = polyline_paths(np.stack([start, end], axis=1), pace)
...     return single_person(paths, pose, cfg)
>>> env = gym.make("PersonFollow-v0", scenario="diagonal")
>>> obs, info = env.reset(seed=0)
>>> round(info["true_distance_m"], 1)
1.0
"""

from follow_env.tasks.person_follow.scenarios import basic, realistic  # noqa: F401  (registers)
from follow_env.tasks.person_follow.scenarios.registry import (
    PW,
    SCENARIOS,
    SPLITS,
    WALL_MARGIN_M,
    ScenarioBatch,
    ScenarioRandom,
    ScenarioSpec,
    check_inside,
    cruise_speeds,
    get_scenario,
    pack_lanes,
    person_ahead,
    polyline_paths,
    register_scenario,
    room,
    room_size,
    single_person,
)

__all__ = [
    "PW",
    "SCENARIOS",
    "SPLITS",
    "WALL_MARGIN_M",
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
