"""PersonFollow's reward, term by term (weights in ``RewardConfig``; see the env's manual).

Dense, from ground truth, per step::

    r = alive_bonus
        - distance_weight * min(|d_true - target_distance|, 1 m)
        - offset_weight   * min(|offset_true| / (width / 2), 1)
        - accel_weight    * |robot acceleration (encoder-based)|
        - lost_penalty    * [target not in frame]
        - collision_penalty * [collision]          (once, at the end)

Each term is kept in the lane's state (``reward_terms``, in :data:`TERMS` order) so that a user
can see what the reward is made of.
"""

from __future__ import annotations

import numpy as np

from follow_env.sim.jit import njit
from follow_env.sim.schema import Block, f8

__all__ = ["PARAMS", "TERMS", "collision_term", "following_reward"]

TERMS = ("alive", "distance", "offset", "accel", "lost", "collision")
"""The reward's named terms, in the order of the state's ``reward_terms``."""


@njit(inline="always")
def following_reward(rp: np.void, ts: np.void, accel: float, half_width_px: float) -> float:
    """The per-step reward before any collision penalty (terms into ``ts.reward_terms``).

    The distance term is capped at 1 m: a person far away costs no more than a lost one, so
    that losing them on purpose (ending the episode) never beats following badly.
    """
    terms = ts.reward_terms
    terms[0] = rp.alive_bonus
    terms[1] = rp.distance_weight * min(abs(ts.true_d - rp.target_distance), 1.0)
    terms[2] = rp.offset_weight * min(abs(ts.true_o) / half_width_px, 1.0)
    terms[3] = rp.accel_weight * abs(accel)
    terms[4] = rp.lost_penalty * (1.0 - ts.in_frame)
    terms[5] = 0.0
    return terms[0] - terms[1] - terms[2] - terms[3] - terms[4]


@njit(inline="always")
def collision_term(rp: np.void, ts: np.void) -> float:
    """The collision penalty, recorded as the last term."""
    ts.reward_terms[5] = rp.collision_penalty
    return rp.collision_penalty


PARAMS = Block(
    "reward_params",
    "the reward's weights (RewardConfig)",
    [
        f8("target_distance", "m", "desired following distance", source="reward.target_distance_m"),
        f8("alive_bonus", "/step", "reward for following at all", source="reward.alive_bonus"),
        f8("distance_weight", "/m", "distance error weight", source="reward.distance_weight"),
        f8("offset_weight", "/half-width", "offset weight", source="reward.offset_weight"),
        f8("accel_weight", "/(m/s^2)", "acceleration weight", source="reward.accel_weight"),
        f8("lost_penalty", "/step", "target not in frame", source="reward.lost_penalty"),
        f8("collision_penalty", "", "once, on a collision", source="reward.collision_penalty"),
    ],
)
"""The reward's parameter block."""
