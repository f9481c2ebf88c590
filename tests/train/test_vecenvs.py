"""train/vecenvs.py: ConcatVecEnv keeps SB3's VecEnv conventions for the whole."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from stable_baselines3.common.vec_env import DummyVecEnv

import follow_env
from train.vecenvs import ConcatVecEnv


class CountingEnv(gym.Env):
    """Episodes of ``length`` steps; each reset's info says which reset it was, and the options
    it was given."""

    def __init__(self, name: str, length: int = 2) -> None:
        self.observation_space = spaces.Box(-10.0, 10.0, shape=(2,), dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.name, self.length, self.resets, self.t = name, length, 0, 0

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self.resets += 1
        self.t = 0
        info = {"env": self.name, "reset": self.resets, "options": options}
        return np.full(2, self.resets, np.float32), info

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        self.t += 1
        obs = np.full(2, 10.0 * self.resets + self.t, np.float32)
        return obs, 1.0, False, self.t >= self.length, {"t": self.t}


def parts(lengths: tuple[tuple[int, ...], ...] = ((2, 3), (2,))) -> list[DummyVecEnv]:
    """One DummyVecEnv per tuple; env ``k`` of part ``p`` is named ``p.k``."""
    return [
        DummyVecEnv([lambda p=p, k=k, n=n: CountingEnv(f"{p}.{k}", n) for k, n in enumerate(part)])
        for p, part in enumerate(lengths)
    ]


def test_reset_infos_are_the_parts_in_lane_order() -> None:
    joined = ConcatVecEnv(parts())
    joined.reset()
    assert [info["env"] for info in joined.reset_infos] == ["0.0", "0.1", "1.0"]
    assert [info["reset"] for info in joined.reset_infos] == [1, 1, 1]


def test_an_autoreset_lane_gets_its_new_episodes_reset_info_and_its_terminal_observation() -> None:
    joined = ConcatVecEnv(parts())
    joined.reset()
    actions = np.zeros((3, 2), np.float32)
    joined.step(actions)
    obs, _, dones, infos = joined.step(actions)  # lanes 0 and 2 end at their second step
    assert dones.tolist() == [True, False, True]
    assert [info["reset"] for info in joined.reset_infos] == [2, 1, 2]
    assert [info["env"] for info in joined.reset_infos] == ["0.0", "0.1", "1.0"]
    for j in (0, 2):
        np.testing.assert_array_equal(infos[j]["terminal_observation"], [12.0, 12.0])
        assert infos[j]["TimeLimit.truncated"] is True
        np.testing.assert_array_equal(obs[j], [2.0, 2.0])  # the new episode's first
    assert "terminal_observation" not in infos[1]
    joined.step(actions)  # lane 1 ends at its third step
    assert [info["reset"] for info in joined.reset_infos] == [2, 2, 2]


def test_set_options_reach_every_part_at_the_next_reset() -> None:
    joined = ConcatVecEnv(parts())
    joined.set_options({"speed": 1})
    joined.reset()
    assert [info["options"] for info in joined.reset_infos] == [{"speed": 1}] * 3
    joined.set_options([{"lane": 0}, {"lane": 1}, {"lane": 2}])
    joined.reset()
    assert [info["options"] for info in joined.reset_infos] == [{"lane": j} for j in range(3)]
    with pytest.raises(ValueError, match="2 option dicts for 3 lanes"):
        joined.set_options([{}, {}])


def test_the_task_adapters_reset_infos_and_refused_options_pass_through() -> None:
    part = follow_env.make_sb3_vec_env(2, scenario="straight")
    joined = ConcatVecEnv([part, follow_env.make_sb3_vec_env(1, scenario="curve")])
    joined.env_method("include_info", ["true_distance_m"])
    joined.reset()
    assert len(joined.reset_infos) == 3
    assert all(info["true_distance_m"] > 0.0 for info in joined.reset_infos)
    joined.set_options({"speed": 1})  # the task takes none: refused, not dropped
    with pytest.raises(ValueError, match="option"):
        joined.reset()
    joined.close()


@pytest.mark.parametrize("indices", [[3], -1, [0, 5]])
def test_an_index_past_the_lanes_is_refused_not_sent_to_another_part(indices: Any) -> None:
    joined = ConcatVecEnv(parts())
    for call in (
        lambda: joined.get_attr("render_mode", indices),
        lambda: joined.set_attr("x", 1, indices),
        lambda: joined.env_method("render", indices=indices),
    ):
        with pytest.raises(ValueError, match=r"out of range: must be lanes in \[0, 3\)"):
            call()


def test_indices_reach_the_lanes_of_their_part() -> None:
    joined = ConcatVecEnv(parts())
    joined.set_attr("name", "x", [1, 2])
    assert joined.get_attr("name") == ["0.0", "x", "x"]
    assert joined.get_attr("name", 2) == ["x"]
