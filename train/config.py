"""Hyperparameters in rl-zoo3's YAML format, keyed by env id (``train/configs/ppo.yaml``).

The keys rl-zoo3 reads are read here with the same meaning, so the file serves both::

    PersonFollow-v0:
      policy: MlpPolicy
      n_envs: 44                # all lanes; follow-train splits them evenly over the scenarios
      n_timesteps: !!float 4e6
      normalize: {norm_obs: true, norm_reward: true}   # VecNormalize kwargs, or true / false
      frame_stack: 4            # VecFrameStack over the normalised observation
      vec_env_wrapper:          # applied in order, innermost first, below VecNormalize
        - train.wrappers.VecRescaleAction: {w_max_radps: 2.0}
      policy_kwargs: {net_arch: [64, 64]}
      learning_rate: lin_3e-4   # a float, or lin_<x>: linear decay from x to 0
      n_steps: 64               # ... and any other PPO argument

rl-zoo3 ``eval``-uates strings for ``normalize`` and ``policy_kwargs``; here they are YAML
mappings (rl-zoo3 accepts those too), and nothing is evaluated. Project settings that are not
hyperparameters (scenarios, seeds, evaluation and checkpoint intervals) are ``follow-train``
options (:class:`train.ppo.Args`).
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import yaml

__all__ = [
    "ConfigError",
    "Hyperparams",
    "import_object",
    "load_hyperparams",
    "parse_hyperparams",
    "policy_class",
    "schedule",
    "wrapper_specs",
]

# Keys rl-zoo3 consumes itself; the rest go to the PPO constructor.
ZOO_KEYS = ("policy", "n_envs", "n_timesteps", "normalize", "frame_stack", "vec_env_wrapper")
POLICIES = ("MlpPolicy",)  # or a dotted name of an ActorCriticPolicy subclass

Hyperparams = dict[str, Any]


class ConfigError(ValueError):
    """A hyperparameter file that cannot be used; the message names the file and the key."""


def _ppo_arguments() -> set[str]:
    from stable_baselines3 import PPO

    names = set(inspect.signature(PPO.__init__).parameters)
    return names - {"self", "policy", "env", "tensorboard_log", "verbose", "seed", "device"}


def sole_section(path: str | Path) -> str:
    """The env id of a hyperparameter file with one section (the usual case).

    :raises ConfigError: if the file is unreadable or has several sections (name one).
    """
    path = Path(path)
    try:
        document = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as e:
        raise ConfigError(f"{path}: cannot read hyperparameters: {e.strerror or e}") from None
    except yaml.YAMLError as e:
        raise ConfigError(f"{path}: not valid YAML: {e}") from None
    if not isinstance(document, dict) or len(document) != 1:
        found = ", ".join(map(str, document)) if isinstance(document, dict) else "nothing"
        raise ConfigError(f"{path}: one section expected (found: {found}); give --env-id")
    return str(next(iter(document)))


def load_hyperparams(path: str | Path, env_id: str) -> Hyperparams:
    """Read the hyperparameters for ``env_id`` from an rl-zoo3-style YAML file and check them.

    :raises ConfigError: if the file is missing or unreadable, has no section ``env_id``, or a
        key or value is not understood (the message names the file and the key).
    """
    path = Path(path)
    try:
        document = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as e:
        raise ConfigError(f"{path}: cannot read hyperparameters: {e.strerror or e}") from None
    except yaml.YAMLError as e:
        raise ConfigError(f"{path}: not valid YAML: {e}") from None
    if not isinstance(document, dict) or env_id not in document:
        found = ", ".join(map(str, document)) if isinstance(document, dict) else "nothing"
        raise ConfigError(f"{path}: no section {env_id!r} (found: {found})")
    return parse_hyperparams(document[env_id], where=f"{path} [{env_id}]")


def parse_hyperparams(section: Mapping[str, Any], *, where: str = "hyperparameters") -> Hyperparams:
    """Check one env's hyperparameters (a mapping as in the YAML file) and return a copy.

    :param section: the mapping under the env id.
    :param where: names the source in error messages.
    :raises ConfigError: on a missing, unknown or ill-typed key.
    """
    if not isinstance(section, Mapping):
        raise ConfigError(f"{where}: must be a mapping of hyperparameters")
    hp = dict(section)
    for key in ("n_envs", "n_timesteps"):
        if key not in hp:
            raise ConfigError(f"{where}: {key} is missing")
        value = hp[key]
        if isinstance(value, float) and value.is_integer():
            value = int(value)  # YAML's !!float 4e6
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ConfigError(f"{where}: {key}={hp[key]!r} is out of range: must be an int >= 1")
        hp[key] = value
    hp.setdefault("policy", "MlpPolicy")
    if hp["policy"] not in POLICIES:
        policy_class(hp["policy"], where=where)
    normalize = hp.setdefault("normalize", False)
    if not isinstance(normalize, bool | Mapping):
        raise ConfigError(
            f"{where}: normalize={normalize!r} must be true, false or a mapping of "
            "VecNormalize arguments (strings are not evaluated)"
        )
    stack = hp.setdefault("frame_stack", 1)
    if isinstance(stack, bool) or not isinstance(stack, int) or stack < 1:
        raise ConfigError(f"{where}: frame_stack={stack!r} is out of range: must be an int >= 1")
    if not isinstance(hp.setdefault("policy_kwargs", {}), Mapping):
        raise ConfigError(f"{where}: policy_kwargs must be a mapping (strings are not evaluated)")
    wrapper_specs(hp.setdefault("vec_env_wrapper", []), where=where)
    unknown = sorted(set(hp) - set(ZOO_KEYS) - {"policy_kwargs"} - _ppo_arguments())
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {', '.join(unknown)}")
    for key in ("learning_rate", "clip_range"):
        if key in hp:
            schedule(hp[key], where=f"{where}: {key}")
    return hp


def policy_class(name: str, *, where: str = "policy") -> Any:
    """``"MlpPolicy"``, or the class a dotted name imports (an SB3 ``ActorCriticPolicy``).

    :raises ConfigError: if the name does not import or is no actor-critic policy.
    """
    if name in POLICIES:
        return name
    from stable_baselines3.common.policies import ActorCriticPolicy

    try:
        cls = import_object(str(name))
    except (ImportError, AttributeError, ValueError) as e:
        raise ConfigError(f"{where}: policy {name!r} does not import: {e}") from None
    if not (isinstance(cls, type) and issubclass(cls, ActorCriticPolicy)):
        raise ConfigError(f"{where}: policy {name!r} is not an SB3 ActorCriticPolicy")
    return cls


def schedule(value: Any, *, where: str = "schedule") -> float | Callable[[float], float]:
    """A float, or rl-zoo3's ``"lin_<x>"``: ``x`` times SB3's progress_remaining (1 -> 0).

    :raises ConfigError: for anything else.
    """
    if isinstance(value, int | float) and not isinstance(value, bool):
        return float(value)
    if isinstance(value, str) and value.startswith("lin_"):
        try:
            start = float(value[4:])
        except ValueError:
            pass
        else:
            return _Linear(start)
    raise ConfigError(f"{where}={value!r} must be a number or 'lin_<number>'")


class _Linear:
    """``start * progress_remaining``: a picklable linear schedule (SB3 saves schedules)."""

    def __init__(self, start: float) -> None:
        self.start = start

    def __call__(self, progress_remaining: float) -> float:
        return self.start * progress_remaining

    def __repr__(self) -> str:
        return f"lin_{self.start:g}"


def wrapper_specs(value: Any, *, where: str = "vec_env_wrapper") -> list[tuple[str, dict]]:
    """rl-zoo3's wrapper list as ``[(dotted.name, kwargs), ...]``; each class is imported.

    Entries are ``dotted.ClassName`` or ``{dotted.ClassName: {kwarg: value}}``.

    :raises ConfigError: for a malformed entry or a name that does not import.
    """
    entries = value if isinstance(value, list) else [value] if value else []
    specs = []
    for entry in entries:
        if isinstance(entry, str):
            name, kwargs = entry, {}
        elif isinstance(entry, Mapping) and len(entry) == 1:
            name, kwargs = next(iter(entry.items()))
            kwargs = {} if kwargs is None else kwargs
        else:
            raise ConfigError(f"{where}: vec_env_wrapper entry {entry!r} is malformed")
        if not isinstance(name, str) or not isinstance(kwargs, Mapping):
            raise ConfigError(f"{where}: vec_env_wrapper entry {entry!r} is malformed")
        try:
            import_object(name)
        except (ImportError, AttributeError, ValueError) as e:
            raise ConfigError(f"{where}: vec_env_wrapper {name!r} does not import: {e}") from None
        specs.append((name, dict(kwargs)))
    return specs


def import_object(dotted: str) -> Any:
    """Import ``package.module.Name`` and return ``Name``."""
    module, _, attr = dotted.rpartition(".")
    if not module:
        raise ValueError(f"{dotted!r} is not a dotted name (package.module.Name)")
    return getattr(importlib.import_module(module), attr)
