"""The search driver: an Optuna study asked in batches, each trial scored on growing seed sets.

:func:`run_search` knows nothing of laws or environments: it asks the study for a batch of
trials, hands their parameters with a set of seeds to an ``evaluate`` function (which places
the episodes on an execution backend), reports each trial's mean score after every rung, lets
the study's pruner stop the poor ones, and tells the study the final score of the rest. So the
same driver can tune anything whose score is a mean over seeded episodes.

Rungs (:func:`rungs`): a trial is scored on the first quarter of the tuning seeds, then on the
first half, then on all of them; after each rung its mean so far is ``trial.report``-ed at step
= seeds so far, and Optuna's :class:`~optuna.pruners.MedianPruner` prunes it when its best
reported mean so far is below the median of the finished trials' means at the same step.
Every trial meets the same seeds in the same order, so the finished trials' means at one step
are over the same episodes; the trial's own best may be of an earlier rung (Optuna's rule:
``PercentilePruner`` takes the best of a trial's intermediate values), so a trial lucky on the
first quarter of the seeds can survive the half rung while trailing there: it costs episodes,
not a wrong result (every trial that finishes is scored on all the seeds).

In a batch, the trials asked while others of the batch have not been told are sampled with
TPE's ``constant_liar`` (the pending ones count as poor), as Optuna recommends for parallel
asks, so a batch of a cluster's size does not sample its trials from one unchanged model.

Reproducibility: the sampler is a seeded :class:`~optuna.samplers.TPESampler`, the trials of a
batch are asked, evaluated and told in trial order, and the evaluation is exact (identical
rollouts), so the same seed, batch size and budget give the same trials on any backend. A
resumed study seeds its sampler with ``seed + trials already in the study``, so it never
replays the first trials' random draws (modulo 2**32, the seeds the sampler takes).

Storage: a journal file is checked before Optuna opens it (:func:`check_journal`), because
Optuna appends its first record to any file it is given before it reads the file back, so an
unrelated file named by mistake would be changed; a journal this module created is removed
again if opening the study fails.

Shared studies: machines sharing a study each ask their own batches; a running trial counts
towards the budget, so together they do not overshoot it by more than a batch for each other
machine that asks at the same moment (tested with three processes on one SQLite file). Drivers
started together on a new database race to make its tables: the losers open it again once it
is made (:func:`_rdb`). Each trial records its owner and heartbeats, and before each batch the
running trials whose process is gone are failed (:mod:`eval.tuning.liveness`). A trial failed
so while its process was in fact alive (a machine suspended for ten minutes) stays failed:
that process drops it, whichever of its writes meets the failure, and finishes the rest of
its batch.
"""

from __future__ import annotations

import json
import math
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import optuna
from optuna.distributions import FloatDistribution
from optuna.exceptions import UpdateFinishedTrialError
from optuna.trial import FrozenTrial, TrialState

from eval.tuning.liveness import Heartbeat, fail_stale, own, told
from policies.space import SearchSpace

__all__ = [
    "FINISHED",
    "MAX_SAMPLER_SEED",
    "Evaluate",
    "SearchConfig",
    "check_journal",
    "distributions",
    "is_url",
    "journal_problem",
    "journal_study_names",
    "open_study",
    "run_search",
    "rungs",
]

#: The largest seed the TPE sampler takes (numpy's legacy ``RandomState``: 0..2**32 - 1).
MAX_SAMPLER_SEED = 2**32 - 1

#: Trial states that count towards the budget once reached.
FINISHED = (TrialState.COMPLETE, TrialState.PRUNED)

Evaluate = Callable[[Sequence[Mapping[str, float]], Sequence[int]], list[dict[str, np.ndarray]]]
"""``evaluate(params of each trial, seeds)`` -> per trial a dict of arrays shaped (variants,
seeds): ``"score"`` (required: the summed reward of each episode) and any further per-episode
numbers (their mean over the trial's episodes is stored as a user attribute of the trial)."""


