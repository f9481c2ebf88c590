"""The learners ``follow-train --algo`` trains: each one's class, rules and shipped file.

======================  ===================================  ====================================
``--algo``              class                                shipped hyperparameters
======================  ===================================  ====================================
``ppo`` (the default)   stable-baselines3 ``PPO``            ``train/configs/ppo.yaml``
``recurrent_ppo``       sb3-contrib ``RecurrentPPO`` (LSTM)  ``train/configs/recurrent_ppo.yaml``
``sac``                 stable-baselines3 ``SAC``            ``train/configs/sac.yaml``
======================  ===================================  ====================================

An :class:`Algo` says which arguments a hyperparameter file may give the algorithm's
constructor (:attr:`Algo.rules`, each checked with SB3's meaning and range; any other key is
refused), which policies it takes (SB3's names, or a dotted subclass of
:attr:`Algo.policy_base`), the constraints SB3 asserts later on the batch and the buffer
(:attr:`Algo.check_batch`, run before anything is built), which arguments are schedules, and
which ``policy_kwargs`` its policy adds to the actor-critic's. :mod:`train.config` applies them;
:func:`train.ppo.train` builds :meth:`Algo.cls` (one code path for every algorithm).
"""

from __future__ import annotations

import copy
import importlib
import inspect
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from follow_env.sim.checks import one_line
from train.rules import (
    Check,
    ConfigError,
    decimal,
    fail,
    flag,
    integer,
    is_number,
    number,
    optional,
    positive_schedule,
    schedule,
    unsupported,
)

__all__ = [
    "ALGOS",
    "DEFAULT_ALGO",
    "PPO_RULES",
    "RECURRENT_PPO_RULES",
    "SAC_RULES",
    "Algo",
    "algo",
    "load_model",
    "new_model",
    "shipped_hint",
]

CONFIGS = Path(__file__).parent / "configs"
DEFAULT_ALGO = "ppo"


def shipped_hint(path: Path, error: OSError) -> str:
    """For ``train/configs/<file>`` not found here (the README's ``--hyperparams`` given from
    outside the clone) that names a shipped file: where that file is, as the end of the
    message of ``error``; else ``""``."""
    shipped = CONFIGS / path.name
    relative = not path.is_absolute() and path.parts[-3:-1] == ("train", "configs")
    if not (isinstance(error, FileNotFoundError) and relative and shipped.is_file()):
        return ""
    return f" (looked for in {Path.cwd()}; the shipped {path.name} is {shipped})"


#: (where, hp, name, defaults): raise ConfigError if the section breaks an SB3 constraint;
#: ``name(key)`` is how the key is named in messages (``--n-envs`` when given as an option).
BatchCheck = Callable[[str, dict[str, Any], Callable[[str], str], Mapping[str, Any]], None]


@dataclass(frozen=True)
class Algo:
    """One learner of ``follow-train --algo`` (module docstring)."""

    name: str  # the --algo value, and the prefix of run folders and checkpoints
    label: str  # the class's name, as model cards say it
    library: str  # the package that has it, as model cards say it
    module: str  # where the class is imported from
    class_name: str
    policies: tuple[str, ...]  # the policy names the file may give; the first is the default
    policy_base: str  # a dotted policy must subclass this class (module.Class)
    rules: Mapping[str, Check]  # every constructor argument a file may set, with its check
    check_batch: BatchCheck
    schedules: tuple[str, ...]  # arguments that take a schedule (lin_<x>)
    net_arch_keys: tuple[str, ...]  # the keys of a net_arch mapping (actor's and critic's)
    policy_rules: Mapping[str, Check] = field(default_factory=dict)  # the policy's own kwargs

    @property
    def hyperparams(self) -> Path:
        """The shipped hyperparameter file (``--hyperparams``'s default for this algorithm)."""
        return CONFIGS / f"{self.name}.yaml"

    def cls(self) -> type:
        """The algorithm's class (imports SB3 or sb3-contrib)."""
        return getattr(importlib.import_module(self.module), self.class_name)

    def base_policy(self) -> type:
        """The policy class a dotted ``policy`` must subclass."""
        module, _, name = self.policy_base.rpartition(".")
        return getattr(importlib.import_module(module), name)

    def defaults(self) -> dict[str, Any]:
        """SB3's defaults of the arguments :attr:`rules` names."""
        parameters = inspect.signature(self.cls().__init__).parameters
        return {name: p.default for name, p in parameters.items() if name in self.rules}


# -- Rule tables: every argument a file may set, with SB3's meaning and range ----------------


def _int(low: int) -> Check:
    return lambda w, k, v: integer(w, k, v, low)


def _unit(w: str, k: str, v: Any) -> float:  # discounts and GAE's lambda
    return number(w, k, v, 0.0, 1.0)


