"""Hyperparameters in rl-zoo3's YAML format, keyed by env id (``train/configs/ppo.yaml``).

The keys rl-zoo3 reads are read here with the same meaning, so the file serves both::

    PersonFollow-v0:
      policy: MlpPolicy
      n_envs: 48                # all lanes; follow-train splits them evenly over the scenarios
      n_timesteps: !!float 4e6
      normalize: {norm_obs: true, norm_reward: true}   # VecNormalize kwargs, or true / false
      frame_stack: 4            # VecFrameStack over the normalised observation
      vec_env_wrapper:          # applied in order, innermost first, below VecNormalize
        - train.wrappers.VecRescaleAction: {w_max_radps: 2.0}
      policy_kwargs: {net_arch: [64, 64]}
      learning_rate: lin_3e-4   # a float, or lin_<x>: linear decay from x to 0
      n_steps: 64               # ... and any other PPO argument
      env_kwargs: {platform: mecanum}   # gym.make keyword arguments (default: none)

rl-zoo3 ``eval``-uates strings for ``normalize`` and ``policy_kwargs``; here they are YAML
mappings (rl-zoo3 accepts those too), and nothing is evaluated. ``env_kwargs`` are the env's
``gym.make`` keyword arguments, as rl-zoo3 saves them with an agent (for its ``train``, give them
as ``--env-kwargs``): ``platform`` names the robot the agent is trained for (a registered
platform, default the preset's, the differential drive); ``scenario`` and ``config`` are
follow-train's own (``--scenarios``, ``--env-config``) and may not be set here. The platform
decides the action's width and names, which the per-action settings must fit
(:func:`check_action_fit`). Project settings that are not
hyperparameters (scenarios, seeds, evaluation and checkpoint intervals) are ``follow-train``
options (:class:`train.ppo.Args`).

Every key is checked here, before anything is built or written: its type, its range, and the
constraints stable-baselines3 asserts later (``batch_size`` > 1 and at most ``n_steps *
n_envs``), so a bad file fails in one line naming the key, the value and what it may be, not
with a traceback (or a NaN) in the middle of training. The rules are :data:`PPO_RULES`;
``policy_kwargs`` must be arguments of the policy class, and each ``vec_env_wrapper`` entry a
``VecEnvWrapper`` whose keyword arguments its constructor takes (the constructors check the
values when the agent's env is built, still before anything is written).
"""

from __future__ import annotations

import importlib
import inspect
import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import yaml

__all__ = [
    "PPO_RULES",
    "ConfigError",
    "Hyperparams",
    "check_action_fit",
    "import_object",
    "load_hyperparams",
    "parse_hyperparams",
    "policy_class",
    "schedule",
    "wrapper_specs",
]

# Keys rl-zoo3 consumes itself; the rest go to the PPO constructor.
ZOO_KEYS = (
    "policy",
    "n_envs",
    "n_timesteps",
    "normalize",
    "frame_stack",
    "vec_env_wrapper",
    "env_kwargs",
)
# gym.make keyword arguments follow-train sets itself (--scenarios, --env-config; no rendering).
_ENV_KWARGS_OWN = ("scenario", "config", "render_mode")
POLICIES = ("MlpPolicy",)  # or a dotted name of an ActorCriticPolicy subclass

Hyperparams = dict[str, Any]


class ConfigError(ValueError):
    """A hyperparameter file that cannot be used; the message names the file and the key."""


# -- Checks of one value: each returns the value as stored, or raises naming key and range ---


def _fail(where: str, key: str, value: Any, rule: str) -> ConfigError:
    return ConfigError(f"{where}: {key}={value!r} is out of range: must be {rule}")


def _integer(where: str, key: str, value: Any, low: int) -> int:
    """An integer >= ``low``; an integral float (YAML's ``!!float 4e6``) counts as one."""
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise _fail(where, key, value, f"an integer >= {low}")
    return value


