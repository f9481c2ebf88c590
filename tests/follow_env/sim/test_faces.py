"""The env faces of every task keep Gymnasium's and SB3's contracts at their edges: copies,
actions that are not real numbers, stepping before a reset, seeds, options, and the shorthand
arguments given as whole sections."""

from __future__ import annotations

import copy
import pickle
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import ResetNeeded

import follow_env
from follow_env.tasks.line_trace.env import make_sb3_vec_env as line_sb3_vec_env
from follow_env.tasks.person_follow.config import ScenarioConfig

# One busy case per task: random people or a random course, every noise stream on.
TASKS: dict[str, dict[str, Any]] = {
    "PersonFollow-v0": {"scenario": "random", "config": "noisy"},
    "LineTrace-v0": {"track": "random", "config": "noisy"},
}
SB3 = {"PersonFollow-v0": follow_env.make_sb3_vec_env, "LineTrace-v0": line_sb3_vec_env}


def _action(space: gym.spaces.Box) -> np.ndarray:
    """A fixed action a third of the way to the bounds (same for the original and a copy)."""
    return (space.high / 3.0).astype(np.float32)


def _steps(env: Any, action: np.ndarray, n: int) -> list[tuple[np.ndarray, float]]:
    """``n`` steps of ``action``: (observation, reward) each (episodes here last longer)."""
    return [(out[0], out[1]) for out in (env.step(action) for _ in range(n))]


def _assert_same(
    ours: list[tuple[np.ndarray, float]], theirs: list[tuple[np.ndarray, float]]
) -> None:
    for (o1, r1), (o2, r2) in zip(ours, theirs, strict=True):
        assert np.array_equal(o1, o2)
        assert r1 == r2


# -- copies ----------------------------------------------------------------------------------


@pytest.mark.parametrize("env_id", list(TASKS))
@pytest.mark.parametrize("how", ["deepcopy", "pickle"])
def test_a_copy_of_an_env_mid_episode_goes_on_exactly_as_the_original(
    env_id: str, how: str
) -> None:
    env = gym.make(env_id, render_mode="rgb_array", **TASKS[env_id])
    env.reset(seed=3)
    a = _action(env.action_space)
    _steps(env, a, 5)
    twin = copy.deepcopy(env) if how == "deepcopy" else pickle.loads(pickle.dumps(env))
    # A copy used to read stale views of its state: its observation froze while the original's
    # moved on (deepcopy), or pickling failed on a platform's lambdas.
    _assert_same(_steps(env, a, 20), _steps(twin, a, 20))
    assert np.array_equal(env.render(), twin.render())
    # ... and its next episode (reset without a seed) too.
    assert np.array_equal(env.reset()[0], twin.reset()[0])
    _assert_same(_steps(env, a, 5), _steps(twin, a, 5))
    # The copy keeps the registered task and platform (the runner's record types are keyed
    # on them), not copies of them.
    assert twin.unwrapped.sim.task is env.unwrapped.sim.task
    assert twin.unwrapped.sim.platform is env.unwrapped.sim.platform


def test_a_copied_vector_env_and_sb3_adapter_step_as_the_originals() -> None:
    vec = gym.make_vec(
        "PersonFollow-v0", num_envs=3, vectorization_mode="vector_entry_point", scenario="random"
    )
    vec.reset(seed=1)
    twin = copy.deepcopy(vec)
    a = np.tile(_action(vec.single_action_space), (3, 1))
    for _ in range(5):
        assert np.array_equal(vec.step(a)[0], twin.step(a)[0])
    sb3 = follow_env.make_sb3_vec_env(2)
    sb3.seed(4)
    sb3.reset()
    sb3_twin = pickle.loads(pickle.dumps(sb3))
    for _ in range(5):
        assert np.array_equal(sb3.step(a[:2])[0], sb3_twin.step(a[:2])[0])


# -- actions that are not real numbers ---------------------------------------------------------


