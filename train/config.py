"""Hyperparameters in rl-zoo3's YAML format, keyed by env id (``train/configs/<algo>.yaml``).

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
      n_steps: 64               # ... and any other argument of the algorithm
      env_kwargs: {platform: mecanum}   # gym.make keyword arguments (default: none)

A file is read for one algorithm (``follow-train --algo``, :mod:`train.algos`): PPO
(``ppo.yaml``), sb3-contrib's RecurrentPPO (``recurrent_ppo.yaml``, policy ``MlpLstmPolicy``) or
SAC (``sac.yaml``). The rl-zoo3 keys above are the same for all three; the rest of the section
are arguments of the algorithm's constructor, and each algorithm has its own table of those it
takes (:data:`train.algos.PPO_RULES`, ``RECURRENT_PPO_RULES``, ``SAC_RULES``): a SAC file may
set ``buffer_size`` or ``tau`` and not ``n_epochs``, a PPO file the reverse.

rl-zoo3 ``eval``-uates strings for ``normalize`` and ``policy_kwargs``; here they are YAML
mappings (rl-zoo3 accepts those too), and nothing is evaluated. ``env_kwargs`` are the env's
``gym.make`` keyword arguments, as rl-zoo3 saves them with an agent (for its ``train``, give them
as ``--env-kwargs``): ``platform`` names the robot the agent is trained for (a registered
platform, default the preset's, the differential drive); ``scenario`` and ``config`` are
follow-train's own (``--scenarios``, ``--env-config``) and may not be set here. The platform
decides the action's width and names, which the per-action settings must fit
(:func:`check_action_fit`). Project settings that are not hyperparameters (scenarios, seeds,
evaluation and checkpoint intervals) are ``follow-train`` options (:class:`train.ppo.Args`).

Every key is checked here, before anything is built or written: its type, its range (SB3's
meaning of it for the algorithm), and the constraints stable-baselines3 asserts later, each
algorithm's own (PPO: ``batch_size`` > 1 and at most ``n_steps * n_envs``; RecurrentPPO: the
same, and no last mini-batch of one step; SAC: ``batch_size`` at most ``buffer_size``, at least
one transition per lane, episodic ``train_freq`` with one lane only), so a bad file fails in one
line naming the key, the value and what it may be, not with a traceback (or a NaN) in the middle
of training. ``policy`` must be one of the algorithm's (PPO's custom
``train.mirror.MirrorMlpPolicy`` is PPO's only); ``policy_kwargs`` must be arguments of the
policy class, and each ``vec_env_wrapper`` entry a ``VecEnvWrapper`` whose keyword arguments
its constructor takes (the constructors check the values when the agent's env is built, still
before anything is written).
"""

from __future__ import annotations

import importlib
import inspect
import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import yaml

from follow_env.sim.checks import load_yaml, utf8_problem, yaml_problem
from policies.learned.feature import wrapper_entries
from train.algos import DEFAULT_ALGO, PPO_RULES, Algo, algo, shipped_hint
from train.rules import (
    ConfigError,
    _Linear,  # noqa: F401  (models saved with a lin_ schedule name it here)
    fail,
    flag,
    integer,
    net_arch,
    normalize_gamma,
    number,
    schedule,
    unsupported,
)

__all__ = [
    "PPO_RULES",
    "ConfigError",
    "Hyperparams",
    "check_action_fit",
    "import_object",
    "load_hyperparams",
    "parse_hyperparams",
    "policy_class",
    "read_document",
    "schedule",
    "wrapper_specs",
]

#: The most frames an agent may stack: 1,000 control steps (33 s at 30 Hz) is far beyond any
#: use; 10**9 once filled the memory building the env, before any check could say why.
MAX_FRAME_STACK = 1_000

