"""Identical rollouts: every policy on the same scenario x seed grid, on the batched core.

``rollout(policies, scenarios, seeds)`` runs each policy for one episode per (scenario, seed)
pair and returns the step logs. The environment draws every random number from the episode's
seed and the step index, never from the actions (follow_env's seeding, README "Seeding and
identical rollouts"), so for a given (scenario, seed) every policy meets the same person on the
same path with the same detector misses, jitter and depth noise. Differences between the rows of
a table then come from the policies alone, and policies can be compared pair-wise on the same
seeds (:mod:`eval.stats`).

The episodes of one (policy, scenario, config) run together as the lanes of one batched core
(:func:`run_batch`): lane ``i`` seeded ``s_i`` is bit-for-bit the single env reset with
``seed=s_i``, and a policy that acts for many lanes at once (``act_batch``) gives each lane the
action it would give that episode alone (a policy without it gets one copy per lane). So the
step logs are exactly those of one-by-one episodes, only faster. The work units (:func:`work_units`:
one policy, scenario and chunk of at most :data:`BATCH_LANES` seeds each) run on an
:class:`execution.Backend`: this process, a process pool (``workers``) or Ray tasks; whichever,
the results are identical and come back in grid order (policy, then scenario, then seed). A unit
names an agent by its absolute path (a worker's folder is not this process's) and carries this
process's digests of its sources and of the agent's files, which its worker checks; messages
name it by its policy, scenario and seeds (:mod:`eval.units`).

The task is PersonFollow's unless ``task=`` names another (``"line_trace"``): its variants (the
``scenario`` arguments) are then its own (LineTrace's tracks), and its step logs have its layout
(``follow_env.tasks.<task>.steplog``). Everything else is the same machinery.
"""

from __future__ import annotations

import importlib
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import gymnasium as gym
import numpy as np
import pandas as pd

from eval.grid import PolicySpec, checked_policy, policy_spec
from eval.provenance import check_worker_code, check_worker_model
from eval.units import BATCH_LANES, Sent, Work, chunk_size, sent, unit_label, work_units
from execution import Backend, execute
from follow_env.platforms.base import Platform
from follow_env.sim.runner import BatchedSim
from follow_env.tasks import get_task
from policies import Policy, at_period, for_platform, make_policy
from policies.lanes import Lanes
from policies.learned.ensemble import is_learned

__all__ = [
    "BATCH_LANES",
    "MAX_EPISODES",
    "Episode",
    "auto_workers",
    "chunk_size",
    "policy_spec",
    "rollout",
    "run_batch",
    "run_episode",
    "work_units",
]

EnvConfigSpec = str | Mapping[str, Any] | Any
Reducer = Callable[["Episode"], Any]

#: The task a rollout runs unless told.
DEFAULT_TASK = "person_follow"

# Measured on the 2-core development machine (README "Evaluation"): an episode of `straight` or
# `curve` costs about 5 ms (stepping, policy, log), a pool worker about 2 s to start (imports,
# loading the compiled kernels): a pool pays off only above this many episodes per worker.
_EPISODES_PER_WORKER_START = 1000
# The same with the episodes' logs and tables made on the pool too (follow-eval run): pn on
# every scenario took 5.6 s both ways on 300 episodes, 6.3 s against 6.0 on 420 and 7.4-7.6 s
# against 6.6 on 600, and make eval's 160 episodes 3.0 s against 4.5.
_SCORED_EPISODES_PER_WORKER_START = 200
# A learned agent's episode costs this many of a law's in one process (its network acts lane by
# lane, step by step): 1,200 episodes of every scenario took ppo_law 25.7 s and pn 12.5 s on
# the 2-core machine, and two processes ran ppo_law's 1.24x faster, pn's 0.93x.
_LEARNED_EPISODE_COST = 2.1


