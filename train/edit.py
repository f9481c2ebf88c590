"""``follow-train --add-step DIR --step STEP [--before NAME]``: put a step into a trained
agent's view without training it again.

A filter measured in front of an agent trained without it (the jump gate in front of
``ppo_ahead``: README, "A step left out of training") is one more ``vec_env_wrapper`` entry of
the agent's ``config.yaml``, marked ``in_training: false``: the exported agent's pipeline runs
it in evaluation and on the robot, and a run resumed from the folder passes observations
through it, as the agent was trained. This command writes that entry, so that nobody edits an
agent's files by hand:

- ``DIR`` is an agent folder: a run folder of ``follow-train``, or a folder an export wrote;
  or an ensemble's folder (``ensemble.yaml``, :mod:`policies.learned.ensemble`), whose members
  must see the env alike: the step then goes into every member's view, each checked (and the
  ensemble loaded with the new views) before any is written.
- ``STEP`` is YAML: ``train.wrappers.VecJumpGate`` or ``{train.wrappers.VecJumpGate:
  {max_jump_m: 0.5}}``. It must be a step of an agent's view (:data:`FEATURES`) that keeps the
  observation and action shapes it is given; ``in_training: false`` is added (``true`` is
  refused: the weights were trained without it).
- ``--before NAME`` puts it before the first entry of that name; without it, it goes first
  (innermost: it sees the env's own observation).

Checked before anything is written: the step's class and arguments, the shapes, and the agent
loading with the new view (its model and statistics, as ``make_policy`` loads it). Then the
model card gets a line under "Edited after training" (when, the command, the step, and that
the scores above were measured without it), and ``config.yaml`` the entry; each file is
replaced atomically. In a folder an export wrote, the manifest (:mod:`train.export`) lists the
new contents beside the exported ones, so a later export over the folder still recognises it
as its own; files changed since that export by anything else are refused unless ``force``.

``follow-train --change-step DIR --step STEP`` changes arguments of a step already in the view
instead (the turn kept behind an occluder, ``held_keep`` with ``ahead_index``, put into a
shipped agent's command steps): STEP's arguments replace the entry's, the others stay, the
step keeps its place, the shapes it gives and whether it acts in training. It is checked and
written as above, and the card's line gives the old values beside the new ones.
"""

from __future__ import annotations

import copy
import hashlib
import json
import os
import tempfile
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import yaml

from follow_env.sim.atomic import atomic_write_text
from follow_env.sim.checks import load_yaml, utf8_problem
from policies.learned.boxes import Box
from policies.learned.ensemble import ENSEMBLE, EnsemblePolicy, member_folders
from policies.learned.feature import IN_TRAINING, split_in_training, wrapper_entries
from policies.learned.features import FEATURES, Pipeline
from policies.learned.ppo import AgentLoadError
from train import run as runs
from train.config import wrapper_specs
from train.export import MANIFEST, read_manifest, sha256

__all__ = ["EDITED", "AddedStep", "ChangedStep", "add_step", "change_step", "parse_step"]

#: The model card's section that lists the edits made after training.
EDITED = "## Edited after training"


@dataclass(frozen=True)
class AddedStep:
    """What :func:`add_step` did.

    :param folder: the agent folder. :param entry: the ``vec_env_wrapper`` entry written.
    :param index: its place in the list (0: innermost). :param before: the entry it precedes.
    :param members: for an ensemble, the member folders edited (those that lacked the step).
    """

    folder: Path
    entry: dict[str, dict[str, Any]]
    index: int
    before: str | None
    members: tuple[Path, ...] = ()


@dataclass(frozen=True)
class ChangedStep:
    """What :func:`change_step` did.

    :param folder: the agent folder. :param name: the step changed. :param old: its arguments
    before, :param new: after (in the first folder edited). :param index: its place in the
    list. :param members: for an ensemble, the member folders edited.
    """

    folder: Path
    name: str
    old: dict[str, Any]
    new: dict[str, Any]
    index: int
    members: tuple[Path, ...] = ()