@pytest.mark.parametrize(
    "action",
    [
        np.array([0.3 + 1j, 0.0]),
        np.array(["0.3", "0"]),
        np.array([b"1", b"0"]),
        np.array(["0.3", "0"], dtype=object),  # strings in an object array were parsed too
        np.array([0.3, b"0"], dtype=object),
        np.array([10**400, 0], dtype=object),  # an int past float's range: OverflowError once
    ],
    ids=["complex", "str", "bytes", "object-str", "object-bytes", "object-huge-int"],
)
def test_an_action_that_is_not_real_numbers_raises(action: np.ndarray) -> None:
    env = gym.make("PersonFollow-v0").unwrapped
    env.reset(seed=0)
    before = env.sim.state.copy()
    # Complex actions lost their imaginary part and strings were parsed, silently.
    with pytest.raises(ValueError, match="real numbers"):
        env.step(action)
    assert env.sim.state.tobytes() == before.tobytes()  # nothing stepped
    vec = follow_env.PersonFollowVectorEnv(2)
    vec.reset(seed=0)
    with pytest.raises(ValueError, match="real numbers"):
        vec.step(np.stack([action, action]))
    sb3 = follow_env.make_sb3_vec_env(2)
    sb3.reset()
    with pytest.raises(ValueError, match="real numbers"):
        sb3.step(np.stack([action, action]))


def test_real_actions_of_every_numeric_dtype_are_still_taken() -> None:
    env = gym.make("PersonFollow-v0").unwrapped
    env.reset(seed=0)
    real = ([0.3, 0.0], np.array([1, 0]), np.array([0.3, 0.0], np.float16), [2**70, 0])
    for action in (*real, np.array([0.3, np.float32(0)], dtype=object), [np.bool_(True), 0]):
        obs, *_ = env.step(action)
        assert env.observation_space.contains(obs)


# -- stepping before a reset -------------------------------------------------------------------


@pytest.mark.parametrize("env_id", list(TASKS))
def test_the_vector_env_refuses_step_before_every_lane_was_reset(env_id: str) -> None:
    vec = gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point")
    a = np.tile(_action(vec.single_action_space), (2, 1))
    # It used to step zeroed records: no episode, a reward, no error.
    with pytest.raises(ResetNeeded):
        vec.step(a)
    vec.reset(seed=0, options={"reset_mask": np.array([True, False])})
    with pytest.raises(ResetNeeded, match=r"lanes \[1\]"):
        vec.step(a)
    vec.reset(seed=0)
    obs, *_ = vec.step(a)
    assert vec.observation_space.contains(obs)


@pytest.mark.parametrize("env_id", list(TASKS))
def test_the_sb3_adapter_refuses_step_before_reset(env_id: str) -> None:
    venv = SB3[env_id](2)
    a = np.tile(_action(venv.action_space), (2, 1))
    with pytest.raises(ResetNeeded):
        venv.step(a)
    venv.reset()
    obs, *_ = venv.step(a)
    assert obs.shape == (2, *venv.observation_space.shape)


# -- seeds and options -------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [1.5, True, "ab"], ids=["float", "bool", "str"])
def test_the_vector_env_refuses_a_seed_that_is_no_int_nor_list_naming_it(seed: object) -> None:
    vec = follow_env.PersonFollowVectorEnv(2)
    # A float or a bool raised TypeError ('float' object is not iterable); a string was read as
    # one seed per letter.
    with pytest.raises(ValueError, match=rf"seed={seed!r} is out of range"):
        vec.reset(seed=seed)  # type: ignore[arg-type]


def test_a_seed_given_as_a_numpy_scalar_or_0d_array_is_one_seed() -> None:
    vec = follow_env.PersonFollowVectorEnv(2)
    expected, _ = vec.reset(seed=7)
    for seed in (np.int64(7), np.array(7), np.array(7, dtype=np.uint8)):
        obs, _ = vec.reset(seed=seed)  # type: ignore[arg-type]
        np.testing.assert_array_equal(obs, expected)


