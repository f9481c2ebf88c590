"""The realistic world: obstacles, occlusion, bystanders, the tracker and the new scenarios."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from numba import njit

from follow_env.sensors.detector import APPEARANCE_KEY
from follow_env.sim.rng import LaneSeeds, uniform_at
from follow_env.sim.runner import BatchedSim
from follow_env.tasks.person_follow.config import IDEAL, THESIS
from follow_env.tasks.person_follow.people import (
    PERSON,
    as_waypoints,
    person_reset,
    person_step,
    social_forces,
)
from follow_env.tasks.person_follow.scenarios import SCENARIOS, polyline_paths
from follow_env.tasks.person_follow.task import batched_sim
from follow_env.world.geometry import point_segment_distance

WORLD_SCENARIOS = [
    "corridor_turn",
    "doorway",
    "occlusion",
    "crossing",
    "crowd",
    "stop_and_go",
    "zigzag",
    "random_world",
]


def _follower(obs: np.ndarray) -> np.ndarray:
    """A plain proportional follower (what the guidance laws do, without their tuning)."""
    d, o = float(obs[0]), float(obs[1])
    if d <= 0.0:
        return np.zeros(2, dtype=np.float32)
    return np.array([1.5 * (d - 1.0), -0.005 * o], dtype=np.float32)


def _wall_sim(height_m: float, robot_x: float = -7.0) -> BatchedSim:
    """The doorway scenario (room to spare for extra walls) with perfect sensing, the robot
    moved to ``robot_x`` and one more wall of ``height_m`` standing across the gap between
    camera and person."""
    sim = batched_sim(IDEAL.replace(scenario={"name": "doorway"}), 1)
    sim.reset_lanes(np.zeros(1, dtype=np.int64), [0])
    sim.body["x"][0] = robot_x
    n_walls = sim.state["task"]["n_walls"]
    k = n_walls[0]
    # Camera at x = -6.8, the person's front at x = -5.8: the wall stands at x = -6.3.
    sim.world[2][0, k] = (-6.3, -1.0, -6.3, 1.0, height_m)
    n_walls[0] = k + 1
    sim.step(np.zeros((1, 2)))
    return sim


@pytest.mark.parametrize("name", WORLD_SCENARIOS)
def test_every_world_scenario_passes_the_gymnasium_checker(name: str) -> None:
    check_env(gym.make("PersonFollow-v0", scenario=name).unwrapped)


@pytest.mark.parametrize("name", WORLD_SCENARIOS)
def test_every_world_scenario_starts_as_the_thesis_does(name: str) -> None:
    env = gym.make("PersonFollow-v0", scenario=name, config="ideal")
    _, info = env.reset(seed=3)
    assert np.isclose(info["true_distance_m"], 1.0)
    assert np.isclose(info["true_offset_px"], 0.0, atol=1e-6)
    assert info["detected"]


@pytest.mark.parametrize("name", WORLD_SCENARIOS)
def test_world_scenarios_are_deterministic_per_seed(name: str) -> None:
    a = batched_sim(THESIS.replace(scenario={"name": name}), 2)
    b = batched_sim(THESIS.replace(scenario={"name": name}), 2)
    a.reset_lanes(np.arange(2), [4, 5])
    b.reset_lanes(np.arange(2), [4, 5])
    for x, y in zip(a.world, b.world, strict=True):  # people, their paths, walls
        assert np.array_equal(x, y)
    assert np.array_equal(a.state, b.state)


def test_a_wall_between_camera_and_person_hides_them() -> None:
    sim = _wall_sim(3.0)
    ts = sim.state["task"]
    assert ts["vis_frac"][0] == 0.0
    assert ts["in_frame"][0] == 0.0
    assert ts["detected"][0] == 0.0


def test_a_low_obstacle_clips_the_box_to_the_part_in_sight() -> None:
    # From 2.3 m the camera sees the body from the floor to 1.5 m; a table-high barrier in
    # between hides its lower part.
    open_view = _wall_sim(0.0, robot_x=-8.3)  # a wall of no height hides nothing
    low = _wall_sim(0.6, robot_x=-8.3)
    low_s, open_s = low.state["task"][0], open_view.state["task"][0]
    assert low_s["detected"] == 1.0
    assert low_s["vis_frac"] < open_s["vis_frac"]
    assert low_s["box"][3] < open_s["box"][3] - 20  # the bottom is cut


def _stolen_frames(association: str, seed: int) -> tuple[int, str]:
    env = gym.make("PersonFollow-v0", scenario="crossing", perception={"association": association})
    obs, info = env.reset(seed=seed)
    stolen = 0
    while True:
        obs, _, te, tr, info = env.step(_follower(obs))
        stolen += info["detected_person"] == 1
        if te or tr:
            return stolen, info["termination"]


def _looks(seed: int) -> tuple[float, float]:
    """The appearance values of the target and the bystander in episode 0 of ``seed``."""
    seeds = LaneSeeds(1)
    seeds.seed(np.zeros(1, dtype=np.int64), [seed])
    keys = seeds.next_keys(np.zeros(1, dtype=np.int64))[0]
    key = keys[APPEARANCE_KEY.stream.index] ^ np.uint64(APPEARANCE_KEY.constant)
    return uniform_at(key, 0), uniform_at(key, 1)


def test_a_crossing_bystander_steals_the_target_under_the_first_detection_rule() -> None:
    stolen = [_stolen_frames("first", seed)[0] for seed in range(4)]
    assert sum(s > 10 for s in stolen) >= 3, stolen


def test_the_tracker_keeps_the_target_from_a_bystander_who_looks_different() -> None:
    seeds = [s for s in range(12) if abs(np.subtract(*_looks(s))) > 0.3][:4]
    assert len(seeds) == 4
    stolen = [_stolen_frames("tracker", seed)[0] for seed in seeds]
    assert max(stolen) <= 3, stolen


def test_driving_into_an_obstacle_terminates_with_the_reason() -> None:
    env = gym.make("PersonFollow-v0", scenario="occlusion", config="ideal")
    env.reset(seed=1)
    sim = env.unwrapped.sim
    sides = sim.world[2][0, 4:8]  # the column's four sides
    column = (np.r_[sides["x1"], sides["x2"]].mean(), np.r_[sides["y1"], sides["y2"]].mean())
    bearing = np.arctan2(column[1] - sim.body["y"][0], column[0] - sim.body["x"][0])
    info: dict[str, Any] = {}
    for _ in range(100):  # face the column, then drive into it
        heading_err = (bearing - info.get("robot_theta_rad", 0.0) + np.pi) % (2 * np.pi) - np.pi
        action = [0.0, 4.0 * heading_err] if abs(heading_err) > 0.05 else [0.6, 0.0]
        *_, te, tr, info = env.step(np.array(action, dtype=np.float32))
        if te or tr:
            break
    assert te
    assert info["termination"] == "collision_wall"


@njit
def _walk_towards_each_other(people: np.ndarray, paths: np.ndarray, steps: int) -> float:
    for p in range(2):
        person_reset(people[p], paths[p], 2)
    closest = np.inf
    for _ in range(steps):
        social_forces(people, 2, 0.7, 1.5)
        for p in range(2):
            person_step(people[p], paths[p], 0.5, 0.8, 0.1)
        closest = min(closest, np.hypot(people[0].x - people[1].x, people[0].y - people[1].y))
    return closest


def test_people_step_aside_for_each_other() -> None:
    # Two people walking head-on along the same line.
    ends = np.array([[[-5.0, 0.0], [5.0, 0.0]], [[5.0, 0.0], [-5.0, 0.0]]])
    paths = as_waypoints(polyline_paths(ends, np.full((2, 2), 1.0)))
    people = PERSON.zeros(2)
    closest = _walk_towards_each_other(people, paths, 150)
    assert closest > 0.3  # they passed each other with a gap
    assert people["x"][0] > 4.0  # and both got where they were going
    assert people["x"][1] < -4.0


def test_random_world_paths_keep_clear_of_obstacles() -> None:
    cfg = THESIS.replace(scenario={"name": "random_world"})
    sim = batched_sim(cfg, 6)
    sim.reset_lanes(np.arange(6), list(range(6)))
    _, paths, walls_all = sim.world
    for lane in range(6):
        walls = walls_all[lane, : sim.state["task"]["n_walls"][lane]]
        path = paths[lane, 0]
        for q in path[path["x"] != 0.0]:
            clearance = min(
                point_segment_distance(q["x"], q["y"], w["x1"], w["y1"], w["x2"], w["y2"])
                for w in walls
            )
            assert clearance > 0.3
    assert (walls_all["h"] == 0.9).any()  # some maps have low furniture


def test_world_scenarios_are_registered_with_array_sizes() -> None:
    for name in WORLD_SCENARIOS:
        spec = SCENARIOS[name]
        assert spec.points_for(THESIS) >= 2
        assert spec.max_walls >= 4
    assert SCENARIOS["crowd"].max_people == 5