def _positive(w: str, k: str, v: Any) -> float:
    return number(w, k, v, 0.0, open_low=True)


def _nonnegative(w: str, k: str, v: Any) -> float:
    return number(w, k, v, 0.0)


#: Every PPO argument a hyperparameter file may set, with its check (SB3's meaning and default).
PPO_RULES: dict[str, Check] = {
    "learning_rate": positive_schedule,  # > 0, or lin_<x> with x > 0
    "n_steps": _int(1),  # steps per lane per update
    "batch_size": _int(1),  # also 2 .. n_steps * n_envs, below
    "n_epochs": _int(1),
    "gamma": _unit,  # discount per 0.1 s step
    "gae_lambda": _unit,
    "clip_range": positive_schedule,
    "clip_range_vf": optional(positive_schedule),
    "normalize_advantage": flag,
    "ent_coef": _nonnegative,
    "vf_coef": _nonnegative,
    "max_grad_norm": _positive,
    "use_sde": flag,
    "sde_sample_freq": _int(-1),  # -1: only at rollout start
    "rollout_buffer_class": unsupported,
    "rollout_buffer_kwargs": unsupported,
    "target_kl": optional(_positive),
    "stats_window_size": _int(1),
}

#: sb3-contrib's RecurrentPPO: PPO's arguments (its rollout buffer is its own, not settable);
#: ``batch_size`` None is the whole rollout in one mini-batch.
RECURRENT_PPO_RULES: dict[str, Check] = {
    key: check for key, check in PPO_RULES.items() if not key.startswith("rollout_buffer")
} | {"batch_size": optional(_int(1))}


def _train_freq(where: str, key: str, value: Any) -> Any:
    """An integer >= 1 (env steps per lane between updates), or ``[n, "step" | "episode"]``."""
    if isinstance(value, list | tuple) and len(value) == 2:
        n, unit = value
        whole = isinstance(n, int) and not isinstance(n, bool)
        if whole and n >= 1 and unit in ("step", "episode"):
            return list(value)
    elif not isinstance(value, bool) and isinstance(value, int) and value >= 1:
        return value
    raise fail(where, key, value, 'an integer >= 1, or [n >= 1, "step" or "episode"]')


def _gradient_steps(where: str, key: str, value: Any) -> int:
    """An integer >= 1, or -1: as many gradient steps as env steps were collected."""
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int) or not (value >= 1 or value == -1):
        raise fail(where, key, value, "an integer >= 1, or -1 (as many as env steps collected)")
    return value


def _ent_coef(where: str, key: str, value: Any) -> Any:
    """A number >= 0 (fixed), ``"auto"`` (learned, from 1) or ``"auto_<x>"`` (learned, from
    x > 0), as SAC reads it."""
    if is_number(value) and value >= 0 and value != float("inf"):
        return value
    if value == "auto":
        return value
    if isinstance(value, str) and value.startswith("auto_"):
        start = decimal(value[5:])  # SB3 reads value.split("_")[1]: "auto_1_0" would be 1
        if start is not None and 0 < start < float("inf"):
            return value
    raise fail(where, key, value, "a number >= 0, 'auto', or 'auto_<x>' with x > 0")


def _target_entropy(where: str, key: str, value: Any) -> Any:
    """``"auto"`` (minus the action's size) or a finite number."""
    return value if value == "auto" else number(where, key, value, -float("inf"))


#: Every SAC argument a hyperparameter file may set, with its check (SB3's meaning and default).
SAC_RULES: dict[str, Check] = {
    "learning_rate": positive_schedule,  # actor, critics and entropy coefficient alike
    "buffer_size": _int(1),  # transitions kept, all lanes together
    "learning_starts": _int(0),  # env steps of random actions before the first update
    "batch_size": _int(1),  # transitions per gradient step; at most buffer_size, below
    "tau": lambda w, k, v: number(w, k, v, 0.0, 1.0, open_low=True),  # target-network update
    "gamma": _unit,
    "train_freq": _train_freq,
    "gradient_steps": _gradient_steps,
    "action_noise": unsupported,
    "replay_buffer_class": unsupported,
    "replay_buffer_kwargs": unsupported,
    "optimize_memory_usage": flag,  # must stay false, below
    "n_steps": _int(1),  # n-step returns (1: SAC's one-step target)
    "ent_coef": _ent_coef,
    "target_update_interval": _int(1),  # gradient steps between target updates
    "target_entropy": _target_entropy,
    "use_sde": flag,
    "sde_sample_freq": _int(-1),
    "use_sde_at_warmup": flag,
    "stats_window_size": _int(1),
}


# -- Constraints SB3 asserts (or breaks on) later, checked first -----------------------------


