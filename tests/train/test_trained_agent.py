"""train/trained_agent.py: ``follow-train --trained-agent`` starts a new run from an agent."""

from __future__ import annotations

import json
import pickle
import shutil
from pathlib import Path
from types import SimpleNamespace

import pytest
import torch
import yaml
from gymnasium.spaces import Box
from stable_baselines3.common.save_util import load_from_zip_file
from stable_baselines3.common.vec_env import VecNormalize

import train.ppo
from follow_env.tasks.person_follow import ENV_ID
from train.cli import main
from train.options import Args
from train.ppo import DEFAULT_HYPERPARAMS
from train.study_record import study_settings
from train.trained_agent import check_spaces, check_task, read_trained_agent

# Two scenarios, 4 lanes, tiny intervals: a few seconds a run.
TINY = [
    "--n-envs", "4",
    "--eval-freq", "800",
    "--checkpoint-freq", "800",
    "--final-episodes", "0",
    "--no-progress",
]  # fmt: skip


@pytest.fixture(scope="module")
def agent(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny trained agent, exported (as users' agents are)."""
    root = tmp_path_factory.mktemp("trained")
    argv = [*TINY, "--scenarios", "straight,curve", "--n-timesteps", "1000"]
    assert main([*argv, "--out", str(root / "run"), "--export", str(root / "agent")]) == 0
    return root / "agent"


def _error(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err
    assert err.startswith("follow-train: error: "), err
    assert err.count("\n") == 1, err
    return err


def _stats(path: Path) -> VecNormalize:
    with path.open("rb") as f:
        stats = pickle.load(f)
    assert isinstance(stats, VecNormalize)
    return stats


@pytest.mark.slow
def test_the_run_starts_from_the_agents_weights_and_statistics(
    agent: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    loaded: dict[str, torch.Tensor] = {}
    real = train.ppo.start_from

    def spy(model, trained):  # the new model's weights once the agent's are in
        steps = real(model, trained)
        loaded.update({k: v.clone() for k, v in model.policy.state_dict().items()})
        return steps

    monkeypatch.setattr(train.ppo, "start_from", spy)
    run = tmp_path / "on"
    argv = ["--trained-agent", str(agent), *TINY, "--n-timesteps", "512", "--seed", "77"]
    assert main([*argv, "--out", str(run)]) == 0
    _, params, _ = load_from_zip_file(agent / "model.zip", device="cpu")
    saved = params["policy"]
    assert loaded.keys() == saved.keys()
    for key, value in saved.items():
        assert torch.equal(loaded[key], value), key
    # The optimiser went on from the agent's too (Adam's step count carries on).
    mine = load_from_zip_file(run / "model.zip", device="cpu")[1]["policy.optimizer"]
    theirs = params["policy.optimizer"]
    assert mine["state"][0]["step"] > theirs["state"][0]["step"]
    # ... and the reward normalisation from its statistics: their counts add up.
    before, after = _stats(agent / "vecnormalize.pkl"), _stats(run / "vecnormalize.pkl")
    assert after.ret_rms.count == pytest.approx(before.ret_rms.count + 512)
    # Without --hyperparams: the agent's own, on its scenarios, with its algorithm.
    config = yaml.safe_load((run / "config.yaml").read_text())
    own = yaml.safe_load((agent / "config.yaml").read_text())
    assert config["args"]["scenarios"] == ["straight", "curve"]
    assert config["args"]["hyperparams"] is None
    assert config["args"]["trained_agent"] == str(agent)
    assert config["args"]["seed"] == 77
    expected = {**own["hyperparams"], "n_timesteps": 512, "n_envs": 4}
    assert config["hyperparams"] == expected
    record = config["trained_agent"]
    assert (record["path"], record["algo"], record["steps"]) == (str(agent), "ppo", 1024)
    assert set(record["sha256"]) == {"model.zip", "vecnormalize.pkl"}
    card = (run / "MODEL_CARD.md").read_text()
    assert f"- started from the weights and normalisation of `{agent}` (ppo, 1,024" in card
    assert record["sha256"]["model.zip"][:12] in card


@pytest.mark.slow
def test_a_run_from_an_agent_resumes_as_any_run(agent: Path, tmp_path: Path) -> None:
    run = tmp_path / "on"
    argv = ["--trained-agent", str(agent), *TINY, "--n-timesteps", "900"]
    assert main([*argv, "--out", str(run)]) == 0
    record = yaml.safe_load((run / "config.yaml").read_text())["trained_agent"]
    assert main(["--resume", str(run), "--n-timesteps", "1700", "--no-progress"]) == 0
    sessions = json.loads((run / "sessions.json").read_text())
    assert [s["first_step"] for s in sessions] == [0, 1024]  # its final checkpoint: 4 x 256
    config = yaml.safe_load((run / "config.yaml").read_text())
    assert config["trained_agent"] == record  # the start is still on record


@pytest.mark.slow
def test_a_study_from_an_ensemble_starts_each_seed_from_its_member(
    agent: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    ensemble = tmp_path / "pair"
    for k in (0, 1):
        shutil.copytree(agent, ensemble / f"seed-{k}")
    # One member differs, so that which member a seed started from shows.
    shutil.copy(agent.parent / "run" / "checkpoints" / "ppo_800_steps.zip",
                ensemble / "seed-1" / "model.zip")  # fmt: skip
    (ensemble / "ensemble.yaml").write_text("{members: [seed-0, seed-1]}\n")
    study = tmp_path / "study"
    argv = ["--trained-agent", str(ensemble), *TINY, "--n-timesteps", "256", "--seeds", "0-1"]
    assert main([*argv, "--out", str(study)]) == 0
    for k, steps in ((0, 1024), (1, 800)):
        record = yaml.safe_load((study / f"seed-{k}" / "config.yaml").read_text())
        assert record["trained_agent"]["path"] == str(ensemble / f"seed-{k}")
        assert record["trained_agent"]["steps"] == steps
    settings = json.loads((study / "study.json").read_text())
    assert settings["trained_agent"] == str(ensemble)
    assert settings["hyperparams"] is None
    capsys.readouterr()
    # A seed the ensemble has no member for is named before any seed trains.
    assert main([*argv[:-1], "0,5", "--out", str(tmp_path / "other")]) == 2
    err = _error(capsys)
    assert "the ensemble has no member seed-5 for training seed 5" in err
    assert not (tmp_path / "other").exists()


def _section(tmp_path: Path, **changes: object) -> Path:
    """The shipped PPO file with the tiny agent's lanes and ``changes``."""
    document = yaml.safe_load(DEFAULT_HYPERPARAMS.read_text())
    document[ENV_ID].update(changes)
    path = tmp_path / "hp.yaml"
    path.write_text(yaml.safe_dump(document))
    return path


def test_a_file_with_the_agents_network_may_change_the_rest(agent: Path, tmp_path: Path) -> None:
    hp = _section(tmp_path, learning_rate=1e-4, gamma=0.95, policy_kwargs={
        "net_arch": [64, 64], "log_std_init": -0.5,  # the initial log std: the agent's wins
        "mirror_obs": [1, -1, 1, 1, -1], "mirror_action": [1, -1],
    })  # fmt: skip
    run = tmp_path / "on"
    argv = ["--trained-agent", str(agent), "--hyperparams", str(hp), *TINY]
    assert main([*argv, "--n-timesteps", "256", "--out", str(run)]) == 0
    config = yaml.safe_load((run / "config.yaml").read_text())
    assert config["hyperparams"]["learning_rate"] == 1e-4
    # The statistics go on from the agent's, discounted with this run's gamma (not its 0.99).
    assert _stats(agent / "vecnormalize.pkl").gamma == 0.99
    assert _stats(run / "vecnormalize.pkl").gamma == 0.95
    assert config["args"]["scenarios"] == ["straight", "curve"]  # the agent's, as without one
    assert config["args"]["hyperparams"] == str(hp)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"policy_kwargs": {"net_arch": [32, 32]}}, "policy_kwargs={'net_arch': [32, 32]}, but"),
        ({"frame_stack": 2}, "frame_stack=2, but --trained-agent"),
        ({"normalize": False}, "normalize=False, but --trained-agent"),
        (
            {"policy": "MlpPolicy", "policy_kwargs": {"net_arch": [64, 64]}},
            "policy='MlpPolicy', but --trained-agent",
        ),
    ],
)
def test_a_file_the_weights_cannot_follow_is_refused(
    agent: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], changes: dict, message: str
) -> None:
    hp = _section(tmp_path, **changes)
    out = tmp_path / "out"
    argv = ["--trained-agent", str(agent), "--hyperparams", str(hp), *TINY, "--out", str(out)]
    assert main(argv) == 2
    err = _error(capsys)
    assert message in err
    assert "its weights and statistics fit its own" in err
    assert not out.exists()


