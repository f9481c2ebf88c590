"""eval/aggregate.py: ``follow-eval aggregate``, learners over seeds against the laws."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from eval.aggregate import (
    BOOTSTRAP_SEEDS,
    LearnerRuns,
    _between_learners,
    _by_split,
    _cube,
    _resample_cube,
    learner_runs,
    normalised_scores,
    scenario_split,
    stratified_ci,
)
from eval.aggregate_inputs import PLATFORM
from eval.cli import main

ROOT = Path(__file__).parents[2]
AGENT = ROOT / "policies" / "agents" / "ppo"


def test_the_bootstrap_resamples_runs_within_each_task_then_their_episodes() -> None:
    # cube[run, task, episode] = 100 * task + 10 * run + episode
    cube = np.fromfunction(lambda r, t, e: 100 * t + 10 * r + e, (3, 2, 4))
    episodes = np.array([[0, 0, 0, 0], [3, 3, 3, 3]])  # task 0 draws episode 0, task 1 episode 3
    sample = _resample_cube(cube, episodes, np.random.default_rng(0))
    assert sample.shape == (3, 2)
    assert set(sample[:, 0]) <= {0.0, 10.0, 20.0}  # a run of task 0, its episode 0
    assert set(sample[:, 1]) <= {103.0, 113.0, 123.0}  # a run of task 1, its episode 3


def test_a_ci_holds_its_estimate_and_is_reproducible() -> None:
    cube = np.random.default_rng(1).random((5, 3, 10))
    got = stratified_ci(np.mean, [cube], reps=300, seed=4)
    assert got[1] <= got[0] <= got[2]
    assert got[0] == pytest.approx(cube.mean())
    assert got == stratified_ci(np.mean, [cube], reps=300, seed=4)


def test_a_run_is_a_training_seed_so_the_ci_covers_a_learners_mean() -> None:
    # Five agents, each better or worse by its own draw (sd 0.10), ten noisy episodes each
    # (sd 0.05): the intervals must hold the learners' true mean about as often as they say.
    # Counting every (seed, episode) as a run, as an earlier version did, they held it in
    # fewer than half of the studies.
    rng = np.random.default_rng(0)
    studies, held, held_flat = 60, 0, 0
    for k in range(studies):
        cube = 0.6 + rng.normal(0, 0.10, (5, 3, 1)) + rng.normal(0, 0.05, (5, 3, 10))
        _, low, high = stratified_ci(np.mean, [cube], reps=300, seed=k)
        held += low <= 0.6 <= high
        flat = cube.transpose(0, 2, 1).reshape(50, 3)  # (seed x episode, task)
        _, low, high = stratified_ci(np.mean, [flat], reps=300, seed=k)
        held_flat += low <= 0.6 <= high
    assert held / studies >= 0.8
    assert held_flat / studies <= 0.6
    # the README quotes this simulation's figures
    readme = " ".join((ROOT / "README.md").read_text(encoding="utf-8").split())
    quoted = (
        f"in {round(100 * held_flat / studies)} % of studies, the present unit's in "
        f"{round(100 * held / studies)} %"
    )
    assert quoted in readme, quoted


def test_the_episodes_are_drawn_alike_for_every_controller() -> None:
    # Two controllers whose every episode differs by exactly 0.1 on the same seeds: a paired
    # draw keeps the difference at 0.1 in every resample, an unpaired one would spread it.
    law = np.random.default_rng(2).random((1, 2, 20))
    learner = law + 0.1
    got = stratified_ci(lambda a, b: float(np.mean(a) - np.mean(b)), [learner, law], reps=200)
    assert got == pytest.approx((0.1, 0.1, 0.1))


def test_the_cube_is_ordered_by_run_scenario_and_seed() -> None:
    scores = pd.DataFrame(
        {
            "run": [1, 0, 1, 0, 1, 0, 1, 0],
            "scenario": ["b", "b", "a", "a", "b", "b", "a", "a"],
            "seed": [8, 8, 8, 8, 7, 7, 7, 7],
            "normalised": np.arange(8.0),
        }
    )
    cube = _cube(scores, ["a", "b"])
    assert cube.shape == (2, 2, 2)
    assert cube[1, 0].tolist() == [6.0, 2.0]  # run 1, scenario a, seeds 7 and 8
    assert cube[0, 1].tolist() == [5.0, 1.0]  # run 0, scenario b, seeds 7 and 8


def test_scores_are_normalised_per_scenario_by_the_episodes_seen() -> None:
    raw = pd.DataFrame(
        {
            "controller": ["a", "b", "a", "b"],
            "run": [0, 0, 0, 0],
            "scenario": ["s", "s", "t", "t"],
            "seed": [0, 0, 0, 0],
            "score": [10.0, 30.0, -5.0, -1.0],
        }
    )
    assert normalised_scores(raw)["normalised"].tolist() == [0.0, 1.0, 0.0, 1.0]


def test_a_folder_without_an_agent_is_refused_by_name(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="holds no trained agent"):
        learner_runs(tmp_path)


def _agent_study(folder: Path, seeds: tuple[int, ...]) -> Path:
    """A study without study.json whose ``seed-<k>`` folders each hold the shipped agent."""
    for k in seeds:
        shutil.copytree(AGENT, folder / f"seed-{k}")
    return folder


@pytest.mark.slow
def test_a_study_against_a_law_writes_the_tables_and_plots(
    tmp_path: Path, capsys: pytest.CaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    # two "seeds" (the shipped agent twice): the machinery, not the numbers
    study = _agent_study(tmp_path / "study", (0, 2))
    (study / "study.json").write_text(json.dumps({"seeds": [2, 0]}))
    out = tmp_path / "agg"
    grid = ["--laws", "pn", "--scenarios", "straight,curve", "--episodes", "2", "--reps", "200"]
    monkeypatch.setattr("sys.argv", ["follow-eval", "aggregate", str(study), *grid])
    assert main(["aggregate", str(study), *grid, "--out", str(out)]) == 0
    agg = pd.read_csv(out / "aggregate.csv")
    assert set(agg["controller"]) == {"study", "pn"}
    assert set(agg["metric"]) == {"iqm", "mean", "median", "optimality_gap"}
    assert (
        (agg["ci_low"] <= agg["estimate"] + 1e-12) & (agg["estimate"] <= agg["ci_high"] + 1e-12)
    ).all()
    imp = pd.read_csv(out / "improvement.csv")
    assert imp[["learner", "law"]].to_numpy().tolist() == [["study", "pn"]]
    pairs = pd.read_csv(out / "learners.csv")  # one learner: no pair, the columns only
    assert pairs.empty
    assert list(pairs.columns)[:2] == ["learner", "other"]
    assert 0.0 <= imp["probability"].iloc[0] <= 1.0
    scores = pd.read_csv(out / "scores.csv")
    assert len(scores) == (2 + 1) * 2 * 2  # (2 seeds + 1 law) x 2 scenarios x 2 episodes
    assert scores["normalised"].between(0.0, 1.0).all()
    assert set(scores["split"]) == {"single_target"}
    splits = pd.read_csv(out / "splits.csv")
    # both scenarios are single-target: one split, an IQM per controller and one P(improvement)
    assert splits[["split", "scenarios"]].drop_duplicates().to_numpy().tolist() == [
        ["single_target", "straight,curve"]
    ]
    assert sorted(splits["metric"]) == ["iqm", "iqm", "p_improvement"]
    iqm = agg[agg["metric"] == "iqm"].set_index("controller")["estimate"]
    split_iqm = splits[splits["metric"] == "iqm"].set_index("controller")["estimate"]
    assert np.allclose(split_iqm.loc[iqm.index], iqm)  # one split holding every scenario: the same
    assert {p.name for p in (out / "plots").iterdir()} == {
        "aggregates.png",
        "performance_profiles.png",
    }
    assert "Probability of improvement" in capsys.readouterr().out
    assert "one run (one training seed)" not in (out / "aggregate.md").read_text()  # two seeds
    # each run by its training seed and agent, not only its place in the learner; a law's blank
    runs = scores[scores["controller"] == "study"].drop_duplicates("run")
    assert runs[["run", "training_seed"]].to_numpy().tolist() == [[0, 0], [1, 2]]
    assert runs["agent"].tolist() == [str(study / "seed-0"), str(study / "seed-2")]
    law = scores[scores["controller"] == "pn"]
    assert law["training_seed"].isna().all()
    assert law["agent"].isna().all()
    # what ran, as follow-eval run records it
    meta = json.loads((out / "meta.json").read_text())
    assert meta["command"] == "follow-eval aggregate " + " ".join([str(study), *grid])
    agents = meta["learners"]["study"]["agents"]
    assert [(a["path"], a["training_seed"]) for a in agents] == [
        (str(study / "seed-0"), 0),
        (str(study / "seed-2"), 2),
    ]
    assert all(len(a["model_sha256"]) == 64 for a in agents)
    assert meta["learners"]["study"]["study_json"] is True
    assert meta["laws"] == {"pn": "pn:tuned"}
    assert (meta["scenarios"], meta["seeds"]) == (["straight", "curve"], [9001, 9002])
    assert meta["bootstrap"]["reps"] == 200
    assert meta["bootstrap"]["profile_reps"] == 50
    assert meta["bootstrap"]["seeds"] == BOOTSTRAP_SEEDS
    assert meta["platform"] == PLATFORM
    assert len(meta["code"]["sources_sha256"]) == 64
    assert "numpy" in meta["versions"]


def test_bad_arguments_give_one_line(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["aggregate", str(AGENT), "--laws", "pnn", "--out", str(tmp_path / "x")]) == 2
    assert "unknown policy 'pnn'" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
    assert main(["aggregate", str(tmp_path), "--out", str(tmp_path / "y")]) == 2
    assert "holds no trained agent" in capsys.readouterr().err
    # two names of one law (pn is pn:tuned) would be the same controller's lines twice
    laws = ["--laws", "pn,gsmpn,pn:tuned", "--out", str(tmp_path / "z")]
    assert main(["aggregate", str(AGENT), *laws]) == 2
    err = capsys.readouterr().err
    assert "--laws: 'pn' and 'pn:tuned' are the same controller (pn:tuned); give it once" in err
    assert err.count("\n") == 1
    assert not (tmp_path / "z").exists()


def test_a_learner_named_twice_is_refused_before_any_episode(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = ["--scenarios", "straight", "--laws", "pn", "--out", str(tmp_path / "x")]
    assert main(["aggregate", str(AGENT), str(AGENT), *out]) == 2
    err = capsys.readouterr().err
    assert "names the learner 'ppo' twice; give each folder once" in err
    assert err.count("\n") == 1
    other = tmp_path / "elsewhere" / "ppo"  # another folder of the same name
    shutil.copytree(AGENT, other)
    assert main(["aggregate", str(AGENT), str(other), *out]) == 2
    assert "are both named 'ppo' (a learner is named by its folder)" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_scenarios_fall_into_the_splits_they_declare() -> None:
    assert {s: scenario_split(s) for s in ("straight", "occlusion", "crossing", "crowd")} == {
        "straight": "single_target",
        "occlusion": "single_target",  # walls hide the person; nobody else is there
        "crossing": "distractor",
        "crowd": "distractor",
    }


def test_each_split_is_scored_on_its_own_scenarios_only() -> None:
    # scenarios straight (single-target) and crossing (distractor); the learner is best on
    # straight and worst on crossing, the law the reverse
    learner = np.array([[1.0, 0.0], [0.9, 0.1], [0.8, 0.2]])
    law = 1.0 - learner
    table = _by_split(
        {"agent": learner, "law": law}, [LearnerRuns("agent", [])], ["law"],
        ["straight", "crossing"], reps=100,
    )  # fmt: skip
    got = table.set_index(["split", "controller", "metric"])["estimate"]
    assert got["single_target", "agent", "iqm"] == pytest.approx(0.9)
    assert got["distractor", "agent", "iqm"] == pytest.approx(0.1)
    assert got["single_target", "agent", "p_improvement"] == pytest.approx(1.0)
    assert got["distractor", "agent", "p_improvement"] == pytest.approx(0.0)
    assert set(table["scenarios"]) == {"straight", "crossing"}


def test_learners_are_compared_with_each_other_once_a_pair() -> None:
    # overlapping IQM intervals cannot say whether one learner's runs beat another's
    runs = np.array([[0.50, 0.60], [0.55, 0.65], [0.52, 0.62]])  # 3 runs x 2 scenarios
    matrix = {"a": runs + 0.2, "b": runs, "c": runs - 0.2}
    learners = [LearnerRuns(name, []) for name in ("a", "b", "c")]
    pairs = _between_learners(matrix, learners, reps=200)
    assert [(first, second) for first, second, *_ in pairs] == [("a", "b"), ("a", "c"), ("b", "c")]
    for _, _, point, low, high in pairs:
        assert point == pytest.approx(1.0)  # every run of the first above every run of the next
        assert low <= point <= high
    assert _between_learners(matrix, learners[:1], reps=200) == []  # one learner: no pair


@pytest.mark.slow
def test_any_accepted_reps_gives_the_tables(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    # --reps 3 used to run every episode and then fail: the profiles drew reps // 4 = 0 samples
    out = tmp_path / "agg"
    grid = ["--laws", "pn", "--scenarios", "straight", "--episodes", "2", "--reps", "3"]
    assert main(["aggregate", str(AGENT), *grid, "--out", str(out)]) == 0
    capsys.readouterr()
    # one run folder: its interval is the episodes' alone, which the report says under the
    # header that speaks of training seeds
    report = (out / "aggregate.md").read_text()
    assert "ppo: one run (one training seed), so its intervals hold the evaluation" in report
    profiles = pd.read_csv(out / "profiles.csv")
    assert len(profiles) == 2 * 21  # two controllers, 21 taus
    assert (profiles["ci_low"] <= profiles["ci_high"]).all()
    with pytest.raises(ValueError, match="reps must be >= 1, got 0"):
        stratified_ci(np.mean, [np.ones((3, 1))], reps=0)


@pytest.fixture
def no_episode(monkeypatch: pytest.MonkeyPatch) -> None:
    """Fail the test if any episode would run: the refusals below come first."""

    def refuse(*_: object, **__: object) -> None:
        pytest.fail("an episode ran before the arguments were refused")

    monkeypatch.setattr("eval.aggregate.rollout", refuse)


def _one_line(capsys: pytest.CaptureFixture) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert err.startswith("follow-eval: error: ")
    return err


@pytest.mark.parametrize(
    ("folder", "laws", "law"),
    [
        ("pn", "pn,gsmpn", "pn"),
        ("ppo", "ppo", "ppo"),
        ("pn:tuned", "gsmpn,pn", "pn"),
        ("pn", "gsmpn,pn:tuned", "pn:tuned"),  # the same law spelt otherwise
        ("gsmpn:tuned", "gsmpn", "gsmpn"),
    ],
)
def test_a_learner_named_as_a_law_is_refused_before_any_episode(
    tmp_path: Path, capsys: pytest.CaptureFixture, no_episode: None, folder: str, laws: str,
    law: str,
) -> None:  # fmt: skip
    learner = tmp_path / "learners" / folder
    shutil.copytree(AGENT, learner)
    out = tmp_path / "x"
    argv = ["aggregate", str(learner), "--laws", laws, "--scenarios", "straight", "--out", str(out)]
    assert main(argv) == 2
    err = _one_line(capsys)
    assert f"{learner}: the learner is named {folder!r} (by its folder), as the law {law!r}" in err
    assert not out.exists()


def test_an_agent_in_two_learners_is_refused_before_any_episode(
    tmp_path: Path, capsys: pytest.CaptureFixture, no_episode: None
) -> None:
    study = _agent_study(tmp_path / "study", (0, 1))
    out = tmp_path / "x"
    grid = ["--laws", "pn", "--scenarios", "straight", "--out", str(out)]
    assert main(["aggregate", str(study), str(study / "seed-0"), *grid]) == 2
    err = _one_line(capsys)
    assert f"the agent {study / 'seed-0'} is in two learners, {study} and {study / 'seed-0'}" in err
    # the same agent spelled another way is the same agent
    assert main(["aggregate", str(study / "seed-1"), f"{study}/./", *grid]) == 2
    assert f"is in two learners, {study / 'seed-1'} and {study}: give" in _one_line(capsys)
    assert not out.exists()


def test_an_unknown_scenario_names_the_option(
    tmp_path: Path, capsys: pytest.CaptureFixture, no_episode: None
) -> None:
    argv = ["aggregate", str(AGENT), "--laws", "pn", "--scenarios", "straight,bogus"]
    assert main([*argv, "--out", str(tmp_path / "x")]) == 2
    assert "error: --scenarios: unknown scenario 'bogus'; known scenarios: " in _one_line(capsys)


def _study(folder: Path, finished: list[str], listed: list[int] | None = None) -> Path:
    """A study whose ``finished`` seed folders hold a (placeholder) model.zip; ``listed``: its
    study.json's seeds (None: no study.json)."""
    for name in finished:
        (folder / name).mkdir(parents=True)
        (folder / name / "model.zip").write_bytes(b"")
    if listed is not None:
        (folder / "study.json").write_text(json.dumps({"seeds": listed, "n_envs": 4}))
    return folder


