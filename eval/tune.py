"""``python -m eval.tune``: the search behind the guidance laws' ``tuned`` presets, now
``follow-tune`` (:mod:`eval.tuning`) run once per law with the committed budget.

    python -m eval.tune                        # the committed search: pn, mpn, gsmpn (~3 min)
    python -m eval.tune --out-root runs/quick --trials 30 --seeds 4   # quicker, coarser

Each law runs as ``follow-tune <law> --trials 150 --seeds 20 --holdout-seeds 50 --out
<root>/tune-<law>`` (:data:`BUDGET`); further options are passed on to every run and override
the budget's. The grid search that used to live here is replaced by that Optuna search (its
ranges cover the old grid: ``tests/eval/test_tuning.py``).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from eval.tuning import cli

__all__ = ["BUDGET", "LAWS", "commands", "help_text", "main"]

#: The laws tuned, in order.
LAWS: tuple[str, ...] = ("pn", "mpn", "gsmpn")
#: The committed budget (README "Tuning": the run whose held-out tables are quoted there).
BUDGET: tuple[str, ...] = ("--trials", "150", "--seeds", "20", "--holdout-seeds", "50")


def commands(
    argv: Sequence[str] = (), laws: Sequence[str] = LAWS, budget: Sequence[str] = BUDGET
) -> list[list[str]]:
    """The ``follow-tune`` argument lists run, one per law: the budget, the output folder
    ``<root>/tune-<law>`` (``--out-root``, default ``runs``), then ``argv``'s other options."""
    rest = list(argv)
    root = "runs"
    if "--out-root" in rest:
        i = rest.index("--out-root")
        if i + 1 >= len(rest):
            raise cli.UsageError("argument --out-root: expected one argument")
        root = rest[i + 1]
        del rest[i : i + 2]
    return [[law, *budget, "--out", f"{root}/tune-{law}", *rest] for law in laws]


def help_text(prog: str, laws: Sequence[str], budget: Sequence[str] = BUDGET) -> str:
    """The ``--help`` of a command that runs follow-tune once per law (``python -m eval.tune``,
    ``python -m eval.line_tune``): its own usage, not follow-tune's (which takes one law and
    no ``--out-root``)."""
    parser = argparse.ArgumentParser(
        prog=prog,
        usage=f"{prog} [-h] [--out-root DIR] [follow-tune options]",
        description=f"Run follow-tune once per law ({', '.join(laws)}), each as `follow-tune "
        f"LAW {' '.join(budget)} --out DIR/tune-LAW`, in turn; stop at the first that fails.",
        epilog="Any other option is passed on to every run and overrides the budget's "
        "(follow-tune --help lists them; LAW and --out are given here).",
    )
    parser.add_argument(
        "--out-root", metavar="DIR", default="runs", help="where the runs' folders go (runs)"
    )
    return parser.format_help()


def run_all(
    argv: Sequence[str], laws: Sequence[str], prog: str, budget: Sequence[str] = BUDGET
) -> int:
    """Run :func:`commands` in turn; stop at the first that fails, with its exit status
    (``-h``/``--help``: :func:`help_text`, exit status 0)."""
    if any(a in ("-h", "--help") for a in argv):
        print(help_text(prog, laws, budget), end="")
        return 0
    try:
        runs = commands(argv, laws, budget)
    except cli.UsageError as e:
        print(f"{prog}: error: {e}", file=sys.stderr)
        return 2
    for args in runs:
        status = cli.main(args)
        if status != 0:
            return status
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m eval.tune``: follow-tune each of :data:`LAWS`; returns the exit status."""
    return run_all(sys.argv[1:] if argv is None else argv, LAWS, "python -m eval.tune")


if __name__ == "__main__":
    sys.exit(main())
