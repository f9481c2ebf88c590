"""Shared fixtures."""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import pytest
from hypothesis import settings

# The first call of a compiled function compiles it (or loads it from the cache): no deadline,
# or a property test would fail on whichever example happened to come first.
settings.register_profile("personfollow", deadline=None)
settings.load_profile("personfollow")

# render_mode="human" opens its pygame window on SDL's dummy driver: no screen needed.
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")

import follow_env  # noqa: E402, F401  (registers PersonFollow-v0; after the SDL setting)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Tests marked ``before_ray`` run first, in their order, the rest after them in theirs.

    Those tests ask how a command resolves the address ``auto`` on a machine where no Ray runs.
    The session's Ray (:func:`local_ray`), once a test has started it, runs until the session
    ends, and ``auto`` would find it; so they must run before any test that starts it.
    """
    items.sort(key=lambda item: item.get_closest_marker("before_ray") is None)


@pytest.fixture(autouse=True)
def _quiet_action_space_advice() -> None:
    # Gymnasium and SB3 advise a [-1, 1] action space; ours is SI by design (see README).
    warnings.filterwarnings("ignore", message=".*symmetric and normalized.*")
    warnings.filterwarnings("ignore", message=".*normalized.*action space.*")


@pytest.fixture(scope="session")
def local_ray():
    """A local Ray with 2 CPUs, started once for the session (about 5 s) and shut down after.

    :mod:`execution` uses the running instance instead of starting its own.
    """
    ray = pytest.importorskip("ray", reason="Ray is a dev dependency: pip install -e '.[dev]'")
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    ray.init(address="local", num_cpus=2, include_dashboard=False, logging_level="warning")
    yield ray
    ray.shutdown()


@pytest.fixture(scope="session")
def one_rollout():
    """Train an agent for one rollout (the view, not the skill): ``one_rollout(config, out,
    scenarios)`` runs ``follow-train`` on ``train/configs/<config>`` with 64 lanes for 4,096
    steps into ``out`` and returns it."""
    from train.cli import main

    root = Path(__file__).resolve().parents[1]

    def train(config: str, out: Path, scenarios: str) -> Path:
        argv = [
            "--hyperparams", str(root / "train/configs" / config),
            "--scenarios", scenarios,
            "--n-envs", "64",
            "--n-timesteps", "4096",
            "--eval-freq", "100000",
            "--final-episodes", "1",
            "--no-progress",
            "--out", str(out),
        ]  # fmt: skip
        assert main(argv) == 0
        return out

    return train


@pytest.fixture(scope="session")
def acts_as_trained():
    """A check that a loaded agent acts as it did in training: one lane of its training stack
    (eval mode: frozen statistics), stepped by SB3's own ``load`` and ``predict``, against the
    policy in the single env on the same seed: the same SI actions, step by step. SB3's model
    is widened to float64 as the policy's network is (``policies.learned.networks.widened``):
    in float32 its actions are the policy's but for float32's rounding, and over a closed loop
    a last bit can move a detection by a pixel.
    ``acts_as_trained(run_dir, policy, steps)``: the first ``steps`` actions (fewer when the
    episode ends sooner). The training stack's env gets what evaluation gives the policy on top
    of the run's configuration (its ``env_overrides``: an agent's reading ahead)."""
    import numpy as np
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecEnvWrapper

    from eval.rollout import run_episode
    from policies.learned.networks import widened
    from train.envs import agent_env, base_env
    from train.run import read_config

    class RecordActions(VecEnvWrapper):  # the SI actions reaching lane 0, as float32
        def __init__(self, venv) -> None:
            super().__init__(venv)
            self.actions: list = []

        def reset(self):
            return self.venv.reset()

        def step_async(self, actions) -> None:
            # The env gets float32 actions, as a policy gives them (the action space's dtype).
            # The training wrappers compute in float64: the 8th digit can differ, and on some
            # CPUs that moves a later detection by a pixel (curve, seed 7, step 34 on an
            # AVX-512 Xeon), which is a difference of the test's inputs, not of the agent.
            actions = np.asarray(actions, dtype=np.float32)
            self.actions.append(actions[0].copy())
            self.venv.step_async(actions)

        def step_wait(self):
            return self.venv.step_wait()

    def check(run, policy, steps: int, scenario: str = "curve", seed: int = 7) -> None:
        config = read_config(run)
        model = PPO.load(run / "model.zip", device="cpu")
        model.policy = widened(model.policy)
        # what eval.rollout applies on top of the run's configuration (a PPOPolicy always has it)
        overrides = policy.env_overrides or None
        env = base_env([scenario], 1, config["args"]["env_config"], env_kwargs=overrides)
        recorder = RecordActions(env)
        stats = run / "vecnormalize.pkl"
        venv = agent_env(recorder, config["hyperparams"], "eval", normalization=stats)
        venv.seed(seed)
        agent_obs = venv.reset()
        for _ in range(steps):
            action, _ = model.predict(agent_obs, deterministic=True)
            # rounded to float32 where the network rounds it, before the view's action steps
            agent_obs, *_ = venv.step(action.astype(np.float32))
        log = run_episode(policy, scenario, seed).log
        expected = log[["action_v_mps", "action_w_radps"]].to_numpy()  # row k: obs k
        # the first `steps` actions, or all of an episode that ends sooner (its last row, the
        # final observation, has none); the training stack goes on into the next episode
        expected = expected[np.isfinite(expected).all(axis=1)][:steps]
        assert len(expected) >= min(steps, 20), f"the episode ended after {len(expected)} steps"
        np.testing.assert_array_equal(np.array(recorder.actions)[: len(expected)], expected)

    return check
