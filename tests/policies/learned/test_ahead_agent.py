"""An agent trained with the reading ahead (train/configs/ppo_ahead.yaml): it reads three
entries, evaluation gives it the reading, and the runner refuses a perception without it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bridge import SerialLink
from bridge.perception import PerceptionError, Replay
from bridge.runner import Runner, RunnerConfig
from eval.rollout import run_batch, run_episode
from eval.steplog import read_step_log, write_step_log
from policies import make_policy
from policies.learned.ppo import PPOPolicy

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def ahead_agent(tmp_path_factory: pytest.TempPathFactory, one_rollout) -> Path:
    """One rollout of ppo_ahead.yaml on 64 lanes: the view, not the skill."""
    return one_rollout("ppo_ahead.yaml", tmp_path_factory.mktemp("ahead") / "run", "straight,crowd")


@pytest.mark.slow
def test_it_names_the_reading_it_needs(ahead_agent: Path) -> None:
    agent = make_policy(str(ahead_agent))
    assert isinstance(agent, PPOPolicy)
    assert agent.reads_ahead == {
        "ahead_rays": 5,
        "ahead_half_angle_deg": 14.0,
        "ahead_target": "include",
    }
    assert make_policy("ppo").reads_ahead is None
    agent.reset()
    with pytest.raises(ValueError, match=r"reads the reading ahead .* perception=\{'ahead_rays'"):
        agent.act(np.array([1.0, 0.0], dtype=np.float32))
    action = agent.act(np.array([1.0, 0.0, 3.0], dtype=np.float32))
    assert action.shape == (2,)
    assert np.isfinite(action).all()


def test_an_agent_without_it_reads_the_first_two_entries() -> None:
    for name in ("ppo", "gsmpn:tuned"):
        plain, given = make_policy(name), make_policy(name)
        plain.reset()
        given.reset()
        for obs in ([1.2, 40.0], [1.1, -12.0], [0.0, 0.0], [1.4, 3.0]):
            np.testing.assert_array_equal(
                plain.act(np.array(obs, dtype=np.float32)),
                given.act(np.array([*obs, 0.7], dtype=np.float32)),
            )


@pytest.mark.slow
def test_evaluation_gives_it_the_reading_and_leaves_the_others_alone(ahead_agent: Path) -> None:
    name = str(ahead_agent)
    batch = run_batch(name, "crowd", [3, 4])
    for episode in batch:
        assert "obs_ahead_m" in episode.log.columns
        assert episode.log["obs_ahead_m"].between(0.0, 10.0).all()
    alone = run_episode(name, "crowd", 4).log
    pd.testing.assert_frame_equal(alone, batch[1].log, check_exact=True)
    # The laws' episodes: no column of the reading unless the run's config asks for it, and
    # the same episode with it as without it.
    law = run_batch("gsmpn:tuned", "crowd", [3])[0].log
    assert "obs_ahead_m" not in law.columns
    asked = run_batch("gsmpn:tuned", "crowd", [3], config={"perception": {"ahead_rays": 5}})
    with_it = asked[0].log
    assert with_it["obs_ahead_m"].notna().all()
    pd.testing.assert_frame_equal(with_it.drop(columns="obs_ahead_m"), law, check_exact=True)


@pytest.mark.slow
def test_the_runner_feeds_it_from_a_replay_and_refuses_a_source_without(
    ahead_agent: Path, tmp_path: Path
) -> None:
    recorded = run_episode(str(ahead_agent), "straight", 1).log
    source = tmp_path / "with.csv"
    write_step_log(recorded, source)
    log = tmp_path / "replayed.csv"
    with SerialLink("loop://", "reference") as link:
        runner = Runner(
            link,
            make_policy(str(ahead_agent)),
            Replay(source),
            config=RunnerConfig(duration_s=0.5),
            log=log,
        )
        runner.run()
    replayed = read_step_log(log)
    n = len(replayed) - 1
    np.testing.assert_allclose(
        replayed["obs_ahead_m"].to_numpy()[:n], recorded["obs_ahead_m"].to_numpy()[:n]
    )
    plain = tmp_path / "without.csv"
    write_step_log(recorded.drop(columns="obs_ahead_m"), plain)
    with SerialLink("loop://", "reference") as link:
        runner = Runner(link, make_policy(str(ahead_agent)), Replay(plain))
        with pytest.raises(PerceptionError, match=r"does not publish it: start the emulator"):
            runner.run()


@pytest.mark.slow
def test_the_shipped_agent_that_reads_ahead() -> None:
    """``ppo_ahead`` (policies/agents/ppo_ahead): it names the reading it was trained with, and
    its episodes in evaluation carry it, batched as alone."""
    agent = make_policy("ppo_ahead")
    assert agent.name == "ppo_ahead"
    assert agent.reads_ahead == {
        "ahead_rays": 5,
        "ahead_half_angle_deg": 14.0,
        "ahead_target": "include",
    }
    (batched,) = run_batch("ppo_ahead", "crossing", [2])
    alone = run_episode("ppo_ahead", "crossing", 2)
    pd.testing.assert_frame_equal(batched.log, alone.log, check_exact=True)
    assert batched.log["obs_ahead_m"].notna().all()
    assert batched.log.termination.iloc[-1] == "walk_over"


@pytest.mark.slow
def test_the_shipped_agent_that_reads_ahead_runs_the_gate_it_was_not_trained_with(
    tmp_path: Path,
) -> None:
    """Its view holds the jump gate (``in_training: false``) before the age. Through a crowd
    where the detection jumps to a bystander, it acts as the same weights without the gate up to
    the first jump, and otherwise after it."""
    import shutil

    import yaml

    shipped = ROOT / "policies/agents/ppo_ahead"
    config = yaml.safe_load((shipped / "config.yaml").read_text())
    entries = config["hyperparams"]["vec_env_wrapper"]
    gate = {
        "train.wrappers.VecJumpGate": {"max_jump_m": 0.5, "accept_after": 10, "in_training": False}
    }
    assert gate in entries
    steps = [type(s).__name__ for s in make_policy("ppo_ahead")._agent.pipeline(1).steps]
    assert steps[1:3] == ["JumpGate", "ObservationAge"]
    plain = tmp_path / "plain"
    plain.mkdir()
    for name in ("model.zip", "vecnormalize.pkl"):
        shutil.copy(shipped / name, plain / name)
    config["hyperparams"]["vec_env_wrapper"] = [e for e in entries if e != gate]
    (plain / "config.yaml").write_text(yaml.safe_dump(config))
    gated, ungated = (
        run_episode("ppo_ahead", "crowd", 4).log,
        run_episode(str(plain), "crowd", 4).log,
    )
    distance = gated["obs_distance_m"].to_numpy()
    first = int(np.flatnonzero(np.abs(np.diff(distance)) > 0.5)[0]) + 1  # the first jump's row
    action = ["action_v_mps", "action_w_radps"]
    np.testing.assert_array_equal(gated[action][:first], ungated[action][:first])
    n = min(len(gated), len(ungated))
    assert not np.array_equal(gated[action][first:n], ungated[action][first:n])
