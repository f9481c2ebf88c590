"""T-RRT: a transition-based RRT on a 2-D cost map (reference §3), for people's walking paths.

A plain RRT finds *a* path; people walk down the middle of corridors and keep off walls. T-RRT
(reference §3) grows the tree with a *transition test* on a cost map whose cost rises near
obstacles, so the tree prefers the valleys of the cost (the middle of free space) and only
climbs towards obstacles when it has to. A deterministic post-processing pass then takes out
the random zigzags and resamples the path to waypoints a simulated person can walk.

**Cost map** (:class:`CostMap`, built by :func:`cost_map_from_obstacles`): a grid of cells of
``resolution_m`` with its lower-left corner at ``(x0_m, y0_m)``; cell ``[iy, ix]`` covers
``x0 + ix res <= x < x0 + (ix + 1) res`` and likewise in y. Each cell has an occupancy flag
(the body of a walker, a disc of ``body_radius_m``, would touch an obstacle) and a cost
``exp(-clearance / length_scale_m)`` in (0, 1], where ``clearance`` is the distance (m) from
the edge of the body to the nearest obstacle: 1 at contact, falling off over a few length
scales. A point outside the grid is never free.

**The planner** (:func:`plan`), reference §3 step by step, in compiled code:

1. *sample* a point uniformly over the grid, or the goal with probability ``goal_bias``;
2. find the *nearest node* of the tree (linear scan: a few thousand nodes at most);
3. *extend* from it towards the sample by at most ``step_m``;
4. reject the new node unless the segment from its parent stays in free space (every cell it
   crosses is free, traced exactly: Amanatides & Woo's grid traversal);
5. the *transition test* (:func:`transition_probability`): a child no costlier than its parent
   is accepted; otherwise ``dC = (child_cost - parent_cost) / distance`` and the child is
   accepted with probability ``exp(-dC / (K T))``, with ``K`` the mean cost of start and goal;
6. the *temperature update* (:func:`update_temperature`) after every uphill test;
7. stop when a new node lies within ``goal_tol_m`` of the goal and the segment to the goal is
   free (the goal joins the tree), or when ``max_iters`` iterations have run.

**Reading of reference §3's temperature rule.** The text says, literally: "on acceptance
``T = T / alpha`` and reset the failure count; on rejection, if failures reached a maximum then
``T = T * alpha`` and reset the count, else count the failure". We follow it to the letter, with
``alpha > 1`` (the value of the T-RRT literature, e.g. 2): every accepted *uphill* move cools
the search (T falls, uphill moves get rarer), and a run of rejected uphill moves heats it (T
rises once the count of failures has *reached* ``n_fail_max``: the rejection after
``n_fail_max`` counted failures multiplies T by alpha). With ``alpha < 1`` the same formulas
would run away (acceptances would make acceptance likelier), so ``alpha`` must exceed 1.
The update runs only inside the transition test, i.e. for uphill children: a downhill child is
accepted outright and a colliding one never reaches the test, and neither changes T.

**Randomness** comes from :func:`follow_env.sim.rng.uniform_at` with the caller's key, so the same
key always grows the same tree. Iteration ``i`` reads counters ``counter0 + 4 i + slot``: slot
0 the goal-bias coin, 1 and 2 the sample's x and y, 3 the transition test's draw
(:data:`COUNTERS_PER_ITER`; a caller sharing a stream reserves :func:`counters_needed`).

**Post-processing** (deterministic, never leaves free space): a greedy shortcut (from each
waypoint, jump to the farthest later one whose straight segment is free *and* no costlier at
its worst than the stretch of path it replaces, so shortcuts do not hug walls the tree kept
away from), Chaikin corner cutting (a cut that would hit an obstacle keeps its corner), and
resampling by arc length to waypoints at most ``waypoint_spacing_m`` apart (keeping any corner
whose chord would not be free).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from follow_env.sim.config import Validated, param
from follow_env.sim.jit import njit
from follow_env.sim.rng import uniform_at
from follow_env.world.buckets import bucket_of, nearest_in_buckets
from follow_env.world.costmap import (
    CostMap,
    cell_of,
    checked_point,
    cost_map_from_obstacles,
    segment_is_free,
    trace_segment,
)
from follow_env.world.paths import chaikin, resample, shortcut

__all__ = [
    "COUNTERS_PER_ITER",
    "CostMap",
    "PlanResult",
    "TRRTParams",
    "cost_map_from_obstacles",
    "counters_needed",
    "plan",
    "segment_is_free",
    "transition_probability",
    "update_temperature",
]

# Random counters read per iteration (see the module docstring for the slots).
COUNTERS_PER_ITER = 4
_SLOT_GOAL, _SLOT_X, _SLOT_Y, _SLOT_TEST = 0, 1, 2, 3

# Numerical guard only: T stays within float range however long a run of acceptances or
# failures lasts (reference §3 puts no bound on T; ordinary runs never come near these).
_T_MIN = 1e-200
_T_MAX = 1e200

# Slots of the statistics array the kernel fills.
_ST_DOWNHILL = 0  # children accepted without a test (child cost <= parent cost)
_ST_UP_ACCEPT = 1  # uphill children accepted by the transition test
_ST_UP_REJECT = 2  # uphill children rejected by the transition test
_ST_COLLISION = 3  # new nodes rejected because they or their segment leave free space
_ST_COOL = 4  # T = T / alpha events
_ST_HEAT = 5  # T = T * alpha events
_N_ST = 6

# Columns of the uphill log: one row per transition test of an uphill child.
_LOG_T, _LOG_DC, _LOG_ACCEPTED = 0, 1, 2


# --- the transition test and the temperature rule (reference §3) ------------------------------


@njit
def transition_probability(
    child_cost: float, parent_cost: float, distance_m: float, K: float, T: float
) -> float:
    """Probability that reference §3's transition test accepts a child.

    1 when ``child_cost <= parent_cost``; else ``exp(-dC / (K T))`` with
    ``dC = (child_cost - parent_cost) / distance_m`` (cost per m).

    :param child_cost: cost at the new node.
    :param parent_cost: cost at its parent.
    :param distance_m: length of the extension (m, > 0).
    :param K: cost normaliser, the mean cost of start and goal (> 0).
    :param T: temperature (> 0).
    """
    if child_cost <= parent_cost:
        return 1.0
    dC = (child_cost - parent_cost) / distance_m
    return np.exp(-dC / (K * T))


@njit
def update_temperature(
    T: float, n_fail: int, accepted: bool, alpha: float, n_fail_max: int
) -> tuple[float, int]:
    """reference §3's temperature rule after the transition test of an uphill child.

    Accepted: ``T = T / alpha`` and the failure count resets. Rejected: if the count has
    reached ``n_fail_max``, ``T = T * alpha`` and the count resets; else the failure is counted.
    (With ``alpha > 1``: acceptances cool, runs of failures heat; see the module docstring.)

    :param T: temperature before the update (> 0).
    :param n_fail: uphill rejections counted since the last reset.
    :param accepted: the outcome of the test.
    :param alpha: temperature factor (> 1).
    :param n_fail_max: failures counted before T is multiplied by alpha.
    :return: ``(T, n_fail)`` after the update.
    """
    if accepted:
        return max(T / alpha, _T_MIN), 0
    if n_fail >= n_fail_max:
        return min(T * alpha, _T_MAX), 0
    return T, n_fail + 1


# --- the planner loop --------------------------------------------------------------------------


@njit
def _grow_tree(
    cost: np.ndarray,
    occ: np.ndarray,
    x0: float,
    y0: float,
    res: float,
    sx: float,
    sy: float,
    gx: float,
    gy: float,
    key: np.uint64,
    counter0: int,
    step: float,
    max_iters: int,
    goal_bias: float,
    goal_tol: float,
    alpha: float,
    n_fail_max: int,
    T0: float,
    K: float,
) -> tuple:
    """Grow a T-RRT from (sx, sy) towards (gx, gy) (reference §3; see the module docstring).

    :return: ``(nodes (n, 2), parent (n,), goal_index or -1, iterations, T, stats, log)``.
    """
    ny, nx = cost.shape
    width, height = nx * res, ny * res
    cap = max_iters + 2  # the start, one node per iteration at most, the goal
    nodes = np.empty((cap, 2))
    parent = np.empty(cap, dtype=np.int64)
    # Buckets of the nearest-node search: linked lists of node indices per grid cell.
    g = max(step, res)
    gnx, gny = int(width / g) + 1, int(height / g) + 1
    head = np.full(gnx * gny, -1, dtype=np.int64)
    nxt = np.empty(cap, dtype=np.int64)
    node_cost = np.empty(cap)
    stats = np.zeros(_N_ST, dtype=np.int64)
    log = np.empty((max_iters, 3))
    n_log = 0
    nodes[0, 0], nodes[0, 1] = sx, sy
    parent[0] = -1
    b = bucket_of(sx, sy, x0, y0, g, gnx, gny)
    nxt[0], head[b] = head[b], 0
    ix, iy = cell_of(sx, sy, x0, y0, res, ny, nx)
    node_cost[0] = cost[iy, ix]
    n = 1
    T = T0
    n_fail = 0
    goal_i = -1

    # Start already at the goal: no search.
    if (
        np.hypot(gx - sx, gy - sy) <= goal_tol
        and trace_segment(cost, occ, x0, y0, res, sx, sy, gx, gy) < np.inf
    ):
        nodes[1, 0], nodes[1, 1] = gx, gy
        parent[1] = 0
        return nodes[:2], parent[:2], 1, 0, T, stats, log[:0]

    it = 0
    while it < max_iters:
        c = counter0 + COUNTERS_PER_ITER * it
        it += 1
        # 1. Sample: the goal with probability goal_bias, else uniform over the grid.
        if uniform_at(key, c + _SLOT_GOAL) < goal_bias:
            qx, qy = gx, gy
        else:
            qx = x0 + width * uniform_at(key, c + _SLOT_X)
            qy = y0 + height * uniform_at(key, c + _SLOT_Y)
        # 2. Nearest node (the first of equals in index order, found through the buckets).
        best, best_d2 = nearest_in_buckets(nodes, head, nxt, qx, qy, x0, y0, g, gnx, gny)
        d = np.sqrt(best_d2)
        if d < 1e-9:
            continue  # the sample is a node already: nothing to extend
        # 3. Extend by at most one step.
        px, py = nodes[best, 0], nodes[best, 1]
        if d > step:
            qx = px + (qx - px) * (step / d)
            qy = py + (qy - py) * (step / d)
            d = step
        # 4. Collision: the child and the whole segment from its parent must be free.
        if trace_segment(cost, occ, x0, y0, res, px, py, qx, qy) == np.inf:
            stats[_ST_COLLISION] += 1
            continue
        # 5. Transition test (reference §3), 6. temperature update on uphill moves only.
        ix, iy = cell_of(qx, qy, x0, y0, res, ny, nx)
        child_cost = cost[iy, ix]
        if child_cost <= node_cost[best]:
            stats[_ST_DOWNHILL] += 1
        else:
            p = transition_probability(child_cost, node_cost[best], d, K, T)
            accepted = uniform_at(key, c + _SLOT_TEST) < p
            log[n_log, _LOG_T] = T
            log[n_log, _LOG_DC] = (child_cost - node_cost[best]) / d
            log[n_log, _LOG_ACCEPTED] = 1.0 if accepted else 0.0
            n_log += 1
            T, n_fail = update_temperature(T, n_fail, accepted, alpha, n_fail_max)
            if accepted:
                stats[_ST_COOL] += 1
            elif n_fail == 0:  # a rejection resets the count only when it heats
                stats[_ST_HEAT] += 1
            if not accepted:
                stats[_ST_UP_REJECT] += 1
                continue
            stats[_ST_UP_ACCEPT] += 1
        nodes[n, 0], nodes[n, 1] = qx, qy
        parent[n] = best
        node_cost[n] = child_cost
        b = bucket_of(qx, qy, x0, y0, g, gnx, gny)
        nxt[n], head[b] = head[b], n
        n += 1
        # 7. Goal reached: within tolerance and a free last segment.
        if np.hypot(gx - qx, gy - qy) <= goal_tol:
            if qx == gx and qy == gy:
                goal_i = n - 1
                break
            if trace_segment(cost, occ, x0, y0, res, qx, qy, gx, gy) < np.inf:
                nodes[n, 0], nodes[n, 1] = gx, gy
                parent[n] = n - 1
                goal_i = n
                n += 1
                break
    return nodes[:n], parent[:n], goal_i, it, T, stats, log[:n_log]


@njit
def _branch(nodes: np.ndarray, parent: np.ndarray, leaf: int) -> np.ndarray:
    """Points from the root to ``leaf`` along the tree: (k, 2)."""
    k = 0
    i = leaf
    while i >= 0:
        k += 1
        i = parent[i]
    out = np.empty((k, 2))
    i = leaf
    for j in range(k - 1, -1, -1):
        out[j] = nodes[i]
        i = parent[i]
    return out


# --- Python API --------------------------------------------------------------------------------


@dataclass(frozen=True)
class TRRTParams(Validated):
    """Parameters of the T-RRT planner (reference §3) and of its post-processing.

    The spec gives the algorithm only; every value here is a choice, tuned so that a path
    through a 20 m x 14 m maze is found in a few milliseconds.
    """

    step_m: float = param(
        1.0,
        0.0,
        10.0,
        "m",
        "choice: a long step grows the tree fast; post-processing smooths the corners",
        lo_open=True,
    )
    max_iters: int = param(
        20_000, 1, 1_000_000, "iterations", "choice: ample for a maze", integer=True
    )
    goal_bias: float = param(
        0.05, 0.0, 1.0, "", "choice: share of samples drawn at the goal, as usual for RRTs"
    )
    goal_tol_m: float = param(
        0.5, 0.0, 10.0, "m", "choice: a node this close to the goal connects to it", lo_open=True
    )
    alpha: float = param(
        2.0,
        1.0,
        100.0,
        "",
        "reference §3: temperature factor; > 1 so that acceptances cool (module docstring)",
        lo_open=True,
    )
    n_fail_max: int = param(
        2,
        0,
        1_000_000,
        "failures",
        "reference §3: uphill rejections counted before T rises. Choice of value: the rule settles "
        "near 1 / (n_fail_max + 2) of uphill moves accepted; 2 (about 25 %) still finds "
        "1 m doorways quickly, 10 (8 %) takes several times longer there",
        integer=True,
    )
    T0: float = param(
        1.0, 0.0, 1e12, "", "choice: initial temperature (the rule adapts it)", lo_open=True
    )
    k_floor: float = param(
        0.01,
        0.0,
        1e6,
        "",
        "choice: least K (reference §3: mean cost of start and goal), so that start and goal far "
        "from all obstacles (cost ~ 0) do not make every uphill step impossible",
        lo_open=True,
    )
    shortcut: bool = field(default=True)  # greedy shortcut pass (module docstring)
    smooth_cost_max: float = param(
        0.5,
        0.0,
        1e12,
        "",
        "choice: shortcuts and corner cuts may take the path up to this cost (or the tree "
        "path's own worst cost over the stretch, if higher); 0.5 with the cost of "
        "cost_map_from_obstacles keeps ln(2) length scales (0.35 m) clear of the body",
    )
    smooth_passes: int = param(
        2, 0, 8, "passes", "choice: Chaikin corner-cutting passes after the shortcut", integer=True
    )
    waypoint_spacing_m: float = param(
        0.3, 0.01, 10.0, "m", "choice: waypoints a walker follows, as in the scenarios (0.25 m)"
    )

    def __post_init__(self) -> None:
        super().__post_init__()
        if not isinstance(self.shortcut, bool):
            raise ValueError(
                f"TRRTParams.shortcut={self.shortcut!r} is out of range: must be True or False"
            )


@dataclass(frozen=True, eq=False)
class PlanResult:
    """Outcome of :func:`plan`.

    ``path`` is what a walker follows; the rest describes the search. ``uphill_log`` has one
    row per transition test of an uphill child: the temperature T at the test, ``dC`` (cost per
    m) and 1.0 if accepted else 0.0, so the acceptance probability of each test is
    ``exp(-dC / (K T))``.
    """

    path: np.ndarray  # (n, 2) m: start .. goal, post-processed; (0, 2) when not success
    success: bool
    status: str  # "reached" or "iterations_exhausted"
    iterations: int  # iterations run (0: start within goal_tol_m of a visible goal)
    raw_path: np.ndarray  # (k, 2) m: the tree's branch from start to goal; (0, 2) on failure
    tree_xy: np.ndarray  # (nodes, 2) m: every node of the tree, the start first
    tree_parent: np.ndarray  # (nodes,) int: index of each node's parent, -1 for the start
    K: float  # cost normaliser used (mean cost of start and goal, floored at k_floor)
    temperature_final: float  # T when the search stopped
    n_downhill: int  # children accepted without a test (child cost <= parent cost)
    n_uphill_accepted: int  # uphill children accepted by the transition test
    n_uphill_rejected: int  # uphill children rejected by the transition test
    n_collision_rejected: int  # new nodes rejected for leaving free space
    n_cooled: int  # times T was divided by alpha
    n_heated: int  # times T was multiplied by alpha
    uphill_log: np.ndarray  # (tests, 3): T, dC (cost/m), accepted (1.0 / 0.0)

    @property
    def uphill_acceptance_rate(self) -> float:
        """Share of uphill transition tests passed (NaN when none ran)."""
        tests = self.n_uphill_accepted + self.n_uphill_rejected
        return self.n_uphill_accepted / tests if tests else math.nan

    @property
    def length_m(self) -> float:
        """Length of ``path`` (m)."""
        return float(np.sum(np.linalg.norm(np.diff(self.path, axis=0), axis=1)))


def counters_needed(params: TRRTParams) -> int:
    """Random counters :func:`plan` may read from ``counter0`` on: reserve this many when the
    key's stream is shared (e.g. ``LaneRandom.reserve``)."""
    return COUNTERS_PER_ITER * params.max_iters


