"""train/edit.py and ``follow-train --add-step``: a step put into a trained agent's view."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from policies.learned.ppo import AGENTS, PPOPolicy
from train.cli import main
from train.edit import EDITED, add_step, change_step, parse_step
from train.export import MANIFEST, check_export, export_agent, sha256

GATE = "train.wrappers.VecJumpGate"
AGE = "train.wrappers.VecObservationAge"
STEP = "{train.wrappers.VecJumpGate: {max_jump_m: 0.5, accept_after: 10}}"


@pytest.fixture
def agent(tmp_path: Path) -> Path:
    """A copy of the shipped agent, as its export wrote it (no gate in its view)."""
    folder = tmp_path / "agent"
    shutil.copytree(AGENTS / "ppo", folder)
    return folder


def _view(folder: Path) -> list:
    config = yaml.safe_load((folder / "config.yaml").read_text())
    return config["hyperparams"]["vec_env_wrapper"]


def _files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def test_the_step_goes_into_the_view_the_card_and_the_manifest(agent: Path) -> None:
    before = _view(agent)
    recorded = json.loads((agent / MANIFEST).read_text())
    done = add_step(agent, STEP, AGE, command="follow-train --add-step agent")
    view = _view(agent)
    entry = {GATE: {"max_jump_m": 0.5, "accept_after": 10, "in_training": False}}
    index = [next(iter(e)) for e in before].index(AGE)
    assert view == [*before[:index], entry, *before[index:]]
    assert (done.entry, done.index, done.before) == (entry, index, AGE)
    card = (agent / "MODEL_CARD.md").read_text()
    assert card.count(EDITED) == 1
    assert (
        "`follow-train --add-step agent` added `train.wrappers.VecJumpGate: {max_jump_m: 0.5, "
        "accept_after: 10, in_training: false}` to the agent's view, before "
        "`train.wrappers.VecObservationAge`" in card
    )
    assert "measured without it" in card
    # the export's record knows the new files as its own: a new export needs no --force
    manifest = json.loads((agent / MANIFEST).read_text())
    for name in ("config.yaml", "MODEL_CARD.md"):
        assert manifest["files"][name][-1] == sha256(agent / name)
        assert manifest["files"][name] == [*recorded["files"][name], sha256(agent / name)]
    assert len(manifest["edited_utc"]) == len(recorded.get("edited_utc", [])) + 1
    check_export(agent)
    # the other files are the export's, byte for byte
    for name in ("model.zip", "vecnormalize.pkl", "learning_curve.png"):
        assert (agent / name).read_bytes() == (AGENTS / "ppo" / name).read_bytes()


def test_the_edited_agent_acts_as_before_until_the_detection_jumps(agent: Path) -> None:
    plain = PPOPolicy(AGENTS / "ppo")
    add_step(agent, STEP)  # first: innermost
    assert next(iter(_view(agent)[0])) == GATE
    gated = PPOPolicy(agent)
    assert gated.name == str(agent)
    plain.reset()
    gated.reset()
    walk = [np.array([1.2 + 0.01 * k, 20.0 - k], dtype=np.float32) for k in range(15)]
    for obs in walk:  # a person walking: no jump, the gate lets every reading through
        np.testing.assert_array_equal(gated.act(obs), plain.act(obs))
    jump = np.array([4.5, 300.0], dtype=np.float32)  # a bystander 3 m further, 300 px aside
    assert not np.array_equal(gated.act(jump), plain.act(jump))


def test_a_second_step_adds_a_line_to_the_same_section(tmp_path: Path) -> None:
    agent = tmp_path / "line"
    shutil.copytree(AGENTS / "ppo_line", agent)  # its view has room for two steps
    card = (agent / "MODEL_CARD.md").read_text()
    earlier = card.split(EDITED)[1].strip().splitlines() if EDITED in card else []
    configs = len(json.loads((agent / MANIFEST).read_text())["files"]["config.yaml"])
    add_step(agent, f"{{train.wrappers.VecScaleObservation: {{scale: {[1.0] * 25}}}}}")
    add_step(agent, "{train.wrappers.VecJumpGate: {max_jump_m: null}}")
    assert [next(iter(e)) for e in _view(agent)[:2]] == [GATE, "train.wrappers.VecScaleObservation"]
    PPOPolicy(agent)  # loads
    card = (agent / "MODEL_CARD.md").read_text()
    assert card.count(EDITED) == 1
    assert card.count("to the agent's view") == 2
    section = card.split(EDITED)[1].strip().splitlines()
    assert len(section) == len(earlier) + 2  # one bullet an edit, no blank line between
    assert section[: len(earlier)] == earlier
    assert all(line.startswith("- ") for line in section)
    assert len(json.loads((agent / MANIFEST).read_text())["files"]["config.yaml"]) == configs + 2


@pytest.mark.parametrize(
    ("step", "before", "error"),
    [
        ("train.wrappers.VecShapedReward", None, "not a step of an agent's view"),
        ("{train.wrappers.VecJumpGate: {in_training: true}}", None, "in_training=True"),
        ("{train.wrappers.VecJumpGate: {jump: 1}}", None, "'jump' is not one of its arguments"),
        ("{train.wrappers.VecJumpGate: {max_jump_m: -1}}", None, "max_jump_m=-1 is out of range"),
        ("foo.Bar", None, "does not import"),
        ("[1", None, "not valid YAML"),
        ("[1, 2]", None, "give a step's name"),
        (GATE, "train.wrappers.VecNope", "--before train.wrappers.VecNope: not in the agent's"),
        ("train.wrappers.VecScaleObservation", None, "already in the agent's view"),
    ],
)
def test_a_bad_step_is_refused_and_nothing_is_written(
    agent: Path, step: str, before: str | None, error: str
) -> None:
    files = _files(agent)
    with pytest.raises(ValueError, match=error):
        add_step(agent, step, before)
    assert _files(agent) == files


@pytest.mark.parametrize(
    ("step", "error"),
    [
        (AGE, r"turns observations \(25,\) into \(26,\) and actions \(3,\) into \(3,\)"),
        ("{train.wrappers.VecStackFrames: {n_stack: 2}}", "must keep both shapes"),
    ],
)
def test_a_step_that_changes_a_shape_is_refused(tmp_path: Path, step: str, error: str) -> None:
    agent = tmp_path / "line"
    shutil.copytree(AGENTS / "ppo_line", agent)
    files = _files(agent)
    with pytest.raises(ValueError, match=error):
        add_step(agent, step)
    assert _files(agent) == files


def test_a_configuration_without_the_env_spaces_is_named(agent: Path) -> None:
    config = yaml.safe_load((agent / "config.yaml").read_text())
    del config["env_spaces"]
    (agent / "config.yaml").write_text(yaml.safe_dump(config))
    files = _files(agent)
    with pytest.raises(ValueError, match=r"agent/config\.yaml: env_spaces is missing"):
        add_step(agent, STEP)
    assert _files(agent) == files


def test_a_folder_that_is_no_agent_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="no such folder"):
        add_step(tmp_path / "missing", STEP)
    (tmp_path / "afile").write_text("x")
    with pytest.raises(ValueError, match="afile: is a file, not a folder"):
        add_step(tmp_path / "afile", STEP)
    with pytest.raises(ValueError, match=r"no model\.zip in it"):
        add_step(tmp_path, STEP)


def test_files_changed_since_the_export_need_force(agent: Path) -> None:
    card = agent / "MODEL_CARD.md"
    card.write_text(card.read_text() + "\nmy notes\n")
    files = _files(agent)
    with pytest.raises(ValueError, match=r"MODEL_CARD\.md changed since the export"):
        add_step(agent, STEP)
    assert _files(agent) == files
    add_step(agent, STEP, force=True)
    assert "my notes" in card.read_text()
    assert next(iter(_view(agent)[0])) == GATE


def test_a_run_folder_without_a_manifest_is_edited_too(agent: Path, tmp_path: Path) -> None:
    (agent / MANIFEST).unlink()  # a run folder: no export wrote it
    add_step(agent, STEP)
    assert not (agent / MANIFEST).exists()
    assert next(iter(_view(agent)[0])) == GATE
    # and an export of it carries the step
    export_agent(agent, tmp_path / "exported")
    assert next(iter(_view(tmp_path / "exported")[0])) == GATE


def test_parse_step_takes_a_name_or_a_one_entry_mapping() -> None:
    assert parse_step(GATE) == (GATE, {})
    assert parse_step(f"{{{GATE}: }}") == (GATE, {})
    assert parse_step(STEP) == (GATE, {"max_jump_m": 0.5, "accept_after": 10})


def test_the_command_line_adds_the_step_or_says_in_one_line_why_not(
    agent: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["--add-step", str(agent), "--step", STEP, "--before", AGE]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"Added {GATE} ")
    assert "config.yaml, MODEL_CARD.md, follow-train-export.json" in out
    # the card quotes the command as a shell would take it
    assert (
        f"`follow-train --add-step {agent} --step '{STEP}' --before {AGE}`"
        in (agent / "MODEL_CARD.md").read_text()
    )
    for argv, error in [
        (["--add-step", str(agent)], "--add-step needs --step"),
        (["--step", GATE], "--step and --before apply to --add-step or --change-step only"),
        (["--add-step", str(agent), "--step", GATE, "--seed", "3"], "--seed: --add-step trains"),
        (["--add-step", str(agent), "--step", GATE], "already in the agent's view"),
    ]:
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith("follow-train: error: "), err
        assert error in err, err
        assert err.count("\n") == 1


@pytest.fixture
def ensemble(tmp_path: Path) -> Path:
    """An ensemble of two copies of the shipped agent (its members as an export wrote them)."""
    folder = tmp_path / "study"
    for member in ("seed-0", "seed-1"):
        shutil.copytree(AGENTS / "ppo", folder / member)
    (folder / "ensemble.yaml").write_text("members: [seed-0, seed-1]\n")
    return folder


def test_a_step_goes_into_every_member_of_an_ensemble(
    ensemble: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from policies.learned.ensemble import EnsemblePolicy

    before = _view(ensemble / "seed-0")
    assert main(["--add-step", str(ensemble), "--step", STEP, "--before", AGE]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"Added {GATE} ")
    assert f"of {ensemble / 'seed-0'}/, {ensemble / 'seed-1'}/" in out
    entry = {GATE: {"max_jump_m": 0.5, "accept_after": 10, "in_training": False}}
    index = [next(iter(e)) for e in before].index(AGE)
    for member in ("seed-0", "seed-1"):
        assert _view(ensemble / member) == [*before[:index], entry, *before[index:]]
        assert EDITED in (ensemble / member / "MODEL_CARD.md").read_text()
        check_export(ensemble / member)  # each member's manifest knows its new files
    EnsemblePolicy(ensemble)  # the members still see the env alike
    # run again: every member has it
    with pytest.raises(ValueError, match="is already in the view of every member"):
        add_step(ensemble, STEP, AGE)


def test_an_ensemble_is_edited_whole_or_not_at_all(ensemble: Path) -> None:
    card = ensemble / "seed-1" / "MODEL_CARD.md"
    card.write_text(card.read_text() + "\nmy notes\n")  # the second member needs --force
    files = {m: _files(ensemble / m) for m in ("seed-0", "seed-1")}
    with pytest.raises(ValueError, match=r"seed-1: MODEL_CARD\.md changed since the export"):
        add_step(ensemble, STEP)
    assert {m: _files(ensemble / m) for m in files} == files  # the first member too
    # a member that already has this very entry (an interrupted run) is left as it is
    done = add_step(ensemble / "seed-0", STEP)
    assert done.members == ()
    first = _files(ensemble / "seed-0")
    done = add_step(ensemble, STEP, force=True)
    assert done.members == (ensemble / "seed-1",)
    assert _files(ensemble / "seed-0") == first
    assert _view(ensemble / "seed-1") == _view(ensemble / "seed-0")
    # the same step with other arguments in one member is refused
    other = "{train.wrappers.VecJumpGate: {max_jump_m: 0.7}}"
    with pytest.raises(ValueError, match="already in the agent's view"):
        add_step(ensemble, other)


def test_a_step_that_would_leave_the_members_seeing_the_env_apart_is_refused(
    ensemble: Path,
) -> None:
    add_step(ensemble / "seed-0", STEP)  # innermost in one member
    files = {m: _files(ensemble / m) for m in ("seed-0", "seed-1")}
    # before the age in the other: the same steps in another order
    with pytest.raises(ValueError, match="the edited ensemble would not load: ") as error:
        add_step(ensemble, STEP, AGE)
    assert f"member {ensemble / 'seed-1'} does not see the env as {ensemble / 'seed-0'}" in str(
        error.value
    )
    assert ".add-step-" not in str(error.value)  # no temporary folder named
    assert {m: _files(ensemble / m) for m in files} == files


INCREMENTAL = "train.wrappers.VecIncrementalAction"
# ppo_ahead's turn kept behind an occluder (docs/learned/study.md, "Keeping the turn through a
# gap, tried"): the age is observation entry 3, the reading ahead entry 2
KEEP = f"{{{INCREMENTAL}: {{held_index: 3, held_keep: [false, true], ahead_index: 2}}}}"


@pytest.fixture
def ahead(tmp_path: Path) -> Path:
    folder = tmp_path / "ahead"
    shutil.copytree(AGENTS / "ppo_ahead", folder)
    return folder


def test_a_step_in_the_view_gets_new_arguments_and_the_card_says_which(
    ahead: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    recorded = json.loads((ahead / MANIFEST).read_text())
    before = _view(ahead)
    assert main(["--change-step", str(ahead), "--step", KEEP]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"Changed {INCREMENTAL} to {{'max_change': [0.2, 0.15], ")
    assert "in the view of the agent in" in out
    view = _view(ahead)
    index = [next(iter(e)) for e in before].index(INCREMENTAL)
    assert view[:index] == before[:index]
    assert view[index + 1 :] == before[index + 1 :]
    assert view[index] == {
        INCREMENTAL: {
            "max_change": [0.2, 0.15],
            "reading_index": 0,
            "held_index": 3,
            "held_keep": [False, True],
            "ahead_index": 2,
        }
    }
    card = (ahead / "MODEL_CARD.md").read_text()
    assert (
        f"changed `{INCREMENTAL}` in the agent's view to `{{held_index: 3, held_keep: [false, "
        "true], ahead_index: 2}` (it was `{held_index: default, held_keep: default, "
        "ahead_index: default}`)" in card
    )
    assert "measured with them" in card
    manifest = json.loads((ahead / MANIFEST).read_text())
    assert manifest["files"]["config.yaml"] == [
        *recorded["files"]["config.yaml"],
        sha256(ahead / "config.yaml"),
    ]
    check_export(ahead)
    # the changed agent loads and keeps its turn through a gap behind the column
    policy = PPOPolicy(ahead)
    policy.reset()
    assert np.all(np.isfinite(policy.act(np.array([1.0, 0.0, 1.0], dtype=np.float32))))
    with pytest.raises(ValueError, match="changes nothing"):
        change_step(ahead, KEEP)


@pytest.mark.parametrize(
    ("step", "error"),
    [
        (GATE, "give the arguments to change"),
        (f"{{{GATE}: {{in_training: true}}}}", "in_training is not changed after training"),
        ("{train.wrappers.VecStackFrames: {n_stack: 2}}", r"must keep its shapes"),
        (
            f"{{{INCREMENTAL}: {{held_index: 3, held_keep: [true]}}}}",
            r"held_keep=\[True\] is out of range",
        ),
        (f"{{{INCREMENTAL}: {{held_index: 3}}}}", "serves nothing"),
        (f"{{{INCREMENTAL}: {{jump: 1}}}}", "'jump' is not one of its arguments"),
        ("{train.wrappers.VecRescaleObservation: {a: 1}}", "does not import"),
        ("{train.wrappers.VecShapedReward: {alive_bonus: 2.0}}", "not a step of an agent's"),
    ],
)
def test_a_bad_change_is_refused_and_nothing_is_written(ahead: Path, step: str, error: str) -> None:
    files = _files(ahead)
    with pytest.raises(ValueError, match=error):
        change_step(ahead, step)
    assert _files(ahead) == files


def test_a_step_not_in_the_view_is_named_with_the_view(agent: Path) -> None:
    files = _files(agent)
    with pytest.raises(ValueError, match=f"--step {GATE}: not in the agent's view .*entries: "):
        change_step(agent, STEP)
    assert _files(agent) == files


def test_a_change_goes_into_every_member_of_an_ensemble(ensemble: Path) -> None:
    step = f"{{{INCREMENTAL}: {{max_change: [0.2, 0.1]}}}}"
    done = change_step(ensemble, step)
    assert done.members == (ensemble / "seed-0", ensemble / "seed-1")
    assert done.old["max_change"] == [0.2, 0.15]
    assert done.new["max_change"] == [0.2, 0.1]
    assert _view(ensemble / "seed-0") == _view(ensemble / "seed-1")
    with pytest.raises(ValueError, match="has these arguments in the view of every member"):
        change_step(ensemble, step)


def test_the_command_line_refuses_mixed_edit_options_in_one_line(
    ahead: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for argv, error in [
        (["--change-step", str(ahead)], "--change-step needs --step"),
        (["--change-step", str(ahead), "--step", KEEP, "--before", AGE], "--before: --change"),
        (["--change-step", str(ahead), "--add-step", str(ahead), "--step", KEEP], "give one"),
        (["--change-step", str(ahead), "--step", KEEP, "--seed", "3"], "it takes --step and"),
        # named as typed: there is no --progress option
        (["--add-step", str(ahead), "--step", KEEP, "--no-progress"], "--no-progress: --add-step"),
    ]:
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith("follow-train: error: "), err
        assert error in err, err
        assert err.count("\n") == 1


def test_a_step_argument_given_twice_is_refused(agent: Path) -> None:
    files = _files(agent)
    with pytest.raises(ValueError, match=r"--step .*found the key 'max_jump_m' twice"):
        add_step(agent, f"{{{GATE}: {{max_jump_m: 0.5, max_jump_m: 0.7}}}}")
    assert _files(agent) == files


@pytest.mark.parametrize(
    ("name", "error"),
    [("model.zip", "not a readable stable-baselines3"), ("vecnormalize.pkl", "not VecNormalize")],
)
def test_a_damaged_agent_file_is_named_where_it_is(agent: Path, name: str, error: str) -> None:
    # The load check reads the files through a temporary folder; the message names the
    # agent's own file, not the temporary one, which is gone when the user reads it.
    (agent / name).write_bytes((agent / name).read_bytes()[:100])
    files = _files(agent)
    with pytest.raises(ValueError, match=error) as caught:
        add_step(agent, STEP)
    assert str(caught.value).startswith(f"{agent / name}: "), caught.value
    assert ".add-step-" not in str(caught.value)
    assert _files(agent) == files


@pytest.mark.parametrize("name", ["config.yaml", "MODEL_CARD.md"])
def test_a_file_that_is_not_utf8_is_named(agent: Path, name: str) -> None:
    path = agent / name
    path.write_bytes(b"\xff\xfe" + path.read_bytes())
    files = _files(agent)
    with pytest.raises(ValueError, match=rf"{name}: .*not a UTF-8 text file"):
        add_step(agent, STEP, force=True)
    assert _files(agent) == files