def test_a_study_is_the_seeds_its_record_lists(tmp_path: Path) -> None:
    # seed-7 (not the study's) and seed-1.bak (not a seed) hold models too: neither is a run
    study = _study(tmp_path / "s", ["seed-10", "seed-2", "seed-0", "seed-7", "seed-1.bak"])
    (study / "study.json").write_text(json.dumps({"seeds": [10, 0, 2]}))
    got = learner_runs(study)
    assert (got.name, got.agents, got.seeds) == (
        "s",
        [study / "seed-0", study / "seed-2", study / "seed-10"],
        [0, 2, 10],
    )


def test_a_study_seed_that_did_not_finish_is_refused_by_name(tmp_path: Path) -> None:
    # seed 2 of 0-3 was cut short (checkpoints, no model.zip), seed 3 never started: scoring
    # seeds 0 and 1 alone would keep the survivors
    study = _study(tmp_path / "s", ["seed-0", "seed-1"], listed=[0, 1, 2, 3])
    (study / "seed-2" / "checkpoints").mkdir(parents=True)
    with pytest.raises(ValueError, match="seed-2, seed-3 of the study's seeds") as e:
        learner_runs(study)
    assert str(e.value) == (
        f"{study}: seed-2, seed-3 of the study's seeds (study.json: 0,1,2,3) have no model.zip "
        "(training did not finish), and scoring only the seeds that finished would bias the "
        f"learner: run the same follow-train --seeds 0,1,2,3 ... --out {study} command again, "
        "which resumes them"
    )
    (study / "study.json").write_text("{}")
    with pytest.raises(ValueError, match=r"study.json: not a study description"):
        learner_runs(study)


