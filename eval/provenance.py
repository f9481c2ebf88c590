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

A tuning study keeps a looser digest, :func:`code_sha256`: the same files parsed, without
their comments, docstrings and layout, so that an edit to a comment or a docstring does not
make a study's scores incomparable (:func:`eval.tuning.folders.open_search`).

It is also what a work unit carries from the driver to its worker (:func:`check_worker_code`):
on a cluster each node runs its own installation, and a node with other code would make other
episodes, or train another agent, without a sign. The worker's own digest is read once per
process (:func:`running_sources_sha256`), so each unit pays a comparison of two strings.

A learned policy's files are not sources: ``meta.json``'s ``model_sha256`` maps each learned
policy's label to :func:`model_sha256` of the files it was loaded from (laws have no entry).
The journal of an interrupted run records it too (a resume with other files is refused,
:mod:`eval.journal`), each work unit carries the driver's (:func:`check_worker_model`: a node
holding other files at the agent's path stops the command, naming its host and the policy), and
pooling runs refuses two digests under one label and notes a run that records none
(:func:`model_notes`). Only the files that decide the agent's actions count
(:data:`MODEL_ROLES`); the model card, learning curve and an export's manifest
(``follow-train-export.json``) do not, so a re-export of the same files keeps its digest.
"""

from __future__ import annotations

import ast
import hashlib
import importlib.util
import os
import socket
import subprocess
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

__all__ = [
    "MODEL_ROLES",
    "ROLLOUT_PACKAGES",
    "CodeMismatchError",
    "ModelMismatchError",
    "agent_path",
    "check_worker_code",
    "check_worker_model",
    "code_notes",
    "code_revision",
    "code_sha256",
    "model_notes",
    "model_sha256",
    "running_code_sha256",
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


def _py_files(dirs: Sequence[Path]) -> list[tuple[str, Path]]:
    """The ``.py`` files under ``dirs``, each with its path relative to its folder's parent,
    sorted by it; ``__pycache__`` (numba's generated modules among them) left out."""
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
    return files


def _hash_files(files: list[tuple[str, bytes]]) -> str:
    digest = hashlib.sha256()
    for name, data in files:
        # the size between the name and the bytes: no two file sets hash alike by shifting
        # bytes from one file's end into the next one's name
        digest.update(name.encode() + b"\0" + len(data).to_bytes(8, "big"))
        digest.update(data)
    return digest.hexdigest()


def sources_sha256(dirs: Sequence[Path]) -> str:
    """SHA-256 (hex) over the ``.py`` files under ``dirs`` (module docstring), paths relative
    to each folder's parent; ``__pycache__`` (numba's generated modules among them) left out."""
    return _hash_files([(name, path.read_bytes()) for name, path in _py_files(dirs)])


_DOCUMENTED = (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)


def _code_of(source: bytes) -> bytes:
    """What a file's code is, without its comments, docstrings and layout: its syntax tree,
    docstrings removed, written out by :func:`_tree_text` (the source itself if it does not
    parse)."""
    try:
        tree = ast.parse(source)
    except (SyntaxError, ValueError):
        return source
    for node in ast.walk(tree):
        if isinstance(node, _DOCUMENTED) and node.body:
            first = node.body[0]
            if (
                isinstance(first, ast.Expr)
                and isinstance(first.value, ast.Constant)
                and isinstance(first.value.value, str)
            ):
                node.body = node.body[1:] or [ast.Pass()]
    return _tree_text(tree).encode()


def _tree_text(node: Any) -> str:
    """A syntax tree as text, the same under every Python that parses it alike: each node's
    type and its fields by name, leaving out the empty ones (``ast.dump`` writes them
    differently from one Python version to the next, and 3.12 added empty ``type_params``)."""
    if isinstance(node, ast.AST):
        fields = []
        for name in node._fields:
            value = getattr(node, name, None)
            if value is None or value == []:
                continue
            fields.append(f"{name}={_tree_text(value)}")
        return f"{type(node).__name__}({', '.join(fields)})"
    if isinstance(node, list):
        return f"[{', '.join(_tree_text(item) for item in node)}]"
    return repr(node)


def code_sha256(dirs: Sequence[Path]) -> str:
    """SHA-256 (hex) over the code of the ``.py`` files under ``dirs``, as
    :func:`sources_sha256` takes them but each file as :func:`_code_of` gives it: an edit to a
    comment, a docstring or the layout keeps it, any other edit changes it."""
    return _hash_files([(name, _code_of(path.read_bytes())) for name, path in _py_files(dirs)])


#: This process's digest of each package set, read at its first use (the code it imported then).
_RUNNING: dict[tuple[str, ...], str] = {}
_RUNNING_CODE: dict[tuple[str, ...], str] = {}


class CodeMismatchError(ValueError):
    """A worker runs other code than the driver that sent it a unit (a ValueError: the
    commands report it in one line, as they do bad input)."""


def _kept(
    kept: dict[tuple[str, ...], str],
    digest: Callable[[Sequence[Path]], str],
    packages: Sequence[str],
) -> str:
    """``digest`` of ``packages``' folders, read once per process and kept in ``kept``."""
    key = tuple(packages)
    value = kept.get(key)
    if value is None:
        # Two threads may both read it the first time: the same value, harmlessly twice.
        value = kept[key] = digest(_package_dirs(key))
    return value


def running_sources_sha256(packages: Sequence[str] = ROLLOUT_PACKAGES) -> str:
    """:func:`sources_sha256` of ``packages``, read once per process and kept: the digest of
    the code this process runs (its modules were imported from those files). 3-12 ms the
    first time, a dictionary look-up after."""
    return _kept(_RUNNING, sources_sha256, packages)


def running_code_sha256(packages: Sequence[str] = ROLLOUT_PACKAGES) -> str:
    """:func:`code_sha256` of ``packages``, read once per process and kept, as
    :func:`running_sources_sha256` is (parsing them takes about half a second)."""
    return _kept(_RUNNING_CODE, code_sha256, packages)


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


#: The files of a learned agent its digest covers, by role (``agent_files`` of
#: :mod:`policies.learned.ppo`): the SB3 model (``model.zip``, or a checkpoint's
#: ``ppo_<steps>_steps.zip``), the observation normalisation statistics (``vecnormalize.pkl``,
#: or the checkpoint's own) and ``config.yaml`` (how the agent sees the env and acts). Roles,
#: not file names, are hashed: a checkpoint's files are named after its step count, and the
#: same files are the same model wherever they are saved.
MODEL_ROLES = ("model", "normalization", "config")
#: :func:`model_sha256` by the versions of the files it read
#: (:func:`policies.learned.ppo.file_version`), so that a unit's check reads no file whose
#: version it has seen: a few ``stat`` calls.
_MODELS: dict[tuple[Any, ...], str] = {}
#: Versions kept before the cache starts afresh (an agent is a few files; a long tuning session
#: that re-exports an agent now and then still stays small).
_MODELS_KEPT = 256
#: How ``meta.json``'s ``policies`` names a learned policy (its ``repr``), in runs written
#: before ``model_sha256`` was recorded.
_LEARNED_REPRS = ("PPOPolicy(", "EnsemblePolicy(")


class ModelMismatchError(ValueError):
    """A worker reads other files for a learned policy than the driver did (a ValueError: the
    commands report it in one line, as they do bad input)."""


def _agent_folders(policy: object) -> list[str] | None:
    """The folders (or ``.zip`` files) a learned policy was loaded from, an ensemble's members
    in its ``ensemble.yaml``'s order; None for any other policy."""
    from policies.learned.ensemble import EnsemblePolicy
    from policies.learned.ppo import PPOPolicy

    if isinstance(policy, PPOPolicy):
        return [policy.path]
    if isinstance(policy, EnsemblePolicy):
        return list(policy.members)
    return None


def agent_path(policy: object) -> str | None:
    """The absolute path a learned policy was loaded from (its folder, ``.zip`` or ensemble),
    as messages name it; None for any other policy."""
    path = getattr(policy, "path", None) if _agent_folders(policy) is not None else None
    return None if path is None else str(Path(path).absolute())


def _files_sha256(files: Sequence[tuple[str, Path]]) -> str:
    """SHA-256 (hex) over ``(role, path)`` pairs: :func:`model_sha256`'s layout."""
    digest = hashlib.sha256()
    for role, path in files:
        digest.update(role.encode("ascii"))
        if not path.is_file():
            digest.update(b"\0absent\0")
            continue
        data = path.read_bytes()  # an agent's files are at most a few MB
        digest.update(b"\0%d\0" % len(data))  # lengths keep the files' bounds apart
        digest.update(data)
    return digest.hexdigest()


def model_sha256(policy: object) -> str | None:
    """SHA-256 (hex) of the files a learned policy was loaded from; None for any other policy
    (a law: its gains are in the sources).

    A trained agent's name and ``repr`` hold only the path it was given (often relative), so
    two runs of ``runs/agent`` may hold two different models: the digest tells them apart. For
    each agent (an ensemble's members in its ``ensemble.yaml``'s order) and each of
    :data:`MODEL_ROLES` in turn, it hashes the role's name, then ``\\0absent\\0`` for a file
    the agent does without (a run that does not normalise), else ``\\0<size in bytes, in
    decimal>\\0`` and the file's bytes. Read once per version of the files
    (:func:`policies.learned.ppo.file_version`) and kept: 0.25 ms for the shipped ``ppo`` the
    first time (1 ms its two-member ensemble), then a ``stat`` of each file (25 us; 50 us).
    """
    folders = _agent_folders(policy)
    if folders is None:
        return None
    from policies.learned.ppo import agent_files, file_version

    files: list[tuple[str, Path]] = []
    for folder in folders:
        found = agent_files(folder)
        files += zip(MODEL_ROLES, (found.model, found.normalization, found.config), strict=True)
    key = tuple((str(path), file_version(path)) for _, path in files)
    digest = _MODELS.get(key)
    if digest is None:
        digest = _files_sha256(files)
        # kept only if no file changed while it was read (else its bytes may be either version's)
        if tuple((str(path), file_version(path)) for _, path in files) == key:
            if len(_MODELS) >= _MODELS_KEPT:
                _MODELS.clear()
            _MODELS[key] = digest
    return digest


def check_worker_model(expected: str | None, policy: object, label: str) -> None:
    """Refuse to run a unit of ``policy`` (built by this worker from the unit) whose files are
    not those the driver read: a node holding another model at the agent's path (or files
    replaced while the command runs) would play other episodes under the run's label.

    :param expected: the driver's :func:`model_sha256` of the policy, as the unit carries it;
        None checks nothing (a law, or a unit made without it).
    :param label: the policy's label in the run (its episodes').
    :raises ModelMismatchError: naming this host, the policy, its path and both digests' first
        :data:`SHORT` digits.
    """
    if expected is None:
        return
    mine = model_sha256(policy)
    if mine != expected:
        here = "none (not a learned policy here)" if mine is None else mine[:SHORT]
        raise ModelMismatchError(
            f"this worker ({socket.gethostname()}) reads other files for the learned policy "
            f"{label} than the driver: the SHA-256 of its model, statistics and config in "
            f"{agent_path(policy) or repr(policy)} is {here}, the driver's {expected[:SHORT]}; "
            "give every node the driver's files at that path (a shipped agent: install the "
            "same version), and leave them unchanged while a command runs"
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


def _recorded(meta: Mapping[str, Any], label: str) -> str | None:
    """The SHA-256 of ``label``'s agent files a run records, or None."""
    models = meta.get("model_sha256")
    digest = models.get(label) if isinstance(models, Mapping) else None
    return digest if isinstance(digest, str) and digest else None


def model_notes(
    runs: Sequence[Path | str], metas: Sequence[Mapping[str, Any]], labels: Sequence[str]
) -> list[str]:
    """What pooling ``runs`` (their ``meta.json`` in ``metas``) should say about the models
    under ``labels`` (the policies judged), one line each: for a label that is a learned policy
    in some run (it records the digest of its files, or names an agent in ``policies``), the
    runs holding it that record no digest (made before runs recorded it), whose model cannot be
    checked to be the others'. Two digests under one label are not noted: pooling refuses them
    (another model is another controller; :mod:`eval.cli_dominance`)."""
    notes = []
    for label in dict.fromkeys(labels):
        held = [
            (str(run), meta)
            for run, meta in zip(runs, metas, strict=True)
            if isinstance(meta.get("policies"), Mapping) and label in meta["policies"]
        ]
        learned = any(
            _recorded(meta, label) is not None
            or str(meta["policies"][label]).startswith(_LEARNED_REPRS)
            for _, meta in held
        )
        unknown = [run for run, meta in held if _recorded(meta, label) is None]
        if learned and unknown:
            which = "its" if len(unknown) == 1 else "their"
            notes.append(
                f"{', '.join(unknown)}: the model under {label} is unknown ({which} meta.json "
                f"records no SHA-256 of its agent files: made before runs recorded it), so the "
                f"runs pooled cannot be checked to hold the same model under {label}"
            )
    return notes