def test_the_sb3_adapter_refuses_options_as_the_single_env_does() -> None:
    venv = follow_env.make_sb3_vec_env(2)
    venv.set_options({"difficulty": 3})
    # They used to be dropped without a word.
    with pytest.raises(ValueError, match=r"options=.*difficulty.*takes no options"):
        venv.reset()
    venv.reset()  # the refused options are not kept for the next reset
    with pytest.raises(ValueError, match="takes no options"):
        gym.make("PersonFollow-v0").reset(options={"difficulty": 3})


# -- the shorthand arguments given as whole sections -------------------------------------------


@pytest.mark.parametrize(
    "scenario",
    [{"name": "curve", "room_length_m": 30.0}, ScenarioConfig(name="curve", room_length_m=30.0)],
    ids=["mapping", "object"],
)
def test_scenario_may_be_given_as_a_section(scenario: object) -> None:
    # The README and the manual list scenario among the sections given as a dict; it was
    # taken as a name only ("ScenarioConfig.name={...} is out of range: must be a string").
    cfg = gym.make("PersonFollow-v0", scenario=scenario).unwrapped.config
    assert (cfg.scenario.name, cfg.scenario.room_length_m) == ("curve", 30.0)
    assert gym.make("PersonFollow-v0", scenario="curve").unwrapped.config.scenario.name == "curve"
    with pytest.raises(ValueError, match=r"unknown field scenario\.pace"):
        gym.make("PersonFollow-v0", scenario={"pace": 2.0})
    with pytest.raises(ValueError, match=r"ScenarioConfig\.name=5 is out of range"):
        gym.make("PersonFollow-v0", scenario=5)


def test_track_may_be_given_as_a_section() -> None:
    cfg = gym.make("LineTrace-v0", track={"name": "gaps", "gap_m": 0.1}).unwrapped.config
    assert (cfg.track.name, cfg.track.gap_m) == ("gaps", 0.1)


# -- frame rate --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("env_id", "kwargs", "fps"),
    [
        ("PersonFollow-v0", {}, 10),  # 0.1 s steps
        ("LineTrace-v0", {}, 50),  # 0.02 s steps
        ("LineTrace-v0", {"episode__control_dt_s": 0.04}, 25),
        ("PersonFollow-v0", {"episode__control_dt_s": 0.2}, 5),
    ],
)
def test_the_frame_rate_plays_an_episode_in_real_time(
    env_id: str, kwargs: dict[str, Any], fps: int
) -> None:
    # One frame a control step: the human window and RecordVideo's videos keep real time.
    env = gym.make(env_id, render_mode="rgb_array", **kwargs)
    assert env.metadata["render_fps"] == fps
    assert env.unwrapped.metadata["render_fps"] == fps
    vec = gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point", **kwargs)
    assert vec.metadata["render_fps"] == fps
    assert round(1.0 / env.unwrapped.config.control_dt_s) == fps


def test_recorded_videos_play_at_the_envs_frame_rate(tmp_path: Any) -> None:
    pytest.importorskip("moviepy")
    env = gym.make("LineTrace-v0", track="straight", render_mode="rgb_array")
    video = gym.wrappers.RecordVideo(
        env, str(tmp_path / "videos"), episode_trigger=lambda k: k == 0
    )
    assert video.frames_per_sec == 50
    video.close()


def test_the_human_window_keeps_to_the_envs_frame_rate(monkeypatch: pytest.MonkeyPatch) -> None:
    import follow_env.sim.window as window

    shown: list[float] = []

    class Recorder:
        def __init__(self, title: str, width: int, height: int) -> None:
            pass

        def show(self, frame: np.ndarray, fps: float) -> None:
            shown.append(fps)

        def close(self) -> None:
            pass

    monkeypatch.setattr(window, "Window", Recorder)
    env = gym.make("LineTrace-v0", track="straight", render_mode="human")
    env.reset(seed=0)
    env.step(np.zeros(3, np.float32))
    env.close()
    assert shown == [50, 50]  # reset and step: 50 frames a second for 0.02 s steps


