"""``follow-eval dominance``: a learner against the best law, from one run folder or several
pooled (see :mod:`eval.cli` and :mod:`eval.dominance`).

A run holds at most :data:`~eval.cli_base.MAX_EPISODES` episodes
(:data:`~eval.cli_base.MAX_EPISODES_WITHOUT_LOGS` with ``--no-logs``), and the strict reading of
"at least as good" needs many: the best of six laws on a line is the best of six noisy means,
so with 100 episodes a scenario a learner that ties the laws misses lines by chance. Several
runs on disjoint seeds are therefore pooled into one table, as if one run had held them all,
after checking that they can be: each run made alike (task, configuration, ideal baseline, and
the same gains or model under each label, from ``meta.json``: a learned policy's model by the
SHA-256 of its files where both runs record one, else by its ``repr``), each holding the same
scenarios and every learner and law judged, and no episode (policy, scenario, seed) in two of
them. The pooled table keeps a ``run`` column naming each episode's run. Runs made from other
simulator, policy or evaluation code (``meta.json``'s ``code``, :mod:`eval.provenance`), or
recording none, are pooled with a warning and a note under the report's opening line, not
refused: rollouts can survive a refactor. So are runs that record no digest of a judged learned
policy's files (``model_sha256``: written before runs recorded it), whose model under that
label cannot be checked to be the other runs'.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import json
import sys
from array import array
from collections.abc import Sequence
from decimal import Decimal, InvalidOperation
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from eval.cli_base import MAX_SEED, PROG, UsageError, _names
from follow_env.sim.checks import one_line

__all__ = ["check_covered", "cmd_dominance", "pooled_table", "read_episode_table"]

#: What ``meta.json`` records that must agree for two runs to be pooled.
ALIKE = ("task", "config", "ideal_baseline")
#: The largest decimal exponent of a seed: ``MAX_SEED`` = 2**256 - 1 is 1.16e77.
_MAX_SEED_DIGITS = 77


def cmd_dominance(args: argparse.Namespace) -> int:
    """``follow-eval dominance``: see :mod:`eval.dominance`."""
    from eval.cli_run import IDEAL_SUFFIX
    from eval.dominance import (
        CRITERIA,
        ENDINGS,
        calibration,
        default_laws,
        dominance,
        finished_view,
    )
    from eval.dominance_report import dominance_markdown, finished_markdown
    from eval.report import safe_name
    from follow_env.sim.atomic import atomic_folder, atomic_write_text, check_new_folder

    runs: list[Path] = args.runs
    if len(runs) > 1 and args.out is None:
        raise UsageError(
            f"{len(runs)} runs are pooled: give --out, a new folder for the pooled tables"
        )
    if args.out is not None:
        check_new_folder(args.out)
    # the criteria's columns are needed, the endings among them (which tell finished episodes)
    metrics = list(dict.fromkeys([*(c.metric for c in CRITERIA), *ENDINGS]))
    table = pooled_table(runs, metrics)
    learners = _names(args.learner, "learner")
    given = _names(args.laws, "laws") if args.laws is not None else None
    if given is not None and (both := [name for name in learners if name in given]):
        raise UsageError(f"--learner and --laws both name {', '.join(both)}: give each once")
    stems: dict[str, str] = {}
    for learner in learners:  # "pn:x" and "pn_x" would write the same files
        if (first := stems.setdefault(safe_name(learner), learner)) != learner:
            raise UsageError(
                f"--learner: {first!r} and {learner!r} would both write "
                f"dominance-{safe_name(learner)}.md: judge them in two commands"
            )
    # Every learner is judged before anything is written, so a bad label writes nothing.
    judged = []
    for learner in learners:
        laws = given or [p for p in default_laws(table, learner) if p not in learners]
        check_covered(table, [learner, *laws])
        judged.append((learner, laws, dominance(table, learner, laws)))
    # meta.json names a policy by its own label: `ppo+ideal` (--ideal-baseline) is `ppo`'s model
    judged_labels = [label for learner, laws, _ in judged for label in (learner, *laws)]
    labels = [label.removesuffix(IDEAL_SUFFIX) for label in judged_labels]
    pooled = _pooled_note(runs, table, _code_notes(runs, labels)) if len(runs) > 1 else ""
    calibrated: dict[tuple[str, ...], Any] = {}
    files: dict[str, str] = {}  # file name -> text, written together at the end
    written: list[str] = []
    for learner, laws, frame in judged:
        if tuple(laws) not in calibrated:  # the laws against each other: once per set
            calibrated[tuple(laws)] = calibration(table, laws) if len(laws) > 1 else None
        report = pooled + dominance_markdown(frame, learner, calibrated[tuple(laws)])
        stem = f"dominance-{safe_name(learner)}"
        written.append(f"{stem}.md|csv")
        view = finished_view(table, frame, learner)
        report += finished_markdown(view, learner)
        files[f"{stem}-finished.csv"] = view.to_csv(index=False)
        written.append(f"{stem}-finished.csv")
        files[f"{stem}.csv"] = frame.to_csv(index=False)
        files[f"{stem}.md"] = report
        print(report)
    if args.out is None:  # one run: its folder takes the tables, all of them or none
        _write_all(runs[0], files)
    else:  # a new folder appears whole, with the pooled episodes the tables were read from
        with atomic_folder(args.out) as tmp:
            for name, text in files.items():
                atomic_write_text(tmp / name, text)
            atomic_write_text(tmp / "episodes.csv", table.to_csv(index=False))
            written.append("episodes.csv (the pooled episodes)")
    print(f"Wrote {args.out if args.out is not None else runs[0]}/: {', '.join(written)}")
    if len(judged) > 1:
        print(_learners_table(judged))
    return 0


def _write_all(folder: Path, files: dict[str, str]) -> None:
    """Write ``files`` (name -> text) into ``folder`` so that a failure leaves none changed:
    every target checked first, every text written to its temporary file, then all renamed.

    :raises UsageError: naming a target that is not a regular file (a folder, a FIFO).
    """
    from follow_env.sim.atomic import atomic_path

    for name in files:
        path = folder / name
        if (path.exists() or path.is_symlink()) and not path.is_file():
            raise UsageError(
                f"{path}: not a regular file (a folder, a device or a FIFO); left as it is, "
                "and no table written"
            )
    with contextlib.ExitStack() as stack:  # renamed only once every text is written
        for name, text in files.items():
            stack.enter_context(atomic_path(folder / name)).write_text(text, encoding="utf-8")


def pooled_table(runs: list[Path], metrics: list[str]) -> Any:
    """The episode tables of ``runs`` as one (one run: its own table, read and checked by
    :func:`read_episode_table`, ``metrics`` needed).

    :raises UsageError: naming the run and what keeps it out: a folder given twice, a missing
        or unreadable table or ``meta.json``, runs made differently or of different scenarios,
        or an episode in two runs (:func:`check_covered` checks the policies judged).
    """
    import pandas as pd

    from eval.stats import variant_column

    resolved = [run.resolve() for run in runs]
    for k, run in enumerate(resolved):
        if run in resolved[:k]:
            raise UsageError(f"{runs[k]}: given twice; give each run once")
    # each run's own table holds an episode once; pooling then looks only across runs
    tables = [read_episode_table(run / "episodes.csv", metrics) for run in runs]
    if len(runs) == 1:
        return tables[0]
    metas = [_meta(run) for run in runs]
    first, meta0, table0 = runs[0], metas[0], tables[0]
    variant = variant_column(table0)
    for run, meta, table in zip(runs[1:], metas[1:], tables[1:], strict=True):
        for key in ALIKE:
            if meta.get(key) != meta0.get(key):
                raise UsageError(
                    f"{run}: its {key} is {meta.get(key)!r} and {first}'s {meta0.get(key)!r}: "
                    "pool runs made alike"
                )
        _same_controllers(first, meta0, run, meta)
        if variant not in table or set(table[variant]) != set(table0[variant]):
            mine = sorted(set(table[variant])) if variant in table else []
            raise UsageError(
                f"{run}: holds the {variant}s {mine} and {first} "
                f"{sorted(set(table0[variant]))}: pool runs of the same {variant}s"
            )
    for run, table in zip(runs, tables, strict=True):
        table.insert(0, "run", str(run))
    pooled = pd.concat(tables, ignore_index=True)
    key = ["policy", variant, "seed"]
    twice = pooled[pooled.duplicated(key, keep=False)]
    if not twice.empty:
        row = twice.iloc[0]
        where = dict.fromkeys(twice[(twice[key] == row[key]).all(axis=1)]["run"])
        raise UsageError(
            f"seed {row['seed']} of {row[variant]} for {row['policy']} is in "
            f"{' and '.join(where)}: pool runs of disjoint seeds"
        )
    return pooled


def _same_controllers(first: Path, meta0: dict[str, Any], run: Path, meta: dict[str, Any]) -> None:
    """Refuse ``run`` if a label it shares with ``first`` is another controller there: another
    model (the SHA-256 of its files, where both runs record one: a learned policy's ``repr``
    names only the path it was loaded from) or other gains (the ``repr``, for a law, and for
    a learned policy when a run written before the digests has none).

    :raises UsageError: naming the label and both runs.
    """
    ours, theirs = meta0.get("policies", {}), meta.get("policies", {})
    our_digests, their_digests = (
        digests if isinstance(digests := m.get("model_sha256"), dict) else {} for m in (meta0, meta)
    )
    for label in ours.keys() & theirs.keys():
        mine, other = our_digests.get(label), their_digests.get(label)
        if mine is not None and other is not None:
            if mine != other:
                raise UsageError(
                    f"{run}: the model under {label} is not the one in {first} (SHA-256 of "
                    f"its files {other[:12]}... there, {mine[:12]}... in {first}): pool runs "
                    "of the same controllers"
                )
        elif ours[label] != theirs[label]:
            raise UsageError(
                f"{run}: {label} is {theirs[label]} there and {ours[label]} in {first}: "
                "pool runs of the same controllers"
            )


def check_covered(table: Any, policies: list[str]) -> None:
    """Refuse a pooled ``table`` in which a run lacks one of ``policies`` on a scenario: each
    policy judged must have met the same persons, so every run pooled must hold it.

    :raises UsageError: naming the run, the policy and the scenario.
    """
    from eval.stats import variant_column

    if "run" not in table:  # one run: nothing pooled
        return
    variant = variant_column(table)
    held = set(zip(table["run"], table["policy"], table[variant], strict=True))
    present = set(table["policy"])  # a label in no run is the judge's to name
    for run in dict.fromkeys(table["run"]):
        for policy in (p for p in policies if p in present):
            for scenario in dict.fromkeys(table[variant]):
                if (run, policy, scenario) not in held:
                    raise UsageError(
                        f"{run}: holds no episode of {policy} on {scenario}: every run pooled "
                        "must hold each learner and law judged"
                    )


def read_episode_table(path: Path, metrics: list[str]) -> Any:
    """``follow-eval run``'s ``episodes.csv`` at ``path``, checked: every row as long as the
    header, the columns ``policy``, the variant's (``scenario`` or ``track``), ``seed`` and
    ``metrics`` each once, a name in every text cell, an integer seed, and a finite number (or
    nothing: a metric undefined for that episode) in each cell of ``metrics``.

    Seeds are read as exact integers (``run`` takes seeds up to 2**256 - 1): int64 when they
    all fit, else Python ints. The other cells are read as pandas reads a CSV (so a table
    written back is the same text): a metric's empty cell (or ``NaN``) is a metric undefined
    for that episode.

    :raises UsageError: naming the file, and the line and column of a bad cell.
    """
    import pandas as pd

    from eval.stats import variant_column

    if not path.is_file():
        raise UsageError(f"{path}: no such file (give a follow-eval run output folder)")
    header, lines = _checked_rows(path, metrics)
    variant = variant_column(pd.DataFrame(columns=header))
    labels = ["policy", variant]
    try:  # the structure is checked: the cells are converted below
        table = pd.read_csv(
            path, dtype=dict.fromkeys([*labels, "seed"], str), index_col=False, encoding="utf-8-sig"
        )
    except (pd.errors.ParserError, UnicodeDecodeError, OSError) as e:
        raise UsageError(f"{path}: not an episode table ({one_line(e)})") from None
    if list(table.columns) != header or len(table) != len(lines):  # what the rows said
        raise UsageError(f"{path}: not an episode table (its rows do not parse as CSV)")
    for column in labels:  # "NA" or "nan" in a label reads as missing
        if (missing := table[column].isna().to_numpy()).any():
            row = int(missing.argmax())
            cell = _cell(path, row, header.index(column))
            raise UsageError(f"{path}: line {lines[row]}, column {column}: {cell!r} names none")
    table["seed"] = _seeds(path, table["seed"], lines)
    for column in metrics:
        values = pd.to_numeric(table[column], errors="coerce")
        # missing: undefined for that episode; text, inf or 1e400 (which reads as inf): not
        infinite = np.isinf(values.to_numpy(dtype=np.float64))
        bad = (values.isna() & table[column].notna()).to_numpy() | infinite
        if bad.any():
            row = int(bad.argmax())
            what = "not finite" if infinite[row] else "not a number"
            raise UsageError(
                f"{path}: line {lines[row]}, column {column}: "
                f"{_cell(path, row, header.index(column))!r} is {what} (a metric's cell "
                "holds a finite number, or nothing where it is undefined)"
            )
        table[column] = values
    return _once(path, table, lines)


def _cell(path: Path, row: int, column: int) -> str:
    """The text of data row ``row`` (0: the first after the header), ``column``, as written:
    for a message (the table read has made ``1e400`` inf, ``NA`` missing)."""
    with path.open(newline="", encoding="utf-8-sig") as f:
        for k, cells in enumerate(csv.reader(f)):
            if k == row + 1:
                return cells[column]
    return ""


def _checked_rows(path: Path, metrics: list[str]) -> tuple[list[str], array[int]]:
    """``path``'s header and the line each row starts on, after checking the rows: each as
    long as the header (a truncated or ragged table is refused, not padded), no blank line,
    the required columns there once each, and ``policy`` and the variant named in every row.

    :raises UsageError: naming the file and the first bad line.
    """
    from eval.stats import VARIANT_COLUMNS

    lines: array[int] = array("q")
    try:
        # utf-8-sig: a table saved by a spreadsheet starts with a byte-order mark
        with path.open(newline="", encoding="utf-8-sig") as f:
            reader = csv.reader(f)
            header = next(reader, None)
            if header is None:
                raise UsageError(f"{path}: not an episode table (the file is empty)")
            twice = [name for name in dict.fromkeys(header) if header.count(name) > 1]
            if twice:
                raise UsageError(f"{path}: line 1: the column {twice[0]} is there twice")
            variant = next((v for v in VARIANT_COLUMNS if v in header), VARIANT_COLUMNS[0])
            needed = ["policy", variant, "seed", *metrics]
            missing = [name for name in needed if name not in header]
            if missing:
                raise UsageError(
                    f"{path}: not an episode table (no {', '.join(missing)} "
                    f"column{'s' if len(missing) > 1 else ''}; follow-eval run writes them)"
                )
            names = [(header.index(name), name) for name in ("policy", variant)]
            start = 2
            for row in reader:
                if len(row) != len(header):
                    got = "an empty line" if not row else f"{len(row)} fields"
                    raise UsageError(
                        f"{path}: line {start}: {got} where the header has {len(header)} "
                        "(a truncated or damaged table)"
                    )
                for k, name in names:
                    if not row[k]:
                        raise UsageError(f"{path}: line {start}, column {name}: empty")
                lines.append(start)
                start = reader.line_num + 1
    except (UnicodeDecodeError, csv.Error) as e:
        raise UsageError(f"{path}: not an episode table ({one_line(e)})") from None
    if not lines:
        raise UsageError(f"{path}: holds no episodes (a header only)")
    return header, lines


def _seeds(path: Path, text: Any, lines: array[int]) -> Any:
    """The ``seed`` column as exact integers: int64 when every seed fits, else Python ints (a
    float would merge seeds 2**53 apart, int64 wraps past 2**63).

    :raises UsageError: naming the line of a cell that is not an integer.
    """
    import pandas as pd

    fast = pd.to_numeric(text, errors="coerce")
    if fast.dtype == np.int64:  # decimal digits within int64: read exactly
        if (negative := (fast < 0).to_numpy()).any():
            k = int(negative.argmax())
            _seed_out_of_range(path, lines[k], text.iloc[k])
        return fast
    seeds: list[int] = []
    for k, cell in enumerate(text.tolist()):
        if not isinstance(cell, str):  # empty, or NA
            raise UsageError(
                f"{path}: line {lines[k]}, column seed: no seed (every episode has one)"
            )
        try:
            value = Decimal(cell)  # exact: "12", "12.0" and "1.2e1" are the seed 12
            if not value.is_finite() or value != value.to_integral_value():
                raise InvalidOperation
        except InvalidOperation:
            raise UsageError(
                f"{path}: line {lines[k]}, column seed: {cell!r} is not an integer seed"
            ) from None
        # The exponent first: int() of "1e999999999" would build a billion-digit number.
        if value.adjusted() > _MAX_SEED_DIGITS or not 0 <= (seed := int(value)) <= MAX_SEED:
            _seed_out_of_range(path, lines[k], cell)
        seeds.append(seed)
    if all(s < 2**63 for s in seeds):
        return pd.Series(seeds, index=text.index, dtype=np.int64)
    return pd.Series(seeds, index=text.index, dtype=object)


def _seed_out_of_range(path: Path, line: int, cell: str) -> NoReturn:
    raise UsageError(
        f"{path}: line {line}, column seed: {cell!r} is out of range: follow-eval run's seeds "
        "are 0..2**256-1"
    )


def _once(path: Path, table: Any, lines: array[int]) -> Any:
    """``table`` (read from ``path``, its rows starting on ``lines``) if it holds each
    (policy, scenario, seed) once: a repeated episode would be paired with every copy on the
    other side.

    :raises UsageError: naming the line of the first repeat.
    """
    from eval.stats import variant_column

    key = ["policy", variant_column(table), "seed"]
    twice = table.duplicated(key)
    if twice.any():
        row = int(twice.to_numpy().argmax())
        r = table.iloc[row]
        raise UsageError(
            f"{path}: line {lines[row]}: seed {r['seed']} of {r[key[1]]} for {r['policy']} "
            "is there twice"
        )
    return table


def _meta(run: Path) -> dict[str, Any]:
    """A run's ``meta.json``, which pooling reads to check that the runs were made alike."""
    path = run / "meta.json"
    if not path.is_file():
        raise UsageError(
            f"{path}: no such file; pooling reads it to check that the runs were made alike "
            "(follow-eval run writes it)"
        )
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise UsageError(f"{path}: not a run's meta.json ({e})") from None
    if not isinstance(meta, dict):
        raise UsageError(f"{path}: not a run's meta.json (not a JSON object)")
    return meta


