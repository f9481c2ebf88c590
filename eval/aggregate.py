"""``follow-eval aggregate``: learners over training seeds against the laws, at rliable's standard.

::

    follow-eval aggregate runs/ppo-study [runs/other-study ...] --laws pn,mpn,gsmpn \\
        --scenarios straight,curve,random --episodes 10 --out runs/aggregate-x

Each ``RUN`` is a learner: a study of ``follow-train --seeds`` (its ``seed-<k>/`` run folders,
one per training seed) or a single run folder (one seed). Every seed's agent and every law
play the same scenarios x evaluation seeds (identical rollouts; seeds ``--seed`` ..), and each
episode is scored by the env's own summed reward, normalised per scenario to [0, 1] by the
lowest and highest episode score any controller reached there (a score of 1 is the best
episode seen on that scenario), so that scenarios with larger rewards do not outweigh the rest.

Following Agarwal et al. (2021) and their library rliable, a controller's **run** is one
training seed's agent (a law, which is not trained, is one run), and its score on a scenario is
the mean of its normalised episode scores there: a (runs, tasks) matrix as rliable takes it.
For every controller:

- the **interquartile mean** (IQM), mean, median and optimality gap of that matrix, each with a
  95 % **stratified hierarchical bootstrap** CI: within each scenario the runs are resampled
  with replacement (rliable's ``StratifiedBootstrap``), and then the evaluation episodes of each
  drawn run (the evaluation seeds, drawn once per scenario and draw for every controller alike,
  so paired comparisons stay paired); so the interval holds both the spread between training
  seeds and the episodes' own, and a law's interval (one run) the episodes' alone;
- the **performance profile**: the share of (run, scenario) scores above tau, for tau in
  [0, 1], with its bootstrap band;
- the **probability of improvement** of each learner over each law, and of each learner over
  each other learner, P(X > Y) between their runs' scores averaged over the scenarios
  (rliable's ``probability_of_improvement``, the Mann-Whitney statistic), with the same
  bootstrap over both.

An earlier version counted every (training seed, episode) as a run. That ignores that episodes
of one agent share its training seed: with five seeds whose agents differ, its intervals
covered a learner's mean in fewer than half of simulated studies (the unit here: about 9 in
10 at the nominal 95 %, the rest being the percentile bootstrap's shortfall on five runs).

The point estimates are rliable's own functions (``rliable.metrics``). rliable 1.2's bootstrap
module does not import with pandas 3 (its dependency ``arch`` 7.2 fails on import, and ``arch``
8 changed the call rliable makes), so the bootstrap here is a few lines of numpy that resample
the runs exactly as rliable's ``StratifiedBootstrap`` does (per task, with replacement), and
the episodes within them, seeded, so the intervals are reproducible.

The scenarios are also grouped into the splits of the social-navigation benchmarks
(:data:`~follow_env.tasks.person_follow.scenarios.SPLITS`: ``single_target``, ``distractor``,
``look_alike``; each scenario declares its own): per split that holds any of the scenarios run,
the IQM of every controller and each learner's probability of improvement over each law,
with the same stratified bootstrap over that split's scenarios only.

A study's runs are the seeds its ``study.json`` lists, each of which must have finished
(:mod:`eval.aggregate_inputs`, which finds and checks the learners before any episode runs);
every controller runs on the differential drive (:data:`~eval.aggregate_inputs.PLATFORM`).

Writes ``aggregate.csv`` (controller, metric, estimate, ci_low, ci_high), ``improvement.csv``
(learner, law, probability, ci_low, ci_high), ``learners.csv`` (learner, other, probability,
ci_low, ci_high: P(learner > other) for each pair of learners, with two or more),
``splits.csv`` (split, scenarios, controller, law, metric, estimate, ci_low, ci_high),
``profiles.csv``, ``scores.csv`` (every episode's raw and normalised score, with its split, its
run's position ``run`` in the learner, the run's ``training_seed`` and ``agent`` path, both
blank for a law; a run's score is the mean of its rows), ``aggregate.md``, ``plots/``
(interval estimates, performance profiles) and ``meta.json`` (the command, each learner's
agents with their training seeds and model digests, the laws, scenarios, evaluation seeds, the
bootstrap's draws and seeds (:func:`bootstrap_record`), package versions and the code's
digest), atomically.
"""

from __future__ import annotations

