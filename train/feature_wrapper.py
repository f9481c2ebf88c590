"""The training side of an agent's view: a feature step (:mod:`policies.learned.features`)
wrapped as an SB3 ``VecEnvWrapper``, so that training and inference run the same code.
:mod:`train.wrappers` lists the wrappers, one subclass per step."""

from __future__ import annotations

import inspect
from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvObs, VecEnvStepReturn

from policies.learned.feature import IN_TRAINING, Feature, split_in_training
from policies.learned.features import Box
from train.vecenvs import env_action_names

__all__ = ["FeatureWrapper"]


class FeatureWrapper(VecEnvWrapper):
    """A step of the agent's feature pipeline (:mod:`policies.learned.features`) as an SB3
    ``VecEnvWrapper``: the same code the policy runs at inference, wrapped for training. Each
    subclass's constructor takes ``venv`` and its feature's own arguments (its signature says
    which, for the hyperparameter checks), and ``in_training``: with ``False`` the wrapper
    passes observations and actions through, and the step acts only in the exported agent's view
    (:data:`policies.learned.feature.IN_TRAINING`; only for a step that keeps both shapes)."""

    feature_class: type[Feature]

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        params = list(inspect.signature(cls.feature_class.__init__).parameters.values())
        venv = inspect.Parameter("venv", inspect.Parameter.POSITIONAL_OR_KEYWORD)
        flag = inspect.Parameter(
            IN_TRAINING, inspect.Parameter.KEYWORD_ONLY, default=True, annotation=bool
        )

        def __init__(self: FeatureWrapper, venv: VecEnv, *args: Any, **kwargs: Any) -> None:  # noqa: N807
            FeatureWrapper._setup(self, venv, *args, **kwargs)

        __init__.__signature__ = inspect.Signature([params[0], venv, *params[1:], flag])  # type: ignore[attr-defined]
        __init__.__doc__ = cls.feature_class.__init__.__doc__
        cls.__init__ = __init__  # type: ignore[method-assign]

    def _setup(self, venv: VecEnv, *args: Any, **kwargs: Any) -> None:
        name = type(self).__name__
        obs_box, act_box = venv.observation_space, venv.action_space
        if not (isinstance(obs_box, spaces.Box) and isinstance(act_box, spaces.Box)):
            raise ValueError(f"{name} needs Box observation and action spaces")
        if len(obs_box.shape) != 1:
            raise ValueError(f"{name} needs a flat Box observation space")
        #: False: the step is the exported agent's, not the training env's (passes through).
        self.in_training, kwargs = split_in_training(kwargs, name)
        try:
            self.feature = self.feature_class(*args, **kwargs)
        except TypeError as e:
            raise ValueError(f"{name}: {e}") from None
        self.feature.owner = name
        names = env_action_names(venv)
        obs, act = self.feature.bind(
            Box(obs_box.low, obs_box.high), Box(act_box.low, act_box.high, names), venv.num_envs
        )
        if not self.in_training:
            if obs.shape != obs_box.shape or act.shape != act_box.shape or act.names != names:
                # Left out of training, a step that changes what the agent sees or does would
                # hand the exported agent a view it has never had the shape of.
                raise ValueError(
                    f"{name}.{IN_TRAINING}=False needs a step that keeps the observation and "
                    f"action shapes; {name} turns {obs_box.shape} / {act_box.shape} into "
                    f"{obs.shape} / {act.shape}"
                )
            # observations and actions pass through: the training env keeps its own boxes
            obs, act = Box(obs_box.low, obs_box.high), Box(act_box.low, act_box.high, names)
        super().__init__(
            venv,
            observation_space=spaces.Box(obs.low, obs.high, dtype=np.float32),
            action_space=spaces.Box(act.low, act.high, dtype=np.float32),
        )
        #: The action entries' names (the platform's; every feature keeps them).
        self.action_names = act.names

    def reset(self) -> VecEnvObs:
        obs = self.venv.reset()
        return self.feature.start(obs) if self.in_training else obs

    def step_async(self, actions: np.ndarray) -> None:
        self.venv.step_async(self.feature.act(actions) if self.in_training else actions)

    def step_wait(self) -> VecEnvStepReturn:
        obs, rewards, dones, infos = self.venv.step_wait()
        if not self.in_training:
            return obs, rewards, dones, infos
        for i in np.flatnonzero(dones):
            if "terminal_observation" in infos[i]:
                infos[i]["terminal_observation"] = self.feature.terminal(
                    infos[i]["terminal_observation"], i
                )
        return self.feature.observe(obs, np.asarray(dones, dtype=bool)), rewards, dones, infos
