"""Compiled code, cached once per version of the package's sources.

numba checks a cached function against its own source file only, while our kernels inline
functions from many files: an edit to, say, the PID model would leave a stale kernel in numba's
cache. So every function compiled from a file of this package (or from a kernel module that
:mod:`follow_env.sim.compose` generates) is cached by :class:`SourceKeyedLocator`: in a folder
named by a hash of *all* the package's sources, with that hash as its freshness stamp. Any edit
anywhere in the package therefore recompiles everything once, and nothing stale can ever run,
whether a module is imported eagerly or lazily.

Every compiled function of the package is declared with :func:`njit` from here, which installs
the locator before numba sets up the function's cache.
"""

from __future__ import annotations

import hashlib
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numba
from numba.core import caching

__all__ = ["CACHE_ROOT", "PACKAGE_ROOT", "SOURCE_DIGEST", "SourceKeyedLocator", "njit"]

PACKAGE_ROOT = Path(__file__).resolve().parents[1]
"""The ``follow_env`` package folder."""


def _source_digest(root: Path) -> str:
    """sha1 of every ``.py`` file under ``root`` (relative path and contents, sorted)."""
    digest = hashlib.sha1()
    for path in sorted(root.rglob("*.py")):
        if "__pycache__" in path.parts:
            continue
        digest.update(path.relative_to(root).as_posix().encode() + b"\0")
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


SOURCE_DIGEST = _source_digest(PACKAGE_ROOT)
"""Hash of the package's sources: the freshness stamp of every cached function."""


def _writable(path: Path) -> bool:
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / f".probe-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError:
        return False
    return True


def _cache_root() -> Path:
    """Beside the sources when that is writable (a checkout, an editable install), else in the
    user's cache folder (a read-only site-packages)."""
    in_tree = PACKAGE_ROOT / "__pycache__" / f"numba-{SOURCE_DIGEST}"
    if _writable(in_tree):
        return in_tree
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "personfollow" / f"numba-{SOURCE_DIGEST}"


CACHE_ROOT = _cache_root()
"""Where compiled functions and generated kernel modules of this source version live."""


def _inside(path: Path, root: Path) -> bool:
    try:
        path.relative_to(root)
    except ValueError:
        return False
    return True


class SourceKeyedLocator(caching._SourceFileBackedLocatorMixin, caching._CacheLocator):
    """numba cache locator for the package's files: one folder per source version, stamped
    with :data:`SOURCE_DIGEST` (see the module docstring)."""

    def __init__(self, py_func: Callable[..., Any], py_file: str) -> None:
        self._py_file = py_file
        self._lineno = py_func.__code__.co_firstlineno
        self._cache_path = str(CACHE_ROOT / self.get_suitable_cache_subpath(py_file))

    def get_cache_path(self) -> str:
        return self._cache_path

    def get_source_stamp(self) -> str:
        return SOURCE_DIGEST

    @classmethod
    def from_function(cls, py_func: Callable[..., Any], py_file: str) -> SourceKeyedLocator | None:
        path = Path(py_file).resolve()
        if not (_inside(path, PACKAGE_ROOT) or _inside(path, CACHE_ROOT)):
            return None  # not ours: numba's own locators handle it
        self = cls(py_func, py_file)
        try:
            self.ensure_cache_path()
        except OSError:
            return None
        return self


def install_locator() -> None:
    """Put :class:`SourceKeyedLocator` first in numba's list (idempotent)."""
    classes = caching.CacheImpl._locator_classes
    if SourceKeyedLocator not in classes:
        classes.insert(0, SourceKeyedLocator)


install_locator()


def njit(*args: Any, **kwargs: Any) -> Any:
    """``numba.njit`` with ``cache=True`` by default, cached by :class:`SourceKeyedLocator`."""
    kwargs.setdefault("cache", True)
    return numba.njit(*args, **kwargs)


def is_cached(dispatcher: Any) -> bool:
    """Whether ``dispatcher`` has a compiled version on disk already (its cache index exists)."""
    try:
        return os.path.exists(dispatcher._cache._cache_file._index_path)
    except AttributeError:  # pragma: no cover - numba internals moved
        return True


def compile_notice(dispatchers: list[Any], what: str = "simulation kernels") -> None:
    """Tell the user, once, that the first run compiles (tens of seconds) rather than hangs."""
    if not all(is_cached(d) for d in dispatchers):
        print(f"personfollow: compiling {what} (first run only)...", file=sys.stderr, flush=True)
