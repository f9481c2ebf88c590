"""Build the policy of a mode chosen on the robot without stalling its control loop.

Building a learned agent the first time imports torch and loads its weights: about 2 s on a
2-core PC, 20 control periods of 0.1 s. Built inside the control loop, that would leave the
wheels at their last targets, with no fresh command, for as long. :class:`PolicyLoader` builds
it in a thread of its own instead; until it is ready the robot goes on doing what it did (the
previous mode's policy, or standing still), and a mode that cannot be built or run is refused
then. Modes are built side by side, so a law chosen while an agent is loading (the user
changed their mind) takes over at once instead of waiting for that load.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

__all__ = ["MAX_BUILDS", "PolicyLoader"]

#: How many modes are built at once; a mode chosen while as many are building waits for one
#: of them. Each learned agent being built holds its weights and a torch model (tens of MB).
MAX_BUILDS = 4


class PolicyLoader:
    """Builds the policies of modes in background threads, up to :data:`MAX_BUILDS` at once.

    :param factory: builds a mode's policy (``make_policy``).
    :param check: checks that the robot can run a built policy and returns it; raises the
        reason it cannot (``ValueError``, ``PerceptionError``).
    """

    def __init__(self, factory: Callable[[str], Any], check: Callable[[Any], Any]) -> None:
        self._factory = factory
        self._check = check
        self._pool = ThreadPoolExecutor(max_workers=MAX_BUILDS, thread_name_prefix="policy-loader")
        self._pending: dict[str, Future[Any]] = {}

    def get(self, mode: str) -> Any | None:
        """``mode``'s policy once built and checked, ``None`` while it is being built (the
        first call starts building it). Once built, the policy is handed over once: the caller
        keeps it, and a later call builds afresh.

        :raises: what building or checking it raised, once, when it finishes.
        """
        future = self._pending.get(mode)
        if future is None:
            future = self._pending[mode] = self._pool.submit(self._build, mode)
        if not future.done():
            return None
        del self._pending[mode]
        return future.result()

    @property
    def pending(self) -> list[str]:
        """The modes being built, in the order they were asked for (not those built and not
        yet claimed: a mode given up before it was built is no longer being built)."""
        return [mode for mode, future in self._pending.items() if not future.done()]

    def close(self) -> None:
        """Forget the modes not started yet; those being built finish in their threads, unused."""
        self._pool.shutdown(wait=False, cancel_futures=True)
        self._pending.clear()

    def _build(self, mode: str) -> Any:
        return self._check(self._factory(mode))
