"""Which code made a run, and whether runs pooled together were made by the same code.

``follow-eval run`` records :func:`code_revision` in its ``meta.json`` under ``"code"``:

* ``sources_sha256``: SHA-256 over every ``.py`` file of the packages that decide a rollout
  (:data:`ROLLOUT_PACKAGES`: the simulation, the policies and the evaluation, whose metrics
  fill the episode tables that pooling reads; not the tests, and not a learned agent's files,
  which ``model_sha256`` covers), in sorted order of their paths relative to the
  packages' folder, each as its path, a NUL, its size in bytes (8, big-endian) and its bytes;
* ``git``: the HEAD commit of the git checkout the packages sit in, or null (no checkout, an
  installed copy, no git, or git failed);
* ``git_dirty``: whether those packages' files differ from HEAD (changed, staged or untracked
  files), or null where ``git`` is.

The digest, not the commit, is what pooling compares (:func:`code_notes`): a run made from a
checkout with uncommitted edits has the commit of code it did not run, and two commits that
touch only the documentation made the same rollouts.

It is also what a work unit carries from the driver to its worker (:func:`check_worker_code`):
on a cluster each node runs its own installation, and a node with other code would make other
episodes, or train another agent, without a sign. The worker's own digest is read once per
process (:func:`running_sources_sha256`), so each unit pays a comparison of two strings.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import socket
import subprocess
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

__all__ = [
    "ROLLOUT_PACKAGES",
    "CodeMismatchError",
    "check_worker_code",
    "code_notes",
    "code_revision",
    "running_sources_sha256",
    "sources_sha256",
]

#: The packages whose sources decide a rollout and its scores (the env and its kernels; laws
#: and agents' code; the rollout loop and the metrics). A change to the evaluation's command
#: line alone is noted too: the note asks the user to check, it refuses nothing.
ROLLOUT_PACKAGES = ("follow_env", "policies", "eval")
#: Longest wait for one git command [s]: git answers a local query in milliseconds, and a run
#: must not hang on a stuck file system for a provenance record.
GIT_TIMEOUT_S = 2.0
#: Hex digits of a digest or commit shown in a note (git's own short form is 7-12).
SHORT = 12


def _package_dirs(packages: Sequence[str]) -> list[Path]:
    """Each package's folder, found without importing it (so no kernel compiles for this)."""
    dirs = []
    for name in packages:
        spec = importlib.util.find_spec(name)
        if spec is None or not spec.submodule_search_locations:
            raise ValueError(f"{name}: not an importable package")
        dirs.append(Path(next(iter(spec.submodule_search_locations))).resolve())
    return dirs


def sources_sha256(dirs: Sequence[Path]) -> str:
    """SHA-256 (hex) over the ``.py`` files under ``dirs`` (module docstring), paths relative
    to each folder's parent; ``__pycache__`` (numba's generated modules among them) left out."""
    files: list[tuple[str, Path]] = []
    for folder in dirs:
        for where, subdirs, names in os.walk(folder):
            # pruned, not filtered: numba's cache under __pycache__ holds thousands of files
            subdirs[:] = [d for d in subdirs if d != "__pycache__"]
            here = Path(where)
            for name in names:
                if name.endswith(".py"):
                    files.append(((here / name).relative_to(folder.parent).as_posix(), here / name))
    files.sort()
    digest = hashlib.sha256()
    for name, path in files:
        data = path.read_bytes()
        # the size between the name and the bytes: no two file sets hash alike by shifting
        # bytes from one file's end into the next one's name
        digest.update(name.encode() + b"\0" + len(data).to_bytes(8, "big"))
        digest.update(data)
    return digest.hexdigest()


#: This process's digest of each package set, read at its first use (the code it imported then).
_RUNNING: dict[tuple[str, ...], str] = {}


class CodeMismatchError(ValueError):
    """A worker runs other code than the driver that sent it a unit (a ValueError: the
    commands report it in one line, as they do bad input)."""


def running_sources_sha256(packages: Sequence[str] = ROLLOUT_PACKAGES) -> str:
    """:func:`sources_sha256` of ``packages``, read once per process and kept: the digest of
    the code this process runs (its modules were imported from those files). 3-12 ms the
    first time, a dictionary look-up after."""
    key = tuple(packages)
    digest = _RUNNING.get(key)
    if digest is None:
        # Two threads may both read it the first time: the same value, harmlessly twice.
        digest = _RUNNING[key] = sources_sha256(_package_dirs(key))
    return digest


