"""bench/training.py: PPO training speed of follow-train's file beside CartPole-v1's."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bench.training import (
    CHOICES,
    SHIPPED_HYPERPARAMS,
    _cartpole_rate,
    _command_rate,
    _follow_train_rate,
)


@pytest.mark.slow
def test_each_choice_trains_its_file_and_reports_its_rate(tmp_path: Path) -> None:
    # the first choice (ppo.yaml) and the last (the shipped file as it is, on 384 lanes)
    for _, hyperparams, changes, threads in (CHOICES[0], CHOICES[-1]):
        assert _follow_train_rate(hyperparams, changes, threads, 2_000, tmp_path) > 0.0
    assert len(list(tmp_path.glob("run-*/model.zip"))) == 2
    assert CHOICES[-1][1] == SHIPPED_HYPERPARAMS
    assert CHOICES[-1][2] == {}
    assert _cartpole_rate({"n_envs": 4, "batch_size": 64}, 1_000) > 0.0
    # the command rows: a run of its own, here with the option
    commands = tmp_path / "commands"
    commands.mkdir()
    # (ppo.yaml's 48 lanes: the wide file's 384 would take a 24,576-step rollout here)
    assert _command_rate(CHOICES[0][1], 800, commands, "--mkl-intel-paths") > 0.0
    sessions = json.loads((commands / "command-0" / "sessions.json").read_text(encoding="utf-8"))
    assert sessions[-1]["mkl_intel_paths"] is True


def test_the_shipped_file_is_compared_with_itself_on_two_threads(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # rates stand in for training (the test above trains); the rows' ratios are what is checked
    import bench.training as training

    rates = {(label, threads): 1000.0 * (k + 1) for k, (label, _, _, threads) in enumerate(CHOICES)}
    by_threads = {}

    def rate(hyperparams: Path, changes: dict, threads: int, steps: int, folder: Path) -> float:
        label = next(c[0] for c in CHOICES if c[1:] == (hyperparams, changes, threads))
        by_threads[label] = threads
        return rates[(label, threads)]

    monkeypatch.setattr(training, "_follow_train_rate", rate)
    monkeypatch.setattr(training, "_cartpole_rate", lambda changes, steps: 500.0)
    commands = {(): 300.0, ("--mkl-intel-paths",): 450.0}

    def command_rate(hyperparams: Path, steps: int, folder: Path, *options: str) -> float:
        assert hyperparams == training.WIDE_HYPERPARAMS
        return commands[options]

    monkeypatch.setattr(training, "_command_rate", command_rate)
    listed = training.bench_training(quick=True)
    rows = {label: (value, ratio) for label, value, ratio in listed}
    # the last two rows: the wide file without the option, then with it as a ratio
    assert listed[-2:] == [
        ("ppo_ahead_law_wide.yaml, 1 thr", 300.0, "(baseline of the next row)"),
        ("  the same, --mkl-intel-paths", 450.0, "1.50x its rate"),
    ]
    two, one = "ppo_fast.yaml as shipped, 2 thr", "ppo_fast.yaml as shipped, 1 thr"
    assert by_threads[two] == 2
    assert by_threads[one] == 1
    assert rows[one][1] == f"{rates[(one, 1)] / rates[(two, 2)]:.2f}x the 2-thread row's rate"
    assert rows[two][1] == "(2 threads)"
    # the file's rows get no CartPole row of their own; every other 1-thread choice does
    cartpole = sum(label.strip().startswith("CartPole") for label, _, _ in listed)
    others = [c for c in CHOICES if c[1] != SHIPPED_HYPERPARAMS and c[3] == 1]
    assert cartpole == len(others) == 3
    first = CHOICES[0][0]
    assert rows[first][1] == f"{500.0 / rates[(first, 1)]:.2f}x CartPole's time"
