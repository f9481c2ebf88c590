"""A guidance law's command in the agent's view (LawHint), and IncrementalAction tracking it."""

from __future__ import annotations

import re
import shutil
import threading
from pathlib import Path

import numpy as np
import pytest

from policies import make_policy
from policies.learned import hint
from policies.learned.boxes import Box
from policies.learned.features import IncrementalAction, Pipeline
from policies.learned.hint import LawHint
from policies.learned.ppo import AGENTS, AgentLoadError, PPOPolicy
from policies.registry import REGISTRY

ACT = Box(np.array([-1.0, -1.0]), np.array([1.0, 1.0]), ("v_mps", "w_radps"))
OBS = Box(np.array([0.0, -320.0, 0.0]), np.array([10.0, 319.0, 10.0]))
UNITS = np.array([1.5, 2.0])


def _rows(rng: np.random.Generator, n: int) -> np.ndarray:
    return np.column_stack(
        [rng.uniform(0.3, 4.0, n), rng.uniform(-300, 300, n), rng.uniform(0.3, 5.0, n)]
    ).astype(np.float32)


def test_it_appends_the_laws_command_in_the_agents_units() -> None:
    rng = np.random.default_rng(0)
    hint = LawHint(law="pn:thesis", units=UNITS.tolist())
    outer, act = hint.bind(OBS, ACT, 5)
    assert outer.shape == (5,)
    assert act is ACT
    obs = _rows(rng, 5)
    seen = hint.start(obs)
    law = make_policy("pn:thesis")
    want = np.clip([law.act(row) / UNITS for row in obs], -1, 1)
    np.testing.assert_array_equal(seen[:, :3], obs)
    np.testing.assert_allclose(seen[:, 3:], want, rtol=1e-6)
    assert np.abs(seen[:, 3:]).max() == 1.0  # a command beyond the unit reads as 1


def test_each_lane_keeps_the_laws_memory_and_a_new_episode_forgets_it() -> None:
    """mpn remembers the last offset: a lane reset mid-run acts as a fresh law on its first
    observation; the other lanes as one law run through their own episodes."""
    rng = np.random.default_rng(1)
    script = [_rows(rng, 3) for _ in range(4)]
    hint = LawHint(law="mpn:thesis", units=UNITS.tolist())
    hint.bind(OBS, ACT, 3)
    done = np.array([False, True, False])
    seen = [hint.start(script[0])] + [
        hint.observe(script[t], done if t == 2 else np.zeros(3, bool)) for t in (1, 2, 3)
    ]
    for lane in range(3):
        law = make_policy("mpn:thesis")
        for t in range(4):
            if lane == 1 and t == 2:
                law.reset()
            want = np.clip(law.act(script[t][lane]) / UNITS, -1, 1)
            np.testing.assert_allclose(seen[t][lane, 3:], want, rtol=1e-6)


def test_the_terminal_view_leaves_the_memory_alone() -> None:
    rng = np.random.default_rng(2)
    first, last, nxt = _rows(rng, 2), _rows(rng, 2), _rows(rng, 2)
    hint = LawHint(law="gsmpn:thesis", units=UNITS.tolist())
    hint.bind(OBS, ACT, 2)
    hint.start(first)
    peeked = hint.terminal(last[0], 0)
    law = make_policy("gsmpn:thesis")
    law.act(first[0])
    np.testing.assert_allclose(peeked[3:], np.clip(law.act(last[0]) / UNITS, -1, 1), rtol=1e-6)
    after = hint.observe(nxt, np.zeros(2, bool))
    fresh = make_policy("gsmpn:thesis")
    fresh.act(first[0])
    np.testing.assert_allclose(after[0, 3:], np.clip(fresh.act(nxt[0]) / UNITS, -1, 1), rtol=1e-6)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"units": [1.5]}, "LawHint.units=[1.5] is out of range: must be 2 positive numbers"),
        ({"units": [1.5, 0.0]}, "LawHint.units=[1.5, 0.0] is out of range"),
        ({"law": "nope"}, "LawHint.law='nope' is out of range: must be a guidance law"),
        ({"law": "ppo"}, "LawHint.law='ppo' is out of range: must be a guidance law"),
    ],
)
def test_bad_arguments_name_the_field(kwargs: dict, message: str) -> None:
    with pytest.raises(ValueError, match=re.escape(message)):
        LawHint(**kwargs).bind(OBS, ACT, 1)


