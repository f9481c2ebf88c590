"""Checks of one hyperparameter value, shared by the file reader and the algorithms' rule tables.

Each check takes ``(where, key, value)``, returns the value as it is stored, or raises
:class:`ConfigError` with one line naming the source, the key, the value and its allowed range
(``train/configs/ppo.yaml [PersonFollow-v0]: gamma=1.5 is out of range: must be a number in
[0, 1]``). :mod:`train.config` reads the files, :mod:`train.algos` holds the per-algorithm
tables built from these checks.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping
from typing import Any

__all__ = [
    "Check",
    "ConfigError",
    "decimal",
    "fail",
    "finite",
    "flag",
    "integer",
    "is_number",
    "net_arch",
    "normalize_gamma",
    "number",
    "optional",
    "positive_schedule",
    "schedule",
    "unsupported",
]

#: A check of one value: ``check(where, key, value)`` -> the value as stored.
Check = Callable[[str, str, Any], Any]


class ConfigError(ValueError):
    """A hyperparameter file that cannot be used; the message names the file and the key."""


def fail(where: str, key: str, value: Any, rule: str) -> ConfigError:
    """The error for ``key=value`` outside ``rule`` (what it must be, in words)."""
    return ConfigError(f"{where}: {key}={value!r} is out of range: must be {rule}")


def integer(where: str, key: str, value: Any, low: int, high: int | None = None) -> int:
    """An integer in ``[low, high]`` (no ``high``: >= ``low``); an integral float (YAML's
    ``!!float 4e6``) counts as one."""
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    bad = isinstance(value, bool) or not isinstance(value, int) or value < low
    if bad or (high is not None and value > high):
        rule = f"an integer >= {low}" if high is None else f"an integer in [{low}, {high:,}]"
        raise fail(where, key, value, rule)
    return value


def number(
    where: str, key: str, value: Any, low: float, high: float = math.inf, *, open_low: bool = False
) -> float:
    """A finite number in ``[low, high]`` (``(low, high]`` with ``open_low``)."""
    above = (value > low if open_low else value >= low) if is_number(value) else False
    if not (above and value <= high and finite(value)):
        left = "(" if open_low else "["
        rule = f"a number {'>' if open_low else '>='} {low:g}"
        if low == -math.inf:
            rule = "a finite number"
        elif high < math.inf:
            rule = f"a number in {left}{low:g}, {high:g}]"
        raise fail(where, key, value, rule)
    return value


def finite(value: int | float) -> bool:
    """A number a float can hold, not inf or NaN (an int past 1.8e308 cannot: SB3 and torch
    would raise OverflowError on it)."""
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def is_number(value: Any) -> bool:
    """An int or a float, not a bool."""
    return isinstance(value, int | float) and not isinstance(value, bool)


def flag(where: str, key: str, value: Any) -> bool:
    """``true`` or ``false``."""
    if not isinstance(value, bool):
        raise fail(where, key, value, "true or false")
    return value


def net_arch(where: str, value: Any, keys: tuple[str, ...] = ("pi", "vf")) -> None:
    """A list of layer sizes, or a mapping of them with the actor's and critic's ``keys``."""

    def layers(item: Any) -> bool:
        return isinstance(item, list) and all(
            isinstance(n, int) and not isinstance(n, bool) and n >= 1 for n in item
        )

    if isinstance(value, Mapping):
        ok = set(value) <= set(keys) and all(layers(v) for v in value.values())
    else:
        ok = layers(value)
    if not ok:
        raise fail(
            where,
            "policy_kwargs.net_arch",
            value,
            "a list of layer sizes (integers >= 1), or "
            + "{"
            + ", ".join(f"{key}: [...]" for key in keys)
            + "}",
        )


def normalize_gamma(where: str, hp: Mapping[str, Any]) -> None:
    """A ``normalize.gamma`` other than the algorithm's ``gamma`` is refused: rl-zoo3 replaces
    it by that ``gamma``, so the same file would train differently there and here."""
    norm = hp["normalize"]
    given = isinstance(norm, Mapping) and "gamma" in norm and "gamma" in hp
    if given and norm["gamma"] != hp["gamma"]:
        raise ConfigError(
            f"{where}: normalize.gamma={norm['gamma']!r} differs from gamma={hp['gamma']!r}: "
            "rl-zoo3 replaces it by the algorithm's gamma; leave normalize.gamma out"
        )


def positive_schedule(where: str, key: str, value: Any) -> Any:
    """A number > 0 or ``lin_<x>`` (:func:`schedule`), stored as written."""
    schedule(value, where=f"{where}: {key}")
    return value


def optional(check: Check) -> Check:
    """``check``, or None (SB3's "off")."""

    def check_or_none(where: str, key: str, value: Any) -> Any:
        return None if value is None else check(where, key, value)

    return check_or_none


def unsupported(where: str, key: str, value: Any) -> Any:
    """An argument SB3 wants as a class or object: only its default (none) may be given."""
    if value not in (None, {}):
        raise ConfigError(
            f"{where}: {key}={value!r} is not supported by follow-train (SB3 wants a class, "
            "which a YAML file cannot give); leave it out"
        )
    return value


#: A decimal number as rl-zoo3's files write one (``3e-4``, ``0.0003``, ``.5``): no sign, no
#: spaces, no ``_`` (Python's ``float`` reads ``"1_0"`` as 10, which rl-zoo3 refuses).
_DECIMAL = re.compile(r"(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?")


def decimal(text: str) -> float | None:
    """``text`` as a number if it is a plain decimal literal (:data:`_DECIMAL`), else None: the
    ``<x>`` of ``lin_<x>`` and of SAC's ``auto_<x>``."""
    return float(text) if _DECIMAL.fullmatch(text) else None


def schedule(value: Any, *, where: str = "schedule") -> float | Callable[[float], float]:
    """A number > 0, or rl-zoo3's ``"lin_<x>"`` (x > 0): ``x`` times SB3's progress_remaining
    (1 at the start of training, 0 at the end).

    :raises ConfigError: for anything else, e.g. 0, a negative number, NaN or ``"cos_3e-4"``.
    """
    start: float | None = None
    if is_number(value):
        start = float(value) if finite(value) else None
    elif isinstance(value, str) and value.startswith("lin_"):
        start = decimal(value[4:])
    if start is None or not (math.isfinite(start) and start > 0):
        raise ConfigError(
            f"{where}={value!r} is out of range: must be a number > 0, or 'lin_<number>' with "
            "the number > 0 (linear decay to 0)"
        )
    return start if is_number(value) else _Linear(start)


class _Linear:
    """``start * progress_remaining``: a picklable linear schedule (SB3 saves schedules)."""

    def __init__(self, start: float) -> None:
        self.start = start

    def __call__(self, progress_remaining: float) -> float:
        return self.start * progress_remaining

    def __repr__(self) -> str:
        return f"lin_{self.start:g}"
