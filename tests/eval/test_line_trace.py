"""LineTrace through the evaluation: rollout(task="line_trace"), its tables and follow-eval run
--task line_trace, with one-line errors for bad input."""

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from eval.cli import main
from eval.line_metrics import LINE_HEADLINE_METRICS, LINE_METRICS
from eval.rollout import rollout, run_batch, run_episode
from eval.stats import compare, episode_table, summarize
from follow_env.platforms import get_platform
from follow_env.tasks.line_trace.steplog import OBS_COLUMNS, log_columns

LIGHT = ["time_s", *OBS_COLUMNS]  # the readings: the sensor noise and light of the seed


class Stop:
    """Never moves: as different from the controllers as a policy can be."""

    name = "stop"
    action_names = ("v_mps", "vy_mps", "w_radps")

    def reset(self) -> None:
        pass

    def act(self, obs: np.ndarray) -> np.ndarray:
        return np.zeros(3, dtype=np.float32)


def test_batched_and_one_by_one_episodes_are_identical() -> None:
    batch = run_batch("coordinate", "curves", [4, 5], task="line_trace")
    for ep in batch:
        single = run_episode("coordinate", "curves", ep.seed, task="line_trace")
        pd.testing.assert_frame_equal(ep.log, single.log)


def test_logs_have_the_line_layout_with_the_track_named() -> None:
    (ep,) = rollout(["pid"], ["gaps"], [1], task="line_trace")
    mecanum = get_platform("mecanum")
    keys = tuple(key for key, *_ in mecanum.info)
    assert tuple(ep.log.columns) == log_columns(("v_mps", "vy_mps", "w_radps"), keys)
    assert set(ep.log["track"]) == {"gaps"}
    assert ep.log[list(OBS_COLUMNS)].to_numpy().max() > 0.5  # the line was read
    assert ep.log["in_gap"].isin([0, 1]).all()


def test_every_policy_meets_the_same_light_at_the_start() -> None:
    # The first row is the reading at the start, before any action: the same for every policy.
    episodes = rollout(["coordinate", "pid", Stop()], ["random"], [2], task="line_trace")
    first = [ep.log[LIGHT].iloc[:1] for ep in episodes]
    for other in first[1:]:
        pd.testing.assert_frame_equal(first[0], other)
    assert episodes[2].termination == "time_limit"  # standing still on the line: no progress


def test_a_person_following_law_or_an_unknown_track_is_refused() -> None:
    with pytest.raises(ValueError, match="policy 'pn' is not for the line_trace task"):
        rollout(["pn"], ["straight"], [0], task="line_trace")
    with pytest.raises(ValueError, match="unknown track 'moon'; known tracks: corners"):
        rollout(["pid"], ["moon"], [0], task="line_trace")


def test_tables_hold_the_line_metrics_per_track() -> None:
    episodes = rollout(["coordinate", "pid"], ["straight"], [0, 1, 2], task="line_trace")
    table = episode_table(episodes, metrics=LINE_METRICS, variant="track")
    summary = summarize(table, metrics=list(LINE_METRICS))
    assert list(summary.columns[:3]) == ["policy", "track", "episodes"]
    assert set(LINE_HEADLINE_METRICS) <= set(summary.columns)
    assert (summary["completion_pct"] == 100.0).all()  # both finish the straight track
    pairs = compare(table, metrics=list(LINE_METRICS))
    assert set(pairs["track"]) == {"straight"}
    assert (pairs["n"] == 3).all()


GRID = ["--task", "line_trace", "--policies", "coordinate,pid", "--tracks", "straight,gaps"]


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("line") / "run"
    args = ["run", *GRID, "--episodes", "2", "--seed", "3", "--out", str(out), "--workers", "1"]
    assert main(args) == 0
    return out


def test_run_writes_the_tables_logs_and_line_plots(run_dir: Path) -> None:
    names = {p.relative_to(run_dir).as_posix() for p in run_dir.rglob("*") if p.is_file()}
    plots = {"plots/line_metrics.png", "plots/cross_track_seed3.png", "plots/paths_seed3.png"}
    tables = {"summary.csv", "summary.md", "summary.json", "summary.tex", "comparisons.csv"}
    logs = {
        f"logs/{p}/{t}/seed_{k}.csv"
        for p in ("coordinate_tuned", "pid_tuned")
        for t in ("straight", "gaps")
        for k in (3, 4)
    }
    assert names == plots | tables | logs | {"episodes.csv", "meta.json"}


