"""What a work unit carries from the driver to its worker, and what the worker checks.

A resumed ``follow-eval run`` is refused when the code changed since it started (its journal
records the sources' digest); a unit names an agent given by a relative path by its absolute
path (a Ray worker's folder is not the driver's); and a worker whose code is not the driver's
refuses its unit, naming its host, in one line.
"""

from __future__ import annotations

import json
import shutil
import socket
import sys
import timeit
from pathlib import Path

import pytest

from eval import provenance
from eval.cli import main
from eval.journal import journal_folder
from eval.provenance import CodeMismatchError, check_worker_code, running_sources_sha256
from eval.rollout import rollout, run_batch
from eval.scoring import read_episodes
from eval.steplog import StepLogError, read_step_log
from policies.learned.ppo import AGENTS

GRID = ["--policies", "pn", "--scenarios", "straight", "--episodes", "2", "--seed", "5"]
OTHER = "f" * 64  # a digest no code has


def _interrupted_after_every_unit(monkeypatch: pytest.MonkeyPatch, args: list[str]) -> None:
    """Run ``follow-eval ARGS`` and Ctrl-C it after every unit has run and been kept."""

    def interrupted(*_: object, **__: object) -> None:
        raise KeyboardInterrupt

    with monkeypatch.context() as patch:
        patch.setattr("eval.scoring.score", interrupted)
        assert main(args) == 130


def _one_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err
    assert err.startswith("follow-eval: error: "), err
    assert err.count("\n") == 1, err
    return err