@dataclass(frozen=True)
class Episode:
    """One policy's episode on one scenario and seed.

    :param policy: the policy's name (``Policy.name``, e.g. ``"pn:tuned"``).
    :param scenario: the scenario name (the task's variant: LineTrace's track).
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
        """Why the episode ended (the info key "termination")."""
        return str(self.log["termination"].iloc[-1])

    @property
    def total_reward(self) -> float:
        """The env's reward summed over the episode (the reset row's NaN is skipped)."""
        return float(self.log["reward"].sum())


class _Task(NamedTuple):
    """What a rollout needs of a task: its model (``follow_env.tasks.<name>.task.TASK``), its
    Gymnasium id and its step-log layout module (``follow_env.tasks.<name>.steplog``: its
    ``log_columns``, ``META_COLUMNS``, ``OBS_COLUMNS`` and ``FLAG_COLUMNS``)."""

    name: str
    model: Any
    env_id: str
    steplog: Any


_TASKS: dict[str, _Task] = {}


def _task(name: str) -> _Task:
    """The task called ``name`` (``ValueError`` listing the known ones)."""
    task = _TASKS.get(name)
    if task is None:
        model = get_task(name)
        steplog = importlib.import_module(f"follow_env.tasks.{name}.steplog")
        task = _TASKS[name] = _Task(name, model, model.spec.env_id, steplog)
    return task


class _Layout(NamedTuple):
    """A platform's step-log layout in a task: the columns, those copied from ``info`` under
    the same name (the task's ``steplog.log_columns``), the action's entry names, the
    observation's columns, the flag columns (booleans in info, 0/1 in the log, as a robot's
    CSV would hold them) and the column naming the variant (``scenario``, ``track``)."""

    columns: tuple[str, ...]
    info: tuple[str, ...]
    actions: tuple[str, ...]
    obs: tuple[str, ...]
    flags: tuple[str, ...]
    variant: str


def _layout(platform: Platform, task: _Task, n_obs: int | None = None) -> _Layout:
    """The layout of a task's step log on ``platform``; ``n_obs``: the observation's entries
    when a configuration adds optional ones (PersonFollow's reading ahead)."""
    actions = tuple(a.name for a in platform.actions)
    log = task.steplog
    obs = tuple(log.OBS_COLUMNS)
    extra: dict[str, Any] = {}
    if n_obs is not None and n_obs > len(obs):
        obs, extra = (*obs, log.AHEAD_COLUMN), {"ahead": True}
    columns = log.log_columns(actions, tuple(key for key, *_ in platform.info), **extra)
    keys = task.model.info_keys(platform)
    info = tuple(c for c in columns if c in keys and c != "termination")
    return _Layout(columns, info, actions, obs, tuple(log.FLAG_COLUMNS), log.META_COLUMNS[1])


_ENV_CACHE: dict[tuple[str, str, str, str], gym.Env] = {}

#: Most episodes one grid may hold (policies x scenarios x seeds): beyond this a run is refused
#: before any work, rather than allowed to exhaust memory.
MAX_EPISODES = 1_000_000


def _env(
    scenario: str,
    config: EnvConfigSpec,
    render: bool,
    platform: str | None,
    task: _Task,
    needs: Mapping[str, Any],
) -> gym.Env:
    """One env per (task, scenario, config, platform, the policy's needs) per process: gym.make
    costs more than an episode."""
    kwargs: dict[str, Any] = {task.model.variant_key: scenario, "config": config}
    kwargs |= {"platform": platform, **needs}
    if render:
        return gym.make(task.env_id, render_mode="rgb_array", **kwargs)
    key = (task.name, scenario, repr(config), str(platform), repr(needs))
    env = _ENV_CACHE.get(key)
    if env is None:
        env = _ENV_CACHE[key] = gym.make(task.env_id, **kwargs)
    return env


def _policy(spec: PolicySpec, task: str = DEFAULT_TASK) -> Policy:
    # the task's policy of a name several tasks have (``ppo``: each task's shipped agent)
    return make_policy(spec, task) if isinstance(spec, str) else spec


def _needs(policy: Policy) -> dict[str, Any]:
    # What the policy needs on top of the run's configuration (policies.base.Policy).
    return dict(getattr(policy, "env_overrides", None) or {})


def _label(name: str, platform: str | None) -> str:
    return name if platform is None else f"{name}@{platform}"


def run_episode(
    policy: PolicySpec,
    scenario: str,
    seed: int,
    *,
    config: EnvConfigSpec | None = None,
    on_frame: Callable[[np.ndarray], None] | None = None,
    task: str = DEFAULT_TASK,
) -> Episode:
    """Run one episode on the single env and return its step log (the same log as lane
    ``seed`` of :func:`run_batch`; this path also renders, for videos).

    :param policy: a policy name (``make_policy``) or a :class:`~policies.Policy`; it is reset
        before the first step.
    :param scenario: a registered scenario name (of ``task``: LineTrace's are tracks).
    :param seed: the episode's seed (``env.reset(seed=seed)``).
    :param config: the env configuration (``gym.make``'s ``config``): a preset name, a dict of
        overrides or the task's config object; None is the task's default preset (PersonFollow's
        ``thesis``).
    :param on_frame: if given, the env renders (``rgb_array``) and each frame, the reset frame
        included, is passed to it (for videos).
    :param task: the task (``"person_follow"``, ``"line_trace"``).
    """
    spec, platform = policy_spec(policy)
    t = _task(task)
    built = _policy(spec, task)
    env = _env(scenario, config, on_frame is not None, platform, t, _needs(built))
    layout = _layout(env.unwrapped.sim.platform, t, env.observation_space.shape[0])
    # a law differentiates over the env's control period, whatever it was built with
    law = for_platform(at_period(built, env.unwrapped.config.episode.control_dt_s), layout.actions)
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
    obs_arr = np.asarray(observations, dtype=np.float64)
    act_arr = np.asarray(actions, dtype=np.float64).reshape(-1, len(layout.actions))
    columns = {k: [inf[k] for inf in infos] for k in (*layout.info, "termination")}
    name = _label(law.name, platform)
    log = _step_log(layout, name, scenario, seed, obs_arr, act_arr, columns, rewards)
    return Episode(name, scenario, int(seed), log)


def run_batch(
    policy: PolicySpec,
    scenario: str,
    seeds: Sequence[int],
    *,
    config: EnvConfigSpec | None = None,
    task: str = DEFAULT_TASK,
    name: str | None = None,
    model_sha256: str | None = None,
) -> list[Episode]:
    """Run one episode per seed, the seeds as the lanes of one batched core; returns the step
    logs in seed order, each identical to :func:`run_episode` of that seed (module docstring).

    :param policy: a policy name or a :class:`~policies.Policy` (a policy with ``act_batch``
        acts for all lanes; another is copied once per lane).
    :param scenario: a registered scenario name.
    :param seeds: the episodes' seeds.
    :param config: the env configuration, as for :func:`run_episode`.
    :param task: the task, as for :func:`run_episode`.
    :param name: the name the episodes carry (before any ``@platform``); None: the policy's.
    :param model_sha256: the agent's files' digest as its unit carries it (the driver's): the
        batch is refused if this process reads other files (:func:`check_worker_model`).
    """
    n = len(seeds)
    spec, platform = policy_spec(policy)
    t = _task(task)
    model = t.model
    built = _policy(spec, task)
    check_worker_model(model_sha256, built, _label(name or built.name, platform))
    variant = {model.variant_key: scenario}
    cfg = model.resolve_config(config, platform=platform, **variant, **_needs(built))
    period = cfg.episode.control_dt_s  # a law differentiates over it (policies.at_period)
    built = at_period(built, period)
    sim = BatchedSim(model, cfg, n)
    layout = _layout(sim.platform, t, model.observations(sim).shape[1])
    try:
        sim.reset_lanes(np.arange(n), [int(s) for s in seeds])
        fresh = (
            (lambda: at_period(make_policy(spec, task), period)) if isinstance(spec, str) else None
        )
        actor = Lanes(built, n, layout.actions, fresh)
        active = np.ones(n, dtype=bool)
        ended_at = np.zeros(n, dtype=np.int64)  # the step each lane's episode ended at
        observations = [model.observations(sim)]
        infos = [model.batch_info(sim)]
        actions: list[np.ndarray] = []
        rewards: list[np.ndarray] = []
        step = 0
        while active.any():
            action = actor.act(observations[-1], active)
            sim.step(action.astype(np.float64), active)
            step += 1
            actions.append(action)
            observations.append(model.observations(sim))
            infos.append(model.batch_info(sim))
            rewards.append(sim.episode["reward"].copy())
            ep = sim.episode
            ended = active & ((ep["terminated"] > 0.0) | (ep["truncated"] > 0.0))
            ended_at[ended] = step
            active &= ~ended
    finally:
        sim.close()
    obs_all = np.stack(observations).astype(np.float64)  # (steps + 1, n, observation size)
    act_all = np.stack(actions).astype(np.float64)  # (steps, n, action size)
    rew_all = np.stack(rewards)  # (steps, n)
    keys = (*layout.info, "termination")
    name = _label(name or actor.name, platform)
    info_all = {k: np.stack([inf[k] for inf in infos]) for k in keys}  # (steps + 1, n)
    episodes = []
    for i, seed in enumerate(seeds):
        last = int(ended_at[i])
        columns = {k: v[: last + 1, i] for k, v in info_all.items()}
        rewards_i = [math.nan, *rew_all[:last, i].tolist()]
        obs_i, act_i = obs_all[: last + 1, i], act_all[:last, i]
        log = _step_log(layout, name, scenario, seed, obs_i, act_i, columns, rewards_i)
        episodes.append(Episode(name, scenario, int(seed), log))
    return episodes


def _step_log(
    layout: _Layout,
    policy: str,
    scenario: str,
    seed: int,
    obs: np.ndarray,
    actions: np.ndarray,
    info: dict[str, Any],
    rewards: list[float],
) -> pd.DataFrame:
    """One episode's step log: rows of observations ``(n, observation size)``, actions
    ``(n - 1, m)`` (the final row has none), info columns of length n, rewards (NaN in the
    reset row)."""
    n = len(obs)
    act = np.full((n, len(layout.actions)), np.nan)
    act[: len(actions)] = actions
    data: dict[str, Any] = {
        "policy": policy,
        layout.variant: scenario,
        "seed": int(seed),
        "reward": np.asarray(rewards, dtype=np.float64),
    }
    for k, column in enumerate(layout.obs):
        data[column] = obs[:, k]
    for k, entry in enumerate(layout.actions):
        data[f"action_{entry}"] = act[:, k]
    for column in layout.info:
        values = np.asarray(info[column])
        data[column] = values.astype(np.int64) if column in layout.flags else values
    # termination is only ever set in the final row; earlier rows are blank in the CSV.
    termination = np.full(n, "", dtype=object)
    termination[-1] = info["termination"][-1]
    data["termination"] = termination
    return pd.DataFrame(data, columns=list(layout.columns))


def auto_workers(episodes: int, learned: int = 0, *, scored: bool = False) -> int:
    """How many processes pay off for ``episodes`` episodes on this machine (1 = no pool):
    small grids such as the thesis comparison (120 episodes) run fastest in this process
    (``_EPISODES_PER_WORKER_START``).

    :param learned: how many of them a learned agent plays; each counts as
        ``_LEARNED_EPISODE_COST`` of a law's (its network is most of the work a pool shares).
    :param scored: the same pool then also writes their logs and computes the tables
        (``follow-eval run``; ``follow-eval metrics``, whose logs it reads: :mod:`eval.scoring`),
        which it pays off sooner for.
    """
    cores = os.cpu_count() or 1
    cost = episodes + (_LEARNED_EPISODE_COST - 1.0) * learned
    per_worker = _SCORED_EPISODES_PER_WORKER_START if scored else _EPISODES_PER_WORKER_START
    return max(1, min(cores, int(cost // per_worker)))


def _run_task(work: Work) -> Any:
    check_worker_code(work.code)  # a worker with other code would make other episodes, unnoticed
    episodes = run_batch(
        work.policy,
        work.scenario,
        work.seeds,
        config=work.config,
        task=work.task,
        name=work.name,
        model_sha256=work.model,  # nor one reading another model at the agent's path
    )
    return episodes if work.reduce is None else [work.reduce(e) for e in episodes]


def rollout(
    policies: Sequence[PolicySpec],
    scenarios: Sequence[str],
    seeds: Sequence[int],
    *,
    config: EnvConfigSpec | None = None,
    workers: int | None = None,
    progress: bool = False,
    reduce: Reducer | None = None,
    task: str = DEFAULT_TASK,
    backend: Backend | None = None,
    chunk: int | None = None,
    done: Mapping[int, list[Any]] | None = None,
    on_unit: Callable[[int, list[Any]], None] | None = None,
    models: Mapping[str, str] | None = None,
    label_suffix: str = "",
) -> list[Any]:
    """Run every policy on every (scenario, seed) pair: identical rollouts.

    :param policies: policy names (``make_policy``; every tool's way of naming them) or
        :class:`~policies.Policy` objects. Episodes never share a policy's memory.
    :param scenarios: registered scenario names (``task``'s variants: LineTrace's tracks).
    :param seeds: the seeds; seed ``s`` gives the same person and noise to every policy.
    :param config: the env configuration, as for :func:`run_episode`.
    :param workers: local processes (1 runs here, None :func:`auto_workers`) without ``backend``.
    :param progress: show a progress bar (tqdm, on stderr; hidden when not a terminal).
    :param reduce: if given, applied to each :class:`Episode` in the process that ran it, and
        its results are returned instead of the episodes (a search that needs one number per
        episode then never holds thousands of step logs). Must be picklable for a pool (a
        module-level function).
    :param task: the task (``"person_follow"``, ``"line_trace"``); a policy registered for
        another task is refused.
    :param backend: where the units run (:class:`execution.Backend`); the same results on each.
    :param chunk: seeds per unit (default :func:`chunk_size`); a resumed run passes its own.
    :param done: results of units already run, by unit index (:func:`work_units`' order).
    :param on_unit: called with (unit index, its episodes) as each finishes (a journal).
    :param models: the digests of the learned policies' files by label as the caller recorded
        them (``meta.json``'s ``model_sha256``): the units carry these, not a digest read now,
        so that files replaced since (between a run's two grids, say) stop the command rather
        than play another model under the recorded label (:func:`check_worker_model`).
    :param label_suffix: appended to each policy's label where messages name its units
        (:func:`eval.units.unit_label`): ``follow-eval run --ideal-baseline`` passes ``+ideal``
        for its second grid, whose failures would otherwise be named as the first grid's. The
        episodes keep their policy's name, and ``models`` is still looked up by the bare label.
    :returns: the episodes (or their reductions) in grid order: policy, scenario, seed.
    :raises ValueError: for an unknown policy or scenario, an empty or too large grid, a
        non-integer seed, or workers < 1, before any episode runs.
    """
    learned, carried = _check_grid(policies, scenarios, seeds, task)
    carried = [
        c._replace(model=(models or {}).get(c.label, c.model), label=c.label + label_suffix)
        for c in carried
    ]
    total = len(policies) * len(scenarios) * len(seeds)
    if backend is None:
        if workers is None:
            workers = auto_workers(total, learned * len(scenarios) * len(seeds))
        if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
            raise ValueError(f"workers={workers!r} is out of range: must be an integer >= 1")
        backend = Backend("local", workers=workers)
    if chunk is None:
        chunk = chunk_size(len(seeds), backend.slots(), len(policies) * len(scenarios))
    units = work_units(carried, scenarios, seeds, config, reduce, chunk, task)
    from tqdm import tqdm

    bar = tqdm(total=total, desc="episodes", unit="ep", disable=None if progress else True)
    bar.update(sum(len(units[i][2]) for i in (done or {})))

    def finished(i: int, chunk: list[Any]) -> None:
        bar.update(len(chunk))
        if on_unit is not None:
            on_unit(i, chunk)

    try:
        chunks = execute(
            _run_task, units, backend, done=done, on_result=finished, describe=unit_label
        )
    finally:
        bar.close()
    return [result for chunk in chunks for result in chunk]


def _check_grid(
    policies: Sequence[PolicySpec],
    scenarios: Sequence[str],
    seeds: Sequence[int],
    task: str = DEFAULT_TASK,
) -> tuple[int, list[Sent]]:
    """Refuse a grid that cannot run (``ValueError``); else how many of its policies learned,
    and each as its units carry it (:func:`eval.units.sent`)."""
    if isinstance(policies, str) or isinstance(scenarios, str):
        raise ValueError("policies and scenarios must be sequences of names, not one string")
    for name, items in (("policies", policies), ("scenarios", scenarios), ("seeds", seeds)):
        if len(items) == 0:
            raise ValueError(f"{name} is empty: give at least one")
    total = len(policies) * len(scenarios) * len(seeds)
    if total > MAX_EPISODES:
        raise ValueError(
            f"the grid holds {total:,} episodes ({len(policies)} policies x {len(scenarios)} "
            f"scenarios x {len(seeds)} seeds): at most {MAX_EPISODES:,} are run at once"
        )
    t = _task(task)  # an unknown task raises
    learned = 0
    carried = []
    for given in policies:
        policy, platform = checked_policy(given, task)
        learned += is_learned(policy)
        carried.append(sent(given, policy, platform))
    known, what = t.model.variants(), t.model.variant_key
    for scenario in scenarios:
        if scenario not in known:
            raise ValueError(f"unknown {what} {scenario!r}; known {what}s: {', '.join(known)}")
    if isinstance(seeds, range):
        if seeds.start < 0 or seeds.step < 1:
            raise ValueError(f"seeds={seeds!r} is out of range: must count up from >= 0")
        return learned, carried
    for seed in seeds:
        if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
            raise ValueError(f"seed={seed!r} is out of range: must be an integer >= 0")
    return learned, carried
