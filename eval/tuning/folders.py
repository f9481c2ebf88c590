"""The checks a search command makes of its files before it writes any, and the opening of its
study: shared by ``follow-tune`` (:mod:`eval.tuning.cli`) and ``python -m train.tune``.

Everything here raises :class:`~eval.cli_base.UsageError` with one line naming the option, the
file and what is wrong, before anything is written; a file or folder the search did not write
is never changed: ``--storage`` must be a new or empty file, an Optuna journal or a database
URL that keeps its data, ``--out`` a new or empty folder or one of the search's own.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from eval.cli_base import UsageError
from eval.provenance import SHORT
from follow_env.sim.atomic import (
    check_writable,
    file_on_path,
    missing_folders,
    remove_empty_folders,
)

__all__ = [
    "SCORING_CODE",
    "check_driver",
    "check_journal_owner",
    "check_journal_path",
    "check_out_folder",
    "check_storage",
    "journal_check",
    "open_search",
    "refuse_empty",
    "refuse_repeats",
    "sqlite_file",
    "text_check",
]

#: The study attribute that keeps the digest of the code that scored its trials
#: (:func:`open_search`).
SCORING_CODE = "scoring_code"


def refuse_empty(args: Any, options: tuple[str, ...]) -> None:
    """Refuse an option of ``options`` (attributes of ``args``) given as empty text: it must
    not fall back to its default (``--storage ''`` would write the default journal, and
    ``--scenarios ''`` once ran a full tune).

    :raises UsageError: naming the option.
    """
    for option in options:
        value = getattr(args, option)
        if value is not None and not value.strip():
            raise UsageError(f"--{option.replace('_', '-')} is empty")


def refuse_repeats(text: str | None, option: str) -> None:
    """A variant named twice in ``--OPTION`` is refused rather than silently dropped: the list
    is the study's identity, and a repeat is most likely a typo for another variant."""
    if text is None:
        return
    names = [n.strip() for n in text.split(",") if n.strip()]
    twice = next((n for i, n in enumerate(names) if n in names[:i]), None)
    if twice is not None:
        raise UsageError(f"--{option} {text}: {twice!r} is given twice; name each variant once")


def check_storage(storage: str | None, out: Path) -> tuple[str, Path | None]:
    """``--storage`` (None: ``OUT/study.journal``; an empty one is :func:`refuse_empty`'s)
    checked: a journal path in an existing folder that is new, empty or a journal, or a
    database URL that keeps its data and whose driver is installed (:func:`check_driver`).

    :returns: the storage to open, and the database file of a ``sqlite:`` URL (else None).
    """
    from eval.tuning.driver import is_url

    if storage is None:
        return str(out / "study.journal"), None
    if not is_url(storage):
        check_journal_path(Path(storage))
    else:
        check_driver(storage)
    return storage, sqlite_file(storage)


#: The package (pip's name) of each database driver module SQLAlchemy imports for a storage
#: URL: Optuna's own message for a missing one names neither the module nor the package.
DRIVER_PACKAGES = {
    "psycopg": "'psycopg[binary]'",  # postgresql:// in SQLAlchemy 2.1, postgresql+psycopg://
    "psycopg2": "psycopg2-binary",  # postgresql:// in SQLAlchemy 2.0, postgresql+psycopg2://
    "MySQLdb": "mysqlclient (or PyMySQL, with a mysql+pymysql:// URL)",  # mysql://
    "pymysql": "PyMySQL",  # mysql+pymysql://
}


def check_driver(storage: str) -> None:
    """A database URL's driver must be installed: say which package provides it.

    :raises UsageError: naming the URL, the driver module and the package to install.
    """
    try:
        from sqlalchemy.engine import make_url

        url = make_url(storage)
        dialect = url.get_dialect()
    except Exception:  # a malformed URL or an unknown database: open_study names it
        return
    try:
        dialect.import_dbapi()  # what create_engine imports (SQLAlchemy 2.0 and later)
    except ImportError as e:
        module = e.name or "its driver"
        package = DRIVER_PACKAGES.get(module.partition(".")[0], module)
        raise UsageError(
            f"--storage {storage}: the {url.drivername} driver ({module}) is not installed: "
            f"pip install {package}"
        ) from None
    except Exception:  # anything else is open_study's to report, as it reports the rest
        return