def test_a_study_without_a_record_is_its_seed_folders(tmp_path: Path) -> None:
    # made by hand (or before study.json): its seed-<k> folders, as follow-train names them
    study = _study(tmp_path / "s", ["seed-1", "seed-0", "seed-1.bak", "seed-01", "seed-x"])
    got = learner_runs(study)
    assert (got.agents, got.seeds) == ([study / "seed-0", study / "seed-1"], [0, 1])
    (study / "seed-2").mkdir()  # a seed whose training did not finish is not left out
    with pytest.raises(ValueError, match=r"s: seed-2 holds no model.zip \(training did not"):
        learner_runs(study)
    assert learner_runs(_study(tmp_path / "run", ["."])).seeds == [None]  # one run folder


def test_an_unfinished_study_is_refused_before_any_episode(
    tmp_path: Path, capsys: pytest.CaptureFixture, no_episode: None
) -> None:
    study = _agent_study(tmp_path / "study", (0, 1))
    (study / "study.json").write_text(json.dumps({"seeds": [0, 1, 2]}))
    out = tmp_path / "x"
    argv = ["aggregate", str(study), "--laws", "pn", "--scenarios", "straight", "--out", str(out)]
    assert main(argv) == 2
    assert f"{study}: seed-2 of the study's seeds (study.json: 0,1,2) has no model.zip" in (
        _one_line(capsys)
    )
    assert not out.exists()