def test_a_resume_by_other_code_is_refused_saying_what_to_do(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Once, a run interrupted, its law's gains edited and the run resumed mixed the old
    gains' episodes with the new ones' in one table."""
    out = tmp_path / "run"
    args = ["run", *GRID, "--out", str(out), "--workers", "1", "--no-logs"]
    _interrupted_after_every_unit(monkeypatch, args)
    kept = json.loads((journal_folder(out) / "run.json").read_text())
    assert kept["code"] == provenance.code_revision()["sources_sha256"]
    capsys.readouterr()
    real = provenance.code_revision

    def edited(*a: object, **k: object) -> dict:
        return real(*a, **k) | {"sources_sha256": OTHER}  # the sources, edited meanwhile

    with monkeypatch.context() as patch:
        patch.setattr(provenance, "code_revision", edited)
        assert main(args) == 2
    err = _one_line(capsys)
    assert "the code changed since the run started" in err
    assert f"was {kept['code'][:12]}, is now {OTHER[:12]}" in err
    assert "run it with the code it started with" in err
    assert "give a new --out" in err
    assert not out.exists()
    assert main(args) == 0  # the code it started with: resumed
    assert "resuming: 1 work units already done" in capsys.readouterr().err


def test_a_journal_that_records_no_code_is_refused_saying_why(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A journal kept before the code was recorded cannot show that its units ran this code."""
    out = tmp_path / "run"
    args = ["run", *GRID, "--out", str(out), "--workers", "1", "--no-logs"]
    _interrupted_after_every_unit(monkeypatch, args)
    run_json = journal_folder(out) / "run.json"
    kept = json.loads(run_json.read_text())
    del kept["code"]
    run_json.write_text(json.dumps(kept))
    capsys.readouterr()
    assert main(args) == 2
    err = _one_line(capsys)
    assert "kept by a version that did not record its code" in err
    assert f"delete {journal_folder(out)} and run the command again" in err
    assert not out.exists()


def _agent_in(folder: Path, shipped: str) -> Path:
    """``folder/agents/mine``: a copy of the shipped agent ``shipped``."""
    agent = folder / "agents" / "mine"
    shutil.copytree(AGENTS / shipped, agent)
    return agent


def test_an_agent_given_by_a_relative_path_is_the_drivers_on_every_worker(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A Ray worker resolves a relative path from the folder ``ray start`` ran in: it loaded
    another agent than the driver read (and recorded the digest of)."""
    here, there = tmp_path / "driver", tmp_path / "worker"
    _agent_in(here, "ppo_law")
    _agent_in(there, "ppo")  # the same relative path names another agent there
    rollout_module = sys.modules["eval.rollout"]  # `eval.rollout` is also the function's name
    real = rollout_module.execute

    def in_the_workers_folder(*args: object, **kwargs: object) -> object:
        monkeypatch.chdir(there)
        return real(*args, **kwargs)

    monkeypatch.chdir(here)
    monkeypatch.setattr(rollout_module, "execute", in_the_workers_folder)
    (got,) = rollout(["agents/mine"], ["straight"], [3], workers=1)
    monkeypatch.undo()
    (want,) = run_batch(str(here / "agents" / "mine"), "straight", [3])
    assert got.policy == "agents/mine"  # named as given, in the tables and the logs
    assert set(got.log["policy"]) == {"agents/mine"}
    assert got.log.drop(columns="policy").equals(want.log.drop(columns="policy"))


def test_step_logs_given_by_relative_paths_are_the_drivers_and_named_as_given(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``follow-eval metrics`` reads the logs on its backend: a worker in another folder read
    other files, or none."""
    here, there = tmp_path / "driver", tmp_path / "worker"
    (got,) = rollout(["pn"], ["straight"], [3], workers=1)
    logs = here / "logs"
    logs.mkdir(parents=True)
    got.log.to_csv(logs / "a.csv", index=False)
    (logs / "b.csv").write_text("time_s\n")  # a header and no rows
    (there / "logs").mkdir(parents=True)  # the same relative paths hold nothing there
    scoring = sys.modules["eval.scoring"]
    real = scoring.execute

    def in_the_workers_folder(*args: object, **kwargs: object) -> object:
        monkeypatch.chdir(there)
        return real(*args, **kwargs)

    monkeypatch.chdir(here)
    monkeypatch.setattr(scoring, "execute", in_the_workers_folder)
    (read,) = read_episodes([Path("logs/a.csv")], task="person_follow")
    assert read.log.equals(read_step_log(logs / "a.csv"))
    assert (read.policy, read.seed) == ("pn:tuned", 3)
    monkeypatch.chdir(here)
    with pytest.raises(StepLogError) as bad:
        read_episodes([Path("logs/a.csv"), Path("logs/b.csv")], task="person_follow")
    assert str(bad.value).startswith("logs/b.csv: ")  # named as the user gave it
    assert "no such file" not in str(bad.value)


def test_a_worker_with_other_code_refuses_its_unit_naming_its_host() -> None:
    check_worker_code(None)  # a unit made without the driver's digest: nothing to check
    check_worker_code(running_sources_sha256())
    with pytest.raises(CodeMismatchError) as refused:
        check_worker_code(OTHER)
    message = str(refused.value)
    assert message.startswith(f"this worker ({socket.gethostname()}) runs other code than the")
    assert f"is {running_sources_sha256()[:12]}, the driver's {OTHER[:12]}" in message
    assert "install the same version on every node" in message
    assert isinstance(refused.value, ValueError)  # the commands' one-line errors


def test_the_code_check_costs_a_unit_microseconds() -> None:
    running_sources_sha256()  # read once per process
    digest = running_sources_sha256()
    per_check_s = min(timeit.repeat(lambda: check_worker_code(digest), number=1000, repeat=5))
    assert per_check_s / 1000 < 50e-6


@pytest.mark.parametrize("workers", ["1", "2"])
def test_a_run_whose_workers_run_other_code_stops_in_one_line(
    workers: str,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """The driver's digest is another than its workers': in this process (its own digest is
    read from its own files) and in a pool of spawned processes alike."""
    # the units are made by eval.units, which reads the driver's digest
    monkeypatch.setattr(sys.modules["eval.units"], "running_sources_sha256", lambda: OTHER)
    out = tmp_path / "run"
    assert main(["run", *GRID, "--out", str(out), "--workers", workers]) == 2
    err = _one_line(capsys)
    assert "runs other code than the driver" in err
    assert f"the driver's {OTHER[:12]}" in err
    assert not out.exists()
    assert not journal_folder(out).exists()  # no unit finished: nothing to resume


def test_scoring_units_are_checked_too(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from eval.metrics import METRICS
    from eval.scoring import score

    episodes = rollout(["pn"], ["straight"], [3], workers=1)
    monkeypatch.setattr(sys.modules["eval.scoring"], "running_sources_sha256", lambda: OTHER)
    with pytest.raises(CodeMismatchError, match="runs other code than the driver"):
        score(episodes, metrics=METRICS)
