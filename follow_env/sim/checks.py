"""The one range-error helper: every "value out of range" message of the project comes from here.

Configuration fields, guidance-law parameters, the planner's parameters and the learned agent's
feature settings all report a bad value the same way, naming the owner, the field, the value and
what is allowed::

    PIDConfig.kp=-1.0 is out of range: must be [0, 10000] %/(m/s)

numpy integer and floating scalars are accepted wherever Python numbers are (sweeps build values
with ``np.linspace``); :func:`as_number` turns them into Python numbers.

A file that does not parse is reported in one line too: :func:`yaml_problem` gives a YAML
error's place and problem without PyYAML's multi-line quotation of the file, and
:func:`utf8_problem` says where a file that should be text is not UTF-8. Every YAML file the
project reads goes through :func:`load_yaml`, which refuses a key given twice in one mapping.
"""

from __future__ import annotations

import math
from numbers import Integral, Real
from typing import Any

import numpy as np
import yaml

__all__ = [
    "as_number",
    "check_number",
    "is_integer",
    "is_real",
    "load_yaml",
    "one_line",
    "out_of_range",
    "range_text",
    "real_array",
    "utf8_problem",
    "yaml_problem",
]


def out_of_range(where: str, value: object, rule: str) -> ValueError:
    """The error for ``where`` (e.g. ``"PIDConfig.kp"``) holding ``value``, which must be ``rule``.

    :param where: owner and field, as the user names them.
    :param value: the rejected value (shown with ``repr``).
    :param rule: what is allowed, e.g. ``"[0, 1]"`` or ``"one of 'clamp', 'none'"``.
    """
    return ValueError(f"{where}={value!r} is out of range: must be {rule}")


def is_real(value: object) -> bool:
    """A real number (Python or numpy int/float), not a bool."""
    return isinstance(value, Real) and not isinstance(value, bool)


def is_integer(value: object) -> bool:
    """An integer (Python or numpy), not a bool."""
    return isinstance(value, Integral) and not isinstance(value, bool)


def as_number(value: object) -> object:
    """numpy scalars as Python ``int``/``float``; anything else unchanged."""
    if is_integer(value):
        return int(value)  # type: ignore[call-overload]
    if is_real(value):
        return float(value)  # type: ignore[arg-type]
    return value


def range_text(
    lo: float | None,
    hi: float | None,
    *,
    unit: str = "",
    lo_open: bool = False,
    hi_open: bool = False,
    integer: bool = False,
) -> str:
    """``[lo, hi] unit`` in interval notation; ``> lo`` / ``>= lo`` / ``<= hi`` for a range
    bounded on one side only."""
    tail = f" {unit}" if unit else ""
    if lo is None or hi is None:
        kind = "an integer " if integer else ""
        if lo is not None:
            return f"{kind}{'>' if lo_open else '>='} {lo:g}{tail}"
        if hi is not None:
            return f"{kind}{'<' if hi_open else '<='} {hi:g}{tail}"
        return ("an integer" if integer else "a finite number") + tail
    left = "(" if lo_open else "["
    right = ")" if hi_open else "]"
    kind = "an integer in " if integer else ""
    return f"{kind}{left}{lo:g}, {hi:g}{right}{tail}"


def check_number(
    where: str,
    value: object,
    lo: float | None = None,
    hi: float | None = None,
    *,
    unit: str = "",
    lo_open: bool = False,
    hi_open: bool = False,
    integer: bool = False,
    optional: bool = False,
) -> int | float | None:
    """Check a number against its range; returns it as a Python number.

    :param where: owner and field for the message, e.g. ``"PNParams.kv"``.
    :param value: the value to check (a Python or numpy number).
    :param lo: lowest allowed value (``None``: unbounded below).
    :param hi: highest allowed value (``None``: unbounded above).
    :param unit: unit shown in the message.
    :param lo_open: ``lo`` itself is not allowed.
    :param hi_open: ``hi`` itself is not allowed.
    :param integer: the value must be an integer.
    :param optional: ``None`` is allowed too (and returned as is).
    :raises ValueError: from :func:`out_of_range` when the value is not allowed.
    """
    if optional and value is None:
        return None
    rule = range_text(lo, hi, unit=unit, lo_open=lo_open, hi_open=hi_open, integer=integer)
    if optional:
        rule = f"None or {rule}"
    ok = is_integer(value) if integer else is_real(value)
    if ok:
        number = float(value)  # type: ignore[arg-type]
        ok = math.isfinite(number)
        ok = ok and (lo is None or number > lo or (number == lo and not lo_open))
        ok = ok and (hi is None or number < hi or (number == hi and not hi_open))
    if not ok:
        raise out_of_range(where, value, rule)
    return as_number(value)  # type: ignore[return-value]


