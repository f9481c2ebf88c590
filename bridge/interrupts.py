"""A shutdown that repeated Ctrl-C cannot cut short.

The runner must stop the wheels and save the step log whatever happens; a user who presses
Ctrl-C twice (or a supervisor that sends SIGINT, then SIGTERM at once) would otherwise raise a
second ``KeyboardInterrupt`` in the middle of that and lose the session's log.
:class:`InterruptGuard` lets the first interrupt through, as before, and only counts the ones
after it, and every one once the shutdown has begun (:attr:`InterruptGuard.holding`).
"""

from __future__ import annotations

import signal
import threading
from types import FrameType, TracebackType
from typing import Any

__all__ = ["InterruptGuard"]


class InterruptGuard:
    """Within ``with InterruptGuard() as guard:`` (in the main thread; elsewhere it does
    nothing, as only the main thread sets and runs signal handlers), SIGINT and SIGTERM whose
    handler is a Python function (Ctrl-C's ``KeyboardInterrupt``; the command line's SIGTERM)
    reach it only once: the first runs the handler, any later one is counted in
    :attr:`deferred` and otherwise ignored. Set :attr:`holding` to ``True`` where a shutdown
    begins (an attribute, not a method: a call is where Python runs pending signal handlers)
    and every signal from then on is deferred. The previous handlers are back on exit.
    """

    def __init__(self, signums: tuple[int, ...] = (signal.SIGINT, signal.SIGTERM)) -> None:
        self.signums = signums
        self.holding = False  # a shutdown is under way: defer every signal
        self.deferred = 0  # signals that arrived while deferred
        self._interrupted = False  # the first signal went through: defer the rest
        self._previous: dict[int, Any] = {}

    def __enter__(self) -> InterruptGuard:
        if threading.current_thread() is not threading.main_thread():
            return self
        for signum in self.signums:
            previous = signal.getsignal(signum)
            if callable(previous):  # SIG_DFL and SIG_IGN keep their meaning
                self._previous[signum] = previous
                signal.signal(signum, self._handle)
        return self

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        for signum, previous in self._previous.items():
            signal.signal(signum, previous)
        self._previous.clear()

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        if self.holding or self._interrupted:
            self.deferred += 1
            return
        self._interrupted = True  # first: a signal during the handler below is deferred
        self._previous[signum](signum, frame)
        self._interrupted = False  # it did not interrupt (it returned): the next one may
