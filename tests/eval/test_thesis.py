"""eval/thesis.py and follow-eval thesis: the Table 4.1 comparison and what one run can show."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from eval import thesis
from eval.cli import main


def _table(values: dict[tuple[str, str], np.ndarray], metric: str) -> pd.DataFrame:
    rows = []
    for (law, walk), xs in values.items():
        rows += [{"law": law, "walk": walk, metric: float(x)} for x in xs]
    frame = pd.DataFrame(rows)
    other = "std_accel_mm_s2" if metric == "mean_offset_px" else "mean_offset_px"
    frame[other] = 0.0
    return frame


def test_one_run_ordering_probability_is_exact_over_the_runs() -> None:
    # straight MeanOffset, thesis order pn < gsmpn < mpn. pn {1, 2}, gsmpn {1.5}, mpn {3, 0}:
    # of the 2 x 1 x 2 combinations only (1, 1.5, 3) is in order: 1/4.
    values = {
        ("pn", "straight"): np.array([1.0, 2.0]),
        ("gsmpn", "straight"): np.array([1.5]),
        ("mpn", "straight"): np.array([3.0, 0.0]),
    }
    for law, walk in itertools.product(thesis.LAWS, ("curve",)):
        values[(law, walk)] = np.array([1.0])
    table = _table(values, "mean_offset_px")
    odds = thesis.one_run_orderings(table)
    row = odds[(odds["walk"] == "straight") & (odds["metric"] == "mean_offset_px")].iloc[0]
    assert row["thesis_order"] == "pn < gsmpn < mpn"
    assert row["p_one_run"] == pytest.approx(0.25)


def test_runs_to_separate_follows_the_normal_approximation() -> None:
    rng = np.random.default_rng(0)
    values = {
        (law, walk): rng.normal(10.0, 2.0, 400) for law in thesis.LAWS for walk in thesis.WALKS
    }
    values[("mpn", "straight")] = rng.normal(11.0, 2.0, 400)  # 1 apart, sd 2
    table = _table(values, "std_accel_mm_s2")
    sep = thesis.runs_to_separate(table)
    row = sep[(sep["walk"] == "straight") & (sep["metric"] == "std_accel_mm_s2")]
    n = int(row[row["pair"] == "pn vs mpn"]["runs_per_cell"].iloc[0])
    assert n == pytest.approx(2 * (1.96 + 0.8416) ** 2 * 4 / 1.0, rel=0.25)  # ~63


def test_follow_eval_thesis_writes_the_table(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "thesis"
    assert main(["thesis", "--episodes", "2", "--seed", "5", "--out", str(out)]) == 0
    table = pd.read_csv(out / "thesis_table.csv")
    assert list(table.columns) == [
        "law",
        "walk",
        "metric",
        "thesis",
        "chain",
        "mean",
        "ci_low",
        "ci_high",
        "band_low",
        "band_high",
    ]
    assert len(table) == 6 * 5 * len(thesis.CHAINS)
    pn = table[
        (table.law == "pn") & (table.walk == "straight") & (table.metric == "std_accel_mm_s2")
    ]
    assert set(pn["thesis"]) == {29109.58}
    corrected = pn[pn.chain == "corrected"]["mean"].iloc[0]
    as_built = pn[pn.chain == "as_built"]["mean"].iloc[0]
    assert as_built > 10 * corrected  # the as-built chain's logged acceleration is far noisier
    document = json.loads((out / "thesis_table.json").read_text())
    assert {"table", "one_run_orderings", "runs_to_separate"} <= set(document)
    for metric in thesis.METRICS:
        assert (out / "plots" / f"thesis_{metric}.png").stat().st_size > 5000
    printed = capsys.readouterr().out
    assert "One run per cell" in printed
    assert "Runs per cell" in printed
    # an existing folder is refused with one line, exit 2, before any work
    assert main(["thesis", "--episodes", "2", "--out", str(out)]) == 2
    assert "error" in capsys.readouterr().err
