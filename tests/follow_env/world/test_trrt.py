"""T-RRT planner (reference §3): finds paths through clutter, keeps to free space, is deterministic
per key, and its transition test and temperature rule behave as the spec says."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from follow_env.sim.rng import uniform_at
from follow_env.world.trrt import (
    COUNTERS_PER_ITER,
    CostMap,
    PlanResult,
    TRRTParams,
    cost_map_from_obstacles,
    counters_needed,
    plan,
    segment_is_free,
    transition_probability,
    update_temperature,
)

# A 20 m x 14 m perfect maze of 8 x 5 cells (2.5 m x 2.8 m), start and goal in opposite
# corner cells.
MAZE_W_M, MAZE_H_M, MAZE_COLS, MAZE_ROWS = 20.0, 14.0, 8, 5
CELL_W_M, CELL_H_M = MAZE_W_M / MAZE_COLS, MAZE_H_M / MAZE_ROWS
START = (0.5 * CELL_W_M, 0.5 * CELL_H_M)
GOAL = (MAZE_W_M - 0.5 * CELL_W_M, MAZE_H_M - 0.5 * CELL_H_M)


def maze_walls(seed: int) -> np.ndarray:
    """Walls (n, 4) of a perfect maze carved by a depth-first search (one route between any two
    cells, so the path winds through dead ends)."""
    rng = np.random.default_rng(seed)
    visited = np.zeros((MAZE_COLS, MAZE_ROWS), dtype=bool)
    opened: set[frozenset[tuple[int, int]]] = set()
    stack = [(0, 0)]
    visited[0, 0] = True
    while stack:
        c, r = stack[-1]
        nbrs = [
            (c + dc, r + dr)
            for dc, dr in ((1, 0), (-1, 0), (0, 1), (0, -1))
            if 0 <= c + dc < MAZE_COLS and 0 <= r + dr < MAZE_ROWS and not visited[c + dc, r + dr]
        ]
        if not nbrs:
            stack.pop()
            continue
        nxt = nbrs[rng.integers(len(nbrs))]
        visited[nxt] = True
        opened.add(frozenset([(c, r), nxt]))
        stack.append(nxt)
    w, h = MAZE_W_M, MAZE_H_M
    walls = [[0, 0, w, 0], [w, 0, w, h], [w, h, 0, h], [0, h, 0, 0]]
    for c in range(MAZE_COLS):
        for r in range(MAZE_ROWS):
            x1, y1 = (c + 1) * CELL_W_M, (r + 1) * CELL_H_M
            if c + 1 < MAZE_COLS and frozenset([(c, r), (c + 1, r)]) not in opened:
                walls.append([x1, r * CELL_H_M, x1, y1])
            if r + 1 < MAZE_ROWS and frozenset([(c, r), (c, r + 1)]) not in opened:
                walls.append([c * CELL_W_M, y1, x1, y1])
    return np.array(walls, dtype=float)


@pytest.fixture(scope="module")
def maze() -> CostMap:
    # A rotated box narrows one junction as well.
    return cost_map_from_obstacles(
        (0, 0, MAZE_W_M, MAZE_H_M), maze_walls(0), boxes=[[10.0, 7.0, 0.6, 0.6, 0.5]]
    )


@pytest.fixture(scope="module")
def maze_plans(maze: CostMap) -> list[PlanResult]:
    return [plan(maze, START, GOAL, key) for key in range(8)]


def _hits_obstacle(cost_map: CostMap, path: np.ndarray, step_m: float = 0.01) -> bool:
    """Sample every segment of ``path`` every ``step_m`` (independently of the planner's own
    grid traversal) and look each sample up in the occupancy grid."""
    for a, b in itertools.pairwise(path):
        n = max(2, math.ceil(np.linalg.norm(b - a) / step_m) + 1)
        pts = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
        ij = np.floor((pts - [cost_map.x0_m, cost_map.y0_m]) / cost_map.resolution_m).astype(int)
        ny, nx = cost_map.shape
        if np.any(ij < 0) or np.any(ij[:, 0] >= nx) or np.any(ij[:, 1] >= ny):
            return True
        if cost_map.occupied[ij[:, 1], ij[:, 0]].any():
            return True
    return False


# --- finding paths ------------------------------------------------------------------------------


def test_finds_a_path_through_a_maze(maze_plans: list[PlanResult]) -> None:
    for r in maze_plans:
        assert r.success
        assert r.status == "reached"
        np.testing.assert_array_equal(r.path[0], START)
        np.testing.assert_array_equal(r.path[-1], GOAL)
        # The maze's route is far longer than the straight line (~19 m).
        assert r.length_m > 30.0


def test_path_stays_in_free_space_at_fine_sampling(
    maze: CostMap, maze_plans: list[PlanResult]
) -> None:
    for r in maze_plans:
        assert not _hits_obstacle(maze, r.path)
        assert not _hits_obstacle(maze, r.raw_path)


def test_every_tree_edge_stays_in_free_space(maze: CostMap, maze_plans: list[PlanResult]) -> None:
    r = maze_plans[0]
    for child, parent in enumerate(r.tree_parent):
        if parent >= 0:
            assert not _hits_obstacle(maze, r.tree_xy[[parent, child]])


def test_path_waypoints_are_at_most_the_spacing_apart(maze_plans: list[PlanResult]) -> None:
    spacing = TRRTParams().waypoint_spacing_m
    for r in maze_plans:
        gaps = np.linalg.norm(np.diff(r.path, axis=0), axis=1)
        assert gaps.max() <= spacing + 1e-9
        assert gaps.min() > 0.0


def test_post_processing_does_not_lengthen_the_tree_path(maze_plans: list[PlanResult]) -> None:
    for r in maze_plans:
        raw_length = np.sum(np.linalg.norm(np.diff(r.raw_path, axis=0), axis=1))
        assert r.length_m <= raw_length + 1e-9


def test_path_keeps_to_low_cost_away_from_walls(
    maze: CostMap, maze_plans: list[PlanResult]
) -> None:
    # The cost pulls the path towards corridor centres: most waypoints sit where the cost is
    # below the middle of its range (a path hugging the inflated walls would sit near 1).
    costs = np.array([maze.cost_at(p) for r in maze_plans for p in r.path])
    assert np.median(costs) < 0.5


def test_start_at_the_goal_gives_a_two_point_path(maze: CostMap) -> None:
    r = plan(maze, START, START, key=0)
    assert r.success
    assert r.iterations == 0
    np.testing.assert_array_equal(r.path, [START, START])


def test_unreachable_goal_returns_failure_without_raising() -> None:
    # The goal lies in a closed room.
    walls = [[0, 0, 10, 0], [10, 0, 10, 10], [10, 10, 0, 10], [0, 10, 0, 0], [6, 0, 6, 10]]
    cost_map = cost_map_from_obstacles((0, 0, 10, 10), walls)
    r = plan(cost_map, (1, 1), (8, 8), key=0, params=TRRTParams(max_iters=3000))
    assert not r.success
    assert r.status == "iterations_exhausted"
    assert r.iterations == 3000
    assert r.path.shape == (0, 2)
    assert r.raw_path.shape == (0, 2)


# --- determinism -----------------------------------------------------------------------------


def test_same_key_gives_the_same_tree_and_path(maze: CostMap, maze_plans: list[PlanResult]) -> None:
    again = plan(maze, START, GOAL, key=0)
    np.testing.assert_array_equal(again.tree_xy, maze_plans[0].tree_xy)
    np.testing.assert_array_equal(again.tree_parent, maze_plans[0].tree_parent)
    np.testing.assert_array_equal(again.path, maze_plans[0].path)


def test_different_keys_give_different_trees(maze_plans: list[PlanResult]) -> None:
    a, b = maze_plans[0], maze_plans[1]
    n = min(len(a.tree_xy), len(b.tree_xy))
    assert not np.array_equal(a.tree_xy[:n], b.tree_xy[:n])
    assert not np.array_equal(a.path, b.path)


def test_counter0_selects_another_part_of_the_stream(maze: CostMap) -> None:
    p = TRRTParams()
    a = plan(maze, START, GOAL, key=0, params=p)
    b = plan(maze, START, GOAL, key=0, params=p, counter0=counters_needed(p))
    assert counters_needed(p) == COUNTERS_PER_ITER * p.max_iters
    assert not np.array_equal(a.tree_xy[:10], b.tree_xy[:10])


# --- the transition test and the temperature rule (reference §3) ------------------------------


def test_a_child_no_costlier_than_its_parent_is_always_accepted() -> None:
    assert transition_probability(0.2, 0.3, 0.5, 0.3, 1e-9) == 1.0
    assert transition_probability(0.3, 0.3, 0.5, 0.3, 1e-9) == 1.0


def test_uphill_child_is_accepted_with_probability_exp_minus_dc_over_k_t() -> None:
    # dC = (0.5 - 0.2) / 0.5 m = 0.6 per m; K T = 0.3 * 2 = 0.6: exp(-1).
    assert math.isclose(transition_probability(0.5, 0.2, 0.5, 0.3, 2.0), math.exp(-1.0))
    # dC = 0.4 / 1 m; K T = 0.2 * 0.5 = 0.1: exp(-4).
    assert math.isclose(transition_probability(0.6, 0.2, 1.0, 0.2, 0.5), math.exp(-4.0))


def test_accepted_uphill_move_divides_t_by_alpha_and_resets_the_failures() -> None:
    assert update_temperature(1.0, 3, True, 2.0, 5) == (0.5, 0)


def test_rejected_uphill_move_counts_a_failure_below_n_fail_max() -> None:
    assert update_temperature(1.0, 0, False, 2.0, 5) == (1.0, 1)
    assert update_temperature(1.0, 4, False, 2.0, 5) == (1.0, 5)


def test_t_is_multiplied_by_alpha_once_failures_reach_n_fail_max() -> None:
    # reference §3, literally: "if failures reached a maximum then T = T * alpha and reset the
    # count". With n_fail_max = 3, three rejections are counted, the fourth multiplies T.
    T, n_fail = 1.0, 0
    history = []
    for _ in range(8):
        T, n_fail = update_temperature(T, n_fail, False, 2.0, 3)
        history.append((T, n_fail))
    assert history == [
        (1.0, 1),
        (1.0, 2),
        (1.0, 3),
        (2.0, 0),
        (2.0, 1),
        (2.0, 2),
        (2.0, 3),
        (4.0, 0),
    ]


def test_uphill_acceptance_rate_drops_when_t_is_small() -> None:
    # The planner's draw: accept when uniform_at(key, counter) < p. Fixed key, fixed dC.
    key = np.uint64(0x5EED)
    n = 20_000
    u = np.array([uniform_at(key, i) for i in range(n)])
    K, child, parent, dist = 0.3, 0.5, 0.2, 0.5
    rates = {}
    for T in (0.25, 1.0, 4.0):
        p = transition_probability(child, parent, dist, K, T)
        rates[T] = np.mean(u < p)
        # Binomial: within 4 standard deviations of exp(-dC / (K T)).
        assert abs(rates[T] - p) < 4.0 * math.sqrt(p * (1.0 - p) / n) + 1e-12
    assert rates[0.25] < rates[1.0] < rates[4.0]
    # exp(-8) ~ 0.0003 at T = 0.25, exp(-0.5) ~ 0.61 at T = 4.
    assert rates[0.25] < 0.01
    assert rates[4.0] > 0.5


def test_planner_acceptances_match_the_transition_probabilities(
    maze_plans: list[PlanResult],
) -> None:
    # Every uphill test of the search, with the T it ran at: accepted ones must number what
    # exp(-dC / (K T)) predicts (sum of Bernoulli trials: mean sum p, variance sum p (1 - p)).
    accepted, p = [], []
    for r in maze_plans:
        T, dC, acc = r.uphill_log.T
        p.append(np.exp(-dC / (r.K * T)))
        accepted.append(acc)
    p_all, acc_all = np.concatenate(p), np.concatenate(accepted)
    assert p_all.size > 1000
    z = (acc_all.sum() - p_all.sum()) / math.sqrt(np.sum(p_all * (1.0 - p_all)))
    assert abs(z) < 4.0
    # And low temperatures accept less: the coldest third against the hottest third.
    T_all = np.concatenate([r.uphill_log[:, 0] for r in maze_plans])
    cold, hot = T_all <= np.quantile(T_all, 1 / 3), T_all >= np.quantile(T_all, 2 / 3)
    assert acc_all[cold].mean() < acc_all[hot].mean()


def test_planner_temperature_follows_the_rule_test_by_test(maze_plans: list[PlanResult]) -> None:
    # Replay reference §3's rule over the logged outcomes: each test ran at the replayed T.
    p = TRRTParams()
    for r in maze_plans:
        T, n_fail = p.T0, 0
        for T_logged, _, acc in r.uphill_log:
            assert T_logged == T
            T, n_fail = update_temperature(T, n_fail, bool(acc), p.alpha, p.n_fail_max)
        assert r.temperature_final == T
        assert r.n_cooled == r.n_uphill_accepted
        assert math.isclose(r.temperature_final, p.T0 * p.alpha ** (r.n_heated - r.n_cooled))


def test_k_is_the_mean_cost_of_start_and_goal_with_a_floor(maze: CostMap) -> None:
    r = plan(maze, START, GOAL, key=0, params=TRRTParams(max_iters=1))
    assert math.isclose(r.K, 0.5 * (maze.cost_at(START) + maze.cost_at(GOAL)))
    # Far from every wall the cost is ~exp(-38 / 0.5) ~ 0: K takes the floor.
    hall = cost_map_from_obstacles((0, 0, 50, 50), [[0, 0, 50, 0]])
    far = plan(hall, (25, 40), (30, 45), key=0, params=TRRTParams(max_iters=1, k_floor=0.02))
    assert far.K == 0.02


# --- cost map ----------------------------------------------------------------------------------


def test_obstacles_are_inflated_by_the_body_radius() -> None:
    # A wall 0.1 m thick along x = 5; body radius 0.3 m: free from ~0.35 m off its axis.
    cm = cost_map_from_obstacles(
        (0, 0, 10, 10), [[5, 0, 5, 10]], resolution_m=0.05, body_radius_m=0.3
    )
    for dx in (0.0, 0.2, 0.3):
        assert not cm.is_free((5 + dx, 5))
        assert not cm.is_free((5 - dx, 5))
    for dx in (0.42, 1.0):
        assert cm.is_free((5 + dx, 5))
        assert cm.is_free((5 - dx, 5))


def test_cost_falls_exponentially_with_clearance() -> None:
    cm = cost_map_from_obstacles(
        (0, 0, 10, 10), [[5, 0, 5, 10]], resolution_m=0.05, body_radius_m=0.3, length_scale_m=0.5
    )
    costs = [cm.cost_at((5 + d, 5)) for d in (0.5, 1.0, 1.5, 2.0)]
    assert all(a > b for a, b in itertools.pairwise(costs))
    # 0.5 m further from the wall: one length scale, a factor e (within a cell's rounding).
    assert math.isclose(costs[1] / costs[2], math.e, rel_tol=0.15)
    # Clearance of the body at 2 m from the axis: 2 - 0.05 (half wall) - 0.3 (body).
    assert math.isclose(costs[3], math.exp(-(2.0 - 0.05 - 0.3) / 0.5), rel_tol=0.15)


def test_rotated_box_is_rasterised_along_its_heading() -> None:
    # 4 m long, 0.2 m wide, turned 90 deg: it runs along y.
    cm = cost_map_from_obstacles(
        (0, 0, 10, 10), boxes=[[5, 5, 4.0, 0.2, math.pi / 2]], body_radius_m=0.0
    )
    assert not cm.is_free((5.0, 6.8))
    assert cm.is_free((6.8, 5.0))
    axis_aligned = cost_map_from_obstacles((0, 0, 10, 10), boxes=[[5, 5, 4.0, 0.2]])
    assert not axis_aligned.is_free((6.8, 5.0))


def test_segment_check_sees_a_wall_between_two_free_points() -> None:
    cm = cost_map_from_obstacles((0, 0, 10, 10), [[5, 2, 5, 8]])
    assert not segment_is_free(cm, (2, 5), (8, 5))
    assert segment_is_free(cm, (2, 1), (8, 1))


# --- bad inputs --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("step_m", 0.0),
        ("max_iters", 0),
        ("max_iters", 10.5),
        ("goal_bias", 1.5),
        ("goal_tol_m", -0.1),
        ("alpha", 1.0),
        ("n_fail_max", -1),
        ("T0", 0.0),
        ("k_floor", float("nan")),
        ("waypoint_spacing_m", 0.0),
        ("shortcut", "yes"),
    ],
)
def test_bad_params_raise_naming_the_field_and_value(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=rf"TRRTParams\.{field}={value!r}"):
        TRRTParams(**{field: value})


@pytest.mark.parametrize(
    ("start", "goal", "message"),
    [
        ((-1.0, 1.0), GOAL, r"start_xy=\(-1, 1\) is outside the cost map"),
        (START, (25.0, 3.0), r"goal_xy=\(25, 3\) is outside the cost map"),
        ((5.0, 0.1), GOAL, r"start_xy=\(5, 0.1\) is inside an obstacle"),
        (START, (float("nan"), 1.0), r"goal_xy=\(nan, 1.0\) is not a point"),
        (START, (1.0, 2.0, 3.0), r"goal_xy=\(1.0, 2.0, 3.0\) is not a point"),
    ],
)
def test_bad_start_or_goal_raises_naming_the_value(
    maze: CostMap, start: tuple[float, ...], goal: tuple[float, ...], message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        plan(maze, start, goal, key=0)


@pytest.mark.parametrize("key", [-1, 2**64, 1.5, True])
def test_bad_key_raises_naming_the_value(maze: CostMap, key: object) -> None:
    with pytest.raises(ValueError, match=rf"key={key!r} is out of range"):
        plan(maze, START, GOAL, key=key)  # type: ignore[arg-type]


def test_bad_cost_map_raises() -> None:
    with pytest.raises(ValueError, match="must match cost"):
        CostMap(np.zeros((3, 4)), np.zeros((4, 3), dtype=bool), 0.0, 0.0, 0.1)
    with pytest.raises(ValueError, match=r"resolution_m=0.0 is out of range"):
        CostMap(np.zeros((3, 4)), np.zeros((3, 4), dtype=bool), 0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="finite and >= 0"):
        CostMap(-np.ones((3, 4)), np.zeros((3, 4), dtype=bool), 0.0, 0.0, 0.1)


def test_the_bucketed_nearest_node_is_the_first_of_the_nearest_in_index_order() -> None:
    from follow_env.world.buckets import bucket_of, nearest_in_buckets

    rng = np.random.default_rng(0)
    x0, y0, g, gnx, gny = -3.0, 2.0, 1.0, 9, 7
    nodes = rng.uniform([x0, y0], [x0 + 8.5, y0 + 6.5], size=(400, 2))
    nodes[200:260] = nodes[100:160]  # equally near twins: the lower index must win
    nodes[300:] = np.round(nodes[300:])  # points on bucket borders
    head, nxt = np.full(gnx * gny, -1, dtype=np.int64), np.empty(len(nodes), dtype=np.int64)
    for j, (x, y) in enumerate(nodes):
        b = bucket_of(x, y, x0, y0, g, gnx, gny)
        nxt[j], head[b] = head[b], j
    queries = np.vstack([rng.uniform([x0, y0], [x0 + 8.5, y0 + 6.5], size=(500, 2)), nodes[::7]])
    for qx, qy in queries:
        d2 = ((nodes - [qx, qy]) ** 2).sum(axis=1)
        assert nearest_in_buckets(nodes, head, nxt, qx, qy, x0, y0, g, gnx, gny) == (
            int(np.argmin(d2)),  # argmin: the first index of the minimum, as the scan kept
            d2.min(),
        )
