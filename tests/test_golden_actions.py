"""The shipped agents act as recorded on recorded observations, on any CPU (tests/golden/)."""

from __future__ import annotations

import importlib.util
import shutil
from pathlib import Path

import numpy as np
import pytest

_spec = importlib.util.spec_from_file_location(
    "golden_actions", Path(__file__).parent / "golden" / "actions.py"
)
golden = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(golden)  # type: ignore[union-attr]

with np.load(golden.GOLDEN) as _archive:
    RECORDED = {name: _archive[name] for name in _archive.files}


def test_every_shipped_agent_and_scenario_was_recorded() -> None:
    names = {golden.key(folder, scenario) for folder, _, scenario in golden.cases()}
    assert {name.rsplit("/", 1)[0] for name in RECORDED} == names
    assert {"ppo_ahead", "ppo_mecanum", "ppo_line"} <= {n.split("/")[0] for n in names}


@pytest.mark.parametrize(("folder", "task", "scenario"), golden.cases())
def test_a_shipped_agent_acts_as_recorded(folder: str, task: str, scenario: str) -> None:
    name = golden.key(folder, scenario)
    obs, recorded = RECORDED[f"{name}/obs"], RECORDED[f"{name}/actions"]
    assert len(obs) == len(recorded) > 50
    actions = golden.replay(folder, task, obs)
    np.testing.assert_allclose(actions, recorded, rtol=0, atol=golden.ATOL, err_msg=name)
    assert np.abs(recorded).max() > 100 * golden.ATOL  # the agent moved: the check can fail


def test_a_changed_view_is_caught(tmp_path: Path) -> None:
    # ppo_ahead with a smaller speed step (IncrementalAction's max_change) than it was trained
    # with: the check must see that by far more than ATOL on the recorded straight walk
    import yaml

    from policies.learned.ppo import AGENTS, PPOPolicy

    agent = tmp_path / "ppo_ahead"
    shutil.copytree(AGENTS / "ppo_ahead", agent)
    config = yaml.safe_load((agent / "config.yaml").read_text())
    steps = config["hyperparams"]["vec_env_wrapper"]
    (incremental,) = [e for e in steps if "train.wrappers.VecIncrementalAction" in e]
    incremental["train.wrappers.VecIncrementalAction"]["max_change"] = [0.1, 0.15]
    (agent / "config.yaml").write_text(yaml.safe_dump(config))
    name = golden.key("ppo_ahead", "straight")
    obs, recorded = RECORDED[f"{name}/obs"], RECORDED[f"{name}/actions"]
    actions = golden.actions_of(PPOPolicy(agent), obs)
    assert np.abs(actions - recorded).max() > 100 * golden.ATOL


def test_recording_one_agent_keeps_the_others(tmp_path: Path, monkeypatch, capsys) -> None:
    kept = tmp_path / "actions.npz"
    shutil.copy(golden.GOLDEN, kept)
    monkeypatch.setattr(golden, "GOLDEN", kept)
    assert golden.record(["no_such_agent"]) == 2
    assert "no_such_agent" in capsys.readouterr().err
    # one agent (the line tracer, the quickest to run) recorded anew: a new closed-loop episode
    # (its length may differ by CPU), every other agent's arrays left as they were
    assert golden.record(["ppo_line"]) == 0
    with np.load(kept) as archive:
        again = {name: archive[name] for name in archive.files}
    assert set(again) == set(RECORDED)
    others = [name for name in RECORDED if not name.startswith("ppo_line/")]
    assert len(others) > len(RECORDED) // 2
    for name in others:
        np.testing.assert_array_equal(again[name], RECORDED[name], err_msg=name)