# Keys rl-zoo3 consumes itself; the rest go to the algorithm's constructor.
ZOO_KEYS = (
    "policy",
    "n_envs",
    "n_timesteps",
    "normalize",
    "frame_stack",
    "vec_env_wrapper",
    "env_kwargs",
)
# Keys rl-zoo3 reads that follow-train does not, and why (refused by name, not as "not PPO
# arguments": the file is rl-zoo3's format, and its reader should learn what to do instead).
_ZOO_KEYS_REFUSED = {
    "env_wrapper": "the lanes are one batched env, not Gymnasium envs to wrap one by one; list "
    "VecEnvWrappers under vec_env_wrapper",
    "callback": "follow-train sets its own callbacks (checkpoints, the held-out evaluation)",
    "monitor_kwargs": "the VecMonitor below the wrappers logs the env's own returns",
    "noise_type": "action noise cannot be set (SAC explores by its entropy)",
    "noise_std": "action noise cannot be set (SAC explores by its entropy)",
}
# gym.make keyword arguments follow-train sets itself (--scenarios, --env-config; no rendering).
_ENV_KWARGS_OWN = ("scenario", "config", "render_mode")

Hyperparams = dict[str, Any]


# VecNormalize's arguments (``normalize: {...}``), as SB3 documents them.
_NORMALIZE_RULES: dict[str, Callable[[str, str, Any], Any]] = {
    "norm_obs": flag,
    "norm_reward": flag,
    "clip_obs": lambda w, k, v: number(w, k, v, 0.0, open_low=True),
    "clip_reward": lambda w, k, v: number(w, k, v, 0.0, open_low=True),
    "gamma": lambda w, k, v: number(w, k, v, 0.0, 1.0),
    "epsilon": lambda w, k, v: number(w, k, v, 0.0, open_low=True),
}

# Policy arguments the algorithm sets itself: a policy_kwargs entry would clash.
_SET_BY_ALGO = ("observation_space", "action_space", "lr_schedule", "use_sde")
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


def read_document(path: str | Path) -> Any:
    """The parsed hyperparameter file (one-line errors naming it).

    :raises ConfigError: if the file is unreadable, not UTF-8 text or not YAML, or gives a key
        twice in one mapping.
    """
    path = Path(path)
    try:
        return load_yaml(path.read_text(encoding="utf-8"))
    except OSError as e:
        why = f"{e.strerror or e}{shipped_hint(path, e)}"
        raise ConfigError(f"{path}: cannot read hyperparameters: {why}") from None
    except UnicodeDecodeError as e:
        raise ConfigError(f"{path}: {utf8_problem(e)}") from None
    except yaml.YAMLError as e:
        raise ConfigError(f"{path}: not valid YAML: {yaml_problem(e)}") from None


def sole_section(path: str | Path) -> str:
    """The env id of a hyperparameter file with one section (the usual case).

    :raises ConfigError: if the file is unreadable or has several sections (name one).
    """
    path = Path(path)
    document = read_document(path)
    if not isinstance(document, dict):
        kind = "nothing" if document is None else f"a {type(document).__name__}"
        raise ConfigError(
            f"{path}: holds {kind}, not rl-zoo3 hyperparameters (a mapping of env ids, e.g. "
            "PersonFollow-v0: {...})"
        )
    if len(document) != 1:
        found = ", ".join(map(str, document)) or "nothing"
        raise ConfigError(f"{path}: one section expected (found: {found}); give --env-id")
    return str(next(iter(document)))


def load_hyperparams(
    path: str | Path,
    env_id: str,
    overrides: Mapping[str, Any] | None = None,
    *,
    algo: str = DEFAULT_ALGO,
) -> Hyperparams:
    """Read the hyperparameters for ``env_id`` from an rl-zoo3-style YAML file and check them
    as arguments of the algorithm ``algo`` (:data:`train.algos.ALGOS`).

    :param overrides: values given on the command line (``n_envs``, ``n_timesteps``); they
        replace the file's and are named as options in messages.
    :raises ConfigError: if the file is missing or unreadable, has no section ``env_id``, or a
        key or value is not understood (the message names the file and the key).
    """
    path = Path(path)
    document = read_document(path)
    if not isinstance(document, dict) or env_id not in document:
        found = ", ".join(map(str, document)) if isinstance(document, dict) else "nothing"
        raise ConfigError(f"{path}: no section {env_id!r} (found: {found})")
    where = f"{path} [{env_id}]"
    return parse_hyperparams(document[env_id], where=where, overrides=overrides, algo=algo)


