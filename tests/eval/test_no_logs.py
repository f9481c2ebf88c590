"""``follow-eval run --no-logs``: the same tables as a run with step logs, no logs written,
each episode reduced to its table row where it ran, and the larger limit it allows."""

import json
import pickle
from pathlib import Path

import pytest

from eval.cli import MAX_EPISODES, MAX_EPISODES_WITHOUT_LOGS, _check_grid, main
from eval.cli_base import UsageError
from eval.journal import journal_folder
from eval.metrics import METRICS
from eval.rollout import MAX_EPISODES as ROLLOUT_MAX_EPISODES
from eval.rollout import Episode, rollout
from eval.stats import EpisodeRow, TableRow, episode_table

TABLES = ("summary.csv", "summary.md", "summary.tex", "episodes.csv", "comparisons.csv")
GRID = ["--policies", "pn,gsmpn:thesis", "--scenarios", "straight,curve", "--episodes", "3"]


def _files(folder: Path) -> set[str]:
    return {p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()}


def _without_logs(out: Path, workers: int = 1) -> list[str]:
    """``follow-eval run``'s arguments for :data:`GRID` from seed 5 into ``out``, without logs."""
    return ["run", *GRID, "--seed", "5", "--out", str(out), "--workers", str(workers), "--no-logs"]


def _same_tables(a: Path, b: Path) -> None:
    for name in TABLES:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name


@pytest.fixture(scope="module")
def with_logs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("logs") / "run"
    assert main(["run", *GRID, "--seed", "5", "--out", str(out), "--workers", "1"]) == 0
    return out


