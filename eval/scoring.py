"""A run's scoring, scenario by scenario on the run's backend: step logs, episodes, statistics.

After its episodes, ``follow-eval run`` writes a step log per episode and computes the episode
table, the bootstrap intervals of every cell (:func:`eval.stats.summarize`) and the paired
comparisons (:func:`eval.stats.compare`). On a grid of thousands of episodes that costs about as
much as the episodes themselves, and every piece of it is independent between scenarios: a
cell's interval is drawn from a stream keyed by its names, and a comparison pairs two policies on
one scenario. So :func:`score` runs one work unit per scenario on the backend the episodes ran
on, and puts the pieces together in the order the serial functions give: the tables are equal,
frame for frame, to ``episode_table``, ``summarize`` and ``compare`` on all the episodes at once,
and each log's text to what :func:`eval.steplog.write_step_log` writes (tested).

The units return the logs' text, and this process writes the files, so that Ray workers on other
machines need not share the run's folder. Each unit carries this process's sources digest, which
its worker checks (:func:`eval.provenance.check_worker_code`): a node with other metrics' code
would score the episodes otherwise, unnoticed.

``follow-eval metrics`` scores step logs from disk the same way, after :func:`read_episodes` has
read them on the same backend, a chunk of files to a unit (reading costs about as much as the
scoring: about 4 ms a simulated log).
"""

from __future__ import annotations

import csv
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from decimal import Decimal
from pathlib import Path

import pandas as pd

from eval.metrics import Metric
from eval.provenance import check_worker_code, running_sources_sha256
from eval.rollout import Episode
from eval.stats import (
    EpisodeRow,
    binary_metrics,
    compare,
    episode_table,
    pairing_notes,
    summarize,
    with_holm,
)
from eval.steplog import StepLogError, read_step_log, step_log_text
from execution.backend import Backend, execute

__all__ = ["Scored", "read_episodes", "score"]

#: Step logs read by one work unit of :func:`read_episodes`: enough that a unit's 0.4 s of
#: reading outweighs sending it, few enough that two workers share 200 logs evenly.
_FILES_PER_UNIT = 100


@dataclass(frozen=True)
class Scored:
    """What :func:`score` gives: the three tables of ``follow-eval run``.

    :param table: :func:`eval.stats.episode_table` of the episodes.
    :param summary: :func:`eval.stats.summarize` of it.
    :param comparisons: :func:`eval.stats.compare` of it.
    """

    table: pd.DataFrame
    summary: pd.DataFrame
    comparisons: pd.DataFrame


@dataclass(frozen=True)
class _Scenario:
    """One work unit: a scenario's episodes, and what to score them by."""

    episodes: list[Episode | EpisodeRow]
    metrics: Mapping[str, Metric]
    variant: str
    policies: tuple[str, ...]  # the run's policies in table order: the comparisons' pairs
    logs: bool
    code: str | None = None  # the driver's sources digest, checked by the worker


