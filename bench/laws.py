"""The guidance laws' rows in ``make bench``: acting for many lanes at once against acting lane
by lane, in this process.

``act_batch`` runs a law's arithmetic on arrays of lanes (:class:`policies.base.GuidanceLaw`);
the baseline is the same law's ``act`` called once per lane, the way a law without batching is
run (one copy per lane, :class:`policies.lanes.Lanes`). Both see the same observations: readings
from 0.3 to 5 m with one in five a detector miss (d = 0), as evaluation and ``LawHint`` give
them.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from policies import Policy, make_policy

__all__ = ["bench_laws"]

LANES = 384
"""The lanes of one step: ``ppo_ahead_law.yaml``'s training lanes (32 per scenario)."""
LAWS = ("pn:thesis", "mpn:thesis", "gsmpn:tuned")


def _observations(steps: int) -> np.ndarray:
    rng = np.random.default_rng(0)
    distance = rng.uniform(0.3, 5.0, (steps, LANES))
    distance[rng.random((steps, LANES)) < 0.2] = 0.0
    offset = rng.normal(0.0, 120.0, (steps, LANES))
    return np.stack([distance, offset], axis=-1).astype(np.float32)


def _rate(act: Callable[[np.ndarray], object], obs: np.ndarray) -> float:
    """Lane-steps per second of ``act`` (called once per step) over ``obs``."""
    start = time.perf_counter()
    for row in obs:
        act(row)
    return obs.shape[0] * obs.shape[1] / (time.perf_counter() - start)


def _lane_by_lane(policy: Policy) -> Callable[[np.ndarray], object]:
    """One step of ``policy.act`` called once per lane."""
    return lambda step: [policy.act(lane) for lane in step]


def bench_laws(quick: bool) -> list[tuple[str, float, str]]:
    """Rows ``(what, lane-steps/s, ratio to acting lane by lane)`` for each law."""
    steps = 50 if quick else 400
    obs = _observations(steps)
    rows = []
    for name in LAWS:
        baseline = _rate(_lane_by_lane(make_policy(name)), obs[: max(5, steps // 10)])
        batch = make_policy(name)
        batch.reset_batch(LANES)
        rate = _rate(batch.act_batch, obs)
        rows.append((f"{name}, act_batch, {LANES} lanes", rate, f"{rate / baseline:.0f}x"))
        rows.append((f"  {name}, act lane by lane", baseline, "1x (baseline)"))
    return rows
