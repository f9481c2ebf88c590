"""Which files made a learned policy's episodes: the digest of an agent's files
(``eval.provenance.model_sha256``), a resume with other files refused naming the policy, and a
worker reading other files at the agent's path stopping its command, naming host and policy.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import socket
import sys
import timeit
from pathlib import Path

import pytest

from eval import provenance
from eval.cli import main
from eval.journal import CODE, MODELS, UnitJournal, journal_folder
from eval.provenance import ModelMismatchError, check_worker_model, model_sha256
from eval.rollout import rollout
from policies import make_policy
from policies.learned.ppo import AGENTS

OTHER = "f" * 64  # a digest no files have


def _agent(folder: Path, shipped: str = "ppo") -> Path:
    """``folder/agent``: a copy of the shipped agent ``shipped``."""
    agent = folder / "agent"
    shutil.copytree(AGENTS / shipped, agent)
    return agent


def _replace(agent: Path, shipped: str) -> None:
    """Another model at ``agent``'s path, as a re-export or a retraining leaves it."""
    shutil.rmtree(agent)
    shutil.copytree(AGENTS / shipped, agent)


def test_the_digest_covers_the_files_that_decide_the_actions_and_nothing_else(
    tmp_path: Path,
) -> None:
    agent = _agent(tmp_path)
    first = model_sha256(make_policy(str(agent)))
    assert first is not None
    assert re.fullmatch("[0-9a-f]{64}", first)
    assert model_sha256(make_policy("pn")) is None  # a law: its gains are in the sources
    # the model card, the learning curve and an export's manifest do not act
    for name in ("MODEL_CARD.md", "learning_curve.png", "follow-train-export.json"):
        with (agent / name).open("ab") as f:
            f.write(b"\n")
    assert model_sha256(make_policy(str(agent))) == first
    seen = {first}
    for name in ("model.zip", "vecnormalize.pkl", "config.yaml"):  # each one does
        with (agent / name).open("ab") as f:
            f.write(b"\n" if name == "config.yaml" else b"\0")
        digest = model_sha256(make_policy(str(agent)))
        assert digest not in seen, name
        seen.add(digest)


def test_a_file_rewritten_with_its_old_times_is_read_again(tmp_path: Path) -> None:
    """The digest is kept per version of the files, told apart without reading them; a copy
    that keeps the modification time (``cp -p``) over the same inode and size is a version."""
    agent = _agent(tmp_path)
    policy = make_policy(str(agent))
    before = model_sha256(policy)
    config = agent / "config.yaml"
    st = config.stat()
    text = config.read_bytes()
    config.write_bytes(text.replace(b"ppo", b"PPO", 1))  # same size, other bytes
    os.utime(config, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert config.stat().st_mtime_ns == st.st_mtime_ns
    assert model_sha256(policy) != before


def test_an_ensemble_digest_covers_every_member(tmp_path: Path) -> None:
    study = tmp_path / "study"
    shutil.copytree(AGENTS / "ppo_ensemble", study)
    first = model_sha256(make_policy(str(study)))
    assert first is not None
    with (study / "seed-1" / "vecnormalize.pkl").open("ab") as f:
        f.write(b"\0")
    assert model_sha256(make_policy(str(study))) != first


def test_a_worker_reading_other_files_refuses_naming_host_policy_and_path(tmp_path: Path) -> None:
    agent = _agent(tmp_path)
    policy = make_policy(str(agent))
    check_worker_model(None, policy, "agent")  # a unit made without a digest: nothing to check
    mine = model_sha256(policy)
    assert mine is not None
    check_worker_model(mine, policy, "agent")
    with pytest.raises(ModelMismatchError) as refused:
        check_worker_model(OTHER, policy, "agent")
    message = str(refused.value)
    assert message.startswith(
        f"this worker ({socket.gethostname()}) reads other files for the learned policy agent "
    )
    assert f"model, statistics and config in {agent} is {mine[:12]}, the driver's ffff" in message
    assert "give every node the driver's files at that path" in message
    assert isinstance(refused.value, ValueError)  # the commands' one-line errors
    with pytest.raises(ModelMismatchError, match="is none"):  # a law where the driver had files
        check_worker_model(OTHER, make_policy("pn"), "pn:tuned")


def test_the_model_check_costs_a_unit_microseconds(monkeypatch: pytest.MonkeyPatch) -> None:
    """Once read, a version's digest is a few ``stat`` calls away: hashing the files again for
    every unit would cost 0.25 ms (the shipped agent) to 1 ms (the shipped ensemble) each."""
    policy = make_policy("ppo")
    digest = model_sha256(policy)
    hashed = []
    real = provenance._files_sha256
    monkeypatch.setattr(provenance, "_files_sha256", lambda files: hashed.append(1) or real(files))
    per_check_s = min(
        timeit.repeat(lambda: check_worker_model(digest, policy, "ppo"), number=200, repeat=5)
    )
    assert hashed == []  # no file read again
    assert per_check_s / 200 < 200e-6  # measured: 25 us on the 2-core machine


def test_an_agent_replaced_after_the_driver_read_it_is_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Files replaced between the driver's read and a unit (or another model at the same path
    on a worker) made the unit play another model under the run's label, without a word."""
    agent = _agent(tmp_path)
    rollout_module = sys.modules["eval.rollout"]  # `eval.rollout` is also the function's name
    real = rollout_module.execute

    def replaced_first(*args: object, **kwargs: object) -> object:
        _replace(agent, "ppo_law")
        return real(*args, **kwargs)

    monkeypatch.setattr(rollout_module, "execute", replaced_first)
    with pytest.raises(ModelMismatchError, match=f"for the learned policy {agent} than the"):
        rollout([str(agent)], ["straight"], [3], workers=1)


