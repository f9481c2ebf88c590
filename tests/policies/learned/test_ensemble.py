"""policies/learned/ensemble.py: several agents acting as one, the mean of their actions."""

from __future__ import annotations

import pickle
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from eval.rollout import run_episode
from policies import make_policy
from policies.learned.ensemble import ENSEMBLE, EnsemblePolicy
from policies.learned.ppo import AGENTS, DEFAULT_AGENT, AgentLoadError, PPOPolicy

FILES = ("model.zip", "vecnormalize.pkl", "config.yaml")


def copy_agent(folder: Path) -> Path:
    folder.mkdir()
    for name in FILES:
        shutil.copy(DEFAULT_AGENT / name, folder / name)
    return folder


def nudge_network(folder: Path, gain: float) -> None:
    """Scale the agent's last layer by ``gain``: another agent that sees the env alike (the
    mirror-symmetric action head wraps the linear layer as ``inner``)."""
    from stable_baselines3 import PPO

    model = PPO.load(folder / "model.zip", device="cpu")
    model.policy.action_net.inner.weight.data *= gain
    model.save(folder / "model.zip")


def write(folder: Path, members: list[str]) -> Path:
    (folder / ENSEMBLE).write_text(yaml.safe_dump({"members": members}), encoding="utf-8")
    return folder


@pytest.fixture
def pair(tmp_path: Path) -> Path:
    """A study-like folder: the shipped agent (seed-0) and a nudged copy of it (seed-1)."""
    copy_agent(tmp_path / "seed-0")
    nudge_network(copy_agent(tmp_path / "seed-1"), 1.3)
    return write(tmp_path, ["seed-0", "seed-1"])


def test_a_folder_with_an_ensemble_file_is_a_policy_name(pair: Path) -> None:
    policy = make_policy(str(pair))
    assert isinstance(policy, EnsemblePolicy)
    assert policy.name == str(pair)
    assert policy.members == (str(pair / "seed-0"), str(pair / "seed-1"))
    assert (policy.platform, policy.action_names) == ("diff_drive", ("v_mps", "w_radps"))
    # the file itself names it too
    assert isinstance(make_policy(str(pair / ENSEMBLE)), EnsemblePolicy)
    # a run folder without the file is still a lone agent
    assert isinstance(make_policy(str(pair / "seed-0")), PPOPolicy)


def test_first_action_is_the_mean_of_the_members_actions(pair: Path) -> None:
    # From rest the command in force is 0 for every member, so (no step reaching a bound) the
    # first SI action is linear in the agent's action: the mean of the lone members' actions.
    for distance_m, offset_px in [(1.3, 40.0), (2.0, -120.0), (0.8, 0.0)]:
        obs = np.array([distance_m, offset_px], np.float32)
        alone = [PPOPolicy(pair / m).act(obs) for m in ("seed-0", "seed-1")]
        together = make_policy(str(pair)).act(obs)
        assert not np.allclose(alone[0], alone[1])  # the members differ
        np.testing.assert_allclose(together, (alone[0] + alone[1]) / 2, rtol=0, atol=1e-6)


def test_identical_members_act_as_the_lone_agent_for_a_whole_episode(tmp_path: Path) -> None:
    # (a + a) / 2 == a exactly, so an ensemble of two copies is the lone agent bit for bit: the
    # shared pipeline carries the command in force as the lone agent's does.
    copy_agent(tmp_path / "a")
    copy_agent(tmp_path / "b")
    write(tmp_path, ["a", "b"])
    lone = run_episode("ppo", "curve", 3).log
    both = run_episode(str(tmp_path), "curve", 3).log
    assert len(lone) > 100
    for column in ("action_v_mps", "action_w_radps", "robot_x_m"):
        np.testing.assert_array_equal(both[column], lone[column])


def test_the_mean_drives_the_shared_command_over_an_episode(pair: Path) -> None:
    # Not the lone agents' actions averaged after the fact: their commands in force drift
    # apart, while the ensemble's command is one.
    ensemble = run_episode(str(pair), "straight", 0).log
    lone = [run_episode(str(pair / m), "straight", 0).log for m in ("seed-0", "seed-1")]
    v = ensemble["action_v_mps"].to_numpy()
    assert not np.array_equal(v, lone[0]["action_v_mps"].to_numpy()[: len(v)])
    assert not np.array_equal(v, lone[1]["action_v_mps"].to_numpy()[: len(v)])
    assert ensemble["in_frame"].all()


