"""The shipped agent that is two agents' mean action, ``ppo_ensemble``
(policies/agents/ppo_ensemble): seeds 0 and 1 of train/configs/ppo_ahead_law_wide.yaml, the
jump gate added to both after training."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from eval.rollout import run_batch, run_episode
from policies import make_policy
from policies.learned.ensemble import EnsemblePolicy, is_learned
from policies.learned.ppo import AGENTS, PPOPolicy

FOLDER = AGENTS / "ppo_ensemble"


def _first_step(member: PPOPolicy) -> np.ndarray:
    """The most a command may move in one frame, in SI (m/s, rad/s): the incremental
    action's max_change of the agent's action range (RescaleAction's)."""
    steps = {type(s).__name__: s for s in member._agent.pipeline(1).steps}
    return steps["IncrementalAction"].max_change * steps["RescaleAction"].si_high


def _first_actions(obs: np.ndarray) -> tuple[EnsemblePolicy, list[PPOPolicy], list[np.ndarray]]:
    """The shipped ensemble, its members built alone, and each member's first action on obs."""
    ensemble = make_policy("ppo_ensemble")
    members = [PPOPolicy(m) for m in ensemble.members]
    return ensemble, members, [np.asarray(m.act(obs), dtype=np.float64) for m in members]


def test_it_is_built_by_name_as_the_mean_of_its_two_seeds() -> None:
    agent = make_policy("ppo_ensemble")
    assert isinstance(agent, EnsemblePolicy)
    assert is_learned(agent)
    assert agent.name == "ppo_ensemble"
    assert agent.path == str(FOLDER)
    assert agent.members == (str(FOLDER / "seed-0"), str(FOLDER / "seed-1"))
    # it reads ahead as ppo_law does, so a robot that publishes the reading feeds both
    assert agent.reads_ahead == make_policy("ppo_law").reads_ahead
    for member in agent.members:
        lone = PPOPolicy(member)
        config = yaml.safe_load((Path(member) / "config.yaml").read_text(encoding="utf-8"))
        assert config["hyperparams"]["policy_kwargs"]["net_arch"] == [128, 128]
        steps = [type(s).__name__ for s in lone._agent.pipeline(1).steps]
        assert steps == [
            "RescaleAction",
            "JumpGate",  # added after training (in_training: false)
            "ObservationAge",
            "LawHint",
            "ScaleObservation",
            "IncrementalAction",
            "FrameStack",
        ]


def test_its_first_command_is_the_mean_of_two_different_members() -> None:
    obs = np.array([1.1, 80.0, 1.1], dtype=np.float32)  # a person 1.1 m ahead, 80 px right
    ensemble, members, seen = _first_actions(obs)
    assert np.abs(seen[0] - seen[1]).min() > 1e-3  # two agents, not one twice
    # From rest a command moves by max_change * clip(action + the law's pull, -1, 1): linear in
    # the agents' actions while no member's first step reaches max_change (0.2 and 0.15 of the
    # 1.484375 m/s and 2 rad/s action range, config.yaml). A person further off, whom the law
    # drives at, saturates a member's step, and the mean of the clipped steps is not the step
    # of the mean action.
    step = _first_step(members[0])
    np.testing.assert_allclose(step, [0.2 * 1.484375, 0.15 * 2.0])
    assert all((np.abs(s) < step - 1e-3).all() for s in seen)
    np.testing.assert_allclose(ensemble.act(obs), (seen[0] + seen[1]) / 2, rtol=0, atol=1e-6)


def test_it_averages_the_members_actions_not_their_commands() -> None:
    """Further off, one member's first step saturates: the ensemble steps by the mean of the
    actions (so it moves further than the mean of the members' clipped commands), between the
    two members."""
    obs = np.array([1.6, 80.0, 1.6], dtype=np.float32)
    ensemble, members, seen = _first_actions(obs)
    v_step = _first_step(members[0])[0]
    assert max(s[0] for s in seen) == pytest.approx(v_step)  # one member saturates ...
    assert min(s[0] for s in seen) < v_step - 1e-3  # ... the other does not
    v = float(ensemble.act(obs)[0])
    assert min(s[0] for s in seen) < v < v_step
    assert v > (seen[0][0] + seen[1][0]) / 2 + 1e-4


@pytest.mark.slow
@pytest.mark.parametrize("member", ["seed-0", "seed-1"])
def test_each_member_acts_as_its_training_stack_did(acts_as_trained, member: str) -> None:
    # A walk with no jump of the detection, so the gate (absent from the training stack)
    # passes every reading.
    acts_as_trained(FOLDER / member, PPOPolicy(FOLDER / member), 60, scenario="curve", seed=7)


@pytest.mark.slow
def test_batched_episodes_are_the_lone_ones() -> None:
    batched = run_batch("ppo_ensemble", "crowd", [30000, 30001])
    for episode in batched:
        alone = run_episode("ppo_ensemble", "crowd", episode.seed)
        np.testing.assert_array_equal(
            episode.log["action_w_radps"].to_numpy(), alone.log["action_w_radps"].to_numpy()
        )


@pytest.mark.parametrize("name", ["ppo", "ppo_law", "ppo_ensemble"])
def test_reset_lanes_restarts_only_the_flagged_lanes(name: str) -> None:
    """An auto-resetting vector env ends one lane's episode: that lane starts afresh (its frame
    stack, command in force, age, gate and law memory), the others go on as they were."""
    rng = np.random.default_rng(0)
    width = 3 if name != "ppo" else 2

    def obs() -> np.ndarray:
        rows = np.column_stack([rng.uniform(0.5, 3.0, 2), rng.uniform(-300, 300, 2)])
        return rows if width == 2 else np.column_stack([rows, rng.uniform(0.5, 5.0, 2)])

    batch = make_policy(name)
    lanes = [make_policy(name), make_policy(name)]
    batch.reset_batch(2)
    first = [obs() for _ in range(4)]
    for step in first:
        got = batch.act_batch(step)
        want = [lanes[k].act(step[k]) for k in range(2)]
        np.testing.assert_array_equal(got, np.array(want))
    batch.reset_lanes(np.array([True, False]))
    lanes[0].reset()  # lane 0's new episode; lane 1's goes on
    for _ in range(4):
        step = obs()
        got = batch.act_batch(step)
        want = [lanes[k].act(step[k]) for k in range(2)]
        np.testing.assert_array_equal(got, np.array(want))
    with pytest.raises(ValueError, match="one flag per lane"):
        batch.reset_lanes(np.array([True]))
