"""The realistic world: obstacles, occlusion, bystanders, the tracker and the new scenarios."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from follow_env.config import IDEAL, THESIS
from follow_env.core import _APPEARANCE_DOMAIN, BatchedSim
from follow_env.layout import (
    I_N_WALLS,
    N_PSTATE,
    PS_X,
    PS_Y,
    PW_X,
    PW_Y,
    S_BOX_Y2,
    S_DETECTED,
    S_IN_FRAME,
    S_VIS_FRAC,
    S_X,
    W_H,
)
from follow_env.person import person_reset, person_step, social_forces
from follow_env.rng import STREAM_DETECTOR, LaneSeeds, uniform_at
from follow_env.scenarios import SCENARIOS, polyline_paths
from follow_env.world import point_segment_distance

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
    sim = BatchedSim(IDEAL.replace(scenario={"name": "doorway"}), 1)
    sim.reset_lanes(np.zeros(1, dtype=np.int64), [0])
    sim.fstate[0, S_X] = robot_x
    k = sim.istate[0, I_N_WALLS]
    # Camera at x = -6.8, the person's front at x = -5.8: the wall stands at x = -6.3.
    sim.walls[0, k] = [-6.3, -1.0, -6.3, 1.0, height_m]
    sim.istate[0, I_N_WALLS] = k + 1
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
    a = BatchedSim(THESIS.replace(scenario={"name": name}), 2)
    b = BatchedSim(THESIS.replace(scenario={"name": name}), 2)
    a.reset_lanes(np.arange(2), [4, 5])
    b.reset_lanes(np.arange(2), [4, 5])
    assert np.array_equal(a.paths, b.paths)
    assert np.array_equal(a.walls, b.walls)
    assert np.array_equal(a.fstate, b.fstate)


def test_a_wall_between_camera_and_person_hides_them() -> None:
    sim = _wall_sim(3.0)
    assert sim.fstate[0, S_VIS_FRAC] == 0.0
    assert sim.fstate[0, S_IN_FRAME] == 0.0
    assert sim.fstate[0, S_DETECTED] == 0.0


def test_a_low_obstacle_clips_the_box_to_the_part_in_sight() -> None:
    # From 2.3 m the camera sees the body from the floor to 1.5 m; a table-high barrier in
    # between hides its lower part.
    open_view = _wall_sim(0.0, robot_x=-8.3)  # a wall of no height hides nothing
    low = _wall_sim(0.6, robot_x=-8.3)
    assert low.fstate[0, S_DETECTED] == 1.0
    assert low.fstate[0, S_VIS_FRAC] < open_view.fstate[0, S_VIS_FRAC]
    assert low.fstate[0, S_BOX_Y2] < open_view.fstate[0, S_BOX_Y2] - 20  # the bottom is cut


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
    key = seeds.next_keys(np.zeros(1, dtype=np.int64))[0, STREAM_DETECTOR] ^ _APPEARANCE_DOMAIN
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
    column = sim.walls[0, 4:8, :4].reshape(-1, 2).mean(axis=0)  # the column's centre
    bearing = np.arctan2(column[1] - sim.fstate[0, 1], column[0] - sim.fstate[0, 0])
    info: dict[str, Any] = {}
    for _ in range(100):  # face the column, then drive into it
        heading_err = (bearing - info.get("robot_theta_rad", 0.0) + np.pi) % (2 * np.pi) - np.pi
        action = [0.0, 4.0 * heading_err] if abs(heading_err) > 0.05 else [0.6, 0.0]
        *_, te, tr, info = env.step(np.array(action, dtype=np.float32))
        if te or tr:
            break
    assert te
    assert info["termination"] == "collision_wall"


def test_people_step_aside_for_each_other() -> None:
    # Two people walking head-on along the same line.
    ps = np.zeros((2, N_PSTATE))
    paths = [
        polyline_paths(np.array([[[-5.0, 0.0], [5.0, 0.0]]]), np.full((1, 2), 1.0))[0],
        polyline_paths(np.array([[[5.0, 0.0], [-5.0, 0.0]]]), np.full((1, 2), 1.0))[0],
    ]
    for p in range(2):
        person_reset(ps[p], paths[p], 2)
    closest = np.inf
    for _ in range(150):
        social_forces(ps, 2, 0.7, 1.5)
        for p in range(2):
            person_step(ps[p], paths[p], 0.5, 0.8, 0.1)
        closest = min(closest, np.hypot(*(ps[0, [PS_X, PS_Y]] - ps[1, [PS_X, PS_Y]])))
    assert closest > 0.3  # they passed each other with a gap
    assert ps[0, PS_X] > 4.0  # and both got where they were going
    assert ps[1, PS_X] < -4.0


def test_random_world_paths_keep_clear_of_obstacles() -> None:
    cfg = THESIS.replace(scenario={"name": "random_world"})
    sim = BatchedSim(cfg, 6)
    sim.reset_lanes(np.arange(6), list(range(6)))
    for lane in range(6):
        walls = sim.walls[lane, : sim.istate[lane, I_N_WALLS]]
        path = sim.paths[lane, 0]
        pts = path[path[:, PW_X] != 0.0][:, [PW_X, PW_Y]]
        for x, y in pts:
            clearance = min(point_segment_distance(x, y, *w[:4]) for w in walls)
            assert clearance > 0.3
    assert (sim.walls[:, :, W_H] == 0.9).any()  # some maps have low furniture


def test_world_scenarios_are_registered_with_array_sizes() -> None:
    for name in WORLD_SCENARIOS:
        spec = SCENARIOS[name]
        assert spec.points_for(THESIS) >= 2
        assert spec.max_walls >= 4
    assert SCENARIOS["crowd"].max_people == 5