def test_batched_acting_equals_acting_lane_by_lane(pair: Path) -> None:
    rng = np.random.default_rng(1)
    rows = rng.uniform([0.5, -300.0], [3.0, 300.0], (20, 4, 2)).astype(np.float32)
    batch = make_policy(str(pair))
    batch.reset_batch(4)
    lanes = [make_policy(str(pair)) for _ in range(4)]
    for step in rows:
        together = batch.act_batch(step)
        alone = np.stack([p.act(step[i]) for i, p in enumerate(lanes)])
        np.testing.assert_array_equal(together, alone)
    with pytest.raises(ValueError, match=r"reset_batch\(3\)"):
        batch.act_batch(rows[0, :3])


def test_reset_forgets_the_previous_episode(pair: Path) -> None:
    policy = make_policy(str(pair))
    obs = np.array([1.4, 60.0], np.float32)
    first = policy.act(obs)
    for _ in range(10):
        policy.act(np.array([2.5, -200.0], np.float32))
    policy.reset()
    np.testing.assert_array_equal(policy.act(obs), first)


def test_ensemble_survives_pickling_by_path(pair: Path) -> None:
    policy = make_policy(str(pair))
    copy = pickle.loads(pickle.dumps(policy))
    obs = np.array([1.3, 50.0], np.float32)
    assert copy.name == policy.name
    np.testing.assert_array_equal(copy.act(obs), policy.act(obs))


def test_an_ensemble_given_a_relative_path_survives_pickling_in_another_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """It was rebuilt from the path as given, which a worker's folder does not hold."""
    monkeypatch.chdir(AGENTS)
    policy = EnsemblePolicy("ppo_ensemble")
    monkeypatch.chdir(tmp_path)
    copy = pickle.loads(pickle.dumps(policy))
    assert (policy.name, policy.path) == ("ppo_ensemble", "ppo_ensemble")  # as given
    assert copy.name == "ppo_ensemble"
    assert Path(copy.path) == AGENTS.absolute() / "ppo_ensemble"
    assert [Path(m) for m in copy.members] == [AGENTS.absolute() / m for m in policy.members]
    for obs in ([1.3, 50.0, 4.0], [2.2, -140.0, 1.5]):  # it reads the reading ahead too
        seen = np.array(obs, np.float32)
        np.testing.assert_array_equal(copy.act(seen), policy.act(seen))


def test_members_that_see_the_env_differently_are_refused_naming_the_difference(pair: Path) -> None:
    config = pair / "seed-1" / "config.yaml"
    data = yaml.safe_load(config.read_text(encoding="utf-8"))
    for entry in data["hyperparams"]["vec_env_wrapper"]:
        if "train.wrappers.VecIncrementalAction" in entry:
            entry["train.wrappers.VecIncrementalAction"]["max_change"] = [0.2, 0.3]
    config.write_text(yaml.safe_dump(data), encoding="utf-8")
    with pytest.raises(AgentLoadError, match=r"seed-1 does not see the env.*feature steps"):
        make_policy(str(pair))


def test_members_may_differ_in_reward_shaping(pair: Path) -> None:
    config = pair / "seed-1" / "config.yaml"
    data = yaml.safe_load(config.read_text(encoding="utf-8"))
    for entry in data["hyperparams"]["vec_env_wrapper"]:
        if "train.wrappers.VecShapedReward" in entry:
            entry["train.wrappers.VecShapedReward"]["offset_weight"] = 9.0
    config.write_text(yaml.safe_dump(data), encoding="utf-8")
    assert len(make_policy(str(pair)).members) == 2


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("members: [seed-0]\n", "at least two run folders"),
        ("members: seed-0\n", "at least two run folders"),
        ("other: 1\n", "at least two run folders"),
        ("members: [seed-0, seed-0]\n", "listed twice"),
        ("members: [seed-0, 3]\n", "run folder's path"),
        ("members: [seed-0\n", r"not valid YAML: line 2, column 1: expected ',' or '\]'"),
        # PyYAML alone keeps the second list: the ensemble would not be the one the file shows
        (
            "members: [seed-0, seed-1]\nmembers: [seed-1, seed-0]\n",
            r"not valid YAML: line 2, column 1: found the key 'members' twice",
        ),
        ("\udcff", "not a UTF-8 text file"),
    ],
)
def test_malformed_ensemble_files_are_named(pair: Path, text: str, message: str) -> None:
    (pair / ENSEMBLE).write_bytes(text.encode("utf-8", "surrogateescape"))  # "\udcff": 0xff
    with pytest.raises(AgentLoadError, match=message) as error:
        make_policy(str(pair))
    assert str(pair / ENSEMBLE) in str(error.value)


