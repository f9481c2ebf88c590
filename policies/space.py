"""Search spaces: the ranges a tuner may try for a law's parameters, declared beside its presets.

A law that can be tuned declares, in its own module next to ``PRESETS``, a ``SEARCH_SPACE``: a
mapping from a field of its parameter dataclass to a :class:`ParamRange` (low, high, and whether
to search it on a log scale), in the field's own SI unit. The law's registration carries it
(``register_law(..., search_space=SEARCH_SPACE)``), so ``follow-tune <law>`` (:mod:`eval.tuning`)
tunes any registered law that has one, and a new tunable law stays one file plus its
registration line. Fields left out keep the value of the law's default preset.

Nothing here imports a tuner: the space is plain data, read by :mod:`eval.tuning`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from follow_env.sim.checks import is_real

__all__ = ["ParamRange", "SearchSpace", "check_space", "params_in_space"]


@dataclass(frozen=True)
class ParamRange:
    """The range a tuner samples one parameter from, in the parameter's own unit.

    :param low: the smallest value tried (> 0 when ``log``).
    :param high: the largest value tried (> ``low``).
    :param log: sample uniformly in log(value) (gains that matter by their order of magnitude).
    """

    low: float
    high: float
    log: bool = False

    def __post_init__(self) -> None:
        for name in ("low", "high"):
            value = getattr(self, name)
            if not is_real(value) or not math.isfinite(value):
                raise ValueError(f"ParamRange.{name}={value!r} is out of range: a finite number")
        if not self.low < self.high:
            raise ValueError(
                f"ParamRange.low={self.low!r} is out of range: must be below high={self.high!r}"
            )
        if self.log and self.low <= 0:
            raise ValueError(
                f"ParamRange.low={self.low!r} is out of range: must be > 0 for a log range"
            )

    def __contains__(self, value: object) -> bool:
        return is_real(value) and self.low <= float(value) <= self.high  # type: ignore[arg-type]


SearchSpace = Mapping[str, ParamRange]
"""Field name -> the range to search it in."""


def check_space(space: SearchSpace, params: Any) -> None:
    """Check that ``space`` fits the parameter dataclass instance ``params``: every key is a
    numeric field of it, every value a :class:`ParamRange`, and a point of the space builds
    valid parameters (the ranges' ends pass the dataclass's own checks).

    :raises ValueError: naming the field that does not fit.
    """
    if not dataclasses.is_dataclass(params) or isinstance(params, type):
        raise ValueError(f"{params!r} is not a parameter dataclass instance")
    if not space:
        raise ValueError(f"the search space of {type(params).__name__} is empty")
    fields = {f.name for f in dataclasses.fields(params)}
    where = type(params).__name__
    for name, rng in space.items():
        if name not in fields:
            raise ValueError(f"search space field {name!r} is not a field of {where}")
        if not isinstance(rng, ParamRange):
            raise ValueError(f"search space {where}.{name}={rng!r} is not a ParamRange")
        if not is_real(getattr(params, name)):
            raise ValueError(f"search space field {where}.{name} is not a number")
    for end in ("low", "high"):
        dataclasses.replace(params, **{k: getattr(r, end) for k, r in space.items()})


def params_in_space(space: SearchSpace, params: Any) -> bool:
    """Whether every searched field of ``params`` lies within its range."""
    return all(getattr(params, name) in rng for name, rng in space.items())
