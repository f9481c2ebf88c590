"""bench/training.py: PPO training speed of follow-train's file beside CartPole-v1's."""

from __future__ import annotations

from pathlib import Path

import pytest

from bench.training import CHOICES, SHIPPED_HYPERPARAMS, _cartpole_rate, _follow_train_rate


@pytest.mark.slow
def test_each_choice_trains_its_file_and_reports_its_rate(tmp_path: Path) -> None:
    # the first choice (ppo.yaml) and the last (the shipped file as it is, on 384 lanes)
    for _, hyperparams, changes, threads in (CHOICES[0], CHOICES[-1]):
        assert _follow_train_rate(hyperparams, changes, threads, 2_000, tmp_path) > 0.0
    assert len(list(tmp_path.glob("run-*/model.zip"))) == 2
    assert CHOICES[-1][1] == SHIPPED_HYPERPARAMS
    assert CHOICES[-1][2] == {}
    assert _cartpole_rate({"n_envs": 4, "batch_size": 64}, 1_000) > 0.0
