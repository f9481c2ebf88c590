"""eval/aggregate.py: ``follow-eval aggregate``, learners over seeds against the laws."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from eval.aggregate import _resample, learner_runs, normalised_scores, stratified_ci
from eval.cli import main

AGENT = Path(__file__).parents[2] / "policies" / "agents" / "ppo"


def test_the_bootstrap_resamples_runs_within_each_task() -> None:
    matrix = np.array([[0.0, 10.0], [1.0, 11.0], [2.0, 12.0]])
    sample = _resample(matrix, np.random.default_rng(0))
    assert set(sample[:, 0]) <= {0.0, 1.0, 2.0}
    assert set(sample[:, 1]) <= {10.0, 11.0, 12.0}


def test_a_ci_holds_its_estimate_and_is_reproducible() -> None:
    matrix = np.random.default_rng(1).random((30, 3))
    got = stratified_ci(np.mean, [matrix], reps=300, seed=4)
    assert got[1] <= got[0] <= got[2]
    assert got == stratified_ci(np.mean, [matrix], reps=300, seed=4)


def test_scores_are_normalised_per_scenario_by_the_episodes_seen() -> None:
    raw = pd.DataFrame(
        {
            "controller": ["a", "b", "a", "b"],
            "run": [0, 0, 0, 0],
            "scenario": ["s", "s", "t", "t"],
            "seed": [0, 0, 0, 0],
            "score": [10.0, 30.0, -5.0, -1.0],
        }
    )
    assert normalised_scores(raw)["normalised"].tolist() == [0.0, 1.0, 0.0, 1.0]


def test_a_folder_without_an_agent_is_refused_by_name(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="holds no trained agent"):
        learner_runs(tmp_path)


@pytest.mark.slow
def test_a_study_against_a_law_writes_the_tables_and_plots(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    study = tmp_path / "study"
    for k in (0, 1):  # two "seeds" (the shipped agent twice): the machinery, not the numbers
        shutil.copytree(AGENT, study / f"seed-{k}")
    out = tmp_path / "agg"
    grid = ["--laws", "pn", "--scenarios", "straight,curve", "--episodes", "2", "--reps", "200"]
    assert main(["aggregate", str(study), *grid, "--out", str(out)]) == 0
    agg = pd.read_csv(out / "aggregate.csv")
    assert set(agg["controller"]) == {"study", "pn"}
    assert set(agg["metric"]) == {"iqm", "mean", "median", "optimality_gap"}
    assert (
        (agg["ci_low"] <= agg["estimate"] + 1e-12) & (agg["estimate"] <= agg["ci_high"] + 1e-12)
    ).all()
    imp = pd.read_csv(out / "improvement.csv")
    assert imp[["learner", "law"]].to_numpy().tolist() == [["study", "pn"]]
    assert 0.0 <= imp["probability"].iloc[0] <= 1.0
    scores = pd.read_csv(out / "scores.csv")
    assert len(scores) == (2 + 1) * 2 * 2  # (2 seeds + 1 law) x 2 scenarios x 2 episodes
    assert scores["normalised"].between(0.0, 1.0).all()
    assert {p.name for p in (out / "plots").iterdir()} == {
        "aggregates.png",
        "performance_profiles.png",
    }
    assert "Probability of improvement" in capsys.readouterr().out


def test_bad_arguments_give_one_line(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["aggregate", str(AGENT), "--laws", "pnn", "--out", str(tmp_path / "x")]) == 2
    assert "unknown policy 'pnn'" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
    assert main(["aggregate", str(tmp_path), "--out", str(tmp_path / "y")]) == 2
    assert "holds no trained agent" in capsys.readouterr().err