def test_run_summary_leads_with_the_line_metrics(run_dir: Path) -> None:
    summary = pd.read_csv(run_dir / "summary.csv")
    assert list(summary.columns[:3]) == ["policy", "track", "episodes"]
    assert list(summary.columns[3 : 3 + len(LINE_HEADLINE_METRICS)]) == list(LINE_HEADLINE_METRICS)
    markdown = (run_dir / "summary.md").read_text()
    assert "cross-track RMS (mm)" in markdown
    assert "| track" in markdown
    meta = json.loads((run_dir / "meta.json").read_text())
    assert meta["task"] == "line_trace"
    assert meta["tracks"] == ["straight", "gaps"]
    assert meta["config"] == "paper"


def one_line_error(capsys: pytest.CaptureFixture) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert err.startswith("follow-eval: error: ")
    return err


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--tracks", "moon"], "--tracks: unknown track 'moon'; known tracks: corners"),
        (["--policies", "pn"], "policy 'pn' is not for the line_trace task; its policies:"),
        (["--policies", "coordinate@diff_drive"], "--policies: "),
        (["--scenarios", "curve"], "--scenarios is not an option of the line_trace task"),
        (
            ["--config", "thesis"],
            "--config: 'thesis' is not a preset: give a preset (ideal, noisy, paper)",
        ),
        (["--config", '{"sensor": {"pitch": 1}}'], "unknown field sensor.pitch"),
        (["--episodes", "0"], "--episodes: 0 is out of range"),
    ],
)
def test_bad_line_arguments_give_one_line_and_exit_2(
    args: list[str], message: str, capsys: pytest.CaptureFixture, tmp_path: Path
) -> None:
    out = tmp_path / "never"
    assert main(["run", "--task", "line_trace", *args, "--out", str(out)]) == 2
    assert message in one_line_error(capsys)
    assert not out.exists()


def test_an_unknown_task_or_tracks_on_person_follow_give_one_line(
    capsys: pytest.CaptureFixture,
) -> None:
    assert main(["run", "--task", "sumo"]) == 2
    assert "--task: task 'sumo' is out of range" in one_line_error(capsys)
    assert main(["run", "--tracks", "course"]) == 2
    assert "--tracks is not an option of the person_follow task" in one_line_error(capsys)


def test_follow_eval_metrics_scores_line_logs_as_the_run_did(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    run = tmp_path / "run"
    grid = ["--task", "line_trace", "--policies", "coordinate,pid", "--tracks", "curves,gaps"]
    assert main(["run", *grid, "--episodes", "3", "--out", str(run)]) == 0
    capsys.readouterr()
    # the task is read from the logs' track column; --task says it outright
    for extra in ([], ["--task", "line_trace"]):
        scored = tmp_path / f"scored{len(extra)}"
        assert main(["metrics", str(run / "logs"), *extra, "--out", str(scored)]) == 0
        assert "12 step logs scored" in capsys.readouterr().out  # 2 policies x 2 tracks x 3
        keys = ["policy", "track"]
        ran = pd.read_csv(run / "summary.csv").sort_values(keys).reset_index(drop=True)
        got = pd.read_csv(scored / "summary.csv").sort_values(keys).reset_index(drop=True)
        assert list(got.columns) == list(ran.columns)
        means = [c for c in ran.columns if not c.endswith(("_ci_low", "_ci_high"))]
        pd.testing.assert_frame_equal(got[means], ran[means], check_exact=False, rtol=1e-6)
        assert json.loads((scored / "summary.json").read_text())
        assert (scored / "plots" / "line_metrics.png").stat().st_size > 5000
    # line logs read as PersonFollow's: one line naming what is missing, exit 2
    assert main(["metrics", str(run / "logs"), "--task", "person_follow"]) == 2
    assert "missing column(s) obs_distance_m" in one_line_error(capsys)
    assert main(["metrics", str(run / "logs"), "--task", "nope"]) == 2
    assert "task 'nope' is out of range" in one_line_error(capsys)
