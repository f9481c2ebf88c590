"""What loading an agent checks of its files beyond their form: that its ``config.yaml`` names
a task's env, that its spaces are boxes an env could have had, and that its normalisation
statistics are its own and usable. Each check says what is wrong; the loader
(:mod:`policies.learned.ppo`) names the file in an :class:`~policies.learned.ppo.AgentLoadError`.

A folder failing one of them would otherwise load and act wrongly without a word: statistics of
another run normalise what the agent saw raw (it drove backwards in a test), NaN or negative
variances make every action NaN.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from follow_env.tasks.line_trace.spec import SPEC as LINE_SPEC
from follow_env.tasks.person_follow.spec import SPEC as FOLLOW_SPEC
from policies.learned.boxes import Box, as_numbers

__all__ = ["ENV_IDS", "box_problem", "normalized_observations", "statistics_problem"]

#: The envs an agent may have been trained on: each task's (its spec's id).
ENV_IDS = (FOLLOW_SPEC.env_id, LINE_SPEC.env_id)


def box_problem(box: Box, low: Any, high: Any) -> str | None:
    """What makes ``box`` (built from the configuration's ``low`` and ``high`` as written) a box
    no env has, or None: bounds that are not numbers (text numpy would parse), a NaN bound, or
    an entry whose low is above its high."""
    if as_numbers(low) is None or as_numbers(high) is None:
        return f"is not a box (its bounds must be numbers, got low={low!r}, high={high!r})"
    if np.isnan(box.low).any() or np.isnan(box.high).any():
        return f"has a NaN bound ({box!r})"
    if (box.low > box.high).any():
        return f"has low > high in entries {np.flatnonzero(box.low > box.high).tolist()} ({box!r})"
    return None


def normalized_observations(value: Any) -> bool | None:
    """Whether the configuration's ``normalize`` normalised observations, read as training
    reads it (``train.config``): None for no normalisation (no statistics are read), else
    ``VecNormalize``'s ``norm_obs`` (true unless a mapping says otherwise).

    :raises ValueError: for a value training would not take.
    """
    if value is None or value is False:
        return None
    if value is True:
        return True
    if isinstance(value, dict):
        return bool(value.get("norm_obs", True))
    raise ValueError(
        f"normalize={value!r} must be true, false or a mapping of VecNormalize's arguments"
    )


def statistics_problem(stats: Any) -> str | None:
    """What makes normalisation statistics (``norm_obs``, ``obs_rms``, ``epsilon``,
    ``clip_obs``, as a saved ``VecNormalize`` holds them) unusable, or None. NaN or negative
    variances, or a non-positive epsilon, make every action NaN; a clip of 0 or less erases the
    observation."""
    if not (math.isfinite(stats.epsilon) and stats.epsilon > 0):
        return f"epsilon={stats.epsilon!r} must be a finite number > 0"
    if not stats.clip_obs > 0:  # inf is VecNormalize's "no clipping"
        return f"clip_obs={stats.clip_obs!r} must be > 0"
    if not stats.norm_obs:
        return None  # the observation statistics are not used (nor saved, by SB3)
    rms = stats.obs_rms
    mean, var = (as_numbers(getattr(rms, k, None)) for k in ("mean", "var"))
    if mean is None or var is None or mean.ndim != 1 or mean.shape != var.shape:
        return "obs_rms must hold a mean and a variance of the same flat shape"
    if not (np.isfinite(mean).all() and np.isfinite(var).all()):
        return "obs_rms has a mean or variance that is not finite (NaN or inf)"
    if (var < 0).any():
        return f"obs_rms has negative variances (entries {np.flatnonzero(var < 0).tolist()})"
    return None
