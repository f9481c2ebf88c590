"""train/seeds.py: ``follow-train --seeds``, one run per training seed and a summary."""

from __future__ import annotations

import json
import shutil
from datetime import datetime, tzinfo
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from follow_env.tasks.person_follow import ENV_ID
from policies import make_policy
from policies.learned.ensemble import EnsemblePolicy
from policies.learned.ppo import PPOPolicy
from train.cli import main
from train.ppo import DEFAULT_HYPERPARAMS
from train.seeds import SEED_STRIDE, _new_study_path, parse_seeds

TINY = [
    "--scenarios", "straight",
    "--n-envs", "4",
    "--n-timesteps", "600",
    "--eval-freq", "300",
    "--checkpoint-freq", "300",
    "--eval-episodes", "2",
    "--final-episodes", "0",
    "--no-progress",
]  # fmt: skip


def _files(folder: Path) -> dict[Path, bytes]:
    """Every file below ``folder`` with its bytes: what a refused command must not change."""
    return {p: p.read_bytes() for p in folder.rglob("*") if p.is_file()}


@pytest.mark.parametrize(
    ("text", "seeds"),
    [("0-4", (0, 1, 2, 3, 4)), ("3", (3,)), ("0,2,7", (0, 2, 7)), ("0-1,5", (0, 1, 5))],
)
def test_seeds_are_read_as_lists_and_ranges(text: str, seeds: tuple[int, ...]) -> None:
    assert parse_seeds(text) == seeds


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--seeds", "4-2"], "counts down"),
        (["--seeds", "1,1"], "names a seed twice"),
        (["--seeds", "0-99"], "training seeds are 0..40"),
        # refused before the range is built (a billion seeds once filled the memory)
        (["--seeds", "0-1000000000000"], "training seeds are 0..40"),
        (["--seeds", "x"], "is not a seed or a range"),
        # digits of other scripts: int() read "٣" as seed 3 and refused "²" naming no option
        (["--seeds", "\u0663"], "is not a seed or a range"),
        (["--seeds", "0-\u00b2"], "is not a seed or a range"),
        (["--workers", "2"], "--workers applies to --seeds only"),
        (["--seeds", "0-1", "--resume", "runs/x"], "--resume takes one run, not a study"),
        (["--seeds", "0-1", "--workers", "0"], "argument --workers: 0 is out of range"),
    ],
)
def test_bad_study_options_give_one_line_and_status_2(
    argv: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main([*argv, "--out", str(tmp_path / "study")]) == 2
    err = capsys.readouterr().err
    assert message in err
    assert err.count("\n") == 1
    assert not (tmp_path / "study").exists()


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("seeds") / "study"
    assert main([*TINY, "--seeds", "0-1", "--out", str(out)]) == 0
    # as first trained (a later test resumes seed 1, which changes its agent)
    shutil.copy(out / "seeds.csv", out.parent / "first-seeds.csv")
    return out


def test_each_seed_is_a_run_of_its_own_seeds(study: Path) -> None:
    seeds = [yaml.safe_load((study / f"seed-{k}" / "config.yaml").read_text()) for k in (0, 1)]
    assert [s["args"]["seed"] for s in seeds] == [10_000, 10_000 + SEED_STRIDE]
    # judged on the same held-out episodes
    assert seeds[0]["args"]["eval_seed"] == seeds[1]["args"]["eval_seed"]
    for k in (0, 1):
        assert (study / f"seed-{k}" / "model.zip").is_file()


def test_the_summary_has_a_row_per_seed_and_the_statistics_across(study: Path) -> None:
    rows = pd.read_csv(study / "seeds.csv")
    assert rows["seed"].tolist() == [0, 1]
    assert rows["env_steps"].tolist() == [768, 768]  # 600 rounded up to whole rollouts of 256
    assert rows["heldout_return"].notna().all()
    summary = json.loads((study / "summary.json").read_text())
    assert summary["seeds"] == 2
    assert summary["heldout_return_mean"] == pytest.approx(rows["heldout_return"].mean(), abs=1e-3)
    assert "IQM" in (study / "summary.md").read_text()


def test_the_study_is_one_agent_the_mean_of_its_seeds(study: Path) -> None:
    assert yaml.safe_load((study / "ensemble.yaml").read_text()) == {
        "members": ["seed-0", "seed-1"]
    }
    policy = make_policy(str(study))
    assert isinstance(policy, EnsemblePolicy)
    obs = np.array([1.3, 40.0], np.float32)
    alone = [PPOPolicy(study / f"seed-{k}").act(obs) for k in (0, 1)]
    np.testing.assert_allclose(policy.act(obs), (alone[0] + alone[1]) / 2, rtol=0, atol=1e-6)


def test_a_finished_seed_with_a_damaged_log_is_named_before_anything_trains(
    study: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    copy = tmp_path / "study"
    shutil.copytree(study, copy)
    log = copy / "seed-1" / "evaluations.npz"
    log.write_bytes(log.read_bytes()[:100])  # truncated, as by a full disk
    before = _files(copy)
    assert main([*TINY, "--seeds", "0-1", "--out", str(copy)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"follow-train: error: {log}: not a readable held-out evaluation log")
    assert err.count("\n") == 1, err
    assert _files(copy) == before


def test_an_interrupted_seed_that_cannot_resume_is_named_before_any_seed_trains(
    study: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Seed 1 as a kill leaves it (checkpoints, no final model) but with a damaged log; seed 2
    # is new and comes first on the command line, so it would train before seed 1 failed.
    copy = tmp_path / "study"
    shutil.copytree(study, copy)
    seed1 = copy / "seed-1"
    (seed1 / "model.zip").unlink()
    log = seed1 / "evaluations.npz"
    log.write_bytes(b"PK\x03\x04")
    assert main([*TINY, "--seeds", "2,1", "--out", str(copy)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"follow-train: error: {log}: not a readable held-out evaluation log")
    assert not (copy / "seed-2").exists()


def _copy(study: Path, tmp_path: Path) -> tuple[Path, dict[Path, bytes]]:
    copy = tmp_path / "study"
    shutil.copytree(study, copy)
    return copy, _files(copy)


def _error(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err
    assert err.startswith("follow-train: error: "), err
    assert err.count("\n") == 1, err
    return err


def test_new_seeds_with_other_hyperparameters_are_refused(
    study: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # The file's path is the study's, its contents were edited: once, seed 2 trained with the
    # new values and the summary averaged it with seeds 0 and 1.
    copy, before = _copy(study, tmp_path)
    document = yaml.safe_load(DEFAULT_HYPERPARAMS.read_text())
    document[ENV_ID]["gamma"] = 0.5
    hp = tmp_path / "ppo.yaml"
    hp.write_text(yaml.safe_dump(document))
    config = copy / "seed-0" / "config.yaml"
    saved = yaml.safe_load(config.read_text())
    saved["args"]["hyperparams"] = str(hp)  # as if the study had been made with this file
    config.write_text(yaml.safe_dump(saved))
    before[config] = config.read_bytes()
    argv = [*TINY, "--hyperparams", str(hp), "--seeds", "0,2", "--out", str(copy)]
    assert main(argv) == 2
    assert "trained with gamma=" in _error(capsys)
    assert _files(copy) == before


def test_new_seeds_after_a_step_was_added_to_the_study_are_refused(
    study: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # The new seeds would not have the step: the ensemble of all of them would not load.
    copy, _ = _copy(study, tmp_path)
    step = "{train.wrappers.VecJumpGate: {max_jump_m: 0.5}}"
    assert main(["--add-step", str(copy), "--step", step]) == 0
    capsys.readouterr()
    before = _files(copy)
    assert main([*TINY, "--seeds", "0-2", "--out", str(copy)]) == 2
    assert "trained with vec_env_wrapper=" in _error(capsys)
    assert _files(copy) == before


def test_a_longer_budget_resumes_the_finished_seeds_and_a_shorter_is_refused(
    study: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    copy, _ = _copy(study, tmp_path)
    shorter = [a if a != "600" else "300" for a in TINY]
    assert main([*shorter, "--seeds", "0-1", "--out", str(copy)]) == 2
    assert "seed 0 in " in _error(capsys)
    longer = [a if a != "600" else "1200" for a in TINY]
    assert main([*longer, "--seeds", "0-1", "--out", str(copy)]) == 0
    rows = pd.read_csv(copy / "seeds.csv")
    assert (rows["env_steps"] >= 1200).all(), rows
    for k in (0, 1):
        sessions = json.loads((copy / f"seed-{k}" / "sessions.json").read_text())
        assert [s["status"] for s in sessions] == ["finished", "finished"]


def test_a_command_for_some_seeds_keeps_the_summary_and_ensemble_of_all(
    study: Path, tmp_path: Path
) -> None:
    # Once, --seeds 0 on a study of seeds 0 and 1 rewrote seeds.csv with seed 0 alone while
    # ensemble.yaml still listed both.
    copy, _ = _copy(study, tmp_path)
    assert main([*TINY, "--seeds", "0", "--out", str(copy)]) == 0
    assert pd.read_csv(copy / "seeds.csv")["seed"].tolist() == [0, 1]
    assert yaml.safe_load((copy / "ensemble.yaml").read_text())["members"] == ["seed-0", "seed-1"]


def test_new_seeds_alone_are_checked_against_the_studys_others(
    study: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    copy, _ = _copy(study, tmp_path)
    longer = [a if a != "600" else "1200" for a in TINY]
    assert main([*longer, "--seeds", "2", "--out", str(copy)]) == 2
    assert "seed 0 of the study" in _error(capsys)
    assert not (copy / "seed-2").exists()


def test_the_env_id_given_or_filled_in_is_the_same_study(
    study: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    copy, _ = _copy(study, tmp_path)
    assert main([*TINY, "--env-id", ENV_ID, "--seeds", "0-1", "--out", str(copy)]) == 0
    # a study.json written before the default was filled in holds none
    settings = json.loads((copy / "study.json").read_text())
    (copy / "study.json").write_text(json.dumps({**settings, "env_id": None}))
    assert main([*TINY, "--env-id", ENV_ID, "--seeds", "0-1", "--out", str(copy)]) == 0
    assert main([*TINY, "--seeds", "0-1", "--out", str(copy)]) == 0
    capsys.readouterr()


def test_an_unreachable_ray_cluster_leaves_no_study(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "study"
    argv = [*TINY, "--seeds", "0-1", "--backend", "ray", "--address", "127.0.0.1:1"]
    assert main([*argv, "--out", str(out)]) == 2
    assert "127.0.0.1:1" in _error(capsys)
    assert not out.exists()


@pytest.mark.parametrize("text", ["[]", '"a study"', '{"seeds": 5}', "{"])
def test_a_damaged_study_file_is_named_in_one_line(
    study: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str
) -> None:
    copy, _ = _copy(study, tmp_path)
    (copy / "study.json").write_text(text)
    assert main([*TINY, "--seeds", "0-1", "--out", str(copy)]) == 2
    assert f"{copy / 'study.json'}: not a" in _error(capsys)


def test_the_same_command_skips_finished_seeds_and_more_seeds_extend_the_study(study: Path) -> None:
    before = (study / "seed-0" / "sessions.json").read_text()
    assert main([*TINY, "--seeds", "0-2", "--out", str(study)]) == 0
    assert (study / "seed-0" / "sessions.json").read_text() == before  # not trained again
    assert pd.read_csv(study / "seeds.csv")["seed"].tolist() == [0, 1, 2]
    assert json.loads((study / "study.json").read_text())["seeds"] == [0, 1, 2]
    assert yaml.safe_load((study / "ensemble.yaml").read_text())["members"] == [
        "seed-0",
        "seed-1",
        "seed-2",
    ]


def test_an_interrupted_seed_resumes_from_its_checkpoint(study: Path) -> None:
    run = study / "seed-1"
    sessions = json.loads((run / "sessions.json").read_text())
    kept = sorted((run / "checkpoints").glob("ppo_*_steps.zip"))
    first = int(kept[0].stem.split("_")[1])
    for late in kept[1:]:
        late.unlink()
    sessions[-1] |= {"status": "interrupted", "last_step": first}
    (run / "sessions.json").write_text(json.dumps(sessions))
    (run / "model.zip").unlink()
    assert main([*TINY, "--seeds", "0-1", "--out", str(study)]) == 0
    sessions = json.loads((run / "sessions.json").read_text())
    assert sessions[-1]["status"] == "finished"
    assert sessions[-1]["first_step"] == first


def test_another_study_in_the_same_folder_is_refused(
    study: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main([*TINY, "--seeds", "0", "--eval-seed", "7", "--out", str(study)]) == 2
    assert "holds another study" in capsys.readouterr().err


@pytest.mark.slow
def test_ray_trains_the_same_agents_as_one_after_another(
    study: Path, local_ray, tmp_path: Path
) -> None:
    out = tmp_path / "ray"
    assert main([*TINY, "--seeds", "0-1", "--out", str(out), "--backend", "ray"]) == 0
    local = pd.read_csv(study.parent / "first-seeds.csv").set_index("seed")["heldout_return"]
    ray = pd.read_csv(out / "seeds.csv").set_index("seed")["heldout_return"]
    assert ray.tolist() == local.tolist()


def test_a_study_is_exported_as_one_agent_and_again_over_its_export(
    study: Path, tmp_path: Path
) -> None:
    dest = tmp_path / "agents" / "pair"
    # the seeds are finished, so the same command trains nothing and exports them
    assert main([*TINY, "--seeds", "0-1", "--out", str(study), "--export", str(dest)]) == 0
    assert yaml.safe_load((dest / "ensemble.yaml").read_text()) == {"members": ["seed-0", "seed-1"]}
    for k in (0, 1):
        exported, run = dest / f"seed-{k}", study / f"seed-{k}"
        assert (exported / "model.zip").read_bytes() == (run / "model.zip").read_bytes()
        assert (exported / "follow-train-export.json").is_file()
    assert sorted(p.name for p in dest.parent.iterdir()) == ["pair"]  # no temporary left
    pair = make_policy(str(dest))
    assert isinstance(pair, EnsemblePolicy)
    obs = np.array([1.3, 40.0], np.float32)
    alone = [PPOPolicy(dest / f"seed-{k}").act(obs) for k in (0, 1)]
    np.testing.assert_allclose(pair.act(obs), (alone[0] + alone[1]) / 2, rtol=0, atol=1e-6)
    # an earlier export is written over, member by member
    (dest / "notes.txt").write_text("kept")
    assert main([*TINY, "--seeds", "0-1", "--out", str(study), "--export", str(dest)]) == 0
    assert (dest / "notes.txt").read_text() == "kept"
    assert isinstance(make_policy(str(dest)), EnsemblePolicy)


def test_one_seed_is_exported_as_one_agent(study: Path, tmp_path: Path) -> None:
    dest = tmp_path / "one"
    assert main([*TINY, "--seeds", "0", "--out", str(study), "--export", str(dest)]) == 0
    assert not (dest / "ensemble.yaml").exists()
    assert (dest / "model.zip").read_bytes() == (study / "seed-0" / "model.zip").read_bytes()


@pytest.mark.parametrize(
    ("where", "message"),
    [
        ("other", "holds no study's export (no ensemble.yaml)"),
        ("inside", "lies in the study folder"),
    ],
)
def test_a_study_export_that_would_lose_a_file_is_refused_before_training(
    where: str, message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "study"
    dest = out / "export" if where == "inside" else tmp_path / "other"
    if where == "other":
        dest.mkdir()
        (dest / "mine.txt").write_text("mine")
    assert main([*TINY, "--seeds", "0-1", "--out", str(out), "--export", str(dest)]) == 2
    err = capsys.readouterr().err
    assert message in err
    assert err.count("\n") == 1
    assert not out.exists()  # nothing trained
    if where == "other":
        assert sorted(p.name for p in dest.iterdir()) == ["mine.txt"]


def test_force_without_export_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main([*TINY, "--seeds", "0-1", "--out", str(tmp_path / "s"), "--force"]) == 2
    assert "--force applies to --export only" in capsys.readouterr().err
    assert not (tmp_path / "s").exists()


class _OneSecond(datetime):
    """Every ``now()`` in the same second: two commands started together."""

    @classmethod
    def now(cls, tz: tzinfo | None = None) -> _OneSecond:
        return cls(2031, 2, 3, 4, 5, 6, tzinfo=tz)


def test_two_studies_named_in_the_same_second_get_two_folders(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The first free name was picked and made only after the checks: two commands started in
    one second took the same folder, and the second was refused by the first's lock."""
    monkeypatch.setattr("train.run.datetime", _OneSecond)
    runs, stamp = tmp_path / "runs", "ppo-seeds-20310203-040506"
    first, second = _new_study_path(runs, "ppo"), _new_study_path(runs, "ppo")
    assert (first.name, second.name) == (stamp, f"{stamp}-1")
    # each made when named: a third command, in the same second, takes neither
    assert first.is_dir()
    assert second.is_dir()
    assert _new_study_path(runs, None).name == f"{stamp}-2"


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--eval-episodes", "0"], "--eval-episodes 0 is out of range"),  # a seed's options
        (["--export", "{runs}"], "is, holds or lies in the study folder"),  # checked after them
    ],
)
@pytest.mark.parametrize("runs_existed", [False, True])
def test_a_refused_study_without_out_leaves_no_folder(
    argv: list[str],
    message: str,
    runs_existed: bool,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """The study's folder is made when named (before the checks): taken back while empty, with
    the --runs folder if the command made it."""
    runs = tmp_path / "runs"
    if runs_existed:
        (runs / "ppo-old").mkdir(parents=True)
    argv = [arg.format(runs=runs) for arg in argv]
    assert main([*TINY, "--seeds", "0-1", "--runs", str(runs), *argv]) == 2
    assert message in _error(capsys)
    left = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*"))
    assert left == (["runs", "runs/ppo-old"] if runs_existed else [])


@pytest.mark.parametrize("below", ["", "sub"])
def test_runs_that_is_a_file_is_refused_in_one_line_before_a_study_folder_is_made(
    below: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    afile = tmp_path / "afile"
    afile.write_text("mine\n")
    runs = afile / below if below else afile
    assert main([*TINY, "--seeds", "0-1", "--runs", str(runs)]) == 2  # was a traceback
    where = "is a file" if not below else f"runs through the file {afile}"
    assert f"--runs {runs}: {where}, not a folder" in _error(capsys)
    assert afile.read_text() == "mine\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]


def test_a_new_study_trains_then_exports_its_seeds_together(tmp_path: Path) -> None:
    out, dest = tmp_path / "study", tmp_path / "pair"
    assert main([*TINY, "--seeds", "0-1", "--out", str(out), "--export", str(dest)]) == 0
    # the seeds' runs export nothing of their own: the study's export is the whole of dest
    assert sorted(p.name for p in dest.iterdir()) == ["ensemble.yaml", "seed-0", "seed-1"]
    assert isinstance(make_policy(str(dest)), EnsemblePolicy)


def test_an_export_folder_filled_during_training_keeps_the_study(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import train.seeds

    out, dest = tmp_path / "study", tmp_path / "pair"
    trained = train.seeds.execute

    def and_then_a_file_in_the_way(*args, **kwargs):
        rows = trained(*args, **kwargs)
        dest.mkdir()
        (dest / "mine.txt").write_text("mine")
        return rows

    monkeypatch.setattr(train.seeds, "execute", and_then_a_file_in_the_way)
    assert main([*TINY, "--seeds", "0-1", "--out", str(out), "--export", str(dest)]) == 2
    err = capsys.readouterr().err
    assert f"training finished: the study is complete in {out}" in err
    assert err.count("\n") == 1
    assert sorted(p.name for p in dest.iterdir()) == ["mine.txt"]
    assert isinstance(make_policy(str(out)), EnsemblePolicy)
