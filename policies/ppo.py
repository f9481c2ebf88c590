"""A trained PPO agent (``follow-train``) behind the :class:`~policies.base.Policy` protocol.

``make_policy("ppo")`` is the shipped agent (``policies/agents/ppo``); ``make_policy(path)``
loads any other: a run folder (``runs/ppo-<timestamp>``), its ``model.zip``, or a checkpoint
(``runs/ppo-<timestamp>/checkpoints/ppo_<steps>_steps.zip``). An agent is three files:

- ``model.zip``: the SB3 PPO model;
- ``vecnormalize.pkl``: the observation normalisation statistics (a checkpoint has its own,
  ``ppo_vecnormalize_<steps>_steps.pkl``);
- ``config.yaml``: the run's resolved configuration, whose ``vec_env_wrapper`` list, ``frame_stack``
  and env spaces say how the agent sees the env.

The policy rebuilds the agent's view with the very wrappers training used
(:func:`train.envs.agent_env` in ``"inference"`` mode) around a one-lane VecEnv that it feeds
with the observations given to :meth:`PPOPolicy.act`. So the agent gets exactly the input it
was trained on (extra features, normalised with the saved statistics, which never update here;
stacked frames), acts deterministically (the mean of its Gaussian), and its action is mapped
back to SI ``[v_mps, w_radps]`` by the same wrappers. :meth:`PPOPolicy.reset` clears the
wrappers' memory (frame stack, command, observation age).

torch and stable-baselines3 load only when an agent is built; a loaded model is shared by the
policies built from the same files (each keeps its own memory).
"""

from __future__ import annotations

import re
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from policies.base import validate_obs

__all__ = [
    "DEFAULT_AGENT",
    "AgentFiles",
    "AgentLoadError",
    "PPOPolicy",
    "agent_files",
    "load_agent",
    "load_default",
    "resolve_path",
]

#: The shipped agent, trained by ``follow-train --export policies/agents/ppo``.
DEFAULT_AGENT = Path(__file__).parent / "agents" / "ppo"
MODEL = "model.zip"
NORMALIZATION = "vecnormalize.pkl"
CONFIG = "config.yaml"
_CHECKPOINT = re.compile(r"^(?P<prefix>.+)_(?P<steps>\d+)_steps\.zip$")


class AgentLoadError(ValueError):
    """A missing, corrupt or mismatched agent file; the message names the file."""


@dataclass(frozen=True)
class AgentFiles:
    """Where an agent's files are.

    :param model: the SB3 ``.zip``.
    :param normalization: the ``VecNormalize`` pickle that belongs to it.
    :param config: the run's ``config.yaml``.
    """

    model: Path
    normalization: Path
    config: Path


def agent_files(path: str | Path) -> AgentFiles:
    """Find an agent's files from a run folder, a ``model.zip`` or a checkpoint ``.zip``.

    :raises AgentLoadError: if ``path`` or the model file does not exist.
    """
    path = Path(path)
    if path.is_dir():
        return AgentFiles(path / MODEL, path / NORMALIZATION, path / CONFIG)
    if path.suffix != ".zip":
        raise AgentLoadError(f"{path}: no such agent (give a run folder or a .zip model file)")
    if not path.exists():
        raise AgentLoadError(f"{path}: model file not found")
    match = _CHECKPOINT.match(path.name)
    if match:  # checkpoints/ppo_<steps>_steps.zip: statistics beside it, config one level up
        stats = path.with_name(f"{match['prefix']}_vecnormalize_{match['steps']}_steps.pkl")
        config = path.parent / CONFIG
        return AgentFiles(path, stats, config if config.exists() else path.parent.parent / CONFIG)
    return AgentFiles(path, path.with_name(NORMALIZATION), path.with_name(CONFIG))


class _Loaded:
    """An agent's model and configuration, read once per process (keyed by file versions)."""

    def __init__(self, files: AgentFiles) -> None:
        from train.config import ConfigError, parse_hyperparams
        from train.run import read_config

        if not files.model.exists():
            raise AgentLoadError(f"{files.model}: model file not found")
        if not files.config.exists():
            raise AgentLoadError(f"{files.config}: the agent's config.yaml is missing")
        try:
            config = read_config(files.config)
            hp = parse_hyperparams(config["hyperparams"], where=str(files.config))
            spaces = config["env_spaces"]
        except (ValueError, ConfigError, KeyError, TypeError) as e:
            raise AgentLoadError(f"{files.config}: not a usable agent configuration: {e}") from None
        if hp["normalize"] and not files.normalization.exists():
            raise AgentLoadError(
                f"{files.normalization}: normalisation statistics not found (the config says "
                "the agent was trained on normalised observations)"
            )
        self.files, self.hp, self.spaces = files, hp, spaces
        self.model = self._load_model(files.model)

    @staticmethod
    def _load_model(path: Path) -> Any:
        from stable_baselines3 import PPO

        try:
            return PPO.load(path, device="cpu")
        except Exception as e:  # zipfile, pickle, torch and SB3 each raise their own
            raise AgentLoadError(
                f"{path}: not a readable stable-baselines3 PPO model ({type(e).__name__}: {e})"
            ) from None


_CACHE: dict[tuple, _Loaded] = {}
_CACHE_LOCK = threading.Lock()


