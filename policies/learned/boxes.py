"""The boxes a learned agent's feature steps see of the spaces around them, numpy only.

:class:`Box` carries float32 bounds and, for an action, the platform's entry names;
:func:`agent_to_si` maps an agent's ``[-1, 1]`` actions onto SI bounds. Split from
:mod:`policies.learned.features`, which re-exports them.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["LEGACY_ACTION_NAMES", "Box", "agent_to_si", "as_numbers"]


#: The action entries of a two-entry box that names none (an agent saved before the names were
#: recorded was trained on the differential drive).
LEGACY_ACTION_NAMES = ("v_mps", "w_radps")


class Box:
    """A box of float32 bounds (what a step sees of the spaces around it; numpy only).

    :param low: lower bounds. :param high: upper bounds.
    :param names: the entries' names (an action box: the platform's action names), or None.
    """

    def __init__(
        self,
        low: Sequence[float] | np.ndarray,
        high: Sequence[float] | np.ndarray,
        names: Sequence[str] | None = None,
    ) -> None:
        self.low = np.asarray(low, dtype=np.float32)
        self.high = np.asarray(high, dtype=np.float32)
        if self.low.shape != self.high.shape or self.low.ndim != 1:
            raise ValueError(
                f"a Box needs matching flat bounds, got {self.low.shape}, {self.high.shape}"
            )
        self.names = None if names is None else tuple(str(n) for n in names)
        if self.names is not None and len(self.names) != self.low.shape[0]:
            raise ValueError(
                f"a Box of {self.low.shape[0]} entries needs as many names, got {list(names)}"
            )

    @property
    def shape(self) -> tuple[int, ...]:
        """The box's shape."""
        return self.low.shape

    def entry_names(self) -> tuple[str, ...]:
        """The entries' names: given ones, or for a two-entry box without names
        :data:`LEGACY_ACTION_NAMES`, or else ``a0, a1, ...``."""
        if self.names is not None:
            return self.names
        if self.shape == (2,):
            return LEGACY_ACTION_NAMES
        return tuple(f"a{k}" for k in range(self.shape[0]))

    def __repr__(self) -> str:
        names = "" if self.names is None else f", names={list(self.names)}"
        return f"Box(low={self.low.tolist()}, high={self.high.tolist()}{names})"


def agent_to_si(action: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """Map an agent action in ``[-1, 1]`` (clipped first) linearly onto ``[low, high]``.

    :param action: shape (..., m), agent units (m: the platform's action entries).
    :param low: the SI box's lower bounds, e.g. ``[-1.44 m/s, -7.2 rad/s]``.
    :param high: the SI box's upper bounds.
    """
    a = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
    return low + (a + 1.0) * 0.5 * (high - low)


def per_entry(where: str, given: Any, act: Box, may: str = "") -> np.ndarray:
    """``given`` as one positive, finite number per entry of the action ``act``, or a
    ValueError naming ``where`` (``owner.field``) and the entries; ``may`` prefixes the allowed
    range (``"None or "`` for an optional one)."""
    numbers = as_numbers(given)
    good = numbers is not None and numbers.shape == act.shape
    if not (good and np.all(np.isfinite(numbers) & (numbers > 0))):
        raise ValueError(
            f"{where}={given!r} is out of range: must be {may}{act.shape[0]} positive numbers, "
            f"one per action entry [{', '.join(act.entry_names())}]"
        )
    return numbers


def as_numbers(values: Any) -> np.ndarray | None:
    """``values`` as a float64 array of numbers, or None if they are not numbers (a string, a
    bool, a mapping, a ragged list), so that a step can name its argument in the error."""
    items = values if isinstance(values, list | tuple | np.ndarray) else [values]
    flat = np.asarray(items, dtype=object).ravel()
    if any(isinstance(v, bool) or not isinstance(v, int | float | np.number) for v in flat):
        return None
    try:
        return np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        return None
