"""``follow-train --seeds ... --export DIR``: a study's trained seeds copied out as one agent.

Each seed's run is exported into ``DIR/seed-<k>`` as one run's export (:mod:`train.export`)
and ``DIR/ensemble.yaml`` lists them, so ``make_policy("DIR")`` is the mean of their actions
(:mod:`policies.learned.ensemble`). ``DIR`` may be new, empty, or a study's earlier export (it
holds an ``ensemble.yaml``); ``--force`` writes into any folder, replacing only the export's
files (:func:`check_study_export` checks it all before any seed trains).

An earlier export of *other* seeds (``--seeds 5-9 --export DIR`` over an export of seeds 0-4)
holds members the new ``ensemble.yaml`` would not name: a folder of stale agents beside the
one ``DIR`` is. Without ``--force`` it is refused, naming them (the user may have meant
``--seeds 0-9``); with ``--force`` the export is replaced: the new members are written whole
first, then ``ensemble.yaml`` (one atomic rename: ``make_policy("DIR")`` is the old agent or
the new one, never a mix), then the stale members are removed, each renamed out of sight
before it is deleted. A stale member is removed only if it is ``seed-<k>`` exported from this
study's ``seed-<k>`` (its manifest names the run, or lists that run's ``model.zip`` by its
content: a study moved since) and every file in it is its export's own,
unchanged (its manifest lists it with its content), as an export never deletes another file;
anything else in ``DIR`` is left as it is. A member the old ``ensemble.yaml`` lists that is not
this study's (``best`` in an ensemble assembled by hand, another study's ``seed-0``) is refused,
with ``--force`` too: the new ``ensemble.yaml`` would drop it. A removal cut short leaves its
hidden folder (``.seed-0.<8 characters>.removed``), which the next export into ``DIR`` removes.

One seed is exported as one agent, into ``DIR`` itself (:func:`train.export.export_agent`); a
``DIR`` holding an ``ensemble.yaml`` is refused then, with ``--force`` too: ``make_policy(DIR)``
would still be the old ensemble.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import tempfile
from collections.abc import Sequence
from pathlib import Path

import yaml

from follow_env.sim.atomic import atomic_folder, atomic_write_text
from policies.learned.ensemble import ENSEMBLE
from train.export import MANIFEST, ExportError, check_export, export_agent, read_manifest, sha256

__all__ = ["check_study_export", "export_study", "stale_members", "write_ensemble"]

#: The name of seed ``k``'s folder in a study and in its export.
_MEMBER = re.compile(r"seed-[0-9]+")
#: The hidden folder a stale member is renamed into to be removed (:func:`_remove`): its name,
#: ``mkdtemp``'s 8 random characters, ".removed".
_REMOVED = re.compile(r"\.seed-[0-9]+\.[a-z0-9_]{8}\.removed")


def check_study_export(
    dest: str | Path, seeds: Sequence[int], study: Path, *, force: bool = False
) -> None:
    """Check that :func:`export_study` loses nothing: each seed's folder ``dest/seed-<k>`` as
    one run's export is checked (:func:`train.export.check_export`), and ``dest`` itself must
    be new, empty, or a study's earlier export (it holds an ``ensemble.yaml``); ``--force``
    writes into any folder, replacing only the export's files. An earlier export of other
    seeds is refused, and replaced with ``--force`` if it is this study's; a member that is not
    is refused, as is a single seed over an ``ensemble.yaml`` (module docstring).

    :raises ExportError: naming the path and what is in the way.
    """
    dest, study = Path(dest), Path(study)
    option = f"--export {dest}"
    if len(seeds) == 1:  # as one run's export: refused beside an ensemble.yaml, --force too
        check_export(dest, force=force, run=study / f"seed-{seeds[0]}")
        return
    target, folder = dest.resolve(), study.resolve()
    if target == folder or target in folder.parents or folder in target.parents:
        raise ExportError(f"{option}: is, holds or lies in the study folder {study}; give another")
    if dest.is_dir() and any(dest.iterdir()) and not (dest / ENSEMBLE).is_file() and not force:
        raise ExportError(
            f"{option}: the folder is not empty and holds no study's export (no {ENSEMBLE}); "
            "choose a new or empty folder, or give --force to write the seeds' folders and "
            f"{ENSEMBLE} into it (nothing else is touched)"
        )
    for k in seeds:
        check_export(dest / f"seed-{k}", force=force, run=study / f"seed-{k}")
    stale = stale_members(dest, [f"seed-{k}" for k in seeds], study)
    foreign = [m for m in stale if Path(m).name != m or not _own(dest / m, study)]
    if foreign:
        where = "; ".join(f"{m} from {_source(dest / m)}" for m in foreign)
        raise ExportError(
            f"{option}: its {ENSEMBLE} lists {', '.join(foreign)}, which the new {ENSEMBLE} "
            f"would drop and which are not exports of {study}'s own seeds ({where}: an "
            "ensemble assembled by hand, another study's export, or a seed trained again "
            f"since); --force removes only this study's own seeds' exports: move "
            f"{'it' if len(foreign) == 1 else 'them'} away, or choose another folder"
        )
    if stale and not force:
        raise ExportError(
            f"{option}: holds an export of other seeds ({', '.join(stale)}), which the new "
            f"{ENSEMBLE} would not name; give --force to replace that export (the stale members "
            "are removed, nothing else is touched), another folder, or those seeds in --seeds too"
        )
    for member in stale:  # before any seed trains: a stale member --force may not remove
        _check_removable(dest, member)


def stale_members(dest: Path, members: Sequence[str], study: Path) -> list[str]:
    """The members of the study export in ``dest`` that are not ``members``: the folders its
    ``ensemble.yaml`` lists and the ``seed-<k>`` folders this ``study``'s export wrote (a
    kill after ``ensemble.yaml`` was replaced leaves them unlisted), sorted by seed. Empty when
    ``dest`` holds no ``ensemble.yaml`` (no study's export: ``--force`` writes into it and
    touches nothing else). Only ``study``'s own (:func:`_own`) may be removed."""
    if not (dest / ENSEMBLE).is_file():
        return []
    listed: list[str] = []
    with contextlib.suppress(OSError, UnicodeDecodeError, yaml.YAMLError):
        document = yaml.safe_load((dest / ENSEMBLE).read_text(encoding="utf-8"))
        if isinstance(document, dict) and isinstance(document.get("members"), list):
            listed = [m for m in document["members"] if isinstance(m, str)]
    # "./seed-0" is seed-0; a member elsewhere ("../run") keeps its spelling, and is not ours.
    names = {Path(m).name if len(Path(m).parts) == 1 else m for m in listed}
    names = {m for m in names if (dest / m).exists() or (dest / m).is_symlink()}
    names |= {p.name for p in dest.iterdir() if _MEMBER.fullmatch(p.name) and _own(p, study)}
    return sorted(names - set(members), key=_seed_order)


