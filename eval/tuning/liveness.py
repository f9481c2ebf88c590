"""Studies shared by processes: which running trials are alive, and telling trials that
another process may finish at the same moment.

Several drivers (machines, or processes of one machine) may share one study. Each records in
each trial it runs its owner (host name and process id), the owner's PID space and a
heartbeat: when it asks the trial (:func:`own`), then every :data:`HEARTBEAT_S` while the
trial's batch runs (:class:`Heartbeat`). :func:`fail_stale` fails the running trials whose
process is gone: of this machine, by their process id; of any machine, when their heartbeat
is older than :data:`STALE_AFTER_S`; and those that name no owner, left by a process that
stopped between Optuna's creating the trial and :func:`own`, when they began more than
:data:`UNOWNED_AFTER_S` ago. :func:`told` is ``study.tell`` for a trial another process may
have finished meanwhile (its owner, or a machine that failed it as stale).
"""

from __future__ import annotations

import os
import socket
import threading
import time
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import optuna
from optuna.exceptions import UpdateFinishedTrialError
from optuna.trial import FrozenTrial, TrialState

__all__ = [
    "HEARTBEAT_S",
    "STALE_AFTER_S",
    "UNOWNED_AFTER_S",
    "Heartbeat",
    "fail_stale",
    "own",
    "stale_text",
    "told",
]

#: How often a search records in the study that its running trials are alive, s.
HEARTBEAT_S = 60.0
#: A running trial whose last heartbeat is older than this was left by a process that is gone
#: (a machine that crashed or lost the network): ten heartbeats missed, s. Heartbeats are
#: wall-clock times (``time.time()``), so machines sharing a study need clocks that agree to
#: well within it (NTP keeps them within a second).
STALE_AFTER_S = 600.0
#: A running trial that names no owner is failed when Optuna's ``datetime_start`` is more than
#: this old, s: a search owns its trial the moment Optuna has created it, so one unowned this
#: long was left by a search that stopped in between. Optuna (5.0 on) keeps that start in UTC
#: in every storage and gives it in this machine's local time, so it compares with this
#: machine's clock as a heartbeat does (the same agreement of clocks is assumed).
UNOWNED_AFTER_S = STALE_AFTER_S

_OWNER = "owner"
#: The user attribute naming the PID space of a trial's owner (:func:`_pid_space`).
_PID_SPACE = "pid_space"
#: The user attribute holding a running trial's last heartbeat (``time.time()``, s).
_BEAT = "heartbeat"
#: Heartbeats refused in a row before a warning says so (a storage hiccup is not worth one).
_FAILED_BEATS = 3


def _owner() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def _pid_space() -> str | None:
    """Which processes this one's id is among (Linux: the kernel's boot id and this process's
    PID namespace), or None where that cannot be read. Machines or containers may share a host
    name; a process id means something only among the processes of one such space."""
    try:
        boot = Path("/proc/sys/kernel/random/boot_id").read_text().strip()
        namespace = os.stat("/proc/self/ns/pid").st_ino
    except OSError:
        return None
    return f"{boot}/{namespace}"


def _alive(trial: FrozenTrial) -> bool:
    """Whether the process that owns a running trial still runs: asked of this machine's
    processes when the trial's owner has this host name and, if it recorded one, this
    process's PID space; anywhere else assumed so (its heartbeat tells)."""
    host, _, pid = str(trial.user_attrs.get(_OWNER, "")).rpartition(":")
    if host != socket.gethostname() or not (pid.isascii() and pid.isdigit()):
        return True
    space = trial.user_attrs.get(_PID_SPACE)
    if space is not None and space != _pid_space():
        return True  # the same name, another machine or container
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _silent_s(trial: FrozenTrial, now: float) -> float | None:
    """Seconds since a running trial's last heartbeat (None when it records none: a trial of a
    version before heartbeats, judged by its owner alone)."""
    beat = trial.user_attrs.get(_BEAT)
    if isinstance(beat, bool) or not isinstance(beat, int | float):
        return None
    return now - float(beat)


