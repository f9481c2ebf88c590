"""eval/scoring.py: a run's logs and tables, scenario by scenario, equal to the serial ones;
step logs read back as episodes on a backend, the first bad file reported."""

from __future__ import annotations

import re
from pathlib import Path

import pandas as pd
import pytest

import eval.scoring
from eval.line_metrics import LINE_METRICS
from eval.metrics import METRICS
from eval.rollout import Episode, rollout
from eval.scoring import read_episodes, score
from eval.stats import binary_metrics, compare, episode_table, summarize
from eval.steplog import StepLogError, read_step_log, write_step_log
from execution.backend import Backend


@pytest.fixture(scope="module")
def episodes() -> list[Episode]:
    # Policy-major, as rollout gives them: the per-scenario units see them in another order.
    return rollout(["pn:thesis", "mpn:tuned", "gsmpn:thesis"], ["curve", "crossing"], [0, 1, 2])


def _serial(episodes: list[Episode], metrics: dict, variant: str = "scenario") -> tuple:
    table = episode_table(episodes, metrics=metrics, variant=variant)
    names = list(metrics)
    summary = summarize(table, metrics=names, rates=binary_metrics(metrics))
    return table, summary, compare(table, metrics=names)


def _check_equal(got: object, want: tuple) -> None:
    pd.testing.assert_frame_equal(got.table, want[0])
    pd.testing.assert_frame_equal(got.summary, want[1])
    pd.testing.assert_frame_equal(got.comparisons, want[2])


def _paths(folder: Path, episodes: list[Episode]) -> dict[int, Path]:
    return {id(ep): folder / f"{ep.policy}-{ep.scenario}-{ep.seed}.csv" for ep in episodes}


@pytest.mark.parametrize("workers", [1, 2])
def test_scored_by_scenario_equals_the_serial_tables_and_logs(
    episodes: list[Episode], workers: int, tmp_path: Path
) -> None:
    want = _serial(episodes, METRICS)
    paths = _paths(tmp_path / "scored", episodes)
    (tmp_path / "scored").mkdir()
    got = score(
        episodes,
        metrics=METRICS,
        log_path=lambda ep: paths[id(ep)],
        backend=Backend(workers=workers),
    )
    _check_equal(got, want)
    assert len(got.comparisons) == 2 * 3 * len(METRICS)  # 2 scenarios x 3 pairs x metrics
    (tmp_path / "serial").mkdir()
    for ep in episodes:
        written = write_step_log(ep.log, tmp_path / "serial" / paths[id(ep)].name)
        assert paths[id(ep)].read_bytes() == written.read_bytes()
    assert len(list((tmp_path / "scored").iterdir())) == len(episodes)


def test_the_order_of_the_episodes_is_kept(episodes: list[Episode]) -> None:
    # Scenario-major and reversed: the table's rows, the summary's cells and the comparisons'
    # pairs follow the episodes as given, as the serial functions do.
    shuffled = sorted(episodes, key=lambda ep: (ep.scenario, ep.seed), reverse=True)
    got = score(shuffled, metrics=METRICS)
    _check_equal(got, _serial(shuffled, METRICS))
    assert list(got.summary["scenario"][:2]) == ["curve", "curve"]
    assert got.comparisons["policy_a"].iloc[0] == shuffled[0].policy


def test_a_scenario_a_policy_did_not_run_is_left_out_of_its_pairs(episodes: list[Episode]) -> None:
    some = [ep for ep in episodes if not (ep.policy == "mpn:tuned" and ep.scenario == "curve")]
    got = score(some, metrics=METRICS)
    _check_equal(got, _serial(some, METRICS))
    curve = got.comparisons[got.comparisons["scenario"] == "curve"]
    assert set(zip(curve["policy_a"], curve["policy_b"], strict=True)) == {
        ("pn:thesis", "gsmpn:thesis")
    }


def test_line_trace_episodes_are_scored_by_track(tmp_path: Path) -> None:
    eps = rollout(["pid", "coordinate"], ["gaps", "curves"], [1, 2], task="line_trace")
    got = score(eps, metrics=LINE_METRICS, variant="track")
    _check_equal(got, _serial(eps, LINE_METRICS, "track"))
    assert list(got.summary["track"]) == ["gaps", "curves", "gaps", "curves"]