def _lanes(name: Callable[[str], str]) -> str:
    return f" (n_envs from {name('n_envs')})" if name("n_envs") != "n_envs" else ""


def _check_rollout(
    where: str, hp: dict[str, Any], name: Callable[[str], str], defaults: Mapping[str, Any]
) -> None:
    """PPO's rollout buffer: ``batch_size`` in [2, n_steps * n_envs] (SB3 asserts > 1 and
    normalises advantages per mini-batch; a standard deviation needs 2 samples)."""
    n_steps = hp.get("n_steps", defaults["n_steps"])
    batch_size = hp.get("batch_size", defaults["batch_size"])
    buffer = n_steps * hp["n_envs"]
    smallest = 2 if hp.get("normalize_advantage", defaults["normalize_advantage"]) else 1
    if buffer < smallest:
        raise ConfigError(
            f"{where}: n_steps * n_envs = {n_steps} * {hp['n_envs']} is out of range: must be "
            f">= 2 while normalize_advantage is true{_lanes(name)}"
        )
    if batch_size is not None and not smallest <= batch_size <= buffer:
        raise ConfigError(
            f"{where}: batch_size={batch_size} is out of range: must be in [{smallest}, "
            f"n_steps * n_envs = {n_steps} * {hp['n_envs']} = {buffer}]{_lanes(name)}"
        )


def _check_recurrent(
    where: str, hp: dict[str, Any], name: Callable[[str], str], defaults: Mapping[str, Any]
) -> None:
    """RecurrentPPO's: PPO's, and no truncated last mini-batch of one step while advantages
    are normalised (sb3-contrib takes its standard deviation: NaN); the critic has its own
    LSTM or shares the actor's, not both."""
    _check_rollout(where, hp, name, defaults)
    batch_size = hp.get("batch_size", defaults["batch_size"])
    buffer = hp.get("n_steps", defaults["n_steps"]) * hp["n_envs"]
    normalize = hp.get("normalize_advantage", defaults["normalize_advantage"])
    if normalize and batch_size is not None and buffer % batch_size == 1:
        raise ConfigError(
            f"{where}: batch_size={batch_size} is out of range: n_steps * n_envs = {buffer} "
            f"leaves a last mini-batch of 1 step, whose advantage cannot be normalised; choose "
            f"a batch_size whose remainder is not 1{_lanes(name)}"
        )
    kwargs = hp.get("policy_kwargs") or {}
    if kwargs.get("shared_lstm") and kwargs.get("enable_critic_lstm", True):
        raise ConfigError(
            f"{where}: policy_kwargs.shared_lstm=True is out of range: must be false while "
            "policy_kwargs.enable_critic_lstm is true (its default); give enable_critic_lstm: "
            "false to share the actor's LSTM"
        )


def _check_replay(
    where: str, hp: dict[str, Any], name: Callable[[str], str], defaults: Mapping[str, Any]
) -> None:
    """SAC's replay buffer: at least one transition per lane (SB3 divides buffer_size among
    the lanes), a batch no larger than the buffer, episodic ``train_freq`` with one lane only
    (SB3 asserts it), and ``optimize_memory_usage`` off (SB3 refuses it with the timeout
    handling its buffer always has here)."""
    buffer = hp.get("buffer_size", defaults["buffer_size"])
    batch_size = hp.get("batch_size", defaults["batch_size"])
    n_envs = hp["n_envs"]
    if buffer < n_envs:
        raise ConfigError(
            f"{where}: buffer_size={buffer} is out of range: must be >= n_envs = {n_envs} (one "
            f"transition per lane at least){_lanes(name)}"
        )
    if batch_size > buffer:
        raise ConfigError(
            f"{where}: batch_size={batch_size} is out of range: must be in [1, buffer_size = "
            f"{buffer}]"
        )
    train_freq = hp.get("train_freq", defaults["train_freq"])
    if isinstance(train_freq, list) and train_freq[1] == "episode" and n_envs > 1:
        raise ConfigError(
            f"{where}: train_freq={train_freq!r} is out of range: counting in episodes needs "
            f"n_envs = 1 (got {n_envs}); count in steps, e.g. train_freq: 1{_lanes(name)}"
        )
    if hp.get("optimize_memory_usage"):
        raise ConfigError(
            f"{where}: optimize_memory_usage=True is out of range: must be false (SB3's replay "
            "buffer cannot combine it with its handle_timeout_termination, which is on: "
            "replay_buffer_kwargs cannot be set)"
        )


# -- The registry ----------------------------------------------------------------------------

_ACTOR_CRITIC = "stable_baselines3.common.policies.ActorCriticPolicy"

