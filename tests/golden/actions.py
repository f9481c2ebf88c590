"""Golden actions of the shipped agents: what each does with recorded observations.

The closed-loop golden rollouts (``rollouts.py``) hash whole episodes bit for bit; a learned
agent's episodes there may differ by CPU (torch picks its kernels by CPU, and 30 s of closed
loop turn a last-bit difference into another episode), so only ``ppo`` is among them. This file
checks every shipped agent on any CPU instead, open loop: one episode per scenario (per track
for the line tracer) was run with the agent and its observations and actions recorded; the
test feeds the recorded observations to the agent built afresh and compares its actions
within :data:`ATOL`. Whatever changes the agent's view (its weights, normalisation, feature
steps such as the jump gate, the command steps, the frame stack) changes its actions by far
more than a CPU's last bits do.

Record anew (only when an agent's behaviour changes on purpose, and say why in the commit)::

    .venv/bin/python tests/golden/actions.py              # every shipped agent
    .venv/bin/python tests/golden/actions.py ppo_ensemble # one (a new one), the others kept
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from eval.rollout import run_episode
from follow_env.sim.atomic import atomic_path
from follow_env.tasks.line_trace.tracks.registry import TRACKS
from follow_env.tasks.person_follow.scenarios.registry import SCENARIOS
from policies import make_policy
from policies.learned.ppo import SHIPPED

GOLDEN = Path(__file__).with_name("actions.npz")
SEED = 0
#: How far an action may be from the recorded one, in its SI unit (m/s, rad/s): far above the
#: float32 rounding of a CPU's kernels summed over an episode's command steps (about 1e-6),
#: far below a change of behaviour.
ATOL = 1e-4
#: The run spec of each shipped agent: the mecanum agent runs on its own platform.
RUN_AS = {"ppo_mecanum": "ppo_mecanum@mecanum"}
#: Each task's scenarios (the line tracer's tracks).
VARIANTS = {"person_follow": tuple(SCENARIOS), "line_trace": tuple(TRACKS)}


def cases() -> list[tuple[str, str, str]]:
    """``(folder, task, scenario)`` for every shipped agent and its task's scenarios."""
    return [
        (folder, task, scenario)
        for folder, (_, task) in sorted(SHIPPED.items())
        for scenario in VARIANTS[task]
    ]


def _columns(log_columns: list[str]) -> tuple[list[str], list[str]]:
    observed = [c for c in log_columns if c.startswith("obs_")]
    actions = [c for c in log_columns if c.startswith("action_")]
    return observed, actions


def record_case(folder: str, task: str, scenario: str) -> tuple[np.ndarray, np.ndarray]:
    """One closed-loop episode of the agent: the observations it acted on (float32, as the
    env gives them) and its actions (SI), one row per step."""
    name = SHIPPED[folder][0]
    log = run_episode(RUN_AS.get(folder, name), scenario, SEED, task=task).log
    observed, actions = _columns(list(log.columns))
    # a row holds an observation and the action taken on it; the last, the final
    # observation, none
    obs = log[observed].to_numpy(dtype=np.float32)[:-1]
    return obs, log[actions].to_numpy(dtype=np.float32)[:-1]  # the policies act in float32


def actions_of(policy: Any, obs: np.ndarray) -> np.ndarray:
    """What ``policy``, reset, does on the observations ``obs``, one row a step."""
    policy.reset()
    return np.array([np.asarray(policy.act(row), dtype=np.float64) for row in obs])


def replay(folder: str, task: str, obs: np.ndarray) -> np.ndarray:
    """The actions of the agent built afresh (``make_policy``) on the observations ``obs``."""
    return actions_of(make_policy(SHIPPED[folder][0], task), obs)


def key(folder: str, scenario: str) -> str:
    return f"{folder}/{scenario}/{SEED}"


def record(folders: Sequence[str] = ()) -> int:
    """Record the named shipped agents' cases (their folders; none: every agent's), keeping
    what is recorded of the others."""
    unknown = sorted(set(folders) - set(SHIPPED))
    if unknown:
        print(f"not a shipped agent's folder: {', '.join(unknown)}", file=sys.stderr)
        return 2
    arrays: dict[str, np.ndarray] = {}
    if folders:
        with np.load(GOLDEN) as kept:
            arrays = {k: kept[k] for k in kept.files if k.split("/", 1)[0] not in folders}
    for folder, task, scenario in cases():
        if folders and folder not in folders:
            continue
        obs, actions = record_case(folder, task, scenario)
        # the recording must itself be what the agent does open loop on its observations
        np.testing.assert_allclose(replay(folder, task, obs), actions, rtol=0, atol=ATOL)
        arrays[f"{key(folder, scenario)}/obs"] = obs
        arrays[f"{key(folder, scenario)}/actions"] = actions
        print(f"{key(folder, scenario)}: {len(obs)} steps")
    with atomic_path(GOLDEN) as tmp:  # its name ends in .npz, so numpy adds no second one
        np.savez_compressed(tmp, **arrays)
    return 0


if __name__ == "__main__":
    sys.exit(record(sys.argv[1:]))