def test_no_episodes_give_empty_tables_with_the_columns(tmp_path: Path) -> None:
    got = score([], metrics=METRICS, log_path=lambda ep: tmp_path / "never.csv")
    _check_equal(got, _serial([], METRICS))
    assert got.table.empty
    assert "mean_offset_px" in got.table
    assert list(tmp_path.iterdir()) == []


def _written(folder: Path, episodes: list[Episode]) -> list[Path]:
    paths = list(_paths(folder, episodes).values())
    for path, ep in zip(paths, episodes, strict=True):
        write_step_log(ep.log, path)
    return paths


@pytest.mark.parametrize("workers", [1, 2])
def test_logs_read_back_are_the_episodes_scored_alike(
    episodes: list[Episode], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, workers: int
) -> None:
    monkeypatch.setattr(eval.scoring, "_FILES_PER_UNIT", 4)  # several units: 18 logs
    paths = _written(tmp_path, episodes)
    read = read_episodes(paths, task="person_follow", backend=Backend(workers=workers))
    assert [(ep.policy, ep.scenario, ep.seed) for ep in read] == [
        (ep.policy, ep.scenario, ep.seed) for ep in episodes
    ]
    for path, ep in zip(paths, read, strict=True):
        pd.testing.assert_frame_equal(ep.log, read_step_log(path))
    # a log as written and read back scores as the episode did (to the logs' 6 digits)
    got, want = score(read, metrics=METRICS), score(episodes, metrics=METRICS)
    pd.testing.assert_frame_equal(got.table, want.table, check_exact=False, rtol=1e-5)


def test_a_log_without_labels_gets_the_given_ones_and_its_position_as_seed(tmp_path: Path) -> None:
    logs = [tmp_path / "a.csv", tmp_path / "b.csv"]
    for log in logs:
        log.write_text("time_s,obs_distance_m,obs_offset_px,accel_mps2\n0,1,0,0\n0.1,1,2,0\n")
    read = read_episodes(logs, task="person_follow", policy="gsmpn-real", label="hall")
    assert [(ep.policy, ep.scenario, ep.seed) for ep in read] == [
        ("gsmpn-real", "hall", 0),
        ("gsmpn-real", "hall", 1),
    ]
    assert "termination" not in read[0].log  # unknown, not a blank (clean) ending


