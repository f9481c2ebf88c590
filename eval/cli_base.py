"""What every ``follow-eval`` command shares: its name, limits, one-line errors and the
parsers of its option values."""

from __future__ import annotations

import argparse
import contextlib
import signal
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any, NoReturn

from follow_env.tasks.person_follow.config import config_from_text

__all__ = [
    "MAX_EPISODES",
    "MAX_EPISODES_WITHOUT_LOGS",
    "MAX_SEED",
    "PROG",
    "USAGE_ERROR",
    "Terminated",
    "UsageError",
    "path_option",
    "sigterm_as_interrupt",
    "stopped",
]

PROG = "follow-eval"
USAGE_ERROR = 2
#: The most episodes one ``follow-eval run`` takes (policies x scenarios x episodes). A run holds
#: every episode's step log in memory until its tables are written (50-200 kB an episode,
#: measured: 135-450 rows of 41 columns) and writes one CSV of 40-140 kB per episode, so 50,000
#: episodes can take 10 GB of memory and 7 GB of disk. Larger searches use ``eval.rollout``
#: with a ``reduce`` function, as ``follow-tune`` (:mod:`eval.tuning`) does.
MAX_EPISODES = 50_000
#: The most episodes one ``follow-eval run --no-logs`` takes: each episode is reduced to its
#: table row where it ran, so memory grows by about 2 kB an episode instead of 50-200 kB
#: (README "Evaluation", measured by ``make bench``); this is the rollout's own limit
#: (:data:`eval.rollout.MAX_EPISODES`).
MAX_EPISODES_WITHOUT_LOGS = 1_000_000
#: The largest seed the env accepts: ``reset(seed=s)`` takes 0 <= s < 2**256 (follow_env seeds
#: numpy's SeedSequence with up to eight 32-bit words; a test pins this).
MAX_SEED = 2**256 - 1


class UsageError(Exception):
    """Bad arguments or input: reported as one line, exit status 2."""


class Terminated(KeyboardInterrupt):
    """SIGTERM (``kill``, ``timeout``, Slurm's preemption, a Kubernetes stop), raised where the
    command was, as Ctrl-C raises ``KeyboardInterrupt``: it takes Ctrl-C's path (``finally``
    blocks release a study's locks and end the workers, one line says what was kept)."""


#: Exit statuses of a command stopped by a signal: 128 + its number, as a shell reports a
#: process the signal ended (Ctrl-C's SIGINT is 2, SIGTERM 15).
INTERRUPTED = 130
TERMINATED = 143


#: Whether SIGTERM arrived within :func:`sigterm_as_interrupt`: Ray's ``ray.get`` catches the
#: :class:`Terminated` raised while it waits and raises a plain ``KeyboardInterrupt`` instead.
_SIGTERM_SEEN = threading.Event()


def stopped(error: KeyboardInterrupt) -> tuple[str, int]:
    """What a command stopped by ``error`` says it was (``interrupted`` for Ctrl-C,
    ``terminated (SIGTERM)``), and its exit status (:data:`INTERRUPTED`, :data:`TERMINATED`)."""
    if isinstance(error, Terminated) or _SIGTERM_SEEN.is_set():
        return "terminated (SIGTERM)", TERMINATED
    return "interrupted", INTERRUPTED


@contextlib.contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """Within the block, SIGTERM raises :class:`Terminated` in the main thread (elsewhere a
    handler cannot be set, and nothing changes); the previous handler is put back after.

    A second SIGTERM while the first is handled is ignored, so that the clean-up it started
    runs to its end (a lock left behind makes the next run wait 30 s); SIGKILL remains for a
    stop that must not wait.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _SIGTERM_SEEN.clear()

    def handler(signum: int, frame: object) -> None:
        if not _SIGTERM_SEEN.is_set():
            _SIGTERM_SEEN.set()
            raise Terminated

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:  # a handler set outside Python reads as None: the default then
        signal.signal(signal.SIGTERM, signal.SIG_DFL if previous is None else previous)
        _SIGTERM_SEEN.clear()  # the block's messages are given: a later Ctrl-C is Ctrl-C


class _Parser(argparse.ArgumentParser):
    """argparse that reports errors as one line (no usage dump), exit status 2."""

    def error(self, message: str) -> NoReturn:
        raise UsageError(message)


def _config(text: str, read: Any = config_from_text) -> str | dict[str, Any]:
    """``--config``: a preset name, a JSON object of section overrides, or a file of one (read
    by the task's ``config_from_text``, PersonFollow's unless told)."""
    try:
        return read(text)  # type: ignore[no-any-return]
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def path_option(text: str) -> Path:
    """A path option's value; an empty one is refused (``Path("")`` is the current folder, which
    the user did not name)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("the path is empty")
    return Path(text)


def _out_folder(text: str) -> Path:
    """``--out``: a folder's path; an empty one is refused (``Path("")`` is the current folder,
    which would be reported as "``.`` already exists")."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"{text!r} is empty: give the path of a new folder")
    return Path(text)


def _names(text: str, what: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names:
        raise UsageError(f"--{what} is empty: give a comma-separated list of names")
    return list(dict.fromkeys(names))  # drop repeats, keep order


def _workers(text: str) -> int | None:
    if text == "auto":
        return None
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not 'auto' or an integer >= 1") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value} is out of range: must be 'auto' or >= 1")
    return value


def _integer(text: str, low: int) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < low:
        raise argparse.ArgumentTypeError(f"{value} is out of range: must be >= {low}")
    return value


def _non_negative(text: str) -> int:
    return _integer(text, 0)


def _positive(text: str) -> int:
    return _integer(text, 1)