def _key(key: Any, name: str = "key") -> np.uint64:
    if isinstance(key, bool) or not isinstance(key, int | np.integer) or not 0 <= key < 2**64:
        raise ValueError(f"{name}={key!r} is out of range: must be an integer in [0, 2**64)")
    return np.uint64(key)


def plan(
    cost_map: CostMap,
    start_xy: ArrayLike,
    goal_xy: ArrayLike,
    key: int | np.uint64,
    params: TRRTParams | None = None,
    *,
    counter0: int = 0,
) -> PlanResult:
    """Plan a walking path from ``start_xy`` to ``goal_xy`` with T-RRT (reference §3).

    Deterministic: the same map, points, key, counter0 and params give the same tree and path.
    Not finding a path is an outcome, not an error: ``success`` is False, ``path`` empty and
    ``status`` ``"iterations_exhausted"``.

    :param cost_map: the map (see :func:`cost_map_from_obstacles`).
    :param start_xy: start point (m), in free space.
    :param goal_xy: goal point (m), in free space.
    :param key: random stream key, an integer in [0, 2**64) (e.g. a ``LaneRandom`` key).
    :param params: planner parameters (default :class:`TRRTParams()`).
    :param counter0: first random counter read; the search reads at most
        :func:`counters_needed` counters from there.
    :raises ValueError: a point outside the map or in an obstacle, a bad key or counter0.
    """
    p = TRRTParams() if params is None else params
    if not isinstance(p, TRRTParams):
        raise ValueError(f"params={params!r} is not a TRRTParams")
    if not isinstance(cost_map, CostMap):
        raise ValueError(f"cost_map={cost_map!r} is not a CostMap")
    sx, sy = checked_point(cost_map, start_xy, "start_xy")
    gx, gy = checked_point(cost_map, goal_xy, "goal_xy")
    k = _key(key)
    if (
        isinstance(counter0, bool)
        or not isinstance(counter0, int | np.integer)
        or not 0 <= counter0 < 2**62
    ):
        raise ValueError(f"counter0={counter0!r} is out of range: must be an integer in [0, 2**62)")
    cost, occ = cost_map.cost, cost_map.occupied
    x0, y0, res = cost_map.x0_m, cost_map.y0_m, cost_map.resolution_m
    # reference §3: K = mean cost of start and goal, floored (see TRRTParams.k_floor).
    K = max(0.5 * (cost_map.cost_at((sx, sy)) + cost_map.cost_at((gx, gy))), p.k_floor)
    nodes, parent, goal_i, iters, T, stats, log = _grow_tree(
        cost,
        occ,
        x0,
        y0,
        res,
        sx,
        sy,
        gx,
        gy,
        k,
        int(counter0),
        p.step_m,
        p.max_iters,
        p.goal_bias,
        p.goal_tol_m,
        p.alpha,
        p.n_fail_max,
        p.T0,
        K,
    )
    success = goal_i >= 0
    if success:
        raw = _branch(nodes, parent, goal_i)
        ceiling = p.smooth_cost_max
        path = shortcut(raw, cost, occ, x0, y0, res, ceiling) if p.shortcut else raw
        for _ in range(p.smooth_passes):
            path = chaikin(path, cost, occ, x0, y0, res, ceiling)
        path = resample(path, p.waypoint_spacing_m, cost, occ, x0, y0, res)
    else:
        raw = np.zeros((0, 2))
        path = np.zeros((0, 2))
    return PlanResult(
        path=path,
        success=success,
        status="reached" if success else "iterations_exhausted",
        iterations=int(iters),
        raw_path=raw,
        tree_xy=nodes.copy(),
        tree_parent=parent.copy(),
        K=float(K),
        temperature_final=float(T),
        n_downhill=int(stats[_ST_DOWNHILL]),
        n_uphill_accepted=int(stats[_ST_UP_ACCEPT]),
        n_uphill_rejected=int(stats[_ST_UP_REJECT]),
        n_collision_rejected=int(stats[_ST_COLLISION]),
        n_cooled=int(stats[_ST_COOL]),
        n_heated=int(stats[_ST_HEAT]),
        uphill_log=log.copy(),
    )
