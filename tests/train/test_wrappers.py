"""train/wrappers.py: the VecEnv wrappers between the env and the agent."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv, VecFrameStack

import follow_env
from policies.learned.features import (
    Box,
    IncrementalAction,
    ObservationAge,
    Pipeline,
    RescaleAction,
)
from train.wrappers import (
    ConcatVecEnv,
    VecIncrementalAction,
    VecJumpGate,
    VecObservationAge,
    VecRescaleAction,
    VecScaleObservation,
    VecShapedReward,
    VecStackFrames,
    agent_to_si,
    env_action_names,
)


class ScriptedVecEnv(VecEnv):
    """A VecEnv that replays scripted observations, rewards and dones; records actions."""

    def __init__(
        self,
        observations: list[list[list[float]]],
        rewards: list[list[float]] | None = None,
        dones: list[list[bool]] | None = None,
        truncated: list[list[bool]] | None = None,
    ) -> None:
        self.render_mode = None
        self.script = np.asarray(observations, dtype=np.float32)  # (steps + 1, lanes, obs)
        n = self.script.shape[1]
        steps = len(self.script) - 1
        self.rewards = np.zeros((steps, n)) if rewards is None else np.asarray(rewards)
        self.dones = np.zeros((steps, n), bool) if dones is None else np.asarray(dones)
        self.truncated = np.zeros((steps, n), bool) if truncated is None else np.asarray(truncated)
        obs_space = spaces.Box(-1000, 1000, shape=self.script.shape[2:], dtype=np.float32)
        act_space = spaces.Box(
            np.array([-2.0, -4.0], np.float32), np.array([2.0, 4.0], np.float32), dtype=np.float32
        )
        super().__init__(n, obs_space, act_space)
        self.t = 0
        self.actions: list[np.ndarray] = []

    def reset(self) -> np.ndarray:
        self.t = 0
        return self.script[0].copy()

    def step_async(self, actions: np.ndarray) -> None:
        self.actions.append(np.array(actions, dtype=np.float64))

    def step_wait(self) -> Any:
        self.t += 1
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        for i in np.flatnonzero(self.dones[self.t - 1]):
            infos[i]["terminal_observation"] = self.script[self.t, i] + 0.5  # marks "terminal"
            infos[i]["TimeLimit.truncated"] = bool(self.truncated[self.t - 1, i])
        rewards = self.rewards[self.t - 1].astype(np.float32)
        return self.script[self.t].copy(), rewards, self.dones[self.t - 1].copy(), infos

    def close(self) -> None:
        pass

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return [getattr(self, attr_name)] * self.num_envs

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        setattr(self, attr_name, value)

    def env_method(self, method_name: str, *args: Any, indices: Any = None, **kw: Any) -> list:
        return []

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False] * self.num_envs


def constant_obs(steps: int, lanes: int = 1, value: tuple[float, ...] = (1.0, 0.0)) -> list:
    return [[list(value) for _ in range(lanes)] for _ in range(steps + 1)]


def test_agent_to_si_maps_the_unit_box_linearly_and_clips() -> None:
    low, high = np.array([-2.0, -4.0]), np.array([2.0, 4.0])
    np.testing.assert_allclose(
        agent_to_si(np.array([[-1, 1], [0, 0.5], [3, -3]]), low, high), [[-2, 4], [0, 2], [2, -4]]
    )


def test_rescale_action_defaults_to_the_env_box_and_takes_smaller_limits() -> None:
    env = ScriptedVecEnv(constant_obs(2))
    wrapped = VecRescaleAction(env, w_max_radps=1.0)
    assert wrapped.action_space == spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
    wrapped.reset()
    wrapped.step(np.array([[1.0, -1.0]]))
    np.testing.assert_allclose(env.actions[-1], [[2.0, -1.0]])


def test_rescale_action_rejects_a_limit_beyond_the_env_box() -> None:
    with pytest.raises(ValueError, match=r"w_max_radps=5.0 is out of range"):
        VecRescaleAction(ScriptedVecEnv(constant_obs(1)), w_max_radps=5.0)


def test_rescale_action_reverse_max_bounds_only_the_backward_speed() -> None:
    env = ScriptedVecEnv(constant_obs(4))  # v within +-2 m/s, w within +-4 rad/s
    wrapped = VecRescaleAction(env, reverse_max_mps=0.5)
    np.testing.assert_allclose(wrapped.action_space.low, [-0.25, -1.0])
    np.testing.assert_allclose(wrapped.action_space.high, [1.0, 1.0])
    wrapped.reset()
    for action, si in (([-1.0, -1.0], [-0.5, -4.0]), ([-0.1, 0.5], [-0.2, 2.0]), ([1, 1], [2, 4])):
        wrapped.step(np.array([action]))
        np.testing.assert_allclose(env.actions[-1], [si])


def test_an_incremental_command_rests_at_the_reverse_bound() -> None:
    env = ScriptedVecEnv(constant_obs(6))
    rescaled = VecRescaleAction(env, reverse_max_mps=0.5)
    wrapped = VecIncrementalAction(rescaled, max_change=[0.2, 0.1])
    wrapped.reset()
    for _ in range(4):
        obs, *_ = wrapped.step(np.array([[-1.0, 0.0]]))
    np.testing.assert_allclose(env.actions[-1], [[-0.5, 0.0]])  # -0.2, -0.25 (the bound), ...
    np.testing.assert_allclose(obs[0, -2:], [-0.25, 0.0])  # the command in agent units
    obs, *_ = wrapped.step(np.array([[1.0, 0.0]]))
    np.testing.assert_allclose(env.actions[-1], [[-0.1, 0.0]])  # forward from the bound at once


@pytest.mark.parametrize(
    ("value", "names", "message"),
    [
        (3.0, ("v_mps", "w_radps"), r"RescaleAction\.reverse_max_mps=3\.0 is out of range"),
        (0.0, ("v_mps", "w_radps"), r"RescaleAction\.reverse_max_mps=0\.0 is out of range"),
        ("1", ("v_mps", "w_radps"), r"RescaleAction\.reverse_max_mps='1' is out of range"),
        (0.5, ("vy_mps", "w_radps"), r"\[vy_mps, w_radps\] has no forward-speed entry v_mps"),
    ],
)
def test_rescale_action_refuses_a_bad_reverse_bound(
    value: object, names: tuple[str, ...], message: str
) -> None:
    act = Box([-2.0, -4.0], [2.0, 4.0], names)
    with pytest.raises(ValueError, match=message):
        RescaleAction(reverse_max_mps=value).bind(Box([0.0], [1.0]), act, 1)  # type: ignore[arg-type]


def test_incremental_action_moves_the_command_by_at_most_max_change() -> None:
    env = ScriptedVecEnv(constant_obs(3))
    wrapped = VecIncrementalAction(env, max_change=[0.5, 1.0])
    obs = wrapped.reset()
    np.testing.assert_allclose(obs, [[1.0, 0.0, 0.0, 0.0]])  # obs + command (at rest)
    obs, *_ = wrapped.step(np.array([[1.0, -0.5]]))
    np.testing.assert_allclose(env.actions[-1], [[0.5, -0.5]])
    np.testing.assert_allclose(obs, [[1.0, 0.0, 0.5, -0.5]])
    wrapped.step(np.array([[7.0, -7.0]]))  # clipped to one max_change
    np.testing.assert_allclose(env.actions[-1], [[1.0, -1.5]])
    wrapped.step(np.array([[1.0, -1.0]]))
    np.testing.assert_allclose(env.actions[-1], [[1.5, -2.5]])


def test_incremental_action_clips_to_the_wrapped_box_and_restarts_at_rest() -> None:
    dones = [[False], [True], [False]]
    env = ScriptedVecEnv(constant_obs(3), dones=dones)
    wrapped = VecIncrementalAction(env, max_change=[1.5, 3.0])
    wrapped.reset()
    wrapped.step(np.array([[1.0, 1.0]]))
    np.testing.assert_allclose(env.actions[-1], [[1.5, 3.0]])
    obs, _, done, infos = wrapped.step(np.array([[1.0, 1.0]]))
    np.testing.assert_allclose(env.actions[-1], [[2.0, 4.0]])  # the box is +-2, +-4
    assert done[0]
    np.testing.assert_allclose(infos[0]["terminal_observation"], [1.5, 0.5, 2.0, 4.0])
    np.testing.assert_allclose(obs, [[1.0, 0.0, 0.0, 0.0]])  # the next episode starts at rest


def test_incremental_action_brakes_by_brake_change_and_stops_at_rest() -> None:
    env = ScriptedVecEnv(constant_obs(6))
    wrapped = VecIncrementalAction(env, max_change=[0.5, 1.0], brake_change=[1.5, 1.0])
    wrapped.reset()
    for a in ([1.0, 1.0], [1.0, 1.0], [1.0, 1.0]):  # speeding up: max_change a step
        wrapped.step(np.array([a]))
    np.testing.assert_allclose(env.actions[-1], [[1.5, 3.0]])
    wrapped.step(np.array([[-0.5, -0.5]]))  # towards rest: brake_change * |a|
    np.testing.assert_allclose(env.actions[-1], [[0.75, 2.5]])
    wrapped.step(np.array([[-1.0, 0.0]]))  # 1.5 of braking asked, 0.75 left: stops at rest
    np.testing.assert_allclose(env.actions[-1], [[0.0, 2.5]])
    wrapped.step(np.array([[-1.0, 0.0]]))  # from rest, backwards at max_change
    np.testing.assert_allclose(env.actions[-1], [[-0.5, 2.5]])
    plain = VecIncrementalAction(ScriptedVecEnv(constant_obs(2)), max_change=[0.5, 1.0])
    plain.reset()
    plain.step(np.array([[0.4, 0.0]]))
    plain.step(np.array([[-1.0, 0.0]]))  # without brake_change: through zero in one step
    np.testing.assert_allclose(plain.venv.actions[-1], [[-0.3, 0.0]])


def test_incremental_action_keeps_the_robot_at_rest_until_a_distance_reading() -> None:
    script = [[[0.0, 5.0]], [[0.0, 5.0]], [[1.2, 5.0]], [[1.2, 5.0]]]
    env = ScriptedVecEnv(script)
    wrapped = VecIncrementalAction(env, max_change=[0.5, 0.5], reading_index=0)
    wrapped.reset()
    wrapped.step(np.array([[1.0, 1.0]]))
    wrapped.step(np.array([[1.0, 1.0]]))
    wrapped.step(np.array([[1.0, 1.0]]))
    np.testing.assert_allclose(np.concatenate(env.actions), [[0, 0], [0, 0], [0.5, 0.5]])


def test_incremental_action_does_not_go_below_the_held_floor_while_the_detection_is_held() -> None:
    held = [0.0, 0.0, 1.0, 1.0, 1.0, 0.0, 0.0]  # obs entry 1 > 0: the detection is held
    env = ScriptedVecEnv([[[1.0, h]] for h in held])
    wrapped = VecIncrementalAction(env, max_change=[0.5, 0.5], held_index=1, held_floor=[0.0, None])
    wrapped.reset()
    for a in ([-1, -1], [-1, -1], [-1, -1], [-1, -1], [0.4, 0.0], [-1.0, 0.0]):
        obs, *_ = wrapped.step(np.array([a], dtype=float))
    np.testing.assert_allclose(
        np.concatenate(env.actions),
        [
            [-0.5, -0.5],  # fresh: backwards at max_change
            [-1.0, -1.0],
            [-0.5, -1.5],  # held: v rises to the floor at max_change (w has no floor)
            [0.0, -2.0],  # at the floor, however hard the agent pushes
            [0.2, -2.0],  # above it as it likes
            [-0.3, -2.0],  # fresh again: below it
        ],
    )
    np.testing.assert_allclose(obs[0, 2:], [-0.3, -2.0])  # the agent sees the command in force


def test_incremental_action_keeps_the_held_entries_while_the_detection_is_held() -> None:
    held = [0.0, 0.0, 1.0, 1.0, 0.0, 0.0]  # obs entry 1 > 0: the detection is held
    env = ScriptedVecEnv([[[1.0, h]] for h in held])
    wrapped = VecIncrementalAction(
        env, max_change=[0.5, 0.5], held_index=1, held_floor=[0.0, None], held_keep=[False, True]
    )
    wrapped.reset()
    for a in ([-1, 1], [-1, 1], [-1, -1], [1, -1], [0, -1]):
        obs, *_ = wrapped.step(np.array([a], dtype=float))
    np.testing.assert_allclose(
        np.concatenate(env.actions),
        [
            [-0.5, 0.5],  # fresh: as the agent asks
            [-1.0, 1.0],
            [-0.5, 1.0],  # held: the turn as it was, v rising to its floor
            [0.0, 1.0],  # and v free above it
            [0.0, 0.5],  # fresh again: the turn changes
        ],
    )
    np.testing.assert_allclose(obs[0, 2:], [0.0, 0.5])


def test_with_ahead_index_the_turn_is_kept_only_in_a_gap_with_something_nearer() -> None:
    # obs [distance, held, ahead]: a gap with nothing nearer (a detector miss), then one in which
    # the reading ahead comes 0.5 m nearer than the held distance (an occluder), latched
    # for the rest of that gap, then a new gap with nothing nearer.
    script = [[1.0, 0, 1.0], [1.0, 0, 1.0], [1.0, 1, 0.95], [1.0, 1, 0.5], [1.0, 1, 5.0]]
    script += [[1.0, 0, 1.0], [1.0, 1, 1.0], [1.0, 1, 1.0]]
    env = ScriptedVecEnv([[row] for row in script])
    wrapped = VecIncrementalAction(
        env,
        max_change=[0.25, 0.25],
        reading_index=0,
        held_index=1,
        held_keep=[False, True],
        ahead_index=2,
        behind_margin_m=0.2,
    )
    wrapped.reset()
    for _ in range(len(script) - 1):
        wrapped.step(np.array([[0.0, 1.0]]))
    np.testing.assert_allclose(
        np.concatenate(env.actions)[:, 1], [0.25, 0.5, 0.75, 0.75, 0.75, 1.0, 1.25]
    )


def test_the_held_floor_acts_the_same_in_the_agents_pipeline() -> None:
    """The exported agent's steps (ObservationAge, then IncrementalAction reading its age)
    give the training wrappers' actions."""
    script = [[[1.0, 5.0]], [[1.0, 4.0]], [[1.0, 4.0]], [[1.0, 4.0]], [[1.1, 3.0]]]
    kwargs = {"max_change": [0.5, 0.5], "held_index": 2, "held_floor": [-0.25, None]}
    env = ScriptedVecEnv(script)
    wrapped = VecIncrementalAction(VecObservationAge(env, max_age_steps=5, entries=1), **kwargs)
    act = Box(np.array([-2.0, -4.0]), np.array([2.0, 4.0]))
    pipeline = Pipeline(
        [ObservationAge(max_age_steps=5, entries=1), IncrementalAction(**kwargs)],
        Box(np.full(2, -1000.0), np.full(2, 1000.0)),
        act,
        1,
    )
    obs, mine = wrapped.reset(), pipeline.start(np.asarray(script[0], dtype=np.float32))
    np.testing.assert_array_equal(obs, mine)
    for t in range(1, len(script)):
        obs, *_ = wrapped.step(np.array([[-1.0, 1.0]]))
        applied = pipeline.act(np.array([[-1.0, 1.0]]))
        mine = pipeline.observe(np.asarray(script[t], dtype=np.float32))
        np.testing.assert_array_equal(env.actions[-1], applied)
        np.testing.assert_array_equal(obs, mine)
    # the age compares the distance only: held from the second observation on
    np.testing.assert_allclose(np.concatenate(env.actions)[:, 0], [-0.5, -0.25, -0.25, -0.25])