def _loaded(files: AgentFiles) -> _Loaded:
    key = tuple(
        (str(p.resolve()), p.stat().st_mtime_ns if p.exists() else None)
        for p in (files.model, files.normalization, files.config)
    )
    with _CACHE_LOCK:
        if key not in _CACHE:
            _CACHE[key] = _Loaded(files)
        return _CACHE[key]


def _feed_env(spaces: dict[str, Any]) -> Any:
    """A one-lane SB3 VecEnv whose observations come from :meth:`PPOPolicy.act`."""
    from gymnasium import spaces as gym_spaces
    from stable_baselines3.common.vec_env import VecEnv

    def box(d: dict[str, list[float]]) -> gym_spaces.Box:
        return gym_spaces.Box(
            np.asarray(d["low"], np.float32), np.asarray(d["high"], np.float32), dtype=np.float32
        )

    class FeedVecEnv(VecEnv):
        def __init__(self) -> None:
            self.render_mode = None
            super().__init__(1, box(spaces["observation"]), box(spaces["action"]))
            self.obs = np.zeros((1, *self.observation_space.shape), np.float32)
            self.action = np.zeros((1, *self.action_space.shape), np.float32)

        def reset(self) -> np.ndarray:
            return self.obs.copy()

        def step_async(self, actions: np.ndarray) -> None:
            self.action = np.asarray(actions, dtype=np.float32).reshape(self.action.shape)

        def step_wait(self) -> Any:
            return self.obs.copy(), np.zeros(1, np.float32), np.zeros(1, bool), [{}]

        def close(self) -> None:
            pass

        def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
            return [getattr(self, attr_name)]

        def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
            setattr(self, attr_name, value)

        def env_method(self, method_name: str, *args: Any, indices: Any = None, **kw: Any) -> list:
            return [getattr(self, method_name)(*args, **kw)]

        def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
            return [False]

    return FeedVecEnv()


class PPOPolicy:
    """A trained agent as a :class:`~policies.base.Policy` (module docstring).

    :param path: a run folder, a ``model.zip`` or a checkpoint ``.zip``.
    :param name: the name in tables and logs (default: ``path`` as given).
    :raises AgentLoadError: for a missing, corrupt or mismatched file (naming it).
    """

    def __init__(self, path: str | Path, name: str | None = None) -> None:
        from train.envs import agent_env

        self.path = str(path)
        self.name = name if name is not None else self.path.rstrip("/")
        self._agent = _loaded(agent_files(path))
        files, hp = self._agent.files, self._agent.hp
        self._feed = _feed_env(self._agent.spaces)
        try:
            self._view = agent_env(self._feed, hp, "inference", normalization=files.normalization)
        except Exception as e:  # a statistics file of another shape, or not a pickle
            raise AgentLoadError(
                f"{files.normalization}: does not fit the agent in {files.config} "
                f"({type(e).__name__}: {e})"
            ) from None
        model = self._agent.model
        if model.observation_space.shape != self._view.observation_space.shape:
            raise AgentLoadError(
                f"{files.model}: expects observations of shape {model.observation_space.shape}, "
                f"but {files.config} builds {self._view.observation_space.shape}; the model and "
                "the configuration are from different runs"
            )
        if model.action_space.shape != self._view.action_space.shape:
            raise AgentLoadError(
                f"{files.model}: acts with shape {model.action_space.shape}, but {files.config} "
                f"expects {self._view.action_space.shape}"
            )
        self._started = False

    def reset(self) -> None:
        """Start a new episode: the next :meth:`act` resets the frame stack and the wrappers."""
        self._started = False

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Map ``[distance_m, offset_px]`` to ``[v_mps, w_radps]`` (deterministic).

        :raises ValueError: if ``obs`` is not a finite array of shape (2,).
        """
        distance_m, offset_px = validate_obs(obs)
        self._feed.obs[0] = (distance_m, offset_px)
        if self._started:
            agent_obs = self._view.step_wait()[0]
        else:
            agent_obs = self._view.reset()
            self._started = True
        action, _ = self._agent.model.predict(agent_obs, deterministic=True)
        self._view.step_async(action)
        return self._feed.action[0].copy()

    def __reduce__(self) -> tuple[Any, ...]:
        # A policy sent to a worker process is rebuilt there from its files (no torch pickling).
        return (PPOPolicy, (self.path, self.name))

    def __repr__(self) -> str:
        return f"PPOPolicy(name={self.name!r}, model={str(self._agent.files.model)!r})"


def load_agent(path: str | Path, name: str | None = None) -> PPOPolicy:
    """Build a :class:`PPOPolicy` from a run folder or a ``.zip`` (see :func:`agent_files`)."""
    return PPOPolicy(path, name)


def load_default() -> PPOPolicy:
    """The shipped agent, named ``"ppo"``."""
    return PPOPolicy(DEFAULT_AGENT, name="ppo")


def resolve_path(name: str) -> PPOPolicy | None:
    """Registry resolver: a name that is a path (a folder, ``*.zip``, or with a ``/``) -> agent.

    Other names are left to the registry (None), so a typo such as ``"pnn"`` still lists the
    known names, while ``"runs/typo"`` says which file is missing.
    """
    path = Path(name)
    if name.endswith(".zip") or "/" in name or path.is_dir():
        return PPOPolicy(path, name)
    return None