def parse_hyperparams(
    section: Mapping[str, Any],
    *,
    where: str = "hyperparameters",
    overrides: Mapping[str, Any] | None = None,
    algo: str = DEFAULT_ALGO,
) -> Hyperparams:
    """Check one env's hyperparameters (a mapping as in the YAML file) and return a copy.

    Defaults are filled in for rl-zoo3's keys (``policy`` the algorithm's MLP policy,
    ``normalize`` false, ``frame_stack`` 1, no wrappers, no ``policy_kwargs``; no
    ``env_kwargs`` is none); the algorithm's own defaults stay SB3's.

    :param section: the mapping under the env id.
    :param where: names the source in error messages.
    :param overrides: command-line values replacing the section's (named ``--n-envs`` etc.).
    :param algo: the learner, ``ppo``, ``recurrent_ppo`` or ``sac``: its rule table says which
        keys the section may set (:mod:`train.algos`).
    :raises ConfigError: on a missing, unknown, ill-typed or out-of-range key.
    """
    learner = _algo(algo, where)
    if not isinstance(section, Mapping):
        raise ConfigError(f"{where}: must be a mapping of hyperparameters")
    overrides = dict(overrides or {})
    hp = dict(section) | overrides

    def name(key: str) -> str:
        return "--" + key.replace("_", "-") if key in overrides else key

    for key in ("n_envs", "n_timesteps"):
        if key not in hp:
            raise ConfigError(f"{where}: {key} is missing")
        hp[key] = integer(where, name(key), hp[key], 1)
    hp.setdefault("policy", learner.policies[0])
    policy = policy_class(hp["policy"], where=where, algo=learner.name)
    hp["normalize"] = _check_normalize(where, hp.setdefault("normalize", False))
    normalize_gamma(where, hp)
    frames = hp.setdefault("frame_stack", 1)
    hp["frame_stack"] = integer(where, "frame_stack", frames, 1, MAX_FRAME_STACK)
    if hp.setdefault("policy_kwargs", {}) is None:  # SB3's and rl-zoo3's "none given"
        hp["policy_kwargs"] = {}
    _check_policy_kwargs(where, learner, policy, hp["policy_kwargs"])
    specs = wrapper_specs(hp.setdefault("vec_env_wrapper", []), where=where)
    _refuse_double_stack(where, hp["frame_stack"], specs)
    _check_privileged(where, hp, specs)
    if "env_kwargs" in hp:
        hp["env_kwargs"] = _check_env_kwargs(where, hp["env_kwargs"])
    unknown = sorted(set(hp) - set(ZOO_KEYS) - {"policy_kwargs"} - set(learner.rules))
    for key in unknown:
        if key in _ZOO_KEYS_REFUSED:
            raise ConfigError(
                f"{where}: {key}={hp[key]!r} is an rl-zoo3 key follow-train does not take: "
                f"{_ZOO_KEYS_REFUSED[key]}; leave it out"
            )
    if unknown:
        raise ConfigError(
            f"{where}: unknown key(s) {', '.join(unknown)} (not {learner.label} arguments)"
        )
    for key, check in learner.rules.items():
        if key in hp:
            hp[key] = check(where, key, hp[key])
    learner.check_batch(where, hp, name, learner.defaults())
    return hp