def test_the_tables_are_those_of_a_run_with_logs_and_no_log_is_written(
    with_logs: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "run"
    # Two processes: the rows are made in the workers and sent back.
    args = _without_logs(out, workers=2)
    assert main(args) == 0
    _same_tables(with_logs, out)
    logs = {name for name in _files(with_logs) if name.startswith("logs/")}
    assert len(logs) == 12
    assert _files(out) == _files(with_logs) - logs  # the plots and every table, no logs/
    assert json.loads((out / "meta.json").read_text())["step_logs"] is False
    assert json.loads((with_logs / "meta.json").read_text())["step_logs"] is True
    said = capsys.readouterr().out.splitlines()[-1]
    assert "episodes.csv, plots/" in said
    assert "logs/" not in said


def test_the_plot_seeds_episodes_keep_their_logs_for_the_plots(
    with_logs: Path, tmp_path: Path
) -> None:
    out = tmp_path / "run"
    args = _without_logs(out)
    assert main([*args, "--plot-seed", "7"]) == 0
    _same_tables(with_logs, out)
    assert {p.name for p in (out / "plots").iterdir()} == {
        "thesis_metrics.png",
        "offsets_seed7.png",
        "trajectories_seed7.png",
    }


def test_the_ideal_baseline_and_line_tracing_give_the_same_tables(tmp_path: Path) -> None:
    runs = {
        "ideal": ["--policies", "pn", "--scenarios", "straight", "--ideal-baseline"],
        "line": ["--task", "line_trace", "--tracks", "course,gaps"],
    }
    for name, grid in runs.items():
        a, b = tmp_path / f"{name}-logs", tmp_path / f"{name}-rows"
        common = [*grid, "--episodes", "2", "--workers", "1"]
        assert main(["run", *common, "--out", str(a)]) == 0
        assert main(["run", *common, "--out", str(b), "--no-logs"]) == 0
        _same_tables(a, b)
        assert not (b / "logs").exists()
        assert (a / "logs").is_dir()
    episodes = (tmp_path / "ideal-rows" / "episodes.csv").read_text()
    assert "pn:tuned+ideal" in episodes  # the baseline's rows carry its label


def test_table_row_reduces_every_episode_but_the_kept_seeds() -> None:
    episodes = rollout(["pn", "mpn:thesis"], ["straight", "random"], [3, 4, 5], workers=1)
    reduced = [TableRow(METRICS, keep_seed=4)(ep) for ep in episodes]
    kept = [ep for ep in reduced if isinstance(ep, Episode)]
    assert {ep.seed for ep in kept} == {4}
    assert len(kept) == 4
    assert all(isinstance(ep, EpisodeRow) for ep in reduced if ep.seed != 4)
    assert episode_table(reduced).equals(episode_table(episodes))
    # on a pool, as follow-eval run sends it (a task's metrics are a read-only mapping)
    pooled = rollout(["pn"], ["curve"], [3, 4], reduce=TableRow(METRICS), workers=2)
    assert all(isinstance(ep, EpisodeRow) for ep in pooled)
    assert episode_table(pooled).equals(episode_table(rollout(["pn"], ["curve"], [3, 4])))


def test_a_run_without_logs_takes_twenty_times_the_episodes(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    assert MAX_EPISODES_WITHOUT_LOGS == ROLLOUT_MAX_EPISODES == 20 * MAX_EPISODES
    grid = ["--policies", "pn,mpn", "--scenarios", "straight,curve"]
    assert main(["run", *grid, "--episodes", "12501", "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err
    assert "at most 50,000 episodes" in err
    assert "--no-logs keeps only each episode's table row and takes up to 1,000,000" in err
    _check_grid(2, 2, 12501, seed=0, logs=False)  # allowed without logs
    _check_grid(4, 5, MAX_EPISODES, seed=0, logs=False)  # both limits exactly: 1,000,000
    with pytest.raises(UsageError, match="1,050,000 episodes is out of range"):
        _check_grid(21, 1, MAX_EPISODES, seed=0, logs=False)
    # A cell's intervals take time with the square of its episodes: a scenario's seeds are
    # held to the run's limit with logs.
    with pytest.raises(UsageError, match="a scenario takes at most 50,000 seeds"):
        _check_grid(1, 1, MAX_EPISODES + 1, seed=0, logs=False)
    args = ["run", *grid, "--episodes", "250001", "--no-logs", "--out", str(tmp_path / "b")]
    assert main(args) == 2
    assert "at most 1,000,000 episodes" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


def _interrupted_after_every_unit(monkeypatch: pytest.MonkeyPatch, args: list[str]) -> None:
    """Run ``follow-eval ARGS`` and Ctrl-C it after every unit has run and been kept."""

    def interrupted(*_: object, **__: object) -> None:
        raise KeyboardInterrupt

    with monkeypatch.context() as patch:
        patch.setattr("eval.scoring.score", interrupted)
        assert main(args) == 130


def test_an_interrupted_run_resumes_only_in_the_same_mode(
    with_logs: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    out = tmp_path / "run"
    args = ["run", *GRID, "--seed", "5", "--out", str(out), "--workers", "1"]
    _interrupted_after_every_unit(monkeypatch, [*args, "--no-logs"])
    journal = journal_folder(out)
    units = len(list(journal.glob("unit-*.pkl")))
    assert units >= 4
    assert not out.exists()
    # What each unit kept: rows, the plot seed's episodes whole (their logs drawn in the plots).
    kept = [ep for unit in journal.glob("unit-*.pkl") for ep in pickle.loads(unit.read_bytes())]
    assert len(kept) == 12
    assert {type(ep) for ep in kept if ep.seed != 5} == {EpisodeRow}
    assert {type(ep) for ep in kept if ep.seed == 5} == {Episode}
    capsys.readouterr()
    # Its units hold rows, not episodes: a run with logs must not take them.
    assert main(args) == 2
    assert "holds the finished units of another run" in capsys.readouterr().err
    assert main([*args, "--no-logs"]) == 0
    assert f"resuming: {units} work units already done" in capsys.readouterr().err
    _same_tables(with_logs, out)
    assert not journal.exists()


def test_metrics_on_a_run_without_logs_says_it_has_none(
    with_logs: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "run"
    args = _without_logs(out)
    assert main(args) == 0
    capsys.readouterr()
    for given in (out / "logs", out):
        assert main(["metrics", str(given), "--out", str(tmp_path / "tables")]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1
        named = f"{given}: the run {out} holds" if given != out else f"error: {out} holds"
        assert named in err
        assert "holds no step logs to score (follow-eval run --no-logs wrote it)" in err
    assert not (tmp_path / "tables").exists()
    # A run with its logs is scored as before.
    assert main(["metrics", str(with_logs / "logs"), "--out", str(tmp_path / "tables")]) == 0


def test_a_resumed_run_without_logs_keeps_its_plot_seed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    """A unit without logs keeps only the plot seed's episodes whole: resumed with another
    --plot-seed it would have nothing to plot, or plot some policies only."""
    out = tmp_path / "run"
    grid = ["--policies", "pn", "--scenarios", "straight", "--episodes", "2", "--seed", "5"]
    args = ["run", *grid, "--out", str(out), "--workers", "1", "--no-logs"]
    _interrupted_after_every_unit(monkeypatch, args)
    assert json.loads((journal_folder(out) / "run.json").read_text())["plot_seed"] == 5
    capsys.readouterr()
    assert main([*args, "--plot-seed", "6"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "holds the finished units of another run" in err
    assert not out.exists()
    assert main([*args, "--plot-seed", "5"]) == 0  # the same plot seed, given: the same run
    assert "resuming: 1 work units already done" in capsys.readouterr().err
    assert (out / "plots" / "offsets_seed5.png").is_file()


def test_a_resume_whose_agent_files_changed_is_another_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    """The units kept were run by the agent's old files: a resume with new ones would mix two
    models' episodes under one label and record the new model's digest only."""
    import shutil

    from policies.learned.ppo import AGENTS

    agent = tmp_path / "agents" / "mine"
    shutil.copytree(AGENTS / "ppo", agent)
    out = tmp_path / "run"
    grid = ["--policies", str(agent), "--scenarios", "straight", "--episodes", "1"]
    args = ["run", *grid, "--out", str(out), "--workers", "1", "--no-logs"]
    _interrupted_after_every_unit(monkeypatch, args)
    shutil.rmtree(agent)
    shutil.copytree(AGENTS / "ppo_law", agent)
    capsys.readouterr()
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    # the policy, its files and what to do are named (it said "another run (its model_sha256
    # differ)" and to run the same command again, which was refused again)
    assert f"the files of its learned policy {agent} changed since the run started" in err
    assert f"the SHA-256 of {agent}'s model, statistics and config in {agent} was " in err
    assert "run it with the agent files it started with to resume" in err
    assert "give a new --out" in err
    assert not out.exists()


def test_metrics_on_a_run_whose_logs_were_deleted_says_so(
    with_logs: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    import shutil

    run = tmp_path / "run"
    shutil.copytree(with_logs, run)
    shutil.rmtree(run / "logs")
    assert main(["metrics", str(run), "--out", str(tmp_path / "tables")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert f"{run} is a follow-eval run folder whose step logs ({run / 'logs'}) are missing" in err
    assert not (tmp_path / "tables").exists()
