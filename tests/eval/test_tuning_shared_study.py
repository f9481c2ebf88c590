"""follow-tune's studies shared across machines and over time.

Heartbeats: several machines may share one study (an RDB URL or a journal on a shared disk). A
machine that crashes leaves its trials running, and running trials count towards the budget
(so that the machines do not overshoot it together): without a sign of life they counted for
ever, and the study ended short of its finished trials with nothing said.

Code: a study resumed by other code (an edited reward, law or simulation) would rank the new
trials against scores the old code gave, as silently.
"""

from __future__ import annotations

import json
import time
import warnings
from pathlib import Path

import numpy as np
import optuna
import pytest
from optuna.trial import TrialState

import eval.tuning.cli
import eval.tuning.driver as driver
import eval.tuning.liveness as liveness
from eval.cli_base import UsageError
from eval.tuning import SearchConfig, open_study, run_search
from eval.tuning.cli import main
from eval.tuning.folders import open_search
from policies import ParamRange

SPACE = {"x": ParamRange(0.0, 1.0)}


def _toy(params: list[dict[str, float]], seeds: list[int]) -> list[dict[str, np.ndarray]]:
    return [{"score": np.full((1, len(seeds)), -((p["x"] - 0.5) ** 2))} for p in params]


def _left_running(
    study: optuna.Study, owner: str, beat_age_s: float | None, **attrs: object
) -> int:
    """A trial another machine asked and never finished; its last heartbeat ``beat_age_s`` ago
    (None: it records none, as a version before heartbeats); ``attrs`` its further user
    attributes."""
    trial = study.ask(driver.distributions(SPACE))
    trial.set_user_attr("owner", owner)
    for key, value in attrs.items():
        trial.set_user_attr(key, value)
    if beat_age_s is not None:
        trial.set_user_attr("heartbeat", time.time() - beat_age_s)
    return trial.number


def _journal_study(path: Path, name: str) -> optuna.Study:
    """The study ``name`` of the journal ``path``, opened as another process would."""
    storage = optuna.storages.JournalStorage(optuna.storages.journal.JournalFileBackend(str(path)))
    return optuna.load_study(study_name=name, storage=storage)


#: A small follow-tune search (its --trials and --out given by each test).
_CLI = ["pn", "--scenarios", "straight", "--seeds", "2", "--holdout-seeds", "2"]


def _state(study: optuna.Study, number: int) -> TrialState:
    return study.trials[number].state


@pytest.mark.parametrize("age_s", [liveness.STALE_AFTER_S + 1.0, 10 * liveness.STALE_AFTER_S])
def test_a_trial_without_a_heartbeat_for_ten_minutes_is_failed_and_the_budget_is_met(
    tmp_path: Path, age_s: float
) -> None:
    config = SearchConfig(trials=3, seeds=(0, 1), batch=1)
    study = open_study(tmp_path / "study.journal", "toy", config)
    lost = _left_running(study, "crashed-host:4242", age_s)
    told: list[list[int]] = []
    ran = run_search(
        study, SPACE, config, _toy, on_stale=lambda ts: told.append([t.number for t in ts])
    )
    assert _state(study, lost) == TrialState.FAIL
    assert told == [[lost]]
    assert ran == 3
    assert len(study.get_trials(states=driver.FINISHED)) == 3


def test_a_trial_another_machine_is_still_beating_for_keeps_running_and_counts(
    tmp_path: Path,
) -> None:
    config = SearchConfig(trials=3, seeds=(0, 1), batch=1)
    study = open_study(tmp_path / "study.journal", "toy", config)
    busy = _left_running(study, "busy-host:4242", liveness.STALE_AFTER_S - 60.0)
    told: list[object] = []
    assert run_search(study, SPACE, config, _toy, on_stale=told.append) == 2
    assert _state(study, busy) == TrialState.RUNNING
    assert told == []


def test_a_trial_that_records_no_heartbeat_is_judged_by_its_owner_alone(tmp_path: Path) -> None:
    config = SearchConfig(trials=2, seeds=(0, 1), batch=1)
    study = open_study(tmp_path / "study.journal", "toy", config)
    elsewhere = _left_running(study, "older-version-host:4242", None)
    assert run_search(study, SPACE, config, _toy) == 1
    assert _state(study, elsewhere) == TrialState.RUNNING