def check_worker_code(expected: str | None, packages: Sequence[str] = ROLLOUT_PACKAGES) -> None:
    """Refuse to run a unit whose driver runs other code than this worker (module docstring).

    :param expected: the driver's :func:`running_sources_sha256` of ``packages``, as the unit
        carries it; None checks nothing (a unit made without it).
    :raises CodeMismatchError: naming this host and both digests' first :data:`SHORT` digits.
    """
    if expected is None:
        return
    mine = running_sources_sha256(packages)
    if mine != expected:
        raise CodeMismatchError(
            f"this worker ({socket.gethostname()}) runs other code than the driver: the "
            f"SHA-256 of its {', '.join(packages)} sources is {mine[:SHORT]}, the driver's "
            f"{expected[:SHORT]}; install the same version on every node (and leave the sources "
            "unedited while a command runs: a worker started later reads them as they are)"
        )


def _git(root: Path, *args: str) -> str | None:
    """``git -C root args`` stdout, or None if git is missing, fails or takes too long."""
    # no prompt, no optional index lock (a concurrent git in the checkout is not disturbed)
    env = {**os.environ, "GIT_TERMINAL_PROMPT": "0", "GIT_OPTIONAL_LOCKS": "0"}
    try:
        done = subprocess.run(
            ["git", "-C", str(root), *args],
            capture_output=True,
            text=True,
            timeout=GIT_TIMEOUT_S,
            env=env,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout if done.returncode == 0 else None


def _git_state(dirs: Sequence[Path]) -> tuple[str | None, bool | None]:
    """(HEAD commit, packages dirty) of the checkout holding ``dirs``, or (None, None) when
    they are not tracked files of one checkout: an installed copy inside some other repository
    (a venv within a checkout) must not take that repository's commit."""
    roots = {folder.parent for folder in dirs}
    if len(roots) != 1:
        return None, None
    root = roots.pop()
    names = [folder.name for folder in dirs]
    tracked = _git(root, "ls-files", "--", *(f"{name}/__init__.py" for name in names))
    if tracked is None or len(tracked.split()) != len(names):
        return None, None
    head = _git(root, "rev-parse", "--verify", "HEAD")
    status = _git(root, "status", "--porcelain", "--untracked-files=all", "--", *names)
    if head is None or status is None:
        return None, None
    return head.strip(), bool(status.strip())


def code_revision(packages: Sequence[str] = ROLLOUT_PACKAGES) -> dict[str, Any]:
    """``{"sources_sha256": ..., "git": ..., "git_dirty": ...}`` (module docstring) of
    ``packages``. For this project's (about 100 files) 13-30 ms on the shared 2-core machine
    (median 20 ms: the digest 3-12 ms, git's three commands the rest)."""
    dirs = _package_dirs(packages)
    head, dirty = _git_state(dirs)
    return {"sources_sha256": sources_sha256(dirs), "git": head, "git_dirty": dirty}


def _digest(meta: Mapping[str, Any]) -> str | None:
    """A run's recorded sources digest, or None (a run made before it was recorded)."""
    code = meta.get("code")
    digest = code.get("sources_sha256") if isinstance(code, Mapping) else None
    return digest if isinstance(digest, str) and digest else None


def _revision(meta: Mapping[str, Any]) -> str:
    """A run's revision as a note names it: ``git 1a2b3c4d5e6f`` (``+ uncommitted edits``),
    ``no git revision``, or ``code unrecorded``."""
    code = meta.get("code")
    if not isinstance(code, Mapping) or _digest(meta) is None:
        return "code unrecorded"
    head = code.get("git")
    if not isinstance(head, str) or not head:
        return f"no git revision, sources {code['sources_sha256'][:SHORT]}"
    edits = " + uncommitted edits" if code.get("git_dirty") is True else ""
    return f"git {head[:SHORT]}{edits}, sources {code['sources_sha256'][:SHORT]}"


def code_notes(runs: Sequence[Path | str], metas: Sequence[Mapping[str, Any]]) -> list[str]:
    """What pooling ``runs`` (their ``meta.json`` in ``metas``) should say about their code,
    one line each: that their sources differ (naming every run and its revision), and which
    runs record no code revision. Empty when every run records the same sources. Pooling is
    not refused on either: rollouts can survive a refactor, and old runs are pooled too.
    """
    digests = [_digest(meta) for meta in metas]
    notes = []
    if len({d for d in digests if d is not None}) > 1:
        named = "; ".join(
            f"{run} ({_revision(meta)})" for run, meta in zip(runs, metas, strict=True)
        )
        notes.append(
            "the runs were made from different simulator, policy or evaluation code (their "
            f"sources' SHA-256 differ): {named}; check that the change left the rollouts alike"
        )
    unknown = [str(run) for run, d in zip(runs, digests, strict=True) if d is None]
    if unknown:
        which = "its" if len(unknown) == 1 else "their"
        notes.append(
            f"{', '.join(unknown)}: {which} code revision is unknown ({which} meta.json records "
            "none: made before runs recorded it), so the runs pooled cannot be checked to come "
            "from the same code"
        )
    return notes