def fail_stale(study: optuna.Study, *, now: float | None = None) -> list[FrozenTrial]:
    """Mark as failed the running trials whose process is gone, and return them as they were:
    those of a process of this machine that no longer runs (an interrupted run); those of any
    machine whose last heartbeat is more than :data:`STALE_AFTER_S` old (a machine that
    crashed: its trials would otherwise count towards the budget for ever); and those that name
    no owner and began more than :data:`UNOWNED_AFTER_S` ago."""
    now = time.time() if now is None else now
    stale = []
    for t in study.get_trials(deepcopy=False, states=(TrialState.RUNNING,)):
        if _OWNER not in t.user_attrs:
            start = t.datetime_start  # this machine's local time, without zone
            if start is not None and now - start.timestamp() > UNOWNED_AFTER_S:
                stale.append(t)
            continue
        silent = _silent_s(t, now)
        if not _alive(t) or (silent is not None and silent > STALE_AFTER_S):
            stale.append(t)
    return [t for t in stale if told(study, t.number, state=TrialState.FAIL)]


def told(study: optuna.Study, number: int, value: float | None = None, **kwargs: Any) -> bool:
    """``study.tell`` of a trial that another process may finish at the same moment (its owner
    telling it, or another machine failing it as stale); whether this tell finished it. A
    trial finished first stays as that process left it."""
    try:
        frozen = study.tell(number, value, skip_if_finished=True, **kwargs)
    except UpdateFinishedTrialError:  # finished between Optuna's check and its write
        return False
    return frozen.state == kwargs.get("state", TrialState.COMPLETE)


def stale_text(trial: FrozenTrial) -> str:
    """What :func:`fail_stale` did to ``trial``, in a sentence for a command's output."""
    if _OWNER not in trial.user_attrs:
        start = trial.datetime_start
        when = f"asked at {start:%Y-%m-%d %H:%M:%S} and" if start is not None else "asked,"
        return (
            f"trial {trial.number}, {when} never owned, marked failed: the search that asked "
            "it stopped before it could record itself"
        )
    return (
        f"trial {trial.number} left running by {trial.user_attrs.get(_OWNER, '?')} marked "
        "failed: its process is gone (on this machine) or sent no heartbeat for "
        f"{STALE_AFTER_S / 60:.0f} min"
    )


class Heartbeat:
    """While in its ``with`` block, records every :data:`HEARTBEAT_S` in each of ``trials``
    that it is alive (the user attribute ``heartbeat``; the first beat is the caller's, on
    asking), from a thread of its own, so another machine sharing the study can tell a slow
    trial from one whose machine is gone. A trial finished meanwhile (told, or failed by
    another machine) is no longer beaten for. A beat the storage refuses is tried again at the
    next one; after :data:`_FAILED_BEATS` refused in a row a warning says so once, since
    other machines fail the trials when none has been recorded for :data:`STALE_AFTER_S`."""

    def __init__(self, trials: Sequence[optuna.Trial], interval_s: float | None = None) -> None:
        self._trials = list(trials)
        self._interval_s = HEARTBEAT_S if interval_s is None else interval_s
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="tuning heartbeat", daemon=True)
        self._refused = 0

    def beat(self) -> None:
        now = time.time()
        for trial in list(self._trials):
            try:
                trial.set_user_attr(_BEAT, now)
            except UpdateFinishedTrialError:
                self._trials.remove(trial)
            except Exception as e:  # a storage hiccup: the next beat tries again
                self._refused += 1
                if self._refused == _FAILED_BEATS:
                    warnings.warn(
                        f"{_FAILED_BEATS} heartbeats in a row could not be recorded in the "
                        f"study ({type(e).__name__}: {e}); other machines sharing it fail "
                        f"this search's running trials after {STALE_AFTER_S / 60:.0f} min "
                        "without one",
                        RuntimeWarning,
                        stacklevel=1,
                    )
                return
        self._refused = 0

    def _run(self) -> None:
        while not self._stop.wait(self._interval_s):
            self.beat()

    def __enter__(self) -> Heartbeat:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()


def own(trial: optuna.Trial) -> None:
    """Record this process as the owner of ``trial``, just asked, with its first heartbeat."""
    trial.set_user_attr(_OWNER, _owner())
    trial.set_user_attr(_PID_SPACE, _pid_space())
    trial.set_user_attr(_BEAT, time.time())