def _own(folder: Path, study: Path) -> bool:
    """``folder`` is ``seed-<k>``, exported from ``study``'s ``seed-<k>``: its manifest names
    that run, or (the study was moved or copied since, or is mounted elsewhere) lists that
    run's ``model.zip`` by its content."""
    if not (_MEMBER.fullmatch(folder.name) and _exported(folder)):
        return False
    seed = study / folder.name
    if _exported_from(folder) == str(seed.resolve()):
        return True
    manifest, model = read_manifest(folder), seed / "model.zip"
    if manifest is None or not model.is_file():
        return False
    return sha256(model) in manifest.get(model.name, [])


def _exported_from(folder: Path) -> str | None:
    """The run the export in ``folder`` was made from, as its manifest names it (None: no
    readable manifest names one)."""
    try:
        run = json.loads((folder / MANIFEST).read_text(encoding="utf-8")).get("run")
    except (OSError, UnicodeDecodeError, ValueError, AttributeError):
        return None
    return run if isinstance(run, str) else None


def _source(folder: Path) -> str:
    """Where the member ``folder`` was exported from, as its manifest says, for a message."""
    run = _exported_from(folder)
    return "no export's run" if run is None else f"the run {run}"


def _exported(folder: Path) -> bool:
    return folder.is_dir() and not folder.is_symlink() and (folder / MANIFEST).is_file()