@dataclass(frozen=True)
class SearchConfig:
    """How a search runs.

    :param trials: the study's budget of finished (complete or pruned) trials, >= 1.
    :param seeds: the tuning seeds, in the order the rungs take them.
    :param batch: trials asked and evaluated together (the backend's slots), >= 1.
    :param sampler_seed: the TPE sampler's seed, 0..:data:`MAX_SAMPLER_SEED`.
    :param startup_trials: finished trials before the pruner prunes anything, >= 0.
    """

    trials: int
    seeds: tuple[int, ...]
    batch: int = 1
    sampler_seed: int = 0
    startup_trials: int = 5

    def __post_init__(self) -> None:
        for name, low in (("trials", 1), ("batch", 1), ("startup_trials", 0)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise ValueError(f"{name}={value!r} is out of range: must be an integer >= {low}")
        seed = self.sampler_seed
        if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SAMPLER_SEED:
            raise ValueError(
                f"sampler_seed={seed!r} is out of range: must be an integer 0..2**32-1"
            )
        if not self.seeds:
            raise ValueError("seeds is empty: give at least one tuning seed")
        if len(set(self.seeds)) != len(self.seeds):
            raise ValueError("seeds holds a seed twice")


def rungs(n_seeds: int) -> tuple[int, ...]:
    """Cumulative seed counts after which a trial is reported: a quarter, a half, all of them
    (fewer rungs when they coincide), e.g. 12 -> (3, 6, 12), 2 -> (1, 2), 1 -> (1,)."""
    if n_seeds < 1:
        raise ValueError(f"n_seeds={n_seeds!r} is out of range: must be >= 1")
    return tuple(sorted({math.ceil(n_seeds / 4), math.ceil(n_seeds / 2), n_seeds}))


def distributions(space: SearchSpace) -> dict[str, FloatDistribution]:
    """Optuna's distributions for a search space (:mod:`policies.space`)."""
    return {
        name: FloatDistribution(float(r.low), float(r.high), log=r.log) for name, r in space.items()
    }


def is_url(storage: str) -> bool:
    """Whether ``--storage`` names a database (``sqlite:///x.db``, ``postgresql://...``)
    rather than a journal file."""
    return "://" in storage


#: The ``op_code`` of a journal record that creates a study (Optuna's private
#: ``optuna.storages.journal._storage.JournalOperation.CREATE_STUDY``; a test pins it).
_CREATE_STUDY = 0


def _is_record(line: bytes) -> bool:
    """Whether ``line`` is one whole record as Optuna's ``JournalFileBackend`` writes them: a
    JSON object on one line ending in a newline, with an integer ``op_code`` and a string
    ``worker_id`` (``JournalStorage._write_log``)."""
    if not line.endswith(b"\n"):
        return False
    try:
        record = json.loads(line)
    except (ValueError, UnicodeDecodeError):
        return False
    return (
        isinstance(record, dict)
        and type(record.get("op_code")) is int
        and isinstance(record.get("worker_id"), str)
    )


def journal_problem(path: str | Path) -> str | None:
    """Why ``path`` cannot be opened as a journal without harm, or None when it can: it does
    not exist, is empty, or is an Optuna journal (every line a whole record, the first one
    creating a study). The reason follows the path in a sentence: ``f"{path} {reason}"``.

    Optuna's ``JournalFileBackend`` appends to any file and only then fails to read it back,
    so this runs before it touches the file. It reads the whole file, as Optuna does on opening.
    """
    path = Path(path)
    if path.is_dir():
        return "is a folder, not a journal file"
    try:
        with path.open("rb") as f:
            for number, line in enumerate(f, start=1):
                if not _is_record(line):
                    return f"is not an Optuna journal: its line {number} is not a journal record"
                if number == 1 and json.loads(line)["op_code"] != _CREATE_STUDY:
                    return "is not an Optuna journal: its first record does not create a study"
    except FileNotFoundError:
        return None
    except OSError as e:
        return f"cannot be read: {e.strerror or e}"
    return None


def journal_study_names(path: str | Path) -> list[str]:
    """The names of the studies a journal file creates, in order (none for a file that cannot
    be read). Read from the file itself rather than through Optuna, whose journal backend
    opens the file for appending: a check must not touch what it checks."""
    names: list[str] = []
    try:
        with Path(path).open("rb") as f:
            for line in f:
                try:
                    record = json.loads(line)
                except (ValueError, UnicodeDecodeError):
                    continue
                if (
                    isinstance(record, dict)
                    and record.get("op_code") == _CREATE_STUDY
                    and isinstance(record.get("study_name"), str)
                    and record["study_name"] not in names
                ):
                    names.append(record["study_name"])
    except OSError:
        return []
    return names


def check_journal(path: str | Path) -> None:
    """Refuse a file :func:`journal_problem` finds a problem with.

    :raises ValueError: naming the file and what is wrong.
    """
    problem = journal_problem(path)
    if problem is not None:
        raise ValueError(f"{path} {problem}")


#: Attempts at opening a database whose tables another process may be making at that moment.
_RDB_TRIES = 5
#: Wait between those attempts, s (a schema is made in well under a second).
_RDB_RETRY_S = 0.5


def _rdb(url: str) -> optuna.storages.RDBStorage:
    """Optuna's storage on the database ``url``. Drivers started together on a new database
    (a cluster's job array) each make its tables, and all but the first may find a table made
    meanwhile ("table studies already exists": SQLite's ``OperationalError``, PostgreSQL's
    ``ProgrammingError``) or the schema's version recorded already (``IntegrityError``, a
    unique key taken): they try again once it is made, rather than fail the run. Any other
    error (a server that does not answer) is raised at once."""
    for attempt in range(1, _RDB_TRIES + 1):
        try:
            return optuna.storages.RDBStorage(url)
        except Exception as e:
            made_meanwhile = type(e).__name__ == "IntegrityError" or "already exists" in str(e)
            if not made_meanwhile or attempt == _RDB_TRIES:
                raise
            time.sleep(_RDB_RETRY_S)
    raise AssertionError("unreachable")  # the loop returns or raises


def _storage(storage: str | Path) -> Any:
    if isinstance(storage, str) and is_url(storage):
        return _rdb(storage)
    from optuna.storages.journal import JournalFileBackend, JournalStorage

    return JournalStorage(JournalFileBackend(str(storage)))


def open_study(storage: str | Path, name: str, config: SearchConfig) -> optuna.Study:
    """Create the study ``name`` in ``storage`` (a journal file path or an RDB URL), or load
    it to resume: maximising, a seeded TPE sampler (:data:`SearchConfig.sampler_seed` plus the
    trials already there), a median pruner after ``startup_trials`` trials.

    :raises ValueError: if the storage cannot be opened (the message says why); a journal file
        that is not one (:func:`check_journal`) is left as it was.
    """
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    journal = None if isinstance(storage, str) and is_url(storage) else Path(storage)
    if journal is not None:
        check_journal(journal)
    created = journal is not None and not journal.exists()
    try:
        return _open_study(storage, name, config)
    except BaseException:
        if created and journal is not None:  # nothing half-written: the journal made here goes
            journal.unlink(missing_ok=True)
        raise


def _open_study(storage: str | Path, name: str, config: SearchConfig) -> optuna.Study:
    """:func:`open_study` once the storage is known to be safe to open."""
    try:
        backend = _storage(storage)
        existing = optuna.get_all_study_names(backend)
        n = (
            len(optuna.load_study(study_name=name, storage=backend).trials)
            if name in existing
            else 0
        )
        # Wrapped into the sampler's range, so a resumed study with a seed near the top still
        # opens (each trial count still gives its own seed).
        sampler = optuna.samplers.TPESampler(
            seed=(config.sampler_seed + n) % (MAX_SAMPLER_SEED + 1), constant_liar=True
        )
        pruner = optuna.pruners.MedianPruner(
            n_startup_trials=config.startup_trials, n_warmup_steps=0
        )
        if name not in existing:
            try:
                return optuna.create_study(
                    storage=backend,
                    study_name=name,
                    direction="maximize",
                    sampler=sampler,
                    pruner=pruner,
                )
            except optuna.exceptions.DuplicatedStudyError:
                pass  # another machine created it meanwhile: load theirs
        # Loaded, never created again: `create_study(load_if_exists=True)` appends a create
        # record to a journal on every call, so even a command refused after opening the
        # study (other settings) would change the journal.
        return optuna.load_study(study_name=name, storage=backend, sampler=sampler, pruner=pruner)
    except (OSError, ImportError, ValueError, RuntimeError) as e:
        raise ValueError(f"cannot open the storage {storage}: {_first_line(e)}") from None
    except Exception as e:  # SQLAlchemy's errors (a bad URL, an unreachable server, a damaged file)
        if type(e).__module__.startswith("sqlalchemy"):
            raise ValueError(f"cannot open the storage {storage}: {_first_line(e)}") from None
        raise


def _first_line(exc: BaseException) -> str:
    """An error's message without what follows its first line: SQLAlchemy adds the SQL
    statement and a link to its documentation on lines of their own."""
    lines = str(exc).strip().splitlines()
    return lines[0] if lines else type(exc).__name__


def _counted(study: optuna.Study) -> int:
    """Trials that count towards the budget: finished ones and those running elsewhere."""
    return len(study.get_trials(deepcopy=False, states=(*FINISHED, TrialState.RUNNING)))


def run_search(
    study: optuna.Study,
    space: SearchSpace,
    config: SearchConfig,
    evaluate: Evaluate,
    *,
    enqueue: Mapping[str, float] | None = None,
    on_batch: Callable[[list[FrozenTrial]], None] | None = None,
    on_stale: Callable[[list[FrozenTrial]], None] | None = None,
) -> int:
    """Run trials until the study holds ``config.trials`` finished ones; returns how many
    trials this call ran (0 when a resumed study was already complete).

    :param study: from :func:`open_study`.
    :param space: the parameters' ranges (each trial's params are sampled from them on ask).
    :param config: the budget, seeds, batch size.
    :param evaluate: scores a batch of trials on a set of seeds (:data:`Evaluate`).
    :param enqueue: parameters to try first in a new study (the current preset).
    :param on_batch: called with the batch's finished trials after each batch (progress).
    :param on_stale: called with the running trials :func:`fail_stale` failed, as they were,
        whenever it fails some: before the first batch and before each further one (a machine
        sharing the study may be lost at any time).
    """
    dists = distributions(space)
    if enqueue is not None and not study.trials:
        study.enqueue_trial(dict(enqueue))
    steps = rungs(len(config.seeds))
    ran = 0
    while True:
        stale = fail_stale(study)
        if stale and on_stale is not None:
            on_stale(stale)
        if (left := config.trials - _counted(study)) <= 0:
            break
        batch: list[optuna.Trial] = []
        try:
            while len(batch) < min(config.batch, left):
                # Owned and beaten for at once: a trial asked, then left by a crash before its
                # batch began, must still be found stale (by its process or its heartbeat).
                # Asked without its parameters, owned, then sampled: Optuna's ask(dists)
                # creates the trial and then samples them (the same calls, in the same order,
                # so the same values, tested), and a search stopped while it sampled left a
                # trial that no owner named. Only the moments between creating and owning
                # remain, for fail_stale to sweep (liveness.UNOWNED_AFTER_S).
                trial = study.ask()
                batch.append(trial)
                try:
                    own(trial)
                except UpdateFinishedTrialError:  # swept as unowned meanwhile: ask another
                    batch.pop()
                    continue
                for name, dist in dists.items():
                    trial.suggest_float(name, dist.low, dist.high, log=dist.log)
            with Heartbeat(batch):
                _evaluate_batch(study, batch, steps, config.seeds, evaluate)
        except BaseException:
            _fail_unfinished(study, batch)
            raise
        ran += len(batch)
        if on_batch is not None:
            on_batch([study.trials[t.number] for t in batch])
    return ran


def _fail_unfinished(study: optuna.Study, batch: list[optuna.Trial]) -> None:
    """After an error or Ctrl-C, fail the batch's unfinished trials. If the storage refuses
    (it may be what failed), a warning says so, and the error that stopped the batch is the
    one the caller raises: a Ctrl-C stays a Ctrl-C."""
    try:
        for trial in batch:
            told(study, trial.number, state=TrialState.FAIL)
    except Exception as e:
        warnings.warn(
            f"the batch's trials could not be marked failed ({type(e).__name__}: {e}); a "
            "search sharing the study fails them when their heartbeats stop",
            RuntimeWarning,
            stacklevel=3,
        )


def _evaluate_batch(
    study: optuna.Study,
    batch: list[optuna.Trial],
    steps: tuple[int, ...],
    seeds: Sequence[int],
    evaluate: Evaluate,
) -> None:
    """Score the batch rung by rung; prune or finish each trial."""
    active = list(batch)
    kept: dict[int, dict[str, list[np.ndarray]]] = {t.number: {} for t in batch}
    start = 0
    for step in steps:
        results = evaluate([t.params for t in active], seeds[start:step])
        survivors = []
        for trial, result in zip(active, results, strict=True):
            arrays = kept[trial.number]
            for key, values in result.items():
                arrays.setdefault(key, []).append(np.asarray(values, dtype=np.float64))
            joined = {k: np.concatenate(v, axis=-1) for k, v in arrays.items()}
            try:
                for key, values in joined.items():
                    trial.set_user_attr(key, float(np.nanmean(values)))
                trial.set_user_attr("seeds", step)
                trial.report(float(joined["score"].mean()), step)
                if step < steps[-1] and trial.should_prune():
                    told(study, trial.number, state=TrialState.PRUNED)
                else:
                    survivors.append(trial)
            except UpdateFinishedTrialError:
                pass  # failed meanwhile by a machine that missed our heartbeats: it stays so
        active = survivors
        start = step
        if not active:
            return
    for trial in active:
        score = float(np.concatenate(kept[trial.number]["score"], axis=-1).mean())
        told(study, trial.number, score)
