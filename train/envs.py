"""The agent's environment: the batched core, the configured wrappers, normalisation, stacking.

One function builds the wrapper stack for training and for the ``EvalCallback``; the policy at
inference runs the same feature code without SB3 (:mod:`policies.learned`)::

    ConcatVecEnv (one batched core per scenario)       base_env()
      -> VecMonitor                                     the env's own returns
      -> vec_env_wrapper entries of the config, in order
      -> VecNormalize                                   if the config says ``normalize``
      -> VecFrameStack(frame_stack)

This is rl-zoo3's order (``vec_env_wrapper``, then ``VecNormalize``, then ``VecFrameStack``).
The env id names the task (``PersonFollow-v0``), whose variants (scenarios) share the lanes.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any, Literal

from stable_baselines3.common.vec_env import VecEnv, VecFrameStack, VecMonitor, VecNormalize

from follow_env.sim.sb3 import TaskSB3VecEnv
from follow_env.tasks import task_for_env
from train.config import Hyperparams, import_object, wrapper_specs
from train.wrappers import ConcatVecEnv

__all__ = ["Mode", "agent_env", "base_env"]

Mode = Literal["train", "eval"]


def base_env(
    scenarios: Sequence[str],
    lanes_per_scenario: int,
    config: Any = "thesis",
    env_id: str = "PersonFollow-v0",
    env_kwargs: dict[str, Any] | None = None,
) -> VecEnv:
    """``lanes_per_scenario`` robots on each scenario, as one VecEnv (lanes grouped by scenario).

    Its ``action_names`` are the platform's action entries (the wrappers read them).

    :param scenarios: the task's variant names (PersonFollow's scenarios).
    :param lanes_per_scenario: lanes of each scenario's batched core.
    :param config: the env configuration (``gym.make``'s ``config``: a preset name or a dict).
    :param env_id: the Gymnasium id that names the task.
    :param env_kwargs: further ``gym.make`` keyword arguments (the hyperparameters'
        ``env_kwargs``, e.g. ``{"platform": "mecanum"}``).
    :raises ValueError: for an unknown scenario (naming the known ones) or a bad lane count.
    """
    task = task_for_env(env_id)
    if not scenarios:
        raise ValueError("scenarios is empty: give at least one")
    known = task.variants()
    for name in scenarios:
        if name not in known:
            raise ValueError(f"unknown scenario {name!r}; known scenarios: {', '.join(known)}")
    kwargs = dict(env_kwargs or {})
    return ConcatVecEnv(
        [
            TaskSB3VecEnv(
                task, lanes_per_scenario, config=config, **kwargs, **{task.variant_key: name}
            )
            for name in scenarios
        ]
    )


def agent_env(
    venv: VecEnv, hp: Hyperparams, mode: Mode, *, normalization: str | Path | None = None
) -> VecEnv:
    """Wrap ``venv`` as the agent sees it (module docstring).

    :param venv: the env below every wrapper (:func:`base_env`).
    :param hp: checked hyperparameters (:func:`train.config.parse_hyperparams`).
    :param mode: ``"train"`` (normalisation statistics update) or ``"eval"`` (frozen statistics,
        raw rewards; the ``EvalCallback`` copies the statistics from the training env).
    :param normalization: a ``VecNormalize`` pickle to start from (resume).
    """
    venv = VecMonitor(venv)
    for name, kwargs in wrapper_specs(hp["vec_env_wrapper"]):
        venv = import_object(name)(venv, **kwargs)
    if hp["normalize"]:
        if normalization is not None:
            venv = VecNormalize.load(str(normalization), venv)
        else:
            kwargs = dict(hp["normalize"]) if isinstance(hp["normalize"], dict) else {}
            # rl-zoo3 does the same: the algorithm's gamma (a normalize.gamma that differs from
            # it is refused, train.config), else VecNormalize's default
            kwargs.setdefault("gamma", hp.get("gamma", 0.99))
            venv = VecNormalize(venv, **kwargs)
        if mode != "train":
            venv.training = False
            venv.norm_reward = False
    if hp["frame_stack"] > 1:
        venv = VecFrameStack(venv, hp["frame_stack"])
    return venv