def _seed_order(name: str) -> tuple[int, str]:
    return (int(name[5:]), name) if _MEMBER.fullmatch(name) else (-1, name)


def _check_removable(dest: Path, member: str) -> None:
    """Check that removing the stale member ``dest/member`` deletes only files its export wrote
    and nobody changed since (its manifest lists each with its content).

    :raises ExportError: naming the member and the first file that is not so.
    """
    folder = dest / member
    manifest = read_manifest(folder) if _exported(folder) else None
    why = f"it is not a folder an export wrote (no valid {MANIFEST})"
    if manifest is not None:
        why = ""
        for child in sorted(p for p in folder.iterdir() if p.name != MANIFEST):
            own = child.is_file() and not child.is_symlink()
            if not (own and sha256(child) in manifest.get(child.name, [])):
                why = f"{child.name} in it was not written by its export, or changed since"
                break
    if why:
        raise ExportError(
            f"--export {dest}: cannot remove the stale member {member}: {why} (--force removes "
            "only an export's own unchanged files); move it away"
        )


def export_study(
    study: Path, seeds: Sequence[int], dest: str | Path, *, force: bool = False
) -> Path:
    """Copy the trained ``seeds`` of ``study`` into ``dest`` as one agent: each seed's run
    exported into ``dest/seed-<k>`` (:func:`train.export.export_agent`) and an
    ``ensemble.yaml`` listing them, so ``make_policy(str(dest))`` is the mean of their actions.
    A new ``dest`` appears whole or not at all; in an earlier export each seed's files are
    replaced as one run's export replaces them, a new seed's folder appears whole, the
    ensemble file is written last, and then the stale members (``--force``) are removed. One
    seed is exported as one agent, into ``dest`` itself.

    :raises ExportError: as :func:`check_study_export` (nothing is written then).
    :returns: ``dest``.
    """
    dest = Path(dest)
    check_study_export(dest, seeds, study, force=force)
    if len(seeds) == 1:
        return export_agent(study / f"seed-{seeds[0]}", dest, force=force)
    members = [f"seed-{k}" for k in seeds]
    if not dest.exists() or not any(dest.iterdir()):
        with atomic_folder(dest) as tmp:
            for member in members:
                export_agent(study / member, tmp / member)
            write_ensemble(tmp, members)
        return dest
    stale = stale_members(dest, members, study)  # checked removable above
    for member in members:
        export_agent(study / member, dest / member, force=force)
    write_ensemble(dest, members)  # the switch: dest is the new agent from here on
    for member in stale:
        _remove(dest / member)
    for left in sorted(dest.iterdir()):  # what a removal cut short left (module docstring)
        if _REMOVED.fullmatch(left.name) and left.is_dir() and not left.is_symlink():
            shutil.rmtree(left)
    return dest


def _remove(folder: Path) -> None:
    """Remove ``folder`` (a stale member): renamed to a hidden name first, so that a kill while
    it is deleted never leaves a half-deleted member under its own name."""
    hidden = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", suffix=".removed", dir=folder.parent))
    os.replace(folder, hidden / folder.name)
    shutil.rmtree(hidden)


def write_ensemble(study: Path, members: Sequence[str]) -> Path:
    """``study/ensemble.yaml``, listing ``members`` (run folders relative to ``study``),
    atomically: ``make_policy(str(study))`` is then the mean of their actions
    (:mod:`policies.learned.ensemble`). Returns its path."""
    path = study / ENSEMBLE
    text = (
        "# The mean of these agents' actions acts as one agent (policies.learned.ensemble).\n"
        + yaml.safe_dump({"members": list(members)}, default_flow_style=True, sort_keys=False)
    )
    atomic_write_text(path, text)
    return path
