"""What the backends share: the layer's errors, and what runs in a worker process (a pool's
or Ray's) around each unit: its threads pinned, its exception made fit to travel back.
"""

from __future__ import annotations

import contextlib
import os
import pickle
import reprlib
import signal
import socket
import sys
import threading
import time
import traceback
from collections.abc import Callable
from typing import Any

__all__ = [
    "WORKERS_LOST",
    "BackendUnavailableError",
    "RemoteTraceback",
    "UnitError",
    "WorkerLostError",
    "error_line",
    "pin_threads",
    "unit_origin",
]

#: Units kept in flight per slot: enough that a slot never waits for the driver, few enough
#: that a long grid is not all queued (and pickled) at once.
_IN_FLIGHT_PER_SLOT = 2


class BackendUnavailableError(RuntimeError):
    """The backend cannot run here (Ray not installed, cluster unreachable); says what to do."""


#: The exit status of a command stopped by :class:`WorkerLostError` (every CLI of the project:
#: 2 is bad input, 130 Ctrl-C), so a script can tell "run it again, with fewer workers" apart.
WORKERS_LOST = 3


class WorkerLostError(RuntimeError):
    """Workers kept dying: a unit was retried ``max_retries`` times and its worker died again.

    :ivar index: the unit's index in the units given to :func:`execution.execute`.
    :ivar label: the unit as its caller knows it (``describe``, or its ``repr`` cut short).
    :ivar deaths: how many times its worker died.
    :ivar unfinished: units that had not finished when the run stopped (this one among them).
    """

    def __init__(
        self, index: int, label: str, deaths: int, max_retries: int, unfinished: int, last: str
    ) -> None:
        super().__init__(
            f"unit {index} {label}: its worker process died {deaths} times (max_retries="
            f"{max_retries}; {unfinished} units unfinished); the last time {last}"
        )
        self.index, self.label, self.deaths, self.unfinished = index, label, deaths, unfinished
        self._fields = (index, label, deaths, max_retries, unfinished, last)

    def __reduce__(self) -> tuple[Any, ...]:
        return (WorkerLostError, self._fields)


class RemoteTraceback(Exception):  # noqa: N818  (text carried as a cause, not an error)
    """A unit's traceback in the worker that ran it, as text: the ``__cause__`` of its exception
    re-raised in the caller, so that a printed traceback shows the worker's frames first (as
    :mod:`concurrent.futures` does for a process pool, whose own class is private)."""

    def __init__(self, text: str) -> None:
        super().__init__(text)
        self.text = text

    def __str__(self) -> str:
        return f'\n"""\n{self.text.rstrip()}\n"""'


class UnitError(RuntimeError):
    """A unit raised an exception that cannot cross a process boundary (it does not survive
    pickling: an ``__init__`` whose arguments are not its ``args``, a lock or a file inside).

    Raised in its place by a pool or Ray worker, so that the caller still learns what failed
    (a pool would otherwise report a broken pool and retry the unit as if its worker had died;
    Ray an ``UnserializableException``).

    :ivar type_name: the original exception's qualified name (``module.Class``).
    :ivar message: its ``str()``.
    :ivar traceback_text: its traceback, formatted in the worker.
    """

    def __init__(self, type_name: str, message: str, traceback_text: str) -> None:
        super().__init__(
            f"{type_name}: {message}\n(re-raised as UnitError: the exception could not be "
            f"pickled back from its worker; its traceback there:)\n{traceback_text}"
        )
        self.type_name = type_name
        self.message = message
        self.traceback_text = traceback_text

    def __reduce__(self) -> tuple[Any, ...]:
        # The three fields, not the composed message: unpickling calls __init__ with these;
        # and the rest of its state (where it was raised: :func:`_tag_origin`).
        return (UnitError, (self.type_name, self.message, self.traceback_text), self.__dict__)


#: Where a worker raised an exception (an attribute of the exception, pickled with it).
_ORIGIN = "_execution_worker"
#: Which unit raised it and where, as :func:`unit_origin` words it (set in the caller).
_UNIT_ORIGIN = "_execution_unit_origin"


def unit_origin(error: BaseException) -> str:
    """Where ``error`` was raised, if a unit raised it in a worker (a pool's or Ray's): e.g.
    ``"work unit 3 (pn:tuned on straight, seeds 0-19) on host node-2, process 4242"`` (the unit as
    its caller's ``describe`` names it); else ``""``.

    A command line that prints an error in one line appends it: the worker's traceback is the
    error's ``__cause__`` (:class:`RemoteTraceback`), which such a line leaves out.
    """
    where = getattr(error, _UNIT_ORIGIN, "")
    return where if isinstance(where, str) else ""


def error_line(error: BaseException) -> str:
    """``error``'s message as a one-line command-line error gives it: followed by `` (in
    <where>)`` (:func:`unit_origin`) if a unit raised it in a worker."""
    where = unit_origin(error)
    return f"{error} (in {where})" if where else str(error)


def _tag_origin(error: BaseException) -> None:
    """Mark ``error`` as raised in this worker (host, pid): an attribute, which travels back
    to the caller with the pickled exception (a class whose pickling drops it loses it)."""
    # An exception class that refuses attributes: no origin, no harm.
    with contextlib.suppress(Exception):
        setattr(error, _ORIGIN, (socket.gethostname(), os.getpid()))


def _note_origin(error: BaseException, index: int, label: str) -> None:
    """In the caller: name the unit that raised ``error`` in a worker, and where, as a note
    (shown under a traceback's last line) and for :func:`unit_origin`."""
    worker = getattr(error, _ORIGIN, None)
    if not (isinstance(worker, tuple) and len(worker) == 2):
        return  # not raised by a unit in a worker (a result that could not be pickled, ...)
    where = f"work unit {index} {label} on host {worker[0]}, process {worker[1]}"
    try:
        setattr(error, _UNIT_ORIGIN, where)
        error.add_note(f"(raised in {where})")
    except Exception:
        pass