import itertools
import operator
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from eval.aggregate_inputs import LearnerRuns, check_learners, learner_runs
from eval.rollout import rollout

__all__ = [
    "BOOTSTRAP_SEEDS",
    "LearnerRuns",
    "aggregate",
    "aggregate_metrics",
    "bootstrap_record",
    "check_learners",
    "learner_runs",
    "normalised_scores",
    "scenario_split",
    "stratified_ci",
]

#: Bootstrap samples of a performance profile's band, as a share of ``reps`` (21 taus each).
_PROFILE_REPS_SHARE = 4
#: Confidence level of every interval.
LEVEL = 0.95
#: The seed of each table's bootstrap (:func:`stratified_ci`'s ``seed``): the aggregate
#: metrics one each; every probability of improvement (overall and per split), the splits'
#: IQMs and the profiles' bands 0. Fixed, so that the same command gives the same intervals;
#: ``meta.json`` records them.
BOOTSTRAP_SEEDS: dict[str, int] = {
    "iqm": 0,
    "mean": 1,
    "median": 2,
    "optimality_gap": 3,
    "improvement": 0,
    "between_learners": 0,
    "splits": 0,
    "profiles": 0,
}


def bootstrap_record(reps: int) -> dict[str, Any]:
    """How the intervals were drawn, as ``meta.json`` records it."""
    return {
        "method": "stratified hierarchical percentile bootstrap (runs per scenario, then the "
        "evaluation seeds, paired across controllers)",
        "level": LEVEL,
        "reps": reps,
        "profile_reps": _profile_reps(reps),
        "seeds": dict(BOOTSTRAP_SEEDS),
    }