def _code_notes(runs: list[Path], labels: Sequence[str] = ()) -> list[str]:
    """What the pooled report notes about the runs' code (:func:`eval.provenance.code_notes`)
    and the models under the judged ``labels`` (:func:`eval.provenance.model_notes`), each
    note also warned of on stderr."""
    from eval.provenance import code_notes, model_notes

    metas = [_meta(run) for run in runs]
    notes = code_notes(runs, metas) + model_notes(runs, metas, labels)
    for note in notes:
        print(f"{PROG}: warning: {note}", file=sys.stderr)
    return notes


def _pooled_note(runs: list[Path], table: Any, notes: Sequence[str] = ()) -> str:
    """The line that opens a pooled report: which runs, how many episodes a cell; then each of
    ``notes`` (on the runs' code and models) as a paragraph of its own."""
    from eval.stats import variant_column

    cells = table.groupby(["policy", variant_column(table)]).size()
    per = f"{cells.min():,}" if cells.min() == cells.max() else f"{cells.min():,}-{cells.max():,}"
    head = (
        f"Pooled from {len(runs)} runs ({', '.join(str(r) for r in runs)}): {per} episodes "
        "per policy and scenario.\n\n"
    )
    return head + "".join(f"Note: {note}.\n\n" for note in notes)


def _learners_table(judged: list[tuple[str, list[str], Any]]) -> str:
    """Several learners' verdicts side by side, a row each (``follow-eval dominance``)."""
    from eval.dominance import dominates, tally

    rows = [
        "",
        "| learner | dominates | requirements met | significantly better | significantly worse "
        "| better, Holm | worse, Holm |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for learner, _, frame in judged:
        t = tally(frame)
        rows.append(
            f"| {learner} | {'yes' if dominates(frame) else 'no'} | {t['met']} of {len(frame)} "
            f"| {t['better']} | {t['worse']} | {t['better_holm']} | {t['worse_holm']} |"
        )
    return "\n".join(rows)
