"""Robot platforms: one module each, registered by name.

A platform module builds a :class:`~follow_env.platforms.base.Platform` and passes it to
:func:`register_platform` at import. :func:`get_platform` finds every module of this package on
first use, so a new platform is one new file here (plus its test), and no list elsewhere names
it.
"""

from __future__ import annotations

import importlib
import pkgutil
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from follow_env.platforms.base import Platform

__all__ = ["PLATFORMS", "available_platforms", "get_platform", "register_platform"]

PLATFORMS: dict[str, Platform] = {}
"""Registered platforms by name."""

_NOT_PLATFORMS = {"base", "wheels"}  # helpers; a platform may also be a package


def register_platform(platform: Platform) -> Platform:
    """Register ``platform`` under its name (a module imported twice registers once)."""
    known = PLATFORMS.get(platform.name)
    if known is not None and known.module != platform.module:
        raise ValueError(f"platform {platform.name!r} is registered already by {known.module}")
    PLATFORMS[platform.name] = platform
    return platform


def _discover() -> None:
    for info in pkgutil.iter_modules(__path__):
        if info.name not in _NOT_PLATFORMS and not info.name.startswith("_"):
            importlib.import_module(f"{__name__}.{info.name}")


def available_platforms() -> list[str]:
    """Names of every platform (built in and registered)."""
    _discover()
    return sorted(PLATFORMS)


def get_platform(name: str) -> Platform:
    """The platform called ``name``; ``ValueError`` listing the known ones otherwise."""
    if name not in PLATFORMS:
        _discover()
    if name not in PLATFORMS:
        raise ValueError(
            f"platform={name!r} is out of range: must be one of "
            + ", ".join(repr(n) for n in sorted(PLATFORMS))
        )
    return PLATFORMS[name]
