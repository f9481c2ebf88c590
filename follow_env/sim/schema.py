"""Named state and parameters: each component declares its fields once, offsets are generated.

A :class:`Block` is a list of :class:`Field` s (name, unit, dtype, shape, meaning, and for a
parameter where its value comes from); it becomes a numpy *structured dtype*, so a lane's state
is one record and compiled code reads ``st.omega[0]`` or ``prm.kp`` by name: numba turns field
names into fixed offsets at compile time, and no column number appears anywhere. Blocks nest:
the state of a (platform, task) pair is a record of the blocks of its parts.

Parameter fields name their source: a dotted path into the configuration (``"pid.kp"``) or a
function of the configuration, so :meth:`Block.pack` fills a parameter record from a config
without a hand-written list of assignments.
"""

from __future__ import annotations

from collections import namedtuple
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["Block", "Field", "f8", "float_column", "i8", "nested", "zeros"]

Source = str | Callable[[Any], Any] | None


@dataclass(frozen=True)
class Field:
    """One named entry of a block.

    :param name: the field's name (what kernels write after the dot).
    :param unit: its unit (``""`` for counts and flags).
    :param doc: what it means.
    :param dtype: ``"f8"`` (float64) or ``"i8"`` (int64), or a :class:`Block` (a nested record).
    :param shape: ``()`` for a scalar, e.g. ``(2,)`` for one value per wheel.
    :param source: parameters only: a dotted config path or a function of the config.
    """

    name: str
    unit: str
    doc: str
    dtype: str | Block = "f8"
    shape: tuple[int, ...] = ()
    source: Source = None


def f8(
    name: str, unit: str, doc: str, *, shape: tuple[int, ...] = (), source: Source = None
) -> Field:
    """A float64 field."""
    return Field(name, unit, doc, "f8", shape, source)


def i8(
    name: str, unit: str, doc: str, *, shape: tuple[int, ...] = (), source: Source = None
) -> Field:
    """An int64 field."""
    return Field(name, unit, doc, "i8", shape, source)


def nested(name: str, block: Block, doc: str = "") -> Field:
    """A field that is a whole block (a record inside the record)."""
    return Field(name, "", doc or block.doc, block)


class Block:
    """A named group of fields: a structured dtype plus the fields' documentation.

    :param name: the block's name.
    :param doc: what the block holds.
    :param fields: its fields, in order.
    """

    def __init__(self, name: str, doc: str, fields: Sequence[Field]) -> None:
        names = [f.name for f in fields]
        if len(set(names)) != len(names):
            dup = sorted({n for n in names if names.count(n) > 1})
            raise ValueError(f"block {name!r} declares {', '.join(dup)} more than once")
        self.name = name
        self.doc = doc
        self.fields = tuple(fields)
        self.dtype = np.dtype(
            [
                (f.name, f.dtype.dtype if isinstance(f.dtype, Block) else f.dtype, f.shape)
                for f in self.fields
            ],
            align=True,
        )

    def __repr__(self) -> str:
        return f"Block({self.name!r}, {len(self.fields)} fields, {self.dtype.itemsize} bytes)"

    def field(self, name: str) -> Field:
        """The field called ``name``."""
        for f in self.fields:
            if f.name == name:
                return f
        raise KeyError(f"block {self.name!r} has no field {name!r}")

    def zeros(self, *shape: int) -> np.ndarray:
        """A zeroed array of records of this block, of the given shape."""
        return np.zeros(shape, dtype=self.dtype)

    def pack(self, cfg: Any) -> np.ndarray:
        """One record (a 0-d array) filled from ``cfg`` by every field's ``source`` (nested
        blocks recursively; fields without a source stay 0)."""
        out = np.zeros((), dtype=self.dtype)
        self.fill(out, cfg)
        return out

    def fill(self, out: np.ndarray, cfg: Any) -> None:
        """Fill the record ``out`` from ``cfg`` (see :meth:`pack`)."""
        for f in self.fields:
            if isinstance(f.dtype, Block):
                f.dtype.fill(out[f.name], cfg)
            elif f.source is not None:
                out[f.name] = _resolve(f.source, cfg)

    def columns(self) -> Any:
        """Column index of every field when a block of scalar float fields is held as a plain
        ``(..., n_fields)`` float array (scenario paths, walls): a named tuple, generated from
        the declaration."""
        if any(f.shape or f.dtype != "f8" for f in self.fields):
            raise ValueError(f"block {self.name!r} is not all scalar floats")
        return namedtuple(f"{self.name.title()}Columns", [f.name for f in self.fields])(
            *range(len(self.fields))
        )

    def describe(self, prefix: str = "") -> list[tuple[str, str, str, str]]:
        """``(name, dtype and shape, unit, meaning)`` of every leaf field (for docs)."""
        rows = []
        for f in self.fields:
            if isinstance(f.dtype, Block):
                rows += f.dtype.describe(prefix + f.name + ".")
            else:
                kind = f.dtype + (str(list(f.shape)) if f.shape else "")
                rows.append((prefix + f.name, kind, f.unit, f.doc))
        return rows


def _resolve(source: Source, cfg: Any) -> Any:
    if callable(source):
        return source(cfg)
    value = cfg
    for part in str(source).split("."):
        value = getattr(value, part)
    if isinstance(value, bool):
        return float(value)
    return value


def float_column(dtype: np.dtype, path: Sequence[str], index: int = 0) -> int:
    """Where a float64 field (``path`` through nested blocks; entry ``index`` of an array field)
    sits in a record of ``dtype`` seen as a row of float64 words (``arr.view(np.float64)``):
    lets code that reads many fields of many lanes gather them in one indexing operation."""
    offset = 0
    current = dtype
    for name in path:
        sub, off = current.fields[name][:2]
        offset += off
        current = sub
    base = current.base if current.shape else current
    if base != np.dtype(np.float64) or offset % 8 or dtype.itemsize % 8:
        raise ValueError(f"{'.'.join(path)} is not a float64 field on a float64 boundary")
    return offset // 8 + index


def zeros(dtype: np.dtype, *shape: int) -> np.ndarray:
    """A zeroed array of ``dtype`` (a convenience for composed dtypes)."""
    return np.zeros(shape, dtype=dtype)