def test_with_prior_index_a_zero_action_tracks_the_prior_within_the_bound() -> None:
    # obs [distance, prior v, prior w]: the command moves towards the prior by at most
    # max_change a step, and the agent's action adds to that pull.
    step = IncrementalAction(max_change=[0.25, 0.25], reading_index=0, prior_index=1)
    step.bind(Box(np.full(3, -5.0), np.full(3, 5.0)), ACT, 1)
    step.start(np.array([[1.0, 0.6, -0.1]]))
    got = []
    for action in ([0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [-1.0, 0.4]):
        got.append(step.act(np.array([action])))
        step.observe(np.array([[1.0, 0.6, -0.1]]), np.zeros(1, bool))
    np.testing.assert_allclose(
        np.concatenate(got), [[0.25, -0.1], [0.5, -0.1], [0.6, -0.1], [0.35, 0.0]], atol=1e-6
    )


def test_with_prior_gain_the_pull_closes_that_share_of_the_distance() -> None:
    step = IncrementalAction(max_change=[1.0, 1.0], prior_index=0, prior_gain=0.5)
    step.bind(Box(np.full(2, -5.0), np.full(2, 5.0)), ACT, 1)
    step.start(np.array([[0.8, -0.4]]))
    first = step.act(np.zeros((1, 2)))
    second = step.act(np.zeros((1, 2)))
    np.testing.assert_allclose(np.concatenate([first, second]), [[0.4, -0.2], [0.6, -0.3]])


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"prior_index": 2}, "IncrementalAction.prior_index=2 is out of range: the 2 prior"),
        ({"prior_index": 0, "prior_gain": 0.0}, "IncrementalAction.prior_gain=0.0 is out of"),
        ({"prior_index": 0, "prior_gain": 1.5}, "IncrementalAction.prior_gain=1.5 is out of"),
        # A gain with nothing to track would be dropped without a word.
        ({"prior_gain": 0.3}, "IncrementalAction.prior_gain=0.3: needs prior_index"),
    ],
)
def test_bad_prior_options_name_the_field(kwargs: dict, message: str) -> None:
    with pytest.raises(ValueError, match=re.escape(message)):
        IncrementalAction(max_change=[0.25, 0.25], **kwargs).bind(
            Box(np.full(3, -5.0), np.full(3, 5.0)), ACT, 1
        )


def test_the_law_and_the_tracking_chain_in_an_agents_pipeline() -> None:
    """LawHint then IncrementalAction reading it: with zero actions the robot drives as the
    law, rate-limited, in the agent's units."""
    rng = np.random.default_rng(3)
    obs = _rows(rng, 1)
    pipeline = Pipeline(
        [
            LawHint(law="pn:thesis", units=UNITS.tolist()),
            IncrementalAction(max_change=[2.0, 2.0], reading_index=0, prior_index=3),
        ],
        OBS,
        ACT,
        1,
    )
    assert pipeline.observation_box.shape == (7,)
    pipeline.start(obs)
    command = pipeline.act(np.zeros((1, 2)))
    want = np.clip(make_policy("pn:thesis").act(obs[0]) / UNITS, -1, 1)
    np.testing.assert_allclose(command[0], want, rtol=1e-6)


@pytest.mark.slow
def test_an_agent_trained_with_a_laws_command_loads_with_the_law_in_its_view(
    tmp_path: Path, one_rollout
) -> None:
    """train/configs/ppo_ahead_law.yaml, one rollout on 64 lanes: the exported agent's view
    holds pn:thesis's command, and the agent acts on an observation as the pipeline says."""
    run = one_rollout("ppo_ahead_law.yaml", tmp_path / "run", "straight")
    agent = make_policy(str(run))
    assert isinstance(agent, PPOPolicy)
    pipeline = agent._agent.pipeline(1)  # the view the policy builds for one robot
    hints = [step for step in pipeline.steps if isinstance(step, LawHint)]
    assert [h.law.name for h in hints] == ["pn:thesis"]
    obs = np.array([[2.0, 100.0, 3.0]], dtype=np.float32)
    view = pipeline.start(obs)
    # the last of 4 frames: [distance, offset / 100, ahead, age, law v, law w, v, w]
    law = make_policy("pn:thesis").act(obs[0]) / np.array([1.484375, 2.0])
    np.testing.assert_allclose(view[0, -4:-2], np.clip(law, -1, 1), rtol=1e-6)
    agent.reset()
    action = agent.act(obs[0])
    assert action.shape == (2,)
    assert np.all(np.isfinite(action))


