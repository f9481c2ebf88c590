"""A holonomic following law for a base that can strafe (the mecanum base, reference §2).

    v  = kv (d - d_ref)
    vy = -ks d o
    w  = -(N kw o / max(d, 1.0))

d = person distance [m], o = pixel offset [px] (> 0: right of centre). The person stands about
``y = -d o / f`` to the side (f the camera's focal length in px), so ``vy = -ks d o`` moves the
robot under them at ``ks f`` (1/s) times that sideways distance, while the turn term (PN's,
reference §1.5) keeps the heading towards the person, as a robot must to follow round a bend.
Strafing centres the person without swinging the camera, so the offset is corrected by two
actuators at once. Signs: a person right of centre (o > 0) needs vy < 0 (to the right) and
w < 0 (clockwise), the project's convention (:mod:`policies.base`).

The ``default`` preset is a choice, not tuned by a search: PN's tuned gains (it is PN plus a
strafe term) and ``ks = 0.0012`` 1/(s px), about 0.75 1/s on the sideways distance with the
default camera (f = 617 px). A first choice, half of PN's turn gain, turned too slowly to follow
the person round bends (README, "The mecanum base").
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from policies.base import GuidanceLaw, LawParams, check_range

__all__ = ["PRESETS", "Holonomic", "HolonomicParams"]

DISTANCE_FLOOR_M = 1.0  # reference §1.5: PN divides by max(d, 1.0)


@dataclass(frozen=True, kw_only=True)
class HolonomicParams(LawParams):
    """Parameters of :class:`Holonomic`, SI.

    :param kv_per_s: speed gain kv [1/s]. :param d_ref_m: following distance [m].
    :param nav_n: navigation constant N [-]. :param kw_rad_per_s_px: turn gain kw [rad/s per px].
    :param ks_per_s_px: strafe gain ks [(m/s) per (m px)].
    """

    kv_per_s: float = 5.0
    d_ref_m: float = 1.0
    nav_n: float = 0.1
    kw_rad_per_s_px: float = 0.05
    ks_per_s_px: float = 0.0012

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("kv_per_s", "d_ref_m", "nav_n"):
            check_range(self, name, gt=0)
        for name in ("kw_rad_per_s_px", "ks_per_s_px"):
            check_range(self, name, ge=0)


PRESETS = MappingProxyType({"default": HolonomicParams()})


class Holonomic(GuidanceLaw):
    """Follows by driving, strafing and turning (module docstring); memoryless.

    :param params: the gains. :param name: the name in tables and logs.
    """

    action_names = ("v_mps", "vy_mps", "w_radps")
    params: HolonomicParams

    def __init__(
        self, params: HolonomicParams = PRESETS["default"], name: str = "holonomic"
    ) -> None:
        super().__init__(params, name)

    def _command(self, distance_m: np.ndarray, offset_px: np.ndarray) -> tuple[np.ndarray, ...]:
        p = self.params
        v_mps = p.kv_per_s * (distance_m - p.d_ref_m)
        # o > 0 (right of centre): strafe right (vy < 0) and turn clockwise (w < 0).
        vy_mps = -p.ks_per_s_px * distance_m * offset_px
        floored_m = np.maximum(distance_m, DISTANCE_FLOOR_M)
        w_radps = -p.nav_n * p.kw_rad_per_s_px * offset_px / floored_m
        return v_mps, vy_mps, w_radps