def _number(
    where: str, key: str, value: Any, low: float, high: float = math.inf, *, open_low: bool = False
) -> float:
    """A finite number in ``[low, high]`` (``(low, high]`` with ``open_low``)."""
    above = (value > low if open_low else value >= low) if _is_number(value) else False
    if not (above and value <= high and math.isfinite(value)):
        left = "(" if open_low else "["
        rule = f"a number {'>' if open_low else '>='} {low:g}"
        if low == -math.inf:
            rule = "a finite number"
        elif high < math.inf:
            rule = f"a number in {left}{low:g}, {high:g}]"
        raise _fail(where, key, value, rule)
    return value


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _flag(where: str, key: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise _fail(where, key, value, "true or false")
    return value


def _positive_schedule(where: str, key: str, value: Any) -> Any:
    schedule(value, where=f"{where}: {key}")
    return value


def _optional(check: Callable[[str, str, Any], Any]) -> Callable[[str, str, Any], Any]:
    def check_or_none(where: str, key: str, value: Any) -> Any:
        return None if value is None else check(where, key, value)

    return check_or_none


def _unsupported(where: str, key: str, value: Any) -> Any:
    if value not in (None, {}):
        raise ConfigError(
            f"{where}: {key}={value!r} is not supported by follow-train (SB3 wants a class, "
            "which a YAML file cannot give); leave it out"
        )
    return value


#: Every PPO argument a hyperparameter file may set, with its check (SB3's meaning and default).
PPO_RULES: dict[str, Callable[[str, str, Any], Any]] = {
    "learning_rate": _positive_schedule,  # > 0, or lin_<x> with x > 0
    "n_steps": lambda w, k, v: _integer(w, k, v, 1),  # steps per lane per update
    "batch_size": lambda w, k, v: _integer(w, k, v, 1),  # also 2 .. n_steps * n_envs, below
    "n_epochs": lambda w, k, v: _integer(w, k, v, 1),
    "gamma": lambda w, k, v: _number(w, k, v, 0.0, 1.0),  # discount per 0.1 s step
    "gae_lambda": lambda w, k, v: _number(w, k, v, 0.0, 1.0),
    "clip_range": _positive_schedule,
    "clip_range_vf": _optional(_positive_schedule),
    "normalize_advantage": _flag,
    "ent_coef": lambda w, k, v: _number(w, k, v, 0.0),
    "vf_coef": lambda w, k, v: _number(w, k, v, 0.0),
    "max_grad_norm": lambda w, k, v: _number(w, k, v, 0.0, open_low=True),
    "use_sde": _flag,
    "sde_sample_freq": lambda w, k, v: _integer(w, k, v, -1),  # -1: only at rollout start
    "rollout_buffer_class": _unsupported,
    "rollout_buffer_kwargs": _unsupported,
    "target_kl": _optional(lambda w, k, v: _number(w, k, v, 0.0, open_low=True)),
    "stats_window_size": lambda w, k, v: _integer(w, k, v, 1),
}

# VecNormalize's arguments (``normalize: {...}``), as SB3 documents them.
_NORMALIZE_RULES: dict[str, Callable[[str, str, Any], Any]] = {
    "norm_obs": _flag,
    "norm_reward": _flag,
    "clip_obs": lambda w, k, v: _number(w, k, v, 0.0, open_low=True),
    "clip_reward": lambda w, k, v: _number(w, k, v, 0.0, open_low=True),
    "gamma": lambda w, k, v: _number(w, k, v, 0.0, 1.0),
    "epsilon": lambda w, k, v: _number(w, k, v, 0.0, open_low=True),
}

# ActorCriticPolicy arguments PPO sets itself: a policy_kwargs entry would clash.
_SET_BY_PPO = ("observation_space", "action_space", "lr_schedule", "use_sde")
# Policy arguments that are classes: not expressible in YAML (strings are not evaluated).
_CLASS_ARGUMENTS = ("activation_fn", "features_extractor_class", "optimizer_class")
_POLICY_FLAGS = (
    "ortho_init",
    "full_std",
    "use_expln",
    "squash_output",
    "share_features_extractor",
    "normalize_images",
)


def _sb3_defaults() -> dict[str, Any]:
    from stable_baselines3 import PPO

    parameters = inspect.signature(PPO.__init__).parameters
    return {name: p.default for name, p in parameters.items() if name in PPO_RULES}


def _document(path: Path) -> Any:
    """The parsed hyperparameter file (one-line errors naming it)."""
    try:
        return yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as e:
        raise ConfigError(f"{path}: cannot read hyperparameters: {e.strerror or e}") from None
    except yaml.YAMLError as e:
        raise ConfigError(f"{path}: not valid YAML: {' '.join(str(e).split())}") from None


def sole_section(path: str | Path) -> str:
    """The env id of a hyperparameter file with one section (the usual case).

    :raises ConfigError: if the file is unreadable or has several sections (name one).
    """
    path = Path(path)
    document = _document(path)
    if not isinstance(document, dict) or len(document) != 1:
        found = ", ".join(map(str, document)) if isinstance(document, dict) else "nothing"
        raise ConfigError(f"{path}: one section expected (found: {found}); give --env-id")
    return str(next(iter(document)))


def load_hyperparams(
    path: str | Path, env_id: str, overrides: Mapping[str, Any] | None = None
) -> Hyperparams:
    """Read the hyperparameters for ``env_id`` from an rl-zoo3-style YAML file and check them.

    :param overrides: values given on the command line (``n_envs``, ``n_timesteps``); they
        replace the file's and are named as options in messages.
    :raises ConfigError: if the file is missing or unreadable, has no section ``env_id``, or a
        key or value is not understood (the message names the file and the key).
    """
    path = Path(path)
    document = _document(path)
    if not isinstance(document, dict) or env_id not in document:
        found = ", ".join(map(str, document)) if isinstance(document, dict) else "nothing"
        raise ConfigError(f"{path}: no section {env_id!r} (found: {found})")
    return parse_hyperparams(document[env_id], where=f"{path} [{env_id}]", overrides=overrides)


def parse_hyperparams(
    section: Mapping[str, Any],
    *,
    where: str = "hyperparameters",
    overrides: Mapping[str, Any] | None = None,
) -> Hyperparams:
    """Check one env's hyperparameters (a mapping as in the YAML file) and return a copy.

    Defaults are filled in for rl-zoo3's keys (``policy`` MlpPolicy, ``normalize`` false,
    ``frame_stack`` 1, no wrappers, no ``policy_kwargs``; no ``env_kwargs`` is none); PPO's
    own defaults stay SB3's.

    :param section: the mapping under the env id.
    :param where: names the source in error messages.
    :param overrides: command-line values replacing the section's (named ``--n-envs`` etc.).
    :raises ConfigError: on a missing, unknown, ill-typed or out-of-range key.
    """
    if not isinstance(section, Mapping):
        raise ConfigError(f"{where}: must be a mapping of hyperparameters")
    overrides = dict(overrides or {})
    hp = dict(section) | overrides

    def name(key: str) -> str:
        return "--" + key.replace("_", "-") if key in overrides else key

    for key in ("n_envs", "n_timesteps"):
        if key not in hp:
            raise ConfigError(f"{where}: {key} is missing")
        hp[key] = _integer(where, name(key), hp[key], 1)
    hp.setdefault("policy", "MlpPolicy")
    policy = policy_class(hp["policy"], where=where)
    hp["normalize"] = _check_normalize(where, hp.setdefault("normalize", False))
    hp["frame_stack"] = _integer(where, "frame_stack", hp.setdefault("frame_stack", 1), 1)
    _check_policy_kwargs(where, policy, hp.setdefault("policy_kwargs", {}))
    wrapper_specs(hp.setdefault("vec_env_wrapper", []), where=where)
    if "env_kwargs" in hp:
        hp["env_kwargs"] = _check_env_kwargs(where, hp["env_kwargs"])
    unknown = sorted(set(hp) - set(ZOO_KEYS) - {"policy_kwargs"} - set(PPO_RULES))
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {', '.join(unknown)}")
    for key, check in PPO_RULES.items():
        if key in hp:
            hp[key] = check(where, key, hp[key])
    _check_batch(where, hp, name)
    return hp


def _check_batch(where: str, hp: Hyperparams, name: Callable[[str], str]) -> None:
    """SB3's own constraints on the rollout buffer, checked before SB3 asserts them."""
    defaults = _sb3_defaults()
    n_steps = hp.get("n_steps", defaults["n_steps"])
    batch_size = hp.get("batch_size", defaults["batch_size"])
    buffer = n_steps * hp["n_envs"]
    # SB3 normalises advantages per mini-batch (a standard deviation needs 2 samples).
    smallest = 2 if hp.get("normalize_advantage", defaults["normalize_advantage"]) else 1
    lanes = f" (n_envs from {name('n_envs')})" if name("n_envs") != "n_envs" else ""
    if buffer < smallest:
        raise ConfigError(
            f"{where}: n_steps * n_envs = {n_steps} * {hp['n_envs']} is out of range: must be "
            f">= 2 while normalize_advantage is true{lanes}"
        )
    if not smallest <= batch_size <= buffer:
        raise ConfigError(
            f"{where}: batch_size={batch_size} is out of range: must be in [{smallest}, "
            f"n_steps * n_envs = {n_steps} * {hp['n_envs']} = {buffer}]{lanes}"
        )


def platform_label(platform: Any) -> str | None:
    """``env_kwargs.platform`` for people: ``mecanum``, or ``mecanum (drive.mode=pid)`` for a
    mapping with section overrides; None when the run names no platform."""
    if not isinstance(platform, Mapping):
        return platform
    flat = [
        f"{section}.{key}={value}"
        for section, fields in platform.items()
        if section != "name"
        for key, value in (fields.items() if isinstance(fields, Mapping) else [("", fields)])
    ]
    return f"{platform['name']} ({', '.join(flat)})" if flat else str(platform["name"])


def _check_env_kwargs(where: str, value: Any) -> dict[str, Any]:
    """``env_kwargs``: a mapping of ``gym.make`` keyword arguments; ``platform`` a registered
    platform's name (the other values are the env's to check when it is built)."""
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise ConfigError(
            f"{where}: env_kwargs={value!r} must be a mapping of gym.make keyword arguments"
        )
    checked = dict(value)
    for key in checked:
        if key in _ENV_KWARGS_OWN:
            option = {"scenario": "--scenarios", "config": "--env-config"}.get(key)
            instead = f"give {option}" if option else "follow-train does not render"
            raise ConfigError(f"{where}: env_kwargs.{key} is set by follow-train ({instead})")
    if "platform" in checked:
        from follow_env.platforms import available_platforms
        from follow_env.tasks.config import named_platform

        platform = checked["platform"]
        name = platform.get("name") if isinstance(platform, Mapping) else platform
        if not isinstance(name, str) or name not in available_platforms():
            raise _fail(
                where,
                "env_kwargs.platform",
                platform,
                f"a platform's name ({', '.join(available_platforms())}) or a mapping with its "
                "'name' and section overrides",
            )
        try:
            named_platform("platform", platform)
        except ValueError as e:
            raise ConfigError(f"{where}: env_kwargs.platform: {e}") from None
    return checked


def check_action_fit(hp: Hyperparams, names: Any, *, where: str = "hyperparameters") -> None:
    """Check the settings that depend on the env's action against its entries ``names`` (the
    platform's, e.g. ``v_mps, vy_mps, w_radps``): the mirror policy's ``mirror_action`` must
    have one sign per entry, each its entry's reflection
    (:func:`policies.learned.mirror.check_mirror_action`). The wrappers check their own
    per-action arguments when they are built.

    :raises ConfigError: naming the file and the key.
    """
    signs = (hp.get("policy_kwargs") or {}).get("mirror_action")
    if signs is None or names is None:
        return
    from policies.learned.mirror import check_mirror_action

    try:
        check_mirror_action(signs, names, "policy_kwargs.mirror_action")
    except ValueError as e:
        platform = platform_label((hp.get("env_kwargs") or {}).get("platform"))
        on = f" (env_kwargs.platform: {platform})" if platform else ""
        raise ConfigError(f"{where}: {e}{on}") from None


def _check_normalize(where: str, value: Any) -> bool | dict[str, Any]:
    if isinstance(value, bool):
        return value
    if not isinstance(value, Mapping):
        raise ConfigError(
            f"{where}: normalize={value!r} must be true, false or a mapping of "
            "VecNormalize arguments (strings are not evaluated)"
        )
    checked = dict(value)
    for key, item in checked.items():
        rule = _NORMALIZE_RULES.get(key)
        if key == "norm_obs_keys":  # dict observation spaces only; ours is a Box
            _unsupported(where, f"normalize.{key}", item)
        elif rule is None:
            known = ", ".join([*_NORMALIZE_RULES, "norm_obs_keys"])
            raise ConfigError(f"{where}: normalize.{key} is not a VecNormalize argument ({known})")
        else:
            checked[key] = rule(where, f"normalize.{key}", item)
    return checked


def _accepted_arguments(cls: type) -> set[str]:
    """Keyword arguments ``cls(...)`` takes: its ``__init__``'s, and its bases' while it
    passes ``**kwargs`` on."""
    names: set[str] = set()
    for klass in cls.__mro__:
        if "__init__" not in vars(klass):
            continue
        parameters = inspect.signature(klass.__init__).parameters.values()
        names |= {p.name for p in parameters if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)}
        if not any(p.kind is p.VAR_KEYWORD for p in parameters):
            break
    return names - {"self"}


