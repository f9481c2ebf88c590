"""follow-train --algo recurrent_ppo / sac: real (tiny) training runs, resumed, loaded as
policies, acting bitwise alike alone and in a batch; and --seeds with another algorithm."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from follow_env.tasks.person_follow import ENV_ID
from policies import make_policy
from policies.learned.ppo import PPOPolicy
from train.algos import ALGOS
from train.cli import main
from train.run import newest_checkpoint, replay_buffer_file

STEPS = 800
TINY = [
    "--scenarios", "straight,curve",
    "--n-envs", "2",
    "--n-timesteps", str(STEPS),
    "--eval-freq", "400",
    "--checkpoint-freq", "400",
    "--final-episodes", "0",
    "--no-progress",
]  # fmt: skip
# The shipped files with small networks and buffers: a few seconds of training each.
SMALL = {
    "recurrent_ppo": {
        "n_steps": 32,
        "batch_size": 32,
        "n_epochs": 2,
        "policy_kwargs": {"lstm_hidden_size": 8, "net_arch": {"pi": [8], "vf": [8]}},
    },
    "sac": {
        "buffer_size": 2000,
        "learning_starts": 200,
        "batch_size": 32,
        "gradient_steps": 1,
        "policy_kwargs": {"net_arch": [16, 16]},
    },
}


def small_yaml(folder: Path, algo: str) -> Path:
    document = yaml.safe_load(ALGOS[algo].hyperparams.read_text())
    document[ENV_ID].update(SMALL[algo])
    path = folder / f"{algo}.yaml"
    path.write_text(yaml.safe_dump(document))
    return path


@pytest.fixture(scope="module", params=["recurrent_ppo", "sac"])
def run(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Path:
    algo = request.param
    root = tmp_path_factory.mktemp(algo)
    out = root / "run"
    argv = ["--algo", algo, "--hyperparams", str(small_yaml(root, algo)), *TINY]
    assert main([*argv, "--out", str(out)]) == 0
    return out


def observations(n: int, steps: int, seed: int = 0) -> np.ndarray:
    """``steps`` observations ``[distance_m, offset_px]`` of ``n`` lanes, each lane its own
    walk; one step in ten repeats the last one (as the env does while the detector sees
    nothing)."""
    rng = np.random.default_rng(seed)
    distance = 1.5 + np.cumsum(rng.normal(0, 0.05, (steps, n)), axis=0)
    offset = np.cumsum(rng.normal(0, 20.0, (steps, n)), axis=0)
    obs = np.stack([np.clip(distance, 0.3, 5.0), np.clip(offset, -300, 300)], axis=-1)
    for t in range(1, steps):
        stale = rng.random(n) < 0.1
        obs[t, stale] = obs[t - 1, stale]
    return obs.astype(np.float32)


def test_a_run_writes_its_folder_with_the_algorithm(run: Path) -> None:
    config = yaml.safe_load((run / "config.yaml").read_text())
    algo = config["algo"]
    assert config["args"]["algo"] == algo
    assert config["hyperparams"]["policy"] == ALGOS[algo].policies[0]
    assert "use_sde" not in config["hyperparams"]["policy_kwargs"]  # SB3's, not the file's
    for name in ("model.zip", "MODEL_CARD.md", "learning_curve.png", "evaluations.npz"):
        assert (run / name).is_file(), name
    steps, model, _ = newest_checkpoint(run, algo)
    final = json.loads((run / "sessions.json").read_text())[-1]["last_step"]
    assert steps == final >= STEPS  # the final state is the newest checkpoint
    assert model.name == f"{algo}_{final}_steps.zip"
    assert (run / "vecnormalize.pkl").is_file() == bool(config["hyperparams"]["normalize"])
    card = (run / "MODEL_CARD.md").read_text()
    assert card.startswith(f"# {ALGOS[algo].label} agent for PersonFollow-v0")
    assert f"{ALGOS[algo].library} {ALGOS[algo].label}" in card
    buffers = sorted(p.name for p in (run / "checkpoints").glob("*replay_buffer*"))
    assert buffers == ([f"sac_replay_buffer_{final}_steps.pkl"] if algo == "sac" else [])


def test_resume_continues_with_the_saved_algorithm(
    run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    algo = yaml.safe_load((run / "config.yaml").read_text())["algo"]
    other = "ppo" if algo == "sac" else "sac"
    capsys.readouterr()
    assert main(["--resume", str(copy), "--algo", other, "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert f"--algo {other}: {copy} is a {algo} run" in err
    assert main(["--resume", str(copy), "--n-timesteps", "1200", "--no-progress"]) == 0
    sessions = json.loads((copy / "sessions.json").read_text())
    # each session goes on from the last one's final state, its newest checkpoint
    assert [s["first_step"] for s in sessions] == [0, sessions[0]["last_step"]]
    final = sessions[1]["last_step"]
    assert newest_checkpoint(copy, algo)[0] == final >= 1200
    if algo == "sac":  # the newest checkpoint only keeps its replay buffer
        buffers = [p.name for p in (copy / "checkpoints").glob("*replay_buffer*")]
        assert buffers == [f"sac_replay_buffer_{final}_steps.pkl"]


@pytest.mark.parametrize("run", ["sac"], indirect=True)  # the only algorithm with a buffer
def test_a_sac_resume_reads_the_replay_buffer(
    run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    replay = replay_buffer_file(newest_checkpoint(copy, "sac")[1])
    replay.write_bytes(b"not a pickle")
    capsys.readouterr()
    assert main(["--resume", str(copy), "--n-timesteps", "1200", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert f"{replay}: cannot resume from it" in err


def test_the_run_loads_as_a_policy_acting_alike_alone_and_batched(run: Path) -> None:
    policy = make_policy(str(run))
    assert isinstance(policy, PPOPolicy)
    lanes = observations(3, 40)
    alone = np.empty((40, 3, 2), dtype=np.float32)
    for lane in range(3):
        policy.reset()
        for t in range(40):
            alone[t, lane] = policy.act(lanes[t, lane])
    policy.reset_batch(3)
    batched = np.stack([policy.act_batch(lanes[t]) for t in range(40)])
    np.testing.assert_array_equal(batched, alone)  # bitwise
    assert np.all(np.isfinite(alone))


def test_reset_starts_the_agent_afresh(run: Path) -> None:
    policy = make_policy(str(run))
    episode = observations(1, 30, seed=1)[:, 0]
    first = [policy.act(o) for o in episode]
    policy.reset()
    second = [policy.act(o) for o in episode]
    np.testing.assert_array_equal(first, second)
    policy.reset_batch(2)
    both = [policy.act_batch(np.stack([o, o])) for o in episode]
    policy.reset_batch(2)
    again = [policy.act_batch(np.stack([o, o])) for o in episode]
    np.testing.assert_array_equal(both, again)
    np.testing.assert_array_equal(np.asarray(both)[:, 0], first)


def test_the_network_acts_as_the_librarys_predict(run: Path) -> None:
    """The loaded network's deterministic action equals SB3's / sb3-contrib's predict (SAC:
    squashed and rescaled; RecurrentPPO: with the LSTM state carried) but for float32's
    rounding: the network acts in float64, the library in float32."""
    import torch

    algo = yaml.safe_load((run / "config.yaml").read_text())["algo"]
    network = make_policy(str(run))._agent.model
    model = ALGOS[algo].cls().load(run / "model.zip", device="cpu")
    rng = np.random.default_rng(2)
    obs = rng.uniform(-1, 1, (12, *network.observation_space.shape)).astype(np.float32)
    memory = network.memory(1)
    state, start = None, np.ones(1, dtype=bool)
    for row in obs:
        ours = network.act(row[None], memory)
        theirs, state = model.predict(row[None], state=state, episode_start=start,
                                      deterministic=True)  # fmt: skip
        start = np.zeros(1, dtype=bool)
        np.testing.assert_allclose(ours, theirs, rtol=1e-5, atol=1e-6)
    if algo == "recurrent_ppo":  # the state matters: the same input, a different action
        again = network.act(obs[-1:], memory)
        assert not np.array_equal(again, network.act(obs[-1:], network.memory(1)))
    # A network made from the caller's own policy leaves it as it was: the library's predict
    # (sb3-contrib's builds float32 LSTM states) still runs on it and gives the same actions.
    before = model.predict(obs, deterministic=True)[0]
    mine = type(network)(model.policy)
    assert {p.dtype for p in model.policy.parameters()} == {torch.float32}
    np.testing.assert_array_equal(model.predict(obs, deterministic=True)[0], before)
    np.testing.assert_array_equal(
        mine.act(obs[:1], mine.memory(1)), network.act(obs[:1], network.memory(1))
    )


def test_a_study_trains_every_seed_with_the_algorithm(tmp_path: Path) -> None:
    study = tmp_path / "study"
    argv = ["--algo", "sac", "--hyperparams", str(small_yaml(tmp_path, "sac")), *TINY]
    argv[argv.index(str(STEPS))] = "400"
    assert main([*argv, "--seeds", "0-1", "--out", str(study)]) == 0
    for k in (0, 1):
        assert yaml.safe_load((study / f"seed-{k}" / "config.yaml").read_text())["algo"] == "sac"
    assert json.loads((study / "study.json").read_text())["algo"] == "sac"
    assert (study / "seeds.csv").is_file()
    assert main([*argv, "--seeds", "0-1", "--out", str(study)]) == 0  # all done: nothing new


def test_the_evaluation_harness_runs_the_agent_alike_alone_and_batched(run: Path) -> None:
    from eval.rollout import run_batch, run_episode

    batched = run_batch(str(run), "curve", [3, 4])
    for seed, episode in zip((3, 4), batched, strict=True):
        pd.testing.assert_frame_equal(episode.log, run_episode(str(run), "curve", seed).log)


def test_follow_eval_runs_the_agent_by_its_run_folder(
    run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from eval.cli import main as follow_eval

    argv = ["run", "--policies", str(run), "--scenarios", "straight", "--episodes", "1"]
    assert follow_eval([*argv, "--out", str(tmp_path / "eval"), "--workers", "1"]) == 0
    assert str(run) in capsys.readouterr().out


def test_loading_the_agent_imports_no_training_code(run: Path) -> None:
    code = (
        "import sys; from policies import make_policy; "
        f"make_policy({str(run)!r}).act([1.5, 20.0]); "
        "print(sorted({m.split('.')[0] for m in sys.modules} & {'train', 'eval'}))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]"
