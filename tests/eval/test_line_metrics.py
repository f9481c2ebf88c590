"""eval/line_metrics.py: each line metric on a hand-made step log."""

import math

import pandas as pd
import pytest

from eval.line_metrics import LINE_HEADLINE_METRICS, LINE_METRICS, line_episode_metrics


def log(cte_mm: list[float], seen: list[int], ending: str, progress: list[float]) -> pd.DataFrame:
    n = len(cte_mm)
    return pd.DataFrame(
        {
            "time_s": [0.5 * k for k in range(n)],
            "progress_m": progress,
            "track_length_m": [2.15] * n,
            "cross_track_m": [c / 1000.0 for c in cte_mm],
            "line_seen": seen,
            "termination": [""] * (n - 1) + [ending],
        }
    )


FINISHED = log([3.0, -4.0, 0.0, 4.0], [1, 1, 1, 1], "track_end", [0.15, 0.8, 1.5, 2.13])
LOST = log([0.0, 10.0, 60.0, 90.0, 120.0], [1, 0, 1, 0, 0], "lost", [0.15, 0.4, 0.6, 0.6, 0.6])


def test_cross_track_mean_rms_and_max_are_in_mm() -> None:
    m = line_episode_metrics(FINISHED)
    assert m["cross_track_mean_mm"] == pytest.approx(11.0 / 4)
    assert m["cross_track_rms_mm"] == pytest.approx(math.sqrt(41.0 / 4))
    assert m["max_deviation_mm"] == pytest.approx(4.0)


def test_a_finished_episode_is_complete_with_a_lap_time() -> None:
    m = line_episode_metrics(FINISHED)
    assert m["completion_pct"] == 100.0
    assert m["lap_time_s"] == pytest.approx(1.5)
    assert m["failed_pct"] == 0.0


def test_a_lost_episode_counts_its_losses_and_the_share_it_covered() -> None:
    m = line_episode_metrics(LOST)
    assert m["completion_pct"] == pytest.approx(100.0 * 0.45 / 2.0)
    assert math.isnan(m["lap_time_s"])
    assert m["line_lost_count"] == 2.0  # seen -> unseen twice
    assert m["failed_pct"] == 100.0


def test_the_headline_metrics_are_registered_in_table_order() -> None:
    assert list(LINE_METRICS)[: len(LINE_HEADLINE_METRICS)] == list(LINE_HEADLINE_METRICS)


def test_a_log_without_its_ending_has_no_failure_value() -> None:
    # A robot's log may carry no termination column: its ending is unknown, not a success.
    m = line_episode_metrics(LOST.drop(columns="termination"))
    assert math.isnan(m["failed_pct"])
    assert math.isnan(m["lap_time_s"])
    assert m["completion_pct"] == pytest.approx(100.0 * 0.45 / 2.0)


def test_the_failure_rate_is_a_rate_of_episodes_with_a_wilson_interval() -> None:
    from eval.stats import binary_metrics, summarize

    assert binary_metrics(LINE_METRICS) == {"failed_pct"}
    table = pd.DataFrame(
        {"policy": "p", "track": "course", "seed": range(20), "failed_pct": [0.0] * 20}
    )
    row = summarize(table, metrics=["failed_pct"], rates=binary_metrics(LINE_METRICS)).iloc[0]
    assert row["failed_pct_ci_low"] == 0.0
    assert row["failed_pct_ci_high"] == pytest.approx(16.1, abs=0.05)  # not [0, 0]
