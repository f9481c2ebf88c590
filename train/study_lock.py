"""One ``follow-train`` command at a time on a study folder, and one training on a run folder.

Two commands on one study at once would both resume the same seed, and a seed still training
before its first checkpoint looks exactly like one killed then, which the other command clears
(:mod:`train.seeds`); two trainings of one run (``--resume RUN`` twice, or beside the study
command training it) would write the same checkpoints and logs. A command therefore holds its
study folder for as long as it runs, and a training its run folder (:func:`train.ppo.train`):
an exclusive ``flock`` on the folder itself, so no lock file is left behind, and the kernel
releases it when the process ends, however it ends (a killed command never blocks the next).
A second command is refused in one line before it changes anything. A file system that takes
no lock on a folder (NFS, on a folder opened to read) leaves it unguarded, as before.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

try:
    import fcntl
except ImportError:  # Windows: no flock, so unguarded (as on a file system without locks)
    fcntl = None  # type: ignore[assignment]

__all__ = ["StudyLock"]


class StudyLock(contextlib.ExitStack):
    """The hold of this command on ``study`` (module docstring), released on leaving the
    ``with`` block; :meth:`take` takes it once the folder exists."""

    def __init__(
        self, study: Path | None = None, option: str = "--out", what: str = "study"
    ) -> None:
        """:param study: the folder (None: named by :meth:`take`, when a new run makes it).
        :param option: the option that named the folder, and ``what`` it is, for the refusal
            (``--resume``, ``run``)."""
        super().__init__()
        self.study, self.held = study, False
        self.option, self.what = option, what

    def take(self, folder: Path | None = None) -> None:
        """Hold the study folder (``folder``, if given), if it exists and is not held yet.

        :raises ValueError: if another command holds it (nothing is changed).
        """
        # (one class for a study and a run: the same hold, only the words differ)
        self.study = self.study if folder is None else folder
        if self.held or fcntl is None or self.study is None or not self.study.is_dir():
            return
        try:
            fd = os.open(self.study, os.O_RDONLY)
        except OSError:  # a folder this user may not read: its first use names it
            return
        self.callback(os.close, fd)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise ValueError(
                f"{self.option} {self.study}: another follow-train command is training this "
                f"{self.what} now; wait for it to end (or stop it) and run this again"
            ) from None
        except OSError:
            pass  # no lock on this file system: unguarded (module docstring)
        self.held = True