def sqlite_file(storage: str) -> Path | None:
    """The database file of a ``sqlite:`` storage URL (None for other storages).

    :raises UsageError: for an in-memory database (``sqlite://``, ``sqlite:///``,
        ``sqlite:///:memory:``, ``mode=memory``): it keeps nothing, so a study there could
        never be resumed and its trials would be lost with the process.
    """
    from eval.tuning.driver import is_url

    if not is_url(storage) or not storage.lower().startswith("sqlite"):
        return None
    try:
        from sqlalchemy.engine import make_url

        url = make_url(storage)
    except Exception:  # a malformed URL: open_study names it in one line
        return None
    database = url.database or ""
    if (
        database in ("", ":memory:")
        or "mode=memory" in database
        or url.query.get("mode") == ("memory")
    ):
        raise UsageError(
            f"--storage {storage}: an in-memory SQLite database keeps nothing; give a file "
            "(sqlite:///tuning.db), a journal file or another database URL"
        )
    return Path(database.removeprefix("file:").partition("?")[0])


def check_journal_path(path: Path) -> None:
    """A journal path: in an existing folder, and new, empty or an Optuna journal (Optuna
    appends to whatever file it is given before it reads it)."""
    from eval.tuning.driver import journal_problem

    if path.is_dir():
        raise UsageError(f"--storage {path}: a folder; give a journal file's path or an RDB URL")
    blocker = file_on_path(path.parent)
    if blocker is not None or not path.parent.is_dir():
        raise UsageError(f"--storage {path}: its folder {path.parent} does not exist")
    problem = journal_problem(path)
    if problem is not None:
        raise UsageError(
            f"--storage {path} {problem}; give a new or empty file, or a follow-tune journal"
        )


def check_journal_owner(out: Path, study: str) -> None:
    """``--out``'s journal, if it has one, must hold ``study``: a folder whose journal holds
    only other studies is another search's, whose results would be overwritten."""
    from eval.tuning.driver import journal_study_names

    journal = out / "study.journal"
    names = journal_study_names(journal) if journal.is_file() else []
    if names and study not in names:
        raise UsageError(
            f"--out {out}: its study.journal holds the study {', '.join(names)}, not {study}; "
            "give another --out, or that --study to resume it"
        )


def journal_check(path: Path) -> str | None:
    """What is wrong with ``path`` as a study journal, or None (:func:`check_out_folder`'s
    test of ``study.journal``; the driver, and Optuna with it, imported only when asked)."""
    from eval.tuning.driver import journal_problem

    return journal_problem(path)


def text_check(prog: str, test: Callable[[str], bool]) -> Callable[[Path], str | None]:
    """:func:`check_out_folder`'s test of a file by its text: None if ``test`` takes it for
    ``prog``'s, else what is wrong."""

    def problem(path: Path) -> str | None:
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as e:
            return f"cannot be read: {getattr(e, 'strerror', None) or e}"
        return None if test(text) else f"is not {prog}'s"

    return problem


def check_out_folder(
    out: Path,
    *,
    prog: str,
    own: Mapping[str, Callable[[Path], str | None] | None],
    temporary: re.Pattern[str],
    folders: tuple[str, ...] = (),
) -> None:
    """A search's ``--out`` (follow-tune's, or ``python -m train.tune``'s): a folder that can
    be made, an empty one, or one of the search's own (to resume it); never a folder of other
    files, which the results would be written among.

    :param prog: the command, in messages.
    :param own: the files the search writes, each with its test: what is wrong with the file
        as the search's (None: nothing), e.g. :func:`journal_check`, :func:`text_check`; or
        None for any file of that name.
    :param temporary: the names of interrupted atomic writes the search may leave.
    :param folders: the folders the search writes into ``out``.
    :raises UsageError: naming the folder and what it holds.
    """
    blocker = file_on_path(out)
    if blocker is not None:
        raise UsageError(f"--out {out}: {blocker} is a file, not a folder")
    try:  # a real file made and removed: root passes os.access, /proc takes no file
        check_writable(out / "result.json")
    except OSError as e:
        raise UsageError(f"--out {out}: {e}") from None
    if not out.exists():  # to be made: nothing of anyone's in it
        return
    tail = f"give a new or empty folder, or a {prog} study's folder to resume it"
    foreign = sorted(
        e.name
        for e in out.iterdir()
        if not (e.name in own and not e.is_dir())
        and not (e.name in folders and e.is_dir())
        and not temporary.fullmatch(e.name)
    )
    if foreign:
        more = f" and {len(foreign) - 1} more" if len(foreign) > 1 else ""
        raise UsageError(
            f"--out {out}: the folder holds {foreign[0]}{more}, which {prog} did not write; {tail}"
        )
    for name, check in own.items():
        path = out / name
        problem = check(path) if check is not None and path.exists() else None
        if problem is not None:
            raise UsageError(f"--out {out}: its {name} {problem}; {tail}")