def parse_step(text: str) -> tuple[str, dict[str, Any]]:
    """``--step``'s YAML as ``(dotted.name, kwargs)``.

    :raises ValueError: for text that is not a name or a one-entry mapping of a name to its
        arguments.
    """
    try:
        value = load_yaml(text)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        at = f" at column {mark.column + 1}" if mark is not None else ""
        problem = getattr(e, "problem", None) or type(e).__name__
        raise ValueError(f"--step {text!r}: not valid YAML ({problem}{at})") from None
    if isinstance(value, str):
        return value, {}
    if isinstance(value, dict) and len(value) == 1:
        name, kwargs = next(iter(value.items()))
        kwargs = {} if kwargs is None else kwargs
        if isinstance(name, str) and isinstance(kwargs, dict):
            return name, dict(kwargs)
    raise ValueError(
        f"--step {text!r}: give a step's name, or {{name: {{argument: value}}}} "
        "(e.g. '{train.wrappers.VecJumpGate: {max_jump_m: 0.5}}')"
    )


def _shapes(
    config: dict[str, Any], where: Path, inner: list[tuple[str, dict]], name: str, kwargs: dict
) -> tuple[tuple[tuple[int, ...], tuple[int, ...]], tuple[tuple[int, ...], tuple[int, ...]]]:
    """``((obs, action) shapes the steps inside give, (obs, action) shapes the step gives)``."""
    spaces = config.get("env_spaces") or {}
    try:
        obs = Box(spaces["observation"]["low"], spaces["observation"]["high"])
        act = Box(spaces["action"]["low"], spaces["action"]["high"])
    except (KeyError, TypeError, ValueError) as e:
        raise ValueError(f"{where}: env_spaces is missing or not usable ({e!r})") from None
    steps = Pipeline.from_wrappers(inner)
    view = Pipeline(steps, obs, act, 1)
    short = name.rsplit(".", 1)[-1].removeprefix("Vec")
    _, own = split_in_training(kwargs, name)
    step = FEATURES[short](**own)
    step.owner = name
    out_obs, out_act = step.bind(view.observation_box, view.action_box, 1)
    inside = (view.observation_box.shape, view.action_box.shape)
    return inside, (out_obs.shape, out_act.shape)


def _check_shapes(
    config: dict[str, Any], where: Path, inner: list[tuple[str, dict]], name: str, kwargs: dict
) -> None:
    """The step keeps the observation and action shapes the steps inside it give."""
    (obs, act), (out_obs, out_act) = _shapes(config, where, inner, name, kwargs)
    if (out_obs, out_act) != (obs, act):
        raise ValueError(
            f"--step {name}: turns observations {obs} into {out_obs} and actions {act} into "
            f"{out_act} there; a step added after training must keep both shapes (the network "
            "reads them)"
        )


def _linked_copy(folder: Path, config: dict[str, Any], dest: Path) -> None:
    """``dest`` made the agent of ``folder`` with ``config``: its model and statistics linked,
    the configuration written, for a load check that writes nothing in ``folder``."""
    for name in (runs.MODEL, runs.NORMALIZATION):
        if (folder / name).exists():
            os.symlink((folder / name).resolve(), dest / name)
    runs.write_config(dest, config)


def _check_loads(folder: Path, config: dict[str, Any]) -> None:
    """The agent loads with ``config`` as make_policy would load it (model and statistics)."""
    from policies.learned.ppo import PPOPolicy

    with tempfile.TemporaryDirectory(prefix=".add-step-") as tmp:
        _linked_copy(folder, config, Path(tmp))
        try:
            PPOPolicy(tmp, name=str(folder))
        except AgentLoadError as e:
            # named as the user knows it: the temporary folder is gone when the error is read
            raise AgentLoadError(_renamed(str(e), {tmp: str(folder)})) from None


def _renamed(message: str, places: dict[str, str]) -> str:
    """``message`` with each temporary path in ``places`` replaced by the user's own (the
    longest first, so that a folder does not replace part of a file inside it)."""
    for temporary in sorted(places, key=len, reverse=True):
        message = message.replace(temporary, places[temporary])
    return message


def _flow(value: dict[str, Any]) -> str:
    """``value`` as one line of flow-style YAML, for a card's line."""
    return yaml.safe_dump(value, default_flow_style=True, sort_keys=False, width=1000).strip()