def _profile_reps(reps: int) -> int:
    # a share of the draws (21 taus each), at least one: --reps 1..3 is allowed
    return max(1, reps // _PROFILE_REPS_SHARE)


def aggregate_metrics() -> dict[str, Callable[[np.ndarray], float]]:
    """The aggregate metrics over a (runs, tasks) score matrix, by name: rliable's."""
    from rliable import metrics

    return {
        "iqm": metrics.aggregate_iqm,
        "mean": metrics.aggregate_mean,
        "median": metrics.aggregate_median,
        "optimality_gap": metrics.aggregate_optimality_gap,
    }


def normalised_scores(raw: pd.DataFrame) -> pd.DataFrame:
    """``raw`` (columns controller, run, scenario, seed, score) with ``normalised``: per
    scenario, (score - lowest) / (highest - lowest) over every controller's episodes."""
    out = raw.copy()
    by = out.groupby("scenario")["score"]
    low, high = by.transform("min"), by.transform("max")
    span = (high - low).where(high > low, 1.0)
    out["normalised"] = (out["score"] - low) / span
    return out


def _cube(scores: pd.DataFrame, scenarios: Sequence[str]) -> np.ndarray:
    """A controller's (runs, tasks, episodes) normalised scores: runs = training seeds, tasks =
    scenarios, episodes = evaluation seeds in ascending order (the same for every controller of
    a grid, so that the bootstrap can draw them alike)."""
    table = scores.pivot_table(
        index=["run", "scenario"], columns="seed", values="normalised", aggfunc="first"
    )
    runs = sorted(set(scores["run"]))
    rows = pd.MultiIndex.from_product([runs, list(scenarios)], names=["run", "scenario"])
    cube = table.reindex(rows).sort_index(axis=1).to_numpy(dtype=float)
    return cube.reshape(len(runs), len(scenarios), -1)


def _resample_cube(cube: np.ndarray, episodes: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """One hierarchical draw of a (runs, tasks, episodes) cube as a (runs, tasks) matrix: the
    runs resampled with replacement within each task (rliable's ``StratifiedBootstrap``), then
    the drawn episode indices ``episodes`` (tasks, episodes) taken from each drawn run, and
    averaged."""
    runs, tasks, _ = cube.shape
    rows = rng.integers(0, runs, size=(runs, tasks))
    task = np.arange(tasks)
    return cube[rows[:, :, None], task[None, :, None], episodes[None, :, :]].mean(axis=2)


def stratified_ci(
    func: Callable[..., float],
    cubes: Sequence[np.ndarray],
    reps: int,
    seed: int = 0,
    level: float = LEVEL,
) -> tuple[float, float, float]:
    """``func`` of the controllers' (runs, tasks) score matrices and its percentile CI over
    ``reps`` stratified hierarchical bootstrap draws (module docstring).

    :param cubes: each controller's (runs, tasks, episodes) scores, all with the same tasks and
        episodes; a (runs, tasks) matrix is one episode a cell (runs resampled only). ``func``
        is given the cubes' means over their episodes.
    :raises ValueError: for ``reps`` < 1 (a percentile of no draws is undefined), or cubes
        whose tasks or episodes differ.
    """
    if reps < 1:
        raise ValueError(f"stratified_ci: reps must be >= 1, got {reps}")
    cubes = [c[:, :, None] if c.ndim == 2 else c for c in (np.asarray(c, float) for c in cubes)]
    shape = cubes[0].shape[1:]
    if any(c.shape[1:] != shape for c in cubes):
        shapes = ", ".join(str(c.shape[1:]) for c in cubes)
        raise ValueError(f"stratified_ci: the (tasks, episodes) of the cubes differ: {shapes}")
    tasks, episodes = shape
    rng = np.random.default_rng(seed)
    point = float(func(*(c.mean(axis=2) for c in cubes)))
    draws = np.empty(reps)
    for k in range(reps):
        # one draw of the evaluation seeds per task, shared by every controller: paired
        drawn = rng.integers(0, episodes, size=(tasks, episodes))
        draws[k] = func(*(_resample_cube(c, drawn, rng) for c in cubes))
    tail = 100.0 * (1.0 - level) / 2.0
    low, high = np.percentile(draws, [tail, 100.0 - tail])
    return point, float(low), float(high)


def aggregate(
    learners: Sequence[LearnerRuns],
    laws: Sequence[str],
    scenarios: Sequence[str],
    seeds: Sequence[int],
    *,
    config: Any = None,
    reps: int = 2000,
    backend: Any = None,
) -> dict[str, pd.DataFrame]:
    """Run every agent and law on the grid and compute the tables (module docstring).

    :returns: ``scores``, ``aggregate``, ``improvement``, ``learners``, ``splits`` and
        ``profiles`` tables.
    """
    agents = [str(a) for learner in learners for a in learner.agents]
    policies = [*agents, *laws]
    # rollout checks every name (agents, laws, scenarios) before any episode runs
    returns = rollout(
        policies,
        list(scenarios),
        list(seeds),
        config=config,
        reduce=operator.attrgetter("total_reward"),
        backend=backend,
    )
    # each agent's (learner, run, training seed, path); a law is its own single run
    owner = {
        str(a): (learner.name, k, seed, str(Path(a).absolute()))
        for learner in learners
        for k, (a, seed) in enumerate(zip(learner.agents, learner.seeds, strict=True))
    }
    grid = itertools.product(policies, scenarios, seeds)  # rollout's order
    rows = [
        (*owner.get(policy, (policy, 0, None, "")), scenario, int(seed), score)
        for (policy, scenario, seed), score in zip(grid, returns, strict=True)
    ]
    columns = ["controller", "run", "training_seed", "agent", "scenario", "seed", "score"]
    raw = pd.DataFrame(rows, columns=columns)
    raw["training_seed"] = raw["training_seed"].astype("Int64")  # blank for a law, a single run
    scores = normalised_scores(raw)
    controllers = [learner.name for learner in learners] + list(laws)
    matrix = {c: _cube(scores[scores["controller"] == c], scenarios) for c in controllers}
    table = []
    for c in controllers:
        for metric, fn in aggregate_metrics().items():
            point, low, high = stratified_ci(fn, [matrix[c]], reps, seed=BOOTSTRAP_SEEDS[metric])
            table.append((c, metric, point, low, high))
    improvement = _improvements(matrix, learners, laws, reps)
    between = _between_learners(matrix, learners, reps)
    scores["split"] = scores["scenario"].map(scenario_split)
    splits = _by_split(matrix, learners, laws, scenarios, reps)
    taus = np.linspace(0.0, 1.0, 21)
    profiles = []
    for c in controllers:
        for tau in taus:
            point, low, high = stratified_ci(
                lambda m, t=tau: float(np.mean(m > t)),
                [matrix[c]],
                _profile_reps(reps),
                seed=BOOTSTRAP_SEEDS["profiles"],
            )
            profiles.append((c, float(tau), point, low, high))
    return {
        "scores": scores,
        "aggregate": pd.DataFrame(
            table, columns=["controller", "metric", "estimate", "ci_low", "ci_high"]
        ),
        "improvement": pd.DataFrame(
            improvement, columns=["learner", "law", "probability", "ci_low", "ci_high"]
        ),
        "learners": pd.DataFrame(
            between, columns=["learner", "other", "probability", "ci_low", "ci_high"]
        ),
        "profiles": pd.DataFrame(
            profiles, columns=["controller", "tau", "fraction", "ci_low", "ci_high"]
        ),
        "splits": splits,
    }


def scenario_split(scenario: str) -> str:
    """The split a PersonFollow scenario declares (``single_target``, ``distractor``, ...)."""
    from follow_env.tasks.person_follow.scenarios import get_scenario

    return str(get_scenario(scenario).split)


def _improvements(
    matrix: dict[str, np.ndarray], learners: Sequence[LearnerRuns], laws: Sequence[str], reps: int
) -> list[tuple[str, str, float, float, float]]:
    """``(learner, law, P(learner > law), ci_low, ci_high)`` for every learner and law, on
    the given score matrices (all scenarios, or one split's columns)."""
    from rliable import metrics

    rows = []
    for learner in learners:
        for law in laws:
            point, low, high = stratified_ci(
                metrics.probability_of_improvement,
                [matrix[learner.name], matrix[law]],
                reps,
                seed=BOOTSTRAP_SEEDS["improvement"],
            )
            rows.append((learner.name, law, point, low, high))
    return rows


def _between_learners(
    matrix: dict[str, np.ndarray], learners: Sequence[LearnerRuns], reps: int
) -> list[tuple[str, str, float, float, float]]:
    """``(learner, other, P(learner > other), ci_low, ci_high)`` for every pair of learners,
    each pair once in the order given (the Mann-Whitney statistic, ties counting half, so
    P(other > learner) is 1 minus it): whether one learner's runs beat another's, which
    overlapping IQM intervals cannot say."""
    from rliable import metrics

    rows = []
    for i, first in enumerate(learners):
        for second in learners[i + 1 :]:
            point, low, high = stratified_ci(
                metrics.probability_of_improvement,
                [matrix[first.name], matrix[second.name]],
                reps,
                seed=BOOTSTRAP_SEEDS["between_learners"],
            )
            rows.append((first.name, second.name, point, low, high))
    return rows


def _by_split(
    matrix: dict[str, np.ndarray],
    learners: Sequence[LearnerRuns],
    laws: Sequence[str],
    scenarios: Sequence[str],
    reps: int,
) -> pd.DataFrame:
    """Per split of the scenarios run: every controller's IQM and each learner's probability
    of improvement over each law, on that split's columns of the score matrices."""
    from rliable import metrics

    from follow_env.tasks.person_follow.scenarios import SPLITS

    rows = []
    for split in SPLITS:
        columns = [k for k, name in enumerate(scenarios) if scenario_split(name) == split]
        if not columns:
            continue
        names = ",".join(scenarios[k] for k in columns)
        part = {c: m[:, columns] for c, m in matrix.items()}
        for c in part:
            point, low, high = stratified_ci(
                metrics.aggregate_iqm, [part[c]], reps, seed=BOOTSTRAP_SEEDS["splits"]
            )
            rows.append((split, names, c, "", "iqm", point, low, high))
        for learner, law, point, low, high in _improvements(part, learners, laws, reps):
            rows.append((split, names, learner, law, "p_improvement", point, low, high))
    columns = ["split", "scenarios", "controller", "law", "metric", "estimate", "ci_low", "ci_high"]
    return pd.DataFrame(rows, columns=columns)


def write(tables: dict[str, pd.DataFrame], folder: Path, meta: dict[str, Any] | None = None) -> str:
    """Write the tables, plots and ``meta`` (as ``meta.json``, if given) into ``folder``
    (atomically, file by file); returns the Markdown report."""
    import json

    from follow_env.sim.atomic import atomic_write_text

    if meta is not None:
        atomic_write_text(folder / "meta.json", json.dumps(meta, indent=2) + "\n")
    for name in ("scores", "aggregate", "improvement", "learners", "splits", "profiles"):
        atomic_write_text(folder / f"{name}.csv", tables[name].to_csv(index=False))
    report = markdown(tables)
    atomic_write_text(folder / "aggregate.md", report)
    (folder / "plots").mkdir(exist_ok=True)
    _plot_intervals(tables["aggregate"], folder / "plots" / "aggregates.png")
    _plot_profiles(tables["profiles"], folder / "plots" / "performance_profiles.png")
    return report


def markdown(tables: dict[str, pd.DataFrame]) -> str:
    """The aggregate and improvement tables as Markdown."""
    agg = tables["aggregate"].assign(value=_intervals(tables["aggregate"], "estimate"))
    wide = agg.pivot(index="controller", columns="metric", values="value")
    imp = tables["improvement"]
    imp = imp.assign(**{"P(learner > law)": _intervals(imp, "probability")})
    split = tables["splits"]
    split = split.assign(
        value=_intervals(split, "estimate"),
        what=[
            "IQM" if metric == "iqm" else f"P(> {law})"
            for metric, law in zip(split["metric"], split["law"], strict=True)
        ],
    )
    by_split = split[["split", "scenarios", "controller", "what", "value"]]
    between = ""
    if len(tables["learners"]):
        pairs = tables["learners"]
        pairs = pairs.assign(**{"P(learner > other)": _intervals(pairs, "probability")})
        between = "\n\n## Between learners\n\n" + pairs[
            ["learner", "other", "P(learner > other)"]
        ].to_markdown(index=False)
    return (
        "## Aggregate normalised scores (95 % stratified hierarchical bootstrap CIs; a run is a "
        "training seed)\n\n"
        + wide[list(aggregate_metrics())].to_markdown()
        + _single_runs(tables["scores"])
        + "\n\n## Probability of improvement\n\n"
        + imp[["learner", "law", "P(learner > law)"]].to_markdown(index=False)
        + between
        + "\n\n## By scenario split (IQM; P(learner > law))\n\n"
        + by_split.to_markdown(index=False)
        + "\n"
    )


def _intervals(table: pd.DataFrame, point: str) -> list[str]:
    """``point [ci_low, ci_high]`` of each row of ``table``, to three decimals."""
    rows = zip(table[point], table["ci_low"], table["ci_high"], strict=True)
    return [f"{p:.3f} [{lo:.3f}, {hi:.3f}]" for p, lo, hi in rows]


def _single_runs(scores: pd.DataFrame) -> str:
    """A note naming the learners of one run (a single run folder): their intervals hold the
    evaluation episodes' spread only, not the training seeds' the header speaks of."""
    learned = scores[scores["agent"].fillna("").astype(str) != ""]
    runs = learned.groupby("controller", sort=False)["run"].nunique()
    single = [str(name) for name, n in runs.items() if n == 1]
    if not single:
        return ""
    whose = "its" if len(single) == 1 else "their"
    return (
        f"\n\n{', '.join(single)}: one run (one training seed), so {whose} intervals hold the "
        "evaluation episodes' spread only, not the spread between training seeds: give a "
        "follow-train --seeds study to measure that."
    )


def _plot_intervals(table: pd.DataFrame, path: Path) -> Path:
    from eval.report import _pyplot, _save

    plt = _pyplot()
    metrics = list(aggregate_metrics())
    controllers = list(dict.fromkeys(table["controller"]))
    height = 0.5 * len(controllers) + 1.5
    fig, axes = plt.subplots(1, len(metrics), figsize=(3.2 * len(metrics), height))
    for ax, metric in zip(axes, metrics, strict=True):
        rows = table[table["metric"] == metric].set_index("controller").loc[controllers]
        y = np.arange(len(controllers))
        ax.hlines(y, rows["ci_low"], rows["ci_high"], linewidth=6, alpha=0.5)
        ax.plot(rows["estimate"], y, "k|", markersize=14)
        ax.set_yticks(y, controllers if ax is axes[0] else [""] * len(controllers))
        ax.set_title(metric)
        ax.set_xlabel("normalised score")
    fig.tight_layout()
    return _save(fig, path)


def _plot_profiles(table: pd.DataFrame, path: Path) -> Path:
    from eval.report import _pyplot, _save

    fig, ax = _pyplot().subplots(figsize=(6, 4))
    for controller, rows in table.groupby("controller", sort=False):
        ax.plot(rows["tau"], rows["fraction"], label=str(controller))
        ax.fill_between(rows["tau"], rows["ci_low"], rows["ci_high"], alpha=0.2)
    ax.set_xlabel("normalised score tau")
    ax.set_ylabel("fraction of runs with score > tau")
    ax.legend()
    fig.tight_layout()
    return _save(fig, path)
