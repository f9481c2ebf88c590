"""Everything that maps an observation ``[distance_m, offset_px]`` to an action ``[v, w]``.

The classical guidance laws of reference §1.5 (PN, MPN, GS-MPN and its variants) and, later,
learned agents, all behind one :class:`Policy` protocol and reachable by name::

    >>> import numpy as np
    >>> from policies import make_policy
    >>> law = make_policy("pn:thesis")
    >>> law.reset()
    >>> law.act(np.array([2.0, 100.0], dtype=np.float32))  # 2 m away, 100 px right of centre
    array([ 5.  , -0.25], dtype=float32)

Actions are SI with w counter-clockwise positive: a person right of centre gives w < 0. A law
names its action's entries (``action_names``); :func:`for_platform` fits it to a platform's
action by name (PN on the mecanum base: ``vy = 0``).
"""

from policies.adapt import PlatformAction, at_period, for_platform
from policies.base import (
    BatchPolicy,
    GuidanceLaw,
    LawParams,
    OffsetRateLaw,
    Policy,
    validate_obs,
    validate_obs_batch,
)
from policies.gsmpn import GSMPN, GSMPN_THESIS, GSMPN_TUNED, GSMPN_VARIANTS, GSMPNParams
from policies.holonomic import Holonomic, HolonomicParams
from policies.mpn import MPN, MPN_THESIS, MPN_TUNED, MPNParams
from policies.pn import PN, PN_THESIS, PN_TUNED, PNParams
from policies.registry import (
    PolicyRegistry,
    available_policies,
    make_policy,
    policy_task,
    register_law,
    register_policy,
    register_resolver,
    tunable_law,
    tunable_laws,
)
from policies.space import ParamRange, SearchSpace

__all__ = [
    "GSMPN",
    "GSMPN_THESIS",
    "GSMPN_TUNED",
    "GSMPN_VARIANTS",
    "MPN",
    "MPN_THESIS",
    "MPN_TUNED",
    "PN",
    "PN_THESIS",
    "PN_TUNED",
    "BatchPolicy",
    "GSMPNParams",
    "GuidanceLaw",
    "Holonomic",
    "HolonomicParams",
    "LawParams",
    "MPNParams",
    "OffsetRateLaw",
    "PNParams",
    "ParamRange",
    "PlatformAction",
    "Policy",
    "PolicyRegistry",
    "SearchSpace",
    "at_period",
    "available_policies",
    "for_platform",
    "make_policy",
    "policy_task",
    "register_law",
    "register_policy",
    "register_resolver",
    "tunable_law",
    "tunable_laws",
    "validate_obs",
    "validate_obs_batch",
]