def _now() -> str:
    """The UTC time to the second, ISO 8601: when an edit was made."""
    return datetime.now(UTC).isoformat(timespec="seconds")


def _card_line(command: str, entry: dict[str, dict[str, Any]], before: str | None) -> str:
    ((name, kwargs),) = entry.items()
    where = f"before `{before}`" if before else "first (innermost)"
    return (
        f"- {_now()}: `{command}` added `{name}: {_flow(kwargs)}` to the agent's view, {where}. "
        "It was not trained with it (`in_training: false`): the weights and the normalisation "
        "statistics are unchanged, and the held-out return and the scores above were measured "
        "without it."
    )


def _changed_line(command: str, name: str, old: dict[str, Any], given: dict[str, Any]) -> str:
    was = {k: old.get(k, "default") for k in given}
    return (
        f"- {_now()}: `{command}` changed `{name}` in the agent's view to `{_flow(given)}` (it "
        f"was `{_flow(was)}`). The weights and the normalisation statistics are the ones trained "
        "with the old arguments, and the held-out return and the scores above were measured "
        "with them."
    )


def add_step(
    folder: str | Path,
    step: str,
    before: str | None = None,
    *,
    force: bool = False,
    command: str = "follow-train --add-step",
) -> AddedStep:
    """Add ``step`` (``--step``'s YAML) to the view of the agent in ``folder`` (module
    docstring).

    :param folder: an agent's folder, or an ensemble's (``ensemble.yaml``): then the step goes
        into every member's view, which must stay alike. Every member is checked before any
        is written; a member that already has this very entry is left as it is, so a command
        interrupted between two members can be run again.
    :param before: the name of the entry it goes before (None: first).
    :param force: write although ``config.yaml`` or ``MODEL_CARD.md`` changed since the export
        that wrote ``folder``.
    :param command: the command line, for the model card.
    :raises ValueError: naming the folder, file, step or option, before anything is written.
    """
    folder = Path(folder)
    if not folder.is_dir():
        what = "is a file, not a folder" if folder.exists() else "no such folder"
        raise ValueError(f"--add-step {folder}: {what} (give an agent's folder)")
    name, kwargs = parse_step(step)
    _check_step(name, kwargs)
    flag = kwargs.get(IN_TRAINING, False)
    if flag is not False:
        raise ValueError(
            f"--step {name}: {IN_TRAINING}={flag!r}; the agent was trained without this step, "
            f"so it is added with {IN_TRAINING}: false (leave the argument out)"
        )
    entry = {name: {**kwargs, IN_TRAINING: False}}
    request = _Request(name, entry[name], before, force, command, change=False)
    edits, members = _apply(folder, request)
    return AddedStep(folder, entry, edits[0].index, before, members)


def change_step(
    folder: str | Path,
    step: str,
    *,
    force: bool = False,
    command: str = "follow-train --change-step",
) -> ChangedStep:
    """Change arguments of a step already in the view of the agent in ``folder``
    (``--change-step DIR --step YAML``): the arguments given replace the entry's, the others
    stay. The agent's weights were trained with the old ones, so the model card says so.

    Checked as :func:`add_step` checks (the arguments, the agent loading, an ensemble's
    members alike); the step must give the shapes it gave before, and whether it acts in
    training (``in_training``) is not changed here.

    :raises ValueError: naming the folder, file, step or argument, before anything is written.
    """
    folder = Path(folder)
    if not folder.is_dir():
        what = "is a file, not a folder" if folder.exists() else "no such folder"
        raise ValueError(f"--change-step {folder}: {what} (give an agent's folder)")
    name, kwargs = parse_step(step)
    if not kwargs:
        raise ValueError(f"--step {name}: give the arguments to change ({{name: {{arg: value}}}})")
    if IN_TRAINING in kwargs:
        raise ValueError(
            f"--step {name}: {IN_TRAINING} is not changed after training (the weights were "
            "trained with the step acting or not); leave it out"
        )
    _check_step(name, kwargs)
    edits, members = _apply(folder, _Request(name, kwargs, None, force, command, change=True))
    return ChangedStep(folder, name, edits[0].old, edits[0].new, edits[0].index, members)