def test_bad_agents_and_options_are_one_line_and_write_nothing(
    agent: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    empty = tmp_path / "empty"
    empty.mkdir()
    pair = tmp_path / "pair"
    pair.mkdir()
    (pair / "ensemble.yaml").write_text("{members: [a, b]}\n")
    cases = [
        (["--trained-agent", str(tmp_path / "none"), *TINY], "no such agent"),
        (["--trained-agent", str(empty), *TINY], f"--trained-agent {empty}: no model.zip in it"),
        (["--trained-agent", str(pair), *TINY], "an ensemble; name one member"),
        (["--trained-agent", str(agent), "--algo", "sac"], "is a ppo agent; its weights fit"),
        (["--trained-agent", str(agent), "--resume", str(agent)], "--trained-agent: a resumed"),
    ]
    for argv, message in cases:
        assert main([*argv, "--out", str(out)]) == 2, argv
        assert message in _error(capsys), argv
        assert not out.exists()
    broken = tmp_path / "broken"
    shutil.copytree(agent, broken)
    (broken / "model.zip").write_bytes(b"not a zip")
    assert main(["--trained-agent", str(broken), *TINY, "--out", str(out)]) == 2
    assert f"{broken / 'model.zip'}: not a readable model" in _error(capsys)
    assert not out.exists()
    (broken / "vecnormalize.pkl").unlink()
    shutil.copy(agent / "model.zip", broken / "model.zip")
    assert main(["--trained-agent", str(broken), *TINY, "--out", str(out)]) == 2
    assert "no vecnormalize.pkl beside model.zip" in _error(capsys)


@pytest.mark.slow
def test_sacs_entropy_coefficient_carries_over(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from stable_baselines3 import SAC

    argv = [*TINY, "--scenarios", "straight", "--n-timesteps", "300"]
    assert main(["--algo", "sac", *argv, "--out", str(tmp_path / "sac")]) == 0
    saved = SAC.load(tmp_path / "sac" / "model.zip", device="cpu")
    saved.log_ent_coef.data.fill_(0.123)  # not a new model's, so that its arrival shows
    saved.save(tmp_path / "sac" / "model.zip")
    seen: list[float] = []
    real = train.ppo.start_from

    def spy(model, trained):
        steps = real(model, trained)
        seen.append(float(model.log_ent_coef.detach()))
        return steps

    monkeypatch.setattr(train.ppo, "start_from", spy)
    on = ["--trained-agent", str(tmp_path / "sac"), *argv]
    assert main([*on, "--out", str(tmp_path / "on")]) == 0
    assert seen == [pytest.approx(0.123)]


def test_an_agent_of_another_task_is_refused(agent: Path) -> None:
    with pytest.raises(ValueError, match="a PersonFollow-v0 agent; this run trains on LineTrace"):
        check_task(read_trained_agent(agent), "LineTrace-v0")


def test_an_agent_of_another_view_is_refused_by_its_shapes(agent: Path) -> None:
    trained = read_trained_agent(agent)
    fits = SimpleNamespace(observation_space=Box(-1, 1, (20,)), action_space=Box(-1, 1, (2,)))
    check_spaces(trained, fits)  # the agent's own: 4 frames of 5 numbers, 2 actions
    wider = SimpleNamespace(observation_space=Box(-1, 1, (24,)), action_space=Box(-1, 1, (2,)))
    with pytest.raises(ValueError, match=r"observations of shape \[20\], this run's view gives"):
        check_spaces(trained, wider)
    three = SimpleNamespace(observation_space=Box(-1, 1, (20,)), action_space=Box(-1, 1, (3,)))
    with pytest.raises(ValueError, match="acts with 2 numbers, this run's env takes 3"):
        check_spaces(trained, three)


def test_a_study_from_an_agent_records_no_hyperparameter_file() -> None:
    own = study_settings(Args(trained_agent=Path("/a"), algo="ppo", env_id=ENV_ID), [0])
    assert own["hyperparams"] is None
    assert own["trained_agent"] == "/a"
    given = study_settings(Args(trained_agent=Path("/a"), hyperparams=Path("/h.yaml")), [0])
    assert given["hyperparams"] == "/h.yaml"