def _check_policy_kwargs(where: str, policy: Any, kwargs: Any) -> None:
    if not isinstance(kwargs, Mapping):
        raise ConfigError(f"{where}: policy_kwargs must be a mapping (strings are not evaluated)")
    from stable_baselines3.common.policies import ActorCriticPolicy

    cls = ActorCriticPolicy if isinstance(policy, str) else policy
    accepted = _accepted_arguments(cls) - set(_SET_BY_PPO)
    for key, value in kwargs.items():
        field = f"policy_kwargs.{key}"
        if key not in accepted:
            raise ConfigError(
                f"{where}: {field} is not an argument of {cls.__name__} "
                f"(accepted: {', '.join(sorted(accepted))})"
            )
        if key == "net_arch":
            _check_net_arch(where, value)
        elif key in _CLASS_ARGUMENTS:
            _unsupported(where, field, value)
        elif key in _POLICY_FLAGS:
            _flag(where, field, value)
        elif key == "log_std_init":
            _number(where, field, value, -math.inf)
        elif key.endswith("_kwargs") and not isinstance(value, Mapping | None):
            raise _fail(where, field, value, "a mapping")


def _check_net_arch(where: str, value: Any) -> None:
    def layers(item: Any) -> bool:
        return isinstance(item, list) and all(
            isinstance(n, int) and not isinstance(n, bool) and n >= 1 for n in item
        )

    if isinstance(value, Mapping):
        ok = set(value) <= {"pi", "vf"} and all(layers(v) for v in value.values())
    else:
        ok = layers(value)
    if not ok:
        raise _fail(
            where,
            "policy_kwargs.net_arch",
            value,
            "a list of layer sizes (integers >= 1), or {pi: [...], vf: [...]}",
        )


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
    """A number > 0, or rl-zoo3's ``"lin_<x>"`` (x > 0): ``x`` times SB3's progress_remaining
    (1 at the start of training, 0 at the end).

    :raises ConfigError: for anything else, e.g. 0, a negative number, NaN or ``"cos_3e-4"``.
    """
    start: float | None = None
    if _is_number(value):
        start = float(value)
    elif isinstance(value, str) and value.startswith("lin_"):
        try:
            start = float(value[4:])
        except ValueError:
            start = None
    if start is None or not (math.isfinite(start) and start > 0):
        raise ConfigError(
            f"{where}={value!r} is out of range: must be a number > 0, or 'lin_<number>' with "
            "the number > 0 (linear decay to 0)"
        )
    return start if _is_number(value) else _Linear(start)


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

    Entries are ``dotted.ClassName`` or ``{dotted.ClassName: {kwarg: value}}``. Each class must
    be an SB3 ``VecEnvWrapper`` whose constructor takes the given keyword arguments (the
    values are the constructor's to check).

    :raises ConfigError: for a malformed entry, a name that does not import, or an argument the
        class does not take (the message lists those it takes).
    """
    from stable_baselines3.common.vec_env import VecEnvWrapper

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
            cls = import_object(name)
        except (ImportError, AttributeError, ValueError) as e:
            raise ConfigError(f"{where}: vec_env_wrapper {name!r} does not import: {e}") from None
        if not (isinstance(cls, type) and issubclass(cls, VecEnvWrapper)):
            raise ConfigError(f"{where}: vec_env_wrapper {name!r} is not an SB3 VecEnvWrapper")
        accepted = _accepted_arguments(cls) - {"venv"}
        for key in kwargs:
            if key not in accepted:
                raise ConfigError(
                    f"{where}: vec_env_wrapper {name}: {key!r} is not one of its arguments "
                    f"(accepted: {', '.join(sorted(accepted)) or 'none'})"
                )
        specs.append((name, dict(kwargs)))
    return specs


def import_object(dotted: str) -> Any:
    """Import ``package.module.Name`` and return ``Name``."""
    module, _, attr = dotted.rpartition(".")
    if not module:
        raise ValueError(f"{dotted!r} is not a dotted name (package.module.Name)")
    return getattr(importlib.import_module(module), attr)
