"""eval/report.py: the headline table shows collisions, losses and distance error."""

from pathlib import Path

import numpy as np
import pandas as pd
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


def _summary(n: list[int], low: float = 0.1, *, counts: bool = True) -> pd.DataFrame:
    """A summary of one headline metric, a cell per entry of ``n`` (its values), each interval
    starting at ``low`` (NaN: no interval); without ``<metric>_n`` when ``counts`` is False."""
    name = HEADLINE_METRICS[0]
    summary = pd.DataFrame(
        {
            "policy": [f"p{k}" for k in range(len(n))],
            "scenario": "straight",
            "episodes": n,
            name: 0.5,
            f"{name}_ci_low": low,
            f"{name}_ci_high": 0.9,
        }
    )
    return summary.assign(**{f"{name}_n": n}) if counts else summary


@pytest.mark.parametrize(
    ("summary", "marks"),
    [
        (_summary([20, 5]), 1),  # one cell of fewer than 10 values
        (_summary([20, 10]), 0),
        (_summary([5, 3], low=np.nan), 0),  # no interval: nothing to call rough
        (_summary([20, 5], counts=False), 1),  # the cell's episodes are its values then
    ],
)
def test_the_footnote_appears_exactly_when_an_interval_is_marked(
    summary: pd.DataFrame, marks: int
) -> None:
    from eval.report import SMALL_MARK, summary_markdown

    text = summary_markdown(summary)
    table, _, note = text.partition("\n\n")
    assert table.count(SMALL_MARK) == marks
    assert note.startswith(f"{SMALL_MARK} n<10: the interval is from fewer than 10") == bool(marks)


class Reverse:
    """A broken controller: full speed backwards until it hits the wall behind."""

    name = "reverse"

    def reset(self) -> None:
        pass

    def act(self, obs: np.ndarray) -> np.ndarray:
        return np.array([-1.0, 0.0], dtype=np.float32)


def test_bar_plot_draws_a_mean_a_rounding_above_its_point_interval(tmp_path: Path) -> None:
    """Twenty identical values: np.mean gives 17.935018000000003, the interval is the value
    itself, so the bar's upper error was -3.6e-15 and matplotlib refused the plot: the run
    ended in an error after its last episode (its journal kept the episodes for a resume)."""
    from eval.report import plot_metric_bars
    from eval.stats import error_bars

    value = 17.935018
    mean = float(np.mean(np.full(20, value)))
    assert mean != value  # the rounding this test is about
    summary = pd.DataFrame(
        {
            "policy": ["a"],
            "scenario": ["straight"],
            "episodes": [20],
            "in_frame_rate_pct": [mean],
            "in_frame_rate_pct_ci_low": [value],
            "in_frame_rate_pct_ci_high": [value],
        }
    )
    path = plot_metric_bars(summary, tmp_path / "bars.png", ["in_frame_rate_pct"], "t")
    assert path.is_file()
    assert path.stat().st_size > 0
    err = error_bars([mean], [value], [value])
    assert err[1, 0] == 0.0
    assert 0.0 <= err[0, 0] < 1e-12
    # NaN intervals draw no bar; a true interval keeps its lengths
    np.testing.assert_array_equal(error_bars([1.0], [np.nan], [np.nan]), [[0.0], [0.0]])
    np.testing.assert_allclose(error_bars([1.0], [0.5], [2.0]), [[0.5], [1.0]])