def open_search(
    out: Path,
    storage: str,
    study: str,
    config: Any,
    identity: Mapping[str, Any],
    code: str | None = None,
    sources: str | None = None,
) -> Any:
    """The study ``study`` in ``storage``, created with ``identity`` as its ``"search"``
    attribute, or loaded to resume if it holds the same one. The folder ``out`` (and its
    missing parents) is made first, and removed again, with a journal made here, if the
    study cannot be opened or is refused.

    :param config: the search's :class:`~eval.tuning.driver.SearchConfig`.
    :param identity: what the study's trials depend on (JSON): a study run with other
        settings is refused, since its trials would not be comparable with this run's.
    :param code: the digest of the code that scores a trial
        (:func:`eval.provenance.running_code_sha256` of the packages involved: their code,
        comments and docstrings aside), kept as the study's ``"scoring_code"`` attribute: a
        study scored by other code with trials still to run
        (fewer finished than ``config.trials``) is refused as one with other settings is (an
        edited reward or law would rank new trials against old scores); a complete one is
        not, since no trial is scored again (the held-out check scores its candidates anew
        with this code). A study that records none (made before the record, or without
        ``code``) takes this one.
    :param sources: the digest of the sources of the same packages
        (:func:`eval.provenance.running_sources_sha256`): a study made by an earlier version
        kept that as ``"code"``; it is resumed, and given ``code``, only if they are the same
        sources, and refused as above if not.
    :raises UsageError: naming the folder or the study and what is wrong.
    """
    from eval.tuning.driver import FINISHED, open_study

    made = missing_folders(out)  # ``out`` and any missing parents, deepest first
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        remove_empty_folders(made)
        raise UsageError(
            f"--out {out}: cannot make the folder ({e.strerror or e}); give a folder in a "
            "writable place"
        ) from None
    try:
        opened = open_study(storage, study, config)
        had = opened.user_attrs.get("search")
        if had is None:
            opened.set_user_attr("search", dict(identity))
        elif had != json.loads(json.dumps(identity)):
            raise UsageError(
                f"--study {study}: the study in {storage} was run with other settings "
                f"({had}); give another --study or --storage"
            )
        recorded, current = opened.user_attrs.get(SCORING_CODE), code
        legacy = opened.user_attrs.get("code")  # an earlier version's: the sources' digest
        if recorded is None and legacy is not None and sources is not None:
            recorded, current = legacy, sources  # compared as that version compared them
        if code is None:
            return opened
        if recorded is not None and recorded != current:
            if len(opened.get_trials(deepcopy=False, states=FINISHED)) < config.trials:
                raise UsageError(
                    f"--study {study}: the study in {storage} was scored by other code "
                    f"(sources {str(recorded)[:SHORT]}, this code's {str(current)[:SHORT]}): new "
                    "trials' scores would not compare with its own; give another --study or "
                    "--storage"
                )
            # complete: nothing is scored again, and the record stays the scoring code's
        elif recorded is None or SCORING_CODE not in opened.user_attrs:
            # none recorded yet, or an earlier version's record of the same sources
            opened.set_user_attr(SCORING_CODE, code)
        return opened
    except BaseException:
        remove_empty_folders(made)
        raise