def _algo(name: str, where: str) -> Algo:
    try:
        return algo(name)
    except ConfigError as e:
        raise ConfigError(f"{where}: {e}") from None


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
            raise fail(
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
            unsupported(where, f"normalize.{key}", item)
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


def _check_policy_kwargs(where: str, learner: Algo, policy: Any, kwargs: Any) -> None:
    if not isinstance(kwargs, Mapping):
        raise fail(
            where,
            "policy_kwargs",
            kwargs,
            "a mapping of the policy's arguments (strings are not evaluated)",
        )
    cls = learner.base_policy() if isinstance(policy, str) else policy
    accepted = _accepted_arguments(cls) - set(_SET_BY_ALGO)
    for key, value in kwargs.items():
        field = f"policy_kwargs.{key}"
        if key not in accepted:
            raise ConfigError(
                f"{where}: {field} is not an argument of {cls.__name__} "
                f"(accepted: {', '.join(sorted(accepted))})"
            )
        if key == "net_arch":
            net_arch(where, value, learner.net_arch_keys)
        elif key in learner.policy_rules:
            learner.policy_rules[key](where, field, value)
        elif key in _CLASS_ARGUMENTS:
            unsupported(where, field, value)
        elif key in _POLICY_FLAGS:
            flag(where, field, value)
        elif key == "log_std_init":
            number(where, field, value, -math.inf)
        elif key.endswith("_kwargs") and not isinstance(value, Mapping | None):
            raise fail(where, field, value, "a mapping")


def policy_class(name: str, *, where: str = "policy", algo: str = DEFAULT_ALGO) -> Any:
    """One of the algorithm's policy names (``"MlpPolicy"``; RecurrentPPO's
    ``"MlpLstmPolicy"``), or the class a dotted name imports, a subclass of the algorithm's
    policy (PPO's: an SB3 ``ActorCriticPolicy``, such as ``train.mirror.MirrorMlpPolicy``).

    :raises ConfigError: if the name does not import or is not a policy of the algorithm.
    """
    learner = _algo(algo, where)
    if name in learner.policies:
        return name
    base = learner.base_policy()
    known = f"{learner.name} takes {', '.join(learner.policies)} or a {base.__name__} subclass"
    if isinstance(name, str) and name.endswith("MirrorMlpPolicy") and learner.name != "ppo":
        raise ConfigError(f"{where}: policy {name!r} is PPO's only ({known})")
    try:
        cls = import_object(str(name))
    except (ImportError, AttributeError, ValueError) as e:
        raise ConfigError(f"{where}: policy {name!r} does not import: {e}") from None
    if not (isinstance(cls, type) and issubclass(cls, base)):
        library = "sb3-contrib" if base.__module__.startswith("sb3_contrib") else "SB3"
        raise ConfigError(f"{where}: policy {name!r} is not an {library} {base.__name__} ({known})")
    return cls


def wrapper_specs(value: Any, *, where: str = "vec_env_wrapper") -> list[tuple[str, dict]]:
    """rl-zoo3's wrapper list as ``[(dotted.name, kwargs), ...]``; each class is imported.

    Entries are ``dotted.ClassName`` or ``{dotted.ClassName: {kwarg: value}}``. Each class must
    be an SB3 ``VecEnvWrapper`` whose constructor takes the given keyword arguments (the
    values are the constructor's to check).

    :raises ConfigError: for a malformed entry, a name that does not import, or an argument the
        class does not take (the message lists those it takes).
    """
    from stable_baselines3.common.vec_env import VecEnvWrapper

    specs = []
    for entry in wrapper_entries(value):
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
        _check_loadable(where, name, cls)
        accepted = _accepted_arguments(cls) - {"venv"}
        for key in kwargs:
            if key not in accepted:
                raise ConfigError(
                    f"{where}: vec_env_wrapper {name}: {key!r} is not one of its arguments "
                    f"(accepted: {', '.join(sorted(accepted)) or 'none'})"
                )
        specs.append((name, dict(kwargs)))
    return specs


def _check_loadable(where: str, name: str, cls: type) -> None:
    """A wrapper a trained agent loads with: a step of the view (:data:`FEATURES
    <policies.learned.features.FEATURES>`, rebuilt by name) or a training-only one. Any other
    trains, and then ``make_policy``, ``follow-eval`` and ``follow-robot`` refuse the agent."""
    from policies.learned.features import FEATURES, Pipeline

    if not Pipeline.view_entries([(name, {})]):
        return  # training-only: not part of the agent's view
    step = name.rsplit(".", 1)[-1].removeprefix("Vec")
    known = ", ".join(f"train.wrappers.Vec{k}" for k in FEATURES)
    if step not in FEATURES:
        raise ConfigError(
            f"{where}: vec_env_wrapper {name!r} is not a step a trained agent can be loaded "
            f"with (its view is rebuilt without SB3 from: {known})"
        )
    if not cls.__module__.startswith("train."):  # loaded by its name, as the project's step
        raise ConfigError(
            f"{where}: vec_env_wrapper {name!r} is named as the step Vec{step} but is another "
            f"class ({cls.__module__}.{cls.__qualname__}); a trained agent loads "
            f"train.wrappers.Vec{step} by that name"
        )


def _refuse_double_stack(where: str, frame_stack: int, specs: list[tuple[str, dict]]) -> None:
    """``frame_stack`` > 1 beside a frame-stacking wrapper would stack the stacks (4 x 4 = 16
    frames, the first history twice): one history only."""
    from stable_baselines3.common.vec_env import VecFrameStack

    from train.wrappers import VecStackFrames

    if frame_stack == 1:
        return
    for name, _ in specs:
        if issubclass(import_object(name), VecStackFrames | VecFrameStack):
            raise ConfigError(
                f"{where}: frame_stack={frame_stack} is out of range beside the wrapper {name}, "
                "which stacks frames itself: must be 1 (one history, not a stack of stacks)"
            )


def _check_privileged(where: str, hp: Hyperparams, specs: list[tuple[str, dict]]) -> None:
    """The critic's truth (:class:`train.privileged.VecPrivilegedCritic`) must be the last
    entries of what the policy reads, and the policy must know them: the wrapper listed last,
    no ``frame_stack`` or observation normalisation after it (they would stack or shift the
    truth into the actor's view), and ``policy_kwargs.privileged_signs`` one per entry; and
    ``privileged_signs`` without the wrapper would take the actor's own entries from it."""
    from train.privileged import PRIVILEGED, VecPrivilegedCritic

    at = [k for k, (name, _) in enumerate(specs) if import_object(name) is VecPrivilegedCritic]
    signs = (hp.get("policy_kwargs") or {}).get("privileged_signs")
    if not at:
        if signs:
            raise ConfigError(
                f"{where}: policy_kwargs.privileged_signs needs the wrapper "
                "train.privileged.VecPrivilegedCritic, listed last in vec_env_wrapper"
            )
        return
    norm = hp["normalize"]
    problems = [
        (at != [len(specs) - 1], "it must be listed once, last"),
        (hp["frame_stack"] != 1, f"frame_stack={hp['frame_stack']} must be 1"),
        (
            bool(norm) and (not isinstance(norm, Mapping) or norm.get("norm_obs", True)),
            "normalize must leave observations alone (norm_obs: false)",
        ),
        (
            not isinstance(signs, list | tuple) or len(signs) != len(PRIVILEGED),
            f"policy_kwargs.privileged_signs={signs!r} must give {len(PRIVILEGED)} signs "
            "(train.privileged.PRIVILEGED_SIGNS)",
        ),
    ]
    for bad, why in problems:
        if bad:
            raise ConfigError(f"{where}: vec_env_wrapper VecPrivilegedCritic: {why}")


def import_object(dotted: str) -> Any:
    """Import ``package.module.Name`` and return ``Name``."""
    module, _, attr = dotted.rpartition(".")
    if not module:
        raise ValueError(f"{dotted!r} is not a dotted name (package.module.Name)")
    return getattr(importlib.import_module(module), attr)
