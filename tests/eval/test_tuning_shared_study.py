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
from pathlib import Path

import numpy as np
import optuna
import pytest
from optuna.trial import TrialState

import eval.tuning.cli
import eval.tuning.driver as driver
from eval.cli_base import UsageError
from eval.tuning import SearchConfig, open_study, run_search
from eval.tuning.cli import main
from eval.tuning.folders import open_search
from policies import ParamRange

SPACE = {"x": ParamRange(0.0, 1.0)}


def _toy(params: list[dict[str, float]], seeds: list[int]) -> list[dict[str, np.ndarray]]:
    return [{"score": np.full((1, len(seeds)), -((p["x"] - 0.5) ** 2))} for p in params]


def _left_running(study: optuna.Study, owner: str, beat_age_s: float | None) -> int:
    """A trial another machine asked and never finished; its last heartbeat ``beat_age_s`` ago
    (None: it records none, as a version before heartbeats)."""
    trial = study.ask(driver.distributions(SPACE))
    trial.set_user_attr("owner", owner)
    if beat_age_s is not None:
        trial.set_user_attr("heartbeat", time.time() - beat_age_s)
    return trial.number


def _state(study: optuna.Study, number: int) -> TrialState:
    return study.trials[number].state


@pytest.mark.parametrize("age_s", [driver.STALE_AFTER_S + 1.0, 10 * driver.STALE_AFTER_S])
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
    busy = _left_running(study, "busy-host:4242", driver.STALE_AFTER_S - 60.0)
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
    monkeypatch.setattr(driver, "HEARTBEAT_S", 0.02)
    journal = tmp_path / "study.journal"
    config = SearchConfig(trials=2, seeds=(0,), batch=2)
    study = open_study(journal, "toy", config)
    beats: list[set[float]] = []

    def slow(params: list[dict[str, float]], seeds: list[int]) -> list[dict[str, np.ndarray]]:
        seen: set[float] = set()
        for _ in range(10):  # as another machine sees the study while the batch runs
            other = optuna.load_study(
                study_name="toy",
                storage=optuna.storages.JournalStorage(
                    optuna.storages.journal.JournalFileBackend(str(journal))
                ),
            )
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
    cli = ["pn", "--scenarios", "straight", "--seeds", "2", "--holdout-seeds", "2"]
    assert main([*cli, "--trials", "1", "--out", str(out)]) == 0
    study = optuna.load_study(
        study_name="pn-person_follow",
        storage=optuna.storages.JournalStorage(
            optuna.storages.journal.JournalFileBackend(str(out / "study.journal"))
        ),
    )
    lost = _left_running(study, "crashed-host:4242", driver.STALE_AFTER_S + 5.0)
    capsys.readouterr()
    assert main([*cli, "--trials", "2", "--out", str(out)]) == 0
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
    assert study.user_attrs["code"] == "a" * 64
    assert open_search(out, storage, "toy", config, {"n": 1}, "a" * 64).user_attrs == {
        "search": {"n": 1},
        "code": "a" * 64,
    }
    before = Path(storage).read_bytes()
    with pytest.raises(UsageError) as refused:
        open_search(out, storage, "toy", config, {"n": 1}, "b" * 64)
    assert str(refused.value) == (
        f"--study toy: the study in {storage} was scored by other code (sources aaaaaaaaaaaa, "
        "this code's bbbbbbbbbbbb): its trials' scores would not compare with new ones; give "
        "another --study or --storage"
    )
    assert Path(storage).read_bytes() == before


def test_a_study_that_records_no_code_takes_the_resuming_one(tmp_path: Path) -> None:
    out, config = tmp_path / "out", SearchConfig(1, (0,))
    storage = str(out / "study.journal")
    open_search(out, storage, "toy", config, {"n": 1})  # as a version before the record
    assert "code" not in open_study(storage, "toy", config).user_attrs
    assert open_search(out, storage, "toy", config, {"n": 1}, "c" * 64).user_attrs["code"] == (
        "c" * 64
    )


@pytest.mark.slow
def test_follow_tune_refuses_to_resume_after_the_code_changed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "out"
    cli = ["pn", "--scenarios", "straight", "--seeds", "2", "--holdout-seeds", "2"]
    assert main([*cli, "--trials", "1", "--out", str(out)]) == 0
    code = json.loads((out / "result.json").read_text())["code"]
    assert code == eval.tuning.cli.running_sources_sha256()
    journal = (out / "study.journal").read_bytes()
    capsys.readouterr()
    monkeypatch.setattr(eval.tuning.cli, "running_sources_sha256", lambda: "d" * 64)
    assert main([*cli, "--trials", "2", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("follow-tune: error: --study pn-person_follow: ")
    assert f"was scored by other code (sources {code[:12]}, this code's dddddddddddd)" in err
    assert len(err.strip().splitlines()) == 1
    assert (out / "study.journal").read_bytes() == journal
