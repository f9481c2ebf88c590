"""The shipped agent's row in ``make bench``: its network acting on a step of lanes, against the
library's ``predict`` path, in this process.

A PPO agent's network runs one lane at a time (:mod:`policies.learned.networks` says why) and
takes its action as the Gaussian's mean without building SB3's distribution object; the
baseline is the same network through ``policy._predict``, as SB3's ``predict`` runs it. Both see
the same agent observations, drawn uniformly from [-1, 1] in the agent's own view.
"""

from __future__ import annotations

import time

import numpy as np

from policies import make_policy

__all__ = ["bench_agents"]

AGENT = "ppo_law"
LANES = 384
"""The lanes of one step, as in the laws' rows (``bench.laws``)."""


def bench_agents(quick: bool) -> list[tuple[str, float, str]]:
    """Rows ``(what, lane-steps/s, ratio to the predict path)`` for the shipped agent."""
    import torch

    network = make_policy(AGENT)._agent.model
    steps = 2 if quick else 10
    rng = np.random.default_rng(0)
    obs = rng.uniform(-1, 1, (steps, LANES, *network.observation_space.shape)).astype(np.float32)

    def predict(step: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            rows = [network.policy._predict(torch.as_tensor(row[None]), deterministic=True)
                    for row in step]  # fmt: skip
        # float64, as the network is loaded (policies.learned.networks), rounded as it rounds
        return np.clip(torch.cat(rows).numpy(), network._low, network._high).astype(np.float32)

    np.testing.assert_array_equal(network.act(obs[0]), predict(obs[0]))  # the same actions
    rates = {}
    for name, act in (("mean", network.act), ("predict", predict)):
        start = time.perf_counter()
        for step in obs:
            act(step)
        rates[name] = steps * LANES / (time.perf_counter() - start)
    return [
        (
            f"{AGENT} network, {LANES} lanes",
            rates["mean"],
            f"{rates['mean'] / rates['predict']:.2f}x",
        ),
        (f"  {AGENT}, SB3's predict path", rates["predict"], "1x (baseline)"),
    ]
