"""eval/cli.py: ``follow-eval run`` and ``metrics`` end to end, and one-line errors."""

import importlib
import json
import os
from pathlib import Path

import pandas as pd
import pytest

from eval.cli import MAX_EPISODES, MAX_SEED, _check_grid, main
from eval.metrics import THESIS_METRICS

LEADING = [
    "policy",
    "scenario",
    "episodes",
    "mean_offset_px",
    "std_offset_px",
    "mean_accel_mm_s2",
    "std_accel_mm_s2",
    "in_frame_rate_pct",
]
GRID = ["--policies", "pn,gsmpn:thesis", "--scenarios", "straight,curve", "--episodes", "2"]


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("cli") / "run"
    assert main(["run", *GRID, "--seed", "5", "--out", str(out), "--workers", "1"]) == 0
    return out


def test_run_writes_every_report_file(run_dir: Path) -> None:
    names = {p.relative_to(run_dir).as_posix() for p in run_dir.rglob("*") if p.is_file()}
    expected = {
        "summary.csv",
        "summary.md",
        "summary.json",
        "summary.tex",
        "comparisons.csv",
        "episodes.csv",
        "meta.json",
        "plots/thesis_metrics.png",
        "plots/offsets_seed5.png",
        "plots/trajectories_seed5.png",
    }
    logs = {
        f"logs/{p}/{s}/seed_{k}.csv"
        for p in ("pn_tuned", "gsmpn_thesis")
        for s in ("straight", "curve")
        for k in (5, 6)
    }
    assert names == expected | logs
    assert not any(p.name.startswith(".") for p in run_dir.parent.iterdir())  # no temp left


def test_summary_csv_has_the_thesis_columns_first(run_dir: Path) -> None:
    summary = pd.read_csv(run_dir / "summary.csv")
    assert list(summary.columns[: len(LEADING)]) == LEADING
    assert "mean_offset_px_ci_low" in summary.columns
    assert "rms_distance_error_m" in summary.columns
    assert len(summary) == 4
    assert set(summary["episodes"]) == {2}
    assert list(summary["policy"]) == ["pn:tuned", "pn:tuned", "gsmpn:thesis", "gsmpn:thesis"]


def test_json_and_markdown_and_latex_parse(run_dir: Path) -> None:
    document = json.loads((run_dir / "summary.json").read_text())
    assert len(document["summary"]) == 4
    assert document["meta"]["seeds"] == [5, 6]
    assert document["metrics"]["mean_accel_mm_s2"]["unit"] == "mm/s²"
    assert {r["policy_a"] for r in document["comparisons"]} == {"pn:tuned"}
    markdown = (run_dir / "summary.md").read_text()
    assert "| MeanOffset (px)" in markdown
    latex = (run_dir / "summary.tex").read_text()
    assert "\\begin{tabular}" in latex
    assert "pn:tuned" in latex