def _check_step(name: str, kwargs: dict[str, Any]) -> None:
    """The step's class imports and takes ``kwargs``, and is a step of an agent's view."""
    wrapper_specs([{name: kwargs}], where="--step")
    short = name.rsplit(".", 1)[-1].removeprefix("Vec")
    if short not in FEATURES:
        known = ", ".join(f"train.wrappers.Vec{k}" for k in FEATURES)
        raise ValueError(f"--step {name}: not a step of an agent's view; the steps: {known}")


@dataclass(frozen=True)
class _Request:
    """An edit asked for: add the step ``name`` with ``kwargs`` (``before`` an entry), or
    (``change``) give the step there those arguments; ``force`` and ``command`` as given."""

    name: str
    kwargs: dict[str, Any]
    before: str | None
    force: bool
    command: str
    change: bool


def _apply(folder: Path, request: _Request) -> tuple[list[_Edit], tuple[Path, ...]]:
    """Plan the edit of the agent in ``folder`` (or of every member of the ensemble there),
    check it whole, write it; returns the edits written and, for an ensemble, their folders."""
    name, change = request.name, request.change
    if not (folder / ENSEMBLE).is_file():
        edit = _plan(folder, request, member=False)
        assert edit is not None  # a lone agent with nothing to do is refused in _plan
        _write(edit)
        return [edit], ()
    try:
        members = member_folders(folder / ENSEMBLE)
    except AgentLoadError as e:
        raise ValueError(f"{_option(change)} {folder}: {e}") from None
    edits = [_plan(m, request, member=True) for m in members]
    todo = [e for e in edits if e is not None]
    if not todo:
        done = "has these arguments in" if change else "is already in"
        raise ValueError(
            f"--step {name}: {done} the view of every member of the ensemble {folder}; "
            "nothing to do"
        )
    _check_ensemble_loads(folder, members, edits, change)
    for edit in todo:
        _write(edit)
    return todo, tuple(e.folder for e in todo)


def _option(change: bool) -> str:
    return "--change-step" if change else "--add-step"


@dataclass(frozen=True)
class _Edit:
    """One agent folder's new ``config.yaml`` and model card, checked, not yet written."""

    folder: Path
    config: dict[str, Any]
    card: str
    index: int
    exported: bool
    old: dict[str, Any] | None = None  # a changed step's arguments before and after
    new: dict[str, Any] | None = None


def _plan(folder: Path, request: _Request, *, member: bool) -> _Edit | None:
    """The edit ``request`` asks of the agent in ``folder``, checked; for an ensemble's
    ``member``, None if it has the entry as the edit would leave it already."""
    name, kwargs, before, change = request.name, request.kwargs, request.before, request.change
    force, command = request.force, request.command
    option = _option(change)
    if not (folder / runs.MODEL).is_file():
        raise ValueError(
            f"{option} {folder}: no {runs.MODEL} in it; give an agent's folder (a run or an "
            "export) or an ensemble's"
        )
    config = runs.read_config(folder)
    where = folder / runs.CONFIG
    entries = wrapper_entries(config["hyperparams"].get("vec_env_wrapper"))  # to write back
    specs = wrapper_specs(entries, where=str(where))
    names = [n for n, _ in specs]
    listed = ", ".join(names) or "none"
    old = new = None
    if change:
        if name not in names:
            raise ValueError(
                f"--step {name}: not in the agent's view ({where}); its vec_env_wrapper "
                f"entries: {listed}"
            )
        index = names.index(name)
        old = dict(specs[index][1])
        new = {**old, **kwargs}
        if new == old:
            if member:
                return None  # written by an earlier run of the same command
            raise ValueError(f"--step {name}: changes nothing; {where} has these arguments")
        (_, was), (_, now) = (
            _shapes(config, where, specs[:index], name, args) for args in (old, new)
        )
        if now != was:
            raise ValueError(
                f"--step {name}: would turn the observations and actions into {now} where they "
                f"were {was}; a step changed after training must keep its shapes (the network "
                "reads them)"
            )
        view = [*entries[:index], {name: new}, *entries[index + 1 :]]
        line = _changed_line(command, name, old, kwargs)
    else:
        if name in names:
            if member and specs[names.index(name)][1] == kwargs:
                return None  # written by an earlier run of the same command
            raise ValueError(
                f"--step {name}: already in the agent's view (entry {names.index(name) + 1} of "
                f"{where}); a step is added once"
            )
        if before is None:
            index = 0
        elif before in names:
            index = names.index(before)
        else:
            raise ValueError(
                f"--before {before}: not in the agent's view ({where}); its vec_env_wrapper "
                f"entries: {listed}"
            )
        _check_shapes(config, where, specs[:index], name, kwargs)
        view = [*entries[:index], {name: kwargs}, *entries[index:]]
        line = _card_line(command, {name: kwargs}, before)
    manifest = read_manifest(folder)
    if manifest is not None and not force:
        changed = [
            n
            for n in (runs.CONFIG, runs.CARD)
            if (folder / n).is_file() and sha256(folder / n) not in manifest.get(n, [])
        ]
        if changed:
            raise ValueError(
                f"{option} {folder}: {', '.join(changed)} changed since the export that wrote "
                "the folder; give --force to edit it all the same"
            )
    edited = copy.deepcopy(config)
    edited["hyperparams"]["vec_env_wrapper"] = view
    card_path = folder / runs.CARD
    try:
        card = card_path.read_text(encoding="utf-8") if card_path.is_file() else ""
    except UnicodeDecodeError as e:
        raise ValueError(f"{card_path}: the model card is {utf8_problem(e)}") from None
    _check_loads(folder, edited)  # the dearest check last: it loads the model
    card = card.rstrip("\n") + ("\n" if card else "")
    card += ("" if EDITED in card else f"\n{EDITED}\n\n") + line + "\n"  # one list
    return _Edit(folder, edited, card, index, manifest is not None, old, new)