def _law_agent(folder: Path, law: str) -> Path:
    """A copy of the shipped ``ppo_law`` whose LawHint reads ``law`` in place of pn:thesis."""
    folder.mkdir()
    for name in ("model.zip", "vecnormalize.pkl", "config.yaml"):
        shutil.copy(AGENTS / "ppo_law" / name, folder / name)
    config = folder / "config.yaml"
    text = config.read_text(encoding="utf-8")
    assert "law: pn:thesis" in text
    config.write_text(text.replace("law: pn:thesis", f"law: {law!r}"), encoding="utf-8")
    return folder


def _load_in_thread(path: Path, seconds: float = 60.0) -> object:
    """``make_policy(path)``'s policy or error, from a daemon thread: a load that hangs fails
    this test rather than the whole suite."""
    result: list[object] = []

    def load() -> None:
        try:
            result.append(make_policy(str(path)))
        except Exception as e:  # the error is the result
            result.append(e)

    thread = threading.Thread(target=load, daemon=True)
    thread.start()
    thread.join(seconds)
    assert not thread.is_alive(), f"loading {path} hung"
    return result[0]


@pytest.mark.parametrize("law", ["ppo", "ppo_ensemble", "self", "shipped path"])
def test_an_agent_whose_law_is_a_learned_agent_is_refused_naming_its_config(
    tmp_path: Path, law: str
) -> None:
    """It hung for ever: the loader held its lock while the law, an agent, loaded."""
    folder = tmp_path / "agent"
    given = {"self": str(folder), "shipped path": str(AGENTS / "ppo")}.get(law, law)
    _law_agent(folder, given)
    error = _load_in_thread(folder)
    assert isinstance(error, AgentLoadError)
    assert str(folder / "config.yaml") in str(error)
    assert "must be a guidance law, not a learned agent" in str(error)


def test_an_agent_whose_law_name_builds_the_agent_itself_is_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A name registered for the agent itself passes the name check: the loader refuses the
    cycle (one lock held across a load hung on it for ever)."""
    folder = _law_agent(tmp_path / "agent", "selfie")
    factories = {"person_follow": lambda: PPOPolicy(folder)}
    monkeypatch.setitem(REGISTRY._factories, "selfie", factories)
    error = _load_in_thread(folder)
    assert isinstance(error, AgentLoadError)
    assert str(folder / "config.yaml") in str(error)
    assert "needs the agent itself" in str(error)
    # the failed load leaves nothing behind: the agent with a law loads afterwards
    (folder / "config.yaml").write_text(
        (AGENTS / "ppo_law" / "config.yaml").read_text(encoding="utf-8"), encoding="utf-8"
    )
    assert isinstance(_load_in_thread(folder), PPOPolicy)


@pytest.mark.parametrize("law", ["ppo", "ppo_law", "runs/ppo-1", "model.zip", str(AGENTS / "ppo")])
def test_a_learned_agent_is_refused_as_the_law_before_anything_is_built(
    law: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    def build(name: str) -> None:
        raise AssertionError(f"{name} was built")

    monkeypatch.setattr(hint, "_make_law", build)
    with pytest.raises(ValueError, match=re.escape(f"LawHint.law={law!r} is out of range")):
        LawHint(law=law).bind(OBS, ACT, 1)


def test_a_learned_agent_registered_under_another_name_is_refused_as_the_law(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setitem(
        REGISTRY._factories, "my_law", {"person_follow": lambda: make_policy("ppo")}
    )
    with pytest.raises(ValueError, match=r"LawHint\.law='my_law' .* not a learned agent"):
        LawHint(law="my_law").bind(OBS, ACT, 1)
