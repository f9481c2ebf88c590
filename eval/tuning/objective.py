"""The objective of a law's search: the environment's own reward, on identical rollouts.

A candidate's score is the env's reward summed over each episode (the task's declared
objective, the one a learned controller is trained on: ``PersonFollowEnv``'s distance, offset,
acceleration, frame-loss and collision terms; ``LineTraceEnv``'s progress, cross-track,
smoothness and line-loss terms), averaged over the tuning variants (scenarios or tracks) x
seeds. Episodes end early on a loss or a collision, so the summed reward punishes those too.

The episodes run through :func:`eval.rollout.rollout` on the search's execution backend: every
trial of a batch is one policy of one grid, each (policy, variant, seed chunk) a work unit, and
only a few numbers per episode (:func:`episode_score`) come back from the workers.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from eval.metrics import METRICS
from eval.rollout import Episode, rollout
from execution import Backend
from policies.registry import TunableLaw

__all__ = [
    "DEFAULT_VARIANTS",
    "EVAL_SEEDS",
    "HOLDOUT_SEED0",
    "NORMAL_ENDINGS",
    "TUNE_SEED0",
    "LawObjective",
    "episode_score",
]

#: First tuning seed: far from the evaluation seeds 0..19 (``make eval``, the README tables).
TUNE_SEED0 = 1000
#: First held-out seed, for re-evaluating the best trials: disjoint from both.
HOLDOUT_SEED0 = 2000
#: The evaluation's seeds, which neither the search nor the held-out check may touch.
EVAL_SEEDS = range(20)
#: Variants tuned on unless told, per task: PersonFollow's two thesis conditions and the random
#: walk; for LineTrace one track of each kind of tile (the evaluation's mixed ``course`` and
#: ``random`` left out).
DEFAULT_VARIANTS: Mapping[str, tuple[str, ...]] = {
    "person_follow": ("straight", "curve", "random"),
    "line_trace": ("straight", "corners", "curves", "zigzag", "gaps"),
}
#: Endings that are no failure (the walk or the track was finished, or the step limit reached).
NORMAL_ENDINGS = ("walk_over", "step_limit", "track_end")

#: What :func:`episode_score` returns per episode, in order.
SCORE_KEYS = ("score", "turn_accel_rms_rad_s2", "failed")


def episode_score(episode: Episode) -> tuple[float, float, float]:
    """(summed reward, turn accel RMS [rad/s²], 1 if it failed else 0) of one episode; runs
    in the worker. Failed: lost the person or the line, collided, left the field, or ran out of
    time on a track."""
    reward = episode.total_reward
    turn = float(METRICS["turn_accel_rms_rad_s2"].fn(episode.log))
    return reward, turn, float(episode.termination not in NORMAL_ENDINGS)


@dataclass(frozen=True)
class LawObjective:
    """Scores batches of a law's candidates (an :data:`eval.tuning.driver.Evaluate`).

    :param law: the registered law with its space (``policies.tunable_law``).
    :param variants: the task's scenarios or tracks to score on.
    :param backend: where the episodes run.
    :param config: the env configuration (None: the task's default preset).
    """

    law: TunableLaw[Any]
    variants: tuple[str, ...]
    backend: Backend
    config: Any = None

    def __post_init__(self) -> None:
        if not self.variants:
            raise ValueError("variants is empty: give at least one scenario or track")

    def __call__(
        self, params: Sequence[Mapping[str, float]], seeds: Sequence[int]
    ) -> list[dict[str, np.ndarray]]:
        """Per candidate, the :data:`SCORE_KEYS` of its episodes, each shaped (variants, seeds)."""
        policies = [self.law.policy(p, f"{self.law.law}#{i}") for i, p in enumerate(params)]
        return self.score(policies, seeds)

    def score(self, policies: Sequence[Any], seeds: Sequence[int]) -> list[dict[str, np.ndarray]]:
        """As calling, for ready-made policies (the held-out check scores the preset too)."""
        results = rollout(
            list(policies),
            list(self.variants),
            [int(s) for s in seeds],
            config=self.config,
            reduce=episode_score,
            task=self.law.task,
            backend=self.backend,
        )
        shape = (len(policies), len(self.variants), len(seeds), len(SCORE_KEYS))
        table = np.asarray(results, dtype=np.float64).reshape(shape)
        return [{k: table[i, :, :, j] for j, k in enumerate(SCORE_KEYS)} for i in range(shape[0])]
