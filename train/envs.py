"""The agent's environment: the batched core, the configured wrappers, normalisation, stacking.

One function builds the wrapper stack for training, for the ``EvalCallback`` and for inference
(:mod:`policies.ppo`), so the agent sees the same observations everywhere::

    ConcatVecEnv (one batched core per scenario)       base_env()
      -> VecMonitor                                     train and eval: the env's own returns
      -> vec_env_wrapper entries of the config, in order (training-only ones skipped at inference)
      -> VecNormalize                                   if the config says ``normalize``
      -> VecFrameStack(frame_stack)

This is rl-zoo3's order (``vec_env_wrapper``, then ``VecNormalize``, then ``VecFrameStack``).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any, Literal

from stable_baselines3.common.vec_env import VecEnv, VecFrameStack, VecMonitor, VecNormalize

import follow_env
from train.config import Hyperparams, import_object, wrapper_specs
from train.wrappers import ConcatVecEnv

__all__ = ["Mode", "agent_env", "base_env"]

Mode = Literal["train", "eval", "inference"]


def base_env(scenarios: Sequence[str], lanes_per_scenario: int, config: Any = "thesis") -> VecEnv:
    """``lanes_per_scenario`` robots on each scenario, as one VecEnv (lanes grouped by scenario).

    :param scenarios: registered scenario names.
    :param lanes_per_scenario: lanes of each scenario's batched core.
    :param config: the env configuration (``gym.make``'s ``config``: a preset name or a dict).
    :raises ValueError: for an unknown scenario (naming the known ones) or a bad lane count.
    """
    if not scenarios:
        raise ValueError("scenarios is empty: give at least one")
    for name in scenarios:
        if name not in follow_env.SCENARIOS:
            known = ", ".join(sorted(follow_env.SCENARIOS))
            raise ValueError(f"unknown scenario {name!r}; known scenarios: {known}")
    return ConcatVecEnv(
        [
            follow_env.make_sb3_vec_env(lanes_per_scenario, scenario=name, config=config)
            for name in scenarios
        ]
    )


def agent_env(
    venv: VecEnv, hp: Hyperparams, mode: Mode, *, normalization: str | Path | None = None
) -> VecEnv:
    """Wrap ``venv`` as the agent sees it (module docstring).

    :param venv: the env below every wrapper (:func:`base_env`, or one fed by a policy).
    :param hp: checked hyperparameters (:func:`train.config.parse_hyperparams`).
    :param mode: ``"train"`` (normalisation statistics update), ``"eval"`` (frozen statistics,
        raw rewards; the ``EvalCallback`` copies the statistics from the training env) or
        ``"inference"`` (no monitor, no training-only wrappers, statistics from a file).
    :param normalization: a ``VecNormalize`` pickle to start from (resume) or to use
        (inference; required then when the config normalises).
    """
    if mode != "inference":
        venv = VecMonitor(venv)
    for name, kwargs in wrapper_specs(hp["vec_env_wrapper"]):
        wrapper = import_object(name)
        if mode == "inference" and getattr(wrapper, "training_only", False):
            continue
        venv = wrapper(venv, **kwargs)
    if hp["normalize"]:
        if normalization is not None:
            venv = VecNormalize.load(str(normalization), venv)
        else:
            kwargs = dict(hp["normalize"]) if isinstance(hp["normalize"], dict) else {}
            kwargs.setdefault("gamma", hp.get("gamma", 0.99))  # rl-zoo3 does the same
            venv = VecNormalize(venv, **kwargs)
        if mode != "train":
            venv.training = False
            venv.norm_reward = False
    if hp["frame_stack"] > 1:
        venv = VecFrameStack(venv, hp["frame_stack"])
    return venv
