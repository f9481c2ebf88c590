"""The vector env and the SB3 adapter are exactly the single env, lane by lane."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from follow_env import INFO_KEYS, PersonFollowVectorEnv, make_sb3_vec_env

N, SEED, STEPS = 3, 7, 70
# Short episodes so every lane goes through several autoresets; the noisy preset exercises
# every random stream.
KWARGS: dict[str, Any] = {"config": "noisy", "scenario": "random", "episode": {"max_steps": 25}}


def _actions() -> np.ndarray:
    rng = np.random.default_rng(0)
    return rng.uniform([-0.5, -1.5], [1.4, 1.5], (STEPS, N, 2)).astype(np.float32)


def _assert_info_equal(single: dict[str, Any], batch: dict[str, Any], lane: int) -> None:
    for key in INFO_KEYS:
        assert batch[key][lane] == single[key], key
        assert batch["_" + key][lane]


def test_make_vec_returns_the_native_vector_env() -> None:
    env = gym.make_vec("PersonFollow-v0", num_envs=4, vectorization_mode="vector_entry_point")
    assert isinstance(env.unwrapped, PersonFollowVectorEnv)
    assert env.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    assert env.observation_space.shape == (4, 2)
    assert env.single_action_space == gym.make("PersonFollow-v0").action_space


def test_next_step_autoreset_lanes_equal_single_envs() -> None:
    vec = PersonFollowVectorEnv(N, **KWARGS)
    singles = [gym.make("PersonFollow-v0", **KWARGS) for _ in range(N)]
    obs, info = vec.reset(seed=SEED)
    ended = [False] * N
    for i, env in enumerate(singles):
        o, inf = env.reset(seed=SEED + i)
        assert np.array_equal(obs[i], o)
        _assert_info_equal(inf, info, i)
    resets = 0
    for a in _actions():
        obs, rew, term, trunc, info = vec.step(a)
        for i, env in enumerate(singles):
            if ended[i]:  # Gymnasium's next-step autoreset: this step resets the lane
                o, inf = env.reset()
                r, te, tr = 0.0, False, False
                resets += 1
            else:
                o, r, te, tr, inf = env.step(a[i])
            assert np.array_equal(obs[i], o)
            assert (rew[i], term[i], trunc[i]) == (r, te, tr)
            _assert_info_equal(inf, info, i)
            ended[i] = te or tr
    assert resets >= N  # every lane went through at least one autoreset


def test_same_step_autoreset_lanes_equal_single_envs() -> None:
    vec = PersonFollowVectorEnv(N, autoreset_mode=AutoresetMode.SAME_STEP, **KWARGS)
    assert vec.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    singles = [gym.make("PersonFollow-v0", **KWARGS) for _ in range(N)]
    vec.reset(seed=SEED)
    for i, env in enumerate(singles):
        env.reset(seed=SEED + i)
    finals = 0
    for a in _actions():
        obs, rew, term, trunc, info = vec.step(a)
        for i, env in enumerate(singles):
            o, r, te, tr, inf = env.step(a[i])
            assert (rew[i], term[i], trunc[i]) == (r, te, tr)
            if te or tr:
                assert info["_final_obs"][i]
                assert np.array_equal(info["final_obs"][i], o)
                _assert_info_equal(inf, info["final_info"], i)
                o, inf = env.reset()
                finals += 1
            else:
                assert "_final_obs" not in info or not info["_final_obs"][i]
            assert np.array_equal(obs[i], o)
            _assert_info_equal(inf, info, i)
    assert finals >= N


def test_disabled_autoreset_needs_a_masked_reset() -> None:
    vec = PersonFollowVectorEnv(2, autoreset_mode="Disabled", episode={"max_steps": 2})
    vec.reset(seed=0)
    a = np.zeros((2, 2))
    vec.step(a)
    _, _, _, trunc, _ = vec.step(a)
    assert trunc.all()
    with pytest.raises(ValueError, match="reset_mask"):
        vec.step(a)
    _, info = vec.reset(options={"reset_mask": np.array([True, False])})
    assert info["_step"].tolist() == [True, False]
    with pytest.raises(ValueError, match="lanes \\[1\\]"):
        vec.step(a)


def test_seed_list_gives_one_seed_per_lane() -> None:
    vec = PersonFollowVectorEnv(2, scenario="random")
    by_list, _ = vec.reset(seed=[5, 9])
    single, _ = gym.make("PersonFollow-v0", scenario="random").reset(seed=9)
    assert np.array_equal(by_list[1], single)
    with pytest.raises(ValueError, match="num_envs=2"):
        vec.reset(seed=[1, 2, 3])


def test_vector_env_validates_its_arguments() -> None:
    with pytest.raises(ValueError, match="num_envs=0"):
        PersonFollowVectorEnv(0)
    with pytest.raises(ValueError, match="autoreset_mode='sometimes'"):
        PersonFollowVectorEnv(2, autoreset_mode="sometimes")
    with pytest.raises(ValueError, match=r"PerceptionConfig\.miss_prob=2"):
        PersonFollowVectorEnv(2, perception={"miss_prob": 2.0})
    vec = PersonFollowVectorEnv(2)
    vec.reset(seed=0)
    with pytest.raises(ValueError, match="lanes \\[1\\]"):
        vec.step(np.array([[0.0, 0.0], [np.nan, 0.0]]))
    with pytest.raises(ValueError, match="shape"):
        vec.step(np.zeros((3, 2)))


def test_vector_env_renders_one_frame_per_lane() -> None:
    vec = PersonFollowVectorEnv(2, render_mode="rgb_array")
    vec.reset(seed=0)
    vec.step(np.zeros((2, 2)))
    frames = vec.render()
    assert len(frames) == 2
    assert frames[0].shape == frames[1].shape
    assert frames[0].dtype == np.uint8


def _lockstep(venv: Any) -> Iterator[tuple[Any, ...]]:
    """Step the SB3 adapter ``venv`` and N single envs seeded alike with the same actions;
    yield per step ``(obs, rewards, dones, infos, singles)``, ``singles[i]`` the single env's
    ``(final_obs, obs, reward, terminated, truncated, info)``: ``obs`` is the next episode's
    first after an end (the adapter resets that lane in the same step), ``final_obs`` the
    step's own."""
    singles = [gym.make("PersonFollow-v0", **KWARGS) for _ in range(N)]
    venv.seed(SEED)
    obs = venv.reset()
    for i, env in enumerate(singles):
        o, _ = env.reset(seed=SEED + i)
        assert np.array_equal(obs[i], o)
    for a in _actions():
        venv.step_async(a)
        obs, rewards, dones, infos = venv.step_wait()
        steps = []
        for i, env in enumerate(singles):
            final, r, te, tr, inf = env.step(a[i])
            o = env.reset()[0] if te or tr else final
            steps.append((final, o, r, te, tr, inf))
        yield obs, rewards, dones, infos, steps


