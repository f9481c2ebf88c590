"""bench/nologs.py: the rows of make bench for a run without step logs, on a few episodes."""

from pathlib import Path

import pytest

import bench.nologs


def test_the_run_without_logs_has_rows_and_their_baselines(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(bench.nologs, "LAWS", ("pn:thesis",))
    rows = bench.nologs.bench_no_logs(quick=True)
    names = [name for name, _, _ in rows]
    assert names == [
        "run with logs, 24 episodes (ep/s)",  # 1 policy x 12 scenarios x 2
        "  --no-logs (ep/s)",
        "an episode with its log (bytes)",
        "  as its table row (bytes)",
    ]
    (_, logs_rate, one), (_, rows_rate, faster), (_, log, base), (_, row, less) = rows
    assert min(logs_rate, rows_rate) > 0.0
    assert one == base == "1x (baseline)"
    assert faster == f"{rows_rate / logs_rate:.2f}x faster"
    assert less == f"{log / row:.0f}x less"
    assert 0.0 < row < log  # a row is smaller than the log it was made from


def test_tables_that_differ_fail_the_bench(monkeypatch: pytest.MonkeyPatch) -> None:
    real = bench.nologs.main

    def another_row(args: list[str]) -> int:
        status = real(args)
        if "--no-logs" in args:
            table = Path(args[args.index("--out") + 1]) / "episodes.csv"
            table.write_text(table.read_text().replace("pn:thesis", "pn:other", 1))
        return status

    monkeypatch.setattr(bench.nologs, "LAWS", ("pn:thesis",))
    monkeypatch.setattr(bench.nologs, "main", another_row)
    with pytest.raises(AssertionError, match=r"--no-logs wrote another episodes\.csv"):
        bench.nologs.bench_no_logs(quick=True)