#: numpy dtype kinds of real numbers, bools included (an action or observation of bools is 0/1).
REAL_KINDS = "biuf"


def real_array(value: object) -> np.ndarray | None:
    """``value`` as a float64 array if it holds real numbers only (bools, integers, floats,
    or an object array of such Python or numpy numbers), else None: strings and bytes, which
    ``astype`` would parse, complex numbers, which it would cut to their real part, ragged
    lists, and an int past float's range."""
    try:
        arr = np.asarray(value)
        if arr.dtype.kind not in REAL_KINDS + "O":
            return None
        if arr.dtype.kind == "O" and not all(isinstance(x, Real | np.bool_) for x in arr.flat):
            return None
        return arr.astype(np.float64, copy=False)
    except (TypeError, ValueError, OverflowError):
        return None


def one_line(error: BaseException) -> str:
    """An exception's message on one line, for a command's one-line error (pandas', SB3's and
    torch's messages run over several)."""
    return " ".join(str(error).split())


def yaml_problem(exc: Exception) -> str:
    """A YAML parse error in one line: where (line and column, counted from 1) and what.

    PyYAML's own message quotes the offending lines with markers under them, over several
    lines; a command line's error is one.
    """
    mark = getattr(exc, "problem_mark", None)
    problem = " ".join(str(getattr(exc, "problem", None) or exc).split())
    if mark is None:
        return problem
    out = f"line {mark.line + 1}, column {mark.column + 1}: {problem}"
    context, start = getattr(exc, "context", None), getattr(exc, "context_mark", None)
    if context and start is not None:  # e.g. "while parsing a flow sequence" and where it began
        out += f" ({context} from line {start.line + 1}, column {start.column + 1})"
    return out


class _StrictLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that refuses a key given twice in one mapping.

    PyYAML keeps the last of two equal keys without a word, so a file read that way may train
    or run with a value its reader does not see. Keys brought in by a merge (``<<: *base``) are
    not the mapping's own and may be overridden, as YAML says.
    """

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        if isinstance(node, yaml.MappingNode):
            seen: set[Any] = set()
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    new = key not in seen
                except TypeError:  # an unhashable key: SafeLoader's own error says so
                    continue
                if not new:
                    raise yaml.constructor.ConstructorError(
                        None, None, f"found the key {key!r} twice", key_node.start_mark
                    )
                seen.add(key)
        return super().construct_mapping(node, deep=deep)


def load_yaml(text: str) -> Any:
    """``text`` parsed as ``yaml.safe_load`` does, but a key given twice in one mapping raises.

    :raises yaml.YAMLError: for text that is not YAML, a mapping that gives a key twice
        (``found the key 'gamma' twice``, with its place for :func:`yaml_problem`), or text
        nested too deeply to parse (PyYAML's recursion would otherwise end in a traceback).
    """
    try:
        return yaml.load(text, Loader=_StrictLoader)  # a SafeLoader subclass: no arbitrary objects
    except RecursionError:
        raise yaml.YAMLError("nested too deeply (PyYAML stops at a few hundred levels)") from None


def utf8_problem(exc: UnicodeDecodeError) -> str:
    """Where a file that should be UTF-8 text is not: ``not a UTF-8 text file (byte 1 is 0xff)``."""
    bad = exc.object[exc.start : exc.start + 1]
    shown = f" is 0x{bad[0]:02x}" if bad else ""
    return f"not a UTF-8 text file (byte {exc.start + 1}{shown})"