def test_a_log_without_termination_scores_its_endings_as_unknown(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """A robot's log records no ending: collision, lost and success are NaN (n/a), not the 0 %,
    0 % and 100 % of an episode known to have ended well; the other metrics are scored."""
    logs = [tmp_path / "a.csv", tmp_path / "b.csv"]
    for log in logs:
        log.write_text("time_s,obs_distance_m,obs_offset_px,accel_mps2\n0,1,0,0\n0.1,1,2,0\n")
    scored = score(read_episodes(logs, task="person_follow"), metrics=METRICS)
    endings = ["collision_rate_pct", "lost_rate_pct", "success_pct"]
    assert scored.table[endings].isna().all().all()
    assert scored.table["termination"].tolist() == ["", ""]
    [row] = scored.summary.to_dict("records")
    assert all(pd.isna(row[m]) and row[f"{m}_n"] == 0 for m in endings)
    assert row["mean_offset_px"] == pytest.approx(1.0)  # (0 + 2) / 2 on each log
    assert capsys.readouterr().err == ""  # one policy: no pairing to warn about


def test_policies_on_different_seeds_are_said_to_be_paired_on_the_common_ones(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """Logs of two policies on seeds 0-3 and 2-5 are compared on 2-3, and logs numbered by
    their position (no seed column) share none: each pair keeps its rows (n = 0 when nothing
    is shared), and one warning line on stderr says so."""
    logs = []
    for policy, seeds in (("pn", range(4)), ("gsmpn", range(2, 6))):
        for seed in seeds:
            logs.append(tmp_path / f"{policy}-{seed}.csv")
            logs[-1].write_text(
                "policy,scenario,seed,time_s,obs_distance_m,obs_offset_px,accel_mps2,termination\n"
                f"{policy},hall,{seed},0,1,0,0,\n{policy},hall,{seed},0.1,1,{seed},0,walk_over\n"
            )
    scored = score(read_episodes(logs, task="person_follow"), metrics=METRICS)
    [pairing] = scored.comparisons[["seeds_a", "seeds_b", "seeds_both"]].drop_duplicates().values
    assert pairing.tolist() == [4, 4, 2]
    err = capsys.readouterr().err.splitlines()
    assert err == [
        "follow-eval: warning: policies that ran different seeds are compared on the seeds both "
        "ran only: scenario hall: pn ran 4 seeds and gsmpn 4; compared on the 2 both ran"
    ]
    unnumbered = []
    for path in logs[:2] + logs[4:6]:  # without the policy, scenario and seed columns
        unnumbered.append(tmp_path / f"bare-{path.name}")
        unnumbered[-1].write_text(
            "time_s,obs_distance_m,obs_offset_px,accel_mps2\n0,1,0,0\n0.1,1,2,0\n"
        )
    a = read_episodes(unnumbered[:2], task="person_follow", policy="a")
    b = read_episodes(unnumbered, task="person_follow", policy="b")[2:]  # seeds 2, 3
    scored = score([*a, *b], metrics=METRICS)
    assert len(scored.comparisons) == len(METRICS)  # the pair is there, not dropped
    assert (scored.comparisons["n"] == 0).all()
    assert scored.comparisons["mean_diff"].isna().all()
    assert "they share none: not compared" in capsys.readouterr().err


@pytest.mark.parametrize("workers", [1, 2])
def test_the_first_bad_file_in_order_is_reported(
    episodes: list[Episode], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, workers: int
) -> None:
    monkeypatch.setattr(eval.scoring, "_FILES_PER_UNIT", 2)
    paths = _written(tmp_path, episodes[:6])
    # a bad file in the second unit and another in the third, which may finish first
    paths[3].write_text("time_s,obs_distance_m,obs_offset_px,accel_mps2\n0,1,oops,0\n")
    paths[4].write_text("")
    with pytest.raises(StepLogError, match=re.escape(f"{paths[3]}: line 2, column obs_offset_px")):
        read_episodes(paths, task="person_follow", backend=Backend(workers=workers))


def test_one_process_stops_reading_at_a_bad_file(
    episodes: list[Episode], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(eval.scoring, "_FILES_PER_UNIT", 1)
    paths = _written(tmp_path, episodes[:4])
    paths[1].write_text("")
    read: list[Path] = []

    def counted(path: Path, task: str) -> pd.DataFrame:
        read.append(Path(path))
        return read_step_log(path, task)

    monkeypatch.setattr(eval.scoring, "read_step_log", counted)
    with pytest.raises(StepLogError, match="empty file"):
        read_episodes(paths, task="person_follow")
    assert read == paths[:2]


def test_seeds_past_float_precision_are_read_exactly(tmp_path: Path, capsys) -> None:
    """A run takes seeds up to 2**256 - 1; read as float64, seeds 2**60 and 2**60 + 1 of one
    policy and scenario were one seed, and follow-eval metrics refused them as one episode."""
    from eval.cli import main

    big = 2**64 + 3  # past int64 too: the run's seed column holds Python ints
    for first in (2**60, big):
        run = tmp_path / f"run-{first}"
        grid = ["--policies", "pn", "--scenarios", "straight", "--episodes", "2"]
        assert main(["run", *grid, "--seed", str(first), "--out", str(run), "--workers", "1"]) == 0
        logs = sorted((run / "logs").rglob("*.csv"))
        read = read_episodes(logs, task="person_follow")
        assert sorted(ep.seed for ep in read) == [first, first + 1]
        out = tmp_path / f"scored-{first}"
        assert main(["metrics", str(run / "logs"), "--out", str(out)]) == 0
        ran = (run / "episodes.csv").read_text().splitlines()
        assert (out / "episodes.csv").read_text().splitlines()[1].split(",")[2] == str(first)
        assert [line.split(",")[2] for line in ran[1:]] == [str(first), str(first + 1)]
    capsys.readouterr()