def test_a_step_left_out_of_training_passes_through_and_stays_in_the_agents_view() -> None:
    """``in_training: false``: the training wrapper hands on the env's observations and the
    agent's actions untouched, and the exported agent's pipeline (built from the same entry)
    gates the bystander's jump."""
    script = [[[1.0, 0.0]], [[1.25, 10.0]], [[3.0, 300.0]], [[3.0, 300.0]], [[1.5, 20.0]]]
    kwargs = {"max_jump_m": 0.5, "accept_after": 10, "in_training": False}
    env = ScriptedVecEnv(script)
    wrapped = VecJumpGate(env, **kwargs)
    assert not wrapped.in_training
    assert wrapped.observation_space == env.observation_space
    assert wrapped.action_space == env.action_space
    [step] = Pipeline.from_wrappers([("train.wrappers.VecJumpGate", kwargs)])
    assert type(step).__name__ == "JumpGate"
    pipeline = Pipeline(
        [step], Box(np.full(2, -1000.0), np.full(2, 1000.0)), Box(-np.ones(2), np.ones(2)), 1
    )
    np.testing.assert_array_equal(wrapped.reset(), script[0])
    np.testing.assert_array_equal(pipeline.start(np.asarray(script[0], np.float32)), script[0])
    seen = []
    for t in range(1, len(script)):
        obs, *_ = wrapped.step(np.array([[0.3, -0.7]]))
        np.testing.assert_array_equal(obs, script[t])  # the training env's, untouched
        np.testing.assert_array_equal(env.actions[-1], [[0.3, -0.7]])
        seen.append(pipeline.observe(np.asarray(script[t], np.float32))[0].tolist())
    # the agent's view holds the person's reading through the jump, as a trained-in gate does
    gated = VecJumpGate(ScriptedVecEnv(script), max_jump_m=0.5, accept_after=10)
    trained = [gated.reset()] + [gated.step(np.zeros((1, 2)))[0] for _ in script[1:]]
    np.testing.assert_allclose(seen, np.concatenate(trained[1:]))
    np.testing.assert_allclose(seen[1:], [[1.25, 10.0], [1.25, 10.0], [1.5, 20.0]])


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (
            lambda e: VecObservationAge(e, max_age_steps=5, in_training=False),
            r"VecObservationAge\.in_training=False needs a step that keeps the observation and "
            r"action shapes; VecObservationAge turns \(2,\) / \(2,\) into \(3,\) / \(2,\)",
        ),
        (
            lambda e: VecJumpGate(e, in_training="no"),
            r"VecJumpGate\.in_training='no' must be true or false",
        ),
        (
            lambda e: VecJumpGate(e, max_jump_m=-1.0, in_training=False),
            r"VecJumpGate\.max_jump_m=-1\.0 is out of range",
        ),
    ],
)
def test_a_step_left_out_of_training_is_refused_where_it_cannot_be(
    build: Any, message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        build(ScriptedVecEnv(constant_obs(1)))
    with pytest.raises(ValueError, match=r"train\.wrappers\.VecJumpGate\.in_training=1 must be"):
        Pipeline.from_wrappers([("train.wrappers.VecJumpGate", {"in_training": 1})])


def test_observation_age_counts_steps_without_change() -> None:
    script = [[[1.0, 5.0]], [[1.0, 5.0]], [[1.0, 5.0]], [[1.1, 5.0]], [[1.1, 5.0]]]
    wrapped = VecObservationAge(ScriptedVecEnv(script), max_age_steps=2)
    ages = [wrapped.reset()[0, -1]]
    for _ in range(4):
        ages.append(wrapped.step(np.zeros((1, 2)))[0][0, -1])
    np.testing.assert_allclose(ages, [0.0, 0.5, 1.0, 0.0, 0.5])


def test_observation_age_starts_at_zero_in_a_new_episode() -> None:
    script = [[[1.0, 5.0]], [[1.0, 5.0]], [[1.0, 5.0]]]
    wrapped = VecObservationAge(ScriptedVecEnv(script, dones=[[False], [True]]), max_age_steps=4)
    wrapped.reset()
    wrapped.step(np.zeros((1, 2)))
    obs, _, _, infos = wrapped.step(np.zeros((1, 2)))
    assert obs[0, -1] == 0.0
    assert infos[0]["terminal_observation"][-1] == 0.0  # the marked terminal obs is fresh


def test_scale_observation_multiplies_each_entry() -> None:
    wrapped = VecScaleObservation(ScriptedVecEnv(constant_obs(1, value=(2.0, -300.0))), [1, 0.01])
    np.testing.assert_allclose(wrapped.reset(), [[2.0, -3.0]])
    with pytest.raises(ValueError, match="one factor per observation entry"):
        VecScaleObservation(ScriptedVecEnv(constant_obs(1)), [1.0])


def test_shaped_reward_floors_shifts_and_charges_command_changes() -> None:
    rewards = [[-5.0, 0.5], [-5.0, -60.0]]
    dones = [[False, False], [False, True]]
    env = ScriptedVecEnv(constant_obs(2, lanes=2), rewards=rewards, dones=dones)
    wrapped = VecShapedReward(
        env, reward_floor=-1.0, alive_bonus=1.0, v_rate_weight=2.0, w_rate_weight=0.5
    )
    wrapped.reset()
    _, r, *_ = wrapped.step(np.array([[0.5, 0.0], [0.0, -2.0]]))
    # lane 0: max(-5, -1) + 1 - 2 * 0.5; lane 1: 0.5 + 1 - 0.5 * 2
    np.testing.assert_allclose(r, [-1.0, 0.5])
    _, r, *_ = wrapped.step(np.array([[0.5, 0.0], [0.0, -2.0]]))
    # lane 1 ends by termination: its -60 (a collision) is not floored
    np.testing.assert_allclose(r, [0.0, -59.0])


def test_shaped_reward_floors_the_last_step_of_a_truncated_episode() -> None:
    env = ScriptedVecEnv(constant_obs(1), rewards=[[-5.0]], dones=[[True]], truncated=[[True]])
    wrapped = VecShapedReward(env, reward_floor=-1.0)
    wrapped.reset()
    assert wrapped.step(np.zeros((1, 2)))[1][0] == -1.0


def test_far_weight_charges_the_distance_error_beyond_the_cap_before_the_floor() -> None:
    # lane 0 is 4 m away (3 m of error, 2 beyond the cap), then 1.5 m; lane 1's episode ends
    # by termination at step 2, where the scripted terminal observation is the next + 0.5 m
    obs = [[[1.0, 0.0], [1.0, 0.0]], [[4.0, 0.0], [2.5, 0.0]], [[1.5, 0.0], [5.0, 0.0]]]
    rewards = [[0.0, 0.0], [0.0, -50.0]]
    dones = [[False, False], [False, True]]
    env = ScriptedVecEnv(obs, rewards=rewards, dones=dones)
    wrapped = VecShapedReward(env, reward_floor=-1.0, alive_bonus=1.0, far_weight=0.25)
    wrapped.reset()
    _, r, *_ = wrapped.step(np.zeros((2, 2)))
    np.testing.assert_allclose(r, [1.0 - 0.25 * 2.0, 1.0 - 0.25 * 0.5])
    _, r, *_ = wrapped.step(np.zeros((2, 2)))
    # lane 1: the terminal observation 5.5 m (3.5 m beyond the cap), not floored: a collision
    np.testing.assert_allclose(r, [1.0, -50.0 - 0.25 * 3.5 + 1.0])


def test_far_weight_is_floored_and_skips_a_missing_reading() -> None:
    env = ScriptedVecEnv([[[1.0, 0.0]], [[9.0, 0.0]], [[0.0, 0.0]]])
    wrapped = VecShapedReward(env, reward_floor=-1.0, alive_bonus=1.0, far_weight=1.0)
    wrapped.reset()
    assert wrapped.step(np.zeros((1, 2)))[1][0] == 0.0  # -7 floored to -1: no worse than lost
    assert wrapped.step(np.zeros((1, 2)))[1][0] == 1.0  # no reading yet: nothing charged


def test_far_power_charges_the_squared_error_from_the_start() -> None:
    # 3 m away (2 m of error, 1.5 beyond far_from_m), then 1.25 m (0.25 m, none beyond it)
    env = ScriptedVecEnv([[[1.0, 0.0]], [[3.0, 0.0]], [[1.25, 0.0]]])
    wrapped = VecShapedReward(env, alive_bonus=1.0, far_weight=0.5, far_from_m=0.5, far_power=2)
    wrapped.reset()
    assert wrapped.step(np.zeros((1, 2)))[1][0] == pytest.approx(1.0 - 0.5 * 1.5**2)
    assert wrapped.step(np.zeros((1, 2)))[1][0] == 1.0
    squared = VecShapedReward(
        ScriptedVecEnv([[[1.0, 0.0]], [[1.5, 0.0]]]), far_weight=2.0, far_from_m=0.0, far_power=2
    )
    squared.reset()
    assert squared.step(np.zeros((1, 2)))[1][0] == pytest.approx(-2.0 * 0.25)  # below 1 m: less


def test_near_weight_charges_the_near_side_once_more() -> None:
    # lane 0 at 0.6 m (0.4 m too near), then 1.5 m (0.5 m too far); lane 1 has no reading yet
    obs = [[[1.0, 0.0], [1.0, 0.0]], [[0.6, 0.0], [0.0, 0.0]], [[1.5, 0.0], [0.0, 0.0]]]
    wrapped = VecShapedReward(
        ScriptedVecEnv(obs), alive_bonus=1.0, far_weight=2.0, far_from_m=0.0, near_weight=3.0
    )
    wrapped.reset()
    np.testing.assert_allclose(
        wrapped.step(np.zeros((2, 2)))[1], [1.0 - (2.0 + 3.0) * 0.4, 1.0], rtol=1e-6
    )
    np.testing.assert_allclose(wrapped.step(np.zeros((2, 2)))[1], [1.0 - 2.0 * 0.5, 1.0], atol=1e-6)
    alone = VecShapedReward(ScriptedVecEnv(obs), near_weight=3.0)  # without far_weight too
    alone.reset()
    np.testing.assert_allclose(alone.step(np.zeros((2, 2)))[1], [-3.0 * 0.4, 0.0], rtol=1e-6)


def test_the_distance_and_offset_terms_can_charge_the_truth() -> None:
    """far_source / offset_source truth: the target's true distance and offset of the state each
    step reached (an ended episode's final one), from the adapter's infos; the agent's
    observation is unchanged. A twin env with every info key gives the expected values."""
    kwargs: dict[str, Any] = {"scenario": "crowd", "episode": {"max_steps": 20}}
    venv = follow_env.make_sb3_vec_env(2, **kwargs)
    twin = follow_env.make_sb3_vec_env(2, full_info=True, **kwargs)
    weights = {"reward_floor": -1.0, "far_weight": 2.0, "far_from_m": 0.0, "offset_weight": 3.0}
    wrapped = VecShapedReward(venv, far_source="truth", offset_source="truth", **weights)
    for env in (wrapped, twin):
        env.seed(3)
    np.testing.assert_array_equal(wrapped.reset(), twin.reset())
    action = np.array([[0.6, 0.2], [0.3, -0.4]], dtype=np.float32)
    ends = 0
    for _ in range(30):
        obs, shaped, dones, _ = wrapped.step(action)
        twin_obs, r, twin_dones, infos = twin.step(action)
        np.testing.assert_array_equal(obs, twin_obs)
        np.testing.assert_array_equal(dones, twin_dones)
        d = np.array([info["true_distance_m"] for info in infos])
        o = np.array([info["true_offset_px"] for info in infos])
        charged = r - 2.0 * np.abs(d - 1.0)
        terminated = dones & ~np.array([i.get("TimeLimit.truncated", False) for i in infos])
        expected = np.where(terminated, charged, np.maximum(charged, -1.0))
        expected -= 3.0 * np.minimum(np.abs(o) / 320.0, 1.0)
        np.testing.assert_allclose(shaped, expected, rtol=1e-5, atol=1e-5)
        ends += int(dones.sum())
    assert ends >= 2  # final states were charged too


def test_a_truth_source_needs_an_env_that_can_report_it() -> None:
    with pytest.raises(ValueError, match=r"far_source='true' is out of range: must be one of "):
        VecShapedReward(ScriptedVecEnv(constant_obs(1)), far_source="true")
    with pytest.raises(ValueError, match=r"offset_source=truth needs an env whose infos can carry"):
        VecShapedReward(ScriptedVecEnv(constant_obs(1)), offset_source="truth")


@pytest.mark.parametrize(("forward", "backward"), [(2.0, 0.0), (0.0, 3.0), (2.0, 3.0)])
def test_the_blind_weights_charge_the_speed_command_while_nothing_is_detected(
    forward: float, backward: float
) -> None:
    """The charge is ``blind_speed_weight * max(v, 0) + blind_reverse_weight * max(-v, 0)`` on
    the steps whose frame has no detection (the env's ``detected``), nothing otherwise: the
    same shaping without it, on the same rollout, differs by exactly that."""
    kwargs: dict[str, Any] = {"scenario": "occlusion", "episode": {"max_steps": 40}}
    weights = {"reward_floor": -1.0, "alive_bonus": 1.0, "v_rate_weight": 4.0}
    blind = VecShapedReward(
        follow_env.make_sb3_vec_env(2, **kwargs),
        blind_speed_weight=forward,
        blind_reverse_weight=backward,
        **weights,
    )
    plain = VecShapedReward(follow_env.make_sb3_vec_env(2, full_info=True, **kwargs), **weights)
    for env in (blind, plain):
        env.seed(5)
        env.reset()
    rng = np.random.default_rng(0)
    charged = np.zeros(2, dtype=int)
    for _ in range(60):  # lane 0 drives on at 1 m/s (into the walls), lane 1 backs away
        action = np.array([[1.0, rng.uniform(-1, 1)], [-0.5, 0.0]], dtype=np.float32)
        obs, shaped, dones, _ = blind.step(action)
        plain_obs, base, plain_dones, infos = plain.step(action)
        np.testing.assert_array_equal(obs, plain_obs)
        np.testing.assert_array_equal(dones, plain_dones)
        unseen = ~np.array([info["detected"] for info in infos])
        v = action[:, 0].astype(np.float64)
        charge = forward * np.maximum(v, 0.0) + backward * np.maximum(-v, 0.0)
        expected = base - np.where(unseen, charge, 0.0)
        np.testing.assert_allclose(shaped, expected, rtol=1e-6, atol=1e-6)
        charged += unseen & (charge > 0)
    assert charged.sum() >= 5  # frames without a detection were met, and charged,
    assert (charged[0] > 0) == (forward > 0)  # the forward lane by the forward weight only,
    assert (charged[1] > 0) == (backward > 0)  # the reversing lane by the backward one only


@pytest.mark.parametrize(
    ("scenario", "weight", "within", "key", "ending", "action"),
    [
        # both lanes turn and drive on: into a wall
        ("occlusion", "clearance_weight", "clearance_m", "wall_clearance_m", "collision_wall",
         [[1.0, 0.8], [0.6, -1.0]]),
        # both lanes drive on into the crowd the person walks through
        ("crowd", "bystander_weight", "bystander_m", "bystander_clearance_m",
         "collision_bystander", [[1.0, 0.3], [0.8, -0.2]]),
    ],
)  # fmt: skip
def test_a_clearance_weight_charges_the_shortfall_up_to_the_collision(
    scenario: str, weight: str, within: str, key: str, ending: str, action: list
) -> None:
    """The charge is ``w * clip(m - c, 0, m) / m`` with ``c`` the true clearance (to the
    nearest wall, or bystander) of the state each step reached (an ended episode's final one):
    the same shaping without it, on the same rollout, differs by exactly that, and a lane
    driven into a wall or a bystander pays it on the steps before the collision."""
    kwargs: dict[str, Any] = {"scenario": scenario, "episode": {"max_steps": 80}}
    weights = {"reward_floor": -1.0, "alive_bonus": 1.0}
    near = VecShapedReward(
        follow_env.make_sb3_vec_env(2, **kwargs), **{weight: 4.0, within: 0.5}, **weights
    )
    plain = VecShapedReward(follow_env.make_sb3_vec_env(2, full_info=True, **kwargs), **weights)
    for env in (near, plain):
        env.seed(5)
        env.reset()
    charged, collided = 0, 0
    for _ in range(120):
        act = np.array(action, dtype=np.float32)
        _, shaped, dones, _ = near.step(act)
        _, base, plain_dones, infos = plain.step(act)
        np.testing.assert_array_equal(dones, plain_dones)
        c = np.array([info[key] for info in infos])
        expected = base - 4.0 * np.clip(0.5 - c, 0.0, 0.5) / 0.5
        np.testing.assert_allclose(shaped, expected, rtol=1e-6, atol=1e-6)
        charged += int(((c < 0.5) & (c > 0.0)).sum())
        collided += sum(info.get("termination") == ending for info in infos)
    assert charged >= 3  # they were approached and charged,
    assert collided >= 1  # and hit


def test_headway_moves_the_following_distance_with_the_robots_speed() -> None:
    """headway_s: far_weight and near_weight charge the distance from ``target_distance_m +
    headway_s * max(v, 0)``, ``v`` the robot's true forward speed of the state each step
    reached; a twin env with every info key and the same actions gives the expected charge."""
    kwargs: dict[str, Any] = {"scenario": "straight", "episode": {"max_steps": 60}}
    weights = {"far_weight": 2.0, "far_from_m": 0.0, "near_weight": 1.0, "headway_s": 0.5}
    ahead = VecShapedReward(follow_env.make_sb3_vec_env(2, **kwargs), **weights)
    plain = VecShapedReward(follow_env.make_sb3_vec_env(2, full_info=True, **kwargs))
    for env in (ahead, plain):
        env.seed(3)
        env.reset()
    fast, ended = 0, 0
    for t in range(70):  # lane 0 drives on, lane 1 backs away: its target stays 1 m
        act = np.array([[min(0.05 * t, 1.2), 0.0], [-0.3, 0.0]], dtype=np.float32)
        obs, shaped, dones, _ = ahead.step(act)
        _, base, _, infos = plain.step(act)
        ended += int(dones.sum())  # an ended episode is charged from its terminal observation
        d = np.array([i.get("terminal_observation", o)[0] for i, o in zip(infos, obs, strict=True)])
        v = np.array([info["robot_v_mps"] for info in infos])
        target = 1.0 + 0.5 * np.maximum(v, 0.0)
        charge = 2.0 * np.abs(d - target) + np.maximum(target - d, 0.0)
        np.testing.assert_allclose(shaped, base - np.where(d > 0, charge, 0.0), atol=1e-5)
        fast += int(v[0] > 0.5)
        assert target[1] == 1.0
    assert fast >= 10  # the target moved: 1.25 m and more at 0.5 m/s
    assert ended >= 2
    with pytest.raises(ValueError, match=r"headway_s=-0\.1 is out of range"):
        VecShapedReward(ScriptedVecEnv(constant_obs(1)), headway_s=-0.1)
    with pytest.raises(ValueError, match=r"headway_s needs an env whose infos can carry"):
        VecShapedReward(ScriptedVecEnv(constant_obs(1)), far_weight=1.0, headway_s=0.1)
    with pytest.raises(ValueError, match=r"headway_s=0\.1 moves the distance .* give one"):
        VecShapedReward(ScriptedVecEnv(constant_obs(1)), headway_s=0.1)


def test_blind_speed_and_clearance_weights_need_their_info_keys() -> None:
    with pytest.raises(ValueError, match=r"blind_speed_weight needs an env whose infos can carry"):
        VecShapedReward(ScriptedVecEnv(constant_obs(1)), blind_speed_weight=1.0)
    with pytest.raises(ValueError, match=r"blind_speed_weight=-1\.0 is out of range"):
        VecShapedReward(ScriptedVecEnv(constant_obs(1)), blind_speed_weight=-1.0)
    with pytest.raises(ValueError, match=r"blind_reverse_weight needs an env whose infos can"):
        VecShapedReward(ScriptedVecEnv(constant_obs(1)), blind_reverse_weight=1.0)
    with pytest.raises(ValueError, match=r"blind_reverse_weight=-2\.0 is out of range"):
        VecShapedReward(ScriptedVecEnv(constant_obs(1)), blind_reverse_weight=-2.0)
    with pytest.raises(ValueError, match=r"clearance_weight needs an env whose infos can carry"):
        VecShapedReward(ScriptedVecEnv(constant_obs(1)), clearance_weight=1.0)
    with pytest.raises(ValueError, match=r"clearance_m=0\.0 is out of range"):
        VecShapedReward(ScriptedVecEnv(constant_obs(1)), clearance_m=0.0)
    with pytest.raises(ValueError, match=r"bystander_weight needs an env whose infos can carry"):
        VecShapedReward(ScriptedVecEnv(constant_obs(1)), bystander_weight=1.0)
    with pytest.raises(ValueError, match=r"bystander_m=-0\.5 is out of range"):
        VecShapedReward(ScriptedVecEnv(constant_obs(1)), bystander_m=-0.5)


def _stack_script() -> tuple[list, list]:
    """Two lanes, four steps; lane 1's episode ends at step 2 (the next obs is a new one's)."""
    obs = [[[1.0, 5.0], [2.0, -5.0]], [[1.1, 6.0], [2.1, -6.0]], [[1.2, 7.0], [3.0, 9.0]],
           [[1.3, 8.0], [3.1, 8.0]], [[1.4, 9.0], [3.2, 7.0]]]  # fmt: skip
    dones = [[False, False], [False, True], [False, False], [False, False]]
    return obs, dones


def _run(venv: VecEnv, steps: int) -> tuple[list[np.ndarray], list[Any]]:
    seen, terminals = [venv.reset()], []
    for _ in range(steps):
        o, _, _, infos = venv.step(np.zeros((2, 2)))
        seen.append(o)
        terminals += [
            info["terminal_observation"] for info in infos if "terminal_observation" in info
        ]
    return seen, terminals


def test_stack_frames_with_zeros_is_sb3s_frame_stack_terminal_observations_included() -> None:
    obs, dones = _stack_script()
    ours = _run(VecStackFrames(ScriptedVecEnv(obs, dones=dones), n_stack=3), 4)
    sb3 = _run(VecFrameStack(ScriptedVecEnv(obs, dones=dones), n_stack=3), 4)
    for a, b in zip(ours[0] + ours[1], sb3[0] + sb3[1], strict=True):
        np.testing.assert_array_equal(a, b)


def test_stack_frames_padded_with_the_first_observation_at_every_episode_start() -> None:
    obs, dones = _stack_script()
    seen, terminals = _run(VecStackFrames(ScriptedVecEnv(obs, dones=dones), 3, pad="first"), 4)
    np.testing.assert_array_equal(seen[0], [[1, 5, 1, 5, 1, 5], [2, -5, 2, -5, 2, -5]])
    np.testing.assert_allclose(seen[1][0], [1, 5, 1, 5, 1.1, 6])
    # lane 1 starts again from 3 m: its stack is that observation three times
    np.testing.assert_array_equal(seen[2][1], [3, 9, 3, 9, 3, 9])
    np.testing.assert_allclose(seen[3][1], [3, 9, 3, 9, 3.1, 8])
    # its episode's last view: the old stack with the terminal observation (obs + 0.5) pushed on
    np.testing.assert_allclose(terminals[0], [2, -5, 2.1, -6, 3.5, 9.5])
    with pytest.raises(ValueError, match=r"VecStackFrames\.pad='last' is out of range"):
        VecStackFrames(ScriptedVecEnv(obs), 3, pad="last")
    with pytest.raises(ValueError, match=r"VecStackFrames\.n_stack=0 is out of range"):
        VecStackFrames(ScriptedVecEnv(obs), 0)


def test_concat_vec_env_lane_j_replays_its_scenario_seeded_s_plus_j() -> None:
    parts = [follow_env.make_sb3_vec_env(2, scenario=s) for s in ("straight", "curve")]
    joined = ConcatVecEnv(parts)
    joined.seed(100)
    obs = joined.reset()
    single = follow_env.make_sb3_vec_env(1, scenario="curve")
    single.seed(103)  # lane 3 = the second lane of the curve part
    reference = single.reset()
    actions = np.tile([[0.5, 0.1]], (4, 1))
    for _ in range(20):
        obs, *_ = joined.step(actions)
        reference, *_ = single.step(actions[:1])
    np.testing.assert_array_equal(obs[3], reference[0])
    assert joined.num_envs == 4
    assert joined.get_attr("render_mode") == [None] * 4


# Values a YAML file can hold that each constructor refuses, naming Class.argument and the range
# (follow-train reports them before anything is written).
@pytest.mark.parametrize(
    ("build", "message"),
    [
        (lambda e: VecRescaleAction(e, w_max_radps=True), r"VecRescaleAction\.w_max_radps=True"),
        (lambda e: VecRescaleAction(e, v_max_mps="1"), r"VecRescaleAction\.v_max_mps='1'"),
        (lambda e: VecScaleObservation(e, scale="abc"), r"VecScaleObservation\.scale='abc' is out"),
        (lambda e: VecScaleObservation(e, scale=[1.0, "a"]), r"scale=\[1\.0, 'a'\] is out of"),
        (lambda e: VecScaleObservation(e, scale=[1.0, -1.0]), "must be positive numbers"),
        (
            lambda e: VecIncrementalAction(e, max_change="x"),
            r"VecIncrementalAction\.max_change='x' is out of range: must be 2 positive numbers",
        ),
        (
            lambda e: VecIncrementalAction(e, reading_index=5),
            r"VecIncrementalAction\.reading_index=5 is out of range: must be None or an "
            r"observation index in \[0, 1\]",
        ),
        (lambda e: VecIncrementalAction(e, reading_index="0"), r"reading_index='0' is out of"),
        (
            lambda e: VecIncrementalAction(e, max_change=[0.5, 0.5], brake_change=[0.5, 0.0]),
            r"VecIncrementalAction\.brake_change=\[0\.5, 0\.0\] is out of range: must be None or 2 "
            r"positive numbers",
        ),
        (
            lambda e: VecIncrementalAction(e, held_index=1),
            r"VecIncrementalAction\.held_index=1 serves nothing: give held_floor or held_keep, or "
            r"leave held_index out",
        ),
        (
            lambda e: VecIncrementalAction(e, held_floor=[0.0, None]),
            r"VecIncrementalAction\.held_floor=\[0\.0, None\]: needs held_index",
        ),
        (
            lambda e: VecIncrementalAction(e, held_index=1, held_keep=[True]),
            r"VecIncrementalAction\.held_keep=\[True\] is out of range: must be 2 booleans, one "
            r"per action entry \[v_mps, w_radps\]",
        ),
        (
            lambda e: VecIncrementalAction(e, held_index=1, held_keep=[False, True], ahead_index=0),
            r"VecIncrementalAction\.ahead_index=0: needs held_keep and reading_index",
        ),
        (
            lambda e: VecIncrementalAction(
                e,
                reading_index=0,
                held_index=1,
                held_keep=[False, True],
                ahead_index=0,
                behind_margin_m=0.0,
            ),
            r"VecIncrementalAction\.behind_margin_m=0\.0 is out of range",
        ),
        (
            lambda e: VecIncrementalAction(
                e, held_index=1, held_keep=[False, True], behind_margin_m=0.3
            ),
            r"VecIncrementalAction\.behind_margin_m=0\.3: needs ahead_index",
        ),
        (
            lambda e: VecIncrementalAction(e, held_index=1, held_keep=[0, 1]),
            r"VecIncrementalAction\.held_keep=\[0, 1\] is out of range: must be 2 booleans",
        ),
        (
            lambda e: VecIncrementalAction(e, held_index=1, held_floor=[0.0]),
            r"VecIncrementalAction\.held_floor=\[0\.0\] is out of range: must be 2 entries, one "
            r"per action entry \[v_mps, w_radps\]",
        ),
        (
            lambda e: VecIncrementalAction(e, held_index=1, held_floor=[3.0, None]),
            r"VecIncrementalAction\.held_floor\[0\] \(v_mps\)=3\.0 is out of range",
        ),
        (
            lambda e: VecIncrementalAction(e, held_index=7, held_floor=[0.0, None]),
            r"VecIncrementalAction\.held_index=7 is out of range: must be None or an "
            r"observation index in \[0, 1\]",
        ),
        (lambda e: VecObservationAge(e, max_age_steps=2.5), r"max_age_steps=2\.5 is out of range"),
        (
            lambda e: VecObservationAge(e, max_age_steps=2**63),
            r"must be an integer in \[1, 10\*\*9\]",
        ),
        (
            lambda e: VecJumpGate(e, max_jump_m=-1.0),
            r"VecJumpGate\.max_jump_m=-1\.0 is out of range",
        ),
        (lambda e: VecShapedReward(e, v_rate_weight=-1), r"v_rate_weight=-1 is out of range"),
        (
            lambda e: VecShapedReward(e, far_weight=-1.0),
            r"VecShapedReward\.far_weight=-1\.0 is out of range",
        ),
        (
            lambda e: VecShapedReward(e, far_from_m=-0.5),
            r"VecShapedReward\.far_from_m=-0\.5 is out of range",
        ),
        (
            lambda e: VecShapedReward(e, far_power=0.5),
            r"VecShapedReward\.far_power=0\.5 is out of range: must be \[1, 3\]",
        ),
    ],
)
def test_constructors_refuse_bad_arguments_naming_them(build: Any, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        build(ScriptedVecEnv(constant_obs(1)))


def test_a_scale_past_float32_is_refused_without_a_warning() -> None:
    # float64's 1e308 became inf in float32, and numpy's RuntimeWarning came first: two lines
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match=r"positive numbers a float32 holds"):
            VecScaleObservation(ScriptedVecEnv(constant_obs(1)), scale=[1.0, 1e308])


# -- A platform of three action entries (the mecanum base's [v_mps, vy_mps, w_radps]) --------

MECANUM_NAMES = ("v_mps", "vy_mps", "w_radps")


class ThreeEntryVecEnv(ScriptedVecEnv):
    """:class:`ScriptedVecEnv` acting ``[v_mps, vy_mps, w_radps]`` in ``+-2, +-1, +-4``."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.action_space = spaces.Box(
            np.array([-2.0, -1.0, -4.0], np.float32), np.array([2.0, 1.0, 4.0], np.float32)
        )
        self.action_names = MECANUM_NAMES


def test_wrappers_take_the_action_width_and_names_from_the_env() -> None:
    env = ThreeEntryVecEnv(constant_obs(1))
    wrapped = VecIncrementalAction(VecRescaleAction(env), max_change=[0.1, 0.2, 0.3])
    assert wrapped.action_space.shape == (3,)
    assert wrapped.action_names == MECANUM_NAMES
    assert wrapped.observation_space.shape == (5,)  # obs + the three commands


def test_rescale_action_takes_one_limit_per_entry_of_its_unit() -> None:
    env = ThreeEntryVecEnv(constant_obs(2))
    wrapped = VecRescaleAction(env, v_max_mps=[None, 0.5], w_max_radps=2.0)
    wrapped.reset()
    wrapped.step(np.array([[1.0, -1.0, 0.5]]))
    np.testing.assert_allclose(env.actions[-1], [[2.0, -0.5, 1.0]])


def test_rescale_action_one_number_bounds_every_entry_of_its_unit() -> None:
    env = ThreeEntryVecEnv(constant_obs(2))
    wrapped = VecRescaleAction(env, v_max_mps=0.5, w_max_radps=1.0)  # w is the third entry here
    wrapped.reset()
    wrapped.step(np.array([[1.0, 1.0, 1.0]]))
    np.testing.assert_allclose(env.actions[-1], [[0.5, 0.5, 1.0]])


def test_incremental_action_moves_each_of_three_entries_by_its_own_step() -> None:
    env = ThreeEntryVecEnv(constant_obs(2))
    wrapped = VecIncrementalAction(env, max_change=[0.5, 0.25, 1.0])
    wrapped.reset()
    wrapped.step(np.array([[1.0, -1.0, 0.5]]))
    np.testing.assert_allclose(env.actions[-1], [[0.5, -0.25, 0.5]])


def test_shaped_reward_charges_each_entry_its_own_rate_weight() -> None:
    env = ThreeEntryVecEnv(constant_obs(1), rewards=[[0.0]])
    wrapped = VecShapedReward(env, rate_weights=[1.0, 2.0, 4.0])
    wrapped.reset()
    _, r, *_ = wrapped.step(np.array([[0.5, -0.25, 0.125]]))
    np.testing.assert_allclose(r, [-(0.5 + 0.5 + 0.5)])


def test_shaped_reward_named_weights_leave_the_sideways_entry_free() -> None:
    env = ThreeEntryVecEnv(constant_obs(1), rewards=[[0.0]])
    wrapped = VecShapedReward(env, v_rate_weight=1.0, w_rate_weight=1.0)
    wrapped.reset()
    _, r, *_ = wrapped.step(np.array([[0.5, 1.0, 0.25]]))
    np.testing.assert_allclose(r, [-0.75])


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (
            lambda e: VecRescaleAction(e, v_max_mps=[1.0, 2.0, 3.0]),
            r"VecRescaleAction\.v_max_mps=\[1\.0, 2\.0, 3\.0\] is out of range: must be a "
            r"number or 2 entries, one per action entry in mps \[v_mps, vy_mps\]",
        ),
        (
            lambda e: VecRescaleAction(e, v_max_mps=[None, 5.0]),
            r"VecRescaleAction\.v_max_mps\[1\] \(vy_mps\)=5\.0 is out of range",
        ),
        (
            lambda e: VecIncrementalAction(e, max_change=[0.1, 0.1]),
            r"max_change=\[0\.1, 0\.1\] is out of range: must be 3 positive numbers, one per "
            r"action entry \[v_mps, vy_mps, w_radps\]",
        ),
        (
            lambda e: VecShapedReward(e, rate_weights=[1.0, 1.0]),
            r"VecShapedReward\.rate_weights=\[1\.0, 1\.0\] is out of range: must be 3 numbers",
        ),
        (
            lambda e: VecShapedReward(e, rate_weights=[1.0, -1.0, 1.0]),
            r"VecShapedReward\.rate_weights\[1\] \(vy_mps\)=-1\.0 is out of range",
        ),
        (
            lambda e: VecShapedReward(e, rate_weights=[1.0, 1.0, 1.0], v_rate_weight=1.0),
            "give rate_weights or v_rate_weight / w_rate_weight, not both",
        ),
    ],
)
def test_three_entry_arguments_are_checked_naming_the_field(build: Any, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        build(ThreeEntryVecEnv(constant_obs(1)))


def test_concat_vec_env_reports_its_platform_and_action_names() -> None:
    parts = [follow_env.make_sb3_vec_env(1, scenario="straight", platform="mecanum")] * 2
    joined = ConcatVecEnv(parts)
    assert joined.action_names == MECANUM_NAMES
    assert joined.platform_name == "mecanum"
    assert env_action_names(VecRescaleAction(joined)) == MECANUM_NAMES


def test_concat_vec_env_refuses_envs_of_different_platforms() -> None:
    mecanum = follow_env.make_sb3_vec_env(1, scenario="straight", platform="mecanum")
    with pytest.raises(ValueError, match="differ"):
        ConcatVecEnv([follow_env.make_sb3_vec_env(1, scenario="straight"), mecanum])


def train_tiny(tmp_path: Path, wrappers: list[dict], scenarios: str) -> Path:
    """A 2,000-step follow-train run of a small PPO behind ``wrappers`` (its view, not its
    skill); returns the run folder."""
    from train.cli import main

    section = {
        "policy": "MlpPolicy",
        "n_envs": 4,
        "n_steps": 64,
        "batch_size": 128,
        "n_epochs": 2,
        "n_timesteps": 2000,
        "normalize": {"norm_obs": False, "norm_reward": True},
        "vec_env_wrapper": wrappers,
    }
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump({"PersonFollow-v0": section}))
    run = tmp_path / "run"
    args = ["--hyperparams", str(path), "--scenarios", scenarios, "--final-episodes"]
    assert main([*args, "0", "--no-progress", "--eval-freq", "1000", "--out", str(run)]) == 0
    return run


@pytest.mark.slow
def test_an_agent_bounded_backwards_trains_loads_and_keeps_the_bound(
    tmp_path: Path, acts_as_trained
) -> None:
    """follow-train with reverse_max_mps on the outermost step (the model's own action space is
    then asymmetric): the run loads as a policy that acts as SB3's ``predict`` did on the
    training stack, and never commands more than the bound backwards."""
    from stable_baselines3 import PPO

    from eval.rollout import run_episode
    from policies import make_policy

    wrappers = [
        {"train.wrappers.VecScaleObservation": {"scale": [1.0, 0.01]}},
        {"train.wrappers.VecRescaleAction": {"w_max_radps": 2.0, "reverse_max_mps": 0.3}},
    ]
    run = train_tiny(tmp_path, wrappers, "straight,occlusion")
    model = PPO.load(run / "model.zip", device="cpu")
    v_max = follow_env.make_sb3_vec_env(1).action_space.high[0]
    np.testing.assert_allclose(model.action_space.low, [-0.3 / v_max, -1.0], rtol=1e-6)
    policy = make_policy(str(run))
    acts_as_trained(run, policy, 40)
    v = np.concatenate(
        [run_episode(policy, "occlusion", seed).log["action_v_mps"] for seed in range(3)]
    )
    assert np.nanmin(v) >= -0.3 - 1e-6
    view = policy._agent.pipeline(1)  # the loaded agent's own steps: full reverse is 0.3 m/s
    view.start(np.array([[1.0, 0.0]], dtype=np.float32))
    np.testing.assert_allclose(view.act(np.array([[-1.0, 1.0]])), [[-0.3, 2.0]], rtol=1e-6)


def test_the_agent_pipeline_keeps_exactly_the_wrappers_that_are_not_training_only() -> None:
    """``Pipeline.view_entries`` names the training-only wrappers (policies cannot import train);
    each wrapper's ``training_only`` says the same, and every other one is a feature step."""
    import train.privileged
    import train.wrappers
    from policies.learned.features import FEATURES, Pipeline

    classes = {
        f"{module.__name__}.{name}": cls
        for module in (train.wrappers, train.privileged)
        for name, cls in vars(module).items()
        if name.startswith("Vec") and isinstance(cls, type) and cls.__module__ == module.__name__
    }
    training = {"train.wrappers.VecShapedReward", "train.privileged.VecPrivilegedCritic"}
    assert training <= set(classes)
    kept = {name: short for name, short, _ in Pipeline.view_entries([(n, {}) for n in classes])}
    for name, cls in classes.items():
        assert (name in kept) != getattr(cls, "training_only", False), name
        assert name not in kept or kept[name] in FEATURES, name


@pytest.mark.slow
def test_an_agent_behind_the_gate_and_the_held_floor_loads_and_acts_as_trained(
    tmp_path: Path, acts_as_trained
) -> None:
    """follow-train with VecJumpGate and VecIncrementalAction's held floor: the run loads as a
    policy whose own steps include both, acting as SB3's ``predict`` did on the training stack
    through a crowd (bystanders, detector misses)."""
    from eval.rollout import run_episode
    from policies import make_policy

    wrappers = [
        {"train.wrappers.VecRescaleAction": {"w_max_radps": 2.0}},
        {"train.wrappers.VecJumpGate": {"max_jump_m": 0.5, "accept_after": 10}},
        {"train.wrappers.VecObservationAge": {"max_age_steps": 30}},
        {"train.wrappers.VecScaleObservation": {"scale": [1.0, 0.01, 1.0]}},
        {
            "train.wrappers.VecIncrementalAction": {
                "max_change": [0.2, 0.15],
                "reading_index": 0,
                "held_index": 2,
                "held_floor": [0.0, None],
            }
        },
    ]
    run = train_tiny(tmp_path, wrappers, "crowd,occlusion")
    policy = make_policy(str(run))
    steps = [type(step).__name__ for step in policy._agent.pipeline(1).steps]
    assert steps[:2] == ["RescaleAction", "JumpGate"]
    acts_as_trained(run, policy, 60, scenario="crowd", seed=4)
    # Where the view holds the detection, the speed command does not fall below the floor
    # (0 m/s) but by rising towards it: replay an episode's observations through the steps.
    log = run_episode(policy, "occlusion", 0).log
    obs = log[["obs_distance_m", "obs_offset_px"]].to_numpy(np.float32)
    v = log["action_v_mps"].to_numpy()
    rise = 0.2 * follow_env.make_sb3_vec_env(1).action_space.high[0]
    view = policy._agent.pipeline(1)
    held_steps = 0
    for k in np.flatnonzero(np.isfinite(v)):  # row k: the action taken on observation k
        seen = view.start(obs[:1]) if k == 0 else view.observe(obs[k : k + 1])
        if seen[0, 2] > 0:  # the view's age: the detection is held
            held_steps += 1
            assert v[k] >= min(0.0, (v[k - 1] if k else 0.0) + rise) - 1e-5
    assert held_steps > 0
