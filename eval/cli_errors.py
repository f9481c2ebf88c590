"""How ``follow-eval`` reports the errors it expects: one line on stderr and an exit status.

Bad arguments or input exit with :data:`~eval.cli_base.USAGE_ERROR` (2); an exception a work
unit raised in a worker process (a pool's or Ray's) says which unit, on which host
(:func:`execution.unit_origin`), since the one line leaves out the worker's traceback. Workers
that kept dying (:class:`execution.WorkerLostError`: the system's out-of-memory killer, most
often) exit with :data:`WORKERS_LOST` (3), saying what was kept and how to resume.
"""

from __future__ import annotations

import argparse
import sys

from eval.cli_base import PROG, USAGE_ERROR, UsageError
from eval.journal import journal_folder
from eval.steplog import StepLogError
from execution import WORKERS_LOST, BackendUnavailableError, WorkerLostError, error_line

__all__ = ["KNOWN_ERRORS", "WORKERS_LOST", "report_error"]

#: The errors ``follow-eval`` reports in one line; any other is a bug, shown with its traceback.
KNOWN_ERRORS = (
    UsageError,
    StepLogError,
    OSError,  # FileExistsError among them
    ValueError,
    BackendUnavailableError,
    WorkerLostError,
)


def report_error(error: BaseException, args: argparse.Namespace | None) -> int:
    """Print ``error`` (one of :data:`KNOWN_ERRORS`) in one line on stderr; its exit status.

    :param args: the parsed command line (None if it did not parse): what a resume needs.
    """
    if isinstance(error, WorkerLostError):
        print(f"{PROG}: error: {error}; {_what_was_kept(args)}", file=sys.stderr)
        return WORKERS_LOST
    print(f"{PROG}: error: {error_line(error)}", file=sys.stderr)
    return USAGE_ERROR


def _what_was_kept(args: argparse.Namespace | None) -> str:
    """What a command stopped by dying workers leaves, and how to go on."""
    if args is None or getattr(args, "command", None) != "run" or args.out is None:
        return "nothing was written: run it again (with fewer --workers if memory is short)"
    folder = journal_folder(args.out)
    if not folder.is_dir():  # `run` removes a journal that holds no unit
        return f"no work unit had finished, nothing was kept; {args.out} was not written"
    return (
        f"{args.out} was not written, the finished work units are kept in {folder}: the same "
        f"command with --out {args.out} resumes from them (with fewer --workers if memory is "
        "short)"
    )