#: How a unit is named in messages by default: its ``repr``, each part cut short.
_REPR = reprlib.Repr()
_REPR.maxlevel, _REPR.maxtuple, _REPR.maxlist, _REPR.maxdict = 3, 6, 6, 4
_REPR.maxstring, _REPR.maxother = 40, 40
#: The longest a unit's name in a message may be (characters).
_LABEL_CHARS = 120


def _describe(unit: Any) -> str:
    """A unit's name in messages: its ``repr``, long parts cut short (``...``), at most
    :data:`_LABEL_CHARS` characters; never raises (a broken ``__repr__`` names its type)."""
    try:
        text = _REPR.repr(unit)
    except Exception:
        text = f"<{type(unit).__qualname__}>"
    return text if len(text) <= _LABEL_CHARS else text[: _LABEL_CHARS - 3] + "..."


def _label(describe: Callable[[Any], str] | None, unit: Any) -> str:
    """``unit`` in parentheses, as ``describe`` (the caller's) or :func:`_describe` names it."""
    if describe is not None:
        try:
            return f"({describe(unit)})"
        except Exception:
            pass  # a message must not fail for its label's sake
    return f"({_describe(unit)})"


def _exit_reason(code: int | None) -> str:
    """How a worker process ended, from its exit code (negative: the signal that ended it)."""
    if code is None:
        return "for a reason not known"
    if code >= 0:
        return f"exiting with status {code}"
    try:
        name = signal.Signals(-code).name
    except ValueError:
        name = f"signal {-code}"
    oom = " (the system's out-of-memory killer's signal)" if -code == signal.SIGKILL else ""
    return f"killed by {name}{oom}"


def pin_threads(cpus: int) -> None:
    """Limit this process's numba, torch and OpenMP/BLAS threads to ``cpus``.

    Runs at the start of every task: Ray sets ``OMP_NUM_THREADS=1`` only for tasks without
    ``num_cpus``, and numba sizes its pool from the machine, so without this two tasks on a
    2-core machine would each start two busy threads (STACK.md, Ray).
    """
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = str(cpus)
    if "numba" in sys.modules:
        import numba

        numba.set_num_threads(max(1, min(cpus, numba.config.NUMBA_NUM_THREADS)))
    else:
        # Read when numba is first imported; changing it afterwards is refused by numba.
        os.environ["NUMBA_NUM_THREADS"] = str(cpus)
    if "torch" in sys.modules:
        import torch

        torch.set_num_threads(cpus)


#: In a pool worker: its pool's shared array of [pid, unit index running or -1] per worker,
#: and the offset of this worker's pair in it (see :class:`execution.backend._Pool`).
_SLOTS: Any = None
_SLOT = -1


def _run_unit(fn: Callable[[Any], Any], unit: Any, index: int = -1) -> Any:
    """``fn(unit)`` in a worker, its exception made fit to travel back to the caller.

    In a pool worker, the unit's ``index`` is in the worker's slot while it runs: if the
    worker dies, the caller knows which unit it died running.

    An exception that does not survive pickling cannot be sent back: a pool would report its
    worker as broken (and the unit be retried as if it had died), Ray an
    ``UnserializableException``. Such an exception is replaced by a :class:`UnitError` naming
    it; any other goes back as raised.
    """
    if _SLOTS is not None:
        _SLOTS[_SLOT + 1] = index
    try:
        return fn(unit)
    except BaseException as e:
        _tag_origin(e)  # first: the test below then pickles the exception as it will travel
        try:
            pickle.loads(pickle.dumps(e))
        except Exception:
            name = f"{type(e).__module__}.{type(e).__qualname__}"
            text = "".join(traceback.format_exception(e))
            error = UnitError(name, str(e), text)
            _tag_origin(error)
            # from None: the original stays out of the chain, which would be pickled with it
            # by anything that pickles __cause__ or __context__.
            raise error from None
        raise
    finally:
        if _SLOTS is not None:
            _SLOTS[_SLOT + 1] = -1


def _call(fn: Callable[[Any], Any], unit: Any, cpus: int, index: int = -1) -> Any:
    """A Ray task: pin the worker's threads (it may have run other tasks), then the unit."""
    pin_threads(cpus)
    return _run_unit(fn, unit, index)


#: How often a pool worker checks that the process that started it is alive (s).
_PARENT_POLL_S = 1.0


def _start_worker(cpus: int, parent: int, slots: Any) -> None:
    """A pool worker's initializer: pin its threads, take a slot in ``slots`` (the units it
    runs are written there), and exit when ``parent`` has gone.

    Without the watch, a worker whose parent was killed (SIGKILL, out of memory) would finish
    its unit, and then wait for more forever, holding its memory. A thread polling the parent's
    pid, not Linux's PR_SET_PDEATHSIG: that fires when the *thread* that started the worker
    exits, and a pool started by one thread of the caller is kept for calls from others.
    """
    pin_threads(cpus)
    global _SLOTS, _SLOT
    with slots.get_lock():
        for k in range(0, len(slots), 2):
            if slots[k] == 0:  # free: a pool's workers are never replaced, one each suffices
                slots[k], slots[k + 1] = os.getpid(), -1
                _SLOTS, _SLOT = slots, k
                break

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(_PARENT_POLL_S)
        os._exit(1)  # the parent is gone: nobody waits for this worker's results

    threading.Thread(target=watch, name="watch-parent", daemon=True).start()
