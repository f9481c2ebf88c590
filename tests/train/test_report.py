"""train/report.py: the model card says plainly when the agent fails more often than the law."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from policies.learned.ppo import AGENTS, shipped_name
from policies.registry import available_policies
from train.ppo import Args
from train.report import CARD_METRICS, compare_with_law, model_card, outcome_summary


class Reverse:
    """A broken agent: full speed backwards into the wall behind it, every episode."""

    name = "reverse"

    def reset(self) -> None:
        pass

    def act(self, obs: np.ndarray) -> np.ndarray:
        return np.array([-1.0, 0.0], dtype=np.float32)


@pytest.fixture(scope="module")
def broken_comparison() -> pd.DataFrame:
    return compare_with_law(Reverse(), "gsmpn:tuned", ["straight"], range(2), "thesis")


def card(
    tmp_path: Path,
    comparison: pd.DataFrame | None,
    sessions: list[dict],
    wrappers: list | None = None,
    **args: object,
) -> str:
    return model_card(
        run=tmp_path,
        args=Args(scenarios=("straight",), **args),
        hp={"n_envs": 4, "n_timesteps": 2000, "vec_env_wrapper": wrappers or []},
        sessions=sessions,
        comparison=comparison,
        seeds=range(2),
        versions={"python": "3"},
    )


SESSION = {
    "command": "follow-train",
    "first_step": 0,
    "last_step": 2000,
    "wall_s": 60.0,
    "env_steps_per_s": 33,
    "threads": 1,
    "finished_utc": "2026-01-01T00:00:00+00:00",
}


def test_the_comparison_has_collisions_losses_and_distance_error(
    broken_comparison: pd.DataFrame,
) -> None:
    assert list(dict.fromkeys(broken_comparison["metric"])) == list(CARD_METRICS)
    collisions = broken_comparison.set_index("metric").loc["collision_rate_pct"]
    assert (collisions["mean_a"], collisions["mean_b"]) == (100.0, 0.0)


def test_a_card_warns_first_when_the_agent_collides_more_often(
    broken_comparison: pd.DataFrame, tmp_path: Path
) -> None:
    text = card(tmp_path, broken_comparison, [SESSION])
    comparison = text.split("Against `gsmpn:tuned`")[1]
    first = [line for line in comparison.splitlines() if line][1]  # right below the heading
    assert first.startswith(
        "**Warning: the agent collides more often than `gsmpn:tuned` in 1 of 1 scenarios "
        "(straight 100 % against 0 %).**"
    )
    assert "| straight | collision (%) | 100.0 | 0.0 | +100.0" in comparison
    assert "| straight | RMS distance error (m) |" in comparison


def test_the_sentence_names_both_failures_when_both_are_worse() -> None:
    rows = [
        ("straight", "collision_rate_pct", 50.0, 0.0),
        ("straight", "lost_rate_pct", 20.0, 10.0),
        ("curve", "collision_rate_pct", 0.0, 0.0),
        ("curve", "lost_rate_pct", 0.0, 0.0),
    ]
    comparison = pd.DataFrame(
        [
            {"scenario": s, "policy_a": "ppo", "policy_b": "law", "metric": m, "n": 10}
            | {"mean_a": a, "mean_b": b}
            for s, m, a, b in rows
        ]
    )
    assert outcome_summary(comparison) == (
        "**Warning: the agent collides more often than `law` in 1 of 2 scenarios (straight "
        "50 % against 0 %), and loses the person more often in 1 of 2 scenarios (straight 20 % "
        "against 10 %).** Over all scenarios: collisions in 25.0 % of episodes against 0.0 %; "
        "lost person in 10.0 % of episodes against 5.0 %. Better centring or smoothness below "
        "does not make up for that."
    )


def test_the_sentence_says_so_when_the_agent_fails_no_more_often() -> None:
    comparison = pd.DataFrame(
        [
            {"scenario": "straight", "policy_a": "ppo", "policy_b": "law", "metric": m, "n": 4}
            | {"mean_a": 0.0, "mean_b": b}
            for m, b in (("collision_rate_pct", 0.0), ("lost_rate_pct", 25.0))
        ]
    )
    assert outcome_summary(comparison).startswith(
        "The agent collides and loses the person no more often than `law` in any scenario"
    )


def test_killed_and_interrupted_sessions_are_listed_and_counted(tmp_path: Path) -> None:
    killed = SESSION | {"last_step": 800, "wall_s": 30.0, "status": "killed"}
    interrupted = SESSION | {"first_step": 800, "last_step": 1600, "status": "interrupted"}
    finished = SESSION | {"first_step": 1600, "status": "finished"}
    text = card(tmp_path, None, [killed, interrupted, finished])
    assert "(0 -> 800 steps, 30 s, 33 env-steps/s, 1 torch thread(s), killed;" in text
    assert "interrupted 2026-01-01T00:00:00+00:00; steps after its last checkpoint" in text
    assert "total: 2,000 env steps in 2.5 min of training" in text  # 30 + 60 + 60 s


def test_a_card_names_the_steps_the_agent_was_not_trained_with(tmp_path: Path) -> None:
    gate = "train.wrappers.VecJumpGate"
    text = card(tmp_path, None, [SESSION], [{gate: {"max_jump_m": 0.5, "in_training": False}}])
    assert "Not trained with: `VecJumpGate` (`in_training: false`)" in text
    assert "held-out return below is the agent's without it" in text
    for wrappers in ([{gate: {"max_jump_m": 0.5}}], [{gate: {"in_training": True}}], None):
        assert "Not trained with" not in card(tmp_path, None, [SESSION], wrappers)


def test_a_card_says_how_to_load_the_run_and_the_copy_an_export_wrote(tmp_path: Path) -> None:
    run = f"`make_policy({str(tmp_path)!r})`"
    assert f"Load it with\n{run}; the" in card(tmp_path, None, [SESSION])
    # a shipped agent's folder is loaded by the name the registry gives it
    for folder, call in (
        ("ppo_ahead", 'make_policy("ppo_ahead")'),
        ("ppo_mecanum", 'make_policy("ppo_mecanum")'),
        ("ppo", 'make_policy("ppo")'),
        ("ppo_line", 'make_policy("ppo", task="line_trace")'),
    ):
        export = AGENTS / folder
        text = card(tmp_path, None, [SESSION], export=export)
        copy = f"policies/agents/{folder}"  # the card travels with the project: no local paths
        assert (
            f"`{call}` (the copy in `{copy}`, exported from the run folder `{tmp_path.name}`)"
            in text
        )
        assert str(tmp_path) not in text.split("## How it was trained")[0]
        name, task = shipped_name(export)
        assert name in available_policies(task)
    # any other folder by its path
    other = tmp_path / "agents" / "ppo_ahead"
    text = card(tmp_path, None, [SESSION], export=other)
    assert (
        f"`make_policy({str(other)!r})` (the copy in `{other}`) or {run} (the run folder)" in text
    )
    assert 'ppo_ahead")' not in text
