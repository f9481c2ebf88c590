"""The shipped agent that starts from a law's command, ``ppo_law`` (policies/agents/ppo_law):
seed 3 of train/configs/ppo_ahead_law_far.yaml's five-seed study, the jump gate added to its
view after training."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from eval.rollout import run_batch, run_episode
from eval.thesis import LAWS
from policies import make_policy
from policies.learned.hint import LawHint
from policies.learned.incremental import IncrementalAction
from policies.learned.ppo import AGENTS, PPOPolicy


def test_it_is_built_by_name_with_the_law_and_the_gate_in_its_view() -> None:
    agent = make_policy("ppo_law")
    assert isinstance(agent, PPOPolicy)
    assert agent.name == "ppo_law"
    assert agent.path == str(AGENTS / "ppo_law")
    assert agent.reads_ahead == {
        "ahead_rays": 5,
        "ahead_half_angle_deg": 14.0,
        "ahead_target": "include",
    }
    steps = agent._agent.pipeline(1).steps
    assert [type(s).__name__ for s in steps] == [
        "RescaleAction",
        "JumpGate",  # added after training (in_training: false)
        "ObservationAge",
        "LawHint",
        "ScaleObservation",
        "IncrementalAction",
        "FrameStack",
    ]
    (hint,) = [s for s in steps if isinstance(s, LawHint)]
    assert hint.law.name == "pn:thesis"
    (command,) = [s for s in steps if isinstance(s, IncrementalAction)]
    assert command.prior_index == 4  # the law's command: [d, offset, ahead, age, v, w]
    assert command.held_index == 3


@pytest.mark.slow
def test_it_acts_as_its_training_stack_did(acts_as_trained) -> None:
    # A walk with no jump of the detection, so the gate (absent from the training stack)
    # passes every reading: the law, the age, the command steps and the frames as trained.
    acts_as_trained(AGENTS / "ppo_law", make_policy("ppo_law"), 60, scenario="curve", seed=7)


@pytest.mark.slow
def test_it_keeps_the_person_round_the_corner_where_every_law_loses_them() -> None:
    """corridor_turn, seed 30057 (README, "The agent that starts from a law ships as
    ppo_law"): all six laws lose the person at the corner; the agent follows them to the
    end, batched as alone."""
    for law in (f"{name}:{preset}" for name in LAWS for preset in ("thesis", "tuned")):
        assert run_episode(law, "corridor_turn", 30057).termination == "lost", law
    (batched,) = run_batch("ppo_law", "corridor_turn", [30057])
    alone = run_episode("ppo_law", "corridor_turn", 30057)
    pd.testing.assert_frame_equal(batched.log, alone.log, check_exact=True)
    assert alone.termination == "walk_over"
    assert np.isfinite(alone.log["obs_ahead_m"]).all()