def test_sb3_adapter_lanes_equal_single_envs() -> None:
    ends = 0
    for obs, rew, dones, infos, singles in _lockstep(make_sb3_vec_env(N, full_info=True, **KWARGS)):
        for i, (final, o, r, te, tr, inf) in enumerate(singles):
            assert rew[i] == np.float32(r)
            assert dones[i] == (te or tr)
            for key in INFO_KEYS:
                assert infos[i][key] == inf[key], key
            if te or tr:
                assert np.array_equal(infos[i]["terminal_observation"], final)
                assert infos[i]["TimeLimit.truncated"] == (tr and not te)
                ends += 1
            assert np.array_equal(obs[i], o)
    assert ends >= N


def test_sb3_adapter_includes_the_info_keys_asked_for_final_states_included() -> None:
    venv = make_sb3_vec_env(N, **KWARGS)
    venv.include_info(["true_distance_m", "true_offset_px"])
    venv.include_info(["true_distance_m"])  # asking twice adds nothing
    assert venv.info_keys == ("true_distance_m", "true_offset_px")
    ends = 0
    for _, _, dones, infos, singles in _lockstep(venv):
        for i, (_, _, _, te, tr, inf) in enumerate(singles):
            # the step's own state, on a lane that ended its final one (before the reset)
            assert infos[i]["true_distance_m"] == inf["true_distance_m"]
            assert infos[i]["true_offset_px"] == inf["true_offset_px"]
            assert "robot_x_m" not in infos[i]
            assert dones[i] == ("terminal_observation" in infos[i])
            ends += int(te or tr)
    assert ends >= N
    with pytest.raises(ValueError, match="info key 'true_distance' is not one of time_s, "):
        venv.include_info(["true_distance"])
    assert venv.info_keys == ("true_distance_m", "true_offset_px")


def test_sb3_adapter_works_with_monitor_normalize_and_evaluate_policy() -> None:
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    venv = VecNormalize(VecMonitor(make_sb3_vec_env(4, episode={"max_steps": 30})))
    venv.seed(0)
    venv.reset()

    class Still:  # a predict()-compatible policy for evaluate_policy
        def predict(self, obs: np.ndarray, **_: Any) -> tuple[np.ndarray, None]:
            return np.zeros((len(obs), 2), dtype=np.float32), None

    mean, std = evaluate_policy(Still(), venv, n_eval_episodes=4)  # type: ignore[arg-type]
    assert np.isfinite(mean)
    assert np.isfinite(std)


@pytest.mark.slow
def test_ppo_learns_on_the_sb3_adapter_for_a_few_hundred_steps() -> None:
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecMonitor

    venv = VecMonitor(make_sb3_vec_env(8, episode={"max_steps": 40}))
    model = PPO("MlpPolicy", venv, n_steps=32, batch_size=64, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=512)
    assert model.num_timesteps >= 512
    action, _ = model.predict(np.array([1.0, 0.0], dtype=np.float32), deterministic=True)
    assert action.shape == (2,)
