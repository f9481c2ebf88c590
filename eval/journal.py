"""A run's finished work units, kept so that an interrupted run resumes where it stopped.

``follow-eval run --out DIR`` keeps each finished work unit (one policy, scenario and chunk of
seeds: :func:`eval.units.work_units`) in a hidden folder beside ``DIR``, ``.DIR.units/``, one
pickle per unit written atomically. Ctrl-C (or a crash) leaves that folder and no ``DIR``; the
same command run again reads it, skips the finished units and runs the rest, and removes it
once ``DIR`` is written. The folder also holds what the run is (``run.json``: its grid, config
and chunking, the SHA-256 of the code that runs its episodes, ``"code"``, and of each learned
policy's files, ``"model_sha256"``), so a different command pointed at the same ``--out``, or
the same command run by other code or with an agent's files replaced, is refused instead of
mixing two runs; the refusal says what changed and what to do.
"""

from __future__ import annotations

import json
import pickle
import shutil
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from follow_env.sim.atomic import atomic_path, atomic_write_text

__all__ = ["UnitJournal", "journal_folder"]

_RUN = "run.json"
#: The run description's key for the digest of the code its units ran
#: (:func:`eval.provenance.code_revision`'s ``sources_sha256``).
CODE = "code"
#: The run description's key for the SHA-256 of each learned policy's files, by its label
#: (:func:`eval.provenance.model_sha256`; no key: the run has no learned policy).
MODELS = "model_sha256"
#: Hex digits of a digest a refusal shows.
_SHORT = 12


def journal_folder(out: str | Path) -> Path:
    """Where the units of a run writing ``out`` are kept: ``.<name>.units`` beside it."""
    out = Path(out)
    return out.parent / f".{out.name}.units"


class UnitJournal:
    """The finished units of one run (see the module docstring).

    :param folder: the journal's folder (:func:`journal_folder`).
    :param run: what the run is, JSON-serialisable; a journal made by another run is refused.
    :param agents: where each learned policy's files are read from, by label (a refusal names
        it); not part of what the run is (a relative path is the same run from another folder,
        if the files are the same).
    :raises ValueError: if ``folder`` holds another run's units, or its ``run.json`` is corrupt
        (the message names the file).
    """

    def __init__(
        self, folder: str | Path, run: dict[str, Any], agents: Mapping[str, str] | None = None
    ) -> None:
        self.folder = Path(folder)
        self.run = json.loads(json.dumps(run))  # as it reads back: tuples become lists
        self.agents = dict(agents or {})
        path = self.folder / _RUN
        if path.exists():
            try:
                had = json.loads(path.read_text(encoding="utf-8"))
            except (OSError, ValueError) as e:
                raise ValueError(f"{path}: not a readable run description ({e})") from None
            if had != self.run:
                keys = sorted(set(had) | set(self.run)) if isinstance(had, dict) else []
                differ = [k for k in keys if had.get(k) != self.run.get(k)]
                if differ and set(differ) <= {CODE, MODELS}:  # the same command, other code or
                    raise ValueError(self._changed(had, differ))  # agent files: say which
                what = f" (its {', '.join(differ)} differ)" if differ else ""
                raise ValueError(
                    f"{self.folder} holds the finished units of another run{what}; see {path}: "
                    "run that command again to resume it, or delete the folder"
                )
        else:
            self.folder.mkdir(parents=True, exist_ok=True)
            atomic_write_text(path, json.dumps(self.run, indent=1) + "\n")

    def _changed(self, had: dict[str, Any], differ: list[str]) -> str:
        """Why a resume of this run by other code or with other agent files is refused, and
        what to do: one line."""
        code, now = had.get(CODE), self.run.get(CODE)
        if CODE in differ and not (isinstance(code, str) and isinstance(now, str)):
            return self._unrecorded("its code", "the code", "code versions'")
        if MODELS in differ and MODELS not in had:  # kept before runs recorded the digests
            return self._unrecorded("its learned policies' files", "the models", "models'")
        what, why = [], []
        if CODE in differ:
            what.append("the code")
            why.append(
                "the SHA-256 of its simulator, policy and evaluation sources was "
                f"{code[:_SHORT]}, is now {now[:_SHORT]}"
            )
        if MODELS in differ:
            was, is_now = self._models(had), self._models(self.run)
            labels = [k for k in dict.fromkeys([*was, *is_now]) if was.get(k) != is_now.get(k)]
            noun = "policy" if len(labels) == 1 else "policies"
            what.append(f"the files of its learned {noun} {', '.join(labels)}")
            why += [
                f"the SHA-256 of {label}'s model, statistics and config"
                + (f" in {self.agents[label]}" if label in self.agents else "")
                + f" was {self._short(was.get(label))}, is now {self._short(is_now.get(label))}"
                for label in labels
            ]
        mixed, kept = {
            (True, False): ("two code versions'", "the code"),
            (False, True): ("two models'", "the agent files"),  # put back at the same path
            (True, True): ("two versions'", "the code and the agent files"),
        }[CODE in differ, MODELS in differ]
        return (
            f"{self.folder} holds the finished units of this run, but {' and '.join(what)} "
            f"changed since the run started ({'; '.join(why)}): resuming would mix {mixed} "
            f"episodes in one run's tables; run it with {kept} it started with to resume, or "
            f"give a new --out (or delete {self.folder}) to run it anew"
        )

    def _unrecorded(self, what: str, ran: str, versions: str) -> str:
        """A resume refused because the journal's version did not record ``what``: one line."""
        return (
            f"{self.folder} holds the finished units of this run, kept by a version that "
            f"did not record {what}, so whether they ran {ran} that would run the rest "
            f"cannot be checked (a run would mix two {versions} episodes in its tables); "
            f"delete {self.folder} and run the command again, or give a new --out"
        )

    @staticmethod
    def _models(run: dict[str, Any]) -> dict[str, Any]:
        """A run description's digests of its learned policies' files, by label."""
        models = run.get(MODELS)
        return models if isinstance(models, dict) else {}

    @staticmethod
    def _short(digest: Any) -> str:
        """A digest as a refusal shows it (``none``: no learned policy under that label)."""
        return digest[:_SHORT] if isinstance(digest, str) else "none"

    @property
    def resumed(self) -> bool:
        """Whether units were already finished when the journal was opened."""
        return any(self.folder.glob("unit-*.pkl"))

    def load(self) -> dict[int, Any]:
        """The finished units' results by unit index.

        :raises ValueError: for a unit file that cannot be read (names it: delete it to run that
            unit again).
        """
        out: dict[int, Any] = {}
        for path in sorted(self.folder.glob("unit-*.pkl")):
            try:
                index = int(path.stem.removeprefix("unit-"))
                with path.open("rb") as f:
                    out[index] = pickle.load(f)
            except (OSError, ValueError, EOFError, pickle.UnpicklingError) as e:
                raise ValueError(
                    f"{path}: not a readable unit result ({e}); delete it to run that unit again"
                ) from None
        return out

    def put(self, index: int, result: Any) -> None:
        """Keep unit ``index``'s result (atomically: a unit file is whole or absent)."""
        with atomic_path(self.folder / f"unit-{index:06d}.pkl") as tmp, tmp.open("wb") as f:
            pickle.dump(result, f, protocol=pickle.HIGHEST_PROTOCOL)

    def remove(self) -> None:
        """Delete the journal (the run's folder is written)."""
        shutil.rmtree(self.folder, ignore_errors=True)