ALGOS: dict[str, Algo] = {
    "ppo": Algo(
        name="ppo",
        label="PPO",
        library="stable-baselines3",
        module="stable_baselines3",
        class_name="PPO",
        policies=("MlpPolicy",),  # or train.mirror.MirrorMlpPolicy (PPO's only)
        policy_base=_ACTOR_CRITIC,
        rules=PPO_RULES,
        check_batch=_check_rollout,
        schedules=("learning_rate", "clip_range", "clip_range_vf"),
        net_arch_keys=("pi", "vf"),
    ),
    "recurrent_ppo": Algo(
        name="recurrent_ppo",
        label="RecurrentPPO",
        library="sb3-contrib",
        module="sb3_contrib",
        class_name="RecurrentPPO",
        policies=("MlpLstmPolicy",),
        policy_base="sb3_contrib.common.recurrent.policies.RecurrentActorCriticPolicy",
        rules=RECURRENT_PPO_RULES,
        check_batch=_check_recurrent,
        schedules=("learning_rate", "clip_range", "clip_range_vf"),
        net_arch_keys=("pi", "vf"),
        policy_rules={
            "lstm_hidden_size": _int(1),  # units of each LSTM layer
            "n_lstm_layers": _int(1),
            "shared_lstm": flag,  # the critic reads the actor's LSTM
            "enable_critic_lstm": flag,  # the critic has an LSTM of its own
        },
    ),
    "sac": Algo(
        name="sac",
        label="SAC",
        library="stable-baselines3",
        module="stable_baselines3",
        class_name="SAC",
        policies=("MlpPolicy",),
        policy_base="stable_baselines3.sac.policies.SACPolicy",
        rules=SAC_RULES,
        check_batch=_check_replay,
        schedules=("learning_rate",),
        net_arch_keys=("pi", "qf"),
        policy_rules={
            "clip_mean": _nonnegative,  # the actor's mean is clipped to +-clip_mean (0: not)
            "n_critics": _int(1),  # Q-networks; the target is their minimum
        },
    ),
}


def algo(name: Any, *, option: str = "--algo") -> Algo:
    """The registered algorithm ``name``.

    :raises ConfigError: naming ``option`` and the known names, for any other value.
    """
    if not isinstance(name, str) or name not in ALGOS:
        raise ConfigError(f"{option} {name!r} is not a learner: one of {', '.join(ALGOS)}")
    return ALGOS[name]


# -- Building and loading a model ------------------------------------------------------------


def new_model(
    learner: Algo, policy: Any, hp: dict[str, Any], venv: Any, seed: int, *, where: str
) -> Any:
    """A new ``learner`` model on ``venv`` from checked hyperparameters ``hp`` (CPU, silent).

    :param policy: the policy, as :func:`train.config.policy_class` resolves ``hp["policy"]``.
    The constructor gets the keys of :attr:`Algo.rules` and ``policy_kwargs``; rl-zoo3's own
    keys (``n_envs``, ``normalize``, ``vec_env_wrapper`` ...) are the trainer's.

    :raises ConfigError: naming ``where`` if SB3 refuses a value anyway.
    """
    # A copy: SB3 adds its own entries to policy_kwargs (SAC: use_sde), which hp must not get.
    kwargs = copy.deepcopy(
        {k: v for k, v in hp.items() if k in learner.rules or k == "policy_kwargs"}
    )
    for key in learner.schedules:
        if kwargs.get(key) is not None:
            kwargs[key] = schedule(kwargs[key])
    if isinstance(kwargs.get("train_freq"), list):  # YAML's [n, unit]; SB3 wants a tuple
        kwargs["train_freq"] = tuple(kwargs["train_freq"])
    try:
        return learner.cls()(policy, venv, seed=seed, device="cpu", verbose=0, **kwargs)
    except (ValueError, TypeError, AssertionError, OverflowError) as e:
        raise ConfigError(f"{where}: {learner.library} rejects the hyperparameters: {e}") from None
    except (MemoryError, RuntimeError) as e:  # numpy's rollout buffer, torch's layers
        problem = one_line(e)
        raise ConfigError(
            f"{where}: the model does not fit in memory with these hyperparameters (n_steps, "
            f"buffer_size, net_arch, frame_stack): {problem}"
        ) from None


def load_model(learner: Algo, path: Path, venv: Any) -> Any:
    """A saved ``learner`` model (a checkpoint) on ``venv``, to continue training.

    :raises ValueError: naming ``path`` if it is not a readable model of this algorithm.
    """
    try:
        return learner.cls().load(path, env=venv, device="cpu")
    except Exception as e:  # zipfile, pickle, torch and SB3 each raise their own
        problem = f"{type(e).__name__}: {e}"
        raise ValueError(f"{path}: cannot resume from it ({problem})") from None