def _check_ensemble_loads(
    folder: Path, members: list[Path], edits: list[_Edit | None], change: bool
) -> None:
    """The ensemble loads with its members' new views (they must stay alike), as make_policy
    would load it: from a copy of the ensemble file and of each member's agent files."""
    with tempfile.TemporaryDirectory(prefix=".add-step-") as tmp:
        listed = []
        for k, (member, edit) in enumerate(zip(members, edits, strict=True)):
            copy_ = Path(tmp) / f"member-{k}"
            copy_.mkdir()
            _linked_copy(member, runs.read_config(member) if edit is None else edit.config, copy_)
            listed.append(copy_.name)
        (Path(tmp) / ENSEMBLE).write_text(yaml.safe_dump({"members": listed}), encoding="utf-8")
        try:
            EnsemblePolicy(tmp, name=str(folder))
        except AgentLoadError as e:
            # named as the user knows them: the ensemble's file and the member folders
            places = {str(Path(tmp) / ENSEMBLE): str(folder / ENSEMBLE)}
            places |= {str(Path(tmp) / n): str(m) for n, m in zip(listed, members, strict=True)}
            raise ValueError(
                f"{_option(change)} {folder}: the edited ensemble would not load: "
                f"{_renamed(str(e), places)}"
            ) from None


def _write(edit: _Edit) -> None:
    """Write one checked edit: the manifest's record first, then each file atomically."""
    config_text = runs.config_text(edit.config)
    if edit.exported:  # the export's record lists the new contents as its own too
        _record(edit.folder, {runs.CONFIG: config_text, runs.CARD: edit.card})
    atomic_write_text(edit.folder / runs.CONFIG, config_text)
    atomic_write_text(edit.folder / runs.CARD, edit.card)


def _record(folder: Path, texts: dict[str, str]) -> None:
    """Add the new contents' SHA-256 to the export manifest's lists (before the files are
    replaced: a kill between leaves a folder whose files the manifest still recognises)."""
    document = json.loads((folder / MANIFEST).read_text(encoding="utf-8"))
    for name, text in texts.items():
        digest = hashlib.sha256(text.encode("utf-8")).hexdigest()
        hashes = document["files"].setdefault(name, [])
        if digest not in hashes:
            hashes.append(digest)
    document.setdefault("edited_utc", []).append(_now())
    atomic_write_text(folder / MANIFEST, json.dumps(document, indent=2) + "\n")