@pytest.mark.parametrize("env_id", list(TASKS))
def test_the_class_frame_rate_is_the_default_envs(env_id: str) -> None:
    env = gym.make(env_id)
    # LineTraceEnv.metadata said 10 (PersonFollow's), its envs 50.
    assert type(env.unwrapped).metadata["render_fps"] == env.unwrapped.metadata["render_fps"]
    assert type(env.unwrapped).metadata["render_modes"] == ["rgb_array", "human"]


# -- the vector env's info where a mask is False, and its np_random -----------------------------


def _assert_info_as_sync(ours: dict[str, Any], sync: dict[str, Any]) -> None:
    """Every entry, masked or not, as SyncVectorEnv gives it (0 / False / None where the
    key's mask is False), with the same dtype."""
    assert set(ours) == set(sync)
    for key, values in sync.items():
        assert ours[key].dtype == values.dtype, key
        if values.dtype == object:
            assert ours[key].tolist() == values.tolist(), key
        else:
            np.testing.assert_array_equal(ours[key], values, err_msg=key)


def test_masked_entries_of_final_info_and_a_masked_reset_are_zero_or_none_as_in_sync() -> None:
    from gymnasium.vector import AutoresetMode, SyncVectorEnv

    kwargs: dict[str, Any] = {"scenario": "random", "episode__max_steps": 3}
    ours = follow_env.PersonFollowVectorEnv(3, autoreset_mode=AutoresetMode.SAME_STEP, **kwargs)
    sync = SyncVectorEnv(
        [lambda: gym.make("PersonFollow-v0", **kwargs) for _ in range(3)],
        autoreset_mode=AutoresetMode.SAME_STEP,
    )
    a = np.tile(_action(ours.single_action_space), (3, 1))
    for env in (ours, sync):
        env.reset(seed=0)
        env.step(a)
    # Lane 1 starts again: it held the live lanes' values (step [1, 0, 1], not [0, 0, 0]).
    mask = np.array([False, True, False])
    (_, mine), (_, theirs) = (e.reset(seed=5, options={"reset_mask": mask}) for e in (ours, sync))
    _assert_info_as_sync(mine, theirs)
    assert mine["step"].tolist() == [0, 0, 0]
    assert mine["termination"].tolist() == [None, "", None]
    for env in (ours, sync):
        env.step(a)
    # Lanes 0 and 2 end at step 3 and lane 1 runs on: final_info held lane 1's live values.
    (*_, mine), (*_, theirs) = (e.step(a) for e in (ours, sync))
    assert mine["_final_info"].tolist() == [True, False, True]
    _assert_info_as_sync(mine["final_info"], theirs["final_info"])
    assert mine["final_info"]["step"].tolist() == [3, 0, 3]
    assert mine["final_info"]["termination"].tolist() == ["step_limit", None, "step_limit"]


def test_reset_with_an_int_seed_seeds_np_random_and_nothing_else() -> None:
    a, b = (follow_env.PersonFollowVectorEnv(2, scenario="random") for _ in range(2))
    obs_a, _ = a.reset(seed=3)
    obs_b, _ = b.reset(seed=3)
    # np_random kept its fresh entropy: np_random_seed was a random 128-bit number.
    assert a.np_random_seed == b.np_random_seed == 3
    assert a.np_random.random() == b.np_random.random()
    # the lanes' own streams do not come from it: lane 1 is still the single env seeded 4
    single, _ = gym.make("PersonFollow-v0", scenario="random").reset(seed=4)
    np.testing.assert_array_equal(obs_a[1], single)
    np.testing.assert_array_equal(obs_a, obs_b)
    a.reset(seed=[7, 8])  # a list seeds the lanes only, as Gymnasium's VectorEnv has no rule
    assert a.np_random_seed == 3