def test_a_run_whose_pool_workers_read_another_model_stops_in_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """As a cluster node holding other weights at the agent's path: the spawned workers read
    the files the driver did not."""
    agent = _agent(tmp_path)
    rollout_module = sys.modules["eval.rollout"]
    real = rollout_module.execute

    def replaced_first(*args: object, **kwargs: object) -> object:
        _replace(agent, "ppo_law")
        return real(*args, **kwargs)

    monkeypatch.setattr(rollout_module, "execute", replaced_first)
    out = tmp_path / "run"
    grid = ["--policies", str(agent), "--scenarios", "straight", "--episodes", "1", "--seed", "5"]
    assert main(["run", *grid, "--out", str(out), "--workers", "2"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert err.startswith(
        f"follow-eval: error: this worker ({socket.gethostname()}) reads other files for the "
        f"learned policy {agent} than the driver: "
    )
    assert f"(in work unit 0 ({agent} on straight, seed 5) on host {socket.gethostname()}" in err
    assert not out.exists()
    assert not journal_folder(out).exists()  # no unit finished: nothing to resume


def test_an_agent_replaced_between_a_runs_two_grids_stops_the_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """With --ideal-baseline a run makes two grids; each read the digest again, so files
    replaced after the first played the second under the label meta.json recorded for the
    first model (exit 0, two models in one table)."""
    agent = _agent(tmp_path)
    rollout_module = sys.modules["eval.rollout"]
    real = rollout_module.rollout
    calls: list[int] = []

    def replaced_after_the_first(*args: object, **kwargs: object) -> object:
        got = real(*args, **kwargs)
        calls.append(1)
        if len(calls) == 1:
            _replace(agent, "ppo_law")
        return got

    monkeypatch.setattr(rollout_module, "rollout", replaced_after_the_first)
    out = tmp_path / "run"
    grid = ["--policies", str(agent), "--scenarios", "straight", "--episodes", "1", "--seed", "3"]
    argv = ["run", *grid, "--ideal-baseline", "--no-logs", "--workers", "1", "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert f"reads other files for the learned policy {agent} than the driver" in err, err
    assert not out.exists()


# -- the journal: a resume with other agent files --------------------------------------------


RUN = {"policies": ["ppo", "pn"], "seeds": [0, 9], CODE: "c0de" * 16, MODELS: {"ppo": "a" * 64}}


def _reopened(tmp_path: Path, kept: dict, now: dict) -> str:
    """The refusal of a journal kept by run ``kept`` reopened by run ``now``."""
    folder = tmp_path / ".run.units"
    UnitJournal(folder, kept)
    with pytest.raises(ValueError, match="holds the finished units of this run") as refused:
        UnitJournal(folder, now, {"ppo": "/agents/ppo"})
    return str(refused.value)


def test_a_resume_with_other_agent_files_names_the_policy_its_files_and_what_to_do(
    tmp_path: Path,
) -> None:
    message = _reopened(tmp_path, RUN, RUN | {MODELS: {"ppo": "b" * 64}})
    folder = tmp_path / ".run.units"
    assert message == (
        f"{folder} holds the finished units of this run, but the files of its learned policy "
        "ppo changed since the run started (the SHA-256 of ppo's model, statistics and config "
        "in /agents/ppo was aaaaaaaaaaaa, is now bbbbbbbbbbbb): resuming would mix two models' "
        "episodes in one run's tables; run it with the agent files it started with to resume, "
        f"or give a new --out (or delete {folder}) to run it anew"
    )


def test_a_resume_after_the_code_and_an_agent_changed_names_both(tmp_path: Path) -> None:
    now = RUN | {CODE: "beef" * 16, MODELS: {"ppo": "b" * 64}}
    message = _reopened(tmp_path, RUN, now)
    assert "but the code and the files of its learned policy ppo changed since" in message
    assert "sources was c0dec0dec0de, is now beefbeefbeef; the SHA-256 of ppo's" in message
    assert "run it with the code and the agent files it started with" in message


def test_a_journal_kept_before_agents_were_recorded_is_refused_saying_why(tmp_path: Path) -> None:
    kept = {k: v for k, v in RUN.items() if k != MODELS}
    message = _reopened(tmp_path, kept, RUN)
    assert "kept by a version that did not record its learned policies' files" in message
    assert f"delete {tmp_path / '.run.units'} and run the command again" in message


def test_the_agents_path_is_not_part_of_the_run(tmp_path: Path) -> None:
    """The same files read from another folder (a relative path, another working directory)
    are the same run: the paths only name the files in a refusal."""
    folder = tmp_path / ".run.units"
    UnitJournal(folder, RUN, {"ppo": "/here/ppo"})
    UnitJournal(folder, RUN, {"ppo": "/there/ppo"})  # not refused
    assert json.loads((folder / "run.json").read_text()) == RUN