def test_a_missing_member_names_its_file(pair: Path) -> None:
    write(pair, ["seed-0", "seed-7"])
    with pytest.raises(AgentLoadError, match=r"seed-7: no such agent"):
        make_policy(str(pair))


def test_a_missing_ensemble_file_is_named(tmp_path: Path) -> None:
    with pytest.raises(AgentLoadError, match=r"ensemble\.yaml: ensemble file not found"):
        EnsemblePolicy(tmp_path)


def _copy_shipped(source: Path, folder: Path) -> Path:
    folder.mkdir()
    for name in FILES:
        shutil.copy(source / name, folder / name)
    return folder


def test_members_that_read_ahead_make_an_ensemble_that_reads_ahead(tmp_path: Path) -> None:
    """Two copies of the shipped agent that reads ahead: the ensemble names the reading as its
    members do, evaluation gives it the reading (its episode is the lone agent's, frame for
    frame), and a member that reads no reading beside one that does is refused."""
    ahead = DEFAULT_AGENT.parent / "ppo_ahead"
    for k in (0, 1):
        _copy_shipped(ahead, tmp_path / f"seed-{k}")
    ensemble = make_policy(str(write(tmp_path, ["seed-0", "seed-1"])))
    lone = make_policy("ppo_ahead")
    assert ensemble.reads_ahead == lone.reads_ahead is not None
    assert ensemble.env_overrides == lone.env_overrides
    mine, theirs = run_episode(ensemble, "crossing", 3).log, run_episode(lone, "crossing", 3).log
    assert mine["obs_ahead_m"].notna().all()
    action = ["action_v_mps", "action_w_radps", "obs_ahead_m"]
    np.testing.assert_array_equal(mine[action].to_numpy(), theirs[action].to_numpy())
    copy_agent(tmp_path / "plain")
    write(tmp_path, ["seed-0", "plain"])
    with pytest.raises(AgentLoadError, match=r"plain does not see the env.*reading ahead"):
        make_policy(str(tmp_path))


@pytest.mark.parametrize("twice", ["./seed-0", "seed-0/", "seed-0/model.zip", "../{home}/seed-0"])
def test_a_member_listed_twice_under_two_spellings_is_refused(pair: Path, twice: str) -> None:
    """``[seed-0, ./seed-0]`` loaded, and acted as seed-0 alone."""
    write(pair, ["seed-0", twice.format(home=pair.name)])
    with pytest.raises(AgentLoadError, match="a member is listed twice") as error:
        make_policy(str(pair))
    assert str(error.value).startswith(f"{pair / ENSEMBLE}: ")
    assert str((pair / "seed-0" / "model.zip").resolve()) in str(error.value)


def test_a_member_file_linked_from_elsewhere_is_the_same_member(pair: Path) -> None:
    (pair / "alias").symlink_to(pair / "seed-1", target_is_directory=True)
    write(pair, ["seed-0", "seed-1", "alias"])
    with pytest.raises(AgentLoadError, match="'seed-1' and 'alias' are the same agent"):
        make_policy(str(pair))


@pytest.mark.parametrize(
    ("member", "message"),
    [
        (".", "member '.' is the ensemble's own folder"),
        ("../{home}", "is the ensemble's own folder"),
        ("inner", "member 'inner' is itself an ensemble"),
        ("inner/ensemble.yaml", "member 'inner/ensemble.yaml' is itself an ensemble"),
        (str(DEFAULT_AGENT.parent / "ppo_ensemble"), "is itself an ensemble"),
    ],
)
def test_the_ensembles_own_folder_or_another_ensemble_is_refused_as_a_member(
    pair: Path, member: str, message: str
) -> None:
    """They failed with a misleading 'model.zip: model file not found'."""
    inner = pair / "inner"
    inner.mkdir()
    write(inner, ["../seed-0", "../seed-1"])
    write(pair, ["seed-0", member.format(home=pair.name)])
    with pytest.raises(AgentLoadError, match=re.escape(message)) as error:
        make_policy(str(pair))
    assert str(error.value).startswith(f"{pair / ENSEMBLE}: ")


def test_an_ensemble_refuses_observations_that_are_not_real_numbers(pair: Path) -> None:
    policy = make_policy(str(pair))
    with pytest.raises(ValueError, match="dtype <U"):
        policy.act(np.array(["1.4", "30"]))
    policy.reset_batch(1)
    with pytest.raises(ValueError, match="dtype complex128"):
        policy.act_batch(np.array([[1.4 + 0j, 30]]))
