"""eval/report.py: the headline table shows collisions, losses and distance error."""

from pathlib import Path

import numpy as np
import pytest

from eval.cli import main
from eval.metrics import HEADLINE_METRICS, METRICS, OUTCOME_METRICS, THESIS_METRICS


def test_headline_metrics_are_registered_thesis_first() -> None:
    assert HEADLINE_METRICS[: len(THESIS_METRICS)] == THESIS_METRICS
    assert set(OUTCOME_METRICS) <= set(METRICS)


def test_headline_table_shows_collisions_losses_and_distance_error(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "r"
    args = ["run", "--policies", "pn", "--scenarios", "straight", "--episodes", "1"]
    assert main([*args, "--out", str(out)]) == 0
    headline = capsys.readouterr().out.split("## Further metrics")[0]
    tex = (out / "summary.tex").read_text()
    for label in ("collision (%)", "lost person (%)", "mean distance error (m)", "RMS distance"):
        assert label in headline
        assert label.replace("%", "\\%") in tex


def test_headline_table_shows_a_policy_that_always_collides() -> None:
    from eval.report import markdown_report
    from eval.rollout import rollout
    from eval.stats import episode_table, summarize

    episodes = rollout([Reverse(), "pn"], ["straight"], [0, 1], workers=1)
    headline = markdown_report(summarize(episode_table(episodes))).split("## Further")[0]
    reverse_row = next(line for line in headline.splitlines() if line.startswith("| reverse"))
    cells = [c.strip() for c in reverse_row.strip("|").split("|")]
    header = [c.strip() for c in headline.splitlines()[1].strip("|").split("|")]
    # two collisions in two episodes: the Wilson interval, not a bootstrap's point [100, 100],
    # marked as a cell of fewer than 10 episodes
    assert cells[header.index("collision (%)")] == "100.0 [34.2, 100.0]†"


class Reverse:
    """A broken controller: full speed backwards until it hits the wall behind."""

    name = "reverse"

    def reset(self) -> None:
        pass

    def act(self, obs: np.ndarray) -> np.ndarray:
        return np.array([-1.0, 0.0], dtype=np.float32)
