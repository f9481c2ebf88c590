"""A run's finished work units, kept so that an interrupted run resumes where it stopped.

``follow-eval run --out DIR`` keeps each finished work unit (one policy, scenario and chunk of
seeds: :func:`eval.rollout.work_units`) in a hidden folder beside ``DIR``, ``.DIR.units/``, one
pickle per unit written atomically. Ctrl-C (or a crash) leaves that folder and no ``DIR``; the
same command run again reads it, skips the finished units and runs the rest, and removes it
once ``DIR`` is written. The folder also holds what the run is (``run.json``: its grid, config
and chunking, and the SHA-256 of the code that runs its episodes: ``"code"``), so a different
command pointed at the same ``--out``, or the same command run by other code, is refused
instead of mixing two runs.
"""

from __future__ import annotations

import json
import pickle
import shutil
from pathlib import Path
from typing import Any

from follow_env.sim.atomic import atomic_path, atomic_write_text

__all__ = ["UnitJournal", "journal_folder"]

_RUN = "run.json"
#: The run description's key for the digest of the code its units ran
#: (:func:`eval.provenance.code_revision`'s ``sources_sha256``).
CODE = "code"


def journal_folder(out: str | Path) -> Path:
    """Where the units of a run writing ``out`` are kept: ``.<name>.units`` beside it."""
    out = Path(out)
    return out.parent / f".{out.name}.units"


class UnitJournal:
    """The finished units of one run (see the module docstring).

    :param folder: the journal's folder (:func:`journal_folder`).
    :param run: what the run is, JSON-serialisable; a journal made by another run is refused.
    :raises ValueError: if ``folder`` holds another run's units, or its ``run.json`` is corrupt
        (the message names the file).
    """

    def __init__(self, folder: str | Path, run: dict[str, Any]) -> None:
        self.folder = Path(folder)
        self.run = json.loads(json.dumps(run))  # as it reads back: tuples become lists
        path = self.folder / _RUN
        if path.exists():
            try:
                had = json.loads(path.read_text(encoding="utf-8"))
            except (OSError, ValueError) as e:
                raise ValueError(f"{path}: not a readable run description ({e})") from None
            if had != self.run:
                keys = sorted(set(had) | set(self.run)) if isinstance(had, dict) else []
                differ = [k for k in keys if had.get(k) != self.run.get(k)]
                if differ == [CODE]:  # the same command: only the code changed
                    raise ValueError(self._code_changed(had.get(CODE)))
                what = f" (its {', '.join(differ)} differ)" if differ else ""
                raise ValueError(
                    f"{self.folder} holds the finished units of another run{what}; see {path}: "
                    "run that command again to resume it, or delete the folder"
                )
        else:
            self.folder.mkdir(parents=True, exist_ok=True)
            atomic_write_text(path, json.dumps(self.run, indent=1) + "\n")

    def _code_changed(self, had: Any) -> str:
        """Why a resume by other code is refused, and what to do: one line."""
        now = self.run.get(CODE)
        if not isinstance(had, str) or not isinstance(now, str):
            return (
                f"{self.folder} holds the finished units of this run, kept by a version that "
                "did not record its code, so whether they ran the code that would run the rest "
                "cannot be checked (a run would mix two code versions' episodes in its tables); "
                f"delete {self.folder} and run the command again, or give a new --out"
            )
        return (
            f"{self.folder} holds the finished units of this run, but the code changed since "
            f"the run started (the SHA-256 of its simulator, policy and evaluation sources was "
            f"{had[:12]}, is now {now[:12]}): resuming would mix two code versions' episodes in "
            "one run's tables; run it with the code it started with to resume, or give a new "
            f"--out (or delete {self.folder}) to run it anew"
        )

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
