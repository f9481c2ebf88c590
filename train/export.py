"""``follow-train --export DIR``: copy a finished agent into a folder, never losing a file.

An export writes the agent's files (:data:`AGENT_FILES`, the learning curve) and a manifest,
:data:`MANIFEST`, listing each file it wrote with its SHA-256. The manifest is how an export
recognises a folder it made, and the files in it that are still the ones it wrote:

- ``DIR`` does not exist: the agent is assembled in a temporary folder beside it and renamed
  into place, so ``DIR`` appears whole or not at all. An empty folder is written into.
- ``DIR`` holds an earlier export (a valid manifest, every listed file unchanged): each of the
  agent's files is replaced on its own, atomically (temporary file, then rename); a file the
  earlier export listed that this one does not write (``vecnormalize.pkl`` of a run that did
  not normalise) is removed, as it would describe another agent. Nothing else in ``DIR`` is
  touched.
- Anything else is refused, before training starts: a folder that holds other files and no
  manifest, an earlier export whose files were changed since, a file that would be replaced
  but was not written by an export, and a path that is (or runs through) a regular file.

``--force`` lets an export write into an existing folder it did not make, or over exported
files that were changed: the agent's files and the manifest are written over files of the
same names (:data:`EXPORT_NAMES`); every other file in the folder is left as it is, and no file
is ever deleted unless a manifest lists it with its current content. ``--force`` never turns a
regular file into a folder.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from follow_env.sim.atomic import (
    atomic_folder,
    atomic_path,
    atomic_write_text,
    check_writable,
    file_on_path,
)
from policies.learned.ensemble import ENSEMBLE

__all__ = [
    "AGENT_FILES",
    "EXPORT_EXTRAS",
    "EXPORT_NAMES",
    "MANIFEST",
    "ExportError",
    "ExportPlan",
    "check_export",
    "export_agent",
    "read_manifest",
    "sha256",
]

#: The files that make an agent (what policies.ppo loads).
AGENT_FILES = ("model.zip", "vecnormalize.pkl", "config.yaml", "MODEL_CARD.md")
EXPORT_EXTRAS = ("learning_curve.png",)
#: Written by every export: which files it wrote, with their SHA-256.
MANIFEST = "follow-train-export.json"
#: Every name an export may write into ``DIR``.
EXPORT_NAMES = (*AGENT_FILES, *EXPORT_EXTRAS, MANIFEST)
# Only a run without normalisation lacks this one.
_OPTIONAL = ("vecnormalize.pkl",)
_WRITER = "follow-train --export"
#: The error for ``--force`` without ``--export`` (a single run and a study both check it).
FORCE_ALONE_ERROR = "--force applies to --export only (it lets --export write into a folder)"


class ExportError(ValueError):
    """An export target that would lose a file; the message names it and says what to do."""


@dataclass(frozen=True)
class ExportPlan:
    """How an export will write ``dest`` (from :func:`check_export`).

    :param dest: the target folder.
    :param create: ``dest`` does not exist: assembled beside it and renamed into place.
    :param exported: from the manifest of an earlier export: file name -> the SHA-256 values
        that file may have and still be the export's own (empty without a valid manifest).
    """

    dest: Path
    create: bool
    exported: dict[str, list[str]]


def sha256(path: Path) -> str:
    """The SHA-256 of a file's bytes, hex."""
    digest = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def read_manifest(dest: Path) -> dict[str, list[str]] | None:
    """The files an earlier export listed (name -> hashes), or None if there is no valid
    manifest (missing, unreadable, or not written by an export)."""
    try:
        document = json.loads((dest / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    if not isinstance(document, dict) or document.get("written_by") != _WRITER:
        return None
    files = document.get("files")
    if not isinstance(files, dict):
        return None
    exported: dict[str, list[str]] = {}
    for name, hashes in files.items():
        valid = isinstance(hashes, list) and all(isinstance(h, str) for h in hashes)
        if name not in EXPORT_NAMES or name == MANIFEST or not valid:
            return None  # a manifest naming other files was not written by an export
        exported[name] = hashes
    return exported


def _is_exported(dest: Path, name: str, exported: dict[str, list[str]]) -> bool:
    """``dest/name`` is a regular file an earlier export wrote, unchanged since."""
    path = dest / name
    return path.is_file() and not path.is_symlink() and sha256(path) in exported.get(name, [])


def check_export(dest: str | Path, *, force: bool = False, run: Path | None = None) -> ExportPlan:
    """Check that exporting into ``dest`` loses nothing (module docstring), and say how.

    Reads only; called before training starts and again just before the export.

    :param dest: the ``--export`` folder.
    :param force: ``--force``: write into a folder this did not make, or over changed files.
    :param run: the run folder (made or to be made), which must be neither the target nor
        inside it.
    :raises ExportError: naming the path and the files in the way.
    """
    dest = Path(dest)
    option = f"--export {dest}"
    blocker = file_on_path(dest)
    if blocker == dest:
        raise ExportError(
            f"{option}: is a file, not a folder; give a folder (--force never replaces a file)"
        )
    if blocker is not None:
        raise ExportError(f"{option}: {blocker} is a file, not a folder")
    if run is not None:  # exists or not: the run folder may be made after this check
        target, run_folder = dest.resolve(), Path(run).resolve()
        if target == run_folder:
            raise ExportError(f"{option}: is the run folder; give another folder")
        if run_folder in target.parents:  # as a study's export may not lie in the study
            raise ExportError(f"{option}: lies in the run folder {run}; give another folder")
        # A new or empty folder would hold the run, and no export, by the time it is written.
        fresh = not dest.exists() or (dest.is_dir() and not any(dest.iterdir()))
        if fresh and target in run_folder.parents:
            raise ExportError(f"{option}: would contain the run folder {run}; give another folder")
    try:  # a folder that takes no file (read-only, /proc) stops the run before it trains
        check_writable(dest / EXPORT_NAMES[0] if dest.is_dir() else dest)
    except OSError as e:
        raise ExportError(f"{option}: {e}") from None
    if not dest.exists():
        return ExportPlan(dest, create=True, exported={})
    folders = [name for name in EXPORT_NAMES if (dest / name).is_dir()]
    if folders:
        raise ExportError(
            f"{option}: {', '.join(folders)} in it is a folder; an export writes a file of "
            "that name (--force replaces files, never folders)"
        )
    if (dest / ENSEMBLE).exists():  # the agent beside it: make_policy(dest) is the ensemble
        raise ExportError(
            f"{option}: holds {ENSEMBLE}, and an agent is exported into the folder itself, so "
            f"make_policy({str(dest)!r}) would still be the old ensemble (--force does not "
            "remove it); choose another folder"
        )
    if not any(dest.iterdir()):
        return ExportPlan(dest, create=False, exported={})
    exported = read_manifest(dest)
    hint = (
        "choose a new or empty folder, or give --force to write the agent's files into it "
        f"({', '.join(EXPORT_NAMES)} are replaced, nothing else is touched)"
    )
    if exported is None:
        if not force:
            raise ExportError(
                f"{option}: the folder is not empty and holds no export of follow-train "
                f"(no valid {MANIFEST}); {hint}"
            )
        return ExportPlan(dest, create=False, exported={})
    in_the_way = [
        name
        for name in EXPORT_NAMES
        if name != MANIFEST and (dest / name).exists() and not _is_exported(dest, name, exported)
    ]
    if in_the_way and not force:
        raise ExportError(
            f"{option}: {', '.join(in_the_way)} changed since the last export or was not "
            f"written by it; move {'it' if len(in_the_way) == 1 else 'them'} away, or {hint}"
        )
    return ExportPlan(dest, create=False, exported=exported)


def export_agent(run: Path, dest: str | Path, *, force: bool = False) -> Path:
    """Copy the agent of ``run`` into ``dest`` (module docstring: what is replaced, what never).

    :param run: a finished run folder (``model.zip``, ``config.yaml``, ``MODEL_CARD.md``,
        ``learning_curve.png``; ``vecnormalize.pkl`` if the run normalises).
    :param dest: the target folder.
    :param force: as ``--force`` (module docstring).
    :raises ExportError: if exporting would lose a file (nothing is written then).
    :raises FileNotFoundError: if the run lacks one of the agent's files.
    :returns: ``dest``.
    """
    plan = check_export(dest, force=force, run=run)
    sources: dict[str, Path] = {}
    for name in (*AGENT_FILES, *EXPORT_EXTRAS):
        source = Path(run) / name
        if source.exists():
            sources[name] = source
        elif name not in _OPTIONAL:
            raise FileNotFoundError(f"{source}: missing; is the run finished?")
    hashes = {name: sha256(path) for name, path in sources.items()}
    if plan.create:
        with atomic_folder(plan.dest) as tmp:
            for name, source in sources.items():
                shutil.copy2(source, tmp / name)
            _write_manifest(tmp, run, {name: [h] for name, h in hashes.items()})
        return plan.dest
    # In place, one file at a time. A manifest listing both the old and the new content of
    # every file goes first, so a kill between two renames leaves a folder the next export
    # still recognises as its own.
    pending = {name: [*plan.exported.get(name, []), h] for name, h in hashes.items()}
    leftovers = [name for name in plan.exported if name not in sources]
    _write_manifest(plan.dest, run, pending | {n: plan.exported[n] for n in leftovers})
    for name, source in sources.items():
        with atomic_path(plan.dest / name) as tmp:
            shutil.copy2(source, tmp)
    for name in leftovers:  # written by an earlier export, for another agent
        if _is_exported(plan.dest, name, plan.exported):
            (plan.dest / name).unlink()
    _write_manifest(plan.dest, run, {name: [h] for name, h in hashes.items()})
    return plan.dest


def _write_manifest(folder: Path, run: Path, files: dict[str, list[str]]) -> None:
    document: dict[str, Any] = {
        "written_by": _WRITER,
        "run": str(Path(run).resolve()),
        "exported_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "files": files,
    }
    atomic_write_text(folder / MANIFEST, json.dumps(document, indent=2) + "\n")
