"""Identical rollouts: every policy on the same scenario x seed grid.

``rollout(policies, scenarios, seeds)`` runs each policy for one episode per (scenario, seed)
pair and returns the step logs. The environment draws every random number from the episode's
seed and the step index, never from the actions (follow_env's seeding, README "Seeding and
identical rollouts"), so for a given (scenario, seed) every policy meets the same person on the
same path with the same detector misses, jitter and depth noise. Differences between the rows of
a table then come from the policies alone, and policies can be compared pair-wise on the same
seeds (:mod:`eval.stats`).

Episodes run in this process or in a process pool (``workers``); either way the results are
identical and come back in grid order (policy, then scenario, then seed).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from multiprocessing import get_context
from typing import Any

import gymnasium as gym
import numpy as np
import pandas as pd

import follow_env
from eval.steplog import COLUMNS
from policies import Policy, make_policy

__all__ = ["Episode", "auto_workers", "rollout", "run_episode"]

PolicySpec = str | Policy
EnvConfigSpec = str | Mapping[str, Any] | follow_env.EnvConfig
Reducer = Callable[["Episode"], Any]

# Step-log columns copied from ``info`` under the same name (see eval.steplog.COLUMNS).
_INFO_COLUMNS = tuple(c for c in COLUMNS if c in follow_env.INFO_KEYS and c != "termination")
# Booleans in info become 0/1 in the log, as a robot's CSV would hold them.
_FLAG_COLUMNS = ("detected", "in_frame")

# Measured on the 2-core development machine (README "Evaluation"): an episode of `straight` or
# `curve` costs about 5 ms here (stepping, policy, log), while a pool worker needs about 2 s to
# start (imports and loading the compiled kernels). A pool pays off only above this many
# episodes per extra worker.
_EPISODES_PER_WORKER_START = 1000


@dataclass(frozen=True)
class Episode:
    """One policy's episode on one scenario and seed.

    :param policy: the policy's name (``Policy.name``, e.g. ``"pn:tuned"``).
    :param scenario: the scenario name.
    :param seed: the seed passed to ``env.reset``.
    :param log: the step log (columns of :data:`eval.steplog.COLUMNS`).
    """

    policy: str
    scenario: str
    seed: int
    log: pd.DataFrame

    @property
    def steps(self) -> int:
        """Control steps taken (rows minus the reset row)."""
        return len(self.log) - 1

    @property
    def termination(self) -> str:
        """Why the episode ended (``follow_env.INFO_KEYS`` "termination")."""
        return str(self.log["termination"].iloc[-1])


_ENV_CACHE: dict[tuple[str, str], gym.Env] = {}


def _env(scenario: str, config: EnvConfigSpec, render: bool) -> gym.Env:
    """One env per (scenario, config) per process: gym.make costs more than an episode."""
    if render:
        return gym.make(
            "PersonFollow-v0", scenario=scenario, config=config, render_mode="rgb_array"
        )
    key = (scenario, repr(config))
    env = _ENV_CACHE.get(key)
    if env is None:
        env = _ENV_CACHE[key] = gym.make("PersonFollow-v0", scenario=scenario, config=config)
    return env


def _policy(spec: PolicySpec) -> Policy:
    return make_policy(spec) if isinstance(spec, str) else spec


def run_episode(
    policy: PolicySpec,
    scenario: str,
    seed: int,
    *,
    config: EnvConfigSpec = "thesis",
    on_frame: Callable[[np.ndarray], None] | None = None,
) -> Episode:
    """Run one episode and return its step log.

    :param policy: a policy name (``make_policy``) or a :class:`~policies.Policy`; it is reset
        before the first step.
    :param scenario: a registered scenario name.
    :param seed: the episode's seed (``env.reset(seed=seed)``).
    :param config: the env configuration (``gym.make``'s ``config``): a preset name, a dict of
        overrides or an ``EnvConfig``.
    :param on_frame: if given, the env renders (``rgb_array``) and each frame, the reset frame
        included, is passed to it (for videos).
    """
    law = _policy(policy)
    env = _env(scenario, config, render=on_frame is not None)
    try:
        obs, info = env.reset(seed=int(seed))
        law.reset()
        observations, actions, infos, rewards = [obs], [], [info], [math.nan]
        if on_frame is not None:
            on_frame(env.render())
        done = False
        while not done:
            action = np.asarray(law.act(obs), dtype=np.float32)
            obs, reward, terminated, truncated, info = env.step(action)
            done = terminated or truncated
            observations.append(obs)
            actions.append(action)
            infos.append(info)
            rewards.append(reward)
            if on_frame is not None:
                on_frame(env.render())
    finally:
        if on_frame is not None:
            env.close()
    return Episode(
        law.name,
        scenario,
        int(seed),
        _step_log(law.name, scenario, seed, observations, actions, infos, rewards),
    )


def _step_log(
    policy: str,
    scenario: str,
    seed: int,
    observations: list[np.ndarray],
    actions: list[np.ndarray],
    infos: list[dict[str, Any]],
    rewards: list[float],
) -> pd.DataFrame:
    n = len(infos)
    obs = np.asarray(observations, dtype=np.float64)
    act = np.full((n, 2), np.nan)
    act[: len(actions)] = np.asarray(actions, dtype=np.float64).reshape(-1, 2)
    info = pd.DataFrame.from_records(infos)
    data: dict[str, Any] = {
        "policy": policy,
        "scenario": scenario,
        "seed": int(seed),
        "obs_distance_m": obs[:, 0],
        "obs_offset_px": obs[:, 1],
        "action_v_mps": act[:, 0],
        "action_w_radps": act[:, 1],
        "reward": rewards,
    }
    for column in _INFO_COLUMNS:
        values = info[column]
        data[column] = values.astype(np.int64) if column in _FLAG_COLUMNS else values
    # termination is only ever set in the final row; earlier rows are blank in the CSV.
    data["termination"] = info["termination"].where(info.index == n - 1, "")
    return pd.DataFrame(data, columns=list(COLUMNS))


def auto_workers(episodes: int) -> int:
    """How many processes pay off for ``episodes`` episodes on this machine (1 = no pool).

    A pool worker costs about 2 s to start and an episode about 5 ms (measured, see
    ``_EPISODES_PER_WORKER_START``), so small grids such as the thesis comparison (120 episodes)
    run fastest in this process.
    """
    cores = os.cpu_count() or 1
    return max(1, min(cores, episodes // _EPISODES_PER_WORKER_START))


def _run_task(task: tuple[PolicySpec, str, int, EnvConfigSpec, Reducer | None]) -> Any:
    policy, scenario, seed, config, reduce = task
    episode = run_episode(policy, scenario, seed, config=config)
    return episode if reduce is None else reduce(episode)


def rollout(
    policies: Sequence[PolicySpec],
    scenarios: Sequence[str],
    seeds: Sequence[int],
    *,
    config: EnvConfigSpec = "thesis",
    workers: int | None = None,
    progress: bool = False,
    reduce: Reducer | None = None,
) -> list[Any]:
    """Run every policy on every (scenario, seed) pair: identical rollouts.

    :param policies: policy names (``make_policy``; every tool's way of naming them) or
        :class:`~policies.Policy` objects. A fresh policy is built (or the object reset) for
        every episode, so episodes never share memory.
    :param scenarios: registered scenario names (``follow_env.SCENARIOS``).
    :param seeds: the seeds; seed ``s`` gives the same person and noise to every policy.
    :param config: the env configuration, as for :func:`run_episode`.
    :param workers: processes to use; 1 runs here, None picks :func:`auto_workers`.
    :param progress: show a progress bar (tqdm, on stderr; hidden when not a terminal).
    :param reduce: if given, applied to each :class:`Episode` in the process that ran it, and
        its results are returned instead of the episodes (a search that needs one number per
        episode then never holds thousands of step logs). Must be picklable for a pool (a
        module-level function).
    :returns: the episodes (or their reductions) in grid order: policy, scenario, seed.
    :raises ValueError: for an unknown policy or scenario, an empty grid, a non-integer seed, or
        workers < 1, before any episode runs.
    """
    tasks = [(*t, reduce) for t in _tasks(policies, scenarios, seeds, config)]
    if workers is None:
        workers = auto_workers(len(tasks))
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers={workers!r} is out of range: must be an integer >= 1")
    from tqdm import tqdm

    bar = tqdm(total=len(tasks), desc="episodes", unit="ep", disable=None if progress else True)
    try:
        if workers == 1:
            episodes = []
            for task in tasks:
                episodes.append(_run_task(task))
                bar.update()
            return episodes
        chunk = max(1, math.ceil(len(tasks) / (4 * workers)))
        # spawn, not fork: a forked child of a process with live threads (tqdm's monitor, BLAS
        # pools) can deadlock; spawned workers load the cached kernels in about 2 s.
        with ProcessPoolExecutor(workers, mp_context=get_context("spawn")) as pool:
            episodes = []
            for episode in pool.map(_run_task, tasks, chunksize=chunk):
                episodes.append(episode)
                bar.update()
            return episodes
    finally:
        bar.close()


def _tasks(
    policies: Sequence[PolicySpec],
    scenarios: Sequence[str],
    seeds: Sequence[int],
    config: EnvConfigSpec,
) -> list[tuple[PolicySpec, str, int, EnvConfigSpec]]:
    if isinstance(policies, str) or isinstance(scenarios, str):
        raise ValueError("policies and scenarios must be sequences of names, not one string")
    for name, items in (("policies", policies), ("scenarios", scenarios), ("seeds", seeds)):
        if len(items) == 0:
            raise ValueError(f"{name} is empty: give at least one")
    for spec in policies:
        if isinstance(spec, str):
            make_policy(spec)  # raises ValueError listing the known names
        elif not isinstance(spec, Policy):
            raise ValueError(f"policy {spec!r} is neither a policy name nor a Policy")
    known = sorted(follow_env.SCENARIOS)
    for scenario in scenarios:
        if scenario not in follow_env.SCENARIOS:
            raise ValueError(f"unknown scenario {scenario!r}; known scenarios: {', '.join(known)}")
    for seed in seeds:
        if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
            raise ValueError(f"seed={seed!r} is out of range: must be an integer >= 0")
    return [(p, s, int(seed), config) for p in policies for s in scenarios for seed in seeds]