def _score_scenario(unit: _Scenario) -> tuple[list[str], pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    """A scenario's log texts (``[]`` without logs), episode table, summary and comparisons."""
    check_worker_code(unit.code)  # a worker with other metrics would score unnoticed
    texts = [step_log_text(ep.log) for ep in unit.episodes] if unit.logs else []  # type: ignore[union-attr]
    table = episode_table(unit.episodes, metrics=unit.metrics, variant=unit.variant)
    names = list(unit.metrics)
    summary = summarize(table, metrics=names, rates=binary_metrics(unit.metrics))
    comparisons = compare(table, metrics=names, policies=unit.policies)
    return texts, table, summary, comparisons


def score(
    episodes: Sequence[Episode | EpisodeRow],
    *,
    metrics: Mapping[str, Metric],
    variant: str = "scenario",
    log_path: Callable[[Episode], Path] | None = None,
    backend: Backend | None = None,
) -> Scored:
    """Score ``episodes`` and write their step logs, one work unit per scenario on ``backend``.

    :param episodes: the episodes, or with ``log_path=None`` also episodes already reduced to
        their table rows (:class:`eval.stats.TableRow`, a run without step logs).
    :param metrics: the metrics by name, in table order (the task's).
    :param variant: the name of the tables' ``scenario`` column (``"track"`` for LineTrace).
    :param log_path: where each episode's step log goes (its folder must exist); None writes no
        logs.
    :param backend: where the units run (default: this process).
    :returns: the tables, as :func:`eval.stats.episode_table`, :func:`eval.stats.summarize` and
        :func:`eval.stats.compare` give them for all of ``episodes`` at once (the bootstrap's
        default seed). Where two policies ran different seeds of a scenario, one warning line
        on stderr names the pairs (:func:`eval.stats.pairing_notes`): their comparisons use
        only the seeds both ran, or none.
    """
    names = list(metrics)
    if log_path is not None and any(isinstance(ep, EpisodeRow) for ep in episodes):
        raise ValueError("log_path is given, but some episodes were reduced to rows: no step log")
    if not episodes:
        table = episode_table([], metrics=metrics, variant=variant)
        summary = summarize(table, metrics=names, rates=binary_metrics(metrics))
        return Scored(table, summary, compare(table, metrics=names))
    policies = tuple(dict.fromkeys(ep.policy for ep in episodes))
    rows: dict[str, list[int]] = {}  # scenario -> its episodes' positions, in first-seen order
    for k, ep in enumerate(episodes):
        rows.setdefault(ep.scenario, []).append(k)
    code = running_sources_sha256()
    logs = log_path is not None
    units = [
        _Scenario([episodes[k] for k in ks], dict(metrics), variant, policies, logs, code)
        for ks in rows.values()
    ]
    positions = list(rows.values())

    def write_logs(i: int, part: tuple[list[str], ...]) -> None:
        # As each unit finishes, into the run's temporary folder (renamed whole when the run is
        # written); the texts are then let go, so the logs are not all held at once.
        texts = part[0]
        for k, text in zip(positions[i], texts, strict=True):
            log_path(episodes[k]).write_text(text, encoding="utf-8", newline="")  # type: ignore[misc]
        texts.clear()

    parts = execute(
        _score_scenario, units, backend, on_result=write_logs if log_path is not None else None
    )
    order = [k for ks in positions for k in ks]
    table = pd.concat([part[1] for part in parts], ignore_index=True)
    table.index = order  # each row at its episode's position
    table = table.sort_index().reset_index(drop=True)
    # The summary's cells in the order they first appear in the table, as summarize gives them.
    summary = pd.concat([part[2] for part in parts], ignore_index=True)
    cells = table[["policy", variant]].drop_duplicates()
    summary = cells.merge(summary, on=["policy", variant], how="left", validate="one_to_one")
    # Holm's family is a metric's rows over every scenario: adjusted again on the whole table.
    comparisons = with_holm(pd.concat([part[3] for part in parts], ignore_index=True))
    notes = pairing_notes(comparisons)
    if notes:  # the report says so too (eval.report.markdown_report); this is the one line
        print(
            "follow-eval: warning: policies that ran different seeds are compared on the seeds "
            "both ran only: " + "; ".join(notes),
            file=sys.stderr,
        )
    return Scored(table, summary, comparisons)


@dataclass(frozen=True)
class _Files:
    """One work unit of :func:`read_episodes`: some of the files, with their positions."""

    files: list[tuple[int, Path, Path]]  # position, the path as given, the path absolute
    task: str
    variant: str  # the variant's column (``scenario``, ``track``)
    labels: tuple[str, str]  # policy and variant for a log without those columns
    code: str | None = None  # the driver's sources digest, checked by the worker


def _read_files(unit: _Files) -> tuple[list[Episode], StepLogError | None]:
    """The unit's files as episodes, up to the first that cannot be read (returned, so that
    :func:`read_episodes` reports the first bad file in the given order, whichever unit
    finished first).

    Each file is read by its absolute path (a Ray worker's own folder is not the driver's)
    and named in a message as it was given."""
    check_worker_code(unit.code)
    episodes = []
    for i, given, path in unit.files:
        try:
            log = read_step_log(path, unit.task)
        except StepLogError as e:
            return episodes, _as_given(e, path, given)
        policy = _first_text(log, "policy") or unit.labels[0]
        variant = _first_text(log, unit.variant) or unit.labels[1]
        seed = _seed(path, float(log["seed"].iloc[0])) if _has_seeds(log) else i
        # A log without a termination column keeps none: its ending is unknown, so the
        # metrics of endings (collision, lost, success) are NaN, not a clean run's 0 / 100.
        episodes.append(Episode(policy, variant, seed, log))
    return episodes, None


def _as_given(error: StepLogError, path: Path, given: Path) -> StepLogError:
    """``error`` naming the file as the user gave it (every message starts ``<path>: ``)."""
    text, read = str(error), f"{path}: "
    if path == given or not text.startswith(read):
        return error
    return StepLogError(f"{given}: {text[len(read) :]}")


def _has_seeds(log: pd.DataFrame) -> bool:
    return "seed" in log and bool(log["seed"].notna().all())


def _seed(path: Path, value: float) -> int:
    """The log's seed, exactly: ``value`` is its first row's ``seed`` as the log was read
    (float64, exact up to 2**53); a larger one is read again from the file's text, since runs
    take seeds up to 2**256 - 1 and two seeds 2**53 apart would be one float."""
    if abs(value) < 2.0**53:
        return int(value)
    with path.open(newline="", encoding="utf-8") as f:  # read_step_log has checked it
        reader = csv.reader(f)
        column = [cell.strip() for cell in next(reader)].index("seed")
        first = next(row for row in reader if any(cell.strip() for cell in row))  # as read
    return int(Decimal(first[column].strip()))


def _first_text(log: pd.DataFrame, column: str) -> str | None:
    if column not in log:
        return None
    values = [v for v in log[column] if isinstance(v, str) and v]
    return values[0] if values else None


def read_episodes(
    files: Sequence[Path],
    *,
    task: str,
    variant: str = "scenario",
    policy: str = "robot",
    label: str = "recorded",
    backend: Backend | None = None,
) -> list[Episode]:
    """Read step logs (:func:`eval.steplog.read_step_log`) as episodes, in the order given.

    An episode's policy and variant are its log's ``policy`` and ``variant`` columns (the first
    non-blank cell), else ``policy`` and ``label``; its seed the ``seed`` column where every row
    has one, else the file's position in ``files``. A log without ``termination`` is kept without
    one: its ending is unknown, and the metrics of endings are NaN for it.

    :param task: the task whose layout the logs follow (``person_follow``, ``line_trace``).
    :param variant: the name of the task's variant column (``"track"`` for LineTrace).
    :param backend: where the files are read, :data:`_FILES_PER_UNIT` to a unit (default: this
        process).
    :raises StepLogError: of the first file, in the given order, that cannot be read.
    """
    # Absolute for the workers, whose folder is not this process's on a cluster.
    numbered = [(i, Path(f), Path(f).absolute()) for i, f in enumerate(files)]
    code = running_sources_sha256()
    units = [
        _Files(numbered[k : k + _FILES_PER_UNIT], task, variant, (policy, label), code)
        for k in range(0, len(numbered), _FILES_PER_UNIT)
    ]
    finished: dict[int, StepLogError | None] = {}

    def stop_at_a_bad_file(i: int, part: tuple[list[Episode], StepLogError | None]) -> None:
        # Report a bad file as soon as every unit before its own has read well, so that one
        # process stops at the first bad file and a pool gives the same one.
        finished[i] = part[1]
        k = 0
        while k in finished and finished[k] is None:
            k += 1
        error = finished.get(k)
        if error is not None:
            raise error

    parts = execute(_read_files, units, backend, on_result=stop_at_a_bad_file)
    return [episode for read, _ in parts for episode in read]
