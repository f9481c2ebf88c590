"""``python -m eval.line_tune``: the search behind the line followers' ``tuned`` presets, now
``follow-tune`` (:mod:`eval.tuning`) run for ``coordinate`` and ``pid`` on LineTrace.

    python -m eval.line_tune                   # the committed search (~20 min on one core)
    python -m eval.line_tune --out-root runs/quick --trials 20 --seeds 2

Each controller runs as ``follow-tune <law> --task line_trace --trials 80 --seeds 8
--holdout-seeds 20 --holdout-scenarios straight,corners,curves,zigzag,gaps,course,random --out
<root>/tune-<law>`` (:data:`BUDGET`): the same search for both, so that neither is compared
untuned against a tuned other, on the tuning tracks ``straight``, ``corners``, ``curves``,
``zigzag`` and ``gaps`` (the evaluation's mixed ``course`` and ``random`` left out) and tuning
seeds 1000 + k. The held-out check adds the mixed courses (on held-out seeds 2000 + k, not the
evaluation's): the trials that do best on the single-kind tracks were found to fail them far
more often than the presets (README "Tuning"). Further options are passed on to every run.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from eval import tune
from eval.tuning.objective import DEFAULT_VARIANTS

__all__ = ["BUDGET", "LAWS", "TRACKS", "commands", "main"]

#: The controllers tuned, in order.
LAWS: tuple[str, ...] = ("coordinate", "pid")
#: The tracks they are tuned on (follow-tune's default for the task).
TRACKS: tuple[str, ...] = DEFAULT_VARIANTS["line_trace"]
#: The committed budget.
BUDGET: tuple[str, ...] = (
    "--task", "line_trace", "--trials", "80", "--seeds", "8", "--holdout-seeds", "20",
    "--holdout-scenarios", ",".join((*DEFAULT_VARIANTS["line_trace"], "course", "random")),
)  # fmt: skip


def commands(argv: Sequence[str] = ()) -> list[list[str]]:
    """The ``follow-tune`` argument lists run, one per controller (:func:`eval.tune.commands`)."""
    return tune.commands(argv, LAWS, BUDGET)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m eval.line_tune``: follow-tune each of :data:`LAWS`; returns the exit status."""
    argv = sys.argv[1:] if argv is None else argv
    return tune.run_all(argv, LAWS, "python -m eval.line_tune", BUDGET)


if __name__ == "__main__":
    sys.exit(main())
