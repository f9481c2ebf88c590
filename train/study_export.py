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
before it is deleted. A stale member is removed only if every file in it is its export's own,
unchanged (its manifest lists it with its content), as an export never deletes another file;
anything else in ``DIR`` is left as it is.
"""

from __future__ import annotations

import contextlib
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


def check_study_export(
    dest: str | Path, seeds: Sequence[int], study: Path, *, force: bool = False
) -> None:
    """Check that :func:`export_study` loses nothing: each seed's folder ``dest/seed-<k>`` as
    one run's export is checked (:func:`train.export.check_export`), and ``dest`` itself must
    be new, empty, or a study's earlier export (it holds an ``ensemble.yaml``); ``--force``
    writes into any folder, replacing only the export's files. An earlier export of other
    seeds is refused, and replaced with ``--force`` (module docstring). One seed is exported
    as one agent, into ``dest`` itself.

    :raises ExportError: naming the path and what is in the way.
    """
    dest, study = Path(dest), Path(study)
    if len(seeds) == 1:
        check_export(dest, force=force, run=study / f"seed-{seeds[0]}")
        return
    option = f"--export {dest}"
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
    stale = stale_members(dest, [f"seed-{k}" for k in seeds])
    if stale and not force:
        raise ExportError(
            f"{option}: holds an export of other seeds ({', '.join(stale)}), which the new "
            f"{ENSEMBLE} would not name; give --force to replace that export (the stale members "
            "are removed, nothing else is touched), another folder, or those seeds in --seeds too"
        )
    for member in stale:  # before any seed trains: a stale member --force may not remove
        _check_removable(dest, member)


def stale_members(dest: Path, members: Sequence[str]) -> list[str]:
    """The members of the study export in ``dest`` that are not ``members``: the folders its
    ``ensemble.yaml`` lists and the ``seed-<k>`` folders an export wrote (a folder with an
    export manifest), sorted by seed. Empty when ``dest`` holds no ``ensemble.yaml`` (no
    study's export: ``--force`` writes into it and touches nothing else)."""
    if not (dest / ENSEMBLE).is_file():
        return []
    listed: list[str] = []
    with contextlib.suppress(OSError, UnicodeDecodeError, yaml.YAMLError):
        document = yaml.safe_load((dest / ENSEMBLE).read_text(encoding="utf-8"))
        if isinstance(document, dict) and isinstance(document.get("members"), list):
            listed = [m for m in document["members"] if isinstance(m, str)]
    # Only folders right in dest: a member listed as "../run" is not the export's to remove.
    names = {m for m in listed if Path(m).parts == (m,) and m not in (".", "..")}
    names = {m for m in names if (dest / m).exists() or (dest / m).is_symlink()}
    # A seed's export the ensemble.yaml no longer names (a kill after it was replaced).
    names |= {p.name for p in dest.iterdir() if _MEMBER.fullmatch(p.name) and _exported(p)}
    return sorted(names - set(members), key=_seed_order)


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
    stale = stale_members(dest, members)  # checked removable above
    for member in members:
        export_agent(study / member, dest / member, force=force)
    write_ensemble(dest, members)  # the switch: dest is the new agent from here on
    for member in stale:
        _remove(dest / member)
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
