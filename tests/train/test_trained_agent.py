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
from train.algos import ALGOS
from train.cli import main
from train.options import Args
from train.ppo import DEFAULT_HYPERPARAMS
from train.study_record import study_settings
from train.trained_agent import check_base, check_spaces, check_task, read_trained_agent

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
    """A tiny trained agent, exported (as users' agents are), on the ``noisy`` preset."""
    root = tmp_path_factory.mktemp("trained")
    argv = [*TINY, "--scenarios", "straight,curve", "--n-timesteps", "1000"]
    argv += ["--env-config", "noisy"]
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

    def spy(model, trained) -> None:  # the new model's weights once the agent's are in
        real(model, trained)
        loaded.update({k: v.clone() for k, v in model.policy.state_dict().items()})

    monkeypatch.setattr(train.ppo, "start_from", spy)
    run = tmp_path / "on"
    argv = ["--trained-agent", str(agent), *TINY, "--n-timesteps", "512", "--seed", "77"]
    assert main([*argv, "--out", str(run)]) == 0
    _, params, _ = load_from_zip_file(agent / "model.zip", device="cpu")
    saved = params["policy"]
    assert loaded.keys() == saved.keys()
    for key, value in saved.items():
        assert torch.equal(loaded[key], value), key
    # The optimiser went on from the agent's too: Adam's step count carries on, by this run's
    # updates (n_epochs a rollout of n_steps x 4 lanes, one mini-batch each).
    hp = yaml.safe_load((agent / "config.yaml").read_text())["hyperparams"]
    rollout = hp["n_steps"] * 4
    assert hp["batch_size"] == rollout
    mine = load_from_zip_file(run / "model.zip", device="cpu")[1]["policy.optimizer"]
    theirs = params["policy.optimizer"]["state"][0]["step"]
    assert mine["state"][0]["step"] == theirs + hp["n_epochs"] * (512 // rollout)
    # ... and the reward normalisation from its statistics: their counts add up.
    before, after = _stats(agent / "vecnormalize.pkl"), _stats(run / "vecnormalize.pkl")
    assert after.ret_rms.count == pytest.approx(before.ret_rms.count + 512)
    # Without --hyperparams: the agent's own, on its scenarios, with its algorithm.
    config = yaml.safe_load((run / "config.yaml").read_text())
    own = yaml.safe_load((agent / "config.yaml").read_text())
    assert config["args"]["scenarios"] == ["straight", "curve"]
    assert config["args"]["env_config"] == "noisy"
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
    assert "env preset `noisy`" in card
    assert record["sha256"]["model.zip"][:12] in card


@pytest.mark.slow
def test_a_run_from_an_agent_resumes_as_any_run(agent: Path, tmp_path: Path) -> None:
    run = tmp_path / "on"
    argv = ["--trained-agent", str(agent), *TINY, "--n-timesteps", "900"]
    assert main([*argv, "--out", str(run)]) == 0
    started = yaml.safe_load((run / "config.yaml").read_text())
    record = started["trained_agent"]
    # Its lanes go on where a resume of the agent's own training would: seed + its steps.
    assert started["args"]["seed"] == 10_000 + 1024
    assert main(["--resume", str(run), "--n-timesteps", "1700", "--no-progress"]) == 0
    sessions = json.loads((run / "sessions.json").read_text())
    assert [s["first_step"] for s in sessions] == [0, 1024]  # its final checkpoint: 4 x 256
    config = yaml.safe_load((run / "config.yaml").read_text())
    assert config["trained_agent"] == record  # the start is still on record


def _pair(agent: Path, folder: Path) -> Path:
    """An ensemble of two copies of ``agent`` in ``folder``, as a study's export names them
    and seeds them (member k from the agent's seed + k * 10**8)."""
    for k in (0, 1):
        shutil.copytree(agent, folder / f"seed-{k}")
        config = folder / f"seed-{k}" / "config.yaml"
        saved = yaml.safe_load(config.read_text())
        saved["args"]["seed"] += k * 10**8
        config.write_text(yaml.safe_dump(saved))
    (folder / "ensemble.yaml").write_text("{members: [seed-0, seed-1]}\n")
    return folder


@pytest.mark.slow
def test_a_study_from_an_ensemble_starts_each_seed_from_its_member(
    agent: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    ensemble = _pair(agent, tmp_path / "pair")
    # One member differs, so that which member a seed started from shows.
    shutil.copy(agent.parent / "run" / "checkpoints" / "ppo_800_steps.zip",
                ensemble / "seed-1" / "model.zip")  # fmt: skip
    study = tmp_path / "study"
    argv = ["--trained-agent", str(ensemble), *TINY, "--n-timesteps", "256", "--seeds", "0-1"]
    # Seed 1 first, then both: whichever seeds a command lists, seed k's lanes are its own.
    assert main([*argv[:-1], "1", "--out", str(study)]) == 0
    assert main([*argv, "--out", str(study)]) == 0
    for k, steps in ((0, 1024), (1, 800)):
        record = yaml.safe_load((study / f"seed-{k}" / "config.yaml").read_text())
        assert record["trained_agent"]["path"] == str(ensemble / f"seed-{k}")
        assert record["trained_agent"]["steps"] == steps
        # where its member's training stopped: its seed (10000 + k * 10**8) + its steps
        assert record["args"]["seed"] == 10_000 + k * 10**8 + steps
    settings = json.loads((study / "study.json").read_text())
    assert settings["trained_agent"] == str(ensemble)
    assert settings["hyperparams"] is None
    assert settings["seed"] is None  # each seed's own, from its member
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


def _sac_file(tmp_path: Path, name: str, **changes: object) -> Path:
    """The shipped SAC file with ``changes`` (None removes a key)."""
    document = yaml.safe_load(ALGOS["sac"].hyperparams.read_text())
    section = document[ENV_ID]
    section.update(changes)
    document[ENV_ID] = {k: v for k, v in section.items() if v is not None}
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(document))
    return path


@pytest.mark.slow
def test_a_fixed_entropy_coefficient_is_the_files_and_a_change_of_kind_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from stable_baselines3 import SAC

    argv = [*TINY, "--scenarios", "straight", "--n-timesteps", "300"]
    fixed = _sac_file(tmp_path, "fixed", ent_coef=0.1, target_entropy=None)
    first = ["--algo", "sac", "--hyperparams", str(fixed), *argv, "--out", str(tmp_path / "a")]
    assert main(first) == 0
    other = _sac_file(tmp_path, "other", ent_coef=0.05, target_entropy=None)
    on = ["--trained-agent", str(tmp_path / "a"), *argv]
    assert main([*on, "--hyperparams", str(other), "--out", str(tmp_path / "on")]) == 0
    model = SAC.load(tmp_path / "on" / "model.zip", device="cpu")
    assert float(model.ent_coef_tensor) == pytest.approx(0.05)  # as config.yaml says
    config = yaml.safe_load((tmp_path / "on" / "config.yaml").read_text())
    assert config["hyperparams"]["ent_coef"] == 0.05
    capsys.readouterr()
    learned = ALGOS["sac"].hyperparams
    out = tmp_path / "refused"
    assert main([*on, "--hyperparams", str(learned), "--out", str(out)]) == 2
    err = _error(capsys)
    assert "ent_coef='auto' (learned), but --trained-agent" in err
    assert "learned with ent_coef=0.1 (fixed): give a fixed one" in err
    assert not out.exists()


def test_an_agent_of_another_task_is_refused(
    agent: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(ValueError, match="a PersonFollow-v0 agent; this run trains on LineTrace"):
        check_task(read_trained_agent(agent), "LineTrace-v0")
    # Through the command line, before the agent's scenarios are checked against the task's.
    out = tmp_path / "out"
    argv = ["--trained-agent", str(agent), "--env-id", "LineTrace-v0", "--env-config", "paper"]
    assert main([*argv, *TINY, "--out", str(out)]) == 2
    assert "a PersonFollow-v0 agent; this run trains on LineTrace-v0" in _error(capsys)
    assert not out.exists()


@pytest.mark.slow
def test_a_study_refuses_a_new_seed_from_an_agent_changed_since(
    agent: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mine = tmp_path / "agent"
    shutil.copytree(agent, mine)
    study = tmp_path / "study"
    argv = ["--trained-agent", str(mine), *TINY, "--n-timesteps", "256", "--out", str(study)]
    assert main([*argv, "--seeds", "0"]) == 0
    shutil.copy(agent.parent / "run" / "checkpoints" / "ppo_800_steps.zip", mine / "model.zip")
    assert main([*argv, "--seeds", "0"]) == 0  # the study as it was: seed 0 reads no agent
    capsys.readouterr()
    assert main([*argv, "--seeds", "0-1"]) == 2
    err = _error(capsys)
    assert f"--trained-agent: {mine / 'model.zip'} changed since seed-0 started from it" in err
    assert not (study / "seed-1").exists()
    shutil.rmtree(mine)  # moved away: the command says so, not just "no such agent"
    assert main([*argv, "--seeds", "0"]) == 2
    assert f"the study in {study} started from it" in _error(capsys)


def test_agent_files_that_are_missing_are_named(
    agent: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    bare = tmp_path / "bare"
    bare.mkdir()
    shutil.copy(agent / "model.zip", bare / "model.zip")
    assert main(["--trained-agent", str(bare), *TINY, "--out", str(out)]) == 2
    assert f"no config.yaml at {bare / 'config.yaml'}; an agent needs" in _error(capsys)
    # A checkpoint whose statistics are missing: the file named is the checkpoint's own.
    run = tmp_path / "run"
    shutil.copytree(agent.parent / "run", run)
    (run / "checkpoints" / "ppo_vecnormalize_800_steps.pkl").unlink()
    checkpoint = run / "checkpoints" / "ppo_800_steps.zip"
    assert main(["--trained-agent", str(checkpoint), *TINY, "--out", str(out)]) == 2
    assert "no ppo_vecnormalize_800_steps.pkl beside ppo_800_steps.zip" in _error(capsys)
    assert not out.exists()


@pytest.mark.slow
def test_a_relative_agent_is_recorded_absolute_and_shown_relative(
    agent: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    shutil.copytree(agent, tmp_path / "agents" / "mine")
    monkeypatch.chdir(tmp_path)
    argv = ["--trained-agent", "agents/mine", *TINY, "--n-timesteps", "256", "--out", "on"]
    assert main(argv) == 0
    config = yaml.safe_load((tmp_path / "on" / "config.yaml").read_text())
    assert config["trained_agent"]["path"] == str(tmp_path / "agents" / "mine")
    card = (tmp_path / "on" / "MODEL_CARD.md").read_text()
    assert "weights and normalisation of `agents/mine` (ppo" in card


def _space(observations: int, actions: int) -> SimpleNamespace:
    return SimpleNamespace(
        observation_space=Box(-1, 1, (observations,)), action_space=Box(-1, 1, (actions,))
    )


def test_an_agent_of_another_env_or_view_is_refused_by_its_shapes(agent: Path) -> None:
    trained = read_trained_agent(agent)
    check_base(trained, _space(2, 2))  # the env's: distance and offset, 2 actions
    check_spaces(trained, _space(20, 2))  # the view's: 4 frames of 5 numbers
    with pytest.raises(ValueError, match=r"observations of shape \[20\], this run's view gives"):
        check_spaces(trained, _space(24, 2))
    with pytest.raises(ValueError, match="the agent acts with 2 numbers, this run's env takes 3"):
        check_base(trained, _space(2, 3))
    with pytest.raises(ValueError, match="the agent observes 2 numbers, this run's env gives 7"):
        check_base(trained, _space(7, 2))


def test_a_study_from_an_agent_records_no_hyperparameter_file() -> None:
    own = study_settings(Args(trained_agent=Path("/a"), algo="ppo", env_id=ENV_ID), [0])
    assert own["hyperparams"] is None
    assert own["trained_agent"] == "/a"
    given = study_settings(Args(trained_agent=Path("/a"), hyperparams=Path("/h.yaml")), [0])
    assert given["hyperparams"] == "/h.yaml"


@pytest.mark.slow
def test_observation_statistics_carry_over_where_observations_are_normalised(
    tmp_path: Path,
) -> None:
    hp = _section(tmp_path, normalize={"norm_obs": True, "norm_reward": True})
    argv = ["--hyperparams", str(hp), *TINY, "--scenarios", "straight", "--n-timesteps", "256"]
    assert main([*argv, "--out", str(tmp_path / "a")]) == 0
    assert main(["--trained-agent", str(tmp_path / "a"), *argv, "--out", str(tmp_path / "b")]) == 0
    before, after = (
        _stats(tmp_path / "a" / "vecnormalize.pkl"),
        _stats(tmp_path / "b" / "vecnormalize.pkl"),
    )
    # this run's 256 steps' observations and its first reset's, one a lane
    assert after.obs_rms.count == pytest.approx(before.obs_rms.count + 256 + 4)
    assert after.obs_rms.mean.shape == before.obs_rms.mean.shape == (5,)


def test_an_ensemble_whose_members_trained_otherwise_is_named_by_the_key(
    agent: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    ensemble = _pair(agent, tmp_path / "pair")
    config = ensemble / "seed-1" / "config.yaml"
    saved = yaml.safe_load(config.read_text())
    saved["args"]["env_config"] = "thesis"  # seed-0 trained on noisy
    config.write_text(yaml.safe_dump(saved))
    out = tmp_path / "study"
    argv = ["--trained-agent", str(ensemble), *TINY, "--seeds", "0-1", "--out", str(out)]
    assert main(argv) == 2
    err = _error(capsys)
    assert "seed 1 would start from" in err
    assert "trained with --env-config 'thesis', where the study takes 'noisy'" in err
    given = [*argv[:-1], str(tmp_path / "given"), "--env-config", "noisy", "--n-timesteps", "256"]
    assert main(given) == 0  # given on the command line: the command's choice
    saved["args"]["env_config"] = "noisy"
    saved["hyperparams"]["n_timesteps"] = 2000  # trained on for longer than seed-0
    config.write_text(yaml.safe_dump(saved))
    assert main(argv) == 2
    err = _error(capsys)
    assert "seed 1 would start from" in err
    assert "whose n_timesteps=2000 is not the study's 1000" in err
    assert err.rstrip().endswith("give --n-timesteps for the study")
    assert not out.exists()


def test_a_seed_past_the_range_from_the_agent_says_where_it_came_from(
    agent: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    late = tmp_path / "late"
    shutil.copytree(agent, late)
    saved = yaml.safe_load((late / "config.yaml").read_text())
    saved["args"]["seed"] = 2**32 - 2000  # + its 1,024 steps: too little room for another run
    (late / "config.yaml").write_text(yaml.safe_dump(saved))
    out = tmp_path / "out"
    assert main(["--trained-agent", str(late), *TINY, "--out", str(out)]) == 2
    err = _error(capsys)
    assert f"--seed {2**32 - 2000 + 1024}" in err
    assert err.rstrip().endswith(
        "(the agent's seed + its steps, where its training stopped: give --seed)"
    )
    assert not out.exists()
    # In a study: seed k's own.
    argv = ["--trained-agent", str(late), *TINY, "--seeds", "0", "--out", str(out)]
    assert main(argv) == 2
    err = _error(capsys)
    assert f"--seed {2**32 - 2000 + 1024}" in err
    assert err.rstrip().endswith("(seed 0's, from where its agent's training stopped: give --seed)")
    assert not out.exists()


def test_an_agent_of_another_sensor_is_refused_through_the_command_line(
    agent: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # The agent's env gives 2 numbers; reading ahead adds a third, below the view.
    ahead = _section(tmp_path, env_kwargs={"perception": {"ahead_rays": 5}})
    out = tmp_path / "out"
    argv = ["--trained-agent", str(agent), "--hyperparams", str(ahead), *TINY, "--out", str(out)]
    assert main(argv) == 2
    assert "the agent observes 2 numbers, this run's env gives 3" in _error(capsys)
    assert not out.exists()


@pytest.mark.slow
def test_a_study_keeps_its_budget_when_its_agent_trained_on_since(
    agent: Path, tmp_path: Path
) -> None:
    mine = tmp_path / "agent"
    shutil.copytree(agent, mine)
    study = tmp_path / "study"
    argv = ["--trained-agent", str(mine), *TINY, "--seeds", "0", "--out", str(study)]
    assert main(argv) == 0  # the agent's own budget: 1,000 steps
    config = mine / "config.yaml"
    saved = yaml.safe_load(config.read_text())
    saved["hyperparams"]["n_timesteps"] = 1600  # as a --resume of the agent writes
    config.write_text(yaml.safe_dump(saved))
    assert main(argv) == 0
    sessions = json.loads((study / "seed-0" / "sessions.json").read_text())
    assert len(sessions) == 1  # nothing trained further
    run_config = yaml.safe_load((study / "seed-0" / "config.yaml").read_text())
    assert run_config["hyperparams"]["n_timesteps"] == 1000