def test_a_batch_beats_while_it_is_evaluated(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(liveness, "HEARTBEAT_S", 0.02)
    journal = tmp_path / "study.journal"
    config = SearchConfig(trials=2, seeds=(0,), batch=2)
    study = open_study(journal, "toy", config)
    beats: list[set[float]] = []

    def slow(params: list[dict[str, float]], seeds: list[int]) -> list[dict[str, np.ndarray]]:
        seen: set[float] = set()
        for _ in range(10):  # as another machine sees the study while the batch runs
            other = _journal_study(journal, "toy")
            running = other.get_trials(states=(TrialState.RUNNING,))
            assert len(running) == 2
            seen |= {t.user_attrs["heartbeat"] for t in running}
            time.sleep(0.05)
        beats.append(seen)
        return _toy(params, seeds)

    assert run_search(study, SPACE, config, slow) == 2
    # Both trials carry each beat's time: the one on asking, then at least two more.
    assert len(beats[0]) >= 3
    assert max(beats[0]) <= time.time()
    assert not study.get_trials(states=(TrialState.RUNNING,))


def test_a_trial_failed_meanwhile_by_another_machine_stays_failed_and_the_rest_finish(
    tmp_path: Path,
) -> None:
    config = SearchConfig(trials=2, seeds=(0, 1, 2, 3), batch=2, startup_trials=10)
    study = open_study(tmp_path / "study.journal", "toy", config)
    batches: list[int] = []

    def judged_lost(
        params: list[dict[str, float]], seeds: list[int]
    ) -> list[dict[str, np.ndarray]]:
        if not batches:  # as fail_stale on another machine, once, during the first rung
            first = min(t.number for t in study.get_trials(states=(TrialState.RUNNING,)))
            study.tell(first, state=TrialState.FAIL)
        batches.append(len(params))
        return _toy(params, seeds)

    # The failed trial does not count: a third one is run to meet the budget.
    assert run_search(study, SPACE, config, judged_lost) == 3
    states = [t.state for t in study.trials]
    assert states == [TrialState.FAIL, TrialState.COMPLETE, TrialState.COMPLETE]
    assert batches == [2, 1, 1, 1, 1, 1]  # the second trial's later rungs, then the third's


@pytest.mark.slow
def test_follow_tune_says_which_trial_it_failed_and_runs_the_budget(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    assert main([*_CLI, "--trials", "1", "--out", str(out)]) == 0
    study = _journal_study(out / "study.journal", "pn-person_follow")
    lost = _left_running(study, "crashed-host:4242", liveness.STALE_AFTER_S + 5.0)
    capsys.readouterr()
    assert main([*_CLI, "--trials", "2", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert (
        f"follow-tune: trial {lost} left running by crashed-host:4242 marked failed: its "
        "process is gone (on this machine) or sent no heartbeat for 10 min"
    ) in err
    result = json.loads((out / "result.json").read_text())
    assert result["trials"] == {"complete": 2, "fail": 1}  # no pruning before 5 finished
    assert result["ran_now"] == 1


def test_a_study_scored_by_other_code_is_not_resumed(tmp_path: Path) -> None:
    out, config = tmp_path / "out", SearchConfig(1, (0,))
    storage = str(out / "study.journal")
    study = open_search(out, storage, "toy", config, {"n": 1}, "a" * 64)
    assert study.user_attrs["scoring_code"] == "a" * 64
    assert open_search(out, storage, "toy", config, {"n": 1}, "a" * 64).user_attrs == {
        "search": {"n": 1},
        "scoring_code": "a" * 64,
    }
    before = Path(storage).read_bytes()
    with pytest.raises(UsageError) as refused:
        open_search(out, storage, "toy", config, {"n": 1}, "b" * 64)
    assert str(refused.value) == (
        f"--study toy: the study in {storage} was scored by other code (sources aaaaaaaaaaaa, "
        "this code's bbbbbbbbbbbb): new trials' scores would not compare with its own; give "
        "another --study or --storage"
    )
    assert Path(storage).read_bytes() == before


def test_a_complete_study_scored_by_other_code_still_opens_for_its_held_out_check(
    tmp_path: Path,
) -> None:
    out, config = tmp_path / "out", SearchConfig(1, (0,))
    storage = str(out / "study.journal")
    study = open_search(out, storage, "toy", config, {"n": 1}, "a" * 64)
    run_search(study, SPACE, config, _toy)
    # Nothing is scored again, so the code that would score it does not matter; the study
    # keeps the digest of the code that scored its trials.
    again = open_search(out, storage, "toy", config, {"n": 1}, "b" * 64)
    assert again.user_attrs["scoring_code"] == "a" * 64
    with pytest.raises(UsageError, match="was scored by other code"):
        open_search(out, storage, "toy", SearchConfig(2, (0,)), {"n": 1}, "b" * 64)


def test_a_study_that_records_no_code_takes_the_resuming_one(tmp_path: Path) -> None:
    out, config = tmp_path / "out", SearchConfig(1, (0,))
    storage = str(out / "study.journal")
    open_search(out, storage, "toy", config, {"n": 1})  # as a version before the record
    study = open_study(storage, "toy", config)
    assert "scoring_code" not in study.user_attrs
    # the versions of 2026-12-06 kept the digest of the sources, comments and all, as "code"
    study.set_user_attr("code", "a" * 64)
    reopened = open_search(out, storage, "toy", config, {"n": 1}, "c" * 64)
    assert reopened.user_attrs["scoring_code"] == "c" * 64


def _legacy_study(out: Path, trials: int, sources: str) -> tuple[str, SearchConfig]:
    """A study as the versions of 2026-12-06 left it: the sources' digest kept as "code"."""
    config = SearchConfig(trials, (0,))
    storage = str(out / "study.journal")
    study = open_search(out, storage, "toy", config, {"n": 1})
    study.set_user_attr("code", sources)
    return storage, config


def test_an_earlier_versions_study_resumes_on_the_same_sources_only(tmp_path: Path) -> None:
    storage, config = _legacy_study(tmp_path / "same", 2, "s" * 64)
    opened = open_search(tmp_path / "same", storage, "toy", config, {"n": 1}, "c" * 64, "s" * 64)
    assert opened.user_attrs["scoring_code"] == "c" * 64  # the same sources: from now on its code
    storage, config = _legacy_study(tmp_path / "other", 2, "s" * 64)
    with pytest.raises(UsageError, match=r"scored by other code \(sources ssssssssssss, this"):
        open_search(tmp_path / "other", storage, "toy", config, {"n": 1}, "c" * 64, "t" * 64)


def test_an_earlier_versions_complete_study_keeps_no_code_it_was_not_scored_by(
    tmp_path: Path,
) -> None:
    out = tmp_path / "out"
    storage, config = _legacy_study(out, 1, "s" * 64)
    run_search(open_study(storage, "toy", config), SPACE, config, _toy)
    # complete: it opens for its held-out check, and is not given this code
    opened = open_search(out, storage, "toy", config, {"n": 1}, "c" * 64, "t" * 64)
    assert "scoring_code" not in opened.user_attrs
    with pytest.raises(UsageError, match="scored by other code"):  # more trials: refused
        open_search(out, storage, "toy", SearchConfig(2, (0,)), {"n": 1}, "c" * 64, "t" * 64)


@pytest.mark.slow
def test_follow_tune_refuses_to_resume_after_the_code_changed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "out"
    assert main([*_CLI, "--trials", "1", "--out", str(out)]) == 0
    assert json.loads((out / "result.json").read_text())["code"] == (
        eval.tuning.cli.running_sources_sha256()  # the sources this run ran, for provenance
    )
    code = eval.tuning.cli.running_code_sha256()  # what the study keeps: the code, not comments
    journal = (out / "study.journal").read_bytes()
    capsys.readouterr()
    monkeypatch.setattr(eval.tuning.cli, "running_code_sha256", lambda: "d" * 64)
    assert main([*_CLI, "--trials", "2", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("follow-tune: error: --study pn-person_follow: ")
    assert f"was scored by other code (sources {code[:12]}, this code's dddddddddddd)" in err
    assert len(err.strip().splitlines()) == 1
    assert (out / "study.journal").read_bytes() == journal


def test_a_machine_lost_while_this_one_runs_is_found_before_the_next_batch(tmp_path: Path) -> None:
    config = SearchConfig(trials=3, seeds=(0,), batch=1)
    study = open_study(tmp_path / "study.journal", "toy", config)
    lost: list[int] = []

    def meanwhile(params: list[dict[str, float]], seeds: list[int]) -> list[dict[str, np.ndarray]]:
        if not lost:  # another machine asked a trial, then crashed long ago
            lost.append(_left_running(study, "crashed-host:4242", liveness.STALE_AFTER_S + 1.0))
        return _toy(params, seeds)

    told: list[list[int]] = []
    ran = run_search(
        study, SPACE, config, meanwhile, on_stale=lambda ts: told.append([t.number for t in ts])
    )
    assert told == [lost]
    assert ran == 3  # its trial no longer counts: the budget is met by this machine's
    assert _state(study, lost[0]) == TrialState.FAIL


def test_a_trial_pruned_or_told_as_another_machine_fails_it_does_not_end_the_batch(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The race a final tell loses: another machine's FAIL lands between Optuna's check that
    # the trial still runs and its write (UpdateFinishedTrialError).
    config = SearchConfig(trials=3, seeds=(0, 1), batch=3, startup_trials=0)
    study = open_study(tmp_path / "study.journal", "toy", config)
    real_tell = optuna.Study.tell

    def racing_tell(self: optuna.Study, trial: object, *args: object, **kwargs: object) -> object:
        number = trial if isinstance(trial, int) else trial.number  # type: ignore[attr-defined]
        if number == 1 and kwargs.get("state") is None:
            real_tell(self, number, state=TrialState.FAIL)  # the other machine's write first
            raise optuna.exceptions.UpdateFinishedTrialError("finished meanwhile")
        return real_tell(self, trial, *args, **kwargs)

    monkeypatch.setattr(optuna.Study, "tell", racing_tell)
    assert run_search(study, SPACE, config, _toy) == 4  # a fourth trial to meet the budget
    states = [t.state for t in study.trials]
    complete, fail = TrialState.COMPLETE, TrialState.FAIL
    assert states == [complete, fail, complete, complete]


def test_a_trial_failed_just_before_its_prune_stays_failed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    config = SearchConfig(trials=2, seeds=(0, 1), batch=2)
    study = open_study(tmp_path / "study.journal", "toy", config)

    def failed_then_pruned(trial: optuna.Trial) -> bool:
        if trial.number == 0:  # another machine fails it; then the pruner says prune
            study.tell(0, state=TrialState.FAIL, skip_if_finished=True)
            return True
        return False

    monkeypatch.setattr(optuna.Trial, "should_prune", failed_then_pruned)
    assert run_search(study, SPACE, config, _toy) == 3
    assert [t.state for t in study.trials] == [TrialState.FAIL] + [TrialState.COMPLETE] * 2


def test_fail_stale_names_only_the_trials_it_failed(tmp_path: Path) -> None:
    config = SearchConfig(trials=2, seeds=(0,))
    study = open_study(tmp_path / "study.journal", "toy", config)
    lost = _left_running(study, "crashed-host:1", liveness.STALE_AFTER_S + 1.0)
    finishing = _left_running(study, "crashed-host:2", liveness.STALE_AFTER_S + 1.0)
    real_tell = optuna.Study.tell

    def owner_first(self: optuna.Study, trial: object, *args: object, **kwargs: object) -> object:
        if trial == finishing:  # its owner was only slow, and told it first
            real_tell(self, finishing, 1.0)
        return real_tell(self, trial, *args, **kwargs)

    with pytest.MonkeyPatch.context() as m:
        m.setattr(optuna.Study, "tell", owner_first)
        failed = liveness.fail_stale(study)
    assert [t.number for t in failed] == [lost]
    assert _state(study, finishing) == TrialState.COMPLETE


def test_trials_asked_before_an_interrupt_are_failed_not_left_running(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    config = SearchConfig(trials=4, seeds=(0,), batch=4)
    study = open_study(tmp_path / "study.journal", "toy", config)
    real_ask = optuna.Study.ask
    asked: list[int] = []

    def ctrl_c_on_the_third(self: optuna.Study, *args: object, **kwargs: object) -> object:
        if len(asked) == 2:
            raise KeyboardInterrupt
        trial = real_ask(self, *args, **kwargs)
        asked.append(trial.number)
        return trial

    monkeypatch.setattr(optuna.Study, "ask", ctrl_c_on_the_third)
    with pytest.raises(KeyboardInterrupt):
        run_search(study, SPACE, config, _toy)
    assert [t.state for t in study.trials] == [TrialState.FAIL, TrialState.FAIL]


def _suggest_that(monkeypatch: pytest.MonkeyPatch, on_call: int, act) -> None:
    """Make Optuna's ``Trial._suggest`` (how a trial's parameters are sampled) call
    ``act(trial)`` first on its ``on_call``-th call (counted from 1)."""
    real = optuna.trial.Trial._suggest
    calls = [0]

    def suggest(self: optuna.trial.Trial, *args: object, **kwargs: object) -> object:
        calls[0] += 1
        if calls[0] == on_call:
            act(self)
        return real(self, *args, **kwargs)

    monkeypatch.setattr(optuna.trial.Trial, "_suggest", suggest)


def _unowned(study: optuna.Study) -> int:
    """A trial as Optuna creates it, before any search has owned it."""
    return study.ask().number


def test_an_interrupt_while_a_trial_is_sampled_leaves_no_trial_running(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A trial is owned before its parameters are sampled (TPE's sampling is the slow part of
    asking), so a Ctrl-C there fails it with the batch's; another machine's running trials,
    owned or about to be, are left alone."""
    config = SearchConfig(trials=5, seeds=(0,), batch=5)
    study = open_study(tmp_path / "study.journal", "toy", config)
    busy = _left_running(study, "busy-host:4242", 30.0)
    asking = _unowned(study)

    def interrupt(trial: optuna.trial.Trial) -> None:
        assert trial.number == 4
        assert "owner" in study.trials[4].user_attrs
        raise KeyboardInterrupt

    _suggest_that(monkeypatch, 3, interrupt)  # sampling the batch's third trial
    with pytest.raises(KeyboardInterrupt):
        run_search(study, SPACE, config, _toy)
    assert [t.state for t in study.trials] == [*[TrialState.RUNNING] * 2, *[TrialState.FAIL] * 3]
    assert (_state(study, busy), _state(study, asking)) == (TrialState.RUNNING,) * 2


def test_a_search_samples_the_values_optunas_ask_with_distributions_gives(tmp_path: Path) -> None:
    """ask(), own, then suggest: the same calls as Optuna's ask(distributions), so a seed gives
    the same trials as before (random start-up trials and TPE's, with the constant liar)."""
    config = SearchConfig(trials=14, seeds=(0,), batch=2)
    searched = open_study(tmp_path / "a.journal", "toy", config)
    run_search(searched, SPACE, config, _toy)
    reference = open_study(tmp_path / "b.journal", "toy", config)
    for _ in range(7):  # batches of two, told after both are asked, as a search does
        pair = [reference.ask(driver.distributions(SPACE)) for _ in range(2)]
        for trial in pair:
            reference.tell(trial, float(_toy([trial.params], [0])[0]["score"].mean()))
    xs = [t.params["x"] for t in searched.trials]
    assert xs == [t.params["x"] for t in reference.trials]
    assert len(set(xs)) == 14


@pytest.mark.parametrize("kind", ["journal", "sqlite"])
def test_a_trial_left_unowned_is_failed_ten_minutes_on_by_any_machine(
    tmp_path: Path, kind: str
) -> None:
    """A search killed between Optuna's creating a trial and owning it leaves a trial that
    names no owner; Optuna's start time for it, in this machine's local time from either kind
    of storage, says when it was left."""
    config = SearchConfig(trials=2, seeds=(0,), batch=1)
    where = tmp_path / "study.journal" if kind == "journal" else f"sqlite:///{tmp_path}/s.db"
    study = open_study(where, "toy", config)
    left = _unowned(study)
    assert liveness.fail_stale(study) == []  # it may be another search's, being owned now
    later = time.time() + liveness.UNOWNED_AFTER_S
    assert liveness.fail_stale(study, now=later - 30.0) == []
    (failed,) = liveness.fail_stale(study, now=later + 30.0)
    assert failed.number == left
    assert _state(study, left) == TrialState.FAIL
    assert "never owned" in liveness.stale_text(failed)
    assert run_search(study, SPACE, config, _toy) == 2  # the budget is met without it


def test_a_trial_swept_as_unowned_before_it_is_owned_is_let_go(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A search that stalls between Optuna's creating a trial and owning it for longer than
    UNOWNED_AFTER_S finds it failed by another machine's sweep (fail_stale, here its tell):
    it asks another and meets its budget."""
    config = SearchConfig(trials=3, seeds=(0,), batch=3)
    study = open_study(tmp_path / "study.journal", "toy", config)
    other = _journal_study(tmp_path / "study.journal", "toy")
    real_own = driver.own
    swept: list[int] = []

    def own(trial: optuna.Trial) -> None:
        if trial.number == 1 and liveness.told(other, 1, state=TrialState.FAIL):
            swept.append(1)
        real_own(trial)

    monkeypatch.setattr(driver, "own", own)
    assert run_search(study, SPACE, config, _toy) == 3
    assert swept == [1]
    assert [t.state for t in study.trials] == [
        TrialState.COMPLETE,
        TrialState.FAIL,
        *[TrialState.COMPLETE] * 2,
    ]


def test_an_interrupt_stays_an_interrupt_when_the_storage_refuses_to_fail_the_batch(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    config = SearchConfig(trials=2, seeds=(0,), batch=2)
    study = open_study(tmp_path / "study.journal", "toy", config)

    def interrupted(params: list[dict[str, float]], seeds: list[int]) -> list[object]:
        raise KeyboardInterrupt

    def refused(*args: object, **kwargs: object) -> bool:
        raise OSError("the database is gone")

    monkeypatch.setattr(driver, "told", refused)
    warned = pytest.warns(RuntimeWarning, match="could not be marked failed.*database is gone")
    with warned, pytest.raises(KeyboardInterrupt):
        run_search(study, SPACE, config, interrupted)


def test_a_storage_that_refuses_heartbeats_is_warned_of_once(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    class Refusing:
        calls = 0

        def set_user_attr(self, key: str, value: object) -> None:
            Refusing.calls += 1
            raise OSError("disk quota exceeded")

    beating = liveness.Heartbeat([Refusing()], interval_s=3600.0)  # type: ignore[list-item]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(6):
            beating.beat()
    assert [str(w.message)[:52] for w in caught] == [
        "3 heartbeats in a row could not be recorded in the s"
    ]
    assert "OSError: disk quota exceeded" in str(caught[0].message)
    assert Refusing.calls == 6


def test_a_database_whose_tables_another_driver_is_making_is_opened_again(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import sqlalchemy.exc

    real, attempts = optuna.storages.RDBStorage, []

    class Racing(real):  # type: ignore[misc, valid-type]
        def __init__(self, url: str, *args: object, **kwargs: object) -> None:
            attempts.append(url)
            if len(attempts) == 1:  # a table made by another driver first
                raise sqlalchemy.exc.OperationalError(
                    "CREATE TABLE studies", {}, Exception("table studies already exists")
                )
            if len(attempts) == 2:  # the schema's version recorded by another driver first
                raise sqlalchemy.exc.IntegrityError("INSERT INTO alembic_version", {}, Exception())
            super().__init__(url, *args, **kwargs)

    monkeypatch.setattr(driver, "_RDB_RETRY_S", 0.0)
    monkeypatch.setattr(optuna.storages, "RDBStorage", Racing)
    url = f"sqlite:///{tmp_path / 'x.db'}"
    assert open_study(url, "toy", SearchConfig(1, (0,))).study_name == "toy"
    assert len(attempts) == 3

    class Unreachable(real):  # type: ignore[misc, valid-type]
        def __init__(self, url: str, *args: object, **kwargs: object) -> None:
            attempts.append(url)
            raise sqlalchemy.exc.OperationalError("connect", {}, Exception("no server"))

    monkeypatch.setattr(optuna.storages, "RDBStorage", Unreachable)
    del attempts[:]
    with pytest.raises(ValueError, match="cannot open the storage"):
        open_study(url, "toy", SearchConfig(1, (0,)))
    assert len(attempts) == 1  # only the race is tried again


_DRIVER = """
import sys, time
import numpy as np
from eval.tuning import SearchConfig, open_study, run_search
from policies import ParamRange

url, budget, seed, pause = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
config = SearchConfig(trials=budget, seeds=(0, 1), batch=2, sampler_seed=seed)
study = open_study(url, "toy", config)
print("opened", flush=True)


def slow(params, seeds):
    time.sleep(pause)
    return [{"score": np.full((1, len(seeds)), -((p["x"] - 0.5) ** 2))} for p in params]


print("ran", run_search(study, {"x": ParamRange(0.0, 1.0)}, config, slow), flush=True)
"""


def _drivers(tmp_path: Path, url: str, *args: tuple[int, int, float]) -> list[object]:
    import subprocess
    import sys

    script = tmp_path / "driver.py"
    script.write_text(_DRIVER)
    return [
        subprocess.Popen(
            [sys.executable, str(script), url, *map(str, a)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for a in args
    ]


@pytest.mark.slow
def test_drivers_started_together_on_a_new_database_share_one_study(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'shared.db'}"
    procs = _drivers(tmp_path, url, (8, 0, 0.05), (8, 1, 0.05), (8, 2, 0.05))
    outs = [p.communicate(timeout=120) for p in procs]  # type: ignore[attr-defined]
    assert [p.returncode for p in procs] == [0, 0, 0], [err for _, err in outs]  # type: ignore[attr-defined]
    study = optuna.load_study(study_name="toy", storage=url)
    finished = study.get_trials(states=driver.FINISHED)
    # Each driver stops once finished and running trials meet the budget; drivers asking at
    # the same moment may overshoot it by a batch each.
    assert 8 <= len(finished) <= 8 + 2 * 2
    assert not study.get_trials(states=(TrialState.RUNNING, TrialState.FAIL))


@pytest.mark.slow
def test_a_driver_killed_mid_batch_leaves_trials_the_next_one_fails_and_replaces(
    tmp_path: Path,
) -> None:
    import signal

    url = f"sqlite:///{tmp_path / 'shared.db'}"
    (killed,) = _drivers(tmp_path, url, (6, 0, 30.0))  # its first batch never ends
    assert killed.stdout.readline() == "opened\n"  # type: ignore[attr-defined]
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        study = optuna.load_study(study_name="toy", storage=url)
        running = study.get_trials(states=(TrialState.RUNNING,))
        if len(running) == 2 and all("heartbeat" in t.user_attrs for t in running):
            break
        time.sleep(0.1)
    killed.send_signal(signal.SIGKILL)  # type: ignore[attr-defined]
    killed.wait(timeout=30)  # type: ignore[attr-defined]
    config = SearchConfig(trials=6, seeds=(0, 1), batch=2, sampler_seed=1)
    study = open_study(url, "toy", config)
    told: list[list[int]] = []
    ran = run_search(
        study, SPACE, config, _toy, on_stale=lambda ts: told.append([t.number for t in ts])
    )
    assert told == [[t.number for t in running]]  # its process is gone: failed at once
    assert ran == 6
    assert len(study.get_trials(states=driver.FINISHED)) == 6


@pytest.mark.parametrize(
    ("space", "beat_age_s", "failed"),
    [
        ("ours", 1.0, True),  # a process of ours that is gone: at once
        (None, 1.0, True),  # recorded no space (a version before it): as before, at once
        ("another-boot/4026531836", 1.0, False),  # same name, another machine: still beating
        ("another-boot/4026531836", liveness.STALE_AFTER_S + 1.0, True),  # ... no longer
    ],
)
def test_a_process_id_is_asked_only_of_the_pid_space_that_owns_it(
    tmp_path: Path, space: str | None, beat_age_s: float, failed: bool
) -> None:
    import socket
    import subprocess
    import sys

    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    config = SearchConfig(trials=1, seeds=(0,))
    study = open_study(tmp_path / "study.journal", "toy", config)
    recorded = {} if space is None else {"pid_space": space}
    if space == "ours":
        recorded["pid_space"] = liveness._pid_space()
    number = _left_running(study, f"{socket.gethostname()}:{gone.pid}", beat_age_s, **recorded)
    assert [t.number for t in liveness.fail_stale(study)] == ([number] if failed else [])
