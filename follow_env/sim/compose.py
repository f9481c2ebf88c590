"""Kernel composition: one compiled step kernel and one reset kernel per (platform, task) pair.

A platform provides ``drive(prm, st, body, action, keys, step)`` and ``reset(prm, st, body)``;
a task provides ``step(prm, st, world, i, keys)`` and ``reset(prm, st, world, i, keys)``, all
compiled. The pair's kernels loop over lanes and call them in order, so each physical model has
one implementation whatever it is combined with. numba cannot cache a closure over other
compiled functions, so the pair's kernels are written out as a small module (the template
below, filled with the two module names) in the source-keyed cache folder and imported from
there: numba then caches them like any other module's functions (:mod:`follow_env.sim.jit`).
"""

from __future__ import annotations

import importlib.util
import sys
from types import ModuleType

from follow_env.sim.atomic import atomic_write_text
from follow_env.sim.jit import CACHE_ROOT

__all__ = ["kernels"]

_TEMPLATE = '''"""Kernels of task {task!r} on platform {platform!r} (by follow_env.sim.compose)."""

from follow_env.sim.jit import njit
from {platform_module} import drive as platform_drive
from {platform_module} import reset as platform_reset
from {task_module} import reset as task_reset
from {task_module} import step as task_step


@njit(nogil=True)
def step_lanes(params, state, world, keys, actions, active):
    """Advance every active lane by one control step under its row of ``actions``."""
    for i in range(state.shape[0]):
        if not active[i]:
            continue
        prm, st = params[i], state[i]
        ep = st.episode
        ep.step += 1
        ep.t += prm.platform.dt
        platform_drive(prm.platform, st.platform, st.body, actions[i], keys[i], ep.step)
        task_step(prm, st, world, i, keys[i])


@njit
def reset_lanes(lanes, pose, params, state, world, keys):
    """Start an episode on each of ``lanes`` (state zeroed, world arrays written) at ``pose``."""
    for j in range(lanes.shape[0]):
        i = lanes[j]
        prm, st = params[i], state[i]
        st.body.x, st.body.y, st.body.th = pose[j, 0], pose[j, 1], pose[j, 2]
        platform_reset(prm.platform, st.platform, st.body)
        task_reset(prm, st, world, i, keys[i])
'''

_LOADED: dict[tuple[str, str], ModuleType] = {}


def kernels(task: str, task_module: str, platform: str, platform_module: str) -> ModuleType:
    """The module holding ``step_lanes`` and ``reset_lanes`` of the pair (made on first use).

    :param task: the task's name. :param task_module: the module with its ``step``/``reset``.
    :param platform: the platform's name. :param platform_module: the module with its
        ``drive``/``reset``.
    """
    key = (task_module, platform_module)
    if key in _LOADED:
        return _LOADED[key]
    source = _TEMPLATE.format(
        task=task, platform=platform, task_module=task_module, platform_module=platform_module
    )
    folder = CACHE_ROOT / "composed"
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{task}__{platform}.py"
    if not path.exists() or path.read_text() != source:
        atomic_write_text(path, source)  # another process may write the same text at once
    name = f"follow_env._composed.{task}__{platform}"
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:  # pragma: no cover - a path importlib refuses
        raise ImportError(f"cannot load the kernels written to {path}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    _LOADED[key] = module
    return module
