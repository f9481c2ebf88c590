"""Tasks: what the robot is for. One package each (``person_follow``; later ``line_trace``).

A task package holds its spec (names, units; no simulation import), its configuration and
presets, its compiled step (composed with any platform's drive), its scenarios, renderer,
step-log schema, metrics and env classes. Its ``__init__`` stays light: it names the Gymnasium
ids and entry points (:data:`ENVS`), which :func:`register_envs` hands to Gymnasium when
``follow_env`` is imported, so ``gym.make`` finds every task without a list elsewhere.
"""

from __future__ import annotations

import importlib
import pkgutil
from typing import Any

__all__ = ["available_tasks", "env_ids", "get_task", "register_envs", "task_for_env"]


def _packages() -> list[str]:
    return [info.name for info in pkgutil.iter_modules(__path__) if info.ispkg]


def available_tasks() -> list[str]:
    """Names of the task packages."""
    return sorted(_packages())


def _envs() -> dict[str, tuple[str, dict[str, Any]]]:
    """Every task's Gymnasium ids: id -> (task name, its registration keywords)."""
    out = {}
    for name in _packages():
        package = importlib.import_module(f"{__name__}.{name}")
        for env_id, kwargs in getattr(package, "ENVS", {}).items():
            out[env_id] = (name, kwargs)
    return out


def env_ids() -> list[str]:
    """Every task's Gymnasium ids (``"PersonFollow-v0"``, ...), task by task."""
    return list(_envs())


def register_envs() -> None:
    """Register every task's Gymnasium ids (idempotent)."""
    import gymnasium

    for env_id, (_, kwargs) in _envs().items():
        if env_id not in gymnasium.registry:
            # No max_episode_steps: the kernel ends episodes itself, so the single env and
            # the batched core truncate at exactly the same step. gym.make(...,
            # max_episode_steps=n) still wraps TimeLimit; an n past the env's own cap is
            # refused at the first reset (follow_env.sim.faces.TaskEnv._check_time_limit).
            gymnasium.register(id=env_id, **kwargs)


def task_for_env(env_id: str) -> Any:
    """The task model behind a Gymnasium id (``"PersonFollow-v0"``); ``ValueError`` listing
    the known ids otherwise."""
    envs = _envs()
    if env_id in envs:
        return get_task(envs[env_id][0])
    raise ValueError(
        f"env_id={env_id!r} is out of range: must be one of " + ", ".join(map(repr, envs))
    )


def get_task(name: str) -> Any:
    """The task model called ``name`` (its ``TASK``); ``ValueError`` listing the known ones."""
    if name not in _packages():
        raise ValueError(
            f"task={name!r} is out of range: must be one of "
            + ", ".join(repr(n) for n in available_tasks())
        )
    return importlib.import_module(f"{__name__}.{name}.task").TASK