def test_plots_are_png_files(run_dir: Path) -> None:
    for png in (run_dir / "plots").iterdir():
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_run_prints_the_table_and_where_it_wrote(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "r"
    args = ["run", "--policies", "pn", "--scenarios", "straight", "--episodes", "1"]
    assert main([*args, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "| policy" in printed
    assert "MeanOffset (px)" in printed
    assert f"Wrote {out}/" in printed


def test_metrics_on_the_run_logs_reproduces_the_summary(
    run_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "scored"
    assert main(["metrics", str(run_dir / "logs"), "--out", str(out)]) == 0
    assert "8 step logs scored" in capsys.readouterr().out
    key = ["policy", "scenario"]
    ran = pd.read_csv(run_dir / "summary.csv").sort_values(key, ignore_index=True)
    scored = pd.read_csv(out / "summary.csv").sort_values(key, ignore_index=True)
    pd.testing.assert_frame_equal(scored[LEADING], ran[LEADING], check_exact=False, rtol=1e-5)


def test_metrics_on_two_workers_writes_the_same_tables(run_dir: Path, tmp_path: Path) -> None:
    outs = [tmp_path / "one", tmp_path / "two"]
    for workers, out in zip(("1", "2"), outs, strict=True):
        args = ["metrics", str(run_dir / "logs"), "--out", str(out), "--workers", workers]
        assert main(args) == 0
    for name in ("summary.csv", "episodes.csv", "comparisons.csv", "summary.md"):
        assert (outs[1] / name).read_text() == (outs[0] / name).read_text(), name


def test_metrics_labels_a_minimal_robot_log(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    log = tmp_path / "robot.csv"
    log.write_text(
        "time_s,obs_distance_m,obs_offset_px,encoder_speed_mps\n0,1,10,0\n0.1,1,-10,0.1\n"
    )
    assert main(["metrics", str(log), "--policy", "gsmpn-real"]) == 0
    printed = capsys.readouterr().out
    assert "gsmpn-real" in printed
    assert "| recorded" in printed


def one_line_error(capsys: pytest.CaptureFixture) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert err.startswith("follow-eval: error: ")
    assert "Traceback" not in err
    return err


def test_metrics_on_malformed_row_names_file_and_line(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    log = tmp_path / "bad.csv"
    log.write_text("time_s,obs_distance_m,obs_offset_px,accel_mps2\n0,1,0,0\n0.1,1,oops,0\n")
    assert main(["metrics", str(log)]) == 2
    err = one_line_error(capsys)
    assert "bad.csv: line 3, column obs_offset_px: 'oops' is not a number" in err


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["run", "--policies", "pn,lqr"], "unknown policy 'lqr'; known names: "),
        (["run", "--scenarios", "moonwalk"], "unknown scenario 'moonwalk'; known scenarios: "),
        (["run", "--episodes", "0"], "--episodes: 0 is out of range: must be >= 1"),
        (["run", "--episodes", "-1"], "--episodes: -1 is out of range: must be >= 1"),
        (["run", "--seed", "-1"], "--seed: -1 is out of range: must be >= 0"),
        (["run", "--episodes", "many"], "--episodes: 'many' is not an integer"),
        (["run", "--workers", "0"], "--workers: 0 is out of range"),
        (["run", "--policies", ","], "--policies is empty"),
        # empty, not left out: a mistake to name rather than a request for the defaults
        (["run", "--policies", ""], "--policies is empty"),
        (["run", "--scenarios", ""], "--scenarios is empty"),
        (["thesis", "--episodes", "1"], "--episodes: 1 is out of range: must be >= 2"),
        (["run", "--config", '{"perception": '], "is not a valid JSON object: Expecting value"),
        (
            ["run", "--policies", "pn,gsmpn,pn:tuned"],
            "--policies: 'pn' and 'pn:tuned' are the same controller (pn:tuned); give it once",
        ),
        (["run", "--config", "harsh"], "--config: 'harsh' is not a preset"),
        (["run", "--config", '{"perception": {"miss": 1}}'], "unknown field perception.miss"),
        (["run", "--config", "[1, 2]"], "must be a mapping of config sections"),
        (["run", "--config", "missing.yaml"], "cannot read missing.yaml"),
        (["run", "--plot-seed", "99", "--episodes", "2"], "--plot-seed 99 is out of range"),
        (["metrics", "nowhere.csv"], "nowhere.csv: no such file"),
        # named before any log is read, by its option
        (["metrics", "nowhere.csv", "--task", "bogus"], "error: --task: task 'bogus' is out of"),
        # "" is not the current folder: not "'' is a folder", not ". already exists"
        (["run", "--config", ""], "error: argument --config: '' is empty: give a preset"),
        (["run", "--out", ""], "error: argument --out: '' is empty: give the path of a new"),
        (["metrics", "nowhere.csv", "--out", " "], "argument --out: ' ' is empty"),
        (["fly"], "invalid choice: 'fly'"),
        ([], "the following arguments are required: {run,metrics,thesis,aggregate,dominance}"),
    ],
)
def test_bad_arguments_give_one_line_and_exit_2(
    args: list[str], message: str, capsys: pytest.CaptureFixture
) -> None:
    assert main(args) == 2
    assert message in one_line_error(capsys)


def test_config_takes_section_overrides_as_json_or_a_file(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    overrides = {"perception": {"association": "tracker"}}
    out = tmp_path / "json"
    args = ["run", "--policies", "pn", "--scenarios", "straight", "--episodes", "1"]
    assert main([*args, "--config", json.dumps(overrides), "--out", str(out)]) == 0
    assert json.loads((out / "summary.json").read_text())["meta"]["config"] == overrides
    conf = tmp_path / "tracker.yaml"
    conf.write_text("perception:\n  association: tracker\n")
    assert main([*args, "--config", str(conf), "--out", str(tmp_path / "yaml")]) == 0
    capsys.readouterr()


def test_a_config_file_that_is_not_yaml_is_one_line_with_its_place(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("perception: [1,2\n")  # PyYAML's own message takes 8 lines
    assert main(["run", "--config", str(bad), "--out", str(tmp_path / "run")]) == 2
    err = one_line_error(capsys)
    assert f"{bad} is not valid YAML/JSON: line 2, column 1: expected ',' or ']'" in err
    assert "(while parsing a flow sequence from line 1, column 13)" in err
    assert main(["run", "--config", str(tmp_path), "--out", str(tmp_path / "run")]) == 2
    assert f"'{tmp_path}' is a folder: give a preset" in one_line_error(capsys)
    twice = tmp_path / "twice.yaml"  # PyYAML alone keeps the last: the run the file hides
    twice.write_text("perception:\n  association: tracker\n  association: nearest\n")
    assert main(["run", "--config", str(twice), "--out", str(tmp_path / "run")]) == 2
    assert "line 3, column 3: found the key 'association' twice" in one_line_error(capsys)
    text = '{"perception": {"association": "tracker", "association": "nearest"}}'
    assert main(["run", "--config", text, "--out", str(tmp_path / "run")]) == 2
    assert "is not a valid JSON object: found the key 'association' twice" in one_line_error(capsys)
    twice.write_bytes(b"perception: {}\n\xff\n")
    assert main(["run", "--config", str(twice), "--out", str(tmp_path / "run")]) == 2
    assert f"{twice} is not a UTF-8 text file (byte 16 is 0xff)" in one_line_error(capsys)
    # nested thousands deep: the parsers' recursion ended in a traceback, exit status 1
    deep = tmp_path / "deep.yaml"
    deep.write_text("[" * 5000 + "]" * 5000)
    assert main(["run", "--config", str(deep), "--out", str(tmp_path / "run")]) == 2
    assert f"{deep} is not valid YAML/JSON: nested too deeply" in one_line_error(capsys)
    text = '{"a":' * 5000 + "1" + "}" * 5000
    assert main(["run", "--config", text, "--out", str(tmp_path / "run")]) == 2
    assert "the JSON object given (30001 characters) is nested too deeply" in one_line_error(capsys)
    assert not (tmp_path / "run").exists()


def test_an_agent_of_another_task_is_sent_to_its_task(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    agents = Path(__file__).parents[2] / "policies" / "agents"
    line = str(agents / "ppo_line")
    for policies in (line, f"{line}@mecanum"):  # not the platform: the task is what differs
        assert main(["run", "--policies", policies, "--out", str(tmp_path / "run")]) == 2
        err = one_line_error(capsys)
        assert "was trained on LineTrace-v0, not on the person_follow task" in err
        assert err.rstrip().endswith("run it on the line_trace task (--task line_trace)")
    follow = ["--policies", str(agents / "ppo"), "--out", str(tmp_path / "run")]
    assert main(["run", "--task", "line_trace", *follow]) == 2
    assert "run it on the person_follow task (--task person_follow)" in one_line_error(capsys)


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux's /proc")
def test_a_folder_that_takes_no_file_is_refused_before_the_run(
    capsys: pytest.CaptureFixture,
) -> None:
    # /proc refuses new files even to root, for whom a read-only folder is writable
    assert main(["run", "--episodes", "1", "--out", "/proc/personfollow-test/run"]) == 2
    assert "cannot write to /proc" in one_line_error(capsys)


def test_existing_run_folder_is_never_overwritten(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    (tmp_path / "old.txt").write_text("keep")
    assert main(["run", "--episodes", "1", "--out", str(tmp_path)]) == 2
    assert "already exists and is not an empty folder" in one_line_error(capsys)
    assert (tmp_path / "old.txt").read_text() == "keep"


@pytest.mark.skipif(os.geteuid() == 0, reason="root can write into read-only folders")
def test_unwritable_folder_gives_one_line(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    assert main(["run", "--episodes", "1", "--out", str(locked / "run")]) == 2
    assert "cannot write to" in one_line_error(capsys)


@pytest.mark.parametrize("below", ["run", "sub/run"])
def test_output_path_through_a_file_names_that_file(
    tmp_path: Path, capsys: pytest.CaptureFixture, below: str
) -> None:
    # Works as root too: a folder cannot be made below a regular file.
    (tmp_path / "file").write_text("x")
    args = ["run", "--policies", "pn", "--scenarios", "straight", "--episodes", "1"]
    assert main([*args, "--out", str(tmp_path / "file" / below)]) == 2
    assert f"{tmp_path / 'file'} is a file, not a folder" in one_line_error(capsys)


def test_metrics_output_through_a_file_is_refused_before_scoring(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    (tmp_path / "file").write_text("x")
    # The log is malformed: the --out error must come first, before any log is read.
    (tmp_path / "bad.csv").write_text("not a step log\n")
    assert main(["metrics", str(tmp_path / "bad.csv"), "--out", str(tmp_path / "file" / "s")]) == 2
    assert f"{tmp_path / 'file'} is a file, not a folder" in one_line_error(capsys)


@pytest.mark.slow
def test_video_is_one_mp4_per_policy_and_scenario(tmp_path: Path) -> None:
    import cv2

    out = tmp_path / "run"
    args = ["run", "--policies", "pn,mpn", "--scenarios", "straight", "--episodes", "1"]
    assert main([*args, "--seed", "2", "--video", "--out", str(out)]) == 0
    videos = sorted(p.name for p in (out / "videos").iterdir())
    assert videos == ["mpn_tuned_straight_seed2.mp4", "pn_tuned_straight_seed2.mp4"]
    capture = cv2.VideoCapture(str(out / "videos" / videos[0]))
    steps = len(pd.read_csv(out / "logs" / "mpn_tuned" / "straight" / "seed_2.csv"))
    assert int(capture.get(cv2.CAP_PROP_FRAME_COUNT)) == steps  # one frame per row
    assert (capture.get(cv2.CAP_PROP_FRAME_WIDTH), capture.get(cv2.CAP_PROP_FRAME_HEIGHT)) == (
        1280,
        480,
    )


def test_python_dash_m_eval_is_the_same_cli() -> None:
    import subprocess
    import sys

    done = subprocess.run(
        [sys.executable, "-m", "eval", "run", "--episodes", "0"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 2
    assert done.stderr.strip() == (
        "follow-eval: error: argument --episodes: 0 is out of range: must be >= 1"
    )


def test_thesis_metrics_are_the_leading_metric_columns() -> None:
    assert LEADING[3:] == list(THESIS_METRICS)


@pytest.mark.parametrize(
    ("grid", "total"),
    [
        (
            ["--policies", "pn", "--scenarios", "straight", "--episodes", "1000000000"],
            "1,000,000,000",
        ),
        (
            ["--policies", "pn,mpn", "--scenarios", "straight,curve", "--episodes", "12501"],
            "50,004",
        ),
    ],
)
def test_absurd_grid_is_refused_before_any_work_stating_the_limit(
    grid: list[str], total: str, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "run"
    assert main(["run", *grid, "--out", str(out)]) == 2
    err = one_line_error(capsys)
    assert f"= {total} episodes is out of range: a run takes at most 50,000 episodes" in err
    assert not out.exists()


def test_the_largest_grid_is_accepted() -> None:
    _check_grid(2, 2, MAX_EPISODES // 4, seed=0)  # exactly the limit: no error


def test_seeds_beyond_the_envs_range_are_refused(capsys: pytest.CaptureFixture) -> None:
    assert main(["run", "--seed", str(MAX_SEED), "--episodes", "2"]) == 2
    assert "must stay within 0 .. 2**256 - 1 (the env's seeds)" in one_line_error(capsys)


def test_max_seed_is_the_envs_largest_seed() -> None:
    import gymnasium as gym

    env = gym.make("PersonFollow-v0", scenario="straight")
    env.reset(seed=MAX_SEED)
    with pytest.raises(ValueError, match="out of range"):
        env.reset(seed=MAX_SEED + 1)


def test_metrics_gives_runs_intervals_with_seeds_past_9(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    # Seeds 4..15: read as text the logs come as seed_10 .. seed_15, seed_4 .. seed_9. Twelve
    # episodes: with very few, BCa's bias correction hinges on exact ties between resample
    # means, which the 9 digits of a log's values can break.
    out = tmp_path / "run"
    grid = ["--policies", "gsmpn:thesis,pn", "--scenarios", "straight", "--episodes", "12"]
    assert main(["run", *grid, "--seed", "4", "--out", str(out)]) == 0
    assert main(["metrics", str(out / "logs"), "--out", str(tmp_path / "scored")]) == 0
    capsys.readouterr()
    for name in ("summary.csv", "comparisons.csv"):
        ran = pd.read_csv(out / name)
        scored = pd.read_csv(tmp_path / "scored" / name)
        # The signed MeanAccel telescopes to (v_end - v_0) / T, about -2 mm/s² for every law:
        # its interval's ends move by ~1e-4 mm/s² when the logs' 9 digits are re-read, and the
        # paired differences between laws (~1e-6) are rounding, so their signed ranks are too.
        if "wilcoxon_p" in ran:
            signed = ran["metric"] == "mean_accel_mm_s2"
            ran.loc[signed, "wilcoxon_p"] = scored.loc[signed, "wilcoxon_p"] = 0.0
        pd.testing.assert_frame_equal(scored, ran, check_exact=False, rtol=1e-4, atol=1e-3)
    assert list(pd.read_csv(tmp_path / "scored" / "episodes.csv")["seed"]) == list(range(4, 16)) * 2


def test_metrics_refuses_two_logs_of_one_episode(
    run_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    first = run_dir / "logs" / "pn_tuned" / "straight" / "seed_5.csv"
    copy = tmp_path / "copy.csv"
    copy.write_bytes(first.read_bytes())
    assert main(["metrics", str(run_dir / "logs"), str(copy)]) == 2
    err = one_line_error(capsys)
    assert f"{first} and {copy} are both policy 'pn:tuned', scenario 'straight', seed 5" in err


def test_platforms_run_every_policy_on_each_on_the_same_seeds(tmp_path: Path) -> None:
    out = tmp_path / "run"
    argv = ["run", "--policies", "pn", "--platforms", "diff_drive,mecanum", "--scenarios"]
    assert main([*argv, "straight", "--episodes", "2", "--out", str(out)]) == 0
    summary = pd.read_csv(out / "summary.csv")
    assert list(summary["policy"]) == ["pn:tuned@diff_drive", "pn:tuned@mecanum"]
    meta = json.loads((out / "meta.json").read_text())
    assert set(meta["policies"]) == {"pn:tuned@diff_drive", "pn:tuned@mecanum"}
    log = pd.read_csv(out / "logs" / "pn_tuned_mecanum" / "straight" / "seed_1.csv")
    assert "action_vy_mps" in log
    assert "duty_fl" in log


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--policies", "holonomic", "--platforms", "diff_drive"], "commands vy_mps"),
        (["--policies", "pn", "--platforms", "tank"], "--platforms: platform='tank'"),
        (["--policies", "pn@mecanum", "--platforms", "mecanum"], "leave out --platforms"),
    ],
)
def test_a_platform_a_policy_cannot_run_on_is_one_line_and_status_2(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    assert main(["run", *argv, "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert message in err
    assert err.count("\n") == 1
    assert not (tmp_path / "x").exists()


def test_metrics_on_a_runs_logs_orders_its_tables_as_the_run_did(
    run_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    # The logs are found in alphabetical order (gsmpn_thesis before pn_tuned, curve before
    # straight); the run's meta.json says the run's: pn:tuned, gsmpn:thesis; straight, curve.
    out = tmp_path / "scored"
    assert main(["metrics", str(run_dir / "logs"), "--out", str(out)]) == 0
    capsys.readouterr()
    for name, key in (
        ("summary.csv", ["policy", "scenario"]),
        ("episodes.csv", ["policy", "scenario", "seed"]),
        ("comparisons.csv", ["scenario", "policy_a", "policy_b", "metric"]),
    ):
        ran, scored = pd.read_csv(run_dir / name), pd.read_csv(out / name)
        pd.testing.assert_frame_equal(scored[key], ran[key])
    ran, scored = pd.read_csv(run_dir / "summary.csv"), pd.read_csv(out / "summary.csv")
    pd.testing.assert_frame_equal(scored[LEADING], ran[LEADING], check_exact=False, rtol=1e-5)
    # one log of the run, given alone, is ordered by the run too (nothing to reorder)
    one = run_dir / "logs" / "pn_tuned" / "curve" / "seed_5.csv"
    assert main(["metrics", str(one)]) == 0
    assert "| pn:tuned" in capsys.readouterr().out


def test_metrics_refuses_the_same_log_twice_and_a_run_folder(
    run_dir: Path, capsys: pytest.CaptureFixture
) -> None:
    log = run_dir / "logs" / "pn_tuned" / "straight" / "seed_5.csv"
    # without the check, a log without a seed column is scored twice (its position as seed)
    for argv in ([log, log], [run_dir / "logs" / "pn_tuned", log]):
        assert main(["metrics", *map(str, argv)]) == 2
        assert f"error: {log}: the same step log given twice" in one_line_error(capsys)
    other = run_dir / "logs" / "pn_tuned" / ".." / "pn_tuned" / "straight" / "seed_5.csv"
    assert main(["metrics", str(log), str(other)]) == 2
    assert f"{log} and {other}: the same step log given twice" in one_line_error(capsys)
    # the run's folder: its summary tables are not step logs
    assert main(["metrics", str(run_dir)]) == 2
    err = one_line_error(capsys)
    assert f"{run_dir} is a follow-eval run folder, whose tables are not step logs: give " in err
    assert str(run_dir / "logs") in err


# -- errors from work units: dying workers, and an exception a worker raised --------------------


def _stopped_by_dying_workers(finished: int) -> object:
    """A rollout that finishes ``finished`` units, then loses a unit's worker for good."""
    from execution import WorkerLostError

    def rollout(*args: object, on_unit: object = None, **kwargs: object) -> list[object]:
        for i in range(finished):
            on_unit(i, [])  # type: ignore[operator]  # kept in the run's journal
        raise WorkerLostError(
            1, "(pn, straight)", 4, 3, 3, "killed by SIGKILL (the out-of-memory killer's signal)"
        )

    return rollout


def test_workers_that_keep_dying_stop_a_run_in_one_line_saying_how_to_resume(
    tmp_path: Path, capsys: pytest.CaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    from eval.journal import journal_folder

    rollouts = importlib.import_module("eval.rollout")  # `eval.rollout` is also a function
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(rollouts, "rollout", _stopped_by_dying_workers(finished=2))
    args = ["run", "--policies", "pn", "--scenarios", "straight", "--episodes", "4"]
    out = tmp_path / "run"
    assert main([*args, "--out", str(out), "--workers", "1"]) == 3  # not 2: not a bad argument
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "Traceback" not in err
    assert err.startswith("follow-eval: error: unit 1 (pn, straight): its worker process died 4 ")
    folder = journal_folder(out)
    assert f"the finished work units are kept in {folder}: the same command" in err
    assert f"--out {out} resumes" in err
    assert folder.is_dir()
    assert not out.exists()
    # without --out: the folder it would have written is named, to resume into
    assert main([*args, "--workers", "1"]) == 3
    err = capsys.readouterr().err
    [kept] = Path("runs").glob(".eval-*.units")
    assert f"--out {Path('runs') / kept.name[1:].removesuffix('.units')} resumes" in err
    # nothing finished: nothing kept, and said so
    monkeypatch.setattr(rollouts, "rollout", _stopped_by_dying_workers(finished=0))
    assert main([*args, "--out", str(tmp_path / "none"), "--workers", "1"]) == 3
    assert "no work unit had finished, nothing was kept" in capsys.readouterr().err
    assert not journal_folder(tmp_path / "none").exists()


def test_an_error_raised_in_a_worker_names_its_unit_and_host(
    tmp_path: Path, capsys: pytest.CaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    import socket

    from execution import Backend, execute

    def rollout(*args: object, **kwargs: object) -> list[object]:
        return execute(_unit_that_fails, [("pn", "straight")], Backend("local", workers=2))

    monkeypatch.setattr(importlib.import_module("eval.rollout"), "rollout", rollout)
    argv = ["run", "--policies", "pn", "--scenarios", "straight", "--episodes", "1"]
    assert main([*argv, "--out", str(tmp_path / "run"), "--workers", "1"]) == 2
    err = one_line_error(capsys)
    assert "error: the unit's own error (in work unit 0 (('pn', 'straight')) on host " in err
    assert f"on host {socket.gethostname()}, process " in err


def _unit_that_fails(unit: tuple[str, str]) -> None:  # run by a spawned worker, imported by name
    raise ValueError("the unit's own error")