@pytest.mark.parametrize("spelling", ["seed-0", "seed-0/", "./seed-0", "seed-0/model.zip"])
def test_a_learners_agent_as_a_law_is_refused_before_any_episode(
    tmp_path: Path,
    capsys: pytest.CaptureFixture,
    no_episode: None,
    monkeypatch: pytest.MonkeyPatch,
    spelling: str,
) -> None:
    # its episodes were filed under the learner, and the command stopped after every episode
    # with "cannot reshape array of size 0"
    study = _agent_study(tmp_path / "study", (0, 1))
    monkeypatch.chdir(study)
    out = tmp_path / "x"
    law = spelling if spelling.startswith("./") else f"{study}/{spelling}"
    argv = ["aggregate", str(study), "--laws", f"pn,{law}", "--scenarios", "straight"]
    assert main([*argv, "--out", str(out)]) == 2
    err = _one_line(capsys)
    assert f"--laws: {law!r} is the agent {study / 'seed-0'} of the learner {study}" in err
    assert not out.exists()


def test_an_agent_of_another_platform_is_refused_saying_what_compares_it(
    tmp_path: Path, capsys: pytest.CaptureFixture, no_episode: None
) -> None:
    agent = ROOT / "policies" / "agents" / "ppo_mecanum"
    out = tmp_path / "x"
    argv = ["aggregate", str(agent), "--laws", "pn", "--scenarios", "straight"]
    assert main([*argv, "--out", str(out)]) == 2
    err = _one_line(capsys)
    assert f"{agent}: the agent was trained on the mecanum platform" in err
    assert "follow-eval aggregate runs PersonFollow on the diff-drive platform (diff_drive)" in err
    assert f"follow-eval run --policies {agent}@mecanum,pn@mecanum," in err
    assert "run it @mecanum" not in err  # advice aggregate cannot follow
    assert not out.exists()


def test_aggregate_runs_on_the_task_default_platform() -> None:
    from follow_env.platforms import get_platform
    from follow_env.tasks import get_task

    default = get_task("person_follow").resolve_config(None)
    assert type(default.platform) is get_platform(PLATFORM).config
